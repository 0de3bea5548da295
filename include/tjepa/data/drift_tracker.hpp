#pragma once
// DriftTracker: removes the slow drift of each taxel's no-contact reading (temperature, creep of
// the elastomer, the magnet) before the Preprocessor, causally, frame by frame.
//
// Why: the Preprocessor subtracts one baseline measured once (paper, Sec. IV-D). A magnetic taxel's
// rest reading wanders afterwards by tens of counts, independently per taxel. After per-axis
// standardization that wander is the largest variation of an idle taxel, and most taxels are
// idle in most windows; no other taxel predicts it. Touch controllers re-zero the same way:
// a baseline that follows the reading while the taxel is untouched and freezes while it is touched.
//
// Per taxel n and axis a, with b_{n,a} the tracked rest reading (initially the fitted mean of a
// no-contact recording, b⁰) and σ_a the sensor noise of axis a:
//   a frame is *idle* for taxel n when its reading is valid (non-zero, finite, inside
//   [valid_min, valid_max]) and |x_{n,a} − b_{n,a}| ≤ threshold·σ_a on every axis;
//   output   x'_{n,a} = x_{n,a} − (b_{n,a} − b⁰_{n,a})     (valid readings; drop-outs pass unchanged)
//   update   b_{n,a} ← b_{n,a} + α·(x_{n,a} − b_{n,a})     when idle, α = 1 / time_constant (frames)
// The output stays in raw counts, so the Preprocessor that follows (drop-out range, baseline b⁰,
// standardization) is unchanged. σ_a comes from frame-to-frame differences of the no-contact
// recording (√(E[(x_t − x_{t−1})²] / 2), pooled over taxels), so drift does not count as noise.
//
// The state (b⁰, b, σ, config) travels with the model: state() / from_state() as NamedTensors
// "drift.*". step() is allocation-free, for a control loop; apply() runs a recording in time order.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/named_tensor.hpp"
#include "tjepa/data/recording.hpp"

namespace tjepa {

struct DriftTrackerConfig {
  double time_constant = 200.0;  // frames (2 s at 100 Hz): how fast the rest reading is followed
  double threshold = 6.0;        // noise stds: a larger deviation on any axis means "touched"
  float valid_min = -std::numeric_limits<float>::infinity();  // readings outside are drop-outs
  float valid_max = std::numeric_limits<float>::infinity();

  // Xela uSkin counts: drop-outs outside [20000, 60000], as PreprocessConfig::xela_counts().
  static DriftTrackerConfig magnetic() {
    DriftTrackerConfig c;
    c.valid_min = 20000.0f;
    c.valid_max = 60000.0f;
    return c;
  }
  void validate() const {
    require<ConfigError>(std::isfinite(time_constant) && time_constant >= 1.0, "DriftTracker: time_constant = ",
                         time_constant, " frames, expected >= 1");
    require<ConfigError>(std::isfinite(threshold) && threshold > 0, "DriftTracker: threshold = ", threshold,
                         " noise stds, expected > 0");
    require<ConfigError>(!(valid_min >= valid_max), "DriftTracker: valid range [", valid_min, ", ", valid_max,
                         "] is empty");
  }
};

class DriftTracker {
 public:
  explicit DriftTracker(DriftTrackerConfig cfg = {}) : cfg_(cfg) { cfg_.validate(); }

  const DriftTrackerConfig& config() const { return cfg_; }
  bool fitted() const { return !rest0_.empty(); }
  int taxels() const { return taxels_; }
  int axes() const { return axes_; }
  std::span<const float> rest() const { return rest_; }          // [N, m] tracked rest reading b
  std::span<const float> fitted_rest() const { return rest0_; }  // [N, m] b⁰
  std::span<const float> noise() const { return noise_; }        // [m] σ

