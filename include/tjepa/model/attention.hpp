#pragma once
// Multi-head attention modules around the fused kernel of kernels/attention.hpp.
//
// SelfAttention (timm's Attention): <name>.qkv [3d, d] (+ bias), <name>.proj [d, d] (+ bias).
//   qkv = x · Wqkvᵀ + b  [B·L, 3d] (columns: q | k | v, head h at h·Dh within each)
//   att = softmax(q kᵀ / √Dh) v per sample and head  [B·L, d]
//   y   = att · Wprojᵀ + b  [B·L, d]
// SelfAttention's (sample, head) pairs run in parallel; each is one kernel call with H = 1 and
// the row strides of the fused buffers, so no L×L matrix is ever stored.
// CrossAttention (V-JEPA's attentive pooler): <name>.q [d, d], <name>.kv [2d, d], <name>.proj.
//   One learned query row, the same for every sample, attends to each sample's L tokens. The
//   result is the reference's (q = Wq·query + bq, [k | v] = x · Wkvᵀ + bkv, softmax(q_h k_hᵀ/√Dh)
//   v_h per head, then proj), computed without forming k and v: the query is folded into the key
//   weights once per call, u_h = Wk_hᵀ q_h / √Dh, so the logits are x_n · u_h (q_h · bk_h is the
//   same for every key and cancels in the softmax), and the values are taken after pooling,
//   att_h = Wv_h (Σ_n p_hn x_n) + bv_h (the weights sum to 1). That is 4·d·H flops per token
//   instead of the projection's 4·d², in the forward and again in the backward.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "tjepa/core/detail/simd.hpp"
#include "tjepa/kernels/attention.hpp"
#include "tjepa/kernels/softmax.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/workspace.hpp"

namespace tjepa {

// The rows of one attention call: B samples of L tokens each; key_valid [B, L] (nonzero: the key
// may be attended to) or nullptr for all; the query rows are [q_from, L) of each sample.
struct AttentionRows {
  int B = 0, L = 0;
  const std::uint8_t* key_valid = nullptr;
  int q_from = 0;
  int Lq() const { return L - q_from; }
};

// What a self-attention forward fills and its backward reads: qkv [B·L, 3d] (columns q | k | v),
// att [B·Lq, d], the heads' outputs before proj, and lse [B, H, Lq], the softmax's log-sum-exps
// (nullptr in inference).
template <class T>
struct AttentionSaved {
  T* qkv = nullptr;
  T* att = nullptr;
  T* lse = nullptr;
};

// What CrossAttention's forward fills (inference too) and its backward reads.
template <class T>
struct CrossAttentionSaved {
  T* q = nullptr;       // [d]     Wq · query + bq
  T* u = nullptr;       // [H, d]  head h's query folded into its key weights: Wk_hᵀ q_h / √Dh
  T* p = nullptr;       // [B, H, L] the attention weights
  T* pooled = nullptr;  // [B, H, d] Σ_n p_hn x_n
  T* att = nullptr;     // [B, d]  the heads' outputs before proj
};

// A backward pass's scratch, shaped like the saved buffers of the same names.
template <class T>
struct AttentionScratch {
  T* dqkv = nullptr;
  T* datt = nullptr;
};
template <class T>
struct CrossAttentionScratch {
  T* dq = nullptr;       // [d]
  T* datt = nullptr;     // [B, d]
  T* dpooled = nullptr;  // [B, H, d]
  T* du = nullptr;       // [B, H, d]
  T* dp = nullptr;       // [B, H, L]
  T* ds = nullptr;       // [B, H, L]
};

// Forward passes write y = residual + output (residual may equal y: y += output; nullptr: y =
// output). Backward passes add into every gradient they are given (parameters and inputs).
struct SelfAttention {
  LinearParams qkv, proj;
  int heads = 0;

