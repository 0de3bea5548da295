// Attention kernels: the reference against a naive softmax(Q K^T / sqrt(Dh)) V, central-difference
// gradient checks in double, accumulation, and the fast kernels against the reference on sizes that
// are not multiples of the vector width, with fused qkv strides, masks and cross-attention.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

#include <tjepa/core/random.hpp>
#include <tjepa/kernels/attention.hpp>

#include "../support/gradcheck.hpp"

namespace {

namespace kernels = tjepa::kernels;
using kernels::AttentionShape;

// Buffers of one sample: q [Lq, ldq], k [Lk, ldk], v [Lk, ldv], out [Lq, ldo], filled with N(0, sd)
// (padding columns too, so a kernel that reads outside its head's columns gives wrong results).
template <class T>
struct Problem {
  kernels::AttentionShape s;
  std::vector<T> q, k, v, w;  // w: the fixed random weights of L = sum w * out
  std::vector<std::uint8_t> valid;
  bool masked = false;
  // fused: q, k, v are column slices of one [L, 3d] buffer (self-attention only).
  std::vector<T> qkv;
  bool fused = false;

  const T* Q() const { return fused ? qkv.data() : q.data(); }
  const T* K() const { return fused ? qkv.data() + s.d() : k.data(); }
  const T* V() const { return fused ? qkv.data() + 2 * s.d() : v.data(); }
  const std::uint8_t* mask() const { return masked ? valid.data() : nullptr; }
};

template <class T>
void fill(std::vector<T>& x, std::size_t n, tjepa::Rng& rng, double sd) {
  x.resize(n);
  for (auto& e : x) e = static_cast<T>(rng.normal(0.0, sd));
}

template <class T>
Problem<T> make_problem(int Lq, int Lk, int H, int Dh, bool fused, bool masked, std::uint64_t seed,
                        double sd = 1.0, int extra_ld = 0) {
  tjepa::Rng rng(seed);
  Problem<T> p;
  const int d = H * Dh;
  p.fused = fused;
  p.masked = masked;
  if (fused) {
    p.s = kernels::AttentionShape::fused_self(Lq, H, Dh);
    fill(p.qkv, static_cast<std::size_t>(Lq) * 3 * d, rng, sd);
  } else {
    p.s = {Lq, Lk, H, Dh, d + extra_ld, d + 2 * extra_ld, d + 3 * extra_ld, d + extra_ld};
    fill(p.q, static_cast<std::size_t>(Lq) * p.s.ldq, rng, sd);
    fill(p.k, static_cast<std::size_t>(Lk) * p.s.ldk, rng, sd);
    fill(p.v, static_cast<std::size_t>(Lk) * p.s.ldv, rng, sd);
  }
  fill(p.w, static_cast<std::size_t>(Lq) * p.s.ldo, rng, 1.0);
  p.valid.assign(static_cast<std::size_t>(Lk), 1);
  if (masked) {
    for (auto& x : p.valid) x = rng.uniform() < 0.7 ? 1 : 0;
    // At least two valid keys, so the softmax is not constant and q, k get a gradient.
    const auto j0 = static_cast<std::size_t>(rng.below(static_cast<std::uint64_t>(Lk)));
    p.valid[j0] = 1;
    p.valid[(j0 + 1) % static_cast<std::size_t>(Lk)] = 1;
  }
  return p;
}

// softmax(Q_h K_h^T / sqrt(Dh) + mask) V_h by the textbook: the full [Lq, Lk] score matrix of a
// head, then row max, exp, normalize, times V. Plain loops in double, out [Lq, d].
template <class T>
std::vector<double> naive_attention(const Problem<T>& p) {
  const auto& s = p.s;
  const std::size_t Lq = static_cast<std::size_t>(s.Lq), Lk = static_cast<std::size_t>(s.Lk);
  const std::size_t d = static_cast<std::size_t>(s.d()), Dh = static_cast<std::size_t>(s.Dh);
  std::vector<double> out(Lq * d, 0.0), S(Lq * Lk);
  for (std::size_t h = 0; h < static_cast<std::size_t>(s.H); ++h) {
    const std::size_t c0 = h * Dh;
    for (std::size_t i = 0; i < Lq; ++i)
      for (std::size_t j = 0; j < Lk; ++j) {
        double acc = 0.0;
        for (std::size_t c = 0; c < Dh; ++c)
          acc += static_cast<double>(p.Q()[i * s.ldq + c0 + c]) * static_cast<double>(p.K()[j * s.ldk + c0 + c]);
        S[i * Lk + j] = (p.mask() != nullptr && p.mask()[j] == 0) ? -1e300 : acc / std::sqrt(static_cast<double>(Dh));
      }
    for (std::size_t i = 0; i < Lq; ++i) {
      double m = -1e300, sum = 0.0;
      for (std::size_t j = 0; j < Lk; ++j) m = std::max(m, S[i * Lk + j]);
      for (std::size_t j = 0; j < Lk; ++j) sum += (S[i * Lk + j] = std::exp(S[i * Lk + j] - m));
      for (std::size_t j = 0; j < Lk; ++j) S[i * Lk + j] /= sum;
      for (std::size_t j = 0; j < Lk; ++j)
        for (std::size_t c = 0; c < Dh; ++c)
          out[i * d + c0 + c] += S[i * Lk + j] * static_cast<double>(p.V()[j * s.ldv + c0 + c]);
    }
  }
  return out;
}

template <class T>
double max_abs_diff_out(const Problem<T>& p, const std::vector<T>& out, const std::vector<double>& want) {
  double e = 0.0;
  for (int i = 0; i < p.s.Lq; ++i)
    for (int c = 0; c < p.s.d(); ++c)
      e = std::max(e, std::abs(static_cast<double>(out[i * p.s.ldo + c]) - want[static_cast<std::size_t>(i * p.s.d() + c)]));
  return e;
}

enum class Impl { ref, fast, fast_bf16 };  // fast_bf16: Precision::bf16 (fp32 without AVX512-BF16)

template <class T>
void forward(Impl impl, const Problem<T>& p, std::vector<T>& out, std::vector<T>& lse,
             tjepa::kernels::AttentionWorkspace<T>& ws) {
  out.assign(static_cast<std::size_t>(p.s.Lq) * p.s.ldo, T(0));
  lse.assign(static_cast<std::size_t>(p.s.H) * p.s.Lq, T(0));
  if (impl == Impl::ref)
    tjepa::kernels::ref::attention_forward(p.s, p.Q(), p.K(), p.V(), p.mask(), out.data(), lse.data());
  else
    tjepa::kernels::attention_forward(p.s, p.Q(), p.K(), p.V(), p.mask(), out.data(), lse.data(), ws,
                                      impl == Impl::fast_bf16 ? tjepa::Precision::bf16 : tjepa::Precision::fp32);
}

// Gradients of L = sum w * out with respect to the q, k, v buffers (in their own layouts).
template <class T>
struct Grads {
  std::vector<T> dq, dk, dv, dqkv;
};

template <class T>
Grads<T> backward(Impl impl, const Problem<T>& p, const std::vector<T>& out, const std::vector<T>& lse,
                  tjepa::kernels::AttentionWorkspace<T>& ws, int times = 1) {
  Grads<T> g;
  T *dq = nullptr, *dk = nullptr, *dv = nullptr;
  if (p.fused) {
    g.dqkv.assign(p.qkv.size(), T(0));
    dq = g.dqkv.data();
    dk = dq + p.s.d();
    dv = dq + 2 * p.s.d();
  } else {
    g.dq.assign(p.q.size(), T(0));
    g.dk.assign(p.k.size(), T(0));
    g.dv.assign(p.v.size(), T(0));
    dq = g.dq.data();
    dk = g.dk.data();
    dv = g.dv.data();
  }
  for (int t = 0; t < times; ++t) {
    if (impl == Impl::ref)
      tjepa::kernels::ref::attention_backward(p.s, p.Q(), p.K(), p.V(), p.mask(), out.data(), lse.data(),
                                     p.w.data(), dq, dk, dv);
    else
      tjepa::kernels::attention_backward(p.s, p.Q(), p.K(), p.V(), p.mask(), out.data(), lse.data(), p.w.data(),
                                dq, dk, dv, ws,
                                impl == Impl::fast_bf16 ? tjepa::Precision::bf16 : tjepa::Precision::fp32);
  }
  return g;
}

double loss(Impl impl, const Problem<double>& p, tjepa::kernels::AttentionWorkspace<double>& ws) {
  std::vector<double> out, lse;
  forward(impl, p, out, lse, ws);
  double l = 0.0;
  for (int i = 0; i < p.s.Lq; ++i)
    for (int c = 0; c < p.s.d(); ++c) l += p.w[i * p.s.ldo + c] * out[i * p.s.ldo + c];
  return l;
}

// Relative error ||num - ana|| / max(||num||, ||ana||) over every entry of buffer x that the
// kernel reads (columns of the heads), by central differences on x.
double grad_check(Impl impl, Problem<double>& p, std::vector<double>& x, const std::vector<double>& gx,
                  int rows, int ld, int col0) {
  tjepa::kernels::AttentionWorkspace<double> ws;
  const double eps = 1e-5;
  double num2 = 0.0, ana2 = 0.0, diff2 = 0.0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < p.s.d(); ++c) {
      const std::size_t idx = static_cast<std::size_t>(r) * ld + col0 + c;
      const double x0 = x[idx];
      x[idx] = x0 + eps;
      const double lp = loss(impl, p, ws);
      x[idx] = x0 - eps;
      const double lm = loss(impl, p, ws);
      x[idx] = x0;
      const double num = (lp - lm) / (2 * eps);
      num2 += num * num;
      ana2 += gx[idx] * gx[idx];
      diff2 += (num - gx[idx]) * (num - gx[idx]);
    }
  REQUIRE(ana2 > 0.0);
  return std::sqrt(diff2) / std::max(std::sqrt(num2), std::sqrt(ana2));
}

