#pragma once
// General attentive-probe heads of the evaluation protocol (paper, Sec. IV-B, window-level
// head): one AttentiveProbe on a window's token embeddings with R regression outputs and/or C
// class logits, trained with early stopping (downstream/early_stopping.hpp) on frozen embeddings
// (FrozenFeatures) or end to end with the encoder (EncoderFeatures).
//
//   y [B, R + C] = probe(x [B, L, d])
//   y[:, 0:R]  regress standardized targets (v − mean) / std (ColumnScaler, fitted on the
//              fitting samples only), loss = mean over B·R of the squared error
//   y[:, R:]   logits, loss = softmax cross-entropy (downstream/cross_entropy.hpp)
//   loss = L_regression + class_weight · L_class         (the validation loss is the same)
// Tasks of the protocol: force (R = 3, C = 0), object class (R = 0, C = objects), both at once
// (head_targets of ProbeLabels, downstream/probe_labels.hpp: R = 3 force axes, C = the indenter
// classes).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/downstream/cross_entropy.hpp"
#include "tjepa/downstream/early_stopping.hpp"
#include "tjepa/downstream/features.hpp"
#include "tjepa/downstream/metrics.hpp"
#include "tjepa/model/attentive_probe.hpp"
#include "tjepa/model/init.hpp"

namespace tjepa {

// What a head predicts for S samples.
struct HeadTargets {
  int regression = 0;         // R outputs per sample
  int classes = 0;            // C classes (0: no classification; else >= 2)
  std::vector<float> value;   // [S, R]
  std::vector<int> label;     // [S] in [0, C) (empty when C = 0)
  SampleGroups groups;        // optional: the samples' groups, for validation by groups

  int size() const {
    return regression > 0 ? static_cast<int>(value.size() / static_cast<std::size_t>(regression))
                          : static_cast<int>(label.size());
  }
  void validate(const char* who) const {
    require<ConfigError>(regression >= 0 && (classes == 0 || classes > 1) && regression + classes > 0, who,
                         ": regression = ", regression, ", classes = ", classes,
                         ", expected R >= 0, C = 0 or C >= 2, and R + C > 0");
    const int S = size();
    require<ShapeError>(regression == 0 || value.size() == static_cast<std::size_t>(S) * regression, who, ": ",
                        value.size(), " regression values, expected a multiple of R = ", regression);
    require<ShapeError>(classes == 0 ? label.empty() : label.size() == static_cast<std::size_t>(S), who, ": ",
                        label.size(), " labels for ", S, " samples, expected ", classes == 0 ? 0 : S);
    for (int c : label) require<DataError>(c >= 0 && c < classes, who, ": label ", c, ", expected in [0, ", classes, ")");
    for (float v : value) require<DataError>(std::isfinite(v), who, ": regression value ", v, ", expected finite");
    groups.validate(who, S);
  }
};

// Per-column standardization of regression targets, from the given rows only.
struct ColumnScaler {
  std::vector<double> mean, std;  // [cols]

  // values [*, cols]; rows: the sample ids to fit on (at least 2).
  static ColumnScaler fit(std::span<const float> values, int cols, std::span<const std::int64_t> rows) {
    require<DataError>(rows.size() > 1, "ColumnScaler::fit: ", rows.size(), " rows, expected at least 2");
    ColumnScaler s;
    s.mean.assign(static_cast<std::size_t>(cols), 0.0);
    s.std.assign(static_cast<std::size_t>(cols), 0.0);
    const auto n = static_cast<double>(rows.size());
    for (int j = 0; j < cols; ++j) {
      double m = 0, q = 0;
      for (std::int64_t r : rows) m += values[static_cast<std::size_t>(r) * cols + j];
      m /= n;
      for (std::int64_t r : rows) {
        const double e = values[static_cast<std::size_t>(r) * cols + j] - m;
        q += e * e;
      }
      s.mean[static_cast<std::size_t>(j)] = m;
      s.std[static_cast<std::size_t>(j)] = std::max(std::sqrt(q / n), 1e-6);
    }
    return s;
  }
  double standardize(double v, int j) const {
    return (v - mean[static_cast<std::size_t>(j)]) / std[static_cast<std::size_t>(j)];
  }
  double restore(double z, int j) const { return z * std[static_cast<std::size_t>(j)] + mean[static_cast<std::size_t>(j)]; }
};

namespace detail {
// y [B, R + C] (row stride ldy) → dy [B, R + C] (overwritten, may be nullptr) and the two losses:
// the MSE against standardized targets z [B, R] and the cross-entropy against labels [B].
template <class T, class Z>
std::array<double, 2> head_loss(const T* y, std::size_t ldy, const Z* z, const int* labels, int B, int R, int C,
                                double class_weight, T* dy) {
  double f = 0;
  for (int b = 0; b < B; ++b)
    for (int a = 0; a < R; ++a) {
      const std::size_t i = static_cast<std::size_t>(b) * ldy + a;
      const double e = static_cast<double>(y[i]) - static_cast<double>(z[static_cast<std::size_t>(b) * R + a]);
      f += e * e;
      if (dy) dy[i] = static_cast<T>(2.0 * e / (static_cast<double>(B) * R));
    }
  if (R > 0) f /= static_cast<double>(B) * R;
  const double ce = C > 0 ? softmax_cross_entropy(y + R, ldy, labels, B, C, dy ? dy + R : nullptr, ldy, class_weight)
                          : 0.0;
  return {f, ce};
}
}  // namespace detail

// An attentive probe with R + C outputs, its parameters and the standardization of its
// regression targets.
template <class T>
struct ProbeHead {
  ParamSet<T> params;
  AttentiveProbe probe;
  ColumnScaler scaler;
  int regression = 0, classes = 0;

