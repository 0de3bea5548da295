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

// The rows of one attention call: B samples of L tokens each; key_valid [B, L] (nonzero: the key
// may be attended to) or nullptr for all; the query rows are [q_from, L) of each sample.
struct AttentionRows {
  int B = 0, L = 0;
  const std::uint8_t* key_valid = nullptr;
  int q_from = 0;
  int Lq() const { return L - q_from; }
};

// What a forward pass fills and its backward reads. Self-attention: qkv [B·L, 3d] (columns
// q | k | v). Cross-attention: q [B, d] and kv [B·L, 2d]. Both: att [B·Lq, d], the heads' outputs
// before proj, and lse [B, H, Lq], the softmax's log-sum-exps (nullptr in inference).
template <class T>
struct AttentionSaved {
  T* qkv = nullptr;
  T* q = nullptr;
  T* kv = nullptr;
  T* att = nullptr;
  T* lse = nullptr;
};

// The precision of the attention products (QKᵀ, PV) of a forward whose backward is fp32 (cross-
// and causal attention): the workspace's, unless the forward keeps its statistics for that
// backward (it recomputes P from the saved log-sum-exp, which must come from the same
// arithmetic). SelfAttention runs forward and backward in the workspace's precision.
template <class T>
Precision attention_precision(const AttentionSaved<T>& saved, const Workspace<T>& ws) {
  return saved.lse ? Precision::fp32 : ws.precision;
}

// A backward pass's scratch, shaped like the saved buffers of the same names.
template <class T>
struct AttentionScratch {
  T* dqkv = nullptr;
  T* dq = nullptr;
  T* dkv = nullptr;
  T* datt = nullptr;
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

  // x [B·L, d] → y [B·Lq, d], Lq = L − q_from: the outputs of the query rows [q_from, L) of each
  // sample (q_from = 0: every row; the predictor's last block keeps only its target rows).
  // saved.qkv and saved.att are filled; saved.lse may be nullptr (inference).
  template <class T>
  void forward(const ParamSet<T>& ps, const AttentionRows& r, const T* x, const AttentionSaved<T>& saved, T* y,
               Workspace<T>& ws, const T* residual = nullptr) const {
    const int d = dim(), Dh = d / heads, B = r.B, L = r.L, q_from = r.q_from, Lq = r.Lq();
    T* qkv_buf = saved.qkv;
    qkv.forward(ps, x, qkv_buf, B * L, ws.weights());
    ws.mark("qkv");
    // Tasks: (sample, head, block of query rows). Query blocks only split work when there are too
    // few (sample, head) pairs to keep every thread busy (batch 1 has 3 heads for 2+ threads).
    const int pairs = B * heads, threads = detail::max_threads();
    const int chunks = pairs >= 2 * threads ? 1 : std::max(1, std::min((2 * threads + pairs - 1) / pairs, Lq / 32));
    const int rows_per = (Lq + chunks - 1) / chunks;
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(head_shape(L, q_from));
    TJEPA_OMP(omp parallel for schedule(dynamic) if (pairs * chunks > 1))
    for (int task = 0; task < pairs * chunks; ++task) {
      const int bh = task / chunks, b = bh / heads, h = bh % heads;
      const int r0 = (task % chunks) * rows_per, r1 = std::min(Lq, r0 + rows_per);
      if (r0 >= r1) continue;
      kernels::AttentionShape s = head_shape(L, q_from);
      s.Lq = r1 - r0;
      const T* k = qkv_buf + std::size_t(b) * L * 3 * d + d + std::size_t(h) * Dh;
      kernels::attention_forward(s, k - d + std::size_t(q_from + r0) * 3 * d, k, k + d,
                                 r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr,
                                 saved.att + (std::size_t(b) * Lq + r0) * d + std::size_t(h) * Dh,
                                 saved.lse ? saved.lse + std::size_t(bh) * L + r0 : nullptr, aws[detail::thread_id()],
                                 ws.precision);  // its backward runs in the same precision
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
    detail::parallel_fill(dqkv, dqkv + std::size_t(B) * L * 3 * d, T(0));
    const kernels::AttentionShape s = head_shape(L, q_from);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B * heads > 1))
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
    qkv.backward(ps, dqkv, x, dx, B * L, ws.precision);  // qkv = x · Wqkvᵀ + b
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
  kernels::AttentionShape shape(int L) const {
    const int d = dim();
    return {1, L, heads, d / heads, d, 2 * d, 2 * d, d};
  }

  // query [B, d] (one row per sample), x [B·L, d] → y [B, d] (r.q_from is 0). saved.q [B, d],
  // saved.kv [B·L, 2d] and saved.att [B, d] are filled; saved.lse [B, H] may be nullptr.
  template <class T>
  void forward(const ParamSet<T>& ps, const AttentionRows& r, const T* query, const T* x,
               const AttentionSaved<T>& saved, T* y, Workspace<T>& ws, const T* residual = nullptr) const {
    const int d = dim(), B = r.B, L = r.L;
    require<ShapeError>(r.q_from == 0, "CrossAttention::forward: q_from = ", r.q_from, ", expected 0");
    q.forward(ps, query, saved.q, B, ws.weights());
    kv.forward(ps, x, saved.kv, B * L, ws.weights());
    const kernels::AttentionShape s = shape(L);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const T* k = saved.kv + std::size_t(b) * L * 2 * d;
      kernels::attention_forward(s, saved.q + std::size_t(b) * d, k, k + d,
                                 r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr,
                                 saved.att + std::size_t(b) * d, saved.lse ? saved.lse + std::size_t(b) * heads : nullptr,
                                 aws[detail::thread_id()], attention_precision(saved, ws));
    }
    if (residual)
      proj.forward_residual(ps, saved.att, residual, y, B);
    else
      proj.forward(ps, saved.att, y, B);
  }

  // dquery [B, d] and dx [B·L, d] (either may be nullptr) += gradients given dy [B, d]; the
  // parameters' gradients +=. scratch.dq [B, d], scratch.dkv [B·L, 2d], scratch.datt [B, d].
  template <class T>
  void backward(ParamSet<T>& ps, const AttentionRows& r, const T* dy, const T* query, const T* x,
                const AttentionSaved<T>& saved, const AttentionScratch<T>& scratch, T* dquery, T* dx,
                Workspace<T>& ws) const {
    const int d = dim(), B = r.B, L = r.L;
    std::fill(scratch.datt, scratch.datt + std::size_t(B) * d, T(0));
    proj.backward(ps, dy, saved.att, scratch.datt, B);
    std::fill(scratch.dq, scratch.dq + std::size_t(B) * d, T(0));
    std::fill(scratch.dkv, scratch.dkv + std::size_t(B) * L * 2 * d, T(0));
    const kernels::AttentionShape s = shape(L);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(s);
    TJEPA_OMP(omp parallel for schedule(static) if (B > 1))
    for (int b = 0; b < B; ++b) {
      const std::size_t ko = std::size_t(b) * L * 2 * d;
      kernels::attention_backward(s, saved.q + std::size_t(b) * d, saved.kv + ko, saved.kv + ko + d,
                                  r.key_valid ? r.key_valid + std::size_t(b) * L : nullptr,
                                  saved.att + std::size_t(b) * d, saved.lse + std::size_t(b) * heads,
                                  scratch.datt + std::size_t(b) * d, scratch.dq + std::size_t(b) * d,
                                  scratch.dkv + ko, scratch.dkv + ko + d, aws[detail::thread_id()]);
    }
    kv.backward(ps, scratch.dkv, x, dx, B * L);
    q.backward(ps, scratch.dq, query, dquery, B);
  }
};

}  // namespace tjepa
