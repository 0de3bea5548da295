#pragma once
// The peak rates of this core's two product instructions, measured: fp32 FMAs at the build's
// native width, and vdpbf16ps (two bf16 multiply-adds into each fp32 lane) where the build has
// AVX512-BF16. Each runs as twelve independent chains in registers, more than latency × issue
// ports on current x86 cores, so a loop runs at its instruction's issue rate.
//
// Where the build has AMX and amx_enabled(), the linear layers' bf16 products run on AMX tiles
// (kernels/detail/amx.hpp), whose peak is measured as a third rate.
//
// Precision::bf16 is faster only where the second (or third) rate is well above the first. On AMD Zen 4 and
// Zen 5 the bf16 JEPA step ran 1.5-1.7x faster than fp32. On an Intel Xeon (family 6, model 207)
// without AMX, vdpbf16ps issued at a quarter of the FMA's rate, so bf16 products peaked at half of
// fp32's and the bf16 step ran at 0.6-0.7x (bench/RESULTS.md). bench/attention.cpp's BM_FmaPeak and
// BM_Bf16DotPeak time these loops; the command-line tools note a bf16 run that would be slower.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

#include <xsimd/xsimd.hpp>

#include "tjepa/kernels/detail/amx.hpp"
#include "tjepa/kernels/precision.hpp"

#if TJEPA_BF16_NATIVE || defined(__AVX512F__)
#include <immintrin.h>
#endif

namespace tjepa {

namespace detail {

// FLOPs of one iteration of fma_chains and bf16_dot_chains (a multiply-add counts two).
inline constexpr double fma_chain_flops = 12.0 * 2.0 * double(xsimd::batch<float>::size);
inline constexpr double bf16_dot_chain_flops = 12.0 * 64.0;

// a·m + c as one instruction where the target has FMA. xsimd 8.1's AVX-512 fma is a·m + c written
// out, which g++ fuses at -O2 and up but not at -O1 (twice the instructions: half the peak).
inline xsimd::batch<float> fused_multiply_add(xsimd::batch<float> a, xsimd::batch<float> m, xsimd::batch<float> c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, m, c);
#else
  return xsimd::fma(a, m, c);
#endif
}

// 12 chains a ← step(a), started at 1.0, 1.1, ..., 2.1 and run `iterations` times each in
// registers; their sum, so that none is dropped. No start may be a fixed point of the step: a
// compiler drops a chain whose first step returns its start (with a·m + c, m = 1 - 2⁻²³ and
// c = 1e-7, g++ kept 7 of the 12).
template <class Step>
[[gnu::always_inline]] inline float twelve_chains(std::int64_t iterations, Step step) {
  using B = xsimd::batch<float>;
  B a0(1.0f), a1(1.1f), a2(1.2f), a3(1.3f), a4(1.4f), a5(1.5f), a6(1.6f), a7(1.7f), a8(1.8f), a9(1.9f), a10(2.0f),
      a11(2.1f);
  for (std::int64_t k = 0; k < iterations; ++k) {
    a0 = step(a0); a1 = step(a1); a2 = step(a2); a3 = step(a3); a4 = step(a4); a5 = step(a5);
    a6 = step(a6); a7 = step(a7); a8 = step(a8); a9 = step(a9); a10 = step(a10); a11 = step(a11);
  }
  return xsimd::hadd(((a0 + a1) + (a2 + a3)) + ((a4 + a5) + (a6 + a7)) + ((a8 + a9) + (a10 + a11)));
}

// FMA chains: a ← a·m + c with m = 0.9999 and c = 1e-3 (the chains stay near 1-10).
inline float fma_chains(std::int64_t iterations) {
  const xsimd::batch<float> m(0.9999f), c(1e-3f);
  return twelve_chains(iterations, [m, c](xsimd::batch<float> a) { return fused_multiply_add(a, m, c); });
}

#if TJEPA_BF16_NATIVE
// vdpbf16ps chains: a ← a + m₀·c₀ + m₁·c₁ with m = (1, 1) and c = (2⁻¹⁰, 2⁻¹⁰) in bf16: each grows
// by 2⁻⁹ a step (less only the rounding of the start's low bits), so no step is a no-op.
inline float bf16_dot_chains(std::int64_t iterations) {
  const auto m = std::bit_cast<__m512bh>(_mm512_set1_epi32(0x3f803f80));
  const auto c = std::bit_cast<__m512bh>(_mm512_set1_epi32(0x3a803a80));
  return twelve_chains(iterations, [m, c](xsimd::batch<float> a) { return xsimd::batch<float>(_mm512_dpbf16_ps(a, m, c)); });
}
#endif

// The best rate, in GFLOP/s, of chunks of `chains` run for `seconds`: the best, not the mean, so
// that a chunk another process interrupted does not count.
template <class Chains>
double best_rate(Chains chains, double flops_per_iteration, double seconds) {
  using Clock = std::chrono::steady_clock;
  constexpr std::int64_t chunk = 4096;  // 49152 instructions: 10-40 µs
  double best = 0;
  volatile float sink = 0;
  const auto end = Clock::now() + std::chrono::duration<double>(seconds);
  for (int n = 0; n < 3 || Clock::now() < end; ++n) {
    const auto t0 = Clock::now();
    sink = sink + chains(chunk);
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (s > 0) best = std::max(best, flops_per_iteration * double(chunk) / s / 1e9);
  }
  return best;
}

}  // namespace detail

