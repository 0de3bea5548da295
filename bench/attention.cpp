// Benchmarks of the fused attention kernels (float, fused qkv layout as the Attention module uses
// them), 3 heads of 64, at the token counts of the tactile skins (L = 368, 528, 2124), batch 1 and 8.
//
// FLOP convention (per sample): forward 4 L^2 d (Q K^T and P V, 2 L^2 d each; softmax not counted),
// backward 2.5x forward (recomputed Q K^T, dO V^T, P^T dO, dS^T Q, dS K), so forward+backward
// = 3.5 * 4 L^2 d. "peak" is the fraction of the FMA peak of the cores used (233 GFLOP/s fp32 per
// core on the reference machine: 2 x 16-lane FMA per cycle at ~3.6 GHz).
// Batch = a loop over samples, parallel over samples with OpenMP when available (one workspace per
// thread).
// g++ 12 false positives inside its AVX-512 intrinsics as inlined into Eigen's GEMM (baseline).

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <xsimd/xsimd.hpp>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <tjepa/core/random.hpp>
#include <tjepa/kernels/attention.hpp>
#include <tjepa/kernels/peaks.hpp>

namespace {

constexpr double peak_flops_per_core = 233e9;

int threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

struct Batch {
  int B, L, H = 3, Dh = 64;
  tjepa::kernels::AttentionShape s;
  std::vector<float> qkv, out, lse, dout, dqkv;
  std::vector<tjepa::kernels::AttentionWorkspace<float>> ws;
  Batch(int batch, int tokens) : B(batch), L(tokens), s(tjepa::kernels::AttentionShape::fused_self(tokens, 3, 64)) {
    const std::size_t d = static_cast<std::size_t>(H * Dh), n = static_cast<std::size_t>(B) * L;
    tjepa::Rng rng(7);
    qkv.resize(n * 3 * d);
    for (auto& x : qkv) x = static_cast<float>(rng.normal(0.0, 0.5));
    dout.resize(n * d);
    for (auto& x : dout) x = static_cast<float>(rng.normal(0.0, 1.0));
    out.resize(n * d);
    dqkv.resize(n * 3 * d);
    lse.resize(static_cast<std::size_t>(B) * H * L);
    ws.resize(static_cast<std::size_t>(threads()));
    for (auto& w : ws) w.reserve(s);
  }
  int thread_id() const {
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
  }
  void forward(int b) {
    const std::size_t d = static_cast<std::size_t>(H * Dh), o = static_cast<std::size_t>(b) * L;
    const float* x = qkv.data() + o * 3 * d;
    tjepa::kernels::attention_forward(s, x, x + d, x + 2 * d, nullptr, out.data() + o * d, lse.data() + o * H,
                             ws[static_cast<std::size_t>(thread_id())]);
  }
  void backward(int b) {
    const std::size_t d = static_cast<std::size_t>(H * Dh), o = static_cast<std::size_t>(b) * L;
    const float* x = qkv.data() + o * 3 * d;
    float* g = dqkv.data() + o * 3 * d;
    tjepa::kernels::attention_backward(s, x, x + d, x + 2 * d, nullptr, out.data() + o * d, lse.data() + o * H,
                              dout.data() + o * d, g, g + d, g + 2 * d, ws[static_cast<std::size_t>(thread_id())]);
  }
};

void set_counters(benchmark::State& state, const Batch& b, double flops_per_sample) {
  const double flops = flops_per_sample * b.B;
  const int used = b.B > 1 ? threads() : 1;
  state.counters["GFLOP/s"] = benchmark::Counter(flops / 1e9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak"] =
      benchmark::Counter(flops / (peak_flops_per_core * used), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["threads"] = used;
  state.counters["ws_MiB"] = static_cast<double>(b.ws[0].capacity() * sizeof(float)) / (1 << 20);
}

double forward_flops(const Batch& b) { return 4.0 * b.L * double(b.L) * b.H * b.Dh; }

// Times `step(sample)` over the batch, parallel over samples with OpenMP.
template <class Step>
void run_batch(benchmark::State& state, Batch& b, double flops_per_sample, Step step) {
  for (auto _ : state) {
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (b.B > 1)
#endif
    for (int i = 0; i < b.B; ++i) step(i);
    benchmark::ClobberMemory();
  }
  set_counters(state, b, flops_per_sample);
}

void BM_AttentionForward(benchmark::State& state) {
  Batch b(static_cast<int>(state.range(1)), static_cast<int>(state.range(0)));
  run_batch(state, b, forward_flops(b), [&b](int i) { b.forward(i); });
}

void BM_AttentionForwardBackward(benchmark::State& state) {
  Batch b(static_cast<int>(state.range(1)), static_cast<int>(state.range(0)));
  run_batch(state, b, 3.5 * forward_flops(b), [&b](int i) {
    b.forward(i);
    b.backward(i);
  });
}

// Batch 8 of one sample: the forward+backward of sample 0, 8 times per iteration (one thread).
// Beside BM_AttentionForwardBackward at batch 8 it separates the arithmetic from the memory: the
// same work on one sample's 2.3 MB of activations, which stay near the core, against 8 samples'
// 18 MB (bench/profile.sh).
void BM_AttentionForwardBackwardOneSample(benchmark::State& state) {
  Batch b(1, static_cast<int>(state.range(0)));
  const int repeats = static_cast<int>(state.range(1));
  for (auto _ : state) {
    for (int i = 0; i < repeats; ++i) {
      b.forward(0);
      b.backward(0);
    }
    benchmark::ClobberMemory();
  }
  const double flops = 3.5 * forward_flops(b) * repeats;  // one thread
  state.counters["GFLOP/s"] = benchmark::Counter(flops / 1e9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak"] = benchmark::Counter(flops / peak_flops_per_core, benchmark::Counter::kIsIterationInvariantRate);
}

// Baseline: what PyTorch's manual attention does (and what the I-JEPA code runs), with Eigen on one
// sample: per head S = Q K^T / sqrt(Dh) materialized [L, L], row softmax (Eigen's vectorized exp),
// out = S V. O(L^2) memory.
void BM_AttentionNaiveEigen(benchmark::State& state) {
  Batch b(1, static_cast<int>(state.range(0)));
  const int L = b.L, d = b.H * b.Dh;
  using RM = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using Strided = Eigen::Map<const RM, Eigen::Unaligned, Eigen::OuterStride<>>;
  RM S(L, L), O(L, b.Dh);
  const float scale = 1.0f / std::sqrt(static_cast<float>(b.Dh));
  Eigen::setNbThreads(1);  // one thread, like the fused kernel at batch 1
  for (auto _ : state) {
    for (int h = 0; h < b.H; ++h) {
      const Strided Q(b.qkv.data() + h * b.Dh, L, b.Dh, Eigen::OuterStride<>(3 * d));
      const Strided K(b.qkv.data() + d + h * b.Dh, L, b.Dh, Eigen::OuterStride<>(3 * d));
      const Strided V(b.qkv.data() + 2 * d + h * b.Dh, L, b.Dh, Eigen::OuterStride<>(3 * d));
      S.noalias() = (Q * K.transpose()) * scale;
      for (int i = 0; i < L; ++i) {
        auto row = S.row(i).array();
        row = (row - row.maxCoeff()).exp();
        row /= row.sum();
      }
      O.noalias() = S * V;
      benchmark::DoNotOptimize(O.data());
    }
  }
  set_counters(state, b, forward_flops(b));
  state.counters["ws_MiB"] = static_cast<double>(S.size() * sizeof(float)) / (1 << 20);  // the [L, L] scores
}
BENCHMARK(BM_AttentionNaiveEigen)->ArgNames({"L"})->Arg(368)->Arg(528)->Arg(2124)->Unit(benchmark::kMillisecond);

// Batch 1 runs on one thread and is timed in CPU time (robust to other processes on a shared
// machine); batch 8 may use several threads and is timed in wall-clock time.
void batch1(benchmark::internal::Benchmark* bm) {
  bm->ArgNames({"L", "batch"})->Unit(benchmark::kMillisecond);
  for (int L : {368, 528, 2124}) bm->Args({L, 1});
}
void batch8(benchmark::internal::Benchmark* bm) {
  bm->ArgNames({"L", "batch"})->Unit(benchmark::kMillisecond)->UseRealTime();
  for (int L : {368, 528, 2124}) bm->Args({L, 8});
}

// One core's peak rate of an instruction: chains(n) runs 12 independent chains of it n times in
// registers (kernels/peaks.hpp), flops a time round.
void time_chains(benchmark::State& state, float (*chains)(std::int64_t), double flops) {
  constexpr std::int64_t inner = 1 << 16;
  for (auto _ : state) {
    float out = chains(inner);
    benchmark::DoNotOptimize(out);
  }
  state.counters["GFLOP/s"] = benchmark::Counter(flops * double(inner) / 1e9, benchmark::Counter::kIsIterationInvariantRate);
}

// This machine's fp32 FMA peak on one core: native-width FMAs. Its GFLOP/s counter is the peak
// bench/make_results.py uses for "% of peak" (hosts differ: an AVX-512 core with two 512-bit FMA
// units gives ~233 GFLOP/s at 3.6 GHz, one that runs AVX-512 on 256-bit units half).
void BM_FmaPeak(benchmark::State& state) {
  time_chains(state, tjepa::detail::fma_chains, tjepa::detail::fma_chain_flops);
}
BENCHMARK(BM_FmaPeak)->Unit(benchmark::kMillisecond);

#if TJEPA_BF16_NATIVE
// The bf16 dot-product peak: vdpbf16ps, 64 FLOPs each (twice an fp32 FMA's). The bf16 products'
// ceiling, which on some CPUs is below the FMA's (kernels/peaks.hpp).
void BM_Bf16DotPeak(benchmark::State& state) {
  time_chains(state, tjepa::detail::bf16_dot_chains, tjepa::detail::bf16_dot_chain_flops);
}
BENCHMARK(BM_Bf16DotPeak)->Unit(benchmark::kMillisecond);
#endif

#if TJEPA_AMX_NATIVE
// The AMX peak: TDPBF16PS into four C tiles, 16384 FLOPs each (kernels/detail/amx.hpp). The
// linear layers' bf16 products' ceiling where AMX is enabled; skipped where it is not (TJEPA_AMX=off,
// or a CPU or kernel without the tiles).
void BM_AmxPeak(benchmark::State& state) {
  if (!tjepa::amx_enabled()) {
    state.SkipWithError("AMX is not enabled here (amx_available() false, or TJEPA_AMX=off)");
    return;
  }
  time_chains(state, tjepa::detail::amx::peak_chains, tjepa::detail::amx::peak_chain_flops);
}
BENCHMARK(BM_AmxPeak)->Unit(benchmark::kMillisecond);
#endif

BENCHMARK(BM_AttentionForward)->Apply(batch1);
BENCHMARK(BM_AttentionForwardBackward)->Apply(batch1);
BENCHMARK(BM_AttentionForward)->Apply(batch8);
BENCHMARK(BM_AttentionForwardBackward)->Apply(batch8);
BENCHMARK(BM_AttentionForwardBackwardOneSample)
    ->ArgNames({"L", "repeats"})
    ->Args({368, 8})
    ->Args({528, 8})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
