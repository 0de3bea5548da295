#pragma once
// Multi-head scaled dot-product attention kernels (self- and cross-attention), forward and
// backward, with an optional key-padding mask. One call handles one sample; batches loop outside.
//
// Legend: Lq query tokens, Lk key tokens, H heads of width Dh, d = H*Dh.
//   q   [Lq, d] row stride ldq      k [Lk, d] row stride ldk      v [Lk, d] row stride ldv
//   out [Lq, d] row stride ldo      lse [H, Lq] (contiguous)      key_valid [Lk] or nullptr
// Head h uses columns [h*Dh, (h+1)*Dh) of q, k, v and out. A fused qkv buffer [L, 3d] is passed
// as q = qkv, k = qkv + d, v = qkv + 2d with ldq = ldk = ldv = 3d.
//
//   S = scale * Q_h K_h^T (scale = 1/sqrt(Dh), as timm / I-JEPA), masked keys get S = -inf,
//   P = softmax_rows(S), out_h = P V_h, lse[h, i] = log sum_j exp(S_ij).
//
// A query row whose keys are all masked (key_valid all zero) has no distribution to attend with:
// its output is 0, its lse is +inf, and it contributes 0 to every gradient. (lse = +inf makes
// P = exp(S - lse) = 0 in backward with no special case.)
//
// tjepa::ref:: is the spec: plain loops, materializes each row of scores, accumulates in double.
// tjepa:: is the fast path: flash-style (online softmax over key tiles; only the per-query
// statistics lse and D = rowsum(dO * O) are kept, never an Lq x Lk matrix), register-blocked
// micro-kernels and a polynomial exp2 through xsimd (AVX-512, AVX2 or SSE2, whatever the
// translation unit is compiled for), the same code in float and double. Its scratch lives in a
// caller-owned AttentionWorkspace of O((Lq + Lk) * Dh) elements (one head's packed operands plus
// fixed-size tiles; at L = 2124, Dh = 64 about 3.8 MiB in float).
// Backward adds (+=) into dq, dk, dv: every entry is summed completely first and added once, so
// two backward calls give exactly twice the gradient.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"

// g++ 12 reports false "(may be) used uninitialized" warnings inside its own AVX-512 intrinsics
// (the self-initialized _mm512_undefined_* operands of max/min/shift) once they are inlined into
// the kernels below and in detail/.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif

#include "tjepa/kernels/detail/attention_simd.hpp"

namespace tjepa::kernels {

struct AttentionShape {
  int Lq = 0, Lk = 0, H = 0, Dh = 0;
  int ldq = 0, ldk = 0, ldv = 0, ldo = 0;

  int d() const { return H * Dh; }
  // Self-attention on a fused qkv buffer [L, 3d] writing a contiguous out [L, d].
  static AttentionShape fused_self(int L, int H, int Dh) {
    const int d = H * Dh;
    return {L, L, H, Dh, 3 * d, 3 * d, 3 * d, d};
  }
  // Separate contiguous q [Lq, d], k [Lk, d], v [Lk, d], out [Lq, d] (cross-attention).
  static AttentionShape contiguous(int Lq, int Lk, int H, int Dh) {
    const int d = H * Dh;
    return {Lq, Lk, H, Dh, d, d, d, d};
  }
};

// Throws ShapeError naming the field unless every size is positive and every row stride holds a
// full row of d = H*Dh values.
inline void check_attention_shape(const AttentionShape& s, const char* where) {
  require<ShapeError>(s.Lq > 0, where, ": Lq = ", s.Lq, ", expected > 0");
  require<ShapeError>(s.Lk > 0, where, ": Lk = ", s.Lk, ", expected > 0");
  require<ShapeError>(s.H > 0, where, ": H = ", s.H, ", expected > 0");
  require<ShapeError>(s.Dh > 0, where, ": Dh = ", s.Dh, ", expected > 0");
  const int d = s.d();
  require<ShapeError>(s.ldq >= d, where, ": ldq = ", s.ldq, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldk >= d, where, ": ldk = ", s.ldk, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldv >= d, where, ": ldv = ", s.ldv, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldo >= d, where, ": ldo = ", s.ldo, ", expected >= H*Dh = ", d);
}

}  // namespace tjepa::kernels