void check_gradients(Impl impl, int Lq, int Lk, int H, int Dh, bool fused, bool masked, std::uint64_t seed) {
  CAPTURE(Lq);
  CAPTURE(Lk);
  CAPTURE(fused);
  CAPTURE(masked);
  auto p = make_problem<double>(Lq, Lk, H, Dh, fused, masked, seed, 1.0, fused ? 0 : 2);
  tjepa::kernels::AttentionWorkspace<double> ws;
  std::vector<double> out, lse;
  forward(impl, p, out, lse, ws);
  const auto g = backward(impl, p, out, lse, ws);
  const int d = p.s.d();
  if (fused) {
    CHECK(grad_check(impl, p, p.qkv, g.dqkv, Lq, 3 * d, 0) < 1e-6);
    CHECK(grad_check(impl, p, p.qkv, g.dqkv, Lq, 3 * d, d) < 1e-6);
    CHECK(grad_check(impl, p, p.qkv, g.dqkv, Lq, 3 * d, 2 * d) < 1e-6);
  } else {
    CHECK(grad_check(impl, p, p.q, g.dq, Lq, p.s.ldq, 0) < 1e-6);
    CHECK(grad_check(impl, p, p.k, g.dk, Lk, p.s.ldk, 0) < 1e-6);
    CHECK(grad_check(impl, p, p.v, g.dv, Lk, p.s.ldv, 0) < 1e-6);
  }
  // Masked keys get no gradient.
  if (masked && !fused)
    for (int j = 0; j < Lk; ++j)
      if (p.valid[j] == 0)
        for (int c = 0; c < d; ++c) {
          CHECK(g.dk[j * p.s.ldk + c] == 0.0);
          CHECK(g.dv[j * p.s.ldv + c] == 0.0);
        }
}