  template <class T>
  static SelfAttention add(ParamSet<T>& ps, const std::string& name, int dim, int heads, bool qkv_bias,
                           bool proj_bias) {
    require<ConfigError>(heads > 0 && dim % heads == 0, name, ": dim ", dim, " is not a multiple of heads ",
                         heads);
    SelfAttention a;
    a.heads = heads;
    a.qkv = LinearParams::add(ps, name + ".qkv", dim, 3 * dim, qkv_bias);
    a.proj = LinearParams::add(ps, name + ".proj", dim, dim, proj_bias);
    return a;
  }
  int dim() const { return proj.out; }

  // Head h of one sample as a kernel shape over the fused qkv buffer: queries are the rows
  // [q_from, L) of the sample, keys and values all L rows.
  kernels::AttentionShape head_shape(int L, int q_from) const {
    const int d = dim();
    return {L - q_from, L, 1, d / heads, 3 * d, 3 * d, 3 * d, d};
  }

  // Head h of sample b for its query rows [q_from + r0, q_from + r1) on the calling thread, from
  // saved.qkv into saved.att (and saved.lse unless nullptr). precision: the products' (its
  // backward runs in the same).
  template <class T>
  void head_forward(const AttentionRows& r, const AttentionSaved<T>& saved, int b, int h, int r0, int r1,
                    kernels::AttentionWorkspace<T>& aws, Precision precision) const {
    if (r0 >= r1) return;
    const int d = dim(), Dh = d / heads, L = r.L, Lq = r.Lq();
    kernels::AttentionShape s = head_shape(L, r.q_from);
    s.Lq = r1 - r0;
    const T* k = saved.qkv + std::size_t(b) * L * 3 * d + d + std::size_t(h) * Dh;
    kernels::attention_forward(s, k - d + std::size_t(r.q_from + r0) * 3 * d, k, k + d,
                               r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr,
                               saved.att + (std::size_t(b) * Lq + r0) * d + std::size_t(h) * Dh,
                               saved.lse ? saved.lse + std::size_t(b * heads + h) * L + r0 : nullptr, aws, precision);
  }
  // Every head for the rows [m0, m1) of [B·Lq] (the samples they fall in) on the calling thread.
  template <class T>
  void rows_forward(const AttentionRows& r, const AttentionSaved<T>& saved, int m0, int m1,
                    kernels::AttentionWorkspace<T>& aws, Precision precision) const {
    const int Lq = r.Lq();
    for (int b = m0 / Lq; b < r.B && b * Lq < m1; ++b)
      for (int h = 0; h < heads; ++h)
        head_forward(r, saved, b, h, std::max(m0 - b * Lq, 0), std::min(m1 - b * Lq, Lq), aws, precision);
  }

  // x [B·L, d] → y [B·Lq, d], Lq = L − q_from: the outputs of the query rows [q_from, L) of each
  // sample (q_from = 0: every row; the predictor's last block keeps only its target rows).
  // saved.qkv and saved.att are filled; saved.lse may be nullptr (inference).
  template <class T>
  void forward(const ParamSet<T>& ps, const AttentionRows& r, const T* x, const AttentionSaved<T>& saved, T* y,
               Workspace<T>& ws, const T* residual = nullptr) const {
    const int B = r.B, L = r.L, q_from = r.q_from, Lq = r.Lq();
    qkv.forward(ps, x, saved.qkv, B * L, ws.weights());
    ws.mark("qkv");
    // Tasks: (sample, head, block of query rows). Query blocks only split work when there are too
    // few (sample, head) pairs to keep every thread busy (batch 1 has 3 heads for 2+ threads); at
    // batch 1, thread t then takes query block t of every head, the rows the products around it
    // give it (detail::owns_rows).
    const int pairs = B * heads, threads = detail::max_threads();
    const int chunks = pairs >= 2 * threads ? 1 : std::max(1, std::min((2 * threads + pairs - 1) / pairs, Lq / 32));
    const bool own = B == 1 && chunks > 1 && detail::owns_rows(Lq, threads);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(head_shape(L, q_from));
    if (own) {
      TJEPA_OMP(omp parallel num_threads(threads))
      {
        const int t = detail::thread_id(), n = detail::team_size();
        rows_forward(r, saved, detail::row_begin(Lq, t, n), detail::row_begin(Lq, t + 1, n), aws[t], ws.precision);
      }
    } else {
      const int rows_per = (Lq + chunks - 1) / chunks;
      TJEPA_OMP(omp parallel for schedule(dynamic) if (pairs * chunks > 1))
      for (int task = 0; task < pairs * chunks; ++task) {
        const int bh = task / chunks, r0 = (task % chunks) * rows_per;
        head_forward(r, saved, bh / heads, bh % heads, r0, std::min(Lq, r0 + rows_per), aws[detail::thread_id()],
                     ws.precision);
      }
    }
    ws.mark("attention");
    if (residual)
      proj.forward_residual(ps, saved.att, residual, y, B * Lq, ws.weights());
    else
      proj.forward(ps, saved.att, y, B * Lq, ws.weights());
    ws.mark("proj");
  }

