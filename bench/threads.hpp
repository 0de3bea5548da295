#pragma once
// The OpenMP thread count a benchmark runs at: set from one of its arguments, restored after.
#include <benchmark/benchmark.h>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace tjepa_bench {

struct Threads {
#ifdef _OPENMP
  int previous = omp_get_max_threads();
  explicit Threads(const benchmark::State& s, int arg = 0) { omp_set_num_threads(static_cast<int>(s.range(arg))); }
  ~Threads() { omp_set_num_threads(previous); }
#else
  explicit Threads(const benchmark::State&, int = 0) {}
#endif
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;
};

}  // namespace tjepa_bench