  // b⁰ and σ from a no-contact recording of at least 2 frames; resets the tracked state to b⁰.
  void fit(const Recording& no_contact) {
    const int T = no_contact.frames(), N = no_contact.taxels(), m = no_contact.axes();
    require<DataError>(T >= 2 && N > 0, "DriftTracker::fit: ", no_contact.source(), " has ", T,
                       " frame(s), expected a no-contact recording of >= 2 frames");
    taxels_ = N;
    axes_ = m;
    const std::size_t nm = static_cast<std::size_t>(N) * m;
    std::vector<double> sum(nm, 0.0), dsq(static_cast<std::size_t>(m), 0.0);
    std::vector<std::int64_t> count(nm, 0), dcount(static_cast<std::size_t>(m), 0);
    for (int t = 0; t < T; ++t) {
      const float* x = no_contact.frame(t);
      const float* prev = t > 0 ? no_contact.frame(t - 1) : nullptr;
      for (int n = 0; n < N; ++n) {
        const float* xn = x + static_cast<std::size_t>(n) * m;
        if (!valid(xn, m)) continue;
        for (int a = 0; a < m; ++a) {
          sum[static_cast<std::size_t>(n) * m + a] += xn[a];
          ++count[static_cast<std::size_t>(n) * m + a];
        }
        if (prev && valid(prev + static_cast<std::size_t>(n) * m, m))
          for (int a = 0; a < m; ++a) {
            const double d = static_cast<double>(xn[a]) - prev[static_cast<std::size_t>(n) * m + a];
            dsq[static_cast<std::size_t>(a)] += d * d;
            ++dcount[static_cast<std::size_t>(a)];
          }
      }
    }
    rest0_.assign(nm, 0.0f);
    for (std::size_t k = 0; k < nm; ++k) {
      require<DataError>(count[k] > 0, "DriftTracker::fit: taxel ", k / static_cast<std::size_t>(m), " of ",
                         no_contact.source(), " has no valid reading to take its rest reading from");
      rest0_[k] = static_cast<float>(sum[k] / static_cast<double>(count[k]));
    }
    noise_.assign(static_cast<std::size_t>(m), 0.0f);
    for (int a = 0; a < m; ++a) {
      require<DataError>(dcount[static_cast<std::size_t>(a)] > 0, "DriftTracker::fit: ", no_contact.source(),
                         " has no two consecutive valid frames to measure the noise of axis ", a);
      const double s = std::sqrt(dsq[static_cast<std::size_t>(a)] / static_cast<double>(dcount[static_cast<std::size_t>(a)]) / 2.0);
      noise_[static_cast<std::size_t>(a)] = static_cast<float>(std::max(s, 1e-6));
    }
    reset();
  }

  // Back to the fitted rest reading (a new, unrelated recording).
  void reset() {
    require<ConfigError>(fitted(), "DriftTracker::reset: not fitted (call fit() with a no-contact recording)");
    rest_ = rest0_;
  }

  // One frame x [N, m] in place: drift removed, then the rest reading updated where idle.
  void step(float* x) {
    require<ConfigError>(fitted(), "DriftTracker::step: not fitted (call fit() with a no-contact recording)");
    const int m = axes_;
    const float alpha = static_cast<float>(1.0 / cfg_.time_constant);
    const float thr = static_cast<float>(cfg_.threshold);
    for (int n = 0; n < taxels_; ++n) {
      float* xn = x + static_cast<std::size_t>(n) * m;
      if (!valid(xn, m)) continue;  // a drop-out passes unchanged and teaches nothing
      float* b = rest_.data() + static_cast<std::size_t>(n) * m;
      const float* b0 = rest0_.data() + static_cast<std::size_t>(n) * m;
      bool idle = true;
      for (int a = 0; a < m; ++a) idle = idle && std::abs(xn[a] - b[a]) <= thr * noise_[static_cast<std::size_t>(a)];
      for (int a = 0; a < m; ++a) {
        const float raw = xn[a];
        xn[a] = raw - (b[a] - b0[a]);
        if (idle) b[a] += alpha * (raw - b[a]);
      }
    }
  }

