#pragma once
// The thread count the library's parallel kernels use (OpenMP's; 1 without OpenMP).
#include "tjepa/core/detail/parallel.hpp"

namespace tjepa {
// OpenMP's thread count for the next parallel region (1 without OpenMP).
inline int max_threads() { return detail::max_threads(); }
}  // namespace tjepa