  // From a whole probe config (c.out_dim = R + C): parameters "probe.*" allocated, left for the
  // caller to fill (load_probe_head) or initialize.
  ProbeHead(const ProbeConfig& c, int regression_, int classes_) : regression(regression_), classes(classes_) {
    require<ConfigError>(regression_ >= 0 && (classes_ == 0 || classes_ > 1) && regression_ + classes_ > 0,
                         "ProbeHead: regression = ", regression_, ", classes = ", classes_,
                         ", expected R >= 0, C = 0 or C >= 2, and R + C > 0");
    require<ConfigError>(c.out_dim == outputs(), "ProbeHead: out_dim = ", c.out_dim, ", expected R + C = ", outputs());
    probe = AttentiveProbe(params, c);
    params.allocate();
    scaler.mean.assign(static_cast<std::size_t>(regression), 0.0);
    scaler.std.assign(static_cast<std::size_t>(regression), 1.0);
  }
  // head_hidden 0: dim. Parameters "probe.*" initialized from seed. pooling: the probe's pooling
  // (attentive: the paper's).
  ProbeHead(int dim, int heads, int regression_, int classes_, std::uint64_t seed, int head_hidden = 0,
            const PoolingConfig& pooling = {})
      : ProbeHead(ProbeConfig{.dim = dim, .heads = heads, .head_hidden = head_hidden > 0 ? head_hidden : dim,
                              .out_dim = regression_ + classes_, .pooling = pooling},
                  regression_, classes_) {
    init_params(params, seed);
  }
  int outputs() const { return regression + classes; }
};

// Raw outputs y [ids, R + C] (regression still standardized) at inference, batch by batch.
template <class T, class Features>
std::vector<T> head_outputs(const ProbeHead<T>& head, Features& features, std::span<const std::int64_t> ids,
                            int batch = 64) {
  require<ConfigError>(batch > 0, "head_outputs: batch = ", batch, ", expected > 0");
  const int out = head.outputs(), L = features.tokens();
  std::vector<T> y(ids.size() * static_cast<std::size_t>(out));
  Workspace<T> ws;
  for (std::size_t s0 = 0; s0 < ids.size(); s0 += static_cast<std::size_t>(batch)) {
    const int B = static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(batch), ids.size() - s0));
    const T* x = features.forward(ids.subspan(s0, static_cast<std::size_t>(B)), false);
    head.probe.forward(head.params, {x, B, L}, y.data() + s0 * static_cast<std::size_t>(out), ws);
  }
  return y;
}

namespace detail {
// The training loss of outputs y [ids, R + C] (head_outputs) against the targets of ids.
template <class T>
double head_objective_of(const ProbeHead<T>& head, const std::vector<T>& y, const HeadTargets& targets,
                         std::span<const std::int64_t> ids, double class_weight) {
  const int R = head.regression, B = static_cast<int>(ids.size());
  std::vector<double> z(ids.size() * static_cast<std::size_t>(R));
  std::vector<int> lab(head.classes > 0 ? ids.size() : 0);
  for (std::size_t b = 0; b < ids.size(); ++b) {
    const auto s = static_cast<std::size_t>(ids[b]);
    for (int a = 0; a < R; ++a) z[b * R + a] = head.scaler.standardize(targets.value[s * R + a], a);
    if (head.classes > 0) lab[b] = targets.label[s];
  }
  const auto [f, ce] = head_loss(y.data(), static_cast<std::size_t>(head.outputs()), z.data(), lab.data(), B, R,
                                 head.classes, class_weight, static_cast<T*>(nullptr));
  return f + class_weight * ce;
}
}  // namespace detail

