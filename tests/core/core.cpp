// Second translation unit that includes the umbrella header (see tests/main.cpp).
// core/detail/vendor.hpp is tested by the build itself: no test or example file silences GCC 12's
// AVX-512 warning any more, and they all build with -Werror.
#include <doctest/doctest.h>

#include <tjepa/core/detail/vendor.hpp>
#include <tjepa/tjepa.hpp>

#include <cmath>
#include <cstring>
#include <set>
#include <vector>

TEST_SUITE("core") {
  TEST_CASE("version macros match the version string") {
    CHECK(std::string(tjepa::version_string) ==
          std::to_string(TJEPA_VERSION_MAJOR) + "." + std::to_string(TJEPA_VERSION_MINOR) + "." +
              std::to_string(TJEPA_VERSION_PATCH));
  }

  TEST_CASE("Error carries its message and subclasses are Errors") {
    try {
      tjepa::fail<tjepa::ShapeError>("x: shape [", 2, ", ", 3, "], expected [2, 4]");
      FAIL("no throw");
    } catch (const tjepa::Error& e) {
      CHECK(std::string(e.what()) == "x: shape [2, 3], expected [2, 4]");
    }
    CHECK_THROWS_AS(tjepa::require<tjepa::ConfigError>(false, "bad"), tjepa::ConfigError);
    CHECK_NOTHROW(tjepa::require(true, "fine"));
    CHECK_THROWS_WITH_AS(tjepa::require<tjepa::DataError>(false, "v = ", 1.5),
                         "v = 1.5", std::runtime_error);
  }

  TEST_CASE("Rng is xoshiro256** and reproducible") {
    tjepa::Rng r;
    r.set_state({1, 2, 3, 4});
    // Reference xoshiro256** from state {1,2,3,4}: rotl(2*5, 7)*9 = 11520, then 0, then 1509978240.
    CHECK(r() == 11520u);
    CHECK(r() == 0u);
    CHECK(r() == 1509978240u);

    tjepa::Rng a(7), b(7), c(8), s1(7, 1);
    for (int i = 0; i < 100; ++i) {
      const auto x = a();
      CHECK(x == b());
    }
    CHECK(tjepa::Rng(7)() != c());
    CHECK(tjepa::Rng(7)() != s1());
    CHECK(tjepa::Rng(7, 1)() == tjepa::Rng(7, 1)());

    tjepa::Rng saved(3);
    saved();
    auto st = saved.state();
    tjepa::Rng restored;
    restored.set_state(st);
    CHECK(restored() == saved());
    CHECK_THROWS_AS(restored.set_state({0, 0, 0, 0}), tjepa::ConfigError);
  }

  TEST_CASE("uniform below normal and truncated_normal have the right moments") {
    tjepa::Rng r(123);
    const int n = 200000;
    double s = 0, s2 = 0;
    for (int i = 0; i < n; ++i) {
      const double u = r.uniform();
      REQUIRE(u >= 0.0);
      REQUIRE(u < 1.0);
      s += u;
      s2 += u * u;
    }
    CHECK(s / n == doctest::Approx(0.5).epsilon(0.01));
    CHECK(s2 / n - (s / n) * (s / n) == doctest::Approx(1.0 / 12).epsilon(0.02));

    // below(7): chi-square against uniform, 6 degrees of freedom, 99.9% quantile 22.46.
    std::vector<int> counts(7, 0);
    for (int i = 0; i < 70000; ++i) ++counts[r.below(7)];
    double chi2 = 0;
    for (int c : counts) chi2 += (c - 10000.0) * (c - 10000.0) / 10000.0;
    CHECK(chi2 < 22.46);
    CHECK_THROWS_AS(r.below(0), tjepa::ConfigError);

    s = s2 = 0;
    double s4 = 0;
    for (int i = 0; i < n; ++i) {
      const double z = r.normal();
      s += z;
      s2 += z * z;
      s4 += z * z * z * z;
    }
    CHECK(std::abs(s / n) < 0.01);
    CHECK(s2 / n == doctest::Approx(1.0).epsilon(0.02));
    CHECK(s4 / n == doctest::Approx(3.0).epsilon(0.05));  // normal kurtosis

    for (int i = 0; i < 10000; ++i) {
      const double t = r.truncated_normal(0.0, 1.0, -0.5, 1.0);
      REQUIRE(t >= -0.5);
      REQUIRE(t <= 1.0);
    }
    CHECK_THROWS_AS(r.truncated_normal(0, 1, 1, 1), tjepa::ConfigError);
  }

  TEST_CASE("shuffle is a permutation and deterministic") {
    std::vector<int> v(50), w;
    for (int i = 0; i < 50; ++i) v[i] = i;
    w = v;
    tjepa::Rng a(1), b(1);
    a.shuffle(std::span<int>(v));
    b.shuffle(std::span<int>(w));
    CHECK(v == w);
    CHECK(std::set<int>(v.begin(), v.end()).size() == 50);
  }

  TEST_CASE("AlignedVector is 64-byte aligned") {
    tjepa::AlignedVector<float> v(37);
    CHECK(reinterpret_cast<std::uintptr_t>(v.data()) % 64 == 0);
  }

  TEST_CASE("row-major Eigen aliases map PyTorch-ordered buffers") {
    std::vector<float> buf = {1, 2, 3, 4, 5, 6};
    tjepa::ConstMatrixMap<float> m(buf.data(), 2, 3);
    CHECK(m(0, 2) == 3);
    CHECK(m(1, 0) == 4);
    tjepa::ConstStridedMatrixMap<float> head(buf.data() + 1, 2, 2, Eigen::OuterStride<>(3));
    CHECK(head(1, 1) == 6);
  }
}
