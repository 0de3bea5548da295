// Benchmarks of building layouts, graphs and groupings (done once per run, but users rebuild
// them in scripts and tests: the two-hand DECO-50 setup must stay under 5 ms).
#include <benchmark/benchmark.h>

#include <tjepa/graph/block_grouping.hpp>
#include <tjepa/graph/coordinate_graphs.hpp>
#include <tjepa/graph/grow_grouping.hpp>
#include <tjepa/sensors/allegro_xela.hpp>
#include <tjepa/sensors/inspire.hpp>

namespace {

void BM_AllegroXelaLayout(benchmark::State& state) {
  for (auto _ : state) {
    auto skin = tjepa::layouts::allegro_xela();
    benchmark::DoNotOptimize(skin.graph.num_edges());
  }
  state.SetItemsProcessed(state.iterations() * 368);
}
BENCHMARK(BM_AllegroXelaLayout)->Unit(benchmark::kMicrosecond);

// The acceptance number: two Inspire hands (2124 taxels, graph with bridges) plus the DECO-50
// grouping (528 tokens, gather map, group graph).
void BM_InspireHandsPlusGrouping(benchmark::State& state) {
  for (auto _ : state) {
    auto skin = tjepa::layouts::inspire_hands();
    auto grouping = tjepa::layouts::deco50_grouping(skin);
    benchmark::DoNotOptimize(grouping.graph.num_edges());
  }
  state.SetItemsProcessed(state.iterations() * 2124);
}
BENCHMARK(BM_InspireHandsPlusGrouping)->Unit(benchmark::kMillisecond);

void BM_InspireHandsOnly(benchmark::State& state) {
  for (auto _ : state) {
    auto skin = tjepa::layouts::inspire_hands();
    benchmark::DoNotOptimize(skin.graph.num_edges());
  }
  state.SetItemsProcessed(state.iterations() * 2124);
}
BENCHMARK(BM_InspireHandsOnly)->Unit(benchmark::kMillisecond);

void BM_GrowGroupingInspireHands(benchmark::State& state) {
  const auto skin = tjepa::layouts::inspire_hands();
  for (auto _ : state) {
    auto grouping = tjepa::grow_grouping(skin, 4, 5);
    benchmark::DoNotOptimize(grouping.num_groups());
  }
  state.SetItemsProcessed(state.iterations() * 2124);
}
BENCHMARK(BM_GrowGroupingInspireHands)->Unit(benchmark::kMillisecond);

void BM_KnnAllegro(benchmark::State& state) {
  const auto skin = tjepa::layouts::allegro_xela();
  for (auto _ : state) benchmark::DoNotOptimize(tjepa::knn_edges(skin.layout, static_cast<int>(state.range(0))).size());
}
BENCHMARK(BM_KnnAllegro)->Arg(4)->Arg(8)->Unit(benchmark::kMillisecond);

}  // namespace
