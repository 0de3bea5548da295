#pragma once
// AttentiveProbe (paper, Sec. IV-B; V-JEPA's AttentivePooler with one CrossAttentionBlock, then a
// 2-layer MLP head). For frozen token embeddings x [B, L, d]:
//   q₀ = query_tokens                                  [1, 1, d], one learned query
//   q₁ = q₀ + CrossAttn(q₀, norm1(x))                  3 heads, keys = the sample's L tokens
//   q₂ = q₁ + Mlp(norm2(q₁))                           [B, d]
//   y  = head.fc2(gelu(head.fc1(q₂)))                  [B, out]
// pool() stops at q₂ (the sequence head pools each window so); out_dim 0 builds no head.
// pooling.kind = taxel replaces q₀ … q₂ by the taxel pooling (model/taxel_pooling.hpp, parameters
// "<prefix>norm.*", "proj.*", "fc.*"; not in the paper); the head is the same.
// PyTorch names (prefix "probe." by default): query_tokens; cross_attention_block.norm1.*,
// cross_attention_block.xattn.{q,kv,proj}.*, cross_attention_block.norm2.*,
// cross_attention_block.mlp.{fc1,fc2}.*; head.fc1.*, head.fc2.*.
#include <algorithm>
#include <span>
#include <string>
#include <type_traits>

#include "tjepa/model/attention.hpp"
#include "tjepa/model/mlp.hpp"
#include "tjepa/model/taxel_pooling.hpp"

namespace tjepa {

struct ProbeConfig {
  int dim = 192;
  int heads = 3;
  double mlp_ratio = 4.0;
  int head_hidden = 192;
  int out_dim = 1;
  double eps = kernels::layer_norm_eps;
  PoolingConfig pooling;
};

template <class T>
struct ProbeCache {
  int B = 0, L = 0;
  AlignedVector<T> x, xn, mean1, rstd1;       // [B·L, d], [B·L]
  AlignedVector<T> q, u, p, pooled, att;      // CrossAttentionSaved: [d], [H, d], [B, H, L], [B, H, d], [B, d]
  AlignedVector<T> q1, qn, mean2, rstd2, h;   // [B, d], [B, d], [B], [B], [B, hidden]
  AlignedVector<T> q2, z;                     // [B, d], [B, head_hidden]
  std::vector<std::uint8_t> key_valid;
  TaxelPoolCache<T> taxel;                    // pooling.kind = taxel
};

// What the probe reads: x [batch, length, d] and which rows are real tokens (key_valid [batch,
// length], nonzero = real; empty: all).
template <class T>
struct ProbeInput {
  const T* x = nullptr;
  int batch = 0, length = 0;
  std::span<const std::uint8_t> key_valid = {};
};

struct AttentiveProbe {
  ProbeConfig config;
  ParamId query;
  NormParams norm1, norm2;
  CrossAttention xattn;
  Mlp mlp, head;
  TaxelPooling taxel;  // pooling.kind = taxel: instead of query … mlp

  AttentiveProbe() = default;
  template <class T>
  AttentiveProbe(ParamSet<T>& ps, const ProbeConfig& c, const std::string& prefix = "probe.") : config(c) {
    require<ConfigError>(c.out_dim >= 0 && (c.out_dim == 0 || c.head_hidden > 0), "AttentiveProbe: out_dim ",
                         c.out_dim, ", head_hidden ", c.head_hidden, ", expected out_dim >= 0 (0: no head) and head_hidden > 0");
    if (taxel_pooling()) {
      taxel = TaxelPooling::add(ps, prefix, c.dim, c.pooling, c.eps);
    } else {
      const std::string blk = prefix + "cross_attention_block.";
      query = ps.add(prefix + "query_tokens", {1, 1, c.dim}, ParamInit::trunc_normal);
      norm1 = NormParams::add(ps, blk + "norm1", c.dim, c.eps);
      xattn = CrossAttention::add(ps, blk + "xattn", c.dim, c.heads, true);
      norm2 = NormParams::add(ps, blk + "norm2", c.dim, c.eps);
      mlp = Mlp::add(ps, blk + "mlp", c.dim, static_cast<int>(c.dim * c.mlp_ratio), true);
    }
    if (c.out_dim > 0) head = Mlp::add(ps, prefix + "head", c.dim, c.head_hidden, true, c.out_dim);
  }

