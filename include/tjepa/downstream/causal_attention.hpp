#pragma once
// Causal multi-head self-attention for the sequence head (paper, Sec. IV-B): position l of a
// sequence attends to positions 0..l only. Sequences are short (10–12 windows, Sec. IV-D), so
// each query row is one call of the fused kernel (kernels/attention.hpp) over the prefix of keys
// [0, l] — the mask is the key range, nothing else changes. Names as timm's Attention:
// <name>.qkv [3d, d] (+ bias), <name>.proj [d, d] (+ bias).
//
//   qkv = x · Wqkvᵀ + b                       x [B·L, d] → [B·L, 3d] (columns q | k | v)
//   att[b, l] = softmax(q_l k_{0..l}ᵀ / √Dh) v_{0..l}     per head             [B·L, d]
//   y   = att · Wprojᵀ + b                    [B·L, d]
#include <algorithm>
#include <cstdint>
#include <string>

#include "tjepa/model/attention.hpp"
#include "tjepa/kernels/attention.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/workspace.hpp"

namespace tjepa {

struct CausalSelfAttention {
  LinearParams qkv, proj;
  int heads = 0;

  // The parameters of a SelfAttention (model/attention.hpp): only the kernel calls differ.
  template <class T>
  static CausalSelfAttention add(ParamSet<T>& ps, const std::string& name, int dim, int heads, bool bias) {
    const SelfAttention a = SelfAttention::add(ps, name, dim, heads, bias, bias);
    return {a.qkv, a.proj, a.heads};
  }
  int dim() const { return proj.out; }
  // Query row l of one head over the fused qkv buffer: 1 query, l + 1 keys.
  kernels::AttentionShape row_shape(int l) const {
    const int d = dim();
    return {1, l + 1, 1, d / heads, 3 * d, 3 * d, 3 * d, d};
  }

  // x [B·L, d] → y [B·L, d] = residual + attention (r.key_valid and r.q_from unused: the causal
  // mask is the key set). saved.qkv [B·L, 3d], saved.att [B·L, d] and saved.lse [B, H, L] are
  // filled (kept for backward).
  template <class T>
  void forward(const ParamSet<T>& ps, const AttentionRows& r, const T* x, const AttentionSaved<T>& saved, T* y,
               Workspace<T>& ws, const T* residual = nullptr) const {
    const int B = r.B, L = r.L;
    require<ShapeError>(B > 0 && L > 0, "CausalSelfAttention::forward: B = ", B, ", L = ", L, ", expected > 0");
    require<ShapeError>(r.q_from == 0 && r.key_valid == nullptr,
                        "CausalSelfAttention::forward: q_from and key_valid are not used, expected 0 and nullptr");
    const int d = dim(), Dh = d / heads;
    qkv.forward(ps, x, saved.qkv, B * L);
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(row_shape(L - 1));
    TJEPA_OMP(omp parallel for schedule(static) if (B * heads > 1))
    for (int bh = 0; bh < B * heads; ++bh) {
      const int b = bh / heads, h = bh % heads;
      const T* q = saved.qkv + std::size_t(b) * L * 3 * d + std::size_t(h) * Dh;  // row 0 of the sample
      for (int l = 0; l < L; ++l)
        kernels::attention_forward(row_shape(l), q + std::size_t(l) * 3 * d, q + d, q + 2 * d, nullptr,
                                   saved.att + (std::size_t(b) * L + l) * d + std::size_t(h) * Dh,
                                   saved.lse + std::size_t(bh) * L + l, aws[detail::thread_id()]);
    }
    if (residual)
      proj.forward_residual(ps, saved.att, residual, y, B * L);
    else
      proj.forward(ps, saved.att, y, B * L);
  }

  // dx [B·L, d] += ∂L/∂x given dy [B·L, d]; the parameters' gradients +=. scratch.dqkv [B·L, 3d]
  // and scratch.datt [B·L, d].
  template <class T>
  void backward(ParamSet<T>& ps, const AttentionRows& r, const T* dy, const T* x, const AttentionSaved<T>& saved,
                const AttentionScratch<T>& scratch, T* dx, Workspace<T>& ws) const {
    const int B = r.B, L = r.L, d = dim(), Dh = d / heads;
    T* dqkv = scratch.dqkv;
    std::fill(scratch.datt, scratch.datt + std::size_t(B) * L * d, T(0));
    proj.backward(ps, dy, saved.att, scratch.datt, B * L);  // y = att · Wprojᵀ + b
    std::fill(dqkv, dqkv + std::size_t(B) * L * 3 * d, T(0));
    kernels::AttentionWorkspace<T>* aws = ws.attention_per_thread(row_shape(L - 1));
    TJEPA_OMP(omp parallel for schedule(static) if (B * heads > 1))
    for (int bh = 0; bh < B * heads; ++bh) {
      const int b = bh / heads, h = bh % heads;
      const std::size_t q0 = std::size_t(b) * L * 3 * d + std::size_t(h) * Dh;
      for (int l = 0; l < L; ++l) {
        const std::size_t o = (std::size_t(b) * L + l) * d + std::size_t(h) * Dh;
        kernels::attention_backward(row_shape(l), saved.qkv + q0 + std::size_t(l) * 3 * d, saved.qkv + q0 + d,
                                    saved.qkv + q0 + 2 * d, nullptr, saved.att + o, saved.lse + std::size_t(bh) * L + l,
                                    scratch.datt + o, dqkv + q0 + std::size_t(l) * 3 * d, dqkv + q0 + d,
                                    dqkv + q0 + 2 * d, aws[detail::thread_id()]);
      }
    }
    qkv.backward(ps, dqkv, x, dx, B * L);  // qkv = x · Wqkvᵀ + b
  }
};

}  // namespace tjepa