namespace tjepa::detail {
// Throws ShapeError naming the first null buffer among (pointer, name) pairs.
inline void require_buffers(const char* where, std::initializer_list<std::pair<const void*, const char*>> buffers) {
  for (const auto& [p, name] : buffers)
    require<ShapeError>(p != nullptr, where, ": ", name, " is null, expected a buffer");
}
template <class T>
void check_forward_args(const char* where, const kernels::AttentionShape& s, const T* q, const T* k, const T* v, const T* out) {
  kernels::check_attention_shape(s, where);
  require_buffers(where, {{q, "q"}, {k, "k"}, {v, "v"}, {out, "out"}});
}
template <class T>
void check_backward_args(const char* where, const kernels::AttentionShape& s, const T* q, const T* k, const T* v, const T* out,
                         const T* lse, const T* dout, const T* dq, const T* dk, const T* dv) {
  kernels::check_attention_shape(s, where);
  require_buffers(where, {{q, "q"}, {k, "k"}, {v, "v"}, {out, "out"}, {lse, "lse"}, {dout, "dout"},
                          {dq, "dq"}, {dk, "dk"}, {dv, "dv"}});
}
}  // namespace tjepa::detail

namespace tjepa::kernels {

// Caller-owned scratch of the fast kernels. It grows on demand and never shrinks, so after one
// call with the largest shape (or reserve(shape)) no call of the same or a smaller shape allocates.
// One workspace per thread.
template <class T>
struct AttentionWorkspace {
  // Returns at least n elements, 64-byte aligned. Reallocates only when n exceeds the capacity.
  T* get(std::size_t n) {
    if (buffer.size() < n) buffer.resize(n);
    return buffer.data();
  }
  // Grows to what forward and backward of this shape (and any smaller one) need.
  void reserve(const AttentionShape& shape);
  std::size_t capacity() const { return buffer.size(); }

  AlignedVector<T> buffer;
  std::vector<int> keys;  // indices of the valid keys [Lk]
};

// ---------------------------------------------------------------------------------------------
// Reference (spec)
namespace ref {

template <class T>
void attention_forward(const AttentionShape& s, const T* q, const T* k, const T* v,
                       const std::uint8_t* key_valid, T* out, T* lse) {
  detail::check_forward_args("ref::attention_forward", s, q, k, v, out);
  const double scale = 1.0 / std::sqrt(static_cast<double>(s.Dh));
  std::vector<double> p(static_cast<std::size_t>(s.Lk));
  std::vector<double> o(static_cast<std::size_t>(s.Dh));
  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * s.Dh;
    for (int i = 0; i < s.Lq; ++i) {
      const T* qi = q + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      double m = -std::numeric_limits<double>::infinity();
      for (int j = 0; j < s.Lk; ++j) {
        if (key_valid != nullptr && key_valid[j] == 0) {
          p[j] = -std::numeric_limits<double>::infinity();
          continue;
        }
        const T* kj = k + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
        double acc = 0.0;
        for (int c = 0; c < s.Dh; ++c) acc += static_cast<double>(qi[c]) * static_cast<double>(kj[c]);
        p[j] = scale * acc;
        if (p[j] > m) m = p[j];
      }
      T* oi = out + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      if (m == -std::numeric_limits<double>::infinity()) {  // every key masked
        for (int c = 0; c < s.Dh; ++c) oi[c] = T(0);
        if (lse != nullptr) lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i] = std::numeric_limits<T>::infinity();
        continue;
      }
      double sum = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        p[j] = std::exp(p[j] - m);  // exp(-inf) = 0 for masked keys
        sum += p[j];
      }
      for (auto& x : o) x = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        if (p[j] == 0.0) continue;
        const T* vj = v + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
        for (int c = 0; c < s.Dh; ++c) o[c] += p[j] * static_cast<double>(vj[c]);
      }
      for (int c = 0; c < s.Dh; ++c) oi[c] = static_cast<T>(o[c] / sum);
      if (lse != nullptr) lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i] = static_cast<T>(m + std::log(sum));
    }
  }
}

