#pragma once
// Heap allocations of a whole program, counted: allocation_counter.cpp (CMake target
// tjepa_allocation_counter, linked into the tests, the tjepa command and the streaming example)
// replaces global operator new and, without a sanitizer (which owns malloc), interposes malloc,
// calloc, realloc and the aligned forms too: Eigen and xsimd allocate with malloc, not operator
// new. What counts as "no allocation in steady state" is checked with it.
#include <atomic>

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TJEPA_ALLOC_ASAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define TJEPA_ALLOC_ASAN 1
#endif
#if defined(__GLIBC__) && !defined(TJEPA_ALLOC_ASAN)
#define TJEPA_COUNTS_MALLOC 1
#endif

namespace tjepa::alloc {

extern std::atomic<long> allocations;
extern std::atomic<bool> counting;

// Whether malloc itself is counted (false under a sanitizer: operator new only).
constexpr bool counts_malloc() {
#ifdef TJEPA_COUNTS_MALLOC
  return true;
#else
  return false;
#endif
}

// Counting from now on (all threads); allocations() since then.
inline void start() {
  allocations = 0;
  counting = true;
}
inline long stop() {
  counting = false;
  return allocations.load();
}

// Heap allocations made while f runs (all threads).
template <class F>
long count_allocations(F&& f) {
  start();
  f();
  return stop();
}

}  // namespace tjepa::alloc
