// Benchmarks of the RNG draws every sampler and initializer uses.
#include <benchmark/benchmark.h>

#include <tjepa/core/random.hpp>

namespace {

void BM_RngRaw(benchmark::State& state) {
  tjepa::Rng rng(1);
  for (auto _ : state) benchmark::DoNotOptimize(rng());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RngRaw);

void BM_RngUniform(benchmark::State& state) {
  tjepa::Rng rng(1);
  for (auto _ : state) benchmark::DoNotOptimize(rng.uniform());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RngUniform);

void BM_RngBelow(benchmark::State& state) {
  tjepa::Rng rng(1);
  const auto n = static_cast<std::uint64_t>(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(rng.below(n));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RngBelow)->Arg(368)->Arg(2124);

void BM_RngNormal(benchmark::State& state) {
  tjepa::Rng rng(1);
  for (auto _ : state) benchmark::DoNotOptimize(rng.normal());
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RngNormal);

void BM_RngTruncatedNormal(benchmark::State& state) {
  tjepa::Rng rng(1);
  for (auto _ : state) benchmark::DoNotOptimize(rng.truncated_normal(0.0, 0.02, -2.0, 2.0));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RngTruncatedNormal);

}  // namespace