// The training loss (regression MSE on standardized targets + class_weight · cross-entropy) of
// the head on samples ids.
template <class T, class Features>
double head_objective(const ProbeHead<T>& head, Features& features, const HeadTargets& targets,
                      std::span<const std::int64_t> ids, double class_weight, int batch = 64) {
  require<DataError>(!ids.empty(), "head_objective: no samples");
  return detail::head_objective_of(head, head_outputs(head, features, ids, batch), targets, ids, class_weight);
}

// What early stopping minimizes on the validation samples ids: the training loss, or, with
// cfg.stop_on_error and a head with classes, the top-1 error rate e with the loss o breaking ties,
// e + o / (1 + o) / (n + 1) for n samples: the tie-break stays below one sample's worth of error,
// so a lower error always wins.
template <class T, class Features>
double head_validation(const ProbeHead<T>& head, Features& features, const HeadTargets& targets,
                       std::span<const std::int64_t> ids, const HeadTrainConfig& cfg, int batch = 64) {
  require<DataError>(!ids.empty(), "head_validation: no samples");
  const std::vector<T> y = head_outputs(head, features, ids, batch);
  const double o = detail::head_objective_of(head, y, targets, ids, cfg.class_weight);
  if (!cfg.stop_on_error || head.classes == 0) return o;
  std::vector<int> lab(ids.size());
  for (std::size_t b = 0; b < ids.size(); ++b) lab[b] = targets.label[static_cast<std::size_t>(ids[b])];
  const double n = static_cast<double>(ids.size());
  const double wrong = n - std::round(n * accuracy(y.data() + head.regression, static_cast<std::size_t>(head.outputs()),
                                                   lab.data(), static_cast<int>(ids.size()), head.classes));
  return wrong / n + (std::isfinite(o) ? o / (1.0 + o) : 1.0) / (n + 1.0);
}

namespace detail {
// One early-stopped training of head on split (split.validation empty: no validation, every
// epoch counts as the best so far, so the last one is kept and the run goes to max_epochs), as an
// object that runs a given number of epochs at a time: train_head runs its folds side by side.
// It holds references to head, features and targets, and lambdas that point into it: not movable.
template <class T, class Features>
class HeadSplitRun {
 public:
  HeadSplitRun(ProbeHead<T>& head, Features& features, const HeadTargets& targets, const HeadTrainConfig& cfg,
               ValidationSplit split, std::ostream* log, std::int64_t log_every)
      : head_(head), features_(features), targets_(targets), cfg_(cfg), split_(std::move(split)) {
    const int R = head.regression, C = head.classes;
    if (R > 0) head.scaler = ColumnScaler::fit(targets.value, R, split_.fit);
    std::vector<PrefixedParams<T>> parts{{"probe.", &head.params}};
    if (ParamSet<T>* enc = features.trainable()) parts.push_back({"encoder.", enc});
    auto forward = [this](std::span<const std::int64_t> ids) { return forward_batch(ids); };
    auto backward = [this] { backward_batch(); };
    auto validate = [this] {
      if (split_.validation.empty()) return -(epochs_done_ += 1);  // no validation: the latest epoch is the best
      return head_validation(head_, features_, targets_, split_.validation, cfg_);
    };
    trainer_.emplace(std::move(parts), split_.fit, cfg, forward, backward, validate,
                     nlohmann::json{{"kind", "probe"}, {"regression", R}, {"classes", C}});
    if (log) {
      trainer_->log = log;
      trainer_->log_every = log_every;
    }
  }
  HeadSplitRun(const HeadSplitRun&) = delete;
  HeadSplitRun& operator=(const HeadSplitRun&) = delete;

  // Runs `epochs` more epochs (< 0: to the end), fewer if the run stops early or ends.
  void run(int epochs = -1) { trainer_->run(epochs < 0 ? -1 : std::int64_t(epochs) * trainer_->steps_per_epoch()); }
  const HeadTrainResult& record() const { return trainer_->record(); }

