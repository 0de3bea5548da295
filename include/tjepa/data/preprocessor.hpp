#pragma once
// Preprocessor: the per-reading transforms of the paper's Sec. IV-D (data preprocessing) and of the
// reference implementation (E-Kovtun/tactile, tactile_ssl/data/xela/preprocessing.py), with
// statistics fitted on training data only and saved with the model (state() / from_state()).
// Steps, in order:
//
//   1. drop-outs   readings outside [valid_min, valid_max] become 0 (a magnetic taxel that lost its
//                  signal reports counts far outside its range); optionally NaN becomes 0 too.
//   2. baseline    subtract the taxel's no-contact mean, per axis, where the taxel's reading is
//                  non-zero (its axis 0, as the reference masks: a drop-out stays 0).
//   3. scaling     one of: per-axis standardization (mean/std per axis over all taxels and frames,
//                  ignoring zeros and NaN), scalar standardization (one mean/std, same rule), a fixed
//                  per-part maximum (x / max[part of taxel]), or none.
//
// Standardization is applied to every value, zeros included, as the reference model's normalize()
// does. Statistics are accumulated in double, population variance (E[x²] − mean²) like the
// reference; a std below min_std is raised to it so a constant axis does not divide by zero.
//
// apply() works in place on any tensor viewed as [outer, N, inner, m]: a recording [T, N, m]
// (inner = 1) or a batch of windows [B, N, τ, m] (outer = B, inner = τ), so a memory-mapped
// recording never needs a preprocessed copy: each batch is transformed as it is gathered.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/data/recording.hpp"

namespace tjepa {

enum class Scaling : int { none = 0, per_axis = 1, scalar = 2, part_max = 3 };

struct PreprocessConfig {
  bool clip_dropouts = false;  // step 1
  float valid_min = 20000.0f;  // Xela counts (the reference implementation's outlier bounds)
  float valid_max = 60000.0f;
  bool nan_as_dropout = false;     // NaN readings become 0 (otherwise they are a DataError in training)
  bool subtract_baseline = false;  // step 2: needs fit_baseline()
  Scaling scaling = Scaling::none; // step 3
  std::vector<float> part_max;     // [P] fixed maxima for Scaling::part_max (DECO-50: 3486, 4050)
  std::vector<int> taxel_part;     // [N] part of each taxel, for Scaling::part_max
  float min_std = 1e-6f;

  // Xela uSkin counts: drop-outs outside [20000, 60000], baseline, per-axis standardization.
  static PreprocessConfig xela_counts() {
    PreprocessConfig c;
    c.clip_dropouts = true;
    c.subtract_baseline = true;
    c.scaling = Scaling::per_axis;
    return c;
  }
  // Magnetometer skins (AnySkin) and others whose taxels sit at different offsets: each taxel's
  // no-contact mean subtracted, then per-axis standardization. No drop-out range.
  static PreprocessConfig baseline_standardization() {
    PreprocessConfig c;
    c.subtract_baseline = true;
    c.scaling = Scaling::per_axis;
    return c;
  }
  // Tactile socks: one scalar mean and std.
  static PreprocessConfig scalar_standardization() {
    PreprocessConfig c;
    c.scaling = Scaling::scalar;
    return c;
  }
  // DECO-50: divide by a fixed maximum per part (hand).
  static PreprocessConfig per_part_max(std::vector<float> maxima, std::vector<int> taxel_part) {
    PreprocessConfig c;
    c.scaling = Scaling::part_max;
    c.part_max = std::move(maxima);
    c.taxel_part = std::move(taxel_part);
    return c;
  }
};

class Preprocessor {
 public:
  explicit Preprocessor(PreprocessConfig cfg = {}) : cfg_(std::move(cfg)) {
    require<ConfigError>(!cfg_.clip_dropouts || cfg_.valid_min <= cfg_.valid_max, "Preprocessor: valid range [",
                         cfg_.valid_min, ", ", cfg_.valid_max, "], expected valid_min <= valid_max");
    require<ConfigError>(cfg_.min_std > 0, "Preprocessor: min_std = ", cfg_.min_std, ", expected > 0");
    if (cfg_.scaling == Scaling::part_max) {
      require<ConfigError>(!cfg_.part_max.empty() && !cfg_.taxel_part.empty(),
                           "Preprocessor: Scaling::part_max needs part_max (one per part) and taxel_part (one per taxel)");
      for (std::size_t p = 0; p < cfg_.part_max.size(); ++p)
        require<ConfigError>(std::isfinite(cfg_.part_max[p]) && cfg_.part_max[p] > 0, "Preprocessor: part_max[", p,
                             "] = ", cfg_.part_max[p], ", expected a finite value > 0");
      for (std::size_t n = 0; n < cfg_.taxel_part.size(); ++n)
        require<ConfigError>(cfg_.taxel_part[n] >= 0 && cfg_.taxel_part[n] < static_cast<int>(cfg_.part_max.size()),
                             "Preprocessor: taxel_part[", n, "] = ", cfg_.taxel_part[n], ", expected in [0, ",
                             cfg_.part_max.size(), ")");
      taxels_ = static_cast<int>(cfg_.taxel_part.size());
    }
  }

