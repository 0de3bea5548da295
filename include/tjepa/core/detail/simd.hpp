#pragma once
// Small xsimd helpers: the native vector type and width, horizontal sum and max, and the row
// reductions and updates of the row-wise kernels (LayerNorm, GELU, softmax, the shared-query
// cross-attention); the attention kernels (kernels/detail/attention_simd.hpp) use the same
// vector type. Every loop runs whole vectors, then a scalar tail, so any length works.
#include <cstddef>

#include "tjepa/core/detail/vendor.hpp"

namespace tjepa::detail {

template <class T>
using simd = xsimd::batch<T>;
template <class T>
inline constexpr std::size_t simd_width = xsimd::batch<T>::size;

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
T simd_sum(const T* x, std::size_t n) {
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
T simd_dot(const T* x, const T* y, std::size_t n) {
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
void simd_axpy(T a, const T* x, T* y, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  const simd<T> va(a);
  std::size_t i = 0;
  for (; i + W <= n; i += W)
    xsimd::fma(va, xsimd::load_unaligned(x + i), xsimd::load_unaligned(y + i)).store_unaligned(y + i);
  for (; i < n; ++i) y[i] += a * x[i];
}

}  // namespace tjepa::detail
