#pragma once
// Exact GELU (PyTorch nn.GELU(), approximate='none'): gelu(x) = x · Φ(x) = x/2 · (1 + erf(x/√2)),
// gelu'(x) = Φ(x) + x · φ(x). Element-wise on n values; the MLP's fc1 bias is fused into it.
#include <cmath>
#include <cstddef>
#include <numbers>

#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/detail/simd.hpp"

namespace tjepa::kernels {

}  // namespace tjepa::kernels

namespace tjepa::detail {
template <class T>
inline constexpr T inv_sqrt2 = T(0.70710678118654752440084436210484903928);
template <class T>
inline constexpr T inv_sqrt_2pi = T(0.39894228040143267793994605993438186848);

template <class T>
T gelu_grad(T x) {
  return T(0.5) * (T(1) + std::erf(x * inv_sqrt2<T>)) + x * inv_sqrt_2pi<T> * std::exp(T(-0.5) * x * x);
}
template <class T>
simd<T> gelu(simd<T> x) {
  return T(0.5) * x * (T(1) + xsimd::erf(x * simd<T>(inv_sqrt2<T>)));
}
template <class T>
simd<T> gelu_grad(simd<T> x) {
  return T(0.5) * (T(1) + xsimd::erf(x * simd<T>(inv_sqrt2<T>))) +
         x * simd<T>(inv_sqrt_2pi<T>) * xsimd::exp(T(-0.5) * x * x);
}
}  // namespace tjepa::detail

namespace tjepa::kernels {

namespace ref {
template <class T>
void gelu_forward(T* out, const T* in, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) out[i] = T(0.5) * in[i] * (T(1) + std::erf(in[i] * detail::inv_sqrt2<T>));
}
template <class T>
void gelu_backward(T* din, const T* dout, const T* in, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) din[i] += dout[i] * detail::gelu_grad(in[i]);
}
}  // namespace ref

// out[n] = gelu(in[n]); out may alias in.
template <class T>
void gelu_forward(T* out, const T* in, std::size_t n) {
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t nv = n / W;
  TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
  for (std::size_t j = 0; j < nv; ++j)
    detail::gelu<T>(xsimd::load_unaligned(in + j * W)).store_unaligned(out + j * W);
  ref::gelu_forward(out + nv * W, in + nv * W, n - nv * W);
}

// din[n] += dout ⊙ gelu'(in).
template <class T>
void gelu_backward(T* din, const T* dout, const T* in, std::size_t n) {
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t nv = n / W;
  TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
  for (std::size_t j = 0; j < nv; ++j) {
    const std::size_t i = j * W;
    const auto d = xsimd::load_unaligned(din + i) +
                   xsimd::load_unaligned(dout + i) * detail::gelu_grad<T>(xsimd::load_unaligned(in + i));
    d.store_unaligned(din + i);
  }
  ref::gelu_backward(din + nv * W, dout + nv * W, in + nv * W, n - nv * W);
}

// fc1's epilogue, one pass over [M, N]: pre += b (the pre-activation backward needs), then
// out = gelu(pre). out may alias pre (inference keeps only the activation).
template <class T>
void bias_gelu_forward(T* out, T* pre, const T* b, int M, int N) {
  using V = detail::simd<T>;
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t n = std::size_t(N);
  TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(M) * n > detail::parallel_grain))
  for (int m = 0; m < M; ++m) {
    T* p = pre + std::size_t(m) * n;
    T* o = out + std::size_t(m) * n;
    std::size_t i = 0;
    for (; i + W <= n; i += W) {
      V x = xsimd::load_unaligned(p + i);
      if (b) x += xsimd::load_unaligned(b + i);
      x.store_unaligned(p + i);
      detail::gelu<T>(x).store_unaligned(o + i);
    }
    for (; i < n; ++i) {
      if (b) p[i] += b[i];
      o[i] = T(0.5) * p[i] * (T(1) + std::erf(p[i] * detail::inv_sqrt2<T>));
    }
  }
}

}  // namespace tjepa::kernels