 private:
  double forward_batch(std::span<const std::int64_t> ids) {
    const int R = head_.regression, C = head_.classes, out = head_.outputs(), L = features_.tokens();
    B_ = static_cast<int>(ids.size());
    z_.resize(static_cast<std::size_t>(B_) * R);
    lab_.resize(C > 0 ? static_cast<std::size_t>(B_) : 0);
    for (int b = 0; b < B_; ++b) {
      const auto s = static_cast<std::size_t>(ids[static_cast<std::size_t>(b)]);
      for (int a = 0; a < R; ++a)
        z_[static_cast<std::size_t>(b) * R + a] = head_.scaler.standardize(targets_.value[s * R + a], a);
      if (C > 0) lab_[static_cast<std::size_t>(b)] = targets_.label[s];
    }
    T* yp = detail::grow(y_, static_cast<std::size_t>(B_) * out);
    T* dyp = detail::grow(dy_, static_cast<std::size_t>(B_) * out);
    const T* x = features_.forward(ids, true);
    head_.probe.forward(head_.params, {x, B_, L}, yp, cache_, ws_);
    const auto [f, ce] = detail::head_loss(yp, static_cast<std::size_t>(out), z_.data(), lab_.data(), B_, R, C,
                                           cfg_.class_weight, dyp);
    return f + cfg_.class_weight * ce;
  }
  void backward_batch() {
    T* dxp = nullptr;
    if (features_.trainable()) {
      const std::size_t n = static_cast<std::size_t>(B_) * features_.tokens() * features_.dim();
      dxp = detail::grow(dx_, n);
      std::fill(dxp, dxp + n, T(0));
    }
    head_.probe.backward(head_.params, dy_.data(), dxp, cache_, ws_);
    if (dxp) features_.backward(dxp);
  }

  ProbeHead<T>& head_;
  Features& features_;
  const HeadTargets& targets_;
  HeadTrainConfig cfg_;
  ValidationSplit split_;
  Workspace<T> ws_;
  ProbeCache<T> cache_;
  AlignedVector<T> y_, dy_, dx_;
  std::vector<double> z_;
  std::vector<int> lab_;
  int B_ = 0;
  double epochs_done_ = 0;
  std::optional<Trainer<HeadObjective<T>>> trainer_;
};

template <class T, class Features>
HeadTrainResult train_head_split(ProbeHead<T>& head, Features& features, const HeadTargets& targets,
                                 const HeadTrainConfig& cfg, const ValidationSplit& split, std::ostream* log,
                                 std::int64_t log_every) {
  HeadSplitRun<T, Features> run(head, features, targets, cfg, split, log, log_every);
  run.run();
  return run.record();
}
}  // namespace detail

