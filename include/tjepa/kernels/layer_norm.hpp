#pragma once
// LayerNorm over the last dimension of [M, C] rows (PyTorch semantics, biased variance):
//   out = (x - mean) · rstd · w + b,   rstd = 1 / sqrt(var + eps).
// mean[M] and rstd[M] are what backward needs; pass nullptr for inference.
#include <algorithm>
#include <cmath>
#include <cstddef>

#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/detail/simd.hpp"

namespace tjepa::kernels {

// The reference's LayerNorm eps (ViT-Tiny, partial(nn.LayerNorm, eps=1e-6)).
inline constexpr double layer_norm_eps = 1e-6;

namespace ref {
template <class T>
void layer_norm_forward(T* out, T* mean, T* rstd, const T* in, const T* w, const T* b, int M, int C,
                        T eps) {
  for (int m = 0; m < M; ++m) {
    const T* x = in + std::size_t(m) * C;
    T mu = 0;
    for (int c = 0; c < C; ++c) mu += x[c];
    mu /= T(C);
    T var = 0;
    for (int c = 0; c < C; ++c) var += (x[c] - mu) * (x[c] - mu);
    var /= T(C);
    const T rs = T(1) / std::sqrt(var + eps);
    for (int c = 0; c < C; ++c) out[std::size_t(m) * C + c] = (x[c] - mu) * rs * w[c] + b[c];
    if (mean) mean[m] = mu;
    if (rstd) rstd[m] = rs;
  }
}
template <class T>
void layer_norm_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w,
                         const T* mean, const T* rstd, int M, int C) {
  for (int m = 0; m < M; ++m) {
    const T* x = in + std::size_t(m) * C;
    const T* g = dout + std::size_t(m) * C;
    T m1 = 0, m2 = 0;
    for (int c = 0; c < C; ++c) {
      const T xhat = (x[c] - mean[m]) * rstd[m];
      m1 += g[c] * w[c];
      m2 += g[c] * w[c] * xhat;
    }
    m1 /= T(C);
    m2 /= T(C);
    for (int c = 0; c < C; ++c) {
      const T xhat = (x[c] - mean[m]) * rstd[m];
      if (din) din[std::size_t(m) * C + c] += rstd[m] * (g[c] * w[c] - m1 - xhat * m2);
      dw[c] += g[c] * xhat;
      db[c] += g[c];
    }
  }
}
}  // namespace ref

// Rows [m0, m1) of layer_norm_forward on the calling thread (in, out, mean, rstd: the whole
// [M, C] matrix and its statistics).
template <class T>
void layer_norm_forward_rows(T* out, T* mean, T* rstd, const T* in, const T* w, const T* b, int m0, int m1, int C,
                             T eps = T(layer_norm_eps)) {
  using V = detail::simd<T>;
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t n = std::size_t(C);
  for (int m = m0; m < m1; ++m) {
    const T* x = in + std::size_t(m) * n;
    T* y = out + std::size_t(m) * n;
    const T mu = detail::simd_sum(x, n) / T(C);
    const V vmu(mu);
    V acc(T(0));
    std::size_t i = 0;
    for (; i + W <= n; i += W) {
      const V d = xsimd::load_unaligned(x + i) - vmu;
      acc = xsimd::fma(d, d, acc);
    }
    T var = detail::hsum(acc);
    for (; i < n; ++i) var += (x[i] - mu) * (x[i] - mu);
    const T rs = T(1) / std::sqrt(var / T(C) + eps);
    const V vrs(rs);
    for (i = 0; i + W <= n; i += W) {
      const V xh = (xsimd::load_unaligned(x + i) - vmu) * vrs;
      xsimd::fma(xh, xsimd::load_unaligned(w + i), xsimd::load_unaligned(b + i)).store_unaligned(y + i);
    }
    for (; i < n; ++i) y[i] = (x[i] - mu) * rs * w[i] + b[i];
    if (mean) mean[m] = mu;
    if (rstd) rstd[m] = rs;
  }
}

template <class T>
void layer_norm_forward(T* out, T* mean, T* rstd, const T* in, const T* w, const T* b, int M, int C,
                        T eps = T(layer_norm_eps)) {
  // Rows stay with the thread that the products give them (detail::owns_rows), down to a grain a
  // fork is worth: at batch 1 (368 × 192) one thread took 19 µs a call and 37 µs when half the
  // rows came from the other core.
  [[maybe_unused]] const std::size_t size = std::size_t(M) * std::size_t(C);
  const bool own = detail::owns_rows(M, detail::max_threads());
  TJEPA_OMP(omp parallel if (size > (own ? detail::parallel_grain / 8 : detail::parallel_grain)))
  {
    const int t = detail::thread_id(), k = detail::team_size(), block = own ? detail::row_block : 1;
    layer_norm_forward_rows(out, mean, rstd, in, w, b, detail::row_begin(M, t, k, block),
                            detail::row_begin(M, t + 1, k, block), C, eps);
  }
}