  bool has_head() const { return config.out_dim > 0; }
  bool taxel_pooling() const { return config.pooling.kind == PoolingKind::taxel; }
  // The pooling's last parameter (checked to belong to the ParamSet a call gets).
  ParamId pool_last() const { return taxel_pooling() ? taxel.fc.weight : mlp.fc2.weight; }

  // The pooling alone (the sequence head pools each window this way): in.x [B, L, d] → q₂ [B, d];
  // inference.
  template <class T>
  void pool(const ParamSet<T>& ps, const ProbeInput<std::type_identity_t<T>>& in, T* q2, Workspace<T>& ws) const {
    pool_rows(ps, in.x, in.batch, in.length, key_valid_of(in, "AttentiveProbe::pool"), q2, nullptr, ws);
  }
  // The same, keeping in `cache` what pool_backward needs.
  template <class T>
  void pool(const ParamSet<T>& ps, const ProbeInput<std::type_identity_t<T>>& in, T* q2,
            std::type_identity_t<ProbeCache<T>>& cache, Workspace<T>& ws) const {
    pool_rows(ps, in.x, in.batch, in.length, key_valid_of(in, "AttentiveProbe::pool"), q2, &cache, ws);
  }

 private:
  // in.key_valid as a pointer (nullptr: every token valid), checked to hold B·L entries.
  template <class T>
  static const std::uint8_t* key_valid_of(const ProbeInput<T>& in, const char* who) {
    require<ShapeError>(in.key_valid.empty() || in.key_valid.size() == std::size_t(in.batch) * std::size_t(in.length),
                        who, ": ", in.key_valid.size(), " key_valid entries, expected none or B·L = ",
                        std::size_t(in.batch) * std::size_t(in.length));
    return in.key_valid.empty() ? nullptr : in.key_valid.data();
  }

