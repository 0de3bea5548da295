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

#include "bf16.hpp"
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

// One block's MLP backward (model/mlp.hpp: Mlp::backward) at the context encoder's size (M 1312,
// d 192, hidden 768), whole (part 0) and part by part, at the thread count given last: 1 the
// GELU and its derivative (gelu_forward_grad), 2 fc2's dW and db, 3 dh through fc2 and gelu'
// (linear_backward_input_scaled), 4 fc1's dx, dW and db; bf16 1: the products in bf16 (part 1 has
// none, so it runs in fp32 only). The scale profile (bench/scale.sh) reads
// this backward's 2-thread speed-up at 1.5-1.9x from run to run; these parts say how each product splits.
void BM_MlpBackward(benchmark::State& state) {
  const tjepa_bench::Threads threads(state, 3);
  if (threads.skipped()) return;
  const int M = static_cast<int>(state.range(0)), part = static_cast<int>(state.range(1));
  const tjepa::Precision p = state.range(2) ? tjepa::Precision::bf16 : tjepa::Precision::fp32;
  if (tjepa_bench::skipped_without_bf16(state, p)) return;
  constexpr int d = 192, H = 768;
  tjepa::ParamSet<float> ps;
  const tjepa::Mlp mlp = tjepa::Mlp::add(ps, "mlp", d, H, true);
  ps.allocate();
  tjepa::Rng rng(1);
  for (auto& v : ps.values()) v = static_cast<float>(0.02 * rng.normal());
  const std::size_t mh = std::size_t(M) * H, md = std::size_t(M) * d;
  std::vector<float> x(md), dy(md), dx(md), h_pre(mh), h(mh), dh(mh);
  for (auto& v : x) v = static_cast<float>(rng.normal());
  for (auto& v : dy) v = static_cast<float>(rng.normal());
  for (auto& v : h_pre) v = static_cast<float>(rng.normal());
  tjepa::kernels::gelu_forward_grad(h.data(), dh.data(), h_pre.data(), mh);
  const auto run = [&] {
    namespace k = tjepa::kernels;
    switch (part) {
      case 0: mlp.backward(ps, dy.data(), x.data(), h_pre.data(), h.data(), dh.data(), dx.data(), M, p); break;
      case 1: k::gelu_forward_grad(h.data(), dh.data(), h_pre.data(), mh); break;
      case 2: mlp.fc2.backward(ps, dy.data(), h.data(), static_cast<float*>(nullptr), M, p); break;
      case 3:
        k::linear_backward_input_scaled(h_pre.data(), dy.data(), ps.value(mlp.fc2.weight), dh.data(), M, H, d, p);
        break;
      default: mlp.fc1.backward(ps, h.data(), x.data(), dx.data(), M, p); break;
    }
  };
  run();
  for (auto _ : state) {
    run();
    benchmark::ClobberMemory();
  }
  const double flops[] = {4 * 2.0 * M * d * H, 0, 2.0 * M * d * H, 2.0 * M * d * H, 2 * 2.0 * M * d * H};
  if (flops[part] > 0)
    state.counters["GFLOP/s"] = benchmark::Counter(flops[part] / 1e9, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_MlpBackward)
    ->ArgNames({"M", "part", "bf16", "threads"})
    ->ArgsProduct({{1312}, {0, 2, 3, 4}, {0, 1}, {1, 2}})
    ->ArgsProduct({{1312}, {1}, {0}, {1, 2}})
    ->ComputeStatistics("min", [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); })
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
