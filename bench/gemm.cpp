// The linear layers' weight gradients, dW[N, K] += dYᵀ · X over a batch of M rows
// (kernels::linear_backward with only dW wanted), at the thread count given as the last argument:
// the products whose depth (the batch's rows) is split into slabs over the threads
// (kernels/detail/sgemm.hpp's run_split_depth). The sizes are the context encoder's at batch 8
// (bench/jepa_setup.hpp: 164 context tokens a window, M = 1312; d 192, MLP 768): fc1 (K 192,
// N 768), fc2 (768, 192), qkv (192, 576). Run with repetitions and read the real time of the
// "min" rows (their GFLOP/s is the slowest repetition's): on a shared 2-core VM a slow spell of
// the other core falls on the medians.
//   tjepa_bench --benchmark_filter=BM_WeightGradient --benchmark_repetitions=20
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include <tjepa/tjepa.hpp>

#include "threads.hpp"

namespace {

void BM_WeightGradient(benchmark::State& state) {
  const tjepa_bench::Threads threads(state, 3);
  if (threads.skipped()) return;
  const int M = static_cast<int>(state.range(0)), K = static_cast<int>(state.range(1)),
            N = static_cast<int>(state.range(2));
  tjepa::Rng rng(1);
  std::vector<float> dy(std::size_t(M) * N), x(std::size_t(M) * K), w(std::size_t(N) * K), dw(w.size());
  for (auto& v : dy) v = static_cast<float>(rng.normal());
  for (auto& v : x) v = static_cast<float>(rng.normal());
  tjepa::kernels::linear_backward<float>(nullptr, dw.data(), nullptr, dy.data(), x.data(), w.data(), M, K, N);
  for (auto _ : state) {
    tjepa::kernels::linear_backward<float>(nullptr, dw.data(), nullptr, dy.data(), x.data(), w.data(), M, K, N);
    benchmark::DoNotOptimize(dw.data());
  }
  state.counters["GFLOP/s"] = benchmark::Counter(2.0 * M * K * N / 1e9, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_WeightGradient)
    ->ArgNames({"M", "K", "N", "threads"})
    ->ArgsProduct({{1312}, {192}, {768, 576}, {1, 2}})
    ->ArgsProduct({{1312}, {768}, {192}, {1, 2}})
    ->ComputeStatistics("min", [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); })
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