  // x [B, L, d] → q₂ [B, d]; key_valid [B, L] or nullptr; cache == nullptr: inference.
  template <class T>
  void pool_rows(const ParamSet<T>& ps, const T* x, int B, int L, const std::uint8_t* key_valid, T* q2,
                 std::type_identity_t<ProbeCache<T>>* cache, Workspace<T>& ws) const {
    check_params(ps, pool_last(), "AttentiveProbe::pool");
    require<ShapeError>(B > 0 && L > 0, "AttentiveProbe::pool: B = ", B, ", L = ", L, ", expected > 0");
    if (taxel_pooling()) {
      require<ShapeError>(key_valid == nullptr, "AttentiveProbe::pool: the taxel pooling takes no padded tokens");
      if (cache) {
        cache->B = B;
        cache->L = L;
      }
      if (cache)
        taxel.forward(ps, x, B, L, q2, cache->taxel, ws);
      else
        taxel.forward(ps, x, B, L, q2, ws);
      return;
    }
    const int d = config.dim, H = config.heads, hid = mlp.hidden();
    const std::size_t M = std::size_t(B) * L, Bd = std::size_t(B) * d;
    auto buf = [&](AlignedVector<T> ProbeCache<T>::*field, AlignedVector<T>& scratch, std::size_t n) {
      return detail::grow(cache ? cache->*field : scratch, n);
    };
    if (cache) {
      cache->B = B;
      cache->L = L;
      cache->x.assign(x, x + M * d);
      if (key_valid)
        cache->key_valid.assign(key_valid, key_valid + M);
      else
        cache->key_valid.clear();
    }
    // Padded tokens are never read: norm1 sees their rows as zeros, so whatever they hold (NaN
    // too) reaches neither the output nor a gradient (the backward reads cache->x, zeroed alike).
    const T* xin = x;
    if (key_valid && std::find(key_valid, key_valid + M, std::uint8_t(0)) != key_valid + M) {
      T* xz = cache ? cache->x.data() : detail::grow(ws.dbranch, M * d);
      if (!cache) std::copy(x, x + M * d, xz);
      for (std::size_t r = 0; r < M; ++r)
        if (!key_valid[r]) std::fill(xz + r * d, xz + (r + 1) * d, T(0));
      xin = xz;
    }
    T* xn = buf(&ProbeCache<T>::xn, ws.ln, M * d);
    norm1.forward(ps, xin, xn, cache ? detail::grow(cache->mean1, M) : nullptr,
                  cache ? detail::grow(cache->rstd1, M) : nullptr, int(M));
    const T* q0 = ps.value(query);
    T* q1 = buf(&ProbeCache<T>::q1, ws.x, Bd);
    for (int b = 0; b < B; ++b) std::copy(q0, q0 + d, q1 + std::size_t(b) * d);
    const CrossAttentionSaved<T> saved{.q = buf(&ProbeCache<T>::q, ws.rows, std::size_t(d)),
                                       .u = buf(&ProbeCache<T>::u, ws.rows2, std::size_t(H) * d),
                                       .p = buf(&ProbeCache<T>::p, ws.qkv, M * H),
                                       .pooled = buf(&ProbeCache<T>::pooled, ws.branch, Bd * H),
                                       .att = buf(&ProbeCache<T>::att, ws.att, Bd)};
    xattn.forward(ps, AttentionRows{B, L, key_valid}, q0, xn, saved, q1, q1);
    T* qn = buf(&ProbeCache<T>::qn, ws.rows2, Bd);  // ws.rows2 held saved.u, not read again
    norm2.forward(ps, q1, qn, cache ? detail::grow(cache->mean2, std::size_t(B)) : nullptr,
                  cache ? detail::grow(cache->rstd2, std::size_t(B)) : nullptr, B);
    std::copy(q1, q1 + Bd, q2);
    T* h = buf(&ProbeCache<T>::h, ws.hidden, std::size_t(B) * hid);
    mlp.forward(ps, qn, h, detail::grow(ws.hidden2, std::size_t(B) * hid), q2, B, q2);
  }

 public:
  // in.x [B, L, d] → y [B, out]: inference.
  template <class T>
  void forward(const ParamSet<T>& ps, const ProbeInput<std::type_identity_t<T>>& in, T* y, Workspace<T>& ws) const {
    run(ps, in, y, nullptr, ws);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const ProbeInput<std::type_identity_t<T>>& in, T* y,
               std::type_identity_t<ProbeCache<T>>& cache, Workspace<T>& ws) const {
    run(ps, in, y, &cache, ws);
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const ProbeInput<T>& in, T* y, std::type_identity_t<ProbeCache<T>>* cache,
           Workspace<T>& ws) const {
    const T* x = in.x;
    const int B = in.batch, L = in.length;
    const std::uint8_t* key_valid = key_valid_of(in, "AttentiveProbe::forward");
    require<ConfigError>(has_head(), "AttentiveProbe::forward: the probe was built without a head (out_dim 0)");
    check_params(ps, head.fc2.weight, "AttentiveProbe::forward");
    require<ShapeError>(B > 0 && L > 0, "AttentiveProbe::forward: B = ", B, ", L = ", L, ", expected > 0");
    const int d = config.dim, hh = head.hidden();
    T* q2 = detail::grow(cache ? cache->q2 : ws.dx, std::size_t(B) * d);
    pool_rows(ps, x, B, L, key_valid, q2, cache, ws);
    T* z = detail::grow(cache ? cache->z : ws.dhidden, std::size_t(B) * hh);
    T* zact = detail::grow(ws.hidden2, std::size_t(B) * hh);
    head.forward(ps, q2, z, zact, y, B);
  }

