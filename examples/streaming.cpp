// The control loop runs one window at a time (batch 1), and the library parallelizes over the
// batch: OpenMP would add nothing but a team allocation per parallel region (libgomp allocates
// its team each time), so this program is single-threaded by construction.
// GCC 12 flags Eigen's AVX-512 GEMM kernels (avx512fintrin.h, -W[maybe-]uninitialized), a known
// false positive in a system header that -Werror would otherwise turn into an error.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#undef _OPENMP

// Streaming inference: the frozen encoder (and a force/indenter probe on top) called at
// control-loop rate over a ring buffer of the last τ frames of the 368-taxel Allegro hand.
//
// Each tick: one new frame arrives [N, m] → preprocessed in place → written into the ring
// [τ, N, m] → the window is copied out as tokenizer rows [N, m·τ] (oldest frame first) → tokenizer →
// encoder (all N tokens) → probe → force (3) and indenter logits. Every buffer is made before the
// loop and the modules' workspaces stop growing after the first tick, so the steady state
// allocates nothing: every malloc of the process is counted and the example checks it.
//
//   streaming [--checkpoint runs/demo/checkpoint.safetensors] [--ticks 2000] [--rate 100]
// Prints latency p50 / p99 / max per tick and the allocations after warm-up.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <thread>
#include <vector>

#include "cli/setup.hpp"
#include <tjepa/downstream/probe_training.hpp>

// Every heap allocation of the process, counted at the C level (operator new, std::vector and
// xsimd's aligned allocator all end in one of these): glibc lets the program interpose them.
namespace {
std::atomic<long long> g_allocations{0};
}  // namespace

extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);

void* malloc(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n);
}
void* calloc(std::size_t k, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(k, n);
}
void* realloc(void* p, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, n);
}
void* aligned_alloc(std::size_t a, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_memalign(a, n);
}
void* memalign(std::size_t a, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_memalign(a, n);
}
int posix_memalign(void** out, std::size_t a, std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  void* p = __libc_memalign(a, n);
  if (!p) return ENOMEM;
  *out = p;
  return 0;
}
}

