#pragma once
// OpenMP helpers: the library builds and runs the same without OpenMP (pragmas vanish, one thread).
#include <cstddef>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#define TJEPA_OMP(directive) _Pragma(#directive)
#else
#define TJEPA_OMP(directive)
#endif

#include "tjepa/core/aligned.hpp"

namespace tjepa::detail {

// Below these sizes a loop runs on one thread: a parallel region costs microseconds when the
// cores are free and a scheduler time slice when they are not.
inline constexpr std::size_t parallel_grain = std::size_t(1) << 17;  // elements of a row-wise kernel
inline constexpr double parallel_min_flops = 8e6;                     // of a GEMM

inline int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}
// Threads of the enclosing parallel region (1 outside one).
inline int team_size() {
#ifdef _OPENMP
  return omp_get_num_threads();
#else
  return 1;
#endif
}
inline int thread_id() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

// Grows a caller-owned buffer to at least n elements and returns its data. A buffer never shrinks,
// so a second call with the same shape does not allocate.
template <class T, class A>
T* grow(std::vector<T, A>& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
  return v.data();
}

}  // namespace tjepa::detail
