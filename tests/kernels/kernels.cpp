// nn suite, kernels: each fast kernel against its scalar reference on sizes that are not
// multiples of the SIMD width, central-difference gradient checks in double, and accumulation
// (two backward passes give exactly twice the gradient).
#include <doctest/doctest.h>

#include <array>
#include <bit>
#include <initializer_list>
#include <cmath>
#include <cstdint>
#include <limits>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include <tjepa/kernels.hpp>
#include <tjepa/tjepa.hpp>

#include "../support/gradcheck.hpp"

using namespace tjepa;
using test::gradient_error;
using test::grad_tolerance;
using test::max_scaled_diff;
using test::random_vector;

namespace {

// The operands of a GEMM test of shape M × K × N: x [M, K], W [N, K], b [N], g and r [M, N].
struct GemmOperands {
  int M, K, N;
  std::vector<float> x, W, b, g, r;
  GemmOperands(int M_, int K_, int N_, Rng& rng)
      : M(M_),
        K(K_),
        N(N_),
        x(random_vector<float>(std::size_t(M) * K, rng)),
        W(random_vector<float>(std::size_t(N) * K, rng)),
        b(random_vector<float>(std::size_t(N), rng)),
        g(random_vector<float>(std::size_t(M) * N, rng)),
        r(random_vector<float>(std::size_t(M) * N, rng)) {}
};
// Operands for each {M, K, N}, drawn in order from rng.
std::vector<GemmOperands> gemm_cases(std::initializer_list<std::array<int, 3>> shapes, Rng& rng) {
  std::vector<GemmOperands> cases;
  for (const auto& s : shapes) cases.emplace_back(s[0], s[1], s[2], rng);
  return cases;
}

template <class T>
double simd_tolerance() {
  return std::is_same_v<T, float> ? 2e-5 : 1e-12;
}

// Runs backward once and twice into zeroed gradients; checks grad₂ == 2·grad₁, exactly unless a
// tolerance is given (a scatter-add over repeated indices adds several terms into one row, so
// the second pass rounds differently).
void check_accumulates(const std::function<void(std::vector<std::vector<double>>&)>& backward,
                       std::vector<std::size_t> sizes, double tolerance = 0.0) {
  std::vector<std::vector<double>> once, twice;
  for (auto n : sizes) {
    once.emplace_back(n, 0.0);
    twice.emplace_back(n, 0.0);
  }
  backward(once);
  backward(twice);
  backward(twice);
  for (std::size_t k = 0; k < once.size(); ++k)
    for (std::size_t i = 0; i < once[k].size(); ++i)
      REQUIRE(std::abs(twice[k][i] - 2 * once[k][i]) <= tolerance * std::abs(once[k][i]));
}

}  // namespace

