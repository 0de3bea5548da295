// The convolutional kernels: the NHWC conv2d, ReLU and pooling kernels (kernels/conv2d.hpp)
// against their scalar references and hand-computed values, PyTorch's max-pool tie and NaN rules
// and adaptive bins, central-difference gradient checks in double.
#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include <tjepa/kernels/conv2d.hpp>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

template <class T>
bool cnn_bitwise_equal(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

// A convolution's geometry and the im2col chunk bound it runs with.
struct CnnConvCase {
  kernels::Conv2dShape shape;
  std::size_t max_col = std::size_t(1) << 22;
};

std::vector<CnnConvCase> cnn_conv_cases() {
  return {
      {{3, 13, 11, 3, 5, 11, 4, 2}},           // AlexNet's conv₀ geometry
      {{2, 9, 7, 10, 7, 5, 1, 2}},             // conv₁'s: k 5, pad 2
      {{3, 6, 5, 13, 9, 3, 1, 1}},             // conv₂..₄'s: k 3, pad 1, C not a multiple of 8
      {{3, 6, 5, 13, 9, 3, 1, 1}, 500},        // 4 rows per chunk: chunks straddle samples
      {{2, 7, 8, 5, 4, 3, 2, 0}, 200},         // stride 2, no padding, small chunks
      {{3, 5, 4, 6, 3, 1, 1, 0}},              // 1 × 1: the input is the im2col matrix
      {{2, 3, 3, 2, 3, 3, 1, 3}},              // padding ≥ kernel: windows wholly outside
      {{1, 16, 16, 17, 33, 3, 2, 1}},          // O over two GEMM panels
  };
}

}  // namespace