// Differentiates out_h = softmax(scale Q_h K_h^T) V_h:
//   dV += P^T dO,  dP = dO V^T,  dS = P * (dP - D) with D_i = sum_c dO_ic O_ic,
//   dQ += scale dS K,  dK += scale dS^T Q,  P_ij = exp(S_ij - lse_i).
template <class T>
void attention_backward(const AttentionShape& s, const T* q, const T* k, const T* v,
                        const std::uint8_t* key_valid, const T* out, const T* lse, const T* dout,
                        T* dq, T* dk, T* dv) {
  detail::check_backward_args("ref::attention_backward", s, q, k, v, out, lse, dout, dq, dk, dv);
  const double scale = 1.0 / std::sqrt(static_cast<double>(s.Dh));
  // Each gradient entry is summed in double and added to its output once, so that two backward
  // passes give exactly twice the gradient.
  const std::size_t Dh = static_cast<std::size_t>(s.Dh);
  std::vector<double> dqi(Dh), dkh(static_cast<std::size_t>(s.Lk) * Dh), dvh(dkh.size());
  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * s.Dh;
    for (auto& x : dkh) x = 0.0;
    for (auto& x : dvh) x = 0.0;
    for (int i = 0; i < s.Lq; ++i) {
      const double l = static_cast<double>(lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i]);
      if (std::isinf(l)) continue;  // every key masked: P = 0, no gradient
      const T* qi = q + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      const T* oi = out + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      const T* doi = dout + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      double D = 0.0;
      for (int c = 0; c < s.Dh; ++c) D += static_cast<double>(doi[c]) * static_cast<double>(oi[c]);
      for (auto& x : dqi) x = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        if (key_valid != nullptr && key_valid[j] == 0) continue;
        const T* kj = k + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
        const T* vj = v + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
        double sc = 0.0, dp = 0.0;
        for (int c = 0; c < s.Dh; ++c) {
          sc += static_cast<double>(qi[c]) * static_cast<double>(kj[c]);
          dp += static_cast<double>(doi[c]) * static_cast<double>(vj[c]);
        }
        const double p = std::exp(scale * sc - l);
        const double ds = p * (dp - D) * scale;
        double* dkj = dkh.data() + static_cast<std::size_t>(j) * Dh;
        double* dvj = dvh.data() + static_cast<std::size_t>(j) * Dh;
        for (int c = 0; c < s.Dh; ++c) {
          dqi[c] += ds * static_cast<double>(kj[c]);
          dkj[c] += ds * static_cast<double>(qi[c]);
          dvj[c] += p * static_cast<double>(doi[c]);
        }
      }
      T* dqp = dq + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      for (int c = 0; c < s.Dh; ++c) dqp[c] += static_cast<T>(dqi[c]);
    }
    for (int j = 0; j < s.Lk; ++j) {
      T* dkp = dk + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
      T* dvp = dv + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
      for (int c = 0; c < s.Dh; ++c) {
        dkp[c] += static_cast<T>(dkh[static_cast<std::size_t>(j) * Dh + c]);
        dvp[c] += static_cast<T>(dvh[static_cast<std::size_t>(j) * Dh + c]);
      }
    }
  }
}

}  // namespace ref

// ---------------------------------------------------------------------------------------------
// Fast path

}  // namespace tjepa::kernels

namespace tjepa::detail::attn {

// Indices of the valid keys (all of them without a mask), in ws.keys[0, n); returns n.
template <class T>
int compact_keys(const kernels::AttentionShape& s, const std::uint8_t* key_valid, kernels::AttentionWorkspace<T>& ws) {
  if (ws.keys.size() < static_cast<std::size_t>(s.Lk)) ws.keys.resize(static_cast<std::size_t>(s.Lk));
  int n = 0;
  for (int j = 0; j < s.Lk; ++j)
    if (key_valid == nullptr || key_valid[j] != 0) ws.keys[static_cast<std::size_t>(n++)] = j;
  return n;
}

inline constexpr double log2e = 1.4426950408889634074;
inline constexpr double ln2 = 0.6931471805599453094;

}  // namespace tjepa::detail::attn

