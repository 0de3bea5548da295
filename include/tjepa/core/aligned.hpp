#pragma once
// Aligned storage: every buffer a SIMD kernel touches starts on a 64-byte boundary (one AVX-512
// register, one cache line).
#include <cstddef>
#include <vector>

#include "tjepa/core/detail/vendor.hpp"

namespace tjepa {

inline constexpr std::size_t alignment = 64;

template <class T>
using AlignedAllocator = xsimd::aligned_allocator<T, alignment>;

template <class T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

}  // namespace tjepa
