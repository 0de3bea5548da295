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

inline int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
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