namespace tjepa::kernels {

template <class T>
void AttentionWorkspace<T>::reserve(const AttentionShape& shape) {
  check_attention_shape(shape, "AttentionWorkspace::reserve");
  const detail::attn::ForwardLayout<T> f(shape.Lq, shape.Lk, shape.Dh);
  const detail::attn::BackwardLayout<T> b(shape.Lq, shape.Lk, shape.Dh);
  get(static_cast<std::size_t>(std::max(f.total, b.total)));
  if (keys.size() < static_cast<std::size_t>(shape.Lk)) keys.resize(static_cast<std::size_t>(shape.Lk));
}

// Flash-style forward, in the transposed orientation: per head, Q_h^T (panels of BQ queries), K_h
// and V_h of the valid keys are packed once; per block of BQ queries the key tiles of BK keys are
// visited with an online softmax. A tile holds S^T = K_tile Q_blk^T [BK, BQ], so the per-query
// statistics (running max m and sum l, in base 2: scores scaled by c = scale * log2 e) are vectors
// across queries and need no horizontal reductions; the output block is rescaled by
// alpha = 2^(m_old - m_new) in the P V product. Only a [BK, BQ] tile of scores ever exists.
// precision = bf16 (float, on AVX512-BF16): both products take bf16 operands (Q, K, V and the
// tile's P rounded to bf16) and accumulate in fp32; the softmax stays fp32.
template <class T>
void attention_forward(const AttentionShape& s, const T* q, const T* k, const T* v,
                       const std::uint8_t* key_valid, T* out, T* lse, AttentionWorkspace<T>& ws,
                       Precision precision = Precision::fp32) {
  detail::check_forward_args("attention_forward", s, q, k, v, out);
  namespace A = detail::attn;
  using V = A::Vec<T>;
  using Tl = A::Tiles<T>;
  constexpr int w = A::W<T>;
  constexpr int BQ = Tl::BQ, BK = Tl::BK, NB = BQ / w;
  const int Dh = s.Dh, Lq = s.Lq;
  const int nk = A::compact_keys(s, key_valid, ws);
  if (nk == 0) {  // every key masked: output 0, lse +inf
    for (int i = 0; i < Lq; ++i)
      for (int c = 0; c < s.d(); ++c) out[static_cast<std::ptrdiff_t>(i) * s.ldo + c] = T(0);
    if (lse != nullptr)
      for (int i = 0; i < s.H * Lq; ++i) lse[i] = std::numeric_limits<T>::infinity();
    return;
  }
  const A::ForwardLayout<T> lay(Lq, nk, Dh);
  T* const base = ws.get(static_cast<std::size_t>(lay.total));
  T *const qt = base + lay.qt, *const kp = base + lay.kp, *const vp = base + lay.vp;
  T *const st = base + lay.st, *const O = base + lay.o, *const m = base + lay.m;
  T *const l = base + lay.l, *const alpha = base + lay.alpha;
  const T c = static_cast<T>(A::log2e / std::sqrt(static_cast<double>(Dh)));
  const std::ptrdiff_t DhP = lay.DhP;
#if TJEPA_BF16_NATIVE
  constexpr bool can_bf16 = std::is_same_v<T, float>;
  const bool bf16 = can_bf16 && detail::bgemm::resolve(precision) == Precision::bf16;
#if TJEPA_AMX_NATIVE
  std::optional<detail::amx::Tiles> tiles;  // one tile configuration for all the products below
  if (bf16 && amx_enabled()) tiles.emplace();
#endif
  auto words = [base](std::ptrdiff_t off) { return reinterpret_cast<std::uint32_t*>(base + off); };
  const std::ptrdiff_t Dh2 = lay.Dh2;
#else
  (void)precision;
#endif

  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * Dh;
#if TJEPA_BF16_NATIVE
    if constexpr (can_bf16) {
      if (bf16) {
        A::pack_row_pairs(q + c0, s.ldq, nullptr, Lq, Dh, words(lay.qt16), lay.NqP, BQ, true);
        A::pack_row_pairs(k + c0, s.ldk, ws.keys.data(), nk, Dh, words(lay.kp16), nk, 0, false);
        A::pack_pairs_across_rows(v + c0, s.ldv, ws.keys.data(), nk, Dh, words(lay.vp16), DhP);
      }
    }
    if (!bf16)
#endif
    {
      A::pack_transposed(q + c0, s.ldq, nullptr, Lq, Dh, qt, lay.NqP, BQ);
      A::pack_rows(k + c0, s.ldk, ws.keys.data(), nk, Dh, kp, DhP, nk);
      A::pack_rows(v + c0, s.ldv, ws.keys.data(), nk, Dh, vp, DhP, nk);
    }

    for (int q0 = 0; q0 < Lq; q0 += BQ) {
      const int mq = std::min(BQ, Lq - q0);
      const int nb = static_cast<int>(A::round_up(mq, w)) / w;  // query vectors in this block
      const T* qtb = qt + static_cast<std::ptrdiff_t>(q0) * Dh;  // panel q0 / BQ
      for (int j = 0; j < nb; ++j) {
        V(-std::numeric_limits<T>::infinity()).store_aligned(m + j * w);
        V(T(0)).store_aligned(l + j * w);
      }
      for (int kb = 0; kb < nk; kb += BK) {
        const int kv = std::min(BK, nk - kb);
        // S^T [kv, nb*w] = K_tile Q_blk^T (unscaled); query columns past mq are 0 (zero padding).
#if TJEPA_BF16_NATIVE
        if constexpr (can_bf16) {
          if (bf16)
            A::gemm<T, A::Store::overwrite, A::MR_st<T>, A::NV_st<T>, A::Bf16Dot>(
                kv, nb * w, int(Dh2), words(lay.kp16) + kb * Dh2, Dh2, 1, words(lay.qt16) + q0 * Dh2, BQ, st, BQ);
        }
        if (!bf16)
#endif
          A::gemm<T, A::Store::overwrite, A::MR_st<T>, A::NV_st<T>>(kv, nb * w, Dh, kp + kb * DhP, DhP, 1, qtb, BQ, st,
                                                                    BQ);
        // O [mq, DhP] = alpha O + P V_tile, P read transposed out of the P^T tile (in bf16 its
        // pairs, which the softmax writes).
#if TJEPA_BF16_NATIVE
        if constexpr (can_bf16) {
          if (bf16) {
            std::uint32_t* pt = words(lay.pt16);
            if (nb == NB)
              A::online_softmax_tile<T, NB, true, true>(st, BQ, kv, nb, c, m, l, alpha, pt);
            else
              A::online_softmax_tile<T, NB, false, true>(st, BQ, kv, nb, c, m, l, alpha, pt);
            const std::uint32_t* vt = words(lay.vp16) + kb / 2 * DhP;
            const int kv2 = (kv + 1) / 2;
            if (kb == 0)
              A::gemm<T, A::Store::overwrite, A::MR<T>, A::NV, A::Bf16Dot>(mq, int(DhP), kv2, pt, 1, BQ, vt, DhP, O, DhP);
            else
              A::gemm<T, A::Store::rescale_add, A::MR<T>, A::NV, A::Bf16Dot>(mq, int(DhP), kv2, pt, 1, BQ, vt, DhP, O,
                                                                           DhP, alpha);
            continue;
          }
        }
#endif
        if (nb == NB)  // a full query block: the statistics stay in registers
          A::online_softmax_tile<T, NB, true>(st, BQ, kv, nb, c, m, l, alpha);
        else
          A::online_softmax_tile<T, NB, false>(st, BQ, kv, nb, c, m, l, alpha);
        if (kb == 0)
          A::gemm<T, A::Store::overwrite>(mq, static_cast<int>(DhP), kv, st, 1, BQ, vp, DhP, O, DhP);
        else
          A::gemm<T, A::Store::rescale_add>(mq, static_cast<int>(DhP), kv, st, 1, BQ, vp + kb * DhP, DhP, O, DhP,
                                            alpha);
      }
      for (int i = 0; i < mq; ++i) {
        const T inv = T(1) / l[i];
        T* orow = out + static_cast<std::ptrdiff_t>(q0 + i) * s.ldo + c0;
        const T* src = O + i * DhP;
        detail::simd_scale(inv, src, orow, std::size_t(Dh));
        if (lse != nullptr) lse[static_cast<std::ptrdiff_t>(h) * Lq + q0 + i] = (m[i] + std::log2(l[i])) * T(A::ln2);
      }
    }
  }
}