// Differentiates out = xhat · w + b with xhat = (x - mean) · rstd:
//   din += rstd · (dxhat - mean(dxhat) - xhat · mean(dxhat ⊙ xhat)),  dxhat = dout ⊙ w
//   dw += Σ_m dout ⊙ xhat,  db += Σ_m dout.   din may be nullptr.
template <class T>
void layer_norm_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w,
                         const T* mean, const T* rstd, int M, int C) {
  using V = detail::simd<T>;
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t n = std::size_t(C);
  if (din) {
    TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(M) * n > detail::parallel_grain))
    for (int m = 0; m < M; ++m) {
      const T* x = in + std::size_t(m) * n;
      const T* g = dout + std::size_t(m) * n;
      T* dx = din + std::size_t(m) * n;
      const V vmu(mean[m]), vrs(rstd[m]);
      V a1(T(0)), a2(T(0));
      std::size_t i = 0;
      for (; i + W <= n; i += W) {
        const V gw = xsimd::load_unaligned(g + i) * xsimd::load_unaligned(w + i);
        const V xh = (xsimd::load_unaligned(x + i) - vmu) * vrs;
        a1 += gw;
        a2 = xsimd::fma(gw, xh, a2);
      }
      T m1 = detail::hsum(a1), m2 = detail::hsum(a2);
      for (std::size_t j = i; j < n; ++j) {
        const T xh = (x[j] - mean[m]) * rstd[m];
        m1 += g[j] * w[j];
        m2 += g[j] * w[j] * xh;
      }
      m1 /= T(C);
      m2 /= T(C);
      const V vm1(m1), vm2(m2);
      for (i = 0; i + W <= n; i += W) {
        const V gw = xsimd::load_unaligned(g + i) * xsimd::load_unaligned(w + i);
        const V xh = (xsimd::load_unaligned(x + i) - vmu) * vrs;
        const V d = xsimd::load_unaligned(dx + i) + vrs * (gw - vm1 - xh * vm2);
        d.store_unaligned(dx + i);
      }
      for (; i < n; ++i) {
        const T xh = (x[i] - mean[m]) * rstd[m];
        dx[i] += rstd[m] * (g[i] * w[i] - m1 - xh * m2);
      }
    }
  }
  // Parameter gradients: a reduction over rows, summed per column in registers and added once,
  // so that a second backward adds exactly the same amount (and the order is fixed whatever the
  // thread count). Columns are split over the threads in whole vectors; a thread walks its
  // columns in chunks of up to CV vectors row by row (contiguous reads of dout and in).
  constexpr std::size_t CV = 8;
  const std::size_t nvec = n / W;
  [[maybe_unused]] const int threads =
      std::size_t(M) * n > detail::parallel_grain ? std::min<int>(detail::max_threads(), int(std::max<std::size_t>(nvec, 1))) : 1;
  TJEPA_OMP(omp parallel num_threads(threads) if (threads > 1))
  {
    const std::size_t t = std::size_t(detail::thread_id()), k = std::size_t(detail::team_size());
    const std::size_t v1 = nvec * (t + 1) / k;
    for (std::size_t v0 = nvec * t / k; v0 < v1; v0 += CV) {
      const std::size_t nv = std::min(CV, v1 - v0);
      V aw[CV], ab[CV];
      for (std::size_t v = 0; v < CV; ++v) aw[v] = ab[v] = V(T(0));
      for (int m = 0; m < M; ++m) {
        const T* g = dout + std::size_t(m) * n + v0 * W;
        const T* x = in + std::size_t(m) * n + v0 * W;
        const V vmu(mean[m]), vrs(rstd[m]);
        for (std::size_t v = 0; v < nv; ++v) {
          const V gv = xsimd::load_unaligned(g + v * W);
          aw[v] = xsimd::fma(gv, (xsimd::load_unaligned(x + v * W) - vmu) * vrs, aw[v]);
          ab[v] += gv;
        }
      }
      for (std::size_t v = 0; v < nv; ++v) {
        const std::size_t c = (v0 + v) * W;
        (xsimd::load_unaligned(dw + c) + aw[v]).store_unaligned(dw + c);
        (xsimd::load_unaligned(db + c) + ab[v]).store_unaligned(db + c);
      }
    }
  }
  for (std::size_t i = nvec * W; i < n; ++i) {
    T aw = 0, ab = 0;
    for (int m = 0; m < M; ++m) {
      const T g = dout[std::size_t(m) * n + i];
      aw += g * (in[std::size_t(m) * n + i] - mean[m]) * rstd[m];
      ab += g;
    }
    dw[i] += aw;
    db[i] += ab;
  }
}

}  // namespace tjepa::kernels
