#pragma once
// The sequence head (paper, Sec. IV-B, in-hand pose): each of L consecutive windows is pooled by
// the attentive probe's pooling, a 1-layer causal transformer runs over the L pooled vectors, and
// a linear layer predicts the pose after each window. Legend: B sequences, L windows per sequence
// (default 10), N tokens per window, d width, H heads, P outputs (pose x, y, θ: 3).
//
//   p   = pool(x)                    x [B·L, N, d] → [B·L, d]   (AttentiveProbe::pool, "pool.*")
//   h₀  = p + pos_embed[l]           pos_embed [1, L, d]: the window's place in the sequence
//   h₁  = h₀ + CausalAttn(norm1(h₀))                  blocks.0.norm1, blocks.0.attn.{qkv,proj}
//   h₂  = h₁ + Mlp(norm2(h₁))                         blocks.0.norm2, blocks.0.mlp.{fc1,fc2}
//   y   = head(norm(h₂))             y [B·L, P]       norm, head (a Linear)
// Position l sees windows 0..l: the prediction after window l never depends on later windows.
// With pooling.kind = taxel (model/taxel_pooling.hpp; not the paper's; why it exists:
// docs/evaluation.md, "Why the protocol is set this way") pool(x) is
// the per-taxel read-out that keeps where on the skin each feature sits.
#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/downstream/causal_attention.hpp"
#include "tjepa/downstream/early_stopping.hpp"
#include "tjepa/downstream/metrics.hpp"
#include "tjepa/downstream/probe_head.hpp"
#include "tjepa/model/attentive_probe.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/model/mlp.hpp"

namespace tjepa {

struct SequenceHeadConfig {
  int dim = 192;
  int heads = 3;        // of the pooling and of the causal block
  int length = 10;      // L windows per sequence
  int outputs = 3;      // P: pose x, y, θ
  double mlp_ratio = 4.0;
  double eps = kernels::layer_norm_eps;
  PoolingConfig pooling;  // attentive (the paper's) or taxel (model/taxel_pooling.hpp)
};

// Activations of one forward pass, kept for backward; also the scratch of inference.
template <class T>
struct SequenceCache {
  int B = 0;
  ProbeCache<T> pool;
  AlignedVector<T> h0, n1, mean1, rstd1;  // [B·L, d], [B·L, d], [B·L], [B·L]
  AlignedVector<T> qkv, att, lse;         // [B·L, 3d], [B·L, d], [B, H, L]
  AlignedVector<T> h1, n2, mean2, rstd2;  // [B·L, d], [B·L, d], [B·L], [B·L]
  AlignedVector<T> hpre, hact;            // [B·L, hidden]
  AlignedVector<T> h2, n3, mean3, rstd3;  // [B·L, d], [B·L, d], [B·L], [B·L]
  // Backward scratch.
  AlignedVector<T> dn, dh, dqkv, datt, dhid, dhid2;
};

struct SequenceHead {
  SequenceHeadConfig config;
  AttentiveProbe pool;
  ParamId pos;
  NormParams norm1, norm2, norm;
  CausalSelfAttention attn;
  Mlp mlp;
  LinearParams head;

  SequenceHead() = default;
  template <class T>
  SequenceHead(ParamSet<T>& ps, const SequenceHeadConfig& c) : config(c) {
    require<ConfigError>(c.length > 0 && c.outputs > 0 && c.dim > 0, "SequenceHead: length ", c.length, ", outputs ",
                         c.outputs, ", dim ", c.dim, ", expected > 0");
    ProbeConfig pc;
    pc.dim = c.dim;
    pc.heads = c.heads;
    pc.mlp_ratio = c.mlp_ratio;
    pc.out_dim = 0;  // pooling only
    pc.eps = c.eps;
    pc.pooling = c.pooling;
    pool = AttentiveProbe(ps, pc, "pool.");
    pos = ps.add("pos_embed", {1, c.length, c.dim}, ParamInit::trunc_normal);
    norm1 = NormParams::add(ps, "blocks.0.norm1", c.dim, c.eps);
    attn = CausalSelfAttention::add(ps, "blocks.0.attn", c.dim, c.heads, true);
    norm2 = NormParams::add(ps, "blocks.0.norm2", c.dim, c.eps);
    mlp = Mlp::add(ps, "blocks.0.mlp", c.dim, static_cast<int>(c.dim * c.mlp_ratio), true);
    norm = NormParams::add(ps, "norm", c.dim, c.eps);
    head = LinearParams::add(ps, "head", c.dim, c.outputs, true);
  }