// Flash-style backward: key tiles outside (their dK, dV accumulate in the workspace), query tiles
// inside; the transposed scores S^T = K Q^T are recomputed per tile, so the softmax statistics lse
// and D index columns (vector loads, no horizontal work). P^T = 2^(S^T c - lse2),
// dS^T = P^T * (dO V^T - D)^T; dV += P^T dO, dK += scale dS^T Q, dQ += scale dS K.
// Every gradient entry is complete before it is added to dq, dk or dv, once.
// precision = bf16 (float, on AVX512-BF16): the five products take bf16 operands (Q, K, V, dO and
// each tile's P and dS rounded to bf16) with fp32 accumulation; pair it with a bf16 forward, whose
// lse it reproduces.
template <class T>
void attention_backward(const AttentionShape& s, const T* q, const T* k, const T* v,
                        const std::uint8_t* key_valid, const T* out, const T* lse, const T* dout,
                        T* dq, T* dk, T* dv, AttentionWorkspace<T>& ws, Precision precision = Precision::fp32) {
  detail::check_backward_args("attention_backward", s, q, k, v, out, lse, dout, dq, dk, dv);
  namespace A = detail::attn;
  using V = A::Vec<T>;
  using Tl = A::Tiles<T>;
  constexpr int w = A::W<T>;
  const int Dh = s.Dh, Lq = s.Lq;
  const int nk = A::compact_keys(s, key_valid, ws);
  if (nk == 0) return;  // every key masked: no gradient
  const A::BackwardLayout<T> lay(Lq, nk, Dh);
  T* const base = ws.get(static_cast<std::size_t>(lay.total));
  T *const qt = base + lay.qt, *const dot = base + lay.dot, *const qp = base + lay.qp;
  T *const dop = base + lay.dop, *const dqa = base + lay.dq, *const kp = base + lay.kp;
  T *const vp = base + lay.vp, *const lse2 = base + lay.lse2, *const dd = base + lay.dd;
  T *const st = base + lay.st, *const dpt = base + lay.dpt, *const dka = base + lay.dk;
  T* const dva = base + lay.dv;
  const int* keys = ws.keys.data();
  const T scale = static_cast<T>(1.0 / std::sqrt(static_cast<double>(Dh)));
  const T c = static_cast<T>(A::log2e / std::sqrt(static_cast<double>(Dh)));
  const std::ptrdiff_t NqP = lay.NqP, DhP = lay.DhP;
#if TJEPA_BF16_NATIVE
  constexpr bool can_bf16 = std::is_same_v<T, float>;
  const bool bf16 = can_bf16 && detail::bgemm::resolve(precision) == Precision::bf16;
#if TJEPA_AMX_NATIVE
  std::optional<detail::amx::Tiles> tiles;  // one tile configuration for all the products below
  if (bf16 && amx_enabled()) tiles.emplace();
#endif
  auto words = [base](std::ptrdiff_t off) { return reinterpret_cast<std::uint32_t*>(base + off); };
  const std::ptrdiff_t Dh2 = lay.Dh2;
  constexpr int BQB = Tl::BQB;
#else
  (void)precision;
#endif

  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * Dh;
#if TJEPA_BF16_NATIVE
    if constexpr (can_bf16) {
      if (bf16) {
        A::pack_row_pairs(q + c0, s.ldq, nullptr, Lq, Dh, words(lay.qt16), NqP, BQB, true);
        A::pack_row_pairs(dout + c0, s.ldo, nullptr, Lq, Dh, words(lay.dot16), NqP, BQB, true);
        A::pack_row_pairs(k + c0, s.ldk, keys, nk, Dh, words(lay.kr16), nk, 0, false);
        A::pack_row_pairs(v + c0, s.ldv, keys, nk, Dh, words(lay.vr16), nk, 0, false);
        A::pack_pairs_across_rows(dout + c0, s.ldo, nullptr, Lq, Dh, words(lay.do16), DhP);
        A::pack_pairs_across_rows(q + c0, s.ldq, nullptr, Lq, Dh, words(lay.q16), DhP);
        A::pack_pairs_across_rows(k + c0, s.ldk, keys, nk, Dh, words(lay.kx16), DhP);
      }
    }
    if (!bf16)
#endif
    {
      A::pack_rows(q + c0, s.ldq, nullptr, Lq, Dh, qp, DhP, NqP);
      A::pack_rows(dout + c0, s.ldo, nullptr, Lq, Dh, dop, DhP, NqP);
      A::pack_transposed(qp, DhP, nullptr, Lq, Dh, qt, NqP, Tl::BQB);
      A::pack_transposed(dop, DhP, nullptr, Lq, Dh, dot, NqP, Tl::BQB);
      A::pack_rows(k + c0, s.ldk, keys, nk, Dh, kp, DhP, nk);
      A::pack_rows(v + c0, s.ldv, keys, nk, Dh, vp, DhP, nk);
    }
    std::fill(dqa, dqa + NqP * DhP, T(0));
    A::row_dots(dout + c0, out + c0, s.ldo, Lq, Dh, dd);  // D_i = dO_i · O_i
    for (std::ptrdiff_t i = 0; i < NqP; ++i) {
      if (i >= Lq) {
        lse2[i] = std::numeric_limits<T>::infinity();  // P = 0 on padding queries
        dd[i] = T(0);
        continue;
      }
      lse2[i] = lse[static_cast<std::ptrdiff_t>(h) * Lq + i] * T(A::log2e);
    }

    for (int kb = 0; kb < nk; kb += Tl::BKB) {
      const int mk = std::min(Tl::BKB, nk - kb);
      const T* kblk = kp + kb * DhP;
      const T* vblk = vp + kb * DhP;
      for (int qb = 0; qb < Lq; qb += Tl::BQB) {
        const int nq = std::min(Tl::BQB, Lq - qb);
        const int nv = static_cast<int>(A::round_up(nq, w));
#if TJEPA_BF16_NATIVE
        if constexpr (can_bf16) {
          if (bf16) {
            A::gemm<T, A::Store::overwrite, A::MR<T>, A::NV, A::Bf16Dot>(
                mk, nv, int(Dh2), words(lay.kr16) + kb * Dh2, Dh2, 1, words(lay.qt16) + qb * Dh2, BQB, st, BQB);
            A::gemm<T, A::Store::overwrite, A::MR<T>, A::NV, A::Bf16Dot>(
                mk, nv, int(Dh2), words(lay.vr16) + kb * Dh2, Dh2, 1, words(lay.dot16) + qb * Dh2, BQB, dpt, BQB);
          }
        }
        if (!bf16)
#endif
        {
          A::gemm<T, A::Store::overwrite>(mk, nv, Dh, kblk, DhP, 1, qt + qb * Dh, Tl::BQB, st, Tl::BQB);   // S^T
          A::gemm<T, A::Store::overwrite>(mk, nv, Dh, vblk, DhP, 1, dot + qb * Dh, Tl::BQB, dpt, Tl::BQB);  // dP^T
        }
#if TJEPA_BF16_NATIVE
        if constexpr (can_bf16) {
          if (bf16) {
            // P^T and dS^T straight into bf16 words: dV += P^T dO, dK += dS^T Q (A paired along
            // queries), dQ += dS K (A paired across keys).
            const int nq2 = (nq + 1) / 2, mk2 = (mk + 1) / 2;
            A::backward_tile_pairs(st, dpt, BQB, mk, nq, c, lse2 + qb, dd + qb, words(lay.pt16), words(lay.dst16),
                                   words(lay.ds16));
            const std::uint32_t* dob = words(lay.do16) + qb / 2 * DhP;
            const std::uint32_t* qpb = words(lay.q16) + qb / 2 * DhP;
            using Bd = A::Bf16Dot;
            if (qb == 0) {
              A::gemm<T, A::Store::overwrite, A::MR<T>, A::NV, Bd>(mk, int(DhP), nq2, words(lay.pt16), nq2, 1, dob, DhP,
                                                                   dva, DhP);
              A::gemm<T, A::Store::overwrite, A::MR<T>, A::NV, Bd>(mk, int(DhP), nq2, words(lay.dst16), nq2, 1, qpb, DhP,
                                                                   dka, DhP);
            } else {
              A::gemm<T, A::Store::add, A::MR<T>, A::NV, Bd>(mk, int(DhP), nq2, words(lay.pt16), nq2, 1, dob, DhP, dva,
                                                             DhP);
              A::gemm<T, A::Store::add, A::MR<T>, A::NV, Bd>(mk, int(DhP), nq2, words(lay.dst16), nq2, 1, qpb, DhP, dka,
                                                             DhP);
            }
            A::gemm<T, A::Store::add, A::MR<T>, A::NV, Bd>(nq, int(DhP), mk2, words(lay.ds16), 1, BQB,
                                                           words(lay.kx16) + kb / 2 * DhP, DhP, dqa + qb * DhP, DhP);
            continue;
          }
        }
#endif
        const V cv(c);
        for (int r = 0; r < mk; ++r) {
          T* srow = st + r * Tl::BQB;
          T* dprow = dpt + r * Tl::BQB;
          for (int j = 0; j < nv; j += w) {
            const V p = A::exp2(xsimd::fms(V::load_aligned(srow + j), cv, V::load_aligned(lse2 + qb + j)));
            p.store_aligned(srow + j);
            (p * (V::load_aligned(dprow + j) - V::load_aligned(dd + qb + j))).store_aligned(dprow + j);
          }
        }
        if (qb == 0) {
          A::gemm<T, A::Store::overwrite>(mk, static_cast<int>(DhP), nq, st, Tl::BQB, 1, dop, DhP, dva, DhP);
          A::gemm<T, A::Store::overwrite>(mk, static_cast<int>(DhP), nq, dpt, Tl::BQB, 1, qp, DhP, dka, DhP);
        } else {
          A::gemm<T, A::Store::add>(mk, static_cast<int>(DhP), nq, st, Tl::BQB, 1, dop + qb * DhP, DhP, dva, DhP);
          A::gemm<T, A::Store::add>(mk, static_cast<int>(DhP), nq, dpt, Tl::BQB, 1, qp + qb * DhP, DhP, dka, DhP);
        }
        // dQ_blk [nq, DhP] += dS K_blk, dS read transposed out of the dS^T tile.
        A::gemm<T, A::Store::add>(nq, static_cast<int>(DhP), mk, dpt, 1, Tl::BQB, kblk, DhP, dqa + qb * DhP, DhP);
      }
      for (int r = 0; r < mk; ++r) {
        const std::ptrdiff_t j = keys[kb + r];
        T* dkj = dk + j * s.ldk + c0;
        T* dvj = dv + j * s.ldv + c0;
        const T* dkr = dka + r * DhP;
        const T* dvr = dva + r * DhP;
        detail::simd_axpy(scale, dkr, dkj, std::size_t(Dh));
        detail::simd_add(dvr, dvj, std::size_t(Dh));
      }
    }
    for (int i = 0; i < Lq; ++i) {
      T* dqi = dq + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      const T* src = dqa + static_cast<std::ptrdiff_t>(i) * DhP;
      detail::simd_axpy(scale, src, dqi, std::size_t(Dh));
    }
  }
}

}  // namespace tjepa::kernels

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