// This core's product peaks in GFLOP/s: fp32 FMAs, bf16 dot products (0 where the build has
// no AVX512-BF16: Precision::bf16 then computes in fp32), and AMX tiles (0 where amx_enabled() is
// false: the linear layers' bf16 products then run on vdpbf16ps).
struct ProductPeaks {
  double fp32_gflops = 0;
  double bf16_gflops = 0;
  double amx_gflops = 0;

  // Whether Precision::bf16's products can be faster than fp32's here: the peak of the
  // instruction that runs the linear layers' bf16 products (AMX's where enabled, else
  // vdpbf16ps's) at least 1.2x the FMA's: about 2x on CPUs where vdpbf16ps pays, 0.5x on one where
  // it does not, about 15x with AMX.
  bool bf16_faster() const { return std::max(bf16_gflops, amx_gflops) >= 1.2 * fp32_gflops; }
};

// Measures both on the calling thread, `seconds` each (a few milliseconds give the peaks to a few
// per cent: each chunk is tens of microseconds).
inline ProductPeaks measure_product_peaks(double seconds = 0.005) {
  ProductPeaks p;
  p.fp32_gflops = detail::best_rate(detail::fma_chains, detail::fma_chain_flops, seconds);
#if TJEPA_BF16_NATIVE
  p.bf16_gflops = detail::best_rate(detail::bf16_dot_chains, detail::bf16_dot_chain_flops, seconds);
#endif
#if TJEPA_AMX_NATIVE
  if (amx_enabled()) p.amx_gflops = detail::best_rate(detail::amx::peak_chains, detail::amx::peak_chain_flops, seconds);
#endif
  return p;
}

// Why Precision::bf16 would not run faster than fp32 on this build and core, in words; empty
// where it would. The command-line tools print it as a note when bf16 is asked for.
inline std::string bf16_slower_reason(const ProductPeaks& p) {
  if (!has_native_bf16()) return "this build has no AVX512-BF16, so bf16 computes in fp32";
  if (p.bf16_faster()) return {};
  char line[200];
  std::snprintf(line, sizeof line,
                "bf16 products peak at %.0f GFLOP/s on this core against fp32's %.0f (vdpbf16ps at %.2fx an FMA's "
                "FLOP rate), so fp32 runs faster here",
                p.bf16_gflops, p.fp32_gflops, p.bf16_gflops / p.fp32_gflops);
  std::string why = line;
  if (amx_available() && !amx_enabled()) why += " (AMX is here but switched off: TJEPA_AMX=off or set_amx(false))";
  return why;
}

}  // namespace tjepa