TEST_SUITE("kernels") {
  TEST_CASE_TEMPLATE("conv2d fast path matches the scalar reference on awkward shapes", T, float, double) {
    const double tol = std::is_same_v<T, float> ? 1e-4 : 1e-12;
    Rng rng(11);
    for (const CnnConvCase& cc : cnn_conv_cases()) {
      const kernels::Conv2dShape& s = cc.shape;
      INFO("B ", s.B, " H ", s.H, " W ", s.W, " C ", s.C, " O ", s.O, " k ", s.k, " stride ", s.stride, " pad ",
           s.pad, " max_col ", cc.max_col);
      const auto x = test::random_vector<T>(s.in_size(), rng);
      const auto w = test::random_vector<T>(s.weight_size(), rng, 0.3);
      const auto b = test::random_vector<T>(std::size_t(s.O), rng);
      const auto g = test::random_vector<T>(s.out_size(), rng);
      kernels::Conv2dScratch<T> scratch;
      scratch.max_col = cc.max_col;
      std::vector<T> y(s.out_size()), y_ref(s.out_size());
      kernels::conv2d_forward(y.data(), x.data(), w.data(), b.data(), s, scratch);
      kernels::ref::conv2d_forward(y_ref.data(), x.data(), w.data(), b.data(), s);
      CHECK(test::max_scaled_diff(y, y_ref) < tol);
      std::vector<T> y0(s.out_size());  // without a bias
      kernels::conv2d_forward(y0.data(), x.data(), w.data(), static_cast<const T*>(nullptr), s, scratch);
      kernels::ref::conv2d_forward(y_ref.data(), x.data(), w.data(), static_cast<const T*>(nullptr), s);
      CHECK(test::max_scaled_diff(y0, y_ref) < tol);

      // Backward adds: start every gradient from the same random values.
      const auto dx0 = test::random_vector<T>(s.in_size(), rng), dw0 = test::random_vector<T>(s.weight_size(), rng);
      const auto db0 = test::random_vector<T>(std::size_t(s.O), rng);
      auto dx = dx0, dw = dw0, db = db0, dx_ref = dx0, dw_ref = dw0, db_ref = db0;
      kernels::conv2d_backward(dx.data(), dw.data(), db.data(), g.data(), x.data(), w.data(), s, scratch);
      kernels::ref::conv2d_backward(dx_ref.data(), dw_ref.data(), db_ref.data(), g.data(), x.data(), w.data(), s);
      CHECK(test::max_scaled_diff(dx, dx_ref) < tol);
      CHECK(test::max_scaled_diff(dw, dw_ref) < tol);
      CHECK(test::max_scaled_diff(db, db_ref) < tol);
      // Each gradient alone (the others nullptr) gives the same values.
      auto dx1 = dx0, dw1 = dw0, db1 = db0;
      kernels::conv2d_backward(dx1.data(), static_cast<T*>(nullptr), static_cast<T*>(nullptr), g.data(), x.data(),
                               w.data(), s, scratch);
      kernels::conv2d_backward(static_cast<T*>(nullptr), dw1.data(), static_cast<T*>(nullptr), g.data(), x.data(),
                               w.data(), s, scratch);
      kernels::conv2d_backward(static_cast<T*>(nullptr), static_cast<T*>(nullptr), db1.data(), g.data(), x.data(),
                               w.data(), s, scratch);
      CHECK(test::max_scaled_diff(dx1, dx_ref) < tol);
      CHECK(test::max_scaled_diff(dw1, dw_ref) < tol);
      CHECK(test::max_scaled_diff(db1, db_ref) < tol);
    }
  }

  TEST_CASE("conv2d on hand-computed 2 x 2 examples") {
    kernels::Conv2dScratch<double> scratch;
    // One channel: in [[1, 2], [3, 4]], w [[1, 0], [0, −1]], bias 0.5.
    const std::vector<double> x{1, 2, 3, 4}, w{1, 0, 0, -1}, b{0.5};
    std::vector<double> y(1);
    kernels::conv2d_forward(y.data(), x.data(), w.data(), b.data(), {1, 2, 2, 1, 1, 2, 1, 0}, scratch);
    CHECK(y[0] == -2.5);  // 1·1 + 4·(−1) + 0.5
    // With padding 1 the window slides over zeros: out[i][j] = in[i−1][j−1] − in[i][j] + 0.5.
    y.assign(9, 0.0);
    kernels::conv2d_forward(y.data(), x.data(), w.data(), b.data(), {1, 2, 2, 1, 1, 2, 1, 1}, scratch);
    const std::vector<double> padded{-0.5, -1.5, 0.5, -2.5, -2.5, 2.5, 0.5, 3.5, 4.5};
    CHECK(y == padded);

    // Two channels and two outputs: NHWC input against PyTorch's [O, C, kh, kw] weight.
    // Channel 0 is [[1, 2], [3, 4]], channel 1 [[10, 20], [30, 40]].
    const std::vector<double> x2{1, 10, 2, 20, 3, 30, 4, 40};
    const std::vector<double> w2{/* o0 c0 */ 1, 0, 0, 0, /* o0 c1 */ 0, 0, 0, 1,  /* o1 c0 */ 0, 1, 0, 0, /* o1 c1 */ 0, 0, 1, 0};
    const kernels::Conv2dShape s2{1, 2, 2, 2, 2, 2, 1, 0};
    std::vector<double> y2(2);
    kernels::conv2d_forward(y2.data(), x2.data(), w2.data(), static_cast<const double*>(nullptr), s2, scratch);
    CHECK(y2 == std::vector<double>{41, 32});  // o0: in[0][0][0] + in[1][1][1]; o1: in[0][1][0] + in[1][0][1]
    // Backward of output 0 alone: dw[0] is the input patch in [C, kh, kw] order, din is w[0] in NHWC.
    std::vector<double> dx(8, 0.0), dw(16, 0.0), db(2, 0.0);
    const std::vector<double> g{1, 0};
    kernels::conv2d_backward(dx.data(), dw.data(), db.data(), g.data(), x2.data(), w2.data(), s2, scratch);
    CHECK(dw == std::vector<double>{1, 2, 3, 4, 10, 20, 30, 40, 0, 0, 0, 0, 0, 0, 0, 0});
    CHECK(dx == std::vector<double>{1, 0, 0, 0, 0, 0, 0, 1});
    CHECK(db == std::vector<double>{1, 0});
  }

  TEST_CASE("conv2d / relu / pooling gradients match central differences (double)") {
    test::SingleThread one;
    Rng rng(21);
    SUBCASE("conv2d: input / weight / bias") {
      for (const kernels::Conv2dShape& s :
           {kernels::Conv2dShape{2, 9, 8, 3, 4, 5, 2, 2}, kernels::Conv2dShape{1, 6, 7, 5, 3, 3, 1, 1},
            kernels::Conv2dShape{2, 13, 13, 2, 3, 11, 4, 2}}) {
        INFO("k ", s.k, " stride ", s.stride, " pad ", s.pad);
        auto x = test::random_vector<double>(s.in_size(), rng), w = test::random_vector<double>(s.weight_size(), rng, 0.3);
        auto b = test::random_vector<double>(std::size_t(s.O), rng);
        const auto r = test::random_vector<double>(s.out_size(), rng);
        kernels::Conv2dScratch<double> scratch;
        scratch.max_col = 300;  // several chunks
        std::vector<double> y(s.out_size());
        auto loss = [&] {
          kernels::conv2d_forward(y.data(), x.data(), w.data(), b.data(), s, scratch);
          return test::dot(y.data(), r.data(), y.size());
        };
        std::vector<double> dx(x.size(), 0.0), dw(w.size(), 0.0), db(b.size(), 0.0);
        kernels::conv2d_backward(dx.data(), dw.data(), db.data(), r.data(), x.data(), w.data(), s, scratch);
        CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss) < test::grad_tolerance);
        CHECK(test::gradient_error(w.data(), dw.data(), w.size(), loss) < test::grad_tolerance);
        CHECK(test::gradient_error(b.data(), db.data(), b.size(), loss) < test::grad_tolerance);
      }
    }
    SUBCASE("relu") {
      auto x = test::random_vector<double>(300, rng);
      for (auto& v : x) v += v < 0 ? -0.01 : 0.01;  // away from the kink
      const auto r = test::random_vector<double>(x.size(), rng);
      std::vector<double> y(x.size()), dx(x.size());
      auto loss = [&] {
        kernels::relu_forward(y.data(), x.data(), x.size());
        return test::dot(y.data(), r.data(), y.size());
      };
      loss();
      kernels::relu_backward(dx.data(), r.data(), y.data(), x.size());
      CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss, 300) < test::grad_tolerance);
      auto dy = r;  // in place: dx aliases dy
      kernels::relu_backward(dy.data(), dy.data(), y.data(), x.size());
      CHECK(dy == dx);
      loss();  // y at x (the check left it at a perturbed x)
      auto z = x;  // forward in place
      kernels::relu_forward(z.data(), z.data(), z.size());
      CHECK(z == y);
    }
    SUBCASE("maxpool") {
      for (const std::array<int, 6>& c : {std::array<int, 6>{2, 7, 8, 3, 3, 2}, std::array<int, 6>{1, 9, 6, 4, 2, 2},
                                          std::array<int, 6>{2, 5, 5, 2, 3, 1}}) {
        const int B = c[0], H = c[1], W = c[2], C = c[3], k = c[4], st = c[5];
        INFO("H ", H, " W ", W, " k ", k, " stride ", st);
        const int Ho = kernels::pool_out_side(H, k, st), Wo = kernels::pool_out_side(W, k, st);
        auto x = test::random_vector<double>(std::size_t(B) * H * W * C, rng);
        const auto r = test::random_vector<double>(std::size_t(B) * Ho * Wo * C, rng);
        std::vector<double> y(r.size()), dx(x.size(), 0.0);
        std::vector<std::int32_t> arg(r.size());
        auto loss = [&] {
          kernels::maxpool2d_forward(y.data(), static_cast<std::int32_t*>(nullptr), x.data(), B, H, W, C, k, st);
          return test::dot(y.data(), r.data(), y.size());
        };
        kernels::maxpool2d_forward(y.data(), arg.data(), x.data(), B, H, W, C, k, st);
        kernels::maxpool2d_backward(dx.data(), r.data(), arg.data(), B, H, W, C, k, st);
        CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss, 200) < test::grad_tolerance);
      }
    }
    SUBCASE("adaptive average pool: non-divisible and repeated bins") {
      for (const std::array<int, 6>& c : {std::array<int, 6>{2, 5, 7, 3, 3, 2}, std::array<int, 6>{1, 4, 3, 2, 6, 5},
                                          std::array<int, 6>{2, 1, 1, 3, 6, 6}, std::array<int, 6>{1, 6, 6, 2, 6, 6}}) {
        const int B = c[0], H = c[1], W = c[2], C = c[3], Ho = c[4], Wo = c[5];
        INFO("H ", H, " W ", W, " -> ", Ho, "x", Wo);
        auto x = test::random_vector<double>(std::size_t(B) * H * W * C, rng);
        const auto r = test::random_vector<double>(std::size_t(B) * Ho * Wo * C, rng);
        std::vector<double> y(r.size()), dx(x.size(), 0.0);
        auto loss = [&] {
          kernels::adaptive_avgpool2d_forward(y.data(), x.data(), B, H, W, C, Ho, Wo);
          return test::dot(y.data(), r.data(), y.size());
        };
        kernels::adaptive_avgpool2d_backward(dx.data(), r.data(), B, H, W, C, Ho, Wo);
        CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss, 200) < test::grad_tolerance);
      }
    }
  }

  TEST_CASE("maxpool2d keeps the first of tied maxima and lets NaN win as PyTorch") {
    constexpr double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    // One 3 × 3 window (stride 2), five channels; per channel the nine values in scan order:
    const std::array<std::array<double, 9>, 5> plane{{
        {1, 1, 1, 1, 1, 1, 1, 1, 1},              // all tied: the first
        {0, 1, 5, 2, 3, 4, 5, 1, 0},              // tie at 2 and 6: the first (2)
        {9, 1, 2, 3, nan, 4, 5, 6, 7},            // a NaN beats 9
        {0, nan, 2, 3, 1, 4, 5, nan, 7},          // each NaN replaces: the last one (7)
        {-inf, -inf, -inf, -inf, -inf, -inf, -inf, -inf, -inf},
    }};
    std::vector<double> x(9 * 5);
    for (int p = 0; p < 9; ++p)
      for (int c = 0; c < 5; ++c) x[std::size_t(p) * 5 + c] = plane[std::size_t(c)][std::size_t(p)];
    std::vector<double> y(5), y2(5);
    std::vector<std::int32_t> arg(5);
    kernels::maxpool2d_forward(y.data(), arg.data(), x.data(), 1, 3, 3, 5, 3, 2);
    CHECK(arg == std::vector<std::int32_t>{0, 2, 4, 7, 0});
    CHECK(y[0] == 1);
    CHECK(y[1] == 5);
    CHECK(std::isnan(y[2]));
    CHECK(std::isnan(y[3]));
    CHECK(y[4] == -inf);
    kernels::maxpool2d_forward(y2.data(), static_cast<std::int32_t*>(nullptr), x.data(), 1, 3, 3, 5, 3, 2);
    CHECK(cnn_bitwise_equal(y, y2));
    // The gradient goes to the recorded position only.
    std::vector<double> dx(x.size(), 0.0);
    const std::vector<double> g{1, 2, 3, 4, 5};
    kernels::maxpool2d_backward(dx.data(), g.data(), arg.data(), 1, 3, 3, 5, 3, 2);
    std::vector<double> expect(x.size(), 0.0);
    expect[0 * 5 + 0] = 1;
    expect[2 * 5 + 1] = 2;
    expect[4 * 5 + 2] = 3;
    expect[7 * 5 + 3] = 4;
    expect[0 * 5 + 4] = 5;
    CHECK(dx == expect);
    // Floor mode: 8 → 3 windows of 3 with stride 2 (the last column is dropped), indices y·W + x.
    std::vector<float> xf(8 * 8);
    for (int i = 0; i < 64; ++i) xf[std::size_t(i)] = float(i);
    std::vector<float> yf(9);
    std::vector<std::int32_t> af(9);
    kernels::maxpool2d_forward(yf.data(), af.data(), xf.data(), 1, 8, 8, 1, 3, 2);
    CHECK(af == std::vector<std::int32_t>{18, 20, 22, 34, 36, 38, 50, 52, 54});
    CHECK(yf == std::vector<float>{18, 20, 22, 34, 36, 38, 50, 52, 54});
  }

  TEST_CASE("adaptive average pool uses PyTorch's bins (hand-computed)") {
    // in[y][x] = 10 y + x, 5 × 4 → 3 × 6. Rows: [0, 2) [1, 4) [3, 5), means 0.5, 2, 3.5. Columns:
    // [0, 1) [0, 2) [1, 2) [2, 3) [2, 4) [3, 4), means 0, 0.5, 1, 2, 2.5, 3.
    std::vector<double> x(20);
    for (int i = 0; i < 5; ++i)
      for (int j = 0; j < 4; ++j) x[std::size_t(i) * 4 + j] = 10.0 * i + j;
    std::vector<double> y(18);
    kernels::adaptive_avgpool2d_forward(y.data(), x.data(), 1, 5, 4, 1, 3, 6);
    const std::array<double, 3> row{0.5, 2, 3.5};
    const std::array<double, 6> col{0, 0.5, 1, 2, 2.5, 3};
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 6; ++j) CHECK(y[i * 6 + j] == doctest::Approx(10 * row[i] + col[j]).epsilon(1e-15));
    // Backward of ones along 5 → 3 rows: each input gets 1/|bin| of every bin holding it.
    std::vector<double> dx(5, 0.0);
    const std::vector<double> ones(3, 1.0);
    kernels::adaptive_avgpool2d_backward(dx.data(), ones.data(), 1, 5, 1, 1, 3, 1);
    const std::array<double, 5> expect{1.0 / 2, 1.0 / 2 + 1.0 / 3, 1.0 / 3, 1.0 / 3 + 1.0 / 2, 1.0 / 2};
    for (std::size_t i = 0; i < 5; ++i) CHECK(dx[i] == doctest::Approx(expect[i]).epsilon(1e-15));
  }
}
