#pragma once
// Small xsimd helpers: the native vector type and width, exp2, horizontal sum and max, and the
// row reductions and updates of the row-wise kernels (LayerNorm, GELU, softmax, the shared-query
// cross-attention); the attention kernels (kernels/detail/attention_simd.hpp) use the same
// vector type. Every loop runs whole vectors, then a scalar tail, so any length works.
//
// The element-wise loops of the hot paths are written with these rather than left to the
// auto-vectorizer, whose reach depends on the including program's flags: g++ 12 at -O2 (CMake's
// RelWithDebInfo, Debian's default) vectorizes only loops whose trip count it knows at compile
// time (bench/RESULTS.md, "The user's -O2"). Each gives the bits of the plain loop (element-wise;
// a·x + y fused, as g++ contracts it).
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "tjepa/core/detail/vendor.hpp"

// Functions marked TJEPA_PROFILE_INLINE are inline; a build with TJEPA_PROFILE_SYMBOLS defined
// keeps them out of line, so that a sampling profile names them (bench/profile.sh: attention's
// products, the GEMM epilogue, its GELU and its bf16 conversion of A apart from the products).
#ifdef TJEPA_PROFILE_SYMBOLS
#define TJEPA_PROFILE_INLINE [[gnu::noinline]] inline
#else
#define TJEPA_PROFILE_INLINE inline
#endif

