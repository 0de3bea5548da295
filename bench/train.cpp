// One JEPA training step at the reference scale (REFERENCE §4-5: ViT-Tiny encoder d = 192, 12
// blocks, 3 heads; predictor 4 blocks; Allegro/Xela skin, N = 368 tokens, m·τ = 30), float,
// batch 8 (the PyTorch reference point in bench/model.cpp), on 1 and 2 threads: forward + backward + clipping + AdamW + EMA.
//
// FLOP convention (GEMMs and attention products only): a block on L tokens costs per token
// 24 d² (qkv 6d², proj 2d², fc1 8d², fc2 8d²) + 4 L d (QKᵀ and PV) forward; forward + backward
// = 3× forward. Target encoder: forward on N tokens; context encoder: 3× on K tokens; predictor:
// 3× on K + t tokens for each of the 4 targets. Tokenizer, norms and the optimizer are not counted.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <tjepa/tjepa.hpp>

namespace {

double block_flops(double tokens, double L, double d) { return tokens * (24 * d * d + 4 * L * d); }

void BM_JepaTrainStep(benchmark::State& state) {
#ifdef _OPENMP
  const int previous = omp_get_max_threads();
  omp_set_num_threads(static_cast<int>(state.range(0)));
#else
  if (state.range(0) > 1) {
    state.SkipWithError("built without OpenMP");
    return;
  }
#endif
  const int B = 8;
  const auto skin = tjepa::layouts::allegro_xela();
  const tjepa::MaskCollator collator(skin.graph);
  const int N = collator.num_tokens();
  tjepa::JepaModel<float> model(tjepa::JepaConfig::reference(N, 30, 3), 1);
  tjepa::AdamW<float> opt(model.trainable());
  const auto schedule = tjepa::TrainingSchedule::reference(500, 100, 30);
  tjepa::Rng rng(2);
  std::vector<float> x(static_cast<std::size_t>(B) * N * 30);
  for (auto& v : x) v = static_cast<float>(rng.normal());
  const tjepa::MaskBatch masks = collator.sample(B, 3, 0);
  tjepa::JepaStep<float> step(model, tjepa::JepaStepConfig{});  // drop-path 0.3, as the reference
  // FLOPs of one step with these masks.
  const double d = 192, K = masks.K;
  double flops = block_flops(double(B) * N, N, d) * 12;  // target encoder, forward only
  flops += 3 * block_flops(double(B) * K, K, d) * 12;     // context encoder
  for (const auto& t : masks.targets) flops += 3 * block_flops(double(B) * (K + t.size), K + t.size, d) * 4;
  std::int64_t s = 0;
  for (auto _ : state) {
    auto st = step.train(opt, schedule, s, x.data(), B, masks, std::uint64_t(s));
    benchmark::DoNotOptimize(st.loss);
    ++s;
  }
  state.counters["GFLOP/s"] = benchmark::Counter(flops, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["windows/s"] = benchmark::Counter(B, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["K"] = K;
#ifdef _OPENMP
  omp_set_num_threads(previous);
#endif
}
BENCHMARK(BM_JepaTrainStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(4)->UseRealTime();

}  // namespace