  // dx [B·L, d] += ∂L/∂x given dy [B·Lq, d]; the parameters' gradients +=.
  template <class T>
  void backward(ParamSet<T>& ps, const AttentionRows& r, const T* dy, const T* x, const AttentionSaved<T>& saved,
                const AttentionScratch<T>& scratch, T* dx, Workspace<T>& ws) const {
    const int d = dim(), Dh = d / heads, B = r.B, L = r.L, q_from = r.q_from;
    const std::size_t Mq = std::size_t(B) * r.Lq();
    T* dqkv = scratch.dqkv;
    detail::parallel_fill(scratch.datt, scratch.datt + Mq * d, T(0));
    proj.backward(ps, dy, saved.att, scratch.datt, int(Mq), ws.precision);  // y = att · Wprojᵀ + b
    ws.mark("proj backward");
    detail::parallel_fill(dqkv, dqkv + std::size_t(B) * L * 3 * d, T(0));
    const kernels::AttentionShape s = head_shape(L, q_from);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(dynamic) if (B * heads > 1))
    for (int bh = 0; bh < B * heads; ++bh) {
      const int b = bh / heads, h = bh % heads;
      const std::size_t ko = std::size_t(b) * L * 3 * d + d + std::size_t(h) * Dh;
      const std::size_t qo = ko - d + std::size_t(q_from) * 3 * d;
      const std::size_t oo = std::size_t(b) * r.Lq() * d + std::size_t(h) * Dh;
      kernels::attention_backward(s, saved.qkv + qo, saved.qkv + ko, saved.qkv + ko + d,
                                  r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr, saved.att + oo,
                                  saved.lse + std::size_t(bh) * L, scratch.datt + oo, dqkv + qo, dqkv + ko,
                                  dqkv + ko + d, aws[detail::thread_id()], ws.precision);
    }
    ws.mark("attention backward");
    qkv.backward(ps, dqkv, x, dx, B * L, ws.precision);  // qkv = x · Wqkvᵀ + b
    ws.mark("qkv backward");
  }
};

struct CrossAttention {
  LinearParams q, kv, proj;
  int heads = 0;

  template <class T>
  static CrossAttention add(ParamSet<T>& ps, const std::string& name, int dim, int heads, bool bias) {
    require<ConfigError>(heads > 0 && dim % heads == 0, name, ": dim ", dim, " is not a multiple of heads ",
                         heads);
    CrossAttention a;
    a.heads = heads;
    a.q = LinearParams::add(ps, name + ".q", dim, dim, bias);
    a.kv = LinearParams::add(ps, name + ".kv", dim, 2 * dim, bias);
    a.proj = LinearParams::add(ps, name + ".proj", dim, dim, bias);
    return a;
  }
  int dim() const { return proj.out; }
  // Whether sample b has a key to attend to. One whose keys are all masked has no distribution to
  // attend with: its output is 0 (as kernels::attention's) and it passes no gradient to kv.
  static bool has_keys(const AttentionRows& r, int b) {
    return r.key_valid == nullptr || std::any_of(r.key_valid + std::size_t(b) * r.L, r.key_valid + std::size_t(b + 1) * r.L,
                                                 [](std::uint8_t v) { return v != 0; });
  }

