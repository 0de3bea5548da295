#pragma once
// The OpenMP thread count a benchmark runs at: set from one of its arguments, restored after.
// Without OpenMP a count above 1 cannot be had: the benchmark is skipped with an error rather than
// run on one thread under a "threads:2" name, and `skipped()` tells the caller to return.
#include <benchmark/benchmark.h>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace tjepa_bench {

class Threads {
 public:
  explicit Threads(benchmark::State& s, int arg = 0) {
    const int n = static_cast<int>(s.range(arg));
#ifdef _OPENMP
    previous_ = omp_get_max_threads();
    omp_set_num_threads(n);
#else
    if (n > 1) {
      s.SkipWithError("built without OpenMP");
      skipped_ = true;
    }
#endif
  }
  ~Threads() {
#ifdef _OPENMP
    omp_set_num_threads(previous_);
#endif
  }
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;
  bool skipped() const { return skipped_; }

 private:
  [[maybe_unused]] int previous_ = 1;
  bool skipped_ = false;
};

}  // namespace tjepa_bench
