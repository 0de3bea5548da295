#pragma once
// Gather of rows by index, and its gradient, a scatter-add.
//   out[b, k, :] (=|+=) src[b, idx[b, k], :]
// src is [B, N, C] with src_batch = N·C, or one table [N, C] shared by every sample with
// src_batch = 0 (position rows). Indices are trusted (the API boundary checks them).
#include <algorithm>
#include <cstddef>

#include "tjepa/core/detail/parallel.hpp"

namespace tjepa::kernels {

template <class T>
void gather_rows(T* out, const T* src, std::size_t src_batch, const int* idx, int B, int K, int C) {
  TJEPA_OMP(omp parallel for schedule(static) if (B > 1 && std::size_t(B) * K * C > detail::parallel_grain))
  for (int b = 0; b < B; ++b)
    for (int k = 0; k < K; ++k) {
      const T* s = src + b * src_batch + std::size_t(idx[std::size_t(b) * K + k]) * C;
      std::copy(s, s + C, out + (std::size_t(b) * K + k) * C);
    }
}

template <class T>
void gather_add_rows(T* out, const T* src, std::size_t src_batch, const int* idx, int B, int K, int C) {
  TJEPA_OMP(omp parallel for schedule(static) if (B > 1 && std::size_t(B) * K * C > detail::parallel_grain))
  for (int b = 0; b < B; ++b)
    for (int k = 0; k < K; ++k) {
      const T* s = src + b * src_batch + std::size_t(idx[std::size_t(b) * K + k]) * C;
      T* o = out + (std::size_t(b) * K + k) * C;
      detail::simd_add(s, o, std::size_t(C));
    }
}

// Differentiates either gather: dsrc[b, idx[b, k], :] += dout[b, k, :]. Repeated indices add up.
// With a shared table (src_batch = 0) samples write the same rows, so the loop is serial.
template <class T>
void scatter_add_rows(T* dsrc, std::size_t src_batch, const T* dout, const int* idx, int B, int K, int C) {
  TJEPA_OMP(omp parallel for schedule(static) if (src_batch > 0 && std::size_t(B) * K * C > detail::parallel_grain))
  for (int b = 0; b < B; ++b)
    for (int k = 0; k < K; ++k) {
      T* d = dsrc + b * src_batch + std::size_t(idx[std::size_t(b) * K + k]) * C;
      const T* g = dout + (std::size_t(b) * K + k) * C;
      for (int c = 0; c < C; ++c) d[c] += g[c];
    }
}

}  // namespace tjepa::kernels
