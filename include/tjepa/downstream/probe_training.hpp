#pragma once
// Downstream probes (REFERENCE §6): an AttentiveProbe trained on token embeddings to regress the
// window's force (3 axes) and classify its indenter, evaluated on held-out windows.
//
// One probe, one head of 3 + C outputs:  y [B, 3 + C] = probe(x [B, L, d])
//   force    y[:, 0:3] regresses the standardized force (f − mean) / std (ForceScaler, fitted on
//            the training labels), loss = mean over B·3 of the squared error
//   indenter y[:, 3:]   are logits, loss = softmax cross-entropy
//   L = L_force + class_weight · L_indenter
//
// The embeddings come from a Features object (downstream/features.hpp; the loop is a template over it):
//   FrozenFeatures   precomputed embeddings [S, L, d] of a frozen encoder (embed_windows): only
//                    the probe trains
//   EncoderFeatures  a tokenizer + encoder run on the windows at every step and trained with the
//                    probe (end to end), same data, same steps, same optimizer
// A Features object serves sample ids s ∈ [0, S): rows of ProbeLabels.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/downstream/cross_entropy.hpp"
#include "tjepa/downstream/features.hpp"
#include "tjepa/downstream/probe_head.hpp"
#include "tjepa/downstream/metrics.hpp"
#include "tjepa/model/attentive_probe.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/model/tokenizer.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/loss.hpp"

namespace tjepa {

inline constexpr int force_axes = 3;

// The labels of S windows.
struct ProbeLabels {
  std::vector<std::int64_t> window;  // [S] window ids in their WindowSource
  std::vector<float> force;          // [S, 3] N (shear u, shear v, normal)
  std::vector<int> indenter;         // [S] class in [0, num_classes)

  int size() const { return static_cast<int>(indenter.size()); }

  // The labels of windows `ids` of a labelled source; every window must have a contact.
  static ProbeLabels from_source(const WindowSource& src, std::span<const std::int64_t> ids) {
    require<ConfigError>(src.has_labels(), "ProbeLabels::from_source: the windows have no labels");
    ProbeLabels l;
    for (std::int64_t id : ids) {
      const WindowLabel w = src.label(id);
      require<DataError>(w.indenter >= 0, "ProbeLabels::from_source: window ", id,
                         " has no contact, expected windows with an indenter class");
      l.window.push_back(id);
      l.force.insert(l.force.end(), w.force.begin(), w.force.end());
      l.indenter.push_back(w.indenter);
    }
    return l;
  }
};

// The same labels as targets of a general ProbeHead (downstream/probe_head.hpp), trained with
// early stopping by train_head: R = 3 force axes, C = num_classes indenter classes.
inline HeadTargets head_targets(const ProbeLabels& l, int num_classes) {
  HeadTargets t{force_axes, num_classes, l.force, l.indenter, {}};
  t.validate("head_targets");
  return t;
}

// Per-axis standardization of the force targets, from the training labels only.
struct ForceScaler {
  std::array<float, force_axes> mean{}, std{1.0f, 1.0f, 1.0f};

  static ForceScaler fit(const ProbeLabels& l) {
    require<DataError>(l.size() > 1, "ForceScaler::fit: ", l.size(), " labelled windows, expected at least 2");
    ForceScaler s;
    for (int a = 0; a < force_axes; ++a) {
      double m = 0, q = 0;
      for (int i = 0; i < l.size(); ++i) m += l.force[static_cast<std::size_t>(i) * force_axes + a];
      m /= l.size();
      for (int i = 0; i < l.size(); ++i) {
        const double e = l.force[static_cast<std::size_t>(i) * force_axes + a] - m;
        q += e * e;
      }
      s.mean[a] = static_cast<float>(m);
      s.std[a] = static_cast<float>(std::max(std::sqrt(q / l.size()), 1e-6));
    }
    return s;
  }
};

struct ProbeTrainConfig {
  int epochs = 10;
  int batch = 32;
  double lr = 1e-3;          // peak learning rate (warm-up from lr/10, cosine to lr/100)
  double warmup_fraction = 0.1;
  double weight_decay = 0.05;
  double class_weight = 1.0; // weight of the indenter cross-entropy against the force MSE
  double clip_grad_norm = 10.0;
  std::uint64_t seed = 0;    // probe init and data order