 public:
  // dy [B, out] → parameter gradients and dx [B, L, d] += (may be nullptr).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, std::type_identity_t<T>* dx, const ProbeCache<T>& c, Workspace<T>& ws) const {
    require<ConfigError>(has_head(), "AttentiveProbe::backward: the probe was built without a head (out_dim 0)");
    check_params(ps, head.fc2.weight, "AttentiveProbe::backward");
    require<ConfigError>(c.B > 0, "AttentiveProbe::backward: the cache holds no forward pass");
    const int d = config.dim, B = c.B, hh = head.hidden();
    T* dq = detail::grow(ws.dx, std::size_t(B) * d);  // running ∂L/∂q
    std::fill(dq, dq + std::size_t(B) * d, T(0));
    T* s1 = detail::grow(ws.hidden2, std::size_t(B) * hh);
    T* s2 = detail::grow(ws.dhidden, std::size_t(B) * hh);
    // y = head(q₂)
    head.backward(ps, dy, c.q2.data(), c.z.data(), s1, s2, dq, B);
    pool_backward(ps, dq, dx, c, ws);
  }

  // dq [B, d] holds ∂L/∂q₂ of the last pool (it is used as scratch and left changed) → parameter
  // gradients and dx [B, L, d] += (may be nullptr).
  template <class T>
  void pool_backward(ParamSet<T>& ps, std::type_identity_t<T>* dq, std::type_identity_t<T>* dx, const ProbeCache<T>& c,
                     Workspace<T>& ws) const {
    check_params(ps, pool_last(), "AttentiveProbe::pool_backward");
    require<ConfigError>(c.B > 0, "AttentiveProbe::pool_backward: the cache holds no forward pass");
    if (taxel_pooling()) {
      taxel.backward(ps, dq, dx, c.B, c.taxel, ws);
      return;
    }
    const int d = config.dim, H = config.heads, B = c.B, L = c.L, hid = mlp.hidden();
    const std::size_t M = std::size_t(B) * L, Bd = std::size_t(B) * d;
    T* s1 = detail::grow(ws.hidden2, std::size_t(B) * hid);
    T* s2 = detail::grow(ws.dhidden, std::size_t(B) * hid);
    // q₂ = q₁ + mlp(qn), qn = norm2(q₁): dq already holds the identity path
    T* dqn = detail::grow(ws.dln, Bd);
    std::fill(dqn, dqn + Bd, T(0));
    mlp.backward(ps, dq, c.qn.data(), c.h.data(), s1, s2, dqn, B);
    norm2.backward(ps, dqn, c.q1.data(), c.mean2.data(), c.rstd2.data(), dq, B);
    // q₁ = q₀ + xattn(q₀, xn), xn = norm1(x); q₀ is one row shared by every sample
    T* dxn = detail::grow(ws.dbranch, M * d);
    std::fill(dxn, dxn + M * d, T(0));
    T* du = ps.grad(query);
    for (int b = 0; b < B; ++b)
      for (int i = 0; i < d; ++i) du[i] += dq[std::size_t(b) * d + i];
    const CrossAttentionSaved<T> saved{.q = const_cast<T*>(c.q.data()), .u = const_cast<T*>(c.u.data()),
                                       .p = const_cast<T*>(c.p.data()), .pooled = const_cast<T*>(c.pooled.data()),
                                       .att = const_cast<T*>(c.att.data())};
    const CrossAttentionScratch<T> scratch{.dq = detail::grow(ws.rows, std::size_t(d)),
                                           .datt = detail::grow(ws.att, Bd),
                                           .dpooled = detail::grow(ws.drows, Bd * H),
                                           .du = detail::grow(ws.dkept, Bd * H),
                                           .dp = detail::grow(ws.dqkv, M * H),
                                           .ds = detail::grow(ws.qkv, M * H)};
    xattn.backward(ps, AttentionRows{B, L, c.key_valid.empty() ? nullptr : c.key_valid.data()}, dq,
                   ps.value(query), c.xn.data(), saved, scratch, du, dxn);
    norm1.backward(ps, dxn, c.x.data(), c.mean1.data(), c.rstd1.data(), dx, int(M));
  }
};

}  // namespace tjepa
