#pragma once
// Multi-head attention modules around the fused kernel of kernels/attention.hpp.
//
// SelfAttention (timm's Attention): <name>.qkv [3d, d] (+ bias), <name>.proj [d, d] (+ bias).
//   qkv = x · Wqkvᵀ + b  [B·L, 3d] (columns: q | k | v, head h at h·Dh within each)
//   att = softmax(q kᵀ / √Dh) v per sample and head  [B·L, d]
//   y   = att · Wprojᵀ + b  [B·L, d]
// CrossAttention (V-JEPA's attentive pooler): <name>.q [d, d], <name>.kv [2d, d], <name>.proj.
//   One query row per sample attends to that sample's L tokens.
// The (sample, head) pairs run in parallel; each is one kernel call with H = 1 and the row
// strides of the fused buffers, so no L×L matrix is ever stored.
#include <algorithm>
#include <cstdint>
#include <string>

#include "tjepa/model/kernels/attention.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/workspace.hpp"

namespace tjepa {

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
  AttentionShape head_shape(int L, int q_from) const {
    const int d = dim();
    return {L - q_from, L, 1, d / heads, 3 * d, 3 * d, 3 * d, d};
  }

  // x [B·L, d] → y [B·Lq, d] (y += when accumulate), Lq = L - q_from: the outputs of the query
  // rows [q_from, L) of each sample (q_from = 0: every row; the predictor's last block keeps only
  // its target rows). qkv_buf [B·L, 3d] and att [B·Lq, d] are filled (kept for backward); lse
  // [B, H, L] may be nullptr (inference). key_valid [B, L] or nullptr. residual [B·Lq, d] (with
  // accumulate false) or nullptr: y = residual + the output, the block's residual add without a
  // copy of the stream.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int B, int L, const std::uint8_t* key_valid, T* qkv_buf,
               T* att, T* lse, T* y, bool accumulate, Workspace<T>& ws, int q_from = 0,
               const T* residual = nullptr) const {
    const int d = dim(), Dh = d / heads, Lq = L - q_from;
    qkv.forward(ps, x, qkv_buf, B * L, ws.frozen());
    ws.mark("qkv");
    // Tasks: (sample, head, block of query rows). Query blocks only split work when there are too
    // few (sample, head) pairs to keep every thread busy (batch 1 has 3 heads for 2+ threads).
    const int pairs = B * heads, threads = detail::max_threads();
    const int chunks = pairs >= 2 * threads ? 1 : std::max(1, std::min((2 * threads + pairs - 1) / pairs, Lq / 32));
    const int rows_per = (Lq + chunks - 1) / chunks;
    AttentionWorkspace<T>* aws = ws.attention_per_thread(head_shape(L, q_from));
    TJEPA_OMP(omp parallel for schedule(dynamic) if (pairs * chunks > 1))
    for (int task = 0; task < pairs * chunks; ++task) {
      const int bh = task / chunks, b = bh / heads, h = bh % heads;
      const int r0 = (task % chunks) * rows_per, r1 = std::min(Lq, r0 + rows_per);
      if (r0 >= r1) continue;
      AttentionShape s = head_shape(L, q_from);
      s.Lq = r1 - r0;
      const T* k = qkv_buf + std::size_t(b) * L * 3 * d + d + std::size_t(h) * Dh;
      attention_forward(s, k - d + std::size_t(q_from + r0) * 3 * d, k, k + d,
                        key_valid ? key_valid + std::size_t(b) * L : nullptr,
                        att + (std::size_t(b) * Lq + r0) * d + std::size_t(h) * Dh,
                        lse ? lse + std::size_t(bh) * L + r0 : nullptr, aws[detail::thread_id()]);
    }
    ws.mark("attention");
    if (accumulate) residual = y;
    if (residual)
      proj.forward_residual(ps, att, residual, y, B * Lq, ws.frozen());
    else
      proj.forward(ps, att, y, B * Lq, ws.frozen());
    ws.mark("proj");
  }

  // dx [B·L, d] += ∂L/∂x given dy [B·Lq, d] (= when add_dx is false). dqkv [B·L, 3d] and datt
  // [B·Lq, d] are scratch.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, const T* x, int B, int L, const std::uint8_t* key_valid,
                const T* qkv_buf, const T* att, const T* lse, T* dqkv, T* datt, T* dx, Workspace<T>& ws,
                int q_from = 0, bool add_dx = true) const {
    const int d = dim(), Dh = d / heads, Lq = L - q_from;
    const std::size_t Mq = std::size_t(B) * Lq;
    proj.backward(ps, dy, att, datt, int(Mq), false);  // y = att · Wprojᵀ + b
    detail::parallel_fill(dqkv, dqkv + std::size_t(B) * L * 3 * d, T(0));
    const AttentionShape s = head_shape(L, q_from);
    AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B * heads > 1))
    for (int bh = 0; bh < B * heads; ++bh) {
      const int b = bh / heads, h = bh % heads;
      const std::size_t ko = std::size_t(b) * L * 3 * d + d + std::size_t(h) * Dh;
      const std::size_t qo = ko - d + std::size_t(q_from) * 3 * d;
      const std::size_t oo = std::size_t(b) * Lq * d + std::size_t(h) * Dh;
      attention_backward(s, qkv_buf + qo, qkv_buf + ko, qkv_buf + ko + d,
                         key_valid ? key_valid + std::size_t(b) * L : nullptr, att + oo, lse + std::size_t(bh) * L,
                         datt + oo, dqkv + qo, dqkv + ko, dqkv + ko + d, aws[detail::thread_id()]);
    }
    qkv.backward(ps, dqkv, x, dx, B * L, add_dx);  // qkv = x · Wqkvᵀ + b
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
  AttentionShape shape(int L) const {
    const int d = dim();
    return {1, L, heads, d / heads, d, 2 * d, 2 * d, d};
  }

  // query [B, d] (one row per sample), x [B·L, d] → y [B, d] (y += when accumulate).
  // qbuf [B, d], kvbuf [B·L, 2d], att [B, d] are kept for backward; lse [B, H] may be nullptr.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* query, const T* x, int B, int L, const std::uint8_t* key_valid,
               T* qbuf, T* kvbuf, T* att, T* lse, T* y, bool accumulate, Workspace<T>& ws) const {
    const int d = dim();
    q.forward(ps, query, qbuf, B, ws.frozen());
    kv.forward(ps, x, kvbuf, B * L, ws.frozen());
    const AttentionShape s = shape(L);
    AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const T* k = kvbuf + std::size_t(b) * L * 2 * d;
      attention_forward(s, qbuf + std::size_t(b) * d, k, k + d, key_valid ? key_valid + std::size_t(b) * L : nullptr,
                        att + std::size_t(b) * d, lse ? lse + std::size_t(b) * heads : nullptr,
                        aws[detail::thread_id()]);
    }
    if (accumulate)
      proj.forward_accumulate(ps, att, y, B);
    else
      proj.forward(ps, att, y, B);
  }

  // dquery [B, d] and dx [B·L, d] (either may be nullptr) += gradients given dy [B, d].
  // dq [B, d], dkv [B·L, 2d], datt [B, d] are scratch.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, const T* query, const T* x, int B, int L,
                const std::uint8_t* key_valid, const T* qbuf, const T* kvbuf, const T* att, const T* lse, T* dq,
                T* dkv, T* datt, T* dquery, T* dx, Workspace<T>& ws) const {
    const int d = dim();
    std::fill(datt, datt + std::size_t(B) * d, T(0));
    proj.backward(ps, dy, att, datt, B);
    std::fill(dq, dq + std::size_t(B) * d, T(0));
    std::fill(dkv, dkv + std::size_t(B) * L * 2 * d, T(0));
    const AttentionShape s = shape(L);
    AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const std::size_t ko = std::size_t(b) * L * 2 * d;
      attention_backward(s, qbuf + std::size_t(b) * d, kvbuf + ko, kvbuf + ko + d,
                         key_valid ? key_valid + std::size_t(b) * L : nullptr, att + std::size_t(b) * d,
                         lse + std::size_t(b) * heads, datt + std::size_t(b) * d, dq + std::size_t(b) * d,
                         dkv + ko, dkv + ko + d, aws[detail::thread_id()]);
    }
    kv.backward(ps, dkv, x, dx, B * L);
    q.backward(ps, dq, query, dquery, B);
  }
};

}  // namespace tjepa