// Trains head (and the features' encoder, if trainable) on samples 0..S−1 of targets with early
// stopping (a Trainer over a HeadObjective): the scaler is fitted on the fitting split, the
// validation split is held out of training; at return the parameters are those of the best
// validation epoch. log: the Trainer's log line every log_every steps.
// cfg.folds = k > 1 (and no validation groups given in targets.groups.held): k trainings from the
// same start, fold f validating on validation_folds' fold f, run side by side one epoch at a time;
// they stop together once the mean of their validation values has not been lowest for `patience`
// epochs (or at max_epochs), so no fold's own early stop cuts the mean curve short. The epoch e
// with the lowest mean (mean_validation_curve); then, from the same start again, e + 1 epochs on
// every sample. The record: that final run's training losses, the mean validation curve, e and
// its mean loss. A trainable encoder is swapped in and out around each fold's epoch.
template <class T, class Features>
HeadTrainResult train_head(ProbeHead<T>& head, Features& features, const HeadTargets& targets,
                           const HeadTrainConfig& cfg, std::ostream* log = nullptr, std::int64_t log_every = 0) {
  cfg.validate();
  targets.validate("train_head");
  const int S = targets.size();
  require<ShapeError>(targets.regression == head.regression && targets.classes == head.classes,
                      "train_head: targets of R = ", targets.regression, ", C = ", targets.classes,
                      ", the head has R = ", head.regression, ", C = ", head.classes);
  require<ShapeError>(features.size() == S, "train_head: ", features.size(), " feature rows for ", S, " targets");
  require<ShapeError>(features.dim() == head.probe.config.dim, "train_head: features of width ", features.dim(),
                      ", the head expects ", head.probe.config.dim);
  if (cfg.folds <= 1 || !targets.groups.held.empty())
    return detail::train_head_split(head, features, targets, cfg, validation_split(S, cfg, targets.groups), log,
                                    log_every);
  const std::vector<ValidationSplit> splits = validation_folds(S, cfg, targets.groups);
  const std::size_t k = splits.size();
  // A trainable encoder's values per fold, swapped in and out of the one the features train.
  ParamSet<T>* encoder = features.trainable();
  std::vector<std::vector<T>> encoders;
  if (encoder) encoders.assign(k + 1, std::vector<T>(encoder->values().begin(), encoder->values().end()));  // [k]: the start
  auto load = [&](std::size_t f) {
    if (encoder) std::copy(encoders[f].begin(), encoders[f].end(), encoder->values().begin());
  };
  HeadTrainConfig fold_cfg = cfg;
  fold_cfg.patience = cfg.max_epochs;  // no fold stops on its own: the mean decides
  std::vector<ProbeHead<T>> heads(k, head);
  std::vector<std::unique_ptr<detail::HeadSplitRun<T, Features>>> runs;
  for (std::size_t f = 0; f < k; ++f)
    runs.push_back(std::make_unique<detail::HeadSplitRun<T, Features>>(heads[f], features, targets, fold_cfg,
                                                                         splits[f], log, log_every));
  double best = std::numeric_limits<double>::infinity();
  for (int e = 0, best_epoch = -1; e < cfg.max_epochs; ++e) {  // the Trainer's rule, on the mean
    double mean = 0;
    for (std::size_t f = 0; f < k; ++f) {
      load(f);
      runs[f]->run(1);
      if (encoder) std::copy(encoder->values().begin(), encoder->values().end(), encoders[f].begin());
      mean += runs[f]->record().validation_loss.back() / static_cast<double>(k);
    }
    if (mean < best)
      best = mean, best_epoch = e;
    else if (e - best_epoch >= cfg.patience)
      break;
  }
  std::vector<HeadTrainResult> folds;
  for (const auto& r : runs) folds.push_back(r->record());
  HeadTrainResult chosen = mean_validation_curve(folds);
  load(k);
  HeadTrainConfig all = cfg;
  all.max_epochs = chosen.best_epoch + 1;  // no validation: every epoch is the best so far, patience never ends it
  ValidationSplit every;
  for (int i = 0; i < S; ++i) every.fit.push_back(i);
  chosen.train_loss = detail::train_head_split(head, features, targets, all, every, log, log_every).train_loss;
  return chosen;
}

// Predictions [S, R + C] for samples 0..S−1: regression in the targets' units, then the logits.
template <class T, class Features>
std::vector<T> predict_head(const ProbeHead<T>& head, Features& features, int S, int batch = 64) {
  require<ShapeError>(S > 0 && S <= features.size(), "predict_head: S = ", S, ", expected in [1, ", features.size(), "]");
  std::vector<std::int64_t> ids(static_cast<std::size_t>(S));
  for (int s = 0; s < S; ++s) ids[static_cast<std::size_t>(s)] = s;
  std::vector<T> y = head_outputs(head, features, ids, batch);
  const int out = head.outputs();
  for (int s = 0; s < S; ++s)
    for (int a = 0; a < head.regression; ++a) {
      T& v = y[static_cast<std::size_t>(s) * out + a];
      v = static_cast<T>(head.scaler.restore(v, a));
    }
  return y;
}

// Held-out metrics of a head.
struct HeadMetrics {
  std::vector<double> rmse;     // [R] per regression output, in the targets' units
  double accuracy = 0;          // top-1 (C > 0)
  double majority_accuracy = 0; // chance level: the most frequent class
  int samples = 0;
};

template <class T, class Features>
HeadMetrics evaluate_head(const ProbeHead<T>& head, Features& features, const HeadTargets& targets, int batch = 64) {
  targets.validate("evaluate_head");
  const int S = targets.size();
  require<ShapeError>(S > 0 && features.size() == S, "evaluate_head: ", features.size(), " feature rows for ", S,
                      " targets, expected equal and > 0");
  require<ShapeError>(targets.regression == head.regression && targets.classes == head.classes,
                      "evaluate_head: targets of R = ", targets.regression, ", C = ", targets.classes,
                      ", the head has R = ", head.regression, ", C = ", head.classes);
  const std::vector<T> y = predict_head(head, features, S, batch);
  const auto out = static_cast<std::size_t>(head.outputs());
  HeadMetrics m;
  m.samples = S;
  if (head.regression > 0) m.rmse = rmse_per_column(y.data(), out, targets.value.data(), S, head.regression);
  if (head.classes > 0) {
    m.accuracy = accuracy(y.data() + head.regression, out, targets.label.data(), S, head.classes);
    m.majority_accuracy = majority_accuracy(targets.label.data(), S, head.classes);
  }
  return m;
}

}  // namespace tjepa