  // query [d] (the one query row every sample shares), x [B·L, d] → y [B, d] (r.q_from is 0).
  // Fills saved.{q, u, p, pooled, att}; the backward reads them.
  template <class T>
  void forward(const ParamSet<T>& ps, const AttentionRows& r, const T* query, const T* x,
               const CrossAttentionSaved<T>& saved, T* y, const T* residual = nullptr) const {
    const int d = dim(), H = heads, Dh = d / H, B = r.B, L = r.L;
    require<ShapeError>(r.q_from == 0, "CrossAttention::forward: q_from = ", r.q_from, ", expected 0");
    q.forward(ps, query, saved.q, 1);
    const T* Wk = ps.value(kv.weight);  // rows [0, d) of kv: the keys' weights
    const T* Wv = Wk + std::size_t(d) * d;
    const T* bv = kv.has_bias ? ps.value(kv.bias) + d : nullptr;
    const T scale = T(1) / std::sqrt(T(Dh));
    // u_h = scale · Wk_hᵀ q_h: the logits of head h are x_n · u_h (plus q_h · bk_h, the same for
    // every key, which the softmax cancels).
    std::fill(saved.u, saved.u + std::size_t(H) * d, T(0));
    for (int i = 0; i < d; ++i)
      detail::simd_axpy(scale * saved.q[i], Wk + std::size_t(i) * d, saved.u + std::size_t(i / Dh) * d, d);
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const T* xb = x + std::size_t(b) * L * d;
      const std::uint8_t* valid = r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr;
      T* p = saved.p + std::size_t(b) * H * L;  // [H, L]
      T* pooled = saved.pooled + std::size_t(b) * H * d;
      T* att = saved.att + std::size_t(b) * d;
      std::fill(pooled, pooled + std::size_t(H) * d, T(0));
      if (!has_keys(r, b)) {
        std::fill(p, p + std::size_t(H) * L, T(0));
        std::fill(att, att + d, T(0));
        continue;
      }
      for (int n = 0; n < L; ++n) {
        const bool ok = valid == nullptr || valid[n] != 0;
        for (int h = 0; h < H; ++h)
          p[std::size_t(h) * L + n] = ok ? detail::simd_dot(xb + std::size_t(n) * d, saved.u + std::size_t(h) * d, d)
                                         : -std::numeric_limits<T>::infinity();
      }
      kernels::softmax_forward(p, p, H, L);
      for (int n = 0; n < L; ++n) {
        if (valid && !valid[n]) continue;  // a masked token is never read (it may hold anything)
        for (int h = 0; h < H; ++h)
          detail::simd_axpy(p[std::size_t(h) * L + n], xb + std::size_t(n) * d, pooled + std::size_t(h) * d, d);
      }
      // att_h = Wv_h · pooled_h + bv_h (Σ_n p_n = 1 carries the bias through)
      for (int i = 0; i < d; ++i)
        att[i] = detail::simd_dot(Wv + std::size_t(i) * d, pooled + std::size_t(i / Dh) * d, d) + (bv ? bv[i] : T(0));
    }
    if (residual)
      proj.forward_residual(ps, saved.att, residual, y, B);
    else
      proj.forward(ps, saved.att, y, B);
  }

  // dquery [d] and dx [B·L, d] (either may be nullptr) += gradients given dy [B, d]; the
  // parameters' gradients +=. kv.bias's key half gets none: the softmax cancels it.
  template <class T>
  void backward(ParamSet<T>& ps, const AttentionRows& r, const T* dy, const T* query, const T* x,
                const CrossAttentionSaved<T>& saved, const CrossAttentionScratch<T>& scratch, T* dquery, T* dx) const {
    const int d = dim(), H = heads, Dh = d / H, B = r.B, L = r.L;
    const std::size_t Bd = std::size_t(B) * d, HL = std::size_t(H) * L, Hd = std::size_t(H) * d;
    std::fill(scratch.datt, scratch.datt + Bd, T(0));
    proj.backward(ps, dy, saved.att, scratch.datt, B);
    const T* Wk = ps.value(kv.weight);
    const T* Wv = Wk + std::size_t(d) * d;
    T* dWk = ps.grad(kv.weight);
    T* dWv = dWk + std::size_t(d) * d;
    T* dbv = kv.has_bias ? ps.grad(kv.bias) + d : nullptr;
    const T scale = T(1) / std::sqrt(T(Dh));
    // att_h = Wv_h · pooled_h + bv_h: dWv, dbv (rows in parallel, samples in order)
    for (int b = 0; b < B; ++b)  // att = 0 whatever Wv and bv are
      if (!has_keys(r, b)) std::fill(scratch.datt + std::size_t(b) * d, scratch.datt + std::size_t(b + 1) * d, T(0));
    TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(B) * d * d > detail::parallel_grain))
    for (int i = 0; i < d; ++i)
      for (int b = 0; b < B; ++b) {
        const T g = scratch.datt[std::size_t(b) * d + i];
        detail::simd_axpy(g, saved.pooled + std::size_t(b) * Hd + std::size_t(i / Dh) * d, dWv + std::size_t(i) * d, d);
        if (dbv) dbv[i] += g;
      }
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const T* xb = x + std::size_t(b) * L * d;
      const T* p = saved.p + std::size_t(b) * HL;
      T* dpooled = scratch.dpooled + std::size_t(b) * Hd;
      T* dp = scratch.dp + std::size_t(b) * HL;
      T* ds = scratch.ds + std::size_t(b) * HL;
      T* du = scratch.du + std::size_t(b) * Hd;
      std::fill(du, du + Hd, T(0));
      std::fill(dpooled, dpooled + Hd, T(0));
      std::fill(ds, ds + HL, T(0));
      for (int i = 0; i < d; ++i)
        detail::simd_axpy(scratch.datt[std::size_t(b) * d + i], Wv + std::size_t(i) * d, dpooled + std::size_t(i / Dh) * d, d);
      // pooled_h = Σ_n p_hn x_n: ∂/∂p_hn = dpooled_h · x_n, then through the softmax to the logits
      const std::uint8_t* valid = r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr;
      for (int n = 0; n < L; ++n)
        for (int h = 0; h < H; ++h)
          dp[std::size_t(h) * L + n] = valid && !valid[n] ? T(0)  // p = 0 there, and x_n is not read
                                                          : detail::simd_dot(xb + std::size_t(n) * d, dpooled + std::size_t(h) * d, d);
      kernels::softmax_backward(ds, dp, p, H, L);
      // logits s_hn = x_n · u_h: du_h = Σ_n ds_hn x_n; dx_n += Σ_h ds_hn u_h + p_hn dpooled_h
      for (int n = 0; n < L; ++n) {
        if (valid && !valid[n]) continue;  // ds = p = 0: no gradient
        const T* xn = xb + std::size_t(n) * d;
        for (int h = 0; h < H; ++h) {
          const T g = ds[std::size_t(h) * L + n];
          detail::simd_axpy(g, xn, du + std::size_t(h) * d, d);
          if (dx) {
            T* dxn = dx + (std::size_t(b) * L + n) * d;
            detail::simd_axpy(g, saved.u + std::size_t(h) * d, dxn, d);
            detail::simd_axpy(p[std::size_t(h) * L + n], dpooled + std::size_t(h) * d, dxn, d);
          }
        }
      }
    }
    // u_h = scale · Wk_hᵀ q_h: dWk_h += scale · q_h du_hᵀ, dq_h = scale · Wk_h du_h (du summed over samples)
    T* du = scratch.du;
    for (int b = 1; b < B; ++b)
      for (std::size_t j = 0; j < Hd; ++j) du[j] += scratch.du[std::size_t(b) * Hd + j];
    for (int i = 0; i < d; ++i) {
      const T* duh = du + std::size_t(i / Dh) * d;
      detail::simd_axpy(scale * saved.q[i], duh, dWk + std::size_t(i) * d, d);
      scratch.dq[i] = scale * detail::simd_dot(Wk + std::size_t(i) * d, duh, d);
    }
    q.backward(ps, scratch.dq, query, dquery, 1);
  }
};

}  // namespace tjepa
