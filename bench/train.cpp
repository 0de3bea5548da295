// One JEPA training step at the paper's scale (Sec. III-B, IV-D: ViT-Tiny encoder d = 192, 12
// blocks, 3 heads; predictor 4 blocks), float, batch 8 (as bench/compare_torch.py's jepa_step),
// forward + backward + clipping + AdamW + EMA, drop-path 0.3, with the library's
// own masks (MaskCollator, seed 3, batch 0), on the thread count given as the first argument:
//   BM_JepaTrainStep      Allegro/Xela skin, N = 368 tokens of m·τ = 30 values (K 163, targets 4 × 53)
//   BM_JepaTrainStepDeco  DECO-50, two Inspire hands: 2124 taxels in 528 groups of 4 and 5
//                         (deco50_grouping), τ = 3, m = 1, the grouped tokenizer (K 326, targets
//                         38, 38, 39, 39: per hand 1 local + 1 global; two predictor passes)
// bench/compare_torch.py times the same step in plain PyTorch with these sizes (its --jepa-*
// defaults); keep both in step when the masks change (the K counter and the log line name them).
//
// FLOP convention (GEMMs and attention products only): a block on L tokens costs per token
// 24 d² (qkv 6d², proj 2d², fc1 8d², fc2 8d²) + 4 L d (QKᵀ and PV) forward; forward + backward
// = 3× forward. Target encoder: forward on N tokens; context encoder: 3× on K tokens; predictor:
// 3× on K + t tokens for each of the 4 targets. Tokenizer, norms and the optimizer are not counted.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <tjepa/tjepa.hpp>

namespace {

double block_flops(double tokens, double L, double d) { return tokens * (24 * d * d + 4 * L * d); }

// One step of `model` on batch x [B, N, token width] with masks from `graph`'s collator.
void run_jepa_step(benchmark::State& state, const tjepa::TaxelGraph& graph, const tjepa::JepaConfig& config,
                   const std::vector<float>& x, int B, tjepa::Precision precision) {
  if (precision == tjepa::Precision::bf16 && !tjepa::has_native_bf16())
    return state.SkipWithError("built without AVX512-BF16: bf16 runs fp32");
#ifdef _OPENMP
  const int previous = omp_get_max_threads();
  omp_set_num_threads(static_cast<int>(state.range(0)));
#else
  if (state.range(0) > 1) {
    state.SkipWithError("built without OpenMP");
    return;
  }
#endif
  const tjepa::MaskCollator collator(graph);
  const int N = collator.num_tokens();
  tjepa::JepaModel<float> model(config, 1);
  tjepa::AdamW<float> opt(model.trainable());
  const auto schedule = tjepa::TrainingSchedule::reference(500, 100, 30);
  const tjepa::MaskBatch masks = collator.sample(B, 3, 0);
  tjepa::JepaStepConfig step_config;  // drop-path 0.3, as the reference
  step_config.precision = precision;
  tjepa::JepaStep<float> step(model, step_config);
  // FLOPs of one step with these masks.
  const double d = config.encoder.dim, K = masks.K;
  double flops = block_flops(double(B) * N, N, d) * config.encoder.depth;  // target encoder, forward only
  flops += 3 * block_flops(double(B) * K, K, d) * config.encoder.depth;     // context encoder
  for (const auto& t : masks.targets)
    flops += 3 * block_flops(double(B) * (K + t.size), K + t.size, d) * config.predictor.depth;
  std::string targets;
  for (const auto& t : masks.targets) {
    if (!targets.empty()) targets += ',';
    targets += std::to_string(t.size);
  }
  std::string label = "N ";
  label += std::to_string(N);
  label += ", K ";
  label += std::to_string(masks.K);
  label += ", targets ";
  label += targets;
  state.SetLabel(label);
  std::int64_t s = 0;
  step.train(opt, schedule, s, x.data(), B, masks, std::uint64_t(s));  // warm-up: the workspace grows once
  ++s;
  for (auto _ : state) {
    auto st = step.train(opt, schedule, s, x.data(), B, masks, std::uint64_t(s));
    benchmark::DoNotOptimize(st.loss);
    ++s;
  }
  state.counters["GFLOP/s"] = benchmark::Counter(flops, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["windows/s"] = benchmark::Counter(B, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["K"] = K;
  state.counters["N"] = N;
#ifdef _OPENMP
  omp_set_num_threads(previous);
#endif
}

void allegro_step(benchmark::State& state, tjepa::Precision precision) {
  const int B = 8;
  const auto skin = tjepa::layouts::allegro_xela();
  const int N = skin.graph.num_nodes();
  tjepa::Rng rng(2);
  std::vector<float> x(static_cast<std::size_t>(B) * N * 30);
  for (auto& v : x) v = static_cast<float>(rng.normal());
  run_jepa_step(state, skin.graph, tjepa::JepaConfig::reference(N, 30, 3), x, B, precision);
}
void BM_JepaTrainStep(benchmark::State& state) { allegro_step(state, tjepa::Precision::fp32); }
BENCHMARK(BM_JepaTrainStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();
// The same step with bf16 products (JepaStepConfig::precision).
void BM_JepaTrainStepBf16(benchmark::State& state) { allegro_step(state, tjepa::Precision::bf16); }
BENCHMARK(BM_JepaTrainStepBf16)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();

void deco_step(benchmark::State& state, tjepa::Precision precision) {
  const int B = 8, tau = 3, axes = 1;
  const tjepa::Skin hands = tjepa::layouts::inspire_hands();
  const tjepa::Grouping grouping = tjepa::layouts::deco50_grouping(hands);
  const int taxels = grouping.num_taxels, G = grouping.num_groups();
  // Windows [B, 2124, τ, m] gathered into the grouped tokenizer's rows [B, 528, 5·τ·m].
  tjepa::Rng rng(2);
  std::vector<float> windows(static_cast<std::size_t>(B) * taxels * tau * axes);
  for (auto& v : windows) v = static_cast<float>(rng.normal());
  std::vector<float> x(static_cast<std::size_t>(B) * G * grouping.max_size * tau * axes);
  tjepa::gather_groups(windows.data(), B, taxels, tau, axes, grouping.members.data(), G, grouping.max_size, x.data());
  tjepa::JepaConfig config = tjepa::JepaConfig::reference(G, tau * axes, axes);
  config.group_size = grouping.sizes;
  run_jepa_step(state, grouping.graph, config, x, B, precision);
}
void BM_JepaTrainStepDeco(benchmark::State& state) { deco_step(state, tjepa::Precision::fp32); }
BENCHMARK(BM_JepaTrainStepDeco)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();
void BM_JepaTrainStepDecoBf16(benchmark::State& state) { deco_step(state, tjepa::Precision::bf16); }
BENCHMARK(BM_JepaTrainStepDecoBf16)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();

}  // namespace