TEST_SUITE("kernels") {
  TEST_CASE_TEMPLATE("fast row kernels match the scalar reference on awkward sizes", T, float, double) {
    Rng rng(21);
    for (int C : {1, 3, 7, 17, 67, 197}) {
      CAPTURE(C);
      const int M = 5;
      const std::size_t n = std::size_t(M) * C;
      auto x = random_vector<T>(n, rng, 2.0), g = random_vector<T>(n, rng);
      auto w = random_vector<T>(std::size_t(C), rng), b = random_vector<T>(std::size_t(C), rng);
      // LayerNorm
      std::vector<T> y1(n), y2(n), m1(M), m2(M), r1(M), r2(M);
      kernels::ref::layer_norm_forward(y1.data(), m1.data(), r1.data(), x.data(), w.data(), b.data(), M, C, T(1e-6));
      kernels::layer_norm_forward(y2.data(), m2.data(), r2.data(), x.data(), w.data(), b.data(), M, C, T(1e-6));
      CHECK(max_scaled_diff(y2, y1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(r2, r1) < simd_tolerance<T>());
      std::vector<T> dx1(n, T(0.5)), dx2(n, T(0.5)), dw1(C, T(0)), dw2(C, T(0)), db1(C, T(0)), db2(C, T(0));
      kernels::ref::layer_norm_backward(dx1.data(), dw1.data(), db1.data(), g.data(), x.data(), w.data(), m1.data(), r1.data(), M, C);
      kernels::layer_norm_backward(dx2.data(), dw2.data(), db2.data(), g.data(), x.data(), w.data(), m1.data(), r1.data(), M, C);
      CHECK(max_scaled_diff(dx2, dx1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(dw2, dw1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(db2, db1) < simd_tolerance<T>());
      // GELU, and fc1's fused bias + GELU
      kernels::ref::gelu_forward(y1.data(), x.data(), n);
      kernels::gelu_forward(y2.data(), x.data(), n);
      CHECK(max_scaled_diff(y2, y1) < simd_tolerance<T>());
      std::fill(dx1.begin(), dx1.end(), T(0.5));
      std::fill(dx2.begin(), dx2.end(), T(0.5));
      kernels::ref::gelu_backward(dx1.data(), g.data(), x.data(), n);
      kernels::gelu_backward(dx2.data(), g.data(), x.data(), n);
      CHECK(max_scaled_diff(dx2, dx1) < simd_tolerance<T>());
      // gelu and gelu' in one pass (the MLP's backward): gelu_forward's values, and gelu' (in place
      // over the input too)
      std::vector<T> y3(n), d3(n), dref(n);
      for (std::size_t i = 0; i < n; ++i) dref[i] = detail::gelu_grad(x[i]);
      kernels::gelu_forward_grad(y3.data(), d3.data(), x.data(), n);
      CHECK(y3 == y2);
      CHECK(max_scaled_diff(d3, dref) < simd_tolerance<T>());
      std::vector<T> x3 = x;
      kernels::gelu_forward_grad(y3.data(), x3.data(), x3.data(), n);
      CHECK(y3 == y2);
      CHECK(x3 == d3);
      std::vector<T> pre = x, xb(n);
      for (int m = 0; m < M; ++m)
        for (int c = 0; c < C; ++c) xb[std::size_t(m) * C + c] = x[std::size_t(m) * C + c] + b[std::size_t(c)];
      kernels::bias_gelu_forward(y2.data(), pre.data(), b.data(), M, C);
      kernels::ref::gelu_forward(y1.data(), xb.data(), n);
      CHECK(max_scaled_diff(pre, xb) < simd_tolerance<T>());
      CHECK(max_scaled_diff(y2, y1) < simd_tolerance<T>());
      // Softmax
      kernels::ref::softmax_forward(y1.data(), x.data(), M, C);
      kernels::softmax_forward(y2.data(), x.data(), M, C);
      CHECK(max_scaled_diff(y2, y1) < simd_tolerance<T>());
      std::fill(dx1.begin(), dx1.end(), T(0.5));
      std::fill(dx2.begin(), dx2.end(), T(0.5));
      kernels::ref::softmax_backward(dx1.data(), g.data(), y1.data(), M, C);
      kernels::softmax_backward(dx2.data(), g.data(), y1.data(), M, C);
      CHECK(max_scaled_diff(dx2, dx1) < simd_tolerance<T>());
      // Linear: [M, C] → [M, C + 2]
      const int N = C + 2;
      auto W = random_vector<T>(std::size_t(N) * C, rng), bias = random_vector<T>(std::size_t(N), rng);
      std::vector<T> o1(std::size_t(M) * N), o2(o1.size());
      kernels::ref::linear_forward(o1.data(), x.data(), W.data(), bias.data(), M, C, N);
      kernels::linear_forward(o2.data(), x.data(), W.data(), bias.data(), M, C, N);
      CHECK(max_scaled_diff(o2, o1) < simd_tolerance<T>());
      auto go = random_vector<T>(o1.size(), rng);
      std::vector<T> di1(n, T(0)), di2(n, T(0)), dW1(W.size(), T(0)), dW2(W.size(), T(0)), dB1(N, T(0)), dB2(N, T(0));
      kernels::ref::linear_backward(di1.data(), dW1.data(), dB1.data(), go.data(), x.data(), W.data(), M, C, N);
      kernels::linear_backward(di2.data(), dW2.data(), dB2.data(), go.data(), x.data(), W.data(), M, C, N);
      CHECK(max_scaled_diff(di2, di1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(dW2, dW1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(dB2, dB1) < simd_tolerance<T>());
      // ... with fewer outputs than inputs (dWᵀ is computed and added transposed), onto nonzero
      // gradients, din overwritten (add_din = false) rather than added to
      const int Nf = std::max(1, C / 2);
      auto Wf = random_vector<T>(std::size_t(Nf) * C, rng), gf = random_vector<T>(std::size_t(M) * Nf, rng);
      std::vector<T> dWf1(Wf.size(), T(0.25)), dWf2(Wf.size(), T(0.25)), dif1(n, T(0)), dif2(n, T(3));
      kernels::ref::linear_backward(dif1.data(), dWf1.data(), static_cast<T*>(nullptr), gf.data(), x.data(), Wf.data(), M, C, Nf);
      kernels::linear_backward(dif2.data(), dWf2.data(), static_cast<T*>(nullptr), gf.data(), x.data(), Wf.data(), M, C, Nf,
                      false);
      CHECK(max_scaled_diff(dWf2, dWf1) < simd_tolerance<T>());
      CHECK(max_scaled_diff(dif2, dif1) < simd_tolerance<T>());
      // Drop-path: samples are the M rows
      std::vector<T> scale(M);
      kernels::drop_path_sample(scale.data(), 1, M, 0.4, 5);
      std::vector<T> a1 = g, a2 = g;
      kernels::ref::drop_path_forward(a1.data(), x.data(), scale.data(), M, std::size_t(C));
      kernels::drop_path_forward(a2.data(), x.data(), scale.data(), M, std::size_t(C));
      CHECK(a1 == a2);
    }
  }

  TEST_CASE("the GELU's float erf (Eigen's rational fit) is within 5e-7 of erf and the GELU passes NaN and infinity on") {
    constexpr std::size_t W = detail::simd_width<float>;
    double worst = 0;
    for (int i = -2000000; i < 2000000; i += int(W)) {
      alignas(64) float x[W], y[W];
      for (std::size_t j = 0; j < W; ++j) x[j] = float(i + int(j)) * 5e-6f;  // [-10, 10)
      detail::erf<float>(xsimd::load_aligned(x)).store_aligned(y);
      for (std::size_t j = 0; j < W; ++j) worst = std::max(worst, std::abs(double(y[j]) - std::erf(double(x[j]))));
    }
    MESSAGE("largest |erf error| on [-10, 10): ", worst);
    CHECK(worst < 5e-7);  // 3.7e-7 at -O2, 4.2e-7 in the -O1 sanitizer build
    const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
    alignas(64) float x[W], g[W], dg[W];
    for (std::size_t j = 0; j < W; ++j) x[j] = j % 3 == 0 ? nan : j % 3 == 1 ? inf : 1.0f;
    detail::gelu<float>(xsimd::load_aligned(x)).store_aligned(g);
    detail::gelu_grad<float>(xsimd::load_aligned(x)).store_aligned(dg);
    for (std::size_t j = 0; j < W; ++j) {
      INFO("x = ", x[j]);
      if (j % 3 == 0) {
        CHECK(std::isnan(g[j]));
        CHECK(std::isnan(dg[j]));
      } else if (j % 3 == 1) {
        CHECK(g[j] == inf);
      } else {
        CHECK(std::abs(g[j] - 0.8413447f) < 1e-6f);
      }
    }
  }

  TEST_CASE("transpose16 (the packing's 16 x 16 block transpose in registers) equals the scalar transpose") {
    // Rows at any offset and stride, a destination stride that is not 16; every element distinct.
    std::vector<float> src(16 * 37 + 5), dst(16 * 21, -1.0f);
    for (std::size_t i = 0; i < src.size(); ++i) src[i] = float(i) + 0.5f;
    detail::transpose16([&](int r) { return src.data() + 3 + r * 37; }, dst.data() + 1, 21);
    for (int c = 0; c < 16; ++c)
      for (int r = 0; r < 16; ++r) CHECK(dst[std::size_t(1 + c * 21 + r)] == src[std::size_t(3 + r * 37 + c)]);
    for (int c = 0; c < 16; ++c)
      for (int r = 16; r < 20; ++r) CHECK(dst[std::size_t(1 + c * 21 + r)] == -1.0f);  // untouched
    MESSAGE("transpose16 in registers (AVX-512): ", detail::kTranspose16Native);
  }

  TEST_CASE("a large GEMM split over threads equals the scalar reference") {
    Rng rng(22);
    const int M = 301, K = 67, N = 131;
    auto x = random_vector<double>(std::size_t(M) * K, rng), W = random_vector<double>(std::size_t(N) * K, rng);
    auto g = random_vector<double>(std::size_t(M) * N, rng);
    std::vector<double> o1(std::size_t(M) * N), o2(o1.size(), 1.0), o3(o1.size(), 1.0);
    kernels::ref::linear_forward(o1.data(), x.data(), W.data(), static_cast<const double*>(nullptr), M, K, N);
    kernels::linear_forward(o2.data(), x.data(), W.data(), static_cast<const double*>(nullptr), M, K, N);
    CHECK(max_scaled_diff(o2, o1) < 1e-12);
    kernels::linear_forward_accumulate(o3.data(), x.data(), W.data(), static_cast<const double*>(nullptr), M, K, N);
    for (auto& v : o3) v -= 1.0;
    CHECK(max_scaled_diff(o3, o1) < 1e-12);
    std::vector<double> di1(x.size(), 0.0), di2(x.size(), 0.0), dW1(W.size(), 0.0), dW2(W.size(), 0.0);
    kernels::ref::linear_backward(di1.data(), dW1.data(), static_cast<double*>(nullptr), g.data(), x.data(), W.data(), M, K, N);
    kernels::linear_backward(di2.data(), dW2.data(), static_cast<double*>(nullptr), g.data(), x.data(), W.data(), M, K, N);
    CHECK(max_scaled_diff(di2, di1) < 1e-12);
    CHECK(max_scaled_diff(dW2, dW1) < 1e-12);
  }

  TEST_CASE("the packed float GEMM and its epilogues match a double reference on awkward sizes") {
    // Depths past one KC block, column counts with a partial panel, row counts with a short row
    // block, and products large enough to be split over threads; all three transpositions.
    using detail::sgemm::Order;
    Rng rng(24);
    for (const GemmOperands& o : gemm_cases({{1, 1, 1}, {7, 3, 17}, {13, 67, 131}, {301, 300, 70}, {97, 513, 64}, {5, 19, 200}, {1100, 50, 70}}, rng)) {
      const int M = o.M, K = o.K, N = o.N;
      INFO("M ", M, ", K ", K, ", N ", N);
      const auto &x = o.x, &W = o.W, &b = o.b, &g = o.g, &c0 = o.r;
      // References in double: y = x·Wᵀ, dx = g·W, dW = gᵀ·x.
      std::vector<double> y(std::size_t(M) * N, 0.0), dx(x.size(), 0.0), dW(W.size(), 0.0);
      for (int m = 0; m < M; ++m)
        for (int n = 0; n < N; ++n)
          for (int k = 0; k < K; ++k) {
            const std::size_t mk = std::size_t(m) * K + k, nk = std::size_t(n) * K + k, mn = std::size_t(m) * N + n;
            y[mn] += double(x[mk]) * W[nk];
            dx[mk] += double(g[mn]) * W[nk];
            dW[nk] += double(g[mn]) * x[mk];
          }
      auto expect = [](const std::vector<double>& ref, auto&& f) {
        std::vector<float> r(ref.size());
        for (std::size_t i = 0; i < r.size(); ++i) r[i] = float(f(i, ref[i]));
        return r;
      };
      // C = x·Wᵀ + b, with and without GELU (in place and into a second buffer)
      std::vector<float> c(y.size()), h(y.size());
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c.data(), N,
                          {false, b.data(), nullptr});
      const auto yb = expect(y, [&](std::size_t i, double v) { return v + b[i % std::size_t(N)]; });
      CHECK(max_scaled_diff(c, yb) < 3e-5);
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c.data(), N,
                          {false, b.data(), h.data()});
      std::vector<float> hr(y.size());
      kernels::ref::gelu_forward(hr.data(), yb.data(), hr.size());
      CHECK(max_scaled_diff(c, yb) < 3e-5);
      CHECK(max_scaled_diff(h, hr) < 3e-5);
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c.data(), N,
                          {false, b.data(), c.data()});
      CHECK(max_scaled_diff(c, hr) < 3e-5);
      // C += x·Wᵀ (the residual add)
      c = c0;
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c.data(), N, {true});
      CHECK(max_scaled_diff(c, expect(y, [&](std::size_t i, double v) { return v + c0[i]; })) < 3e-5);
      // dx += g·W (B row-major), dW += gᵀ·x (A column-major), onto nonzero starting values
      std::vector<float> dx2(x.size(), 0.5f), dW2(W.size(), -0.25f);
      detail::sgemm::gemm(M, K, N, g.data(), N, Order::row_major, W.data(), K, Order::row_major, dx2.data(), K, {true});
      detail::sgemm::gemm(N, K, M, g.data(), N, Order::col_major, x.data(), K, Order::row_major, dW2.data(), K, {true});
      CHECK(max_scaled_diff(dx2, expect(dx, [](std::size_t, double v) { return v + 0.5; })) < 3e-5);
      CHECK(max_scaled_diff(dW2, expect(dW, [](std::size_t, double v) { return v - 0.25; })) < 3e-5);
      // dpre = (g·W) ⊙ s, overwritten: the MLP's backward through GELU (s = gelu'(pre), here any values)
      std::vector<float> dpre(x.size(), 7.0f);
      const auto s = random_vector<float>(x.size(), rng);
      kernels::linear_backward_input_scaled(dpre.data(), g.data(), W.data(), s.data(), M, K, N);
      CHECK(max_scaled_diff(dpre, expect(dx, [&](std::size_t i, double v) { return v * s[i]; })) < 3e-5);
      // C = r + x·Wᵀ + b from a separate residual r (the block's residual add without a copy)
      std::vector<float> cr(y.size(), -1.0f);
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, cr.data(), N,
                          {false, b.data(), nullptr, nullptr, c0.data()});
      CHECK(max_scaled_diff(cr, expect(y, [&](std::size_t i, double v) { return v + b[i % std::size_t(N)] + c0[i]; })) <
            3e-5);
    }
  }

  TEST_CASE_TEMPLATE("the row-tiled inference MLP equals fc1 → GELU → fc2 on whole matrices", T, float, double) {
    // Row counts below, at and across tile boundaries, a hidden width past one depth block of the
    // float GEMM, an output with a partial panel, and a product large enough to be split over
    // threads; with a separate residual, in place (residual = out), and without one.
    Rng rng(31);
    const int shapes[][4] = {{1, 5, 7, 3}, {47, 13, 40, 9}, {kernels::mlp_tile_rows, 24, 96, 24}, {49, 70, 300, 33},
                             {200, 70, 300, 96}};
    for (const auto& sh : shapes) {
      const int M = sh[0], K = sh[1], H = sh[2], N = sh[3];
      CAPTURE(M);
      CAPTURE(H);
      auto x = random_vector<T>(std::size_t(M) * K, rng), w1 = random_vector<T>(std::size_t(H) * K, rng, 0.3);
      auto b1 = random_vector<T>(std::size_t(H), rng), w2 = random_vector<T>(std::size_t(N) * H, rng, 0.1);
      auto b2 = random_vector<T>(std::size_t(N), rng), r = random_vector<T>(std::size_t(M) * N, rng);
      // The untiled fast path, and the scalar reference.
      std::vector<T> h(std::size_t(M) * H), fast(r.size()), hr(h.size()), want(r.size());
      kernels::linear_bias_gelu_forward(h.data(), h.data(), x.data(), w1.data(), b1.data(), M, K, H);
      kernels::linear_forward_residual(fast.data(), r.data(), h.data(), w2.data(), b2.data(), M, H, N);
      kernels::ref::linear_forward(hr.data(), x.data(), w1.data(), b1.data(), M, K, H);
      kernels::ref::gelu_forward(hr.data(), hr.data(), hr.size());
      kernels::ref::linear_forward(want.data(), hr.data(), w2.data(), b2.data(), M, H, N);
      AlignedVector<T> scratch;
      std::vector<T> y(r.size(), T(7));
      kernels::mlp_forward_tiled(y.data(), static_cast<const T*>(nullptr), x.data(), w1.data(), b1.data(), w2.data(), b2.data(),
                        M, K, H, N, scratch);
      CHECK(max_scaled_diff(y, want) < 10 * simd_tolerance<T>());
      for (std::size_t i = 0; i < want.size(); ++i) want[i] += r[i];
      kernels::mlp_forward_tiled(y.data(), r.data(), x.data(), w1.data(), b1.data(), w2.data(), b2.data(), M, K, H, N, scratch);
      CHECK(max_scaled_diff(y, want) < 10 * simd_tolerance<T>());
      // Each row goes through the same micro-kernels in the same order as untiled: float is
      // bit-identical, so inference and the cached training forward agree exactly.
      if constexpr (std::is_same_v<T, float>) CHECK(y == fast);
      std::vector<T> z = r;
      kernels::mlp_forward_tiled(z.data(), z.data(), x.data(), w1.data(), b1.data(), w2.data(), b2.data(), M, K, H, N, scratch);
      CHECK(z == y);
      // Weights packed once (kernels::PackedWeights; float only) give the same values as packing per call.
      kernels::PackedWeights<T> cache;
      const kernels::WeightPlan p1 = cache.get(w1.data(), H, K);
      const kernels::WeightPlan p2 = cache.get(w2.data(), N, H);
      CHECK(cache.get(w1.data(), H, K).packed == p1.packed);
      CHECK(cache.size() == (std::is_same_v<T, float> ? 2u : 0u));
      CHECK((p1.packed == nullptr) == std::is_same_v<T, double>);
      z = r;
      kernels::mlp_forward_tiled(z.data(), z.data(), x.data(), w1.data(), b1.data(), w2.data(), b2.data(), M, K, H, N, scratch,
                        p1, p2);
      CHECK(z == y);
      std::vector<T> h2(h.size()), y2(r.size());
      kernels::linear_forward(h2.data(), x.data(), w1.data(), b1.data(), M, K, H);
      kernels::linear_forward(hr.data(), x.data(), w1.data(), b1.data(), M, K, H, p1);
      CHECK(hr == h2);
      kernels::linear_forward_residual(y2.data(), r.data(), h.data(), w2.data(), b2.data(), M, H, N, p2);
      CHECK(y2 == fast);
      if constexpr (std::is_same_v<T, float>) {
        // bf16 products: tiled, untiled and from weights packed once agree bit for bit; close
        // to fp32 (a bf16 operand carries 8 significant bits).
        const kernels::WeightPlan bf16{Precision::bf16};
        std::vector<T> hb(h.size()), yb(r.size());
        kernels::linear_bias_gelu_forward(hb.data(), hb.data(), x.data(), w1.data(), b1.data(), M, K, H, bf16);
        kernels::linear_forward_residual(yb.data(), r.data(), hb.data(), w2.data(), b2.data(), M, H, N, bf16);
        CHECK(max_scaled_diff(yb, fast) < 2e-2);
        if (detail::bgemm::native) CHECK(yb != fast);
        kernels::mlp_forward_tiled(z.data(), r.data(), x.data(), w1.data(), b1.data(), w2.data(), b2.data(), M, K, H, N,
                                   scratch, bf16, bf16);
        CHECK(z == yb);
        kernels::PackedWeights<T> bcache;
        bcache.precision = Precision::bf16;
        const kernels::WeightPlan q1 = bcache.get(w1.data(), H, K), q2 = bcache.get(w2.data(), N, H);
        CHECK(q1.precision == detail::bgemm::resolve(Precision::bf16));
        kernels::mlp_forward_tiled(z.data(), r.data(), x.data(), w1.data(), b1.data(), w2.data(), b2.data(), M, K, H, N,
                                   scratch, q1, q2);
        CHECK(z == yb);
      }
    }
  }

  TEST_CASE("bf16 conversion: round to nearest even / denormals to zero / NaN and overflow as vcvtneps2bf16") {
    using detail::bgemm::to_bf16;
    CHECK(to_bf16(1.0f) == 0x3f80);
    CHECK(to_bf16(1.0f + 0x1p-8f) == 0x3f80);        // a tie rounds to the even neighbour
    CHECK(to_bf16(1.0f + 3 * 0x1p-8f) == 0x3f82);    // a tie rounds up to the even one
    CHECK(to_bf16(1.0f + 0x1p-8f + 0x1p-20f) == 0x3f81);
    CHECK(to_bf16(-2.5f) == 0xc020);
    CHECK(to_bf16(0x1p-130f) == 0x0000);             // denormal → +0
    CHECK(to_bf16(-0x1p-140f) == 0x8000);            // → -0
    CHECK(to_bf16(3.4e38f) == 0x7f80);               // rounds past the largest bf16 → inf
    CHECK(to_bf16(-std::numeric_limits<float>::infinity()) == 0xff80);
    const std::uint16_t nan = to_bf16(std::numeric_limits<float>::quiet_NaN());
    CHECK(std::isnan(detail::bgemm::from_bf16(nan)));
    CHECK(std::isnan(detail::bgemm::from_bf16(to_bf16(std::bit_cast<float>(0x7f800001u)))));  // signalling stays NaN
    CHECK(detail::bgemm::round_bf16(0.1f) == 0.10009765625f);
#if TJEPA_BF16_NATIVE
    // The vector conversion of A's rows (vcvtne2ps2bf16) gives the scalar bits, tails included.
    Rng rng(5);
    std::vector<float> row = random_vector<float>(77, rng, 3.0);
    row[3] = 0x1p-131f;
    row[4] = 1.0f + 0x1p-8f;
    row[5] = -std::numeric_limits<float>::infinity();
    alignas(64) std::uint32_t packed[40] = {};
    detail::bgemm::pack_a(packed, 1, 77, row.data(), 77, 39);
    for (int q = 0; q < 39; ++q)
      CHECK(packed[q] == detail::bgemm::pair(row[std::size_t(2 * q)], 2 * q + 1 < 77 ? row[std::size_t(2 * q + 1)] : 0.0f));
    // Column-major A ([kc/2][ld] pairs, 16 rows per conversion: 37 rows are two whole conversions
    // and a partial one, zero up to ld), and B's panels in both orders, against the scalar packing.
    using detail::sgemm::Order;
    namespace bg = detail::bgemm;
    const int depth = 37, cols = 83;  // odd depth, a partial second panel
    const std::vector<float> m = random_vector<float>(std::size_t(depth) * cols, rng);
    AlignedVector<std::uint32_t> acol(19 * bg::CH, 7u);
    bg::pack_a_cols(acol.data(), bg::CH, 37, depth, m.data(), cols);  // a(i, k) = m[k·cols + i], rows 0..36
    for (int q = 0; q < 19; ++q)
      for (int i = 0; i < bg::CH; ++i)
        CHECK(acol[std::size_t(q * bg::CH + i)] ==
              (i < 37 ? bg::pair(m[std::size_t(2 * q) * cols + i],
                                 2 * q + 1 < depth ? m[std::size_t(2 * q + 1) * cols + i] : 0.0f)
                      : 0u));
    for (const Order order : {Order::row_major, Order::col_major}) {
      const std::ptrdiff_t ldb = order == Order::row_major ? cols : depth;
      AlignedVector<std::uint32_t> fast(bg::packed_size(cols, depth), 7u), ref(fast.size(), 9u);
      for (int p = 0; p < 2; ++p) {
        bg::pack_panel(fast.data(), m.data(), ldb, order, depth, cols, p, 0, 19);
        bg::pack_panel_ref(ref.data(), m.data(), ldb, order, depth, cols, p, 0, 19);
      }
      CHECK(fast == ref);
    }
#endif
  }

  TEST_CASE("a long-depth product (the weight gradients) runs in fixed depth slabs: the same bits on 1 and 2 threads") {
    // dW [N, K] += gᵀ·x over M rows: M ≥ 2·depth_slab splits the depth into slabs of depth_slab
    // (the last one partial here), each slab's product a partial, summed in slab order. The slabs
    // do not depend on the thread count, so neither do the bits; fc2's N < K path (the product
    // transposed, then added) and bf16 likewise.
    using detail::sgemm::Order;
    namespace sg = detail::sgemm;
    Rng rng(43);
    const int M = 2 * sg::depth_slab + sg::depth_slab / 2 + 37;
    for (const GemmOperands& o : gemm_cases({{M, 70, 131}, {M, 130, 40}}, rng)) {
      const int K = o.K, N = o.N;
      INFO("M ", M, ", K ", K, ", N ", N);
      CHECK(sg::split_depth(N, K, M, {true}));
      std::vector<double> dW(o.W.size(), 0.0);
      for (int m = 0; m < M; ++m)
        for (int n = 0; n < N; ++n)
          for (int k = 0; k < K; ++k) dW[std::size_t(n) * K + k] += double(o.g[std::size_t(m) * N + n]) * o.x[std::size_t(m) * K + k];
      for (const auto& engine_case : {std::pair{Precision::fp32, false}, std::pair{Precision::bf16, false},
                                      std::pair{Precision::bf16, amx_available()}}) {
        const Precision p = engine_case.first;
        const bool amx = engine_case.second;
        INFO(precision_name(p), ", AMX ", amx);
        const test::Amx engine(amx);
        std::vector<std::vector<float>> runs;
        for (const int threads : {1, 2}) {
          const test::Threads scope(threads);
          std::vector<float> dW2(o.W.size(), -0.25f), db(std::size_t(N), 0.0f);
          kernels::linear_backward(static_cast<float*>(nullptr), dW2.data(), db.data(), o.g.data(), o.x.data(), o.W.data(),
                                   M, K, N, true, p);
          runs.push_back(dW2);
        }
        CHECK(runs[0] == runs[1]);
        std::vector<float> want(dW.size());
        for (std::size_t i = 0; i < dW.size(); ++i) want[i] = float(dW[i] - 0.25);
        CHECK(max_scaled_diff(runs[0], want) < (effective_precision(p) == Precision::bf16 ? 2e-2 : 3e-5));
      }
    }
    CHECK(sg::split_depth(64, 64, 4 * sg::depth_slab, {}));
    CHECK_FALSE(sg::split_depth(64, 64, 2 * sg::depth_slab - 1, {true}));  // one slab and a bit: one pass
    const std::vector<float> bias(64, 0.0f);
    CHECK_FALSE(sg::split_depth(64, 64, 4 * sg::depth_slab, {false, bias.data()}));  // an epilogue: one pass
  }

  TEST_CASE("the bf16 GEMM and its epilogues match a reference on bf16-rounded operands (awkward sizes)") {
    // Products of bf16-rounded operands are exact in fp32; only the order of the fp32 sums
    // differs from the reference's double sum, so |C - ref| stays within a few ulp of Σ|a·b|.
    // Depths past one KC block (the forward's K = 1025; the weight gradient's, M = 1100) and odd,
    // partial panels, short row blocks, column-major A (the weight gradient's, N rows) in chunks of
    // CH = 48 rows, whole and partial (N = 131, 200), thread splits, all transpositions. Without
    // AVX512-BF16 the same calls are the float GEMM, bit for bit.
    using detail::sgemm::Order;
    namespace bg = detail::bgemm;
    CHECK(bg::resolve(Precision::bf16, false) == Precision::fp32);
    CHECK(bg::resolve(Precision::bf16, true) == Precision::bf16);
    CHECK(bg::resolve(Precision::fp32, true) == Precision::fp32);
    Rng rng(41);
    for (const GemmOperands& o : gemm_cases({{1, 1, 1}, {7, 3, 17}, {13, 67, 131}, {301, 192, 70}, {97, 1025, 64}, {5, 19, 200}, {1100, 50, 70}}, rng)) {
      const int M = o.M, K = o.K, N = o.N;
      INFO("M ", M, ", K ", K, ", N ", N);
      const auto &x = o.x, &W = o.W, &b = o.b, &g = o.g, &r = o.r;
      // Fallback: the float GEMM itself.
      std::vector<float> c1(r.size()), c2(r.size());
      bg::gemm<false>(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c1.data(), N, {false, b.data()});
      detail::sgemm::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c2.data(), N,
                          {false, b.data()});
      CHECK(c1 == c2);
      if constexpr (bg::native) {
        // reference: y = bf16(x)·bf16(W)ᵀ, dx = bf16(g)·bf16(W), dW = bf16(g)ᵀ·bf16(x), and Σ|·|
        std::vector<double> y(r.size(), 0.0), ya(r.size(), 0.0), dx(x.size(), 0.0), dxa(x.size(), 0.0),
            dW(W.size(), 0.0), dWa(W.size(), 0.0);
        for (int m = 0; m < M; ++m)
          for (int n = 0; n < N; ++n)
            for (int k = 0; k < K; ++k) {
              const std::size_t mk = std::size_t(m) * K + k, nk = std::size_t(n) * K + k, mn = std::size_t(m) * N + n;
              const double xv = bg::round_bf16(x[mk]), wv = bg::round_bf16(W[nk]), gv = bg::round_bf16(g[mn]);
              y[mn] += xv * wv, ya[mn] += std::abs(xv * wv);
              dx[mk] += gv * wv, dxa[mk] += std::abs(gv * wv);
              dW[nk] += gv * xv, dWa[nk] += std::abs(gv * xv);
            }
        // max |c - want| / (Σ|a·b| + |added terms|)
        auto err = [](const std::vector<float>& c, const std::vector<double>& want, const std::vector<double>& mag) {
          double e = 0;
          for (std::size_t i = 0; i < c.size(); ++i) e = std::max(e, std::abs(c[i] - want[i]) / (mag[i] + 1e-30));
          return e;
        };
        const double tol = 1e-6;
        // On vdpbf16ps, and on AMX tiles where the machine has them.
        for (const bool amx : test::amx_modes()) {
          INFO("AMX ", amx);
          const test::Amx engine(amx);
          // C = r + x·Wᵀ + b; then C = x·Wᵀ + b with GELU into h
          std::vector<double> want(y.size()), mag(y.size());
          for (std::size_t i = 0; i < y.size(); ++i) {
            want[i] = y[i] + b[i % std::size_t(N)] + r[i];
            mag[i] = ya[i] + std::abs(b[i % std::size_t(N)]) + std::abs(r[i]);
          }
          bg::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c1.data(), N,
                   {false, b.data(), nullptr, nullptr, r.data()});
          CHECK(err(c1, want, mag) < tol);
          std::vector<float> h(y.size());
          bg::gemm(M, N, K, x.data(), K, Order::row_major, W.data(), K, Order::col_major, c1.data(), N,
                   {false, b.data(), h.data()});
          for (std::size_t i = 0; i < y.size(); ++i) {
            want[i] = y[i] + b[i % std::size_t(N)];
            mag[i] = ya[i] + std::abs(b[i % std::size_t(N)]);
          }
          CHECK(err(c1, want, mag) < tol);
          std::vector<float> hr(c1.size());
          kernels::ref::gelu_forward(hr.data(), c1.data(), hr.size());
          CHECK(max_scaled_diff(h, hr) < 1e-6);
          // The weight packed once (gemm_packed) gives the per-call product bit for bit.
          AlignedVector<std::uint32_t> packed(bg::packed_size(N, K));
          bg::pack(packed.data(), W.data(), K, Order::col_major, K, N);
          bg::gemm_packed(M, N, K, x.data(), K, Order::row_major, packed.data(), c2.data(), N, {false, b.data(), h.data()});
          CHECK(c2 == c1);
          // dx += g·W (B row-major), dW += gᵀ·x (A column-major), onto starting values
          std::vector<float> dx2(x.size(), 0.5f), dW2(W.size(), -0.25f);
          bg::gemm(M, K, N, g.data(), N, Order::row_major, W.data(), K, Order::row_major, dx2.data(), K, {true});
          bg::gemm(N, K, M, g.data(), N, Order::col_major, x.data(), K, Order::row_major, dW2.data(), K, {true});
          std::vector<double> dx_want = dx, dx_mag = dxa, dW_want = dW, dW_mag = dWa;
          for (auto& v : dx_want) v += 0.5;
          for (auto& v : dx_mag) v += 0.5;
          for (auto& v : dW_want) v -= 0.25;
          for (auto& v : dW_mag) v += 0.25;
          CHECK(err(dx2, dx_want, dx_mag) < tol);
          CHECK(err(dW2, dW_want, dW_mag) < tol);
        }
      }
    }
  }

  TEST_CASE("kernel gradients match central differences (double)") {
    Rng rng(23);
    const int M = 4, C = 9, N = 6;
    const std::size_t n = std::size_t(M) * C;
    auto x = random_vector<double>(n, rng);
    SUBCASE("linear") {
      auto W = random_vector<double>(std::size_t(N) * C, rng), b = random_vector<double>(std::size_t(N), rng);
      auto w = random_vector<double>(std::size_t(M) * N, rng);
      std::vector<double> y(w.size());
      auto loss = [&] {
        kernels::linear_forward(y.data(), x.data(), W.data(), b.data(), M, C, N);
        return test::dot(w.data(), y.data(), y.size());
      };
      auto bwd = [&](std::vector<std::vector<double>>& gr) {
        kernels::linear_backward(gr[0].data(), gr[1].data(), gr[2].data(), w.data(), x.data(), W.data(), M, C, N);
      };
      std::vector<std::vector<double>> gr{std::vector<double>(n), std::vector<double>(W.size()), std::vector<double>(b.size())};
      bwd(gr);
      CHECK(gradient_error(x.data(), gr[0].data(), n, loss) < grad_tolerance);
      CHECK(gradient_error(W.data(), gr[1].data(), W.size(), loss) < grad_tolerance);
      CHECK(gradient_error(b.data(), gr[2].data(), b.size(), loss) < grad_tolerance);
      check_accumulates(bwd, {n, W.size(), b.size()});
    }
    SUBCASE("layer_norm") {
      auto g = random_vector<double>(std::size_t(C), rng), b = random_vector<double>(std::size_t(C), rng);
      auto w = random_vector<double>(n, rng);
      std::vector<double> y(n), mean(M), rstd(M);
      auto loss = [&] {
        kernels::layer_norm_forward(y.data(), mean.data(), rstd.data(), x.data(), g.data(), b.data(), M, C);
        return test::dot(w.data(), y.data(), n);
      };
      loss();
      auto bwd = [&](std::vector<std::vector<double>>& gr) {
        kernels::layer_norm_backward(gr[0].data(), gr[1].data(), gr[2].data(), w.data(), x.data(), g.data(), mean.data(),
                            rstd.data(), M, C);
      };
      std::vector<std::vector<double>> gr{std::vector<double>(n), std::vector<double>(C), std::vector<double>(C)};
      bwd(gr);
      CHECK(gradient_error(x.data(), gr[0].data(), n, loss) < grad_tolerance);
      CHECK(gradient_error(g.data(), gr[1].data(), g.size(), loss) < grad_tolerance);
      CHECK(gradient_error(b.data(), gr[2].data(), b.size(), loss) < grad_tolerance);
      check_accumulates(bwd, {n, std::size_t(C), std::size_t(C)});
    }
    SUBCASE("gelu") {
      auto w = random_vector<double>(n, rng);
      std::vector<double> y(n);
      auto loss = [&] {
        kernels::gelu_forward(y.data(), x.data(), n);
        return test::dot(w.data(), y.data(), n);
      };
      auto bwd = [&](std::vector<std::vector<double>>& gr) { kernels::gelu_backward(gr[0].data(), w.data(), x.data(), n); };
      std::vector<std::vector<double>> gr{std::vector<double>(n)};
      bwd(gr);
      CHECK(gradient_error(x.data(), gr[0].data(), n, loss) < grad_tolerance);
      check_accumulates(bwd, {n});
    }
    SUBCASE("softmax") {
      auto w = random_vector<double>(n, rng);
      std::vector<double> y(n);
      auto loss = [&] {
        kernels::softmax_forward(y.data(), x.data(), M, C);
        return test::dot(w.data(), y.data(), n);
      };
      loss();
      auto bwd = [&](std::vector<std::vector<double>>& gr) { kernels::softmax_backward(gr[0].data(), w.data(), y.data(), M, C); };
      std::vector<std::vector<double>> gr{std::vector<double>(n)};
      bwd(gr);
      CHECK(gradient_error(x.data(), gr[0].data(), n, loss) < grad_tolerance);
      check_accumulates(bwd, {n});
    }
    SUBCASE("drop_path") {
      std::vector<double> scale(M);
      // The first seed whose draws keep some samples and drop others.
      for (std::uint64_t seed = 0; seed < 64; ++seed) {
        kernels::drop_path_sample(scale.data(), 1, M, 0.5, seed);
        if (std::count(scale.begin(), scale.end(), 0.0) % M != 0) break;
      }
      CHECK(std::count(scale.begin(), scale.end(), 0.0) > 0);
      CHECK(std::count(scale.begin(), scale.end(), 2.0) > 0);
      auto base = random_vector<double>(n, rng), w = random_vector<double>(n, rng);
      std::vector<double> y(n);
      auto loss = [&] {
        y = base;
        kernels::drop_path_forward(y.data(), x.data(), scale.data(), M, std::size_t(C));
        return test::dot(w.data(), y.data(), n);
      };
      auto bwd = [&](std::vector<std::vector<double>>& gr) {
        kernels::drop_path_backward(gr[0].data(), w.data(), scale.data(), M, std::size_t(C));
      };
      std::vector<std::vector<double>> gr{std::vector<double>(n)};
      bwd(gr);
      CHECK(gradient_error(x.data(), gr[0].data(), n, loss) < grad_tolerance);
      check_accumulates(bwd, {n});
    }
    SUBCASE("gather and scatter-add, batched source and shared table") {
      const int B = 2, K = 5, Nsrc = 4;
      const std::vector<int> idx{0, 3, 3, 1, 2, 2, 2, 0, 1, 3};
      for (std::size_t batch : {std::size_t(Nsrc) * C, std::size_t(0)}) {
        auto src = random_vector<double>(batch ? B * batch : std::size_t(Nsrc) * C, rng);
        auto base = random_vector<double>(std::size_t(B) * K * C, rng), w = random_vector<double>(base.size(), rng);
        std::vector<double> y(base.size());
        auto loss = [&] {
          y = base;
          kernels::gather_add_rows(y.data(), src.data(), batch, idx.data(), B, K, C);
          double l = test::dot(w.data(), y.data(), y.size());
          kernels::gather_rows(y.data(), src.data(), batch, idx.data(), B, K, C);
          return l + test::dot(w.data(), y.data(), y.size());
        };
        auto bwd = [&](std::vector<std::vector<double>>& gr) {
          kernels::scatter_add_rows(gr[0].data(), batch, w.data(), idx.data(), B, K, C);
          kernels::scatter_add_rows(gr[0].data(), batch, w.data(), idx.data(), B, K, C);
        };
        std::vector<std::vector<double>> gr{std::vector<double>(src.size())};
        bwd(gr);
        CHECK(gradient_error(src.data(), gr[0].data(), src.size(), loss) < grad_tolerance);
        check_accumulates(bwd, {src.size()}, 1e-15);
      }
    }
  }

  TEST_CASE("drop-path draws are per sample: independent of the batch they sit in") {
    std::vector<float> a(3 * 8), b(3 * 5);
    kernels::drop_path_sample(a.data(), 3, 8, 0.3, 77);
    kernels::drop_path_sample(b.data(), 3, 5, 0.3, 77);
    for (int s = 0; s < 3; ++s)
      for (int i = 0; i < 5; ++i) CHECK(a[std::size_t(s) * 8 + i] == b[std::size_t(s) * 5 + i]);
    // A shard [5, 8) of the batch, drawn alone with its offset, equals the batch's samples 5..7.
    std::vector<float> c(3 * 3);
    kernels::drop_path_sample(c.data(), 3, 3, 0.3, 77, 5);
    for (int s = 0; s < 3; ++s)
      for (int i = 0; i < 3; ++i) CHECK(c[std::size_t(s) * 3 + i] == a[std::size_t(s) * 8 + 5 + i]);
    CHECK_THROWS_AS(kernels::drop_path_sample(a.data(), 1, 2, 1.0, 0), ConfigError);
  }
}
