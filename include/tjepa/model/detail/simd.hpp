#pragma once
// Small xsimd helpers shared by the row-wise kernels (LayerNorm, GELU, softmax). Every loop runs
// whole vectors, then a scalar tail, so any length works.
#include <cstddef>

#include <xsimd/xsimd.hpp>

namespace tjepa::detail {

template <class T>
using simd = xsimd::batch<T>;
template <class T>
inline constexpr std::size_t simd_width = xsimd::batch<T>::size;

// Σ x[i]
template <class T>
T simd_sum(const T* x, std::size_t n) {
  constexpr std::size_t W = simd_width<T>;
  simd<T> acc(T(0));
  std::size_t i = 0;
  for (; i + W <= n; i += W) acc += xsimd::load_unaligned(x + i);
  T s = xsimd::reduce_add(acc);
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
  T s = xsimd::reduce_add(acc);
  for (; i < n; ++i) s += x[i] * y[i];
  return s;
}

}  // namespace tjepa::detail
