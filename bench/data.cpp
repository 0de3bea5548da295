// Benchmarks of the data path: simulated windows per second (Allegro/Xela, 368 taxels × τ = 10 ×
// 3 axes), preprocessing throughput on batches, window gathering, and .npy reading.
#include <benchmark/benchmark.h>

#include <tjepa/data/grouped_gather.hpp>
#include <tjepa/data/npy.hpp>
#include <tjepa/data/preprocessor.hpp>
#include <tjepa/sim/simulated_skin.hpp>
#include <tjepa/data/window_source.hpp>
#include <tjepa/sensors/allegro_xela.hpp>
#include <tjepa/sensors/inspire.hpp>

#include <filesystem>
#include <unistd.h>

namespace {

constexpr int kTau = 10;

// Frames of simulated 368-taxel data; items = windows of τ = 10 frames.
void BM_SimulatedWindows(benchmark::State& state) {
  const auto hand = tjepa::layouts::allegro_xela();
  tjepa::SimulatedSkin sim(hand.layout, tjepa::SimConfig{}, 1);
  const int windows = static_cast<int>(state.range(0));
  for (auto _ : state) {
    auto rec = sim.record(windows * kTau);
    benchmark::DoNotOptimize(rec.recording.data());
  }
  state.SetItemsProcessed(state.iterations() * windows);
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(windows) * kTau, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SimulatedWindows)->Arg(1000)->Unit(benchmark::kMillisecond);

struct Fixture {
  tjepa::Preprocessor pre{tjepa::PreprocessConfig::xela_counts()};
  tjepa::SimRecording data;
  Fixture() {
    const auto hand = tjepa::layouts::allegro_xela();
    tjepa::SimulatedSkin sim(hand.layout, tjepa::SimConfig{}, 2);
    pre.fit_baseline(sim.record_baseline(500));
    data = sim.record(256 * kTau * 4);
    pre.fit(data.recording);
  }
};
const Fixture& fixture() {
  static const Fixture f;
  return f;
}

// Magnetic preprocessing (drop-outs, baseline, per-axis standardization) in place on [B, N, τ, m].
void BM_PreprocessBatch(benchmark::State& state) {
  const Fixture& f = fixture();
  const int B = static_cast<int>(state.range(0));
  tjepa::WindowSource src(f.data.recording, {kTau, 0});
  tjepa::WindowBatch batch;
  std::vector<std::int64_t> ids(B);
  for (int b = 0; b < B; ++b) ids[b] = b;
  src.gather(ids, batch);
  const tjepa::AlignedVector<float> raw = batch.x;
  for (auto _ : state) {
    state.PauseTiming();
    batch.x = raw;
    state.ResumeTiming();
    f.pre.apply(batch.x.data(), static_cast<std::size_t>(B), 368, kTau, 3);
    benchmark::DoNotOptimize(batch.x.data());
  }
  state.SetItemsProcessed(state.iterations() * B);
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(raw.size() * sizeof(float)));
}
BENCHMARK(BM_PreprocessBatch)->Arg(256);

// Gathering a shuffled batch of windows with preprocessing and the finiteness check.
void BM_GatherBatch(benchmark::State& state) {
  const Fixture& f = fixture();
  const int B = static_cast<int>(state.range(0));
  tjepa::WindowSource src(f.data.recording, {kTau, 0}, f.data.labels, f.pre);
  const auto order = src.epoch_order(1, 0);
  tjepa::WindowBatch batch;
  for (auto _ : state) {
    src.gather(std::span<const std::int64_t>(order).subspan(0, B), batch);
    benchmark::DoNotOptimize(batch.x.data());
  }
  state.SetItemsProcessed(state.iterations() * B);
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(batch.x.size() * sizeof(float)));
}
BENCHMARK(BM_GatherBatch)->Arg(256);

// DECO-50 grouped tokens: a batch [B, 2124, τ = 3, 1] of the two Inspire hands into the grouped
// tokenizer's rows [B, 528, 5·3].
void BM_GatherGroupsDeco50(benchmark::State& state) {
  static const tjepa::Grouping grouping = tjepa::layouts::deco50_grouping(tjepa::layouts::inspire_hands());
  const int B = static_cast<int>(state.range(0)), N = grouping.num_taxels, G = grouping.num_groups(), tau = 3;
  std::vector<float> x(static_cast<std::size_t>(B) * N * tau, 1.0f);
  std::vector<float> out(static_cast<std::size_t>(B) * G * grouping.max_size * tau);
  for (auto _ : state) {
    tjepa::gather_groups(x.data(), B, N, tau, 1, grouping.members.data(), G, grouping.max_size, out.data());
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations() * B);
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(out.size() * sizeof(float)));
}
BENCHMARK(BM_GatherGroupsDeco50)->Arg(256);

// Reading a float32 .npy recording (mapped: no copy) and checking it for NaN.
void BM_ReadNpy(benchmark::State& state) {
  const Fixture& f = fixture();
  const auto path = std::filesystem::temp_directory_path() / ("tjepa_bench_" + std::to_string(::getpid()) + ".npy");
  tjepa::write_npy(path, f.data.recording);
  tjepa::NpyReadOptions opt;
  opt.require_finite = true;
  for (auto _ : state) {
    auto rec = tjepa::read_recording_npy(path, 3, opt);
    benchmark::DoNotOptimize(rec.data());
  }
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(f.data.recording.size() * sizeof(float)));
  std::filesystem::remove(path);
}
BENCHMARK(BM_ReadNpy)->Unit(benchmark::kMillisecond);

}  // namespace