  // x [B, L, N, d] (the token embeddings of each sequence's L windows) → y [B, L, P]. The cache
  // is filled (training) and is the scratch of inference alike.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int B, int N, T* y, SequenceCache<T>& c, Workspace<T>& ws) const {
    check_params(ps, head.weight, "SequenceHead::forward");
    require<ShapeError>(B > 0 && N > 0, "SequenceHead::forward: B = ", B, ", N = ", N, ", expected > 0");
    const int L = config.length, d = config.dim, hid = mlp.hidden();
    const std::size_t M = std::size_t(B) * L, Md = M * d;
    c.B = B;
    T* h0 = detail::grow(c.h0, Md);
    pool.pool(ps, {x, int(M), N}, h0, c.pool, ws);
    const T* pe = ps.value(pos);
    for (std::size_t r = 0; r < M; ++r)
      for (int i = 0; i < d; ++i) h0[r * d + i] += pe[(r % L) * d + i];
    T* n1 = detail::grow(c.n1, Md);
    norm1.forward(ps, h0, n1, detail::grow(c.mean1, M), detail::grow(c.rstd1, M), int(M));
    T* h1 = detail::grow(c.h1, Md);
    std::copy(h0, h0 + Md, h1);
    attn.forward(ps, AttentionRows{B, L}, n1,
                 AttentionSaved<T>{.qkv = detail::grow(c.qkv, M * 3 * d), .att = detail::grow(c.att, Md),
                                   .lse = detail::grow(c.lse, std::size_t(B) * attn.heads * L)},
                 h1, ws, h1);
    T* n2 = detail::grow(c.n2, Md);
    norm2.forward(ps, h1, n2, detail::grow(c.mean2, M), detail::grow(c.rstd2, M), int(M));
    T* h2 = detail::grow(c.h2, Md);
    std::copy(h1, h1 + Md, h2);
    mlp.forward(ps, n2, detail::grow(c.hpre, M * hid), detail::grow(c.hact, M * hid), h2, int(M), h2);
    T* n3 = detail::grow(c.n3, Md);
    norm.forward(ps, h2, n3, detail::grow(c.mean3, M), detail::grow(c.rstd3, M), int(M));
    head.forward(ps, n3, y, int(M));
  }

  // dy [B, L, P] → parameter gradients and dx [B, L, N, d] += (may be nullptr), for the last
  // forward of c.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, std::type_identity_t<T>* dx, SequenceCache<T>& c, Workspace<T>& ws) const {
    check_params(ps, head.weight, "SequenceHead::backward");
    require<ConfigError>(c.B > 0, "SequenceHead::backward: the cache holds no forward pass");
    const int B = c.B, L = config.length, d = config.dim, hid = mlp.hidden();
    const std::size_t M = std::size_t(B) * L, Md = M * d;
    T* dn = detail::grow(c.dn, Md);  // gradient at a LayerNorm's output
    T* dh = detail::grow(c.dh, Md);  // gradient down the residual stream
    // y = head(n3), n3 = norm(h₂)
    std::fill(dn, dn + Md, T(0));
    head.backward(ps, dy, c.n3.data(), dn, int(M));
    std::fill(dh, dh + Md, T(0));
    norm.backward(ps, dn, c.h2.data(), c.mean3.data(), c.rstd3.data(), dh, int(M));
    // h₂ = h₁ + mlp(n2), n2 = norm2(h₁): dh already holds the identity path
    std::fill(dn, dn + Md, T(0));
    mlp.backward(ps, dh, c.n2.data(), c.hpre.data(), detail::grow(c.dhid, M * hid), detail::grow(c.dhid2, M * hid), dn,
                 int(M));
    norm2.backward(ps, dn, c.h1.data(), c.mean2.data(), c.rstd2.data(), dh, int(M));
    // h₁ = h₀ + attn(n1), n1 = norm1(h₀)
    std::fill(dn, dn + Md, T(0));
    attn.backward(ps, AttentionRows{B, L}, dh, c.n1.data(),
                  AttentionSaved<T>{.qkv = c.qkv.data(), .att = c.att.data(), .lse = c.lse.data()},
                  AttentionScratch<T>{.dqkv = detail::grow(c.dqkv, M * 3 * d), .datt = detail::grow(c.datt, Md)}, dn,
                  ws);
    norm1.backward(ps, dn, c.h0.data(), c.mean1.data(), c.rstd1.data(), dh, int(M));
    // h₀ = p + pos_embed[l]
    T* dpe = ps.grad(pos);
    for (std::size_t r = 0; r < M; ++r)
      for (int i = 0; i < d; ++i) dpe[(r % L) * d + i] += dh[r * d + i];
    pool.pool_backward(ps, dh, dx, c.pool, ws);
  }
};