template <class T>
double max_rel_diff(const std::vector<T>& a, const std::vector<T>& b) {
  double e = 0.0, m = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    e = std::max(e, std::abs(static_cast<double>(a[i]) - static_cast<double>(b[i])));
    m = std::max(m, std::abs(static_cast<double>(b[i])));
  }
  return e / std::max(m, 1e-30);
}

// The fast kernels against the reference on one problem: out, lse and the three gradients.
template <class T>
void check_fast_vs_ref(const Problem<T>& p, double tol) {
  tjepa::kernels::AttentionWorkspace<T> ws;
  std::vector<T> out_r, lse_r, out_f, lse_f;
  forward(Impl::ref, p, out_r, lse_r, ws);
  forward(Impl::fast, p, out_f, lse_f, ws);
  CHECK(max_rel_diff(out_f, out_r) < tol);
  for (std::size_t i = 0; i < lse_r.size(); ++i) {
    if (std::isinf(lse_r[i])) {
      CHECK(std::isinf(lse_f[i]));
    } else {
      CHECK(std::abs(static_cast<double>(lse_f[i]) - static_cast<double>(lse_r[i])) < tol * 10);
    }
  }
  // Backward of the fast path uses its own forward's out and lse, as a training step does.
  const auto gr = backward(Impl::ref, p, out_r, lse_r, ws);
  const auto gf = backward(Impl::fast, p, out_f, lse_f, ws);
  if (p.fused) {
    CHECK(max_rel_diff(gf.dqkv, gr.dqkv) < tol);
  } else {
    CHECK(max_rel_diff(gf.dq, gr.dq) < tol);
    CHECK(max_rel_diff(gf.dk, gr.dk) < tol);
    CHECK(max_rel_diff(gf.dv, gr.dv) < tol);
  }
}

}  // namespace