  // Per-axis standardization with given statistics (a model's own normalization, e.g. the
  // reference's xela_mean / xela_std buffers): (x − mean[a]) / std[a] for every value.
  static Preprocessor with_statistics(std::vector<float> mean, std::vector<float> std) {
    require<ConfigError>(!mean.empty() && mean.size() == std.size(), "Preprocessor::with_statistics: ", mean.size(),
                         " means and ", std.size(), " stds, expected one of each per axis");
    for (std::size_t a = 0; a < mean.size(); ++a)
      require<ConfigError>(std::isfinite(mean[a]) && std::isfinite(std[a]) && std[a] > 0,
                           "Preprocessor::with_statistics: axis ", a, " has mean ", mean[a], " and std ", std[a],
                           ", expected finite values and std > 0");
    PreprocessConfig c;
    c.scaling = Scaling::per_axis;
    c.min_std = *std::min_element(std.begin(), std.end());
    Preprocessor pre(c);
    pre.axes_ = static_cast<int>(mean.size());
    pre.mean_ = std::move(mean);
    pre.std_ = std::move(std);
    return pre;
  }

  const PreprocessConfig& config() const { return cfg_; }
  // True once every statistic the configuration needs is fitted (or restored).
  bool ready() const {
    const bool need_stats = cfg_.scaling == Scaling::per_axis || cfg_.scaling == Scaling::scalar;
    return (!cfg_.subtract_baseline || !baseline_.empty()) && (!need_stats || !mean_.empty());
  }
  const std::vector<float>& baseline() const { return baseline_; }  // [N, m]
  const std::vector<float>& mean() const { return mean_; }          // [m] (per axis) or [1]
  const std::vector<float>& std() const { return std_; }

  // Per-taxel, per-axis mean of a no-contact recording, over readings that are neither drop-outs
  // nor NaN (a taxel-axis with none gets 0).
  void fit_baseline(const Recording& no_contact) {
    check_dims("fit_baseline", no_contact);
    const int n = no_contact.taxels(), m = no_contact.axes();
    std::vector<double> sum(static_cast<std::size_t>(n) * m, 0.0);
    std::vector<std::int64_t> count(sum.size(), 0);
    std::vector<float> frame(sum.size());
    for (int t = 0; t < no_contact.frames(); ++t) {
      std::copy_n(no_contact.frame(t), frame.size(), frame.begin());
      dropouts(frame.data(), frame.size());
      for (std::size_t k = 0; k < frame.size(); ++k)
        if (frame[k] != 0.0f && !std::isnan(frame[k])) {
          sum[k] += frame[k];
          ++count[k];
        }
    }
    baseline_.assign(sum.size(), 0.0f);
    for (std::size_t k = 0; k < sum.size(); ++k)
      if (count[k] > 0) baseline_[k] = static_cast<float>(sum[k] / static_cast<double>(count[k]));
  }

  // Standardization statistics over training recordings (after drop-outs and baseline), ignoring
  // zeros and NaN. Nothing to fit for Scaling::none and part_max.
  void fit(std::span<const Recording> train) {
    require<ConfigError>(!train.empty(), "Preprocessor::fit: no training recordings");
    require<ConfigError>(!cfg_.subtract_baseline || !baseline_.empty(),
                         "Preprocessor::fit: subtract_baseline is on but no baseline is fitted; call fit_baseline() "
                         "with a no-contact recording first");
    for (const auto& r : train) check_dims("fit", r);
    if (cfg_.scaling != Scaling::per_axis && cfg_.scaling != Scaling::scalar) return;
    const int m = axes_;
    const std::size_t k_stats = cfg_.scaling == Scaling::per_axis ? static_cast<std::size_t>(m) : 1;
    std::vector<double> sum(k_stats, 0.0), sq(k_stats, 0.0);
    std::vector<std::int64_t> count(k_stats, 0);
    std::vector<float> frame;
    for (const auto& r : train) {
      frame.resize(static_cast<std::size_t>(r.taxels()) * m);
      for (int t = 0; t < r.frames(); ++t) {
        std::copy_n(r.frame(t), frame.size(), frame.begin());
        dropouts(frame.data(), frame.size());
        if (cfg_.subtract_baseline) subtract_baseline(frame.data(), 1);
        for (std::size_t k = 0; k < frame.size(); ++k) {
          const float v = frame[k];
          if (v == 0.0f || std::isnan(v)) continue;
          const std::size_t s = k_stats == 1 ? 0 : k % m;
          sum[s] += v;
          sq[s] += static_cast<double>(v) * v;
          ++count[s];
        }
      }
    }
    mean_.assign(k_stats, 0.0f);
    std_.assign(k_stats, 1.0f);
    for (std::size_t s = 0; s < k_stats; ++s) {
      require<DataError>(count[s] > 0, "Preprocessor::fit: ",
                         k_stats == 1 ? std::string("the data") : "axis " + std::to_string(s),
                         " has no non-zero finite value to fit a mean and std on");
      const double mu = sum[s] / static_cast<double>(count[s]);
      const double var = std::max(sq[s] / static_cast<double>(count[s]) - mu * mu, 0.0);
      mean_[s] = static_cast<float>(mu);
      std_[s] = std::max(static_cast<float>(std::sqrt(var)), cfg_.min_std);
    }
  }
  void fit(const Recording& train) { fit(std::span<const Recording>(&train, 1)); }

