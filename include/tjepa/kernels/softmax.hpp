#pragma once
// Softmax over the last dimension of [M, N] rows, max-subtracted for range.
//   forward:  y = exp(x - max) / Σ exp(x - max)
//   backward: dx += y ⊙ (dy - Σ dy ⊙ y)
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/detail/simd.hpp"

namespace tjepa::kernels {

namespace ref {
template <class T>
void softmax_forward(T* out, const T* in, int M, int N) {
  for (int m = 0; m < M; ++m) {
    const T* x = in + std::size_t(m) * N;
    T* y = out + std::size_t(m) * N;
    T mx = -std::numeric_limits<T>::infinity();
    for (int i = 0; i < N; ++i) mx = std::max(mx, x[i]);
    T s = 0;
    for (int i = 0; i < N; ++i) s += (y[i] = std::exp(x[i] - mx));
    for (int i = 0; i < N; ++i) y[i] /= s;
  }
}
template <class T>
void softmax_backward(T* din, const T* dout, const T* out, int M, int N) {
  for (int m = 0; m < M; ++m) {
    const T* y = out + std::size_t(m) * N;
    const T* g = dout + std::size_t(m) * N;
    T s = 0;
    for (int i = 0; i < N; ++i) s += g[i] * y[i];
    for (int i = 0; i < N; ++i) din[std::size_t(m) * N + i] += y[i] * (g[i] - s);
  }
}
}  // namespace ref

// out may alias in.
template <class T>
void softmax_forward(T* out, const T* in, int M, int N) {
  using V = detail::simd<T>;
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t n = std::size_t(N);
  TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(M) * n > detail::parallel_grain))
  for (int m = 0; m < M; ++m) {
    const T* x = in + std::size_t(m) * n;
    T* y = out + std::size_t(m) * n;
    V vmx(-std::numeric_limits<T>::infinity());
    std::size_t i = 0;
    for (; i + W <= n; i += W) vmx = xsimd::max(vmx, xsimd::load_unaligned(x + i));
    T mx = detail::hmax(vmx);
    for (; i < n; ++i) mx = std::max(mx, x[i]);
    const V vm(mx);
    V acc(T(0));
    for (i = 0; i + W <= n; i += W) {
      const V e = xsimd::exp(xsimd::load_unaligned(x + i) - vm);
      e.store_unaligned(y + i);
      acc += e;
    }
    T s = detail::hsum(acc);
    for (; i < n; ++i) s += (y[i] = std::exp(x[i] - mx));
    const V inv(T(1) / s);
    for (i = 0; i + W <= n; i += W) (xsimd::load_unaligned(y + i) * inv).store_unaligned(y + i);
    for (; i < n; ++i) y[i] /= s;
  }
}

template <class T>
void softmax_backward(T* din, const T* dout, const T* out, int M, int N) {
  using V = detail::simd<T>;
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t n = std::size_t(N);
  TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(M) * n > detail::parallel_grain))
  for (int m = 0; m < M; ++m) {
    const T* y = out + std::size_t(m) * n;
    const T* g = dout + std::size_t(m) * n;
    T* dx = din + std::size_t(m) * n;
    const T s = detail::simd_dot(g, y, n);
    const V vs(s);
    std::size_t i = 0;
    for (; i + W <= n; i += W) {
      const V yv = xsimd::load_unaligned(y + i);
      xsimd::fma(yv, xsimd::load_unaligned(g + i) - vs, xsimd::load_unaligned(dx + i)).store_unaligned(dx + i);
    }
    for (; i < n; ++i) dx[i] += y[i] * (g[i] - s);
  }
}

}  // namespace tjepa::kernels