int main(int argc, char** argv) {
  using namespace tjepa;
  CLI::App app{"Streaming inference of a frozen Tactile-JEPA encoder over a ring buffer of frames"};
  std::string checkpoint;
  int ticks = 2000, warmup = 20;
  double rate = 0;
  app.add_option("--checkpoint", checkpoint, "checkpoint of `tjepa pretrain`/`tjepa demo` (default: random weights, demo size)");
  app.add_option("--ticks", ticks, "control-loop ticks to time")->capture_default_str();
  app.add_option("--warmup", warmup, "ticks before timing and allocation counting")->capture_default_str();
  app.add_option("--rate", rate, "control-loop rate in Hz (0: back to back)")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "streaming: error: %s\n", e.what());
    return 2;
  }
  try {
    require<ConfigError>(ticks > 0 && warmup >= 1, "--ticks ", ticks, ", --warmup ", warmup, ", expected > 0");
    const Skin skin = layouts::allegro_xela();
    // The sensor: a simulated recording played back frame by frame.
    SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 7);
    const int N = skin.size(), m = sim.axes();
    const Recording baseline = sim.record_baseline(300);
    const SimRecording stream = sim.record(std::max(ticks + warmup, 1000));
    std::unique_ptr<JepaModel<float>> model;
    Preprocessor pre;
    int tau = 10;
    if (!checkpoint.empty()) {
      cli::LoadedModel lm = cli::load_model(checkpoint);
      model = std::move(lm.model);
      pre = std::move(lm.pre);
      tau = lm.run.tau;
    } else {
      cli::RunConfig run;
      model = std::make_unique<JepaModel<float>>(run.model(N, m), 0);
      pre = cli::fit_preprocessor("magnetic", &baseline, std::span<const Recording>(&stream.recording, 1));
    }
    require<ShapeError>(model->num_tokens() == N && model->config.in_dim == tau * m, "the checkpoint expects ",
                        model->num_tokens(), " taxels of ", model->config.in_dim, " values, the hand has ", N,
                        " taxels of ", tau * m);
    const int d = model->dim();
    ForceIndenterProbe<float> probe(d, model->config.encoder.heads, num_indenter_shapes, 1);

    // Everything the loop touches, made once.
    std::vector<float> ring(static_cast<std::size_t>(tau) * N * m, 0.0f);  // [τ, N, m]
    std::vector<float> window(ring.size());                                // [N, m·τ] tokenizer rows
    std::vector<float> tokens(static_cast<std::size_t>(N) * d), emb(tokens.size());
    std::vector<float> y(static_cast<std::size_t>(probe.outputs()));
    Workspace<float> ws;
    std::vector<double> latency_us;
    latency_us.reserve(static_cast<std::size_t>(ticks));
    long long allocations_before = 0;
    double checksum = 0;
    int head = 0;  // ring slot of the next frame
    const auto period = rate > 0 ? std::chrono::duration<double>(1.0 / rate) : std::chrono::duration<double>(0);
    auto next = std::chrono::steady_clock::now();
    for (int k = 0; k < warmup + ticks; ++k) {
      if (k == warmup) allocations_before = g_allocations.load();
      const auto t0 = std::chrono::steady_clock::now();
      float* slot = ring.data() + static_cast<std::size_t>(head) * N * m;
      std::copy_n(stream.recording.frame(k % stream.recording.frames()), static_cast<std::size_t>(N) * m, slot);
      pre.apply(slot, 1, N, 1, m);
      head = (head + 1) % tau;
      // window[n, a·τ + j] = ring[(head + j) mod τ, n, a]: oldest frame first, each taxel's
      // window axis-major as the tokenizer reads it (data/window_source.hpp's windows_to_tokens).
      for (int j = 0; j < tau; ++j) {
        const float* f = ring.data() + static_cast<std::size_t>((head + j) % tau) * N * m;
        for (int n = 0; n < N; ++n)
          for (int a = 0; a < m; ++a)
            window[(static_cast<std::size_t>(n) * m + a) * tau + j] = f[static_cast<std::size_t>(n) * m + a];
      }
      model->tokenizer.forward(model->target, window.data(), 1, tokens.data(), nullptr, ws);
      model->encoder.forward(model->target, tokens.data(), 1, nullptr, N, emb.data(), nullptr, ws);
      probe.probe.forward(probe.params, emb.data(), 1, N, nullptr, y.data(), nullptr, ws);
      checksum += y[0];
      const auto t1 = std::chrono::steady_clock::now();
      if (k >= warmup) latency_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      if (rate > 0) {
        next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
        std::this_thread::sleep_until(next);
      }
    }
    const long long steady_allocations = g_allocations.load() - allocations_before;
    std::vector<double> sorted = latency_us;
    std::sort(sorted.begin(), sorted.end());
    auto pct = [&](double p) { return sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(p * sorted.size()))]; };
    std::printf("streaming: %d taxels x %d axes, window of %d frames, encoder d=%d, %d blocks, %d heads%s\n", N, m, tau,
                d, model->config.encoder.depth, model->config.encoder.heads,
                checkpoint.empty() ? " (random weights)" : "");
    std::printf("%d ticks after %d warm-up ticks, 1 thread%s\n", ticks, warmup, rate > 0 ? "" : ", back to back");
    std::printf("latency per tick: p50 %.0f us, p99 %.0f us, max %.0f us (%.0f Hz sustainable at p99)\n", pct(0.5),
                pct(0.99), sorted.back(), 1e6 / pct(0.99));
    std::printf("allocations in steady state: %lld (checksum %.3f)\n", steady_allocations, checksum);
    return steady_allocations == 0 ? 0 : 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "streaming: error: %s\n", e.what());
    return 1;
  }
}
