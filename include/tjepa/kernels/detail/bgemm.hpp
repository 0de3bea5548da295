#pragma once
// bf16 GEMM: C[rows, cols] (+)= bf16(A) · bf16(B) with fp32 accumulation and sgemm's epilogues
// (bias, residual, GELU, GELU'), on AVX512-BF16's vdpbf16ps, which does two multiply-adds per
// fp32 lane per instruction: twice an fp32 FMA's.
//
// Operands are rounded to bfloat16 (round to nearest even, denormals to zero: what
// vcvtneps2bf16 does) and their products summed in fp32. B is packed into panels of NR columns
// whose entries are pairs of consecutive depths, [depth/2][NR] 32-bit words (low half: the even
// depth); A is converted into pairs too (row-major A per MR-row × KC-depth block, [MR][KC/2];
// column-major A, the weight gradients' dYᵀ, per CH rows × KC-depth block, [KC/2][CH], 16 rows
// per conversion), then each pair is broadcast against the panel:
// acc[i][j] += a(i, 2p)·b(2p, j) + a(i, 2p+1)·b(2p+1, j).
// Blocking, threading and the epilogue are sgemm's (sgemm.hpp).
//
// Where the translation unit is compiled without AVX512-BF16 (`native` is false), the bf16
// products fall back to the float GEMM at compile time: Precision::bf16 then computes in fp32
// (resolve()).
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <type_traits>
#include <utility>

#include "tjepa/core/error.hpp"
#include "tjepa/kernels/detail/amx.hpp"
#include "tjepa/kernels/detail/sgemm.hpp"

#include "tjepa/kernels/precision.hpp"

#if TJEPA_BF16_NATIVE
#include <immintrin.h>
#endif