  // In place on x viewed as [outer, taxels, inner, axes].
  void apply(float* x, std::size_t outer, int taxels, int inner, int axes) const {
    require<ConfigError>(ready(), "Preprocessor::apply: statistics are not fitted (call fit_baseline()/fit() on "
                                  "training data, or restore them with from_state())");
    require<ShapeError>((taxels_ == 0 || taxels == taxels_) && (axes_ == 0 || axes == axes_),
                        "Preprocessor::apply: data have ", taxels, " taxels and ", axes,
                        " axes, the statistics were fitted on ", taxels_, " taxels and ", axes_, " axes");
    const std::size_t block = static_cast<std::size_t>(inner) * axes;
    for (std::size_t o = 0; o < outer; ++o) {
      float* xo = x + o * static_cast<std::size_t>(taxels) * block;
      dropouts(xo, static_cast<std::size_t>(taxels) * block);
      if (cfg_.subtract_baseline) subtract_baseline(xo, inner);
      scale(xo, taxels, inner, axes);
    }
  }
  void apply(Recording& rec) const { apply(rec.mutable_data(), static_cast<std::size_t>(rec.frames()), rec.taxels(), 1, rec.axes()); }
  Recording transformed(const Recording& rec) const {
    Recording out = rec;
    apply(out);
    return out;
  }

  // The configuration and statistics as named tensors ("preprocess.*"), for the checkpoint.
  std::vector<NamedTensor> state() const {
    std::vector<NamedTensor> out;
    out.push_back({"preprocess.config", {9},
                   {cfg_.clip_dropouts ? 1.0f : 0.0f, cfg_.valid_min, cfg_.valid_max, cfg_.nan_as_dropout ? 1.0f : 0.0f,
                    cfg_.subtract_baseline ? 1.0f : 0.0f, static_cast<float>(static_cast<int>(cfg_.scaling)),
                    cfg_.min_std, static_cast<float>(taxels_), static_cast<float>(axes_)}});
    if (!baseline_.empty()) out.push_back({"preprocess.baseline", {taxels_, axes_}, baseline_});
    if (!mean_.empty()) {
      const auto k = static_cast<std::int64_t>(mean_.size());
      out.push_back({"preprocess.mean", {k}, mean_});
      out.push_back({"preprocess.std", {k}, std_});
    }
    if (cfg_.scaling == Scaling::part_max) {
      out.push_back({"preprocess.part_max", {static_cast<std::int64_t>(cfg_.part_max.size())}, cfg_.part_max});
      out.push_back({"preprocess.taxel_part", {static_cast<std::int64_t>(cfg_.taxel_part.size())},
                     std::vector<float>(cfg_.taxel_part.begin(), cfg_.taxel_part.end())});
    }
    return out;
  }

