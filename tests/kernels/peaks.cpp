// kernels/peaks.hpp: the FMA and vdpbf16ps chains compute what they say (so the peaks time real
// work), the measured peaks, and when a bf16 run is noted as slower.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include <xsimd/xsimd.hpp>

#include "tjepa/kernels/peaks.hpp"

TEST_SUITE("kernels") {
  TEST_CASE("the FMA chains equal a scalar reference (all 12 run: none is a fixed point)") {
    // Fused where the target has FMA, a product then a sum where it has not (SSE2 alone): the
    // chains match the one reference or the other.
    for (const std::int64_t n : {0, 1, 7, 1000}) {
      const float m = 0.9999f, c = 1e-3f;
      double fused = 0, unfused = 0;
      for (const float a0 : {1.0f, 1.1f, 1.2f, 1.3f, 1.4f, 1.5f, 1.6f, 1.7f, 1.8f, 1.9f, 2.0f, 2.1f}) {
        CHECK(std::fma(a0, m, c) != a0);
        float a = a0, b = a0;
        for (std::int64_t k = 0; k < n; ++k) {
          a = std::fma(a, m, c);
          b = static_cast<float>(double(b) * double(m)) + c;  // the product rounded (exact in double), then the sum
        }
        fused += double(a);
        unfused += double(b);
      }
      const double lanes = double(xsimd::batch<float>::size), got = double(tjepa::detail::fma_chains(n));
      CAPTURE(n);
      CAPTURE(got);
      CHECK((got == doctest::Approx(lanes * fused).epsilon(1e-6) || got == doctest::Approx(lanes * unfused).epsilon(1e-6)));
    }
  }

#if TJEPA_BF16_NATIVE
  TEST_CASE("the vdpbf16ps chains start at their sum and grow by two products of 2^-10 a step") {
    const double start = 16.0 * (1.0 + 1.1 + 1.2 + 1.3 + 1.4 + 1.5 + 1.6 + 1.7 + 1.8 + 1.9 + 2.0 + 2.1);
    CHECK(double(tjepa::detail::bf16_dot_chains(0)) == doctest::Approx(start).epsilon(1e-6));
    for (const std::int64_t n : {1, 1000}) {
      CAPTURE(n);
      const double moved = double(tjepa::detail::bf16_dot_chains(n)) - start;
      CHECK(moved == doctest::Approx(16.0 * 12.0 * double(n) * 2.0 / 1024.0).epsilon(1e-3));
    }
  }
#endif

#if TJEPA_AMX_NATIVE
  TEST_CASE("the AMX chains: four C tiles of ones times ones grow by 32 a step") {
    if (!tjepa::amx_available()) return;
    for (const std::int64_t n : {0, 1, 1000}) {
      CAPTURE(n);
      CHECK(double(tjepa::detail::amx::peak_chains(n)) == 4.0 * 32.0 * double(n));
    }
  }
#endif

  TEST_CASE("the AMX switch: TJEPA_AMX is on or off / set_amx(true) without tiles is an error") {
    const char* saved = std::getenv("TJEPA_AMX");
    const std::string before = saved ? saved : "";
    unsetenv("TJEPA_AMX");
    CHECK(tjepa::detail::amx::wanted_by_environment());
    setenv("TJEPA_AMX", "on", 1);
    CHECK(tjepa::detail::amx::wanted_by_environment());
    setenv("TJEPA_AMX", "off", 1);
    CHECK_FALSE(tjepa::detail::amx::wanted_by_environment());
    setenv("TJEPA_AMX", "1", 1);
    CHECK_THROWS_WITH_AS(tjepa::detail::amx::wanted_by_environment(), "TJEPA_AMX=1: expected on or off",
                         std::invalid_argument);
    if (saved)
      setenv("TJEPA_AMX", before.c_str(), 1);
    else
      unsetenv("TJEPA_AMX");
    const bool was = tjepa::amx_enabled();
    if (tjepa::amx_available()) {
      tjepa::set_amx(false);
      CHECK_FALSE(tjepa::amx_enabled());
      tjepa::set_amx(true);
      CHECK(tjepa::amx_enabled());
    } else {
      CHECK_FALSE(tjepa::amx_enabled());
      CHECK_THROWS_WITH_AS(tjepa::set_amx(true), "set_amx: this build or CPU has no AMX tiles", std::invalid_argument);
      tjepa::set_amx(false);
    }
    tjepa::set_amx(was);
  }

  TEST_CASE("the measured peaks: fp32 always / bf16 only where the build has AVX512-BF16 / AMX only where enabled") {
    const bool was = tjepa::amx_enabled();
    for (const bool amx : {false, tjepa::amx_available()}) {
      tjepa::set_amx(amx);
      const tjepa::ProductPeaks p = tjepa::measure_product_peaks(0.001);
      CAPTURE(amx);
      if (amx) {
        CHECK(p.amx_gflops > 4 * p.fp32_gflops);  // 16x the FMA's work per cycle on such cores
        CHECK(p.bf16_faster());
      } else {
        CHECK(p.amx_gflops == 0);
      }
    }
    tjepa::set_amx(was);
  }

  TEST_CASE("the measured peaks: fp32 always / bf16 only where the build has AVX512-BF16") {
    const tjepa::ProductPeaks p = tjepa::measure_product_peaks(0.001);
    CHECK(std::isfinite(p.fp32_gflops));
    CHECK(p.fp32_gflops > 0.1);
    if (tjepa::has_native_bf16()) {
      CHECK(std::isfinite(p.bf16_gflops));
      CHECK(p.bf16_gflops > 0.1);
    } else {
      CHECK(p.bf16_gflops == 0);
    }
  }

  TEST_CASE("a bf16 run is noted as slower where the bf16 peak is under 1.2x the FMA peak or the build has no bf16") {
    const bool was = tjepa::amx_enabled();
    if (tjepa::amx_available()) tjepa::set_amx(true);  // the note's text without its AMX remark
    const std::string slower = tjepa::bf16_slower_reason({.fp32_gflops = 172, .bf16_gflops = 83});
    const std::string faster = tjepa::bf16_slower_reason({.fp32_gflops = 210, .bf16_gflops = 420});
    if (tjepa::has_native_bf16()) {
      CHECK(faster.empty());
      CHECK(tjepa::bf16_slower_reason({.fp32_gflops = 172, .bf16_gflops = 83, .amx_gflops = 2700}).empty());
      if (tjepa::amx_available()) {
        tjepa::set_amx(false);
        CHECK(tjepa::bf16_slower_reason({.fp32_gflops = 172, .bf16_gflops = 83}) ==
              slower + " (AMX is here but switched off: TJEPA_AMX=off or set_amx(false))");
        tjepa::set_amx(true);
      }
      CHECK(slower == "bf16 products peak at 83 GFLOP/s on this core against fp32's 172 (vdpbf16ps at 0.48x an "
                      "FMA's FLOP rate), so fp32 runs faster here");
      CHECK(!tjepa::bf16_slower_reason({.fp32_gflops = 100, .bf16_gflops = 119}).empty());
      CHECK(tjepa::bf16_slower_reason({.fp32_gflops = 100, .bf16_gflops = 120}).empty());
    } else {
      CHECK(slower == "this build has no AVX512-BF16, so bf16 computes in fp32");
      CHECK(faster == slower);
    }
    tjepa::set_amx(was);
  }
}
