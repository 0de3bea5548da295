#pragma once
// bf16 benchmarks on a build without AVX512-BF16 would time fp32 under a bf16 name: they are
// skipped with an error instead, and `skipped_without_bf16` tells the caller to return.
#include <benchmark/benchmark.h>

#include <tjepa/kernels/precision.hpp>

namespace tjepa_bench {

inline bool skipped_without_bf16(benchmark::State& s, tjepa::Precision p) {
  if (p != tjepa::Precision::bf16 || tjepa::has_native_bf16()) return false;
  s.SkipWithError("built without AVX512-BF16: bf16 runs fp32");
  return true;
}

}  // namespace tjepa_bench