  void validate() const {
    require<ConfigError>(epochs > 0, "ProbeTrainConfig: epochs = ", epochs, ", expected > 0");
    require<ConfigError>(batch > 0, "ProbeTrainConfig: batch = ", batch, ", expected > 0");
    require<ConfigError>(lr > 0 && std::isfinite(lr), "ProbeTrainConfig: lr = ", lr, ", expected > 0");
    require<ConfigError>(warmup_fraction >= 0 && warmup_fraction <= 1, "ProbeTrainConfig: warmup_fraction = ",
                         warmup_fraction, ", expected in [0, 1]");
    require<ConfigError>(weight_decay >= 0, "ProbeTrainConfig: weight_decay = ", weight_decay, ", expected >= 0");
    require<ConfigError>(class_weight >= 0, "ProbeTrainConfig: class_weight = ", class_weight, ", expected >= 0");
  }
};

// A probe with its parameters and the force standardization it was trained with.
template <class T>
struct ForceIndenterProbe {
  ParamSet<T> params;
  AttentiveProbe probe;
  ForceScaler scaler;
  int num_classes = 4;

  ForceIndenterProbe(int dim, int heads, int num_classes_, std::uint64_t seed) : num_classes(num_classes_) {
    require<ConfigError>(num_classes_ > 1, "ForceIndenterProbe: num_classes = ", num_classes_, ", expected > 1");
    ProbeConfig c;
    c.dim = dim;
    c.heads = heads;
    c.head_hidden = dim;
    c.out_dim = outputs();
    probe = AttentiveProbe(params, c);
    params.allocate();
    init_params(params, seed);
  }
  int outputs() const { return force_axes + num_classes; }
};

namespace detail {
// Statistics fitted on `train` and applied to it and to `others`, in rows of `unit` values
// (unit_name says what a row is): returns train's row count.
template <class T>
std::size_t check_fit_and_apply(const char* who, std::span<T> train, std::span<const std::span<T>> others,
                                std::size_t unit, const std::string& unit_name) {
  require<ShapeError>(!train.empty() && train.size() % unit == 0, who, ": ", train.size(),
                      " training values, expected a positive multiple of ", unit_name);
  for (const auto& o : others)
    require<ShapeError>(o.size() % unit == 0, who, ": ", o.size(), " values, expected a multiple of ", unit_name);
  return train.size() / unit;
}
}  // namespace detail

// Each token's resting embedding, removed from frozen features before a probe: with μ_n the mean of
// token n's embedding over the training windows and μ̄ the mean of μ_n over tokens,
//   x[s, n, :] ← x[s, n, :] − μ_n + μ̄          for every window s of `train` and of each `other`
// (statistics from `train` only). What every window shows at a token (its position, the "no
// contact" embedding of an idle taxel) becomes one vector shared by all tokens, which the probe's
// softmax and its pooled value ignore; what the windows differ in is kept at its own scale. Without
// it, the attentive probe must learn from a few hundred labelled windows to look past per-token
// offsets: on the simulated Allegro hand a random encoder whose position rows have RMS 1 (graph
// positions) gave force RMSE 1.47 N against 0.97 N with the reference's RMS 0.02 rows, and a
// pre-trained encoder whose rows had grown stayed at the training mean.
template <class T>
void center_token_embeddings(std::span<T> train, std::span<const std::span<T>> others, int tokens, int dim) {
  require<ShapeError>(tokens > 0 && dim > 0, "center_token_embeddings: tokens = ", tokens, ", dim = ", dim,
                      ", expected > 0");
  const std::size_t per = static_cast<std::size_t>(tokens) * dim;
  const std::size_t S = detail::check_fit_and_apply("center_token_embeddings", train, others, per,
                                                    "tokens*dim = " + std::to_string(tokens) + "*" + std::to_string(dim));
  std::vector<double> mean(per, 0.0), shared(static_cast<std::size_t>(dim), 0.0);
  for (std::size_t s = 0; s < S; ++s)
    for (std::size_t i = 0; i < per; ++i) mean[i] += static_cast<double>(train[s * per + i]);
  for (std::size_t i = 0; i < per; ++i) {
    mean[i] /= static_cast<double>(S);
    shared[i % static_cast<std::size_t>(dim)] += mean[i] / tokens;
  }
  std::vector<T> shift(per);  // μ̄ − μ_n
  for (std::size_t i = 0; i < per; ++i) shift[i] = static_cast<T>(shared[i % static_cast<std::size_t>(dim)] - mean[i]);
  auto apply = [&](std::span<T> x) {
    for (std::size_t s = 0; s < x.size() / per; ++s)
      for (std::size_t i = 0; i < per; ++i) x[s * per + i] += shift[i];
  };
  for (const auto& o : others) apply(o);
  apply(train);
}

// Frozen features standardized per channel before a head (in the spirit of MAE's linear probe, a
// BatchNorm without affine parameters in front of the head, here applied to every token before the
// pooling, with fixed training statistics): with μ_c and σ_c the mean and standard deviation of
// channel c over every token of every training window,
//   x[s, n, c] ← (x[s, n, c] − μ_c) / sqrt(σ_c² + eps)     for every window of `train` and of each `other`
// (statistics from `train` only). An encoder whose tokens share one large vector (a random
// encoder's output LayerNorm, a pre-trained encoder's common offset) gives keys, values and
// LayerNorm inputs that differ across tokens and windows by a small fraction of their norm; the
// probe then spends its steps on that scale. Unlike center_token_embeddings, what differs between
// tokens (their positions) is kept. eps is absolute: a channel nearly constant in training is
// scaled by up to 1/sqrt(eps). Returns the statistics (μ_c, σ_c) [dim] each.
template <class T>
std::pair<std::vector<double>, std::vector<double>> standardize_channels(std::span<T> train,
                                                                         std::span<const std::span<T>> others, int dim,
                                                                         double eps = 1e-6) {
  require<ShapeError>(dim > 0, "standardize_channels: dim = ", dim, ", expected > 0");
  const auto D = static_cast<std::size_t>(dim);
  const std::size_t R = detail::check_fit_and_apply("standardize_channels", train, others, D, "dim = " + std::to_string(dim));
  std::vector<double> mean(D), sd(D), scale(D);
  detail::column_moments(train.data(), R, D, 0, D, mean.data(), sd.data());
  for (std::size_t c = 0; c < D; ++c) {
    scale[c] = 1.0 / std::sqrt(sd[c] + eps);
    sd[c] = std::sqrt(sd[c]);
    require<NumericError>(std::isfinite(mean[c]) && std::isfinite(sd[c]), "standardize_channels: channel ", c,
                          " has mean ", mean[c], " and sd ", sd[c], ", expected finite");
  }
  for (const auto& o : others) detail::scale_columns(o.data(), o.size() / D, D, 0, D, mean.data(), scale.data());
  detail::scale_columns(train.data(), train.size() / D, D, 0, D, mean.data(), scale.data());
  return {std::move(mean), std::move(sd)};
}

// What a training step reports to the progress callback.
struct ProbeStepInfo {
  std::int64_t step = 0, total_steps = 0;
  double loss = 0, force_loss = 0, indenter_loss = 0;
  double windows_per_second = 0;
};

// Held-out metrics of a probe.
struct ProbeMetrics {
  std::array<double, force_axes> force_rmse{};  // N, per axis (shear u, shear v, normal)
  double indenter_accuracy = 0;
  double majority_accuracy = 0;                 // chance level: the most frequent class
  int windows = 0;
};

namespace detail {
// y [B, 3 + C] → dy (overwritten) and the two losses. force_std [B, 3] are standardized targets.
template <class T>
std::array<double, 2> probe_loss(const T* y, const float* force_std, const int* labels, int B, int C,
                                 double class_weight, T* dy) {
  return head_loss(y, static_cast<std::size_t>(force_axes + C), force_std, labels, B, force_axes, C, class_weight, dy);
}
}  // namespace detail

// Trains probe (and the features' encoder, if it has one) on samples 0..S−1 of labels. Returns
// the mean loss of the last epoch.
template <class T, class Features>
double train_probe(ForceIndenterProbe<T>& probe, Features& features, const ProbeLabels& labels,
                   const ProbeTrainConfig& cfg, const std::function<void(const ProbeStepInfo&)>& progress = {}) {
  cfg.validate();
  const int S = labels.size(), C = probe.num_classes, out = probe.outputs();
  require<ShapeError>(features.size() == S, "train_probe: ", features.size(), " feature rows for ", S, " labels");
  require<ShapeError>(features.dim() == probe.probe.config.dim, "train_probe: features of width ", features.dim(),
                      ", the probe expects ", probe.probe.config.dim);
  const int B = std::min(cfg.batch, S);
  for (int c : labels.indenter)
    require<DataError>(c >= 0 && c < C, "train_probe: indenter label ", c, ", expected in [0, ", C, ")");
  probe.scaler = ForceScaler::fit(labels);
  std::vector<float> fstd(labels.force.size());
  for (std::size_t i = 0; i < fstd.size(); ++i)
    fstd[i] = (labels.force[i] - probe.scaler.mean[i % force_axes]) / probe.scaler.std[i % force_axes];

  std::vector<PrefixedParams<T>> parts{{"probe.", &probe.params}};
  if (ParamSet<T>* enc = features.trainable()) parts.push_back({"encoder.", enc});
  AdamW<T> opt(parts);
  const std::int64_t per_epoch = S / B, total = per_epoch * cfg.epochs;
  WarmupCosineLr lr{cfg.lr * 0.1, cfg.lr, cfg.lr * 0.01, static_cast<std::int64_t>(cfg.warmup_fraction * total), total};

  const int L = features.tokens(), d = features.dim();
  Workspace<T> ws;
  ProbeCache<T> cache;
  AlignedVector<T> y(static_cast<std::size_t>(B) * out), dy(y.size()), dx;
  std::vector<float> fb(static_cast<std::size_t>(B) * force_axes);
  std::vector<int> cb(static_cast<std::size_t>(B));
  std::vector<std::int64_t> order(static_cast<std::size_t>(S));
  double epoch_loss = 0;
  std::int64_t step = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (int e = 0; e < cfg.epochs; ++e) {
    for (int i = 0; i < S; ++i) order[static_cast<std::size_t>(i)] = i;
    Rng(cfg.seed, static_cast<std::uint64_t>(e)).shuffle(std::span<std::int64_t>(order));
    epoch_loss = 0;
    for (std::int64_t k = 0; k < per_epoch; ++k, ++step) {
      const std::span<const std::int64_t> ids(order.data() + k * B, static_cast<std::size_t>(B));
      for (int b = 0; b < B; ++b) {
        const auto s = static_cast<std::size_t>(ids[static_cast<std::size_t>(b)]);
        std::copy_n(fstd.data() + s * force_axes, force_axes, fb.data() + static_cast<std::size_t>(b) * force_axes);
        cb[static_cast<std::size_t>(b)] = labels.indenter[s];
      }
      for (auto& p : parts) p.params->zero_grad();
      const T* x = features.forward(ids, true);
      probe.probe.forward(probe.params, x, B, L, nullptr, y.data(), &cache, ws);
      const auto [fl, cl] = detail::probe_loss(y.data(), fb.data(), cb.data(), B, C, cfg.class_weight, dy.data());
      const double loss = fl + cfg.class_weight * cl;
      require<NumericError>(std::isfinite(loss), "train_probe: step ", step, ": the loss is ", loss);
      T* dxp = nullptr;
      if (features.trainable()) {
        dxp = detail::grow(dx, static_cast<std::size_t>(B) * L * d);
        std::fill(dxp, dxp + static_cast<std::size_t>(B) * L * d, T(0));
      }
      probe.probe.backward(probe.params, dy.data(), dxp, cache, ws);
      if (dxp) features.backward(dxp);
      clip_grad_norm<T>(parts, cfg.clip_grad_norm);
      opt.step(lr(step + 1), cfg.weight_decay);
      epoch_loss += loss / per_epoch;
      if (progress) {
        const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        progress({step, total, loss, fl, cl, sec > 0 ? static_cast<double>((step + 1) * B) / sec : 0.0});
      }
    }
  }
  return epoch_loss;
}

// Predictions y [S, 3 + C] for samples 0..S−1 (force de-standardized, in N), batch by batch.
template <class T, class Features>
std::vector<T> predict_probe(const ForceIndenterProbe<T>& probe, Features& features, int S, int batch = 64) {
  require<ConfigError>(batch > 0, "predict_probe: batch = ", batch, ", expected > 0");
  const int out = probe.outputs(), L = features.tokens();
  std::vector<T> y(static_cast<std::size_t>(S) * out);
  Workspace<T> ws;
  std::vector<std::int64_t> ids;
  for (int s0 = 0; s0 < S; s0 += batch) {
    const int B = std::min(batch, S - s0);
    ids.resize(static_cast<std::size_t>(B));
    for (int b = 0; b < B; ++b) ids[static_cast<std::size_t>(b)] = s0 + b;
    const T* x = features.forward(ids, false);
    probe.probe.forward(probe.params, x, B, L, nullptr, y.data() + static_cast<std::size_t>(s0) * out, nullptr, ws);
  }
  for (int s = 0; s < S; ++s)
    for (int a = 0; a < force_axes; ++a) {
      T& v = y[static_cast<std::size_t>(s) * out + a];
      v = static_cast<T>(v * probe.scaler.std[a] + probe.scaler.mean[a]);
    }
  return y;
}

// Held-out metrics of a trained probe on samples 0..S−1 of labels.
template <class T, class Features>
ProbeMetrics evaluate_probe(const ForceIndenterProbe<T>& probe, Features& features, const ProbeLabels& labels,
                            int batch = 64) {
  const int S = labels.size();
  require<ShapeError>(S > 0 && features.size() == S, "evaluate_probe: ", features.size(), " feature rows for ", S,
                      " labels, expected equal and > 0");
  const std::vector<T> y = predict_probe(probe, features, S, batch);
  const auto out = static_cast<std::size_t>(probe.outputs());
  ProbeMetrics m;
  const auto r = rmse_per_column(y.data(), out, labels.force.data(), S, force_axes);
  std::copy(r.begin(), r.end(), m.force_rmse.begin());
  m.indenter_accuracy = accuracy(y.data() + force_axes, out, labels.indenter.data(), S, probe.num_classes);
  m.majority_accuracy = majority_accuracy(labels.indenter.data(), S, probe.num_classes);
  m.windows = S;
  return m;
}

// The probe's objective on labelled samples 0..S−1: the force MSE standardized by the probe's own
// scaler plus class_weight × the indenter cross-entropy (what train_probe minimizes).
template <class T, class Features>
double probe_objective(const ForceIndenterProbe<T>& probe, Features& features, const ProbeLabels& labels,
                       double class_weight, int batch = 64) {
  const int S = labels.size();
  require<ShapeError>(S > 0 && features.size() == S, "probe_objective: ", features.size(), " feature rows for ", S,
                      " labels, expected equal and > 0");
  const std::vector<T> y = predict_probe(probe, features, S, batch);
  const auto out = static_cast<std::size_t>(probe.outputs());
  double f = 0;
  for (int s = 0; s < S; ++s)
    for (int a = 0; a < force_axes; ++a) {
      const double e = (static_cast<double>(y[s * out + a]) - labels.force[static_cast<std::size_t>(s) * force_axes + a]) /
                       probe.scaler.std[a];
      f += e * e;
    }
  const double ce = softmax_cross_entropy(y.data() + force_axes, out, labels.indenter.data(), S, probe.num_classes,
                                          static_cast<T*>(nullptr), out);
  return f / (static_cast<double>(S) * force_axes) + class_weight * ce;
}

// Samples `ids` of labels, in that order.
inline ProbeLabels subset(const ProbeLabels& l, std::span<const std::int64_t> ids) {
  ProbeLabels r;
  for (std::int64_t i : ids) {
    const auto k = static_cast<std::size_t>(i);
    r.window.push_back(l.window.at(k));
    r.force.insert(r.force.end(), l.force.begin() + static_cast<std::ptrdiff_t>(k * force_axes),
                   l.force.begin() + static_cast<std::ptrdiff_t>((k + 1) * force_axes));
    r.indenter.push_back(l.indenter[k]);
  }
  return r;
}

// The probe's learning rate, chosen by validation as probe evaluations sweep it (V-JEPA's do): a
// seeded split holds out val_fraction of the training samples; one probe per rate trains on the
// rest with cfg otherwise unchanged; the rate with the lowest held-out objective wins. A rate at
// which the probe fails to train (its head's GELU units all die, so it predicts the training mean)
// loses to one that trains. Frozen embeddings [S, L, d] only: an end-to-end sweep costs too much.
struct ProbeLrChoice {
  double lr = 0;
  std::vector<double> objective;  // [lrs] validation objective per rate
};

template <class T>
ProbeLrChoice select_probe_lr(std::span<const T> embeddings, int L, int d, const ProbeLabels& labels,
                              std::span<const double> lrs, const ProbeTrainConfig& cfg, int heads, int num_classes,
                              double val_fraction = 0.2) {
  const int S = labels.size();
  const std::size_t per = static_cast<std::size_t>(L) * d;
  require<ConfigError>(!lrs.empty(), "select_probe_lr: no learning rates to choose from");
  require<ConfigError>(val_fraction > 0 && val_fraction < 1, "select_probe_lr: val_fraction = ", val_fraction,
                       ", expected in (0, 1)");
  require<ShapeError>(embeddings.size() == static_cast<std::size_t>(S) * per, "select_probe_lr: ", embeddings.size(),
                      " values for ", S, " samples of ", L, "x", d);
  const ValidationSplit split = split_for_validation(S, val_fraction, cfg.seed);
  const std::span<const std::int64_t> fit_ids(split.fit), val_ids(split.validation);
  auto rows = [&](std::span<const std::int64_t> ids) {
    AlignedVector<T> x(ids.size() * per);
    for (std::size_t i = 0; i < ids.size(); ++i)
      std::copy_n(embeddings.data() + static_cast<std::size_t>(ids[i]) * per, per, x.data() + i * per);
    return x;
  };
  FrozenFeatures<T> fit(rows(fit_ids), L, d), val(rows(val_ids), L, d);
  const ProbeLabels fit_labels = subset(labels, fit_ids), val_labels = subset(labels, val_ids);
  ProbeLrChoice choice;
  double best = std::numeric_limits<double>::infinity();
  for (double lr : lrs) {
    ProbeTrainConfig c = cfg;
    c.lr = lr;
    ForceIndenterProbe<T> probe(d, heads, num_classes, cfg.seed);
    train_probe(probe, fit, fit_labels, c);
    const double v = probe_objective(probe, val, val_labels, cfg.class_weight);
    choice.objective.push_back(v);
    if (v < best) {
      best = v;
      choice.lr = lr;
    }
  }
  return choice;
}

}  // namespace tjepa