namespace tjepa::detail::bgemm {

using sgemm::Epilogue;
using sgemm::Order;

inline constexpr bool native = TJEPA_BF16_NATIVE != 0;

// The precision a product runs in on this build: bf16 without the instructions runs fp32.
constexpr Precision resolve(Precision p, bool have_bf16 = native) {
  return p == Precision::bf16 && have_bf16 ? Precision::bf16 : Precision::fp32;
}

// bfloat16 bits of x as vcvtneps2bf16 makes them: round to nearest even, a denormal to a zero of
// its sign, a NaN to a quiet NaN, overflow to infinity.
inline std::uint16_t to_bf16(float x) {
  std::uint32_t u = std::bit_cast<std::uint32_t>(x);
  if ((u & 0x7f800000u) == 0) return std::uint16_t((u >> 16) & 0x8000u);
  if ((u & 0x7fffffffu) > 0x7f800000u) return std::uint16_t((u >> 16) | 0x40u);
  u += 0x7fffu + ((u >> 16) & 1u);
  return std::uint16_t(u >> 16);
}
inline float from_bf16(std::uint16_t h) { return std::bit_cast<float>(std::uint32_t(h) << 16); }
inline float round_bf16(float x) { return from_bf16(to_bf16(x)); }
// Two depths of one column (or row) as the 32-bit word vdpbf16ps reads: lo in the low half.
inline std::uint32_t pair(float lo, float hi) { return std::uint32_t(to_bf16(lo)) | std::uint32_t(to_bf16(hi)) << 16; }

// Tiles: 16 fp32 lanes per vector; an MR × NV·16 block of C in 24 of the 32 registers (sgemm's).
inline constexpr int L = 16;
inline constexpr int MR = 6;
inline constexpr int NV = 4;
inline constexpr int NR = NV * L;
inline constexpr int KC = 1024;  // depths per block (even): 128 KiB of a panel, A's 6 rows 12 KiB
// Rows of column-major A converted at a time: whole row blocks (MR) and whole conversions (16),
// their depth block 96 KiB.
inline constexpr int CH = 48;
static_assert(CH % MR == 0 && CH % L == 0);

inline int depth_pairs(int depth) { return (depth + 1) / 2; }
inline std::size_t packed_size(int cols, int depth) {
  return std::size_t((cols + NR - 1) / NR) * std::size_t(depth_pairs(depth)) * NR;
}

// B(k, n) = b[k·ldb + n] (row-major) or b[n·ldb + k] (column-major: a PyTorch weight [cols,
// depth] read as its transpose), depth pairs [p0, p1) of panel p → dst [panels][depth/2][NR]
// (zero beyond cols and beyond an odd depth). The scalar specification of pack_panel below.
inline void pack_panel_ref(std::uint32_t* dst, const float* b, std::ptrdiff_t ldb, Order order, int depth, int cols,
                           int p, int p0, int p1) {
  const int n0 = p * NR, nc = std::min(NR, cols - n0);
  std::uint32_t* d = dst + std::ptrdiff_t(p) * depth_pairs(depth) * NR;
  auto at = [&](int k, int n) {
    if (k >= depth) return 0.0f;
    return order == Order::row_major ? b[std::ptrdiff_t(k) * ldb + n] : b[std::ptrdiff_t(n) * ldb + k];
  };
  for (int q = p0; q < p1; ++q) {
    std::uint32_t* o = d + std::ptrdiff_t(q) * NR;
    for (int j = 0; j < nc; ++j) o[j] = pair(at(2 * q, n0 + j), at(2 * q + 1, n0 + j));
    std::fill(o + nc, o + NR, 0u);
  }
}

#if TJEPA_BF16_NATIVE
static_assert(sgemm::NR == NR && sgemm::MR == MR, "bgemm shares sgemm's tile epilogue and row split");

inline __mmask16 first_lanes(int n) { return n >= L ? __mmask16(0xffff) : n <= 0 ? __mmask16(0) : __mmask16((1u << n) - 1); }

// _mm512_cvtne2ps_pbh(hi, lo) (lo's 16 bf16 in the low half, hi's in the high) as the 16 words
// (lo[j], hi[j]), by vpermw.
inline __m512i interleave_pairs(__m512bh hi_lo) {
  alignas(64) static constexpr std::uint16_t interleave[32] = {0, 16, 1, 17, 2,  18, 3,  19, 4,  20, 5,
                                                                21, 6, 22, 7, 23, 8, 24, 9, 25, 10, 26,
                                                                11, 27, 12, 28, 13, 29, 14, 30, 15, 31};
  return _mm512_permutexvar_epi16(_mm512_load_si512(interleave), std::bit_cast<__m512i>(hi_lo));
}
// The pairs (lo[j], hi[j]) of the first n < 17 lanes as 16 words (zero beyond n; hi = nullptr:
// zero high halves): both rows converted by one vcvtne2ps2bf16, then interleaved.
inline __m512i pairs16(const float* lo, const float* hi, int n) {
  const __mmask16 m = first_lanes(n);
  const __m512 l = _mm512_maskz_loadu_ps(m, lo), h = hi ? _mm512_maskz_loadu_ps(m, hi) : _mm512_setzero_ps();
  return interleave_pairs(_mm512_cvtne2ps_pbh(h, l));
}
// The n < 33 consecutive values x[0, n) as ⌈n/2⌉ words, in order (zero beyond n).
inline __m512i row_pairs(const float* x, int n) {
  return std::bit_cast<__m512i>(
      _mm512_cvtne2ps_pbh(_mm512_maskz_loadu_ps(first_lanes(n - L), x + L), _mm512_maskz_loadu_ps(first_lanes(n), x)));
}

// 16 rows of n < 33 values each (row(i): a const float*) as their ⌈n/2⌉ ≤ 16 pair words,
// transposed: dst[q·ldd + i] = word q of row i, q < words (the packing of B panels and of
// attention's Q^T pairs; a whole block of 16 words in registers, transpose16).
template <class Row>
inline void pairs_transposed16(Row&& row, int n, std::uint32_t* dst, std::ptrdiff_t ldd) {
  alignas(64) std::uint32_t block[L][L];
  for (int i = 0; i < L; ++i) _mm512_store_si512(block[i], row_pairs(row(i), n));
  const int words = (n + 1) / 2;
  if (words == L) {
    transpose16([&](int i) { return static_cast<const std::uint32_t*>(block[i]); }, dst, ldd);
    return;
  }
  for (int i = 0; i < L; ++i)
    for (int q = 0; q < words; ++q) dst[q * ldd + i] = block[i][q];
}

// pack_panel_ref's result, vectorized: row-major B converts two depths × 16 columns per step;
// column-major B converts 32 depths of a column per step and stores its words down the panel.
inline void pack_panel(std::uint32_t* dst, const float* b, std::ptrdiff_t ldb, Order order, int depth, int cols, int p,
                       int p0, int p1) {
  const int n0 = p * NR, nc = std::min(NR, cols - n0);
  std::uint32_t* d = dst + std::ptrdiff_t(p) * depth_pairs(depth) * NR;
  if (order == Order::row_major) {
    for (int q = p0; q < p1; ++q) {
      const float* lo = b + std::ptrdiff_t(2 * q) * ldb + n0;
      const float* hi = 2 * q + 1 < depth ? lo + ldb : nullptr;
#pragma GCC unroll 4
      for (int j = 0; j < NV; ++j)
        _mm512_store_si512(d + std::ptrdiff_t(q) * NR + j * L, pairs16(lo + j * L, hi ? hi + j * L : nullptr, nc - j * L));
    }
    return;
  }
  // Column j's pairs [qa, qb) (zero past nc).
  auto column = [&](int j, int qa, int qb) {
    if (j >= nc) {
      for (int q = qa; q < qb; ++q) d[std::ptrdiff_t(q) * NR + j] = 0u;
      return;
    }
    const float* col = b + std::ptrdiff_t(n0 + j) * ldb;
    for (int q0 = qa; q0 < qb; q0 += L) {
      alignas(64) std::uint32_t w[L];
      _mm512_store_si512(w, row_pairs(col + 2 * q0, std::min(2 * L, depth - 2 * q0)));
      for (int q = q0; q < std::min(qb, q0 + L); ++q) d[std::ptrdiff_t(q) * NR + j] = w[q - q0];
    }
  };
  // 16 columns x 16 pairs at a time: converted row by row, then transposed in registers.
  int j = 0;
  for (; j + L <= nc; j += L) {
    int q0 = p0;
    for (; q0 + L <= p1; q0 += L)  // 16 pairs: 2q0 + 32 <= 2p1 <= depth + 1, so n = 31 or 32
      pairs_transposed16([&](int i) { return b + std::ptrdiff_t(n0 + j + i) * ldb + 2 * q0; },
                         std::min(2 * L, depth - 2 * q0), d + std::ptrdiff_t(q0) * NR + j, NR);
    for (int i = 0; i < L && q0 < p1; ++i) column(j + i, q0, p1);
  }
  for (; j < NR; ++j) column(j, p0, p1);
}

// Row-major A's rows [0, R) × depths [0, kc) as bf16 pairs for the micro-kernel, a(i, k) =
// a[i·ars + k] → dst [R][kc/2] (row stride ld ≥ kc/2 words; 32 depths of a row per conversion).
// Zero high halves after an odd kc.
TJEPA_PROFILE_INLINE void pack_a(std::uint32_t* dst, int R, int kc, const float* a, std::ptrdiff_t ars,
                                 std::ptrdiff_t ld) {
  for (int i = 0; i < R; ++i)
    for (int k = 0; k < kc; k += 2 * L)
      _mm512_mask_storeu_epi32(dst + i * ld + k / 2, first_lanes((std::min(2 * L, kc - k) + 1) / 2),
                               row_pairs(a + i * ars + k, std::min(2 * L, kc - k)));
}

// Column-major A's rows [0, R) × depths [0, kc), a(i, k) = a[k·acs + i], as bf16 pairs along
// depth → dst [kc/2][ld] (ld ≥ R, a multiple of 16; dst 64-byte aligned): two depths × 16 rows
// per conversion, zero past R and in the high halves after an odd kc. Converted for CH rows at
// once: per 6-row block, as row-major A is, a conversion would fill 6 of its 16 lanes.
TJEPA_PROFILE_INLINE void pack_a_cols(std::uint32_t* dst, std::ptrdiff_t ld, int R, int kc, const float* a, std::ptrdiff_t acs) {
  for (int q = 0; q < depth_pairs(kc); ++q) {
    const float* lo = a + std::ptrdiff_t(2 * q) * acs;
    const float* hi = 2 * q + 1 < kc ? lo + acs : nullptr;
    // The depths 8 pairs ahead: a call's first chunk comes cold (the products before each later
    // chunk prefetched it, and these prefetches then hit the cache).
    if (2 * q + 17 < kc)
      for (int i = 0; i < R; i += L) {
        __builtin_prefetch(lo + 16 * acs + i);
        __builtin_prefetch(lo + 17 * acs + i);
      }
    for (int i = 0; i < R; i += L)
      _mm512_store_si512(dst + q * ld + i, pairs16(lo + i, hi ? hi + i : nullptr, std::min(L, R - i)));
  }
}

// 32 bf16 as the 16 pairs vdpbf16ps reads (a no-op: the same 512 bits).
inline __m512bh as_bf16(__m512i v) { return std::bit_cast<__m512bh>(v); }

// acc[R][NV·16] = Σ over kc2 depth pairs of A's packed pairs (QMajor: [kc2][ald], else [R][ald])
// against b [kc2][NR]. pf: fp32 A that the next conversion reads, prefetched while this block
// computes (sgemm's depth loop does the same for the A it reads in place); nullptr: none.
// Row-major (QMajor false): the next row block's MR rows at stride pfs, one line of each per
// 8 pairs. Column-major: pfn depths at stride pfs of the next chunk of CH rows, one depth (CH
// values: three lines, four when unaligned) per pair while q < pfn.
template <int R, bool QMajor>
[[gnu::noinline]] void depth_loop(int kc2, const std::uint32_t* a, std::ptrdiff_t ald, const std::uint32_t* b,
                                  const float* pf, std::ptrdiff_t pfs, int pfn, float* acc_out) {
  __m512 acc[R][NV];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int j = 0; j < NV; ++j) acc[i][j] = _mm512_setzero_ps();
  for (int q = 0; q < kc2; ++q) {
    if (pf) {
      if constexpr (QMajor) {
        if (q < pfn) {
          const float* d = pf + std::ptrdiff_t(q) * pfs;
          static_assert(CH == 3 * L);
          __builtin_prefetch(d);
          __builtin_prefetch(d + L);
          __builtin_prefetch(d + 2 * L);
          __builtin_prefetch(d + CH - 1);
        }
      } else if (q % (L / 2) == 0) {
#pragma GCC unroll 8
        for (int i = 0; i < MR; ++i) __builtin_prefetch(pf + i * pfs + 2 * q);
      }
    }
    __m512i bv[NV];
#pragma GCC unroll 4
    for (int j = 0; j < NV; ++j) bv[j] = _mm512_load_si512(b + std::ptrdiff_t(q) * NR + j * L);
#pragma GCC unroll 8
    for (int i = 0; i < R; ++i) {
      const __m512i ai = _mm512_set1_epi32(int(QMajor ? a[q * ald + i] : a[i * ald + q]));
#pragma GCC unroll 4
      for (int j = 0; j < NV; ++j) acc[i][j] = _mm512_dpbf16_ps(acc[i][j], as_bf16(ai), as_bf16(bv[j]));
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int j = 0; j < NV; ++j) _mm512_store_ps(acc_out + i * NR + j * L, acc[i][j]);
}

template <int R, bool QMajor>
void micro_kernel(int kc2, const std::uint32_t* a, std::ptrdiff_t ald, const std::uint32_t* b, float* c,
                  std::ptrdiff_t ldc, int cols, const float* c_in, const float* bias, float* g, const float* gg,
                  const float* pf, std::ptrdiff_t pfs, int pfn) {
  sgemm::prefetch_tile<R, NV>(c, ldc, c_in, gg);
  alignas(64) float tile[R * NR];
  depth_loop<R, QMajor>(kc2, a, ald, b, pf, pfs, pfn, tile);
  sgemm::finish_tile<R, NV>(tile, c, ldc, cols, c_in, bias, g, gg);
}

using Kernel = void (*)(int, const std::uint32_t*, std::ptrdiff_t, const std::uint32_t*, float*, std::ptrdiff_t, int,
                        const float*, const float*, float*, const float*, const float*, std::ptrdiff_t, int);
template <bool QMajor, int... R>
constexpr auto kernel_table(std::integer_sequence<int, R...>) {
  return std::array<Kernel, sizeof...(R)>{&micro_kernel<R + 1, QMajor>...};
}
// kernels[A column-major][R - 1]
inline constexpr std::array<std::array<Kernel, MR>, 2> kernels = {
    kernel_table<false>(std::make_integer_sequence<int, MR>{}), kernel_table<true>(std::make_integer_sequence<int, MR>{})};

#if TJEPA_AMX_NATIVE
// Column-major A's rows [0, R) × depths [0, kc), a(i, k) = a[k·acs + i], as row-major pairs
// dst [rows][ld] (ld a multiple of 16: the A tiles' layout; rows zero from R to `rows`, a multiple
// of 16 ≥ R). 16 depth pairs at a time: pack_a_cols converts them for all R rows into stage
// [16 pairs][R rounded up to 16], reading a row after row, then each 16 × 16 block is transposed
// into place. (32 rows of C at a time, each depth would be a line of another row of a.)
TJEPA_PROFILE_INLINE void pack_a_cols_to_rows(std::uint32_t* dst, std::ptrdiff_t ld, int R, int rows, int kc,
                                             const float* a, std::ptrdiff_t acs) {
  const int kc2 = depth_pairs(kc), blocks = (R + L - 1) / L, lds = blocks * L;
  thread_local AlignedVector<std::uint32_t> stage_storage;
  std::uint32_t* const stage = grow(stage_storage, std::size_t(L) * std::size_t(lds));
  for (int q0 = 0; q0 < kc2; q0 += L) {
    const int nq = std::min(L, kc2 - q0);
    pack_a_cols(stage, lds, R, std::min(2 * L, kc - 2 * q0), a + std::ptrdiff_t(2 * q0) * acs, acs);
    std::fill(stage + std::ptrdiff_t(nq) * lds, stage + std::ptrdiff_t(L) * lds, 0u);
    for (int b = 0; b < blocks; ++b)
      transpose16([&](int t) { return static_cast<const std::uint32_t*>(stage + t * lds + b * L); },
                  dst + std::ptrdiff_t(b) * L * ld + q0, ld);
  }
  for (int i = lds; i < rows; ++i) std::fill(dst + i * ld, dst + i * ld + kc2, 0u);
}

// compute_rows on AMX tiles: blocks of 32 rows × one panel (amx::block_product), A converted into
// the tiles' layout per KC depths (row-major A per 32 rows, column-major A for all of rows
// [r0, r1) at once), then sgemm's epilogue per 16-row tile of C.
inline void compute_rows_amx(int r0, int r1, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order,
                             const std::uint32_t* packed, float* C, std::ptrdiff_t ldc, const Epilogue& e) {
  constexpr int MB = amx::MB;
  const amx::Tiles tiles;
  const int panels = (cols + NR - 1) / NR, depth2 = depth_pairs(depth);
  // Row-major A: converted per block of 32 rows; column-major A: all of rows [r0, r1) at once
  // (pack_a_cols_to_rows reads it row by row).
  const bool col_major = a_order == Order::col_major;
  const int padded = (r1 - r0 + MB - 1) / MB * MB;
  thread_local AlignedVector<std::uint32_t> abuf_storage;
  std::uint32_t* const abuf = grow(abuf_storage, std::size_t(col_major ? padded : MB) * (KC / 2));
  alignas(64) float tile[MB * NR];
  for (int k0 = 0; k0 < depth; k0 += KC) {
    const int kc = std::min(KC, depth - k0), kc2 = depth_pairs(kc);
    const std::ptrdiff_t ald = (kc2 + amx::TK - 1) / amx::TK * amx::TK;
    const bool first = k0 == 0, last = k0 + kc == depth;
    const float* c_in = !first || e.accumulate ? C : e.residual;
    if (col_major) pack_a_cols_to_rows(abuf, ald, r1 - r0, padded, kc, A + r0 + std::ptrdiff_t(k0) * lda, lda);
    for (int i0 = r0; i0 < r1; i0 += MB) {
      const int R = std::min(MB, r1 - i0);
      if (!col_major) {
        pack_a(abuf, R, kc, A + i0 * lda + k0, lda, ald);
        for (int i = R; i < MB; ++i) std::fill(abuf + i * ald, abuf + i * ald + kc2, 0u);
      }
      const std::uint32_t* a = col_major ? abuf + (i0 - r0) * ald : abuf;
      for (int p = 0; p < panels; ++p) {
        const int n0 = p * NR, nc = std::min(NR, cols - n0);
        amx::block_product<NR>(kc2, a, ald, packed + std::ptrdiff_t(p) * depth2 * NR + std::ptrdiff_t(k0 / 2) * NR,
                               nc, R, tile);
        // The epilogue: whole 16-row tiles of C at once, the rows past the last one by one.
        auto finish = [&]<int Rows>(std::integral_constant<int, Rows>, int i) {
          const std::ptrdiff_t at = std::ptrdiff_t(i0 + i) * ldc + n0;
          sgemm::finish_tile<Rows, NV>(tile + i * NR, C + at, ldc, nc, c_in ? c_in + at : nullptr,
                                       first && e.bias ? e.bias + n0 : nullptr, last && e.gelu ? e.gelu + at : nullptr,
                                       last && e.scale ? e.scale + at : nullptr);
        };
        int i = 0;
        for (; i + amx::TM <= R; i += amx::TM) finish(std::integral_constant<int, amx::TM>{}, i);
        for (; i < R; ++i) finish(std::integral_constant<int, 1>{}, i);
      }
    }
  }
}
#endif

// Rows [r0, r1) of C from the packed B.
inline void compute_rows(int r0, int r1, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order,
                         const std::uint32_t* packed, float* C, std::ptrdiff_t ldc, const Epilogue& e) {
#if TJEPA_AMX_NATIVE
  if (amx_enabled()) return compute_rows_amx(r0, r1, cols, depth, A, lda, a_order, packed, C, ldc, e);
#endif
  const bool col_major = a_order == Order::col_major;
  const int panels = (cols + NR - 1) / NR, depth2 = depth_pairs(depth);
  alignas(64) std::uint32_t apack[MR * KC / 2];
  // Column-major A: CH rows of a depth block at a time, [KC/2][CH] (per thread, grown once).
  thread_local AlignedVector<std::uint32_t> acols;
  std::uint32_t* const abuf = col_major ? grow(acols, std::size_t(CH) * (KC / 2)) : apack;
  for (int k0 = 0; k0 < depth; k0 += KC) {
    const int kc = std::min(KC, depth - k0), kc2 = depth_pairs(kc);
    const bool first = k0 == 0, last = k0 + kc == depth;
    const float* c_in = !first || e.accumulate ? C : e.residual;
    for (int i0 = r0; i0 < r1; i0 += MR) {
      const int R = std::min(MR, r1 - i0);
      const int c0 = r0 + (i0 - r0) / CH * CH;  // the chunk of rows holding this block
      if (!col_major)
        pack_a(apack, R, kc, A + i0 * lda + k0, lda, kc2);
      else if (i0 == c0)
        pack_a_cols(abuf, CH, std::min(CH, r1 - c0), kc, A + c0 + std::ptrdiff_t(k0) * lda, lda);
      const std::uint32_t* a = col_major ? abuf + (i0 - c0) : apack;
      const std::ptrdiff_t ald = col_major ? CH : kc2;
      const Kernel kern = kernels[col_major][std::size_t(R - 1)];
      // The next conversion's input, prefetched during this block's first panel: row-major, the
      // next row block; column-major, this block's share of the depths of the next chunk.
      const float* next = nullptr;
      int next_depths = 0;
      if (!col_major && i0 + MR < r1) {
        next = A + (i0 + MR) * lda + k0;
      } else if (col_major && c0 + CH < r1) {
        const int blocks = (std::min(CH, r1 - c0) + MR - 1) / MR, b = (i0 - c0) / MR;
        const int d0 = kc * b / blocks, d1 = kc * (b + 1) / blocks;
        next = A + c0 + CH + std::ptrdiff_t(k0 + d0) * lda;
        next_depths = d1 - d0;
      }
      for (int p = 0; p < panels; ++p) {
        const int n0 = p * NR;
        const std::uint32_t* b = packed + std::ptrdiff_t(p) * depth2 * NR + std::ptrdiff_t(k0 / 2) * NR;
        kern(kc2, a, ald, b, C + i0 * ldc + n0, ldc, std::min(NR, cols - n0), c_in ? c_in + i0 * ldc + n0 : nullptr,
             first && e.bias ? e.bias + n0 : nullptr, last && e.gelu ? e.gelu + i0 * ldc + n0 : nullptr,
             last && e.scale ? e.scale + i0 * ldc + n0 : nullptr, p == 0 ? next : nullptr, lda, next_depths);
      }
    }
  }
}

#endif  // TJEPA_BF16_NATIVE

// Panel p of B, all of its depth, into its place in packed (the vector packing where the build
// has it).
inline void pack_whole_panel(std::uint32_t* packed, const float* B, std::ptrdiff_t ldb, Order b_order, int depth,
                             int cols, int p) {
#if TJEPA_BF16_NATIVE
  pack_panel(packed, B, ldb, b_order, depth, cols, p, 0, depth_pairs(depth));
#else
  pack_panel_ref(packed, B, ldb, b_order, depth, cols, p, 0, depth_pairs(depth));
#endif
}

// The whole of B packed: [panels][depth/2][NR] (packed_size(cols, depth) words).
inline void pack(std::uint32_t* packed, const float* B, std::ptrdiff_t ldb, Order b_order, int depth, int cols) {
  for (int p = 0; p < (cols + NR - 1) / NR; ++p) pack_whole_panel(packed, B, ldb, b_order, depth, cols, p);
}

// C (+)= A · B per the epilogue, B packed beforehand (pack(), packed_size()). depth ≥ 1. Only on
// a native build (the fallback packs float panels instead: see kernels::PackedWeights).
inline void gemm_packed(int rows, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order,
                        const std::uint32_t* packed, float* C, std::ptrdiff_t ldc, const Epilogue& e = {}) {
#if TJEPA_BF16_NATIVE
  if (rows <= 0 || cols <= 0) return;
  sgemm::run_product(rows, cols, depth, 0, [](int) {}, [&](int r0, int r1) {
    compute_rows(r0, r1, cols, depth, A, lda, a_order, packed, C, ldc, e);
  });
#else
  (void)rows, (void)cols, (void)depth, (void)A, (void)lda, (void)a_order, (void)packed, (void)C, (void)ldc, (void)e;
  fail<std::logic_error>("bgemm::gemm_packed: this build has no AVX512-BF16");
#endif
}

// sgemm::gemm's contract in bf16 (Native) or, without the instructions, sgemm::gemm itself.
template <bool Native = native>
void gemm(int rows, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order, const float* B,
          std::ptrdiff_t ldb, Order b_order, float* C, std::ptrdiff_t ldc, const Epilogue& e = {}) {
#if TJEPA_BF16_NATIVE
  if constexpr (Native) {
    if (rows <= 0 || cols <= 0) return;
    if (depth <= 0) return sgemm::empty_product(rows, cols, C, ldc, e);
    thread_local AlignedVector<std::uint32_t> pack_buffer;
    const int panels = (cols + NR - 1) / NR;
    if (sgemm::split_depth(rows, cols, depth, e)) {
      // sgemm's split over depth slabs (an even depth_slab: pairs never straddle two slabs).
      static_assert(sgemm::depth_slab % 2 == 0 && sgemm::depth_slab <= KC);
      const std::size_t slab_size = packed_size(cols, sgemm::depth_slab);
      const int slabs = (depth + sgemm::depth_slab - 1) / sgemm::depth_slab;
      std::uint32_t* packed = grow(pack_buffer, std::size_t(slabs) * slab_size);
      const auto kd = [&](int slab) { return std::min(sgemm::depth_slab, depth - slab * sgemm::depth_slab); };
      const std::ptrdiff_t a_step = a_order == Order::row_major ? 1 : lda, b_step = b_order == Order::row_major ? ldb : 1;
      sgemm::run_split_depth(
          rows, cols, depth, panels,
          [&](int slab, int p) {
            pack_panel(packed + std::size_t(slab) * slab_size, B + slab * sgemm::depth_slab * b_step, ldb, b_order,
                       kd(slab), cols, p, 0, depth_pairs(kd(slab)));
          },
          [&](int slab, int r0, int r1, float* P) {
            compute_rows(r0, r1, cols, kd(slab), A + slab * sgemm::depth_slab * a_step, lda, a_order,
                         packed + std::size_t(slab) * slab_size, P, cols, {});
          },
          C, ldc, e.accumulate);
      return;
    }
    std::uint32_t* packed = grow(pack_buffer, packed_size(cols, depth));
    // Packing tasks of one panel × one block of depth pairs.
    const int pairs = depth_pairs(depth), kblocks = (pairs + KC / 2 - 1) / (KC / 2);
    sgemm::run_product(
        rows, cols, depth, panels * kblocks,
        [&](int task) {
          const int kb = task % kblocks;
          pack_panel(packed, B, ldb, b_order, depth, cols, task / kblocks, kb * KC / 2,
                     std::min(pairs, (kb + 1) * KC / 2));
        },
        [&](int r0, int r1) { compute_rows(r0, r1, cols, depth, A, lda, a_order, packed, C, ldc, e); });
    return;
  }
#endif
  sgemm::gemm(rows, cols, depth, A, lda, a_order, B, ldb, b_order, C, ldc, e);
}

}  // namespace tjepa::detail::bgemm
