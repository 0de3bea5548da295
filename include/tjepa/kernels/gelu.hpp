#pragma once
// Exact GELU (PyTorch nn.GELU(), approximate='none'): gelu(x) = x · Φ(x) = x/2 · (1 + erf(x/√2)),
// gelu'(x) = Φ(x) + x · φ(x). Element-wise on n values; the MLP's fc1 bias is fused into it.
#include <cmath>
#include <cstddef>
#include <numbers>
#include <type_traits>

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
// erf of a vector. float: Eigen 3.4's generic_fast_erf_float (SpecialFunctionsImpl.h), a rational
// fit, odd degree 13 over even degree 8, on [-4, 4] (beyond, erf is ±1 in float): within 3.7e-7 of
// erf at -O2, 4.2e-7 in the -O1 sanitizer build (3 to 7 ulp of the result; PyTorch's own
// vectorized CPU erf, Abramowitz-Stegun 7.1.26, is within 1.5e-7) in a twelfth of xsimd::erf's
// time, which took a tenth of a training step in the MLPs' GELUs. double: xsimd::erf (the
// gradient checks run in double).
template <class T>
simd<T> erf(simd<T> a) {
  if constexpr (std::is_same_v<T, float>) {
    using V = simd<float>;
    const V x = xsimd::max(xsimd::min(a, V(4.0f)), V(-4.0f)), x2 = x * x;
    V p = xsimd::fma(x2, V(-2.72614225801306e-10f), V(2.77068142495902e-08f));
    p = xsimd::fma(x2, p, V(-2.10102402082508e-06f));
    p = xsimd::fma(x2, p, V(-5.69250639462346e-05f));
    p = xsimd::fma(x2, p, V(-7.34990630326855e-04f));
    p = xsimd::fma(x2, p, V(-2.95459980854025e-03f));
    p = xsimd::fma(x2, p, V(-1.60960333262415e-02f));
    V q = xsimd::fma(x2, V(-1.45660718464996e-05f), V(-2.13374055278905e-04f));
    q = xsimd::fma(x2, q, V(-1.68282697438203e-03f));
    q = xsimd::fma(x2, q, V(-7.37332916720468e-03f));
    q = xsimd::fma(x2, q, V(-1.42647390514189e-02f));
    return x * p / q;
  } else {
    return xsimd::erf(a);
  }
}
template <class T>
TJEPA_PROFILE_INLINE simd<T> gelu(simd<T> x) {
  return T(0.5) * x * (T(1) + erf<T>(x * simd<T>(inv_sqrt2<T>)));
}
// φ(x)·√(2π) = e^(-x²/2) = 2^(-x²/2 · log2 e), by the softmax's exp2 (half xsimd::exp's time:
// no overflow and NaN selects). Rounding the argument adds about 3e-7 relative at |x| = 3; gelu'
// in float stays within 2.1e-7 of the exact value on [-20, 20], as with xsimd::exp (the erf
// dominates).
template <class T>
simd<T> gaussian(simd<T> x) {
  return exp2<T>(x * x * simd<T>(T(-0.5) * std::numbers::log2e_v<T>));
}
// gelu(x) (the same value as gelu()) and gelu'(x) from one erf.
template <class T>
void gelu_and_grad(simd<T> x, simd<T>& g, simd<T>& dg) {
  const simd<T> e = T(1) + erf<T>(x * simd<T>(inv_sqrt2<T>));
  g = T(0.5) * x * e;
  dg = T(0.5) * e + x * simd<T>(inv_sqrt_2pi<T>) * gaussian<T>(x);
}
template <class T>
simd<T> gelu_grad(simd<T> x) {
  simd<T> g, dg;
  gelu_and_grad<T>(x, g, dg);
  return dg;
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

// out[n] = gelu(in[n]) and grad[n] = gelu'(in[n]) in one pass: the MLP's backward, which
// recomputes its activation and needs the derivative at the same points. grad may alias in.
template <class T>
void gelu_forward_grad(T* out, T* grad, const T* in, std::size_t n) {
  constexpr std::size_t W = detail::simd_width<T>;
  const std::size_t nv = n / W;
  TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
  for (std::size_t j = 0; j < nv; ++j) {
    detail::simd<T> g, dg;
    detail::gelu_and_grad<T>(xsimd::load_unaligned(in + j * W), g, dg);
    g.store_unaligned(out + j * W);
    dg.store_unaligned(grad + j * W);
  }
  for (std::size_t i = nv * W; i < n; ++i) {
    const T x = in[i];
    ref::gelu_forward(out + i, &x, 1);
    grad[i] = detail::gelu_grad(x);
  }
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
