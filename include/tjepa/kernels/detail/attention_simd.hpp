#pragma once
// SIMD internals of the fast attention kernels (included only by ../attention.hpp, inside its
// g++ warning suppression): a vectorized exp2, register-blocked GEMM
// micro-kernels on tiles, and the tile sizes. Everything uses xsimd's default architecture (the best
// one the translation unit is compiled for: AVX-512, AVX2 or plain SSE2).
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "tjepa/core/detail/vendor.hpp"

#include "tjepa/core/detail/simd.hpp"
#include "tjepa/core/detail/transpose.hpp"
#include "tjepa/kernels/detail/bgemm.hpp"

namespace tjepa::detail::attn {

template <class T>
using Vec = detail::simd<T>;

template <class T>
inline constexpr int W = static_cast<int>(detail::simd_width<T>);

// Register blocking of the micro-kernels: an MR x (NV*W) block of C lives in MR*NV registers.
// AVX-512 has 32 vector registers (24 accumulators + 4 B vectors + broadcasts); AVX2 and SSE have 16.
template <class T>
inline constexpr int MR = sizeof(Vec<T>) >= 64 ? 6 : 3;
inline constexpr int NV = 4;
template <class T>
inline constexpr int NR = NV * W<T>;  // columns of one micro-panel
// The forward's S^T tile is BQ = 6 W queries wide: on AVX-512 an 8 x 3 block covers it in two
// full panels (a 6 x 4 block would leave a half-empty 6 x 2 one).
template <class T>
inline constexpr int MR_st = sizeof(Vec<T>) >= 64 ? 8 : MR<T>;
template <class T>
inline constexpr int NV_st = sizeof(Vec<T>) >= 64 ? 3 : NV;

inline constexpr std::ptrdiff_t round_up(std::ptrdiff_t n, std::ptrdiff_t m) { return (n + m - 1) / m * m; }

// exp2 on a batch: core/detail/simd.hpp's (the GELU's derivative uses it too).
using detail::exp2;

// 2^(c s - m) of the scores at s (one vector).
template <class T>
[[gnu::always_inline]] inline Vec<T> softmax_p(const T* s, Vec<T> c, Vec<T> m) {
  return exp2(xsimd::fms(Vec<T>::load_aligned(s), c, m));
}

// One key tile of the forward's online softmax on transposed scores st [kv, ld] (key r in row r,
// queries along the row, nb vectors of them): with mx = max over the tile's keys,
//   m_new = max(m, c mx), alpha = 2^(m - m_new), P^T = 2^(c S^T - m_new), l = alpha l + sum_r P^T,
// all in base 2 (c = scale * log2 e); alpha is left for rescaling the output. P^T replaces S^T, or
// with Pairs (the bf16 product P V) goes straight to pt [⌈kv/2⌉][ld] as bf16 pairs of keys 2p and
// 2p+1 (pack_pairs_across_rows's words: the high half 0 past kv; query columns past nb vectors not
// written), without a pass through memory in fp32; l sums the same fp32 P^T in the same order.
// Full = true fixes nb = NBmax at compile time so the per-query vectors live in registers.
template <class T, int NBmax, bool Full, bool Pairs = false>
inline void online_softmax_tile(T* st, int ld, int kv, int nb_rt, T c, T* m, T* l, T* alpha,
                                [[maybe_unused]] std::uint32_t* pt = nullptr) {
  const int nb = Full ? NBmax : nb_rt;
  constexpr int w = W<T>;
  const Vec<T> cv(c);
  Vec<T> mx[NBmax], mn[NBmax], sum[NBmax];
#pragma GCC unroll 8
  for (int j = 0; j < nb; ++j) mx[j] = Vec<T>::load_aligned(st + j * w);
  for (int r = 1; r < kv; ++r)
#pragma GCC unroll 8
    for (int j = 0; j < nb; ++j) mx[j] = xsimd::max(mx[j], Vec<T>::load_aligned(st + r * ld + j * w));
#pragma GCC unroll 8
  for (int j = 0; j < nb; ++j) {
    const Vec<T> mo = Vec<T>::load_aligned(m + j * w);
    mn[j] = xsimd::max(mo, mx[j] * cv);
    exp2(mo - mn[j]).store_aligned(alpha + j * w);  // 0 on the first tile (m = -inf)
    mn[j].store_aligned(m + j * w);
    sum[j] = Vec<T>(T(0));
  }
#if TJEPA_BF16_NATIVE
  if constexpr (Pairs) {
    static_assert(std::is_same_v<T, float> && w == bgemm::L);
    int r = 0;
    for (; r + 1 < kv; r += 2)
#pragma GCC unroll 8
      for (int j = 0; j < nb; ++j) {
        const Vec<T> lo = softmax_p(st + r * ld + j * w, cv, mn[j]);
        const Vec<T> hi = softmax_p(st + (r + 1) * ld + j * w, cv, mn[j]);
        sum[j] += lo;
        sum[j] += hi;
        _mm512_store_si512(pt + r / 2 * ld + j * w, bgemm::interleave_pairs(_mm512_cvtne2ps_pbh(hi, lo)));
      }
    if (r < kv)
#pragma GCC unroll 8
      for (int j = 0; j < nb; ++j) {
        const Vec<T> lo = softmax_p(st + r * ld + j * w, cv, mn[j]);
        sum[j] += lo;
        _mm512_store_si512(pt + r / 2 * ld + j * w, bgemm::interleave_pairs(_mm512_cvtne2ps_pbh(Vec<T>(T(0)), lo)));
      }
  } else
#endif
  {
    static_assert(!Pairs, "bf16 pairs need AVX512-BF16");
    for (int r = 0; r < kv; ++r) {
      T* row = st + r * ld;
#pragma GCC unroll 8
      for (int j = 0; j < nb; ++j) {
        const Vec<T> p = softmax_p(row + j * w, cv, mn[j]);
        p.store_aligned(row + j * w);
        sum[j] += p;
      }
    }
  }
#pragma GCC unroll 8
  for (int j = 0; j < nb; ++j)
    xsimd::fma(Vec<T>::load_aligned(l + j * w), Vec<T>::load_aligned(alpha + j * w), sum[j]).store_aligned(l + j * w);
}

#if TJEPA_BF16_NATIVE
// P^T and dS^T of one vector of queries of the backward's tile: P^T = 2^(c S^T - lse2),
// dS^T = P^T (dP^T - D).
struct ProbGrad {
  Vec<float> p, ds;
};
[[gnu::always_inline]] inline ProbGrad backward_p_ds(const float* s, const float* dp, Vec<float> c, Vec<float> lse2,
                                                     Vec<float> dd) {
  const Vec<float> p = softmax_p(s, c, lse2);
  return {p, p * (Vec<float>::load_aligned(dp) - dd)};
}

// One tile of the bf16 backward's exp pass, straight into its three bf16 operands: from S^T st
// and dP^T dpt [mk][ld] (key r in row r; nv = ⌈nq/16⌉·16 query columns, nq of them real) and the
// tile's lse2 and D, P^T and dS^T as
//   pt, dst [mk][⌈nq/2⌉]: rows paired along the queries (pack_row_pairs's words, the high half 0
//     past nq), the A operands of dV += P^T dO and dK += dS^T Q;
//   ds [⌈mk/2⌉][ld]: pairs of keys 2p and 2p+1 (pack_pairs_across_rows's words over nv columns,
//     the high half 0 past mk, columns [nv, ld) 0), the transposed A operand of dQ += dS K.
// The same fp32 values and roundings as the fp32 pass followed by the three packs, without the
// fp32 tiles' pass through memory.
inline void backward_tile_pairs(const float* st, const float* dpt, int ld, int mk, int nq, float c,
                                const float* lse2, const float* dd, std::uint32_t* pt, std::uint32_t* dst,
                                std::uint32_t* ds) {
  namespace bg = bgemm;
  constexpr int w = bg::L;
  using V = Vec<float>;
  static_assert(W<float> == w);
  const int nv = static_cast<int>(round_up(nq, w)), nq2 = (nq + 1) / 2;
  const V cv(c);
  const ProbGrad zero{V(0.0f), V(0.0f)};
  auto row_words = [](V hi, V lo) { return std::bit_cast<__m512i>(_mm512_cvtne2ps_pbh(hi, lo)); };
  for (int r = 0; r < mk; r += 2) {
    const bool two = r + 1 < mk;
    const float *s0 = st + r * ld, *d0 = dpt + r * ld;
    for (int j = 0; j < nv; j += 2 * w) {
      // Queries [j, j + 32) of keys r and r + 1 (a: the first 16, b: the second, when in the tile).
      const bool second = j + w < nv;
      const V la(V::load_aligned(lse2 + j)), da(V::load_aligned(dd + j));
      const V lb = second ? V::load_aligned(lse2 + j + w) : V(0.0f);
      const V db = second ? V::load_aligned(dd + j + w) : V(0.0f);
      const ProbGrad a0 = backward_p_ds(s0 + j, d0 + j, cv, la, da);
      const ProbGrad b0 = second ? backward_p_ds(s0 + j + w, d0 + j + w, cv, lb, db) : zero;
      const ProbGrad a1 = two ? backward_p_ds(s0 + ld + j, d0 + ld + j, cv, la, da) : zero;
      const ProbGrad b1 = two && second ? backward_p_ds(s0 + ld + j + w, d0 + ld + j + w, cv, lb, db) : zero;
      // Pairs along the queries: the queries past nq read as 0, the words past ⌈nq/2⌉ not written.
      const __mmask16 ma = bg::first_lanes(nq - j), mb = bg::first_lanes(nq - j - w), mw = bg::first_lanes(nq2 - j / 2);
      auto along = [&](std::uint32_t* out, V hi, V lo) {
        _mm512_mask_storeu_epi32(out + j / 2, mw,
                                 row_words(_mm512_maskz_mov_ps(mb, hi), _mm512_maskz_mov_ps(ma, lo)));
      };
      along(pt + r * nq2, b0.p, a0.p);
      along(dst + r * nq2, b0.ds, a0.ds);
      if (two) {
        along(pt + (r + 1) * nq2, b1.p, a1.p);
        along(dst + (r + 1) * nq2, b1.ds, a1.ds);
      }
      // Pairs across the keys.
      std::uint32_t* dsr = ds + r / 2 * ld + j;
      _mm512_store_si512(dsr, bg::interleave_pairs(_mm512_cvtne2ps_pbh(a1.ds, a0.ds)));
      if (second) _mm512_store_si512(dsr + w, bg::interleave_pairs(_mm512_cvtne2ps_pbh(b1.ds, b0.ds)));
    }
    for (int j = nv; j < ld; j += w) _mm512_store_si512(ds + r / 2 * ld + j, _mm512_setzero_si512());
  }
}
#endif

// ---------------------------------------------------------------------------------------------
// Micro-kernel: C[MR_, NV_*W] (op)= A[MR_, K] B[K, NV_*W], over K steps of the dot product D:
// FloatDot (one FMA per step and element), or Bf16Dot (operands bf16 pairs in 32-bit words, one
// vdpbf16ps per step: two depths, fp32 accumulation; K counts pairs).
// A has arbitrary strides (element (i, p) at A[i*a_rs + p*a_cs]); its entries are broadcast, so a
// transposed A costs nothing. B rows are W-aligned with stride ldb; C is W-aligned with stride ldc.
enum class Store { overwrite, add, rescale_add };  // C = AB, C += AB, C = alpha_i C + AB

template <class T>
struct FloatDot {
  using Elem = T;
  using B = Vec<T>;
  static B load(const T* b) { return B::load_aligned(b); }
  static B broadcast(T a) { return B(a); }
  static Vec<T> madd(B a, B b, Vec<T> acc) { return xsimd::fma(a, b, acc); }
};
#if TJEPA_BF16_NATIVE
struct Bf16Dot {
  using Elem = std::uint32_t;
  using B = __m512i;
  static B load(const std::uint32_t* b) { return _mm512_load_si512(b); }
  static B broadcast(std::uint32_t a) { return _mm512_set1_epi32(static_cast<int>(a)); }
  static Vec<float> madd(B a, B b, Vec<float> acc) {
    return _mm512_dpbf16_ps(acc, std::bit_cast<__m512bh>(a), std::bit_cast<__m512bh>(b));
  }
};
#endif

// Inlined into the kernels (out of line in a profiling build: TJEPA_PROFILE_INLINE).
template <class T, int MR_, int NV_, Store S, class D = FloatDot<T>>
TJEPA_PROFILE_INLINE void micro_kernel(int K, const typename D::Elem* __restrict A, std::ptrdiff_t a_rs,
                                       std::ptrdiff_t a_cs, const typename D::Elem* __restrict B, std::ptrdiff_t ldb,
                                       T* __restrict C, std::ptrdiff_t ldc, const T* __restrict alpha) {
  constexpr int w = W<T>;
  Vec<T> acc[MR_][NV_];
#pragma GCC unroll 8
  for (int i = 0; i < MR_; ++i)
#pragma GCC unroll 8
    for (int j = 0; j < NV_; ++j) acc[i][j] = Vec<T>(T(0));
  for (int p = 0; p < K; ++p) {
    const typename D::Elem* b = B + p * ldb;
    typename D::B bv[NV_];
#pragma GCC unroll 8
    for (int j = 0; j < NV_; ++j) bv[j] = D::load(b + j * w);
    const typename D::Elem* a = A + p * a_cs;
#pragma GCC unroll 8
    for (int i = 0; i < MR_; ++i) {
      const typename D::B ai = D::broadcast(a[i * a_rs]);
#pragma GCC unroll 8
      for (int j = 0; j < NV_; ++j) acc[i][j] = D::madd(ai, bv[j], acc[i][j]);
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < MR_; ++i) {
    T* c = C + i * ldc;
#pragma GCC unroll 8
    for (int j = 0; j < NV_; ++j) {
      if constexpr (S == Store::overwrite) {
        acc[i][j].store_aligned(c + j * w);
      } else if constexpr (S == Store::add) {
        (Vec<T>::load_aligned(c + j * w) + acc[i][j]).store_aligned(c + j * w);
      } else {
        xsimd::fma(Vec<T>(alpha[i]), Vec<T>::load_aligned(c + j * w), acc[i][j]).store_aligned(c + j * w);
      }
    }
  }
}

// Runs the micro-kernel of mr rows (1 <= mr <= MRm) and nv vectors (1 <= nv <= NVm).
template <class T, Store S, int MRm, int NVm, class D = FloatDot<T>>
inline void micro_dispatch(int mr, int nv, int K, const typename D::Elem* A, std::ptrdiff_t a_rs, std::ptrdiff_t a_cs,
                           const typename D::Elem* B, std::ptrdiff_t ldb, T* C, std::ptrdiff_t ldc, const T* alpha) {
  if constexpr (MRm > 1) {
    if (mr < MRm) return micro_dispatch<T, S, MRm - 1, NVm, D>(mr, nv, K, A, a_rs, a_cs, B, ldb, C, ldc, alpha);
  }
  if constexpr (NVm > 1) {
    if (nv < NVm) return micro_dispatch<T, S, MRm, NVm - 1, D>(mr, nv, K, A, a_rs, a_cs, B, ldb, C, ldc, alpha);
  }
  micro_kernel<T, MRm, NVm, S, D>(K, A, a_rs, a_cs, B, ldb, C, ldc, alpha);
}

#if TJEPA_AMX_NATIVE
// gemm's bf16 product on AMX tiles (amx_enabled()): per 32 rows of C, A staged into the tiles'
// rows (32 × K pairs rounded up to 16, zero past M and K; rows of A copied, or transposed 16 × 16
// at a time where its pairs run down a column), B's whole groups of 16 pairs read in place and
// its last partial group staged with zero pairs after it; per 32 columns, 2 × 2 C tiles (2 × 1 at
// a last 16), stored, then written to C by the store S. Runs inside the caller's amx::Tiles.
template <Store S>
inline void gemm_amx(int M, int N, int K, const std::uint32_t* A, std::ptrdiff_t a_rs, std::ptrdiff_t a_cs,
                     const std::uint32_t* B, std::ptrdiff_t ldb, float* C, std::ptrdiff_t ldc, const float* alpha) {
  constexpr int TM = amx::TM, TK = amx::TK, MB = amx::MB;
  const amx::Tiles tiles;
  const int Kp = static_cast<int>(round_up(K, TK)), whole = K / TK * TK;
  thread_local AlignedVector<std::uint32_t> a_storage, b_storage;
  std::uint32_t* const at = grow(a_storage, std::size_t(MB) * std::size_t(Kp));
  // B's last partial group of pairs, zero-padded to 16 rows (N words each).
  std::uint32_t* const bt = grow(b_storage, std::size_t(TK) * std::size_t(N));
  if (whole < K) {
    for (int q = whole; q < K; ++q) std::copy(B + q * ldb, B + q * ldb + N, bt + std::ptrdiff_t(q - whole) * N);
    std::fill(bt + std::ptrdiff_t(K - whole) * N, bt + std::ptrdiff_t(TK) * N, 0u);
  }
  alignas(64) float ct[MB * MB];
  for (int m0 = 0; m0 < M; m0 += MB) {
    const int mr = std::min(MB, M - m0);
    const std::uint32_t* a = A + m0 * a_rs;
    if (a_cs == 1) {
      for (int i = 0; i < mr; ++i) {
        std::copy(a + i * a_rs, a + i * a_rs + K, at + i * Kp);
        std::fill(at + i * Kp + K, at + (i + 1) * Kp, 0u);
      }
    } else {
      for (int i0 = 0; i0 < mr; i0 += TM)
        for (int q0 = 0; q0 < Kp; q0 += TK) {
          if (a_rs == 1 && i0 + TM <= mr && q0 + TK <= K) {
            transpose16([&](int t) { return a + (q0 + t) * a_cs + i0; }, at + i0 * Kp + q0, Kp);
            continue;
          }
          for (int i = i0; i < std::min(mr, i0 + TM); ++i)
            for (int q = q0; q < q0 + TK; ++q) at[i * Kp + q] = q < K ? a[i * a_rs + q * a_cs] : 0u;
        }
    }
    for (int i = mr; i < MB; ++i) std::fill(at + i * Kp, at + (i + 1) * Kp, 0u);
    for (int n0 = 0; n0 < N; n0 += 2 * TM) {
      const bool two = n0 + 2 * TM <= N;
      amx::tile_block(
          Kp / TK, at, Kp * 4,
          [&](int g) {
            const int q = g * TK;
            using Group = std::pair<const std::uint32_t*, std::ptrdiff_t>;
            return q >= whole ? Group{bt + n0, std::ptrdiff_t(N) * 4} : Group{B + q * ldb + n0, ldb * 4};
          },
          two, ct, MB * 4);
      for (int i = 0; i < mr; ++i) {
        float* c = C + (m0 + i) * ldc + n0;
        for (int j = 0; j < (two ? 2 : 1); ++j) {
          const Vec<float> v = Vec<float>::load_aligned(ct + i * MB + j * TM);
          if constexpr (S == Store::overwrite)
            v.store_aligned(c + j * TM);
          else if constexpr (S == Store::add)
            (Vec<float>::load_aligned(c + j * TM) + v).store_aligned(c + j * TM);
          else
            xsimd::fma(Vec<float>(alpha[m0 + i]), Vec<float>::load_aligned(c + j * TM), v).store_aligned(c + j * TM);
        }
      }
    }
  }
}
#endif

// C[M, N] (op)= A[M, K] B[K, N] for N a multiple of W: column panels of NVm vectors outside (the B
// panel stays in L1), strips of MRm rows inside. alpha [M] is read only by Store::rescale_add.
// MRm * NVm accumulators must fit the register file. With Bf16Dot, A and B hold bf16 pairs (K
// counts pairs; B's row stride ldb is in words, one word per output column).
template <class T, Store S, int MRm = MR<T>, int NVm = NV, class D = FloatDot<T>>
inline void gemm(int M, int N, int K, const typename D::Elem* A, std::ptrdiff_t a_rs, std::ptrdiff_t a_cs,
                 const typename D::Elem* B, std::ptrdiff_t ldb, T* C, std::ptrdiff_t ldc, const T* alpha = nullptr) {
  constexpr int w = W<T>;
#if TJEPA_AMX_NATIVE
  if constexpr (std::is_same_v<D, Bf16Dot>) {
    if (amx_enabled()) return gemm_amx<S>(M, N, K, A, a_rs, a_cs, B, ldb, C, ldc, alpha);
  }
#endif
  for (int n0 = 0; n0 < N; n0 += NVm * w) {
    const int nv = std::min(NVm, (N - n0) / w);
    for (int m0 = 0; m0 < M; m0 += MRm) {
      const int mr = std::min(MRm, M - m0);
      const typename D::Elem* a = A + m0 * a_rs;
      const typename D::Elem* b = B + n0;
      T* c = C + m0 * ldc + n0;
      const T* al = alpha == nullptr ? nullptr : alpha + m0;
      micro_dispatch<T, S, MRm, NVm, D>(mr, nv, K, a, a_rs, a_cs, b, ldb, c, ldc, al);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Packing one head's columns [0, Dh) of n source rows (row r at src + rows[r]*lds, or r*lds when
// rows is null) into tile-friendly layouts.

// The source rows are strided (e.g. one head of a fused [L, 3d] qkv buffer): the hardware
// prefetcher does not follow them, so each row is fetched `ahead` rows in advance.
template <class T>
inline void prefetch_row(const T* src, std::ptrdiff_t lds, const int* rows, int r, int n, int Dh) {
  constexpr int ahead = 16;
  if (r + ahead >= n) return;
  const char* p = reinterpret_cast<const char*>(src + (rows == nullptr ? r + ahead : rows[r + ahead]) * lds);
  for (std::size_t off = 0; off < Dh * sizeof(T); off += 64) __builtin_prefetch(p + off);
}

// The rows transposed, in panels of `panel` rows: dst [n_pad / panel][Dh][panel], so the B operand
// of one tile (row r of the source is column r % panel of panel r / panel) is contiguous; columns
// [n, n_pad) are zero. n_pad is a multiple of panel.
template <class T>
inline void pack_transposed(const T* src, std::ptrdiff_t lds, const int* rows, int n, int Dh, T* dst,
                            std::ptrdiff_t n_pad, int panel) {
  auto source = [&](std::ptrdiff_t r) { return src + (rows == nullptr ? r : rows[r]) * lds; };
  std::ptrdiff_t r = 0;
  // Float: 16 rows at a time, their 16-column blocks transposed (in registers with AVX-512; a
  // panel holds whole 16-row blocks when panel is a multiple of 16).
  if constexpr (std::is_same_v<T, float>) {
    for (; r + 16 <= n && panel % 16 == 0; r += 16) {
      for (int i = 0; i < 16; ++i) prefetch_row(src, lds, rows, static_cast<int>(r + i), n, Dh);
      T* d = dst + (r / panel) * Dh * panel + r % panel;
      int p = 0;
      for (; p + 16 <= Dh; p += 16)
        transpose16([&](int i) { return source(r + i) + p; }, d + std::ptrdiff_t(p) * panel, panel);
      for (int i = 0; i < 16; ++i)
        for (int c = p; c < Dh; ++c) d[c * panel + i] = source(r + i)[c];
    }
  }
  for (; r < n_pad; ++r) {
    T* d = dst + (r / panel) * Dh * panel + r % panel;
    if (r < n) {
      prefetch_row(src, lds, rows, static_cast<int>(r), n, Dh);
      const T* sr = source(r);
      for (int p = 0; p < Dh; ++p) d[p * panel] = sr[p];
    } else {
      for (int p = 0; p < Dh; ++p) d[p * panel] = T(0);
    }
  }
}

// d[i] = x_i · y_i for the rows x_i = x + i·ld, y_i = y + i·ld, i < n, each summed in order over
// its n_cols columns (the plain loop's bits), 8 rows at a time: 8 independent sums keep the FMA
// pipes busy where one row's sum waits on its own latency at every column.
template <class T>
inline void row_dots(const T* x, const T* y, std::ptrdiff_t ld, int n, int n_cols, T* d) {
  constexpr int RB = 8;
  int i = 0;
  for (; i + RB <= n; i += RB) {
    T acc[RB] = {};
    for (int p = 0; p < n_cols; ++p)
#pragma GCC unroll 8
      for (int r = 0; r < RB; ++r) acc[r] += x[(i + r) * ld + p] * y[(i + r) * ld + p];
    for (int r = 0; r < RB; ++r) d[i + r] = acc[r];
  }
  for (; i < n; ++i) {
    T acc = T(0);
    for (int p = 0; p < n_cols; ++p) acc += x[i * ld + p] * y[i * ld + p];
    d[i] = acc;
  }
}

// dst [n_pad, DhP] = the rows, columns [Dh, DhP) and rows [n, n_pad) zero.
template <class T>
inline void pack_rows(const T* src, std::ptrdiff_t lds, const int* rows, int n, int Dh, T* dst,
                      std::ptrdiff_t DhP, std::ptrdiff_t n_pad) {
  for (std::ptrdiff_t r = 0; r < n_pad; ++r) {
    T* d = dst + r * DhP;
    std::ptrdiff_t p = 0;
    if (r < n) {
      prefetch_row(src, lds, rows, static_cast<int>(r), n, Dh);
      const T* sr = src + (rows == nullptr ? r : rows[r]) * lds;
      simd_copy(sr, d, std::size_t(Dh));
      p = Dh;
    }
    std::fill(d + p, d + DhP, T(0));
  }
}

#if TJEPA_BF16_NATIVE
// The bf16 operands of the attention products (32-bit words of two bf16, bgemm's conversion):
// n rows (row r at src + rows[r]*lds, or r*lds) paired along their Dh columns, as the rows of
// dst [n, Dh2] (A operands), or transposed into panels dst [n_pad / panel][Dh2][panel] (B operands;
// columns [n, n_pad) zero).
inline void pack_row_pairs(const float* src, std::ptrdiff_t lds, const int* rows, int n, int Dh, std::uint32_t* dst,
                           std::ptrdiff_t n_pad, int panel, bool transposed) {
  namespace bg = bgemm;
  const int Dh2 = (Dh + 1) / 2;
  alignas(64) std::uint32_t words[bg::L];
  auto source = [&](std::ptrdiff_t r) { return src + (rows == nullptr ? r : rows[r]) * lds; };
  std::ptrdiff_t r = 0;
  // Transposed: 16 rows at a time, their words transposed in 16 x 16 blocks (a panel holds whole
  // 16-row blocks when panel is a multiple of 16).
  if (transposed && panel % bg::L == 0)
    for (; r + bg::L <= n; r += bg::L) {
      std::uint32_t* d = dst + (r / panel) * Dh2 * panel + r % panel;
      for (int i = 0; i < bg::L; ++i) prefetch_row(src, lds, rows, static_cast<int>(r + i), n, Dh);
      for (int k = 0; k < Dh; k += 2 * bg::L)
        bg::pairs_transposed16([&](int i) { return source(r + i) + k; }, std::min(2 * bg::L, Dh - k),
                               d + (k / 2) * panel, panel);
    }
  for (; r < n_pad; ++r) {
    std::uint32_t* d = transposed ? dst + (r / panel) * Dh2 * panel + r % panel : dst + r * Dh2;
    const std::ptrdiff_t step = transposed ? panel : 1;
    if (r >= n) {
      for (int p = 0; p < Dh2; ++p) d[p * step] = 0u;
      continue;
    }
    prefetch_row(src, lds, rows, static_cast<int>(r), n, Dh);
    const float* sr = source(r);
    if (!transposed) {  // a row's words in place, as the GEMM converts a row of A
      bg::pack_a(d, 1, Dh, sr, 0, bg::depth_pairs(Dh));
      continue;
    }
    for (int k = 0; k < Dh; k += 2 * bg::L) {
      _mm512_store_si512(words, bg::row_pairs(sr + k, std::min(2 * bg::L, Dh - k)));
      for (int p = k / 2; p < std::min(Dh2, k / 2 + bg::L); ++p) d[p * step] = words[p - k / 2];
    }
  }
}
// n rows of width `cols` (row r at src + rows[r]*lds, or r*lds) paired across consecutive rows:
// dst [⌈n/2⌉][ldd] words (pair p = rows 2p and 2p+1; the high half 0 past n; columns [cols, ldd)
// zero, ldd a multiple of 16): V as the B operand of P·V, P^T as the A operand.
inline void pack_pairs_across_rows(const float* src, std::ptrdiff_t lds, const int* rows, int n, int cols,
                                   std::uint32_t* dst, std::ptrdiff_t ldd) {
  namespace bg = bgemm;
  for (int p = 0; 2 * p < n; ++p) {
    const float* lo = src + (rows == nullptr ? 2 * p : rows[2 * p]) * lds;
    const float* hi = 2 * p + 1 < n ? src + (rows == nullptr ? 2 * p + 1 : rows[2 * p + 1]) * lds : nullptr;
    for (int c = 0; c < ldd; c += bg::L)
      _mm512_store_si512(dst + p * ldd + c, bg::pairs16(lo + c, hi ? hi + c : nullptr, cols - c));
  }
}
#endif

// ---------------------------------------------------------------------------------------------
// Tile sizes. Forward: BK keys x BQ queries of transposed scores per tile (both multiples of MR,
// BQ of W).
// Backward (key blocks outside, query blocks inside): BKB keys x BQB queries.
template <class T>
struct Tiles {
  static constexpr int BQ = 16 * MR<T>;
  static constexpr int BK = 8 * MR<T>;
  static constexpr int BKB = 8 * MR<T>;
  static constexpr int BQB = NR<T>;
};

// Hands out consecutive W-aligned offsets (in elements) of one workspace buffer.
template <class T>
struct Carver {
  std::ptrdiff_t at = 0;
  std::ptrdiff_t take(std::ptrdiff_t n) {
    const std::ptrdiff_t off = at;
    at += round_up(n, W<T>);
    return off;
  }
};

// Offsets of the buffers one head needs, carved out of the workspace.
template <class T>
struct ForwardLayout {
  std::ptrdiff_t NqP, DhP;  // padded query count, padded head width
  std::ptrdiff_t qt, kp, vp, st, o, m, l, alpha, Dh2, qt16, kp16, vp16, pt16, total;
  ForwardLayout(int Lq, int Lk, int Dh) {
    using Tl = Tiles<T>;
    NqP = round_up(Lq, Tl::BQ);
    DhP = round_up(Dh, W<T>);
    Carver<T> c;
    auto take = [&c](std::ptrdiff_t n) { return c.take(n); };
    qt = take(Dh * NqP);                           // Q_h^T in panels of BQ queries [NqP / BQ][Dh][BQ]
    kp = take(std::ptrdiff_t{Lk} * DhP);            // K_h of the valid keys [Lk, DhP]
    vp = take(std::ptrdiff_t{Lk} * DhP);            // V_h of the valid keys [Lk, DhP]
    st = take(std::ptrdiff_t{Tl::BK} * Tl::BQ);     // S^T, then P^T, of one tile [BK, BQ]
    o = take(std::ptrdiff_t{Tl::BQ} * DhP);         // unnormalized output of a query block [BQ, DhP]
    m = take(Tl::BQ);                               // running max (base 2) [BQ]
    l = take(Tl::BQ);                               // running sum [BQ]
    alpha = take(Tl::BQ);                           // rescale factor of the current tile [BQ]
    // bf16 operands (Precision::bf16; 32-bit words of two bf16, carved from the same buffer):
    Dh2 = (Dh + 1) / 2;
    qt16 = take(Dh2 * NqP);                            // Q_h^T pairs along Dh [NqP / BQ][Dh2][BQ]
    kp16 = take(std::ptrdiff_t{Lk} * Dh2);             // K_h pairs along Dh [Lk, Dh2]
    vp16 = take((std::ptrdiff_t{Lk} + 1) / 2 * DhP);   // V_h pairs along keys [Lk / 2][DhP]
    pt16 = take(std::ptrdiff_t{Tl::BK} / 2 * Tl::BQ);  // P^T pairs along keys [BK / 2][BQ]
    total = c.at;
  }
};

template <class T>
struct BackwardLayout {
  std::ptrdiff_t Nk, NqP, DhP;
  std::ptrdiff_t qt, dot, qp, dop, dq, kp, vp, lse2, dd, st, dpt, dk, dv;
  std::ptrdiff_t Dh2, qt16, dot16, kr16, vr16, do16, q16, kx16, pt16, dst16, ds16, total;
  BackwardLayout(int Lq, int Lk, int Dh) {
    using Tl = Tiles<T>;
    Nk = round_up(Lk, Tl::BKB);
    NqP = round_up(Lq, Tl::BQB);
    DhP = round_up(Dh, W<T>);
    Carver<T> c;
    auto take = [&c](std::ptrdiff_t n) { return c.take(n); };
    qt = take(Dh * NqP);   // Q_h^T in panels of BQB queries [NqP / BQB][Dh][BQB]
    dot = take(Dh * NqP);  // dO_h^T, same layout
    qp = take(NqP * DhP);  // Q_h [NqP, DhP]
    dop = take(NqP * DhP);  // dO_h [NqP, DhP]
    dq = take(NqP * DhP);   // dQ_h accumulator [NqP, DhP]
    kp = take(Nk * DhP);    // K_h of the valid keys [Nk, DhP]
    vp = take(Nk * DhP);    // V_h of the valid keys [Nk, DhP]
    lse2 = take(NqP);       // lse in base 2, +inf on padding rows [NqP]
    dd = take(NqP);         // D = rowsum(dO * O) [NqP]
    st = take(std::ptrdiff_t{Tl::BKB} * Tl::BQB);   // S^T, then P^T [BKB, BQB]
    dpt = take(std::ptrdiff_t{Tl::BKB} * Tl::BQB);  // dP^T, then dS^T [BKB, BQB]
    dk = take(std::ptrdiff_t{Tl::BKB} * DhP);       // dK accumulator of one key block
    dv = take(std::ptrdiff_t{Tl::BKB} * DhP);       // dV accumulator of one key block
    // bf16 operands (Precision::bf16; words of two bf16): pairs along Dh of Q^T, dO^T (panels of
    // BQB queries) and of K, V rows; pairs across rows of dO, Q [NqP / 2][DhP] and K [Nk / 2][DhP];
    // per tile P^T and dS^T paired along queries [BKB][BQB / 2], dS paired across keys [BKB / 2][BQB].
    Dh2 = (Dh + 1) / 2;
    qt16 = take(Dh2 * NqP);
    dot16 = take(Dh2 * NqP);
    kr16 = take(Nk * Dh2);
    vr16 = take(Nk * Dh2);
    do16 = take(NqP / 2 * DhP);
    q16 = take(NqP / 2 * DhP);
    kx16 = take(Nk / 2 * DhP);
    pt16 = take(std::ptrdiff_t{Tl::BKB} * Tl::BQB / 2);
    dst16 = take(std::ptrdiff_t{Tl::BKB} * Tl::BQB / 2);
    ds16 = take(std::ptrdiff_t{Tl::BKB} / 2 * Tl::BQB);
    total = c.at;
  }
};

}  // namespace tjepa::detail::attn
