// Mask sampling: one batch of 256 mask sets (1 context + 4 targets each), on one core.
// Targets (issue 4): Allegro/Xela 368 taxels < 5 ms; grouped two-hand 528 tokens < 10 ms.
#include <benchmark/benchmark.h>

#include <tjepa/tjepa.hpp>

namespace {

void run_collator(benchmark::State& state, const tjepa::TaxelGraph& graph, tjepa::MaskConfig cfg) {
  cfg.num_threads = 1;
  const int B = static_cast<int>(state.range(0));
  tjepa::MaskCollator col(graph, cfg);
  tjepa::MaskBatch batch;
  std::uint64_t step = 0;
  col.sample_into(batch, B, 42, step++);  // warm-up: buffers grow once
  for (auto _ : state) {
    col.sample_into(batch, B, 42, step++);
    benchmark::DoNotOptimize(batch.context.data());
  }
  state.SetItemsProcessed(state.iterations() * B);
  state.counters["tokens"] = graph.num_nodes();
}

void BM_MasksAllegro(benchmark::State& state) {
  static const tjepa::Skin skin = tjepa::layouts::allegro_xela();
  run_collator(state, skin.graph, {});
}
BENCHMARK(BM_MasksAllegro)->Arg(256)->Unit(benchmark::kMillisecond);

void BM_MasksDeco50Grouped(benchmark::State& state) {
  static const tjepa::Grouping grouping = tjepa::layouts::deco50_grouping(tjepa::layouts::inspire_hands());
  run_collator(state, grouping.graph, {});
}
BENCHMARK(BM_MasksDeco50Grouped)->Arg(256)->Unit(benchmark::kMillisecond);

void BM_MasksAllegroLocalContext(benchmark::State& state) {
  static const tjepa::Skin skin = tjepa::layouts::allegro_xela();
  tjepa::MaskConfig cfg;
  cfg.context_sampling = tjepa::ContextSampling::local;
  run_collator(state, skin.graph, cfg);
}
BENCHMARK(BM_MasksAllegroLocalContext)->Arg(256)->Unit(benchmark::kMillisecond);

}  // namespace

namespace {

// The samplers alone on the Allegro hand, t = 51 (the middle of ⌊368·U(0.10, 0.18)⌋).
struct AllegroFixture {
  tjepa::Skin skin = tjepa::layouts::allegro_xela();
  tjepa::GraphPieces pieces = tjepa::part_pieces(skin.graph);
  tjepa::MaskDomain domain{skin.graph, pieces, -1};
  tjepa::MaskWorkspace ws;
  AllegroFixture() { ws.resize(skin.graph.num_nodes()); }
};

// One mask of state.range(0) tokens per iteration, drawn by sample(domain, rng, ws, out).
template <class Sample>
void run_sampler(benchmark::State& state, Sample sample) {
  static AllegroFixture f;
  tjepa::Rng rng(1);
  std::vector<int> out(static_cast<std::size_t>(state.range(0)));
  for (auto _ : state) {
    sample(f, rng, out);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_MasksLocalAllegro(benchmark::State& state) {
  run_sampler(state, [](AllegroFixture& f, tjepa::Rng& rng, std::vector<int>& out) {
    tjepa::sample_local_mask(f.skin.graph, f.domain, rng, f.ws, out);
  });
}
BENCHMARK(BM_MasksLocalAllegro)->Arg(51);

void BM_MasksGlobalAllegro(benchmark::State& state) {
  run_sampler(state, [](AllegroFixture& f, tjepa::Rng& rng, std::vector<int>& out) {
    tjepa::sample_global_mask(f.domain, tjepa::GlobalSampling::stratified, rng, f.ws, out);
  });
}
BENCHMARK(BM_MasksGlobalAllegro)->Arg(51);

void BM_MasksUniformContextAllegro(benchmark::State& state) {
  static AllegroFixture f;
  tjepa::Rng rng(1);
  std::vector<int> out(368);
  f.ws.excluded.clear();
  for (auto _ : state) {
    benchmark::DoNotOptimize(tjepa::sample_uniform_context(368, static_cast<int>(state.range(0)), rng, f.ws, out));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MasksUniformContextAllegro)->Arg(257);

}  // namespace