TEST_SUITE("kernels") {
  TEST_CASE("ref attention equals a naive softmax(QK^T/sqrt(Dh))V for self and cross attention with masks") {
    for (bool masked : {false, true}) {
      auto self = make_problem<double>(13, 13, 3, 8, true, masked, 1);
      tjepa::kernels::AttentionWorkspace<double> ws;
      std::vector<double> out, lse;
      forward(Impl::ref, self, out, lse, ws);
      CHECK(max_abs_diff_out(self, out, naive_attention(self)) < 1e-12);
      auto cross = make_problem<double>(5, 17, 2, 7, false, masked, 2, 1.0, 3);
      forward(Impl::ref, cross, out, lse, ws);
      CHECK(max_abs_diff_out(cross, out, naive_attention(cross)) < 1e-12);
    }
  }

  TEST_CASE_TEMPLATE("attention with every key masked gives 0 output and +inf lse and 0 gradient", T, float, double) {
    for (Impl impl : {Impl::ref, Impl::fast}) {
      auto p = make_problem<T>(7, 9, 2, 5, false, true, 3);
      std::fill(p.valid.begin(), p.valid.end(), std::uint8_t{0});
      tjepa::kernels::AttentionWorkspace<T> ws;
      std::vector<T> out, lse;
      forward(impl, p, out, lse, ws);
      for (auto x : out) CHECK(x == T(0));
      for (auto x : lse) CHECK(std::isinf(x));
      const auto g = backward(impl, p, out, lse, ws);
      for (const auto* gv : {&g.dq, &g.dk, &g.dv})
        for (auto x : *gv) CHECK(x == T(0));
    }
  }

  TEST_CASE("attention gradients match central differences in double") {
    for (Impl impl : {Impl::ref, Impl::fast}) {
      CAPTURE(static_cast<int>(impl));
      for (bool masked : {false, true}) {
        check_gradients(impl, 9, 9, 2, 5, true, masked, 10);    // self, fused qkv
        check_gradients(impl, 11, 11, 3, 4, false, masked, 11);  // self, strided separate buffers
        check_gradients(impl, 4, 13, 2, 6, false, masked, 12);   // cross: few queries, many keys
        check_gradients(impl, 19, 3, 1, 8, false, masked, 13);   // cross: many queries, few keys
      }
    }
  }

  TEST_CASE_TEMPLATE("attention backward accumulates: two passes give exactly twice the gradient", T, float, double) {
    for (Impl impl : {Impl::ref, Impl::fast}) {
      auto p = make_problem<T>(17, 17, 3, 16, true, true, 20);
      tjepa::kernels::AttentionWorkspace<T> ws;
      std::vector<T> out, lse;
      forward(impl, p, out, lse, ws);
      const auto g1 = backward(impl, p, out, lse, ws, 1);
      const auto g2 = backward(impl, p, out, lse, ws, 2);
      REQUIRE(g1.dqkv.size() == g2.dqkv.size());
      bool exact = true;
      for (std::size_t i = 0; i < g1.dqkv.size(); ++i) exact = exact && (g2.dqkv[i] == T(2) * g1.dqkv[i]);
      CHECK(exact);
    }
  }

  TEST_CASE("attention rejects bad shapes and null buffers and names the argument") {
    std::vector<float> b(64, 0.0f), lse(8, 0.0f);
    tjepa::kernels::AttentionWorkspace<float> ws;
    kernels::AttentionShape s{2, 2, 2, 4, 8, 8, 8, 8};
    kernels::AttentionShape bad = s;
    bad.ldk = 7;
    CHECK_THROWS_WITH_AS(tjepa::kernels::attention_forward(bad, b.data(), b.data(), b.data(), nullptr, b.data(), lse.data(), ws),
                         doctest::Contains("ldk = 7"), tjepa::ShapeError);
    bad = s;
    bad.Lq = 0;
    CHECK_THROWS_WITH_AS(tjepa::kernels::ref::attention_forward(bad, b.data(), b.data(), b.data(), nullptr, b.data(), lse.data()),
                         doctest::Contains("Lq = 0"), tjepa::ShapeError);
    CHECK_THROWS_WITH_AS(tjepa::kernels::attention_backward(s, b.data(), b.data(), b.data(), nullptr, b.data(),
                                                   static_cast<const float*>(nullptr), b.data(), b.data(), b.data(),
                                                   b.data(), ws),
                         doctest::Contains("lse is null"), tjepa::ShapeError);
  }

  TEST_CASE_TEMPLATE("fast attention matches the reference on awkward sizes and strides with masks and cross attention", T, float, double) {
    const double tol = std::is_same_v<T, float> ? 2e-5 : 1e-12;
    std::uint64_t seed = 100;
    for (int L : {1, 7, 17, 131}) {
      for (int Dh : {64, 13, 80}) {
        for (bool masked : {false, true}) {
          CAPTURE(L);
          CAPTURE(Dh);
          CAPTURE(masked);
          check_fast_vs_ref(make_problem<T>(L, L, 3, Dh, true, masked, ++seed), tol);           // fused qkv
          check_fast_vs_ref(make_problem<T>(L, 2 * L + 5, 2, Dh, false, masked, ++seed, 1.0, 5), tol);  // cross
          check_fast_vs_ref(make_problem<T>(L + 3, 4, 1, Dh, false, masked, ++seed, 2.0, 1), tol);      // few keys
        }
      }
    }
  }

  TEST_CASE("fast float attention equals a naive softmax(QK^T/sqrt(Dh))V to 1e-5 up to L = 2124") {
    for (int L : {368, 528, 2124}) {
      CAPTURE(L);
      // sd 0.5 gives scores of a few units, so the softmax is neither flat nor one-hot.
      auto p = make_problem<float>(L, L, 3, 64, true, L == 528, 300 + static_cast<std::uint64_t>(L), 0.5);
      tjepa::kernels::AttentionWorkspace<float> ws;
      std::vector<float> out, lse;
      forward(Impl::fast, p, out, lse, ws);
      CHECK(max_abs_diff_out(p, out, naive_attention(p)) < 1e-5);
      // Flash-style memory: forward and backward scratch is O(L * Dh), far below one [L, L] head.
      backward(Impl::fast, p, out, lse, ws);
      CHECK(ws.capacity() <= std::size_t{8} * 2 * static_cast<std::size_t>(L) * 64 + 65536);
    }
  }

  TEST_CASE("bf16 attention forward against the reference on bf16-rounded inputs (awkward sizes / masks / cross)") {
    // Q, K and V rounded to bf16 make QKᵀ exact in fp32, so lse matches the reference of the
    // rounded inputs to 1e-5; the output differs by the rounding of each tile's P to bf16 (8
    // significant bits), bounded here by 1 % of the largest |v| (measured: 0.07 %).
    // Without AVX512-BF16 the call is the fp32 kernel, bit for bit.
    std::uint64_t seed = 900;
    double worst = 0;
    for (const bool amx : tjepa::test::amx_modes()) {  // vdpbf16ps, then AMX tiles where the machine has them
      const tjepa::test::Amx engine(amx);
      CAPTURE(amx);
      for (int L : {1, 7, 17, 131, 368}) {
        for (int Dh : {64, 13}) {
          for (bool masked : {false, true}) {
            CAPTURE(L);
            CAPTURE(Dh);
            CAPTURE(masked);
            for (auto p : {make_problem<float>(L, L, 3, Dh, true, masked, ++seed, 0.5),
                           make_problem<float>(L, 2 * L + 5, 2, Dh, false, masked, ++seed, 0.5, 5)}) {
              tjepa::kernels::AttentionWorkspace<float> ws;
              std::vector<float> out16, lse16, out32, lse32;
              forward(Impl::fast_bf16, p, out16, lse16, ws);
              forward(Impl::fast, p, out32, lse32, ws);
              if (!tjepa::detail::bgemm::native) {
                CHECK(out16 == out32);
                continue;
              }
              for (auto* x : {&p.q, &p.k, &p.v, &p.qkv})
                for (float& e : *x) e = tjepa::detail::bgemm::round_bf16(e);
              std::vector<float> outr, lser;
              forward(Impl::ref, p, outr, lser, ws);
              double vmax = 0, lse_err = 0;
              for (float e : p.fused ? p.qkv : p.v) vmax = std::max(vmax, double(std::abs(e)));
              for (std::size_t i = 0; i < lser.size(); ++i)
                if (std::isfinite(lser[i])) lse_err = std::max(lse_err, double(std::abs(lse16[i] - lser[i])));
              const double err = max_abs_diff_out(p, out16, naive_attention(p)) / vmax;
              worst = std::max(worst, err);
              CHECK(lse_err < 1e-5);
              CHECK(err < 1e-2);
              CHECK(out16 != out32);  // the bf16 products ran
            }
          }
        }
      }
    }
    MESSAGE("bf16 attention: largest output error / max |v| ", worst);
  }

  TEST_CASE("The bf16 forward's softmax tile writes the words that softmax then pairing gives") {
    // online_softmax_tile with Pairs writes P^T straight into bf16 pairs of keys; the same tile
    // through the fp32 softmax and pack_pairs_across_rows is its specification: the same words and
    // the same running statistics, bit for bit, for odd and even key counts and short query blocks.
#if TJEPA_BF16_NATIVE
    namespace A = tjepa::detail::attn;
    using Tl = A::Tiles<float>;
    constexpr int BQ = Tl::BQ, BK = Tl::BK, w = A::W<float>, NB = BQ / w;
    tjepa::Rng rng(77);
    for (int kv : {1, 2, 7, BK - 1, BK})
      for (int nb : {1, 3, NB}) {
        CAPTURE(kv);
        CAPTURE(nb);
        tjepa::AlignedVector<float> st(std::size_t(BK) * BQ), m(BQ), l(BQ), alpha(BQ);
        for (float& x : st) x = float(rng.normal() * 3);
        for (int i = 0; i < BQ; ++i) {
          m[i] = i % 5 == 0 ? -std::numeric_limits<float>::infinity() : float(rng.normal());
          l[i] = float(1 + rng.uniform());
        }
        tjepa::AlignedVector<float> st2 = st, m2 = m, l2 = l, alpha2 = alpha;
        tjepa::AlignedVector<std::uint32_t> pt(std::size_t(BK) / 2 * BQ, 0u), pt2 = pt;
        const float c = 0.18f;
        if (nb == NB) {
          A::online_softmax_tile<float, NB, true, true>(st.data(), BQ, kv, nb, c, m.data(), l.data(), alpha.data(),
                                                        pt.data());
          A::online_softmax_tile<float, NB, true>(st2.data(), BQ, kv, nb, c, m2.data(), l2.data(), alpha2.data());
        } else {
          A::online_softmax_tile<float, NB, false, true>(st.data(), BQ, kv, nb, c, m.data(), l.data(), alpha.data(),
                                                         pt.data());
          A::online_softmax_tile<float, NB, false>(st2.data(), BQ, kv, nb, c, m2.data(), l2.data(), alpha2.data());
        }
        A::pack_pairs_across_rows(st2.data(), BQ, nullptr, kv, nb * w, pt2.data(), BQ);
        for (int p = 0; p < (kv + 1) / 2; ++p)
          for (int j = 0; j < nb * w; ++j) REQUIRE(pt[std::size_t(p) * BQ + j] == pt2[std::size_t(p) * BQ + j]);
        for (int j = 0; j < nb * w; ++j) {
          REQUIRE(m[j] == m2[j]);
          REQUIRE(l[j] == l2[j]);
          REQUIRE(alpha[j] == alpha2[j]);
        }
      }
#else
    MESSAGE("no AVX512-BF16 in this build: the paired softmax is not compiled");
#endif
  }

  TEST_CASE("The bf16 backward's tile writes the words that the fp32 pass then the three packs give") {
    // backward_tile_pairs writes P^T and dS^T straight into their three bf16 operands; the fp32
    // exp pass followed by pack_row_pairs (twice) and pack_pairs_across_rows is its specification:
    // the same words, bit for bit, for odd and even key counts and every query count's tail,
    // padding queries included (lse2 = inf, D = 0, as attention_backward sets them).
#if TJEPA_BF16_NATIVE
    namespace A = tjepa::detail::attn;
    using Tl = A::Tiles<float>;
    constexpr int BQB = Tl::BQB, BKB = Tl::BKB, w = A::W<float>;
    const float c = 0.18f;
    tjepa::Rng rng(78);
    for (int mk : {1, 2, 7, BKB - 1, BKB})
      for (int nq : {1, 2, 15, 16, 17, 33, 47, BQB - 1, BQB}) {
        CAPTURE(mk);
        CAPTURE(nq);
        const int nv = int(A::round_up(nq, w)), nq2 = (nq + 1) / 2;
        tjepa::AlignedVector<float> st(std::size_t(BKB) * BQB), dpt(st.size()), lse2(BQB), dd(BQB);
        for (float& x : st) x = float(rng.normal() * 3);
        for (float& x : dpt) x = float(rng.normal());
        for (int i = 0; i < BQB; ++i) {
          lse2[i] = i < nq ? float(rng.normal() + 2) : std::numeric_limits<float>::infinity();
          dd[i] = i < nq ? float(rng.normal()) : 0.0f;
        }
        const std::uint32_t stale = 0xdeadbeefu;
        tjepa::AlignedVector<std::uint32_t> pt(std::size_t(BKB) * BQB, stale), dst = pt, ds = pt;
        tjepa::AlignedVector<std::uint32_t> pt2 = pt, dst2 = pt, ds2 = pt;
        A::backward_tile_pairs(st.data(), dpt.data(), BQB, mk, nq, c, lse2.data(), dd.data(), pt.data(), dst.data(),
                               ds.data());
        using V = A::Vec<float>;
        for (int r = 0; r < mk; ++r)  // attention_backward's fp32 exp pass
          for (int j = 0; j < nv; j += w) {
            float *s = st.data() + r * BQB + j, *dp = dpt.data() + r * BQB + j;
            const V p = A::exp2(xsimd::fms(V::load_aligned(s), V(c), V::load_aligned(lse2.data() + j)));
            p.store_aligned(s);
            (p * (V::load_aligned(dp) - V::load_aligned(dd.data() + j))).store_aligned(dp);
          }
        A::pack_row_pairs(st.data(), BQB, nullptr, mk, nq, pt2.data(), mk, 0, false);
        A::pack_row_pairs(dpt.data(), BQB, nullptr, mk, nq, dst2.data(), mk, 0, false);
        A::pack_pairs_across_rows(dpt.data(), BQB, nullptr, mk, nv, ds2.data(), BQB);
        for (std::size_t i = 0; i < pt.size(); ++i) {
          CAPTURE(i);
          REQUIRE(pt[i] == pt2[i]);
          REQUIRE(dst[i] == dst2[i]);
          REQUIRE(ds[i] == ds2[i]);
        }
        CHECK(pt[std::size_t(mk) * nq2] == stale);  // nothing past the last row's words
      }
#else
    MESSAGE("no AVX512-BF16 in this build: the paired backward tile is not compiled");
#endif
  }

  TEST_CASE("bf16 attention backward against fp32 (awkward sizes / masks / cross)") {
    // Forward and backward in bf16 against both in fp32: every gradient within 2 % of the largest
    // fp32 gradient entry of its buffer (measured: 0.6 %). Without AVX512-BF16 they are equal.
    std::uint64_t seed = 1900;
    double worst = 0;
    for (const bool amx : tjepa::test::amx_modes()) {  // vdpbf16ps, then AMX tiles where the machine has them
      const tjepa::test::Amx engine(amx);
      CAPTURE(amx);
      for (int L : {1, 7, 17, 131, 200}) {
        for (int Dh : {64, 13}) {
          for (bool masked : {false, true}) {
            CAPTURE(L);
            CAPTURE(Dh);
            CAPTURE(masked);
            for (const auto& p : {make_problem<float>(L, L, 3, Dh, true, masked, ++seed, 0.5),
                                  make_problem<float>(L, 2 * L + 5, 2, Dh, false, masked, ++seed, 0.5, 5)}) {
              tjepa::kernels::AttentionWorkspace<float> ws;
              std::vector<float> out16, lse16, out32, lse32;
              forward(Impl::fast_bf16, p, out16, lse16, ws);
              forward(Impl::fast, p, out32, lse32, ws);
              const Grads<float> g16 = backward(Impl::fast_bf16, p, out16, lse16, ws);
              const Grads<float> g32 = backward(Impl::fast, p, out32, lse32, ws);
              for (const auto& [a, b] : {std::pair{&g16.dq, &g32.dq}, std::pair{&g16.dk, &g32.dk},
                                          std::pair{&g16.dv, &g32.dv}, std::pair{&g16.dqkv, &g32.dqkv}}) {
                if (!tjepa::detail::bgemm::native) {
                  CHECK(*a == *b);
                  continue;
                }
                double scale = 0, err = 0;
                for (std::size_t i = 0; i < b->size(); ++i) {
                  scale = std::max(scale, double(std::abs((*b)[i])));
                  err = std::max(err, double(std::abs((*a)[i] - (*b)[i])));
                }
                if (scale == 0) continue;
                worst = std::max(worst, err / scale);
                CHECK(err / scale < 2e-2);
              }
            }
          }
        }
      }
    }
    MESSAGE("bf16 attention backward: largest gradient error / largest gradient ", worst);
  }

  TEST_CASE_TEMPLATE("vectorized exp2 is within 2 ulp of std::exp2 and flushes -inf to 0", T, float, double) {
    using V = tjepa::detail::attn::Vec<T>;
    constexpr int w = tjepa::detail::attn::W<T>;
    using Bits = std::conditional_t<std::is_same_v<T, float>, std::int32_t, std::int64_t>;
    const double lo = std::is_same_v<T, float> ? -125.0 : -1020.0;
    tjepa::Rng rng(500);
    std::int64_t worst = 0;
    alignas(64) T x[w], y[w];
    for (int it = 0; it < 20000; ++it) {
      for (int i = 0; i < w; ++i) {
        // Half the arguments in the softmax's busy range [-30, 0], half anywhere down to lo.
        x[i] = static_cast<T>(it % 2 == 0 ? rng.uniform(-30.0, 0.0) : rng.uniform(lo, 0.0));
      }
      tjepa::detail::attn::exp2(V::load_aligned(x)).store_aligned(y);
      for (int i = 0; i < w; ++i) {
        const T want = static_cast<T>(std::exp2(static_cast<long double>(x[i])));
        Bits a, b;
        std::memcpy(&a, &y[i], sizeof(T));
        std::memcpy(&b, &want, sizeof(T));
        worst = std::max<std::int64_t>(worst, a > b ? a - b : b - a);
      }
    }
    CHECK(worst <= 2);
    for (int i = 0; i < w; ++i) x[i] = i % 2 == 0 ? -std::numeric_limits<T>::infinity() : T(-5000);
    tjepa::detail::attn::exp2(V::load_aligned(x)).store_aligned(y);
    for (int i = 0; i < w; ++i) CHECK(y[i] == T(0));
    for (int i = 0; i < w; ++i) x[i] = T(0);
    tjepa::detail::attn::exp2(V::load_aligned(x)).store_aligned(y);
    for (int i = 0; i < w; ++i) CHECK(y[i] == T(1));
  }

  TEST_CASE("attention workspace never reallocates for the same or a smaller shape") {
    auto big = make_problem<float>(131, 131, 3, 64, true, true, 400);
    auto small = make_problem<float>(70, 70, 3, 64, true, false, 401);
    auto cross = make_problem<float>(16, 131, 3, 64, false, true, 402);
    tjepa::kernels::AttentionWorkspace<float> ws;
    ws.reserve(big.s);
    const float* data = ws.buffer.data();
    const int* keys = ws.keys.data();
    const std::size_t cap = ws.capacity();
    for (const auto* p : {&big, &small, &cross}) {
      std::vector<float> out, lse;
      forward(Impl::fast, *p, out, lse, ws);
      backward(Impl::fast, *p, out, lse, ws);
      CHECK(ws.buffer.data() == data);
      CHECK(ws.keys.data() == keys);
      CHECK(ws.capacity() == cap);
    }
  }
}