// Q sequences of L windows with a target after each window.
struct SequenceTargets {
  int length = 10;                  // L
  int outputs = 3;                  // P
  std::vector<std::int64_t> window; // [Q, L] sample ids in the Features the head reads
  std::vector<float> value;         // [Q, L, P] e.g. pose (x, y, θ) after each window
  SampleGroups groups;              // optional: [Q] the sequences' groups, for validation by groups

  int size() const { return length > 0 ? static_cast<int>(window.size() / static_cast<std::size_t>(length)) : 0; }
  void validate(const char* who, int samples) const {
    require<ConfigError>(length > 0 && outputs > 0, who, ": length ", length, ", outputs ", outputs, ", expected > 0");
    const auto Q = static_cast<std::size_t>(size());
    require<ShapeError>(Q > 0 && window.size() == Q * length && value.size() == Q * length * outputs, who, ": ",
                        window.size(), " window ids and ", value.size(), " values, expected [Q, ", length, "] and [Q, ",
                        length, ", ", outputs, "] with Q > 0");
    for (std::int64_t w : window)
      require<DataError>(w >= 0 && w < samples, who, ": window id ", w, ", expected in [0, ", samples, ")");
    for (float v : value) require<DataError>(std::isfinite(v), who, ": target ", v, ", expected finite");
    groups.validate(who, static_cast<int>(Q));
  }
};

// A sequence head with its parameters and the standardization of its targets (per output,
// fitted on the fitting sequences).
template <class T>
struct SequenceModel {
  ParamSet<T> params;
  SequenceHead head;
  ColumnScaler scaler;

  SequenceModel(const SequenceHeadConfig& c, std::uint64_t seed) {
    head = SequenceHead(params, c);
    params.allocate();
    init_params(params, seed);
    scaler.mean.assign(static_cast<std::size_t>(c.outputs), 0.0);
    scaler.std.assign(static_cast<std::size_t>(c.outputs), 1.0);
  }
};

namespace detail {
// Window ids [B·L] of sequences seq.
inline void sequence_windows(const SequenceTargets& t, std::span<const std::int64_t> seq, std::vector<std::int64_t>& w) {
  w.clear();
  for (std::int64_t q : seq)
    w.insert(w.end(), t.window.begin() + q * t.length, t.window.begin() + (q + 1) * t.length);
}
}  // namespace detail

// Raw outputs [seq, L, P] (standardized) at inference, batch by batch.
template <class T, class Features>
std::vector<T> sequence_outputs(const SequenceModel<T>& model, Features& features, const SequenceTargets& targets,
                                std::span<const std::int64_t> seq, int batch = 16) {
  require<ConfigError>(batch > 0, "sequence_outputs: batch = ", batch, ", expected > 0");
  const int L = targets.length, P = targets.outputs;
  std::vector<T> y(seq.size() * static_cast<std::size_t>(L) * P);
  SequenceCache<T> cache;
  Workspace<T> ws;
  std::vector<std::int64_t> w;
  for (std::size_t s0 = 0; s0 < seq.size(); s0 += static_cast<std::size_t>(batch)) {
    const std::size_t B = std::min<std::size_t>(static_cast<std::size_t>(batch), seq.size() - s0);
    detail::sequence_windows(targets, seq.subspan(s0, B), w);
    const T* x = features.forward(w, false);
    model.head.forward(model.params, x, int(B), features.tokens(), y.data() + s0 * L * P, cache, ws);
  }
  return y;
}

// Mean squared error on standardized targets over sequences seq, every position and output.
template <class T, class Features>
double sequence_objective(const SequenceModel<T>& model, Features& features, const SequenceTargets& targets,
                          std::span<const std::int64_t> seq) {
  const std::vector<T> y = sequence_outputs(model, features, targets, seq);
  const int L = targets.length, P = targets.outputs;
  double f = 0;
  for (std::size_t b = 0; b < seq.size(); ++b)
    for (int i = 0; i < L * P; ++i) {
      const double z = model.scaler.standardize(targets.value[static_cast<std::size_t>(seq[b]) * L * P + i], i % P);
      const double e = static_cast<double>(y[b * L * P + static_cast<std::size_t>(i)]) - z;
      f += e * e;
    }
  return f / (static_cast<double>(seq.size()) * L * P);
}