  static Preprocessor from_state(std::span<const NamedTensor> tensors) {
    const char* who = "Preprocessor::from_state";
    const NamedTensor& c = find_tensor(tensors, "preprocess.config", who);
    require<FileError>(c.values.size() == 9, who, ": 'preprocess.config' has ", c.values.size(), " values, expected 9");
    PreprocessConfig cfg;
    cfg.clip_dropouts = c.values[0] != 0.0f;
    cfg.valid_min = c.values[1];
    cfg.valid_max = c.values[2];
    cfg.nan_as_dropout = c.values[3] != 0.0f;
    cfg.subtract_baseline = c.values[4] != 0.0f;
    const int mode = static_cast<int>(c.values[5]);
    require<FileError>(mode >= 0 && mode <= 3, who, ": scaling mode ", mode, ", expected 0..3");
    cfg.scaling = static_cast<Scaling>(mode);
    cfg.min_std = c.values[6];
    const int taxels = static_cast<int>(c.values[7]), axes = static_cast<int>(c.values[8]);
    if (cfg.scaling == Scaling::part_max) {
      cfg.part_max = find_tensor(tensors, "preprocess.part_max", who).values;
      for (float p : find_tensor(tensors, "preprocess.taxel_part", who).values) cfg.taxel_part.push_back(static_cast<int>(p));
    }
    Preprocessor pre(std::move(cfg));
    pre.taxels_ = taxels;
    pre.axes_ = axes;
    if (pre.cfg_.subtract_baseline) {
      pre.baseline_ = find_tensor(tensors, "preprocess.baseline", who).values;
      require<FileError>(pre.baseline_.size() == static_cast<std::size_t>(taxels) * axes, who,
                         ": 'preprocess.baseline' has ", pre.baseline_.size(), " values, expected ", taxels, "*", axes);
    }
    if (pre.cfg_.scaling == Scaling::per_axis || pre.cfg_.scaling == Scaling::scalar) {
      pre.mean_ = find_tensor(tensors, "preprocess.mean", who).values;
      pre.std_ = find_tensor(tensors, "preprocess.std", who).values;
      const std::size_t k = pre.cfg_.scaling == Scaling::per_axis ? static_cast<std::size_t>(axes) : 1;
      require<FileError>(pre.mean_.size() == k && pre.std_.size() == k, who, ": mean/std have ", pre.mean_.size(),
                         "/", pre.std_.size(), " values, expected ", k);
    }
    return pre;
  }

 private:
  void check_dims(const char* who, const Recording& r) {
    if (taxels_ == 0) taxels_ = r.taxels();
    if (axes_ == 0) axes_ = r.axes();
    require<ShapeError>(r.taxels() == taxels_ && r.axes() == axes_, "Preprocessor::", who, ": ", r.source(),
                        " has ", r.taxels(), " taxels and ", r.axes(), " axes, expected ", taxels_, " and ", axes_);
  }

  void dropouts(float* x, std::size_t n) const {
    if (cfg_.clip_dropouts) {
      const float lo = cfg_.valid_min, hi = cfg_.valid_max;
      for (std::size_t k = 0; k < n; ++k)
        if (x[k] < lo || x[k] > hi) x[k] = 0.0f;  // NaN compares false: left alone
    }
    if (cfg_.nan_as_dropout)
      for (std::size_t k = 0; k < n; ++k)
        if (std::isnan(x[k])) x[k] = 0.0f;
  }

  // x: [taxels_, inner, axes_]; subtracts where the taxel's axis-0 reading is non-zero.
  void subtract_baseline(float* x, int inner) const {
    const int m = axes_;
    for (int n = 0; n < taxels_; ++n) {
      const float* b = baseline_.data() + static_cast<std::size_t>(n) * m;
      float* xn = x + static_cast<std::size_t>(n) * inner * m;
      for (int i = 0; i < inner; ++i, xn += m)
        if (xn[0] != 0.0f)
          for (int a = 0; a < m; ++a) xn[a] -= b[a];
    }
  }

  // x: [taxels, inner, axes]
  void scale(float* x, int taxels, int inner, int axes) const {
    const std::size_t block = static_cast<std::size_t>(inner) * axes;
    switch (cfg_.scaling) {
      case Scaling::none:
        return;
      case Scaling::per_axis: {
        float mu[16], inv[16];
        for (int a = 0; a < axes && a < 16; ++a) {
          mu[a] = mean_[a];
          inv[a] = 1.0f / std_[a];
        }
        if (axes <= 16) {
          const std::size_t total = static_cast<std::size_t>(taxels) * block;
          for (std::size_t k = 0; k < total; k += axes)
            for (int a = 0; a < axes; ++a) x[k + a] = (x[k + a] - mu[a]) * inv[a];
        } else {
          const std::size_t total = static_cast<std::size_t>(taxels) * block;
          for (std::size_t k = 0; k < total; ++k) x[k] = (x[k] - mean_[k % axes]) / std_[k % axes];
        }
        return;
      }
      case Scaling::scalar: {
        const float mu = mean_[0], inv = 1.0f / std_[0];
        const std::size_t total = static_cast<std::size_t>(taxels) * block;
        for (std::size_t k = 0; k < total; ++k) x[k] = (x[k] - mu) * inv;
        return;
      }
      case Scaling::part_max:
        for (int n = 0; n < taxels; ++n) {
          const float inv = 1.0f / cfg_.part_max[cfg_.taxel_part[n]];
          float* xn = x + static_cast<std::size_t>(n) * block;
          for (std::size_t k = 0; k < block; ++k) xn[k] *= inv;
        }
        return;
    }
  }

  PreprocessConfig cfg_;
  int taxels_ = 0;
  int axes_ = 0;
  std::vector<float> baseline_;  // [N, m]
  std::vector<float> mean_, std_;
};

}  // namespace tjepa