  // Every frame of rec in time order, in place (continuing from the current state).
  void apply(Recording& rec) {
    require<ShapeError>(rec.taxels() == taxels_ && rec.axes() == axes_, "DriftTracker::apply: ", rec.source(), " has ",
                        rec.taxels(), " taxels and ", rec.axes(), " axes, the tracker was fitted on ", taxels_,
                        " and ", axes_);
    float* x = rec.mutable_data();
    const std::size_t per = static_cast<std::size_t>(taxels_) * axes_;
    for (int t = 0; t < rec.frames(); ++t) step(x + static_cast<std::size_t>(t) * per);
  }

  // "drift.config" [time_constant, threshold, valid_min, valid_max, N, m], "drift.rest0" [N, m],
  // "drift.rest" [N, m], "drift.noise" [m].
  std::vector<NamedTensor> state() const {
    require<ConfigError>(fitted(), "DriftTracker::state: not fitted");
    return {{"drift.config", {6},
             {static_cast<float>(cfg_.time_constant), static_cast<float>(cfg_.threshold), cfg_.valid_min,
              cfg_.valid_max, static_cast<float>(taxels_), static_cast<float>(axes_)}},
            {"drift.rest0", {taxels_, axes_}, rest0_},
            {"drift.rest", {taxels_, axes_}, rest_},
            {"drift.noise", {axes_}, noise_}};
  }
  static bool in_state(std::span<const NamedTensor> tensors) {
    return std::any_of(tensors.begin(), tensors.end(), [](const NamedTensor& t) { return t.name == "drift.config"; });
  }
  static DriftTracker from_state(std::span<const NamedTensor> tensors) {
    const char* who = "DriftTracker::from_state";
    const auto& c = find_tensor(tensors, "drift.config", who).values;
    require<FileError>(c.size() == 6, who, ": 'drift.config' has ", c.size(), " values, expected 6");
    DriftTrackerConfig cfg;
    cfg.time_constant = c[0];
    cfg.threshold = c[1];
    cfg.valid_min = c[2];
    cfg.valid_max = c[3];
    DriftTracker tr(cfg);
    tr.taxels_ = static_cast<int>(c[4]);
    tr.axes_ = static_cast<int>(c[5]);
    const std::size_t nm = static_cast<std::size_t>(tr.taxels_) * tr.axes_;
    require<FileError>(tr.taxels_ > 0 && tr.axes_ > 0, who, ": ", tr.taxels_, " taxels x ", tr.axes_, " axes");
    tr.rest0_ = find_tensor(tensors, "drift.rest0", who).values;
    tr.rest_ = find_tensor(tensors, "drift.rest", who).values;
    tr.noise_ = find_tensor(tensors, "drift.noise", who).values;
    require<FileError>(tr.rest0_.size() == nm && tr.rest_.size() == nm && tr.noise_.size() == static_cast<std::size_t>(tr.axes_),
                       who, ": drift.rest0/rest/noise have ", tr.rest0_.size(), "/", tr.rest_.size(), "/",
                       tr.noise_.size(), " values, expected ", nm, "/", nm, "/", tr.axes_);
    for (float s : tr.noise_)
      require<FileError>(std::isfinite(s) && s > 0, who, ": drift.noise holds ", s, ", expected > 0");
    return tr;
  }

 private:
  bool valid(const float* xn, int m) const {
    for (int a = 0; a < m; ++a)
      if (!std::isfinite(xn[a]) || xn[a] == 0.0f || xn[a] < cfg_.valid_min || xn[a] > cfg_.valid_max) return false;
    return true;
  }

  DriftTrackerConfig cfg_;
  int taxels_ = 0, axes_ = 0;
  std::vector<float> rest0_, rest_, noise_;
};

}  // namespace tjepa