// Trains the sequence head (and the features' encoder, if trainable) on the sequences of targets
// with early stopping (split over sequences). The loss: the MSE on standardized targets over
// every position of every sequence.
template <class T, class Features>
HeadTrainResult train_sequence_head(SequenceModel<T>& model, Features& features, const SequenceTargets& targets,
                                    const HeadTrainConfig& cfg) {
  cfg.validate();
  targets.validate("train_sequence_head", features.size());
  const SequenceHeadConfig& hc = model.head.config;
  require<ShapeError>(targets.length == hc.length && targets.outputs == hc.outputs && features.dim() == hc.dim,
                      "train_sequence_head: sequences of ", targets.length, " windows x ", targets.outputs,
                      " outputs on features of width ", features.dim(), ", the head takes ", hc.length, " x ",
                      hc.outputs, " and width ", hc.dim);
  const int Q = targets.size(), L = targets.length, P = targets.outputs, N = features.tokens(), d = hc.dim;
  const ValidationSplit split = validation_split(Q, cfg, targets.groups);
  std::vector<std::int64_t> fit_rows;  // (sequence, position) rows of the fitting sequences
  for (std::int64_t q : split.fit)
    for (int l = 0; l < L; ++l) fit_rows.push_back(q * L + l);
  model.scaler = ColumnScaler::fit(targets.value, P, fit_rows);

  std::vector<PrefixedParams<T>> parts{{"sequence_head.", &model.params}};
  if (ParamSet<T>* enc = features.trainable()) parts.push_back({"encoder.", enc});
  SequenceCache<T> cache;
  Workspace<T> ws;
  AlignedVector<T> y, dy, dx;
  std::vector<std::int64_t> w;
  int B = 0;
  auto forward = [&](std::span<const std::int64_t> seq) {
    B = static_cast<int>(seq.size());
    const std::size_t n = static_cast<std::size_t>(B) * L * P;
    detail::sequence_windows(targets, seq, w);
    T* yp = detail::grow(y, n);
    T* dyp = detail::grow(dy, n);
    const T* x = features.forward(w, true);
    model.head.forward(model.params, x, B, N, yp, cache, ws);
    double f = 0;
    for (int b = 0; b < B; ++b)
      for (int i = 0; i < L * P; ++i) {
        const std::size_t k = static_cast<std::size_t>(b) * L * P + static_cast<std::size_t>(i);
        const double z =
            model.scaler.standardize(targets.value[static_cast<std::size_t>(seq[static_cast<std::size_t>(b)]) * L * P + i], i % P);
        const double e = static_cast<double>(yp[k]) - z;
        f += e * e;
        dyp[k] = static_cast<T>(2.0 * e / static_cast<double>(n));
      }
    return f / static_cast<double>(n);
  };
  auto backward = [&] {
    T* dxp = nullptr;
    if (features.trainable()) {
      dxp = detail::grow(dx, static_cast<std::size_t>(B) * L * N * d);
      std::fill(dxp, dxp + static_cast<std::size_t>(B) * L * N * d, T(0));
    }
    model.head.backward(model.params, dy.data(), dxp, cache, ws);
    if (dxp) features.backward(dxp);
  };
  auto validate = [&] { return sequence_objective(model, features, targets, split.validation); };
  Trainer<HeadObjective<T>> trainer(std::move(parts), split.fit, cfg, forward, backward, validate,
                                    nlohmann::json{{"kind", "sequence"}, {"length", L}, {"outputs", P}});
  trainer.run();
  return trainer.record();
}

// Predictions [Q, L, P] in the targets' units for every sequence of targets.
template <class T, class Features>
std::vector<T> predict_sequence_head(const SequenceModel<T>& model, Features& features, const SequenceTargets& targets) {
  targets.validate("predict_sequence_head", features.size());
  std::vector<std::int64_t> seq(static_cast<std::size_t>(targets.size()));
  for (std::size_t q = 0; q < seq.size(); ++q) seq[q] = static_cast<std::int64_t>(q);
  std::vector<T> y = sequence_outputs(model, features, targets, seq);
  for (std::size_t i = 0; i < y.size(); ++i)
    y[i] = static_cast<T>(model.scaler.restore(y[i], static_cast<int>(i % static_cast<std::size_t>(targets.outputs))));
  return y;
}

// RMSE per output [P] over every position of every sequence, in the targets' units.
template <class T, class Features>
std::vector<double> evaluate_sequence_head(const SequenceModel<T>& model, Features& features,
                                           const SequenceTargets& targets) {
  const std::vector<T> y = predict_sequence_head(model, features, targets);
  return rmse_per_column(y.data(), static_cast<std::size_t>(targets.outputs), targets.value.data(),
                         targets.size() * targets.length, targets.outputs);
}

}  // namespace tjepa
