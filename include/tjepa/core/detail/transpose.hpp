#pragma once
// A 16 x 16 block of 32-bit values (floats, or the bf16 pairs of detail/bgemm.hpp) transposed in
// registers (AVX-512: 64 shuffles instead of 256 scalar loads and stores), for the packing
// routines that turn rows into columns: the GEMMs' weight panels (detail/sgemm.hpp and
// detail/bgemm.hpp, a PyTorch weight [out, in] read as its transpose) and the attention kernels'
// Q^T panels (kernels/detail/attention_simd.hpp). Without AVX-512 the same function runs
// as scalar loops, so callers need no second path; kTranspose16Native says which one compiled.
#include <cstddef>
#include <type_traits>

#if defined(__AVX512F__)
#include <immintrin.h>
#endif

namespace tjepa::detail {

#if defined(__AVX512F__)
inline constexpr bool kTranspose16Native = true;
#else
inline constexpr bool kTranspose16Native = false;
#endif

// dst[c * ldd + r] = row(r)[c] for r, c in [0, 16). row(r) returns a const T* to 16 readable
// values (any alignment); dst rows need not be aligned. T: any 4-byte trivially copyable type (the
// shuffles move bits, they do no arithmetic).
template <class T, class Row>
inline void transpose16(Row&& row, T* dst, std::ptrdiff_t ldd) {
  static_assert(sizeof(T) == 4 && std::is_trivially_copyable_v<T>, "transpose16: 32-bit values");
#if defined(__AVX512F__)
  // Unrolled by pragma: g++ -O2 does not unroll these loops itself, and r and t then live on the
  // stack instead of in registers.
  __m512 r[16], t[16];
#pragma GCC unroll 16
  for (int i = 0; i < 16; ++i) r[i] = _mm512_loadu_ps(static_cast<const void*>(row(i)));
  // Stage 1: interleave pairs of rows (32-bit elements).
#pragma GCC unroll 16
  for (int i = 0; i < 16; i += 2) {
    t[i] = _mm512_unpacklo_ps(r[i], r[i + 1]);
    t[i + 1] = _mm512_unpackhi_ps(r[i], r[i + 1]);
  }
  // Stage 2: interleave pairs of pairs (64-bit elements).
  auto lo64 = [](__m512 a, __m512 b) {
    return _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)));
  };
  auto hi64 = [](__m512 a, __m512 b) {
    return _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(a), _mm512_castps_pd(b)));
  };
#pragma GCC unroll 16
  for (int i = 0; i < 16; i += 4) {
    r[i] = lo64(t[i], t[i + 2]);
    r[i + 1] = hi64(t[i], t[i + 2]);
    r[i + 2] = lo64(t[i + 1], t[i + 3]);
    r[i + 3] = hi64(t[i + 1], t[i + 3]);
  }
  // Now r[4g + j] holds, in its 128-bit lane L, rows 4g..4g+3 of column 4L + j.
  // Stage 3 (shuffle_f32x4 0x88: lanes 0, 2 of a then of b; 0xdd: lanes 1, 3): t[g + j] holds
  // columns j and 8 + j, t[g + 4 + j] columns 4 + j and 12 + j, of rows g..g+7.
#pragma GCC unroll 2
  for (int g = 0; g < 16; g += 8)
#pragma GCC unroll 4
    for (int j = 0; j < 4; ++j) {
      t[g + j] = _mm512_shuffle_f32x4(r[g + j], r[g + 4 + j], 0x88);
      t[g + 4 + j] = _mm512_shuffle_f32x4(r[g + j], r[g + 4 + j], 0xdd);
    }
  // Stage 4: rows 0-7 with rows 8-15; r[j] is column j.
#pragma GCC unroll 8
  for (int j = 0; j < 8; ++j) {
    r[j] = _mm512_shuffle_f32x4(t[j], t[8 + j], 0x88);
    r[8 + j] = _mm512_shuffle_f32x4(t[j], t[8 + j], 0xdd);
  }
#pragma GCC unroll 16
  for (int j = 0; j < 16; ++j) _mm512_storeu_ps(static_cast<void*>(dst + j * ldd), r[j]);
#else
  for (int i = 0; i < 16; ++i) {
    const T* s = row(i);
    for (int c = 0; c < 16; ++c) dst[c * ldd + i] = s[c];
  }
#endif
}

}  // namespace tjepa::detail