namespace tjepa::detail {

template <class T>
using simd = xsimd::batch<T>;
template <class T>
inline constexpr std::size_t simd_width = xsimd::batch<T>::size;

// exp2 on a batch, for arguments <= 0 as the softmax (x <= 0 after subtracting the row maximum)
// and the GELU's Gaussian use them. 2^x = 2^n * 2^f with n = round(x), f in [-1/2, 1/2]; 2^f by a
// polynomial (Cephes exp2f in float, Taylor of degree 13 in double: both within ~1-2 ulp), 2^n by
// writing the exponent bits. Arguments below the smallest normal exponent (and -inf) give exactly 0.
template <class T>
struct Exp2Traits;

template <>
struct Exp2Traits<float> {
  using Int = std::int32_t;
  static constexpr float lo = -127.0f, hi = 127.0f;
  static constexpr float flush = -151.0f;  // 2^flush rounds to 0 (smallest subnormal 2^-149)
  static constexpr float magic = 0x1.8p23f;  // adding it rounds to an integer in the low bits
  static constexpr Int bias = 127;
  static constexpr int mant = 23;
  [[gnu::always_inline]] static simd<float> poly(simd<float> f) {
    simd<float> p(1.535336188319500e-4f);
    p = xsimd::fma(p, f, simd<float>(1.339887440266574e-3f));
    p = xsimd::fma(p, f, simd<float>(9.618437357674640e-3f));
    p = xsimd::fma(p, f, simd<float>(5.550332471162809e-2f));
    p = xsimd::fma(p, f, simd<float>(2.402264791363012e-1f));
    p = xsimd::fma(p, f, simd<float>(6.931472028550421e-1f));
    return xsimd::fma(p, f, simd<float>(1.0f));
  }
};

template <>
struct Exp2Traits<double> {
  using Int = std::int64_t;
  static constexpr double lo = -1023.0, hi = 1023.0;
  static constexpr double flush = -1076.0;  // 2^flush rounds to 0 (smallest subnormal 2^-1074)
  static constexpr double magic = 0x1.8p52;
  static constexpr Int bias = 1023;
  static constexpr int mant = 52;
  [[gnu::always_inline]] static simd<double> poly(simd<double> f) {
    // sum_k (ln 2)^k / k! f^k, k = 0..13: truncation error < 1e-17 on |f| <= 1/2.
    constexpr double c[14] = {1.0,
                              0.6931471805599453094,
                              0.2402265069591007123,
                              0.05550410866482157995,
                              0.009618129107628477161,
                              0.001333355814642844343,
                              0.0001540353039338160995,
                              1.525273380405984028e-05,
                              1.321548679014430806e-06,
                              1.017808600923969972e-07,
                              7.054911620801123329e-09,
                              4.445538271870811497e-10,
                              2.567843599348820521e-11,
                              1.369104011201429164e-12};
    simd<double> p(c[13]);
    for (int k = 12; k >= 0; --k) p = xsimd::fma(p, f, simd<double>(c[k]));
    return p;
  }
};

// Always inlined: at -O2 g++ kept it out of line in the softmax loops.
template <class T>
[[gnu::always_inline]] inline simd<T> exp2(simd<T> x) {
  using Tr = Exp2Traits<T>;
#if defined(__AVX512F__)
  if constexpr (sizeof(simd<T>) == 64) {
    // AVX-512: round with vrndscale, multiply by 2^n with vscalef (which also flushes 2^-150 and
    // below to 0), no integer domain crossing. The low clamp keeps f finite for x = -inf.
    x = xsimd::max(x, simd<T>(Tr::flush));
    if constexpr (std::is_same_v<T, float>) {
      const __m512 n = _mm512_roundscale_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
      const __m512 p = Tr::poly(simd<T>(_mm512_sub_ps(x, n)));
      return simd<T>(_mm512_scalef_ps(p, n));
    } else {
      const __m512d n = _mm512_roundscale_pd(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
      const __m512d p = Tr::poly(simd<T>(_mm512_sub_pd(x, n)));
      return simd<T>(_mm512_scalef_pd(p, n));
    }
  }
#endif
  using IV = xsimd::batch<typename Tr::Int>;
  x = xsimd::min(xsimd::max(x, simd<T>(Tr::lo)), simd<T>(Tr::hi));  // also maps -inf to lo
  const simd<T> t = x + simd<T>(Tr::magic);                         // low bits of t hold round(x)
  const simd<T> n = t - simd<T>(Tr::magic);
  const simd<T> f = x - n;
  // bits(t) = bits(magic) + n; shifting out the high bits leaves (n + bias) in the exponent field.
  const IV e = (xsimd::bitwise_cast<IV>(t) + IV(Tr::bias)) << Tr::mant;
  return Tr::poly(f) * xsimd::bitwise_cast<simd<T>>(e);
}

// Horizontal sum and max through memory: xsimd 8.1 has no horizontal max, and g++ 12 reports a
// false maybe-uninitialized inside its AVX-512 hadd for double.
template <class T>
T hsum(simd<T> v) {
  alignas(64) T lanes[simd_width<T>];
  v.store_aligned(lanes);
  T s = lanes[0];
  for (std::size_t i = 1; i < simd_width<T>; ++i) s += lanes[i];
  return s;
}
template <class T>
T hmax(simd<T> v) {
  alignas(64) T lanes[simd_width<T>];
  v.store_aligned(lanes);
  T m = lanes[0];
  for (std::size_t i = 1; i < simd_width<T>; ++i) m = m > lanes[i] ? m : lanes[i];
  return m;
}

// Σ x[i]
template <class T>
[[gnu::always_inline]] inline T simd_sum(const T* x, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  simd<T> acc(T(0));
  std::size_t i = 0;
  for (; i + W <= n; i += W) acc += xsimd::load_unaligned(x + i);
  T s = hsum(acc);
  for (; i < n; ++i) s += x[i];
  return s;
}

// Σ x[i]·y[i]
template <class T>
[[gnu::always_inline]] inline T simd_dot(const T* x, const T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  simd<T> acc(T(0));
  std::size_t i = 0;
  for (; i + W <= n; i += W) acc = xsimd::fma(xsimd::load_unaligned(x + i), xsimd::load_unaligned(y + i), acc);
  T s = hsum(acc);
  for (; i < n; ++i) s += x[i] * y[i];
  return s;
}

// y[i] += a·x[i]
template <class T>
[[gnu::always_inline]] inline void simd_axpy(T a, const T* x, T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  const simd<T> va(a);
  std::size_t i = 0;
  for (; i + W <= n; i += W)
    xsimd::fma(va, xsimd::load_unaligned(x + i), xsimd::load_unaligned(y + i)).store_unaligned(y + i);
  for (; i < n; ++i) y[i] += a * x[i];
}

// y[i] += x[i]
template <class T>
[[gnu::always_inline]] inline void simd_add(const T* x, T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  std::size_t i = 0;
  for (; i + W <= n; i += W) (xsimd::load_unaligned(y + i) + xsimd::load_unaligned(x + i)).store_unaligned(y + i);
  for (; i < n; ++i) y[i] += x[i];
}

// y[i] = a·x[i] (y may be x)
template <class T>
[[gnu::always_inline]] inline void simd_scale(T a, const T* x, T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  const simd<T> va(a);
  std::size_t i = 0;
  for (; i + W <= n; i += W) (xsimd::load_unaligned(x + i) * va).store_unaligned(y + i);
  for (; i < n; ++i) y[i] = x[i] * a;
}

// y[i] = x[i]
template <class T>
[[gnu::always_inline]] inline void simd_copy(const T* x, T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  std::size_t i = 0;
  for (; i + W <= n; i += W) xsimd::load_unaligned(x + i).store_unaligned(y + i);
  for (; i < n; ++i) y[i] = x[i];
}

// y[i] = v
template <class T>
[[gnu::always_inline]] inline void simd_fill(T* y, std::size_t n, T v) {
  constexpr std::size_t W = simd_width<T>;
  const simd<T> vv(v);
  std::size_t i = 0;
  for (; i + W <= n; i += W) vv.store_unaligned(y + i);
  for (; i < n; ++i) y[i] = v;
}

}  // namespace tjepa::detail
