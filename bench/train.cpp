// One JEPA training step at the paper's scale (Sec. III-B, IV-D; the model, skins, batch, masks
// and FLOP convention in bench/jepa_setup.hpp), float, batch 8 (as bench/compare_torch.py's
// jepa_step), forward + backward + clipping + AdamW + EMA, on the thread count given as the first
// argument. Drop-path is off (JepaStepConfig's default): every branch is computed, so GFLOP/s is
// the work done, as in PyTorch's timm-style step, which computes every branch and masks it.
//   BM_JepaTrainStep      Allegro/Xela skin, N = 368
//   BM_JepaTrainStepDeco  DECO-50, 528 grouped tokens (two predictor passes)
// bench/scale.cpp times the same step phase by phase.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <string_view>

#include <tjepa/tjepa.hpp>

#include "bf16.hpp"
#include "jepa_setup.hpp"
#include "threads.hpp"

namespace {

void run_jepa_step(benchmark::State& state, std::string_view skin, tjepa::Precision precision) {
  if (tjepa_bench::skipped_without_bf16(state, precision)) return;
  const tjepa_bench::Threads threads(state);
  if (threads.skipped()) return;
  const auto setup = tjepa_bench::jepa_setup(skin);
  const int B = setup.B;
  tjepa_bench::JepaRun run(setup, precision);
  const int N = run.N;
  const tjepa::MaskBatch& masks = run.masks;
  state.SetLabel(tjepa_bench::masks_label(masks, N));
  std::int64_t s = 0;
  run.step.train(run.opt, run.schedule, s, setup.x.data(), B, masks, std::uint64_t(s));  // warm-up: the workspace grows once
  ++s;
  for (auto _ : state) {
    auto st = run.step.train(run.opt, run.schedule, s, setup.x.data(), B, masks, std::uint64_t(s));
    benchmark::DoNotOptimize(st.loss);
    ++s;
  }
  const double flops = tjepa_bench::jepa_step_flops(setup.config, masks, N);
  state.counters["GFLOP/s"] = benchmark::Counter(flops, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["windows/s"] = benchmark::Counter(B, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["K"] = masks.K;
  state.counters["N"] = N;
}

void BM_JepaTrainStep(benchmark::State& state) { run_jepa_step(state, "allegro", tjepa::Precision::fp32); }
BENCHMARK(BM_JepaTrainStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();
// The same step with bf16 products (JepaStepConfig::precision).
void BM_JepaTrainStepBf16(benchmark::State& state) { run_jepa_step(state, "allegro", tjepa::Precision::bf16); }
BENCHMARK(BM_JepaTrainStepBf16)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();
void BM_JepaTrainStepDeco(benchmark::State& state) { run_jepa_step(state, "deco", tjepa::Precision::fp32); }
BENCHMARK(BM_JepaTrainStepDeco)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();
void BM_JepaTrainStepDecoBf16(benchmark::State& state) { run_jepa_step(state, "deco", tjepa::Precision::bf16); }
BENCHMARK(BM_JepaTrainStepDecoBf16)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();

}  // namespace
