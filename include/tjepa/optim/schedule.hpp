#pragma once
// The training schedules as pure functions of the step, numerically as the reference codebases
// compute them (I-JEPA's src/utils/schedulers.py and Tactile-JEPA's custom_scheduler.py).
//
// Both codebases advance the learning-rate scheduler once before the first optimizer step, so
// optimizer step s (0-based) uses value(s + 1). The weight-decay schedule is advanced the same
// way here (I-JEPA's loop; Tactile-JEPA's trainer applies the optimizer's initial weight decay at
// step 0 and value(s) afterwards, a difference of one step). The EMA momentum after optimizer step
// s is momentum(s): the reference's generator yields i = 0, 1, ... once per step.
//
// Let T be the total number of optimizer steps (epochs × steps per epoch) and W the warm-up
// steps (warm-up epochs × steps per epoch).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string_view>
#include <utility>

#include "tjepa/core/enum_names.hpp"
#include "tjepa/core/error.hpp"

namespace tjepa {

// Learning rate: linear warm-up start_lr → ref_lr over W steps, then cosine ref_lr → final_lr:
//   k < W:  start + k/max(1, W) · (ref − start)
//   k ≥ W:  max(final, final + (ref − final) · ½(1 + cos(π · (k − W)/max(1, T − W))))
struct WarmupCosineLr {
  double start_lr = 1e-5;
  double ref_lr = 1e-4;
  double final_lr = 1e-6;
  std::int64_t warmup_steps = 0;
  std::int64_t total_steps = 1;

  double operator()(std::int64_t k) const {
    if (k < warmup_steps) {
      const double progress = static_cast<double>(k) / static_cast<double>(std::max<std::int64_t>(1, warmup_steps));
      return start_lr + progress * (ref_lr - start_lr);
    }
    const double progress = static_cast<double>(k - warmup_steps) /
                            static_cast<double>(std::max<std::int64_t>(1, total_steps - warmup_steps));
    return std::max(final_lr,
                    final_lr + (ref_lr - final_lr) * 0.5 * (1.0 + std::cos(std::numbers::pi * progress)));
  }
};

// Weight decay: cosine from ref_wd (k = 0) to final_wd (k = T), clamped at final_wd:
//   final + (ref − final) · ½(1 + cos(π · k/T))
struct CosineWeightDecay {
  double ref_wd = 0.04;
  double final_wd = 0.4;
  std::int64_t total_steps = 1;

  double operator()(std::int64_t k) const {
    const double progress = static_cast<double>(k) / static_cast<double>(total_steps);
    const double wd = final_wd + (ref_wd - final_wd) * 0.5 * (1.0 + std::cos(std::numbers::pi * progress));
    return final_wd <= ref_wd ? std::max(final_wd, wd) : std::min(final_wd, wd);
  }
};

// EMA momentum: linear from start (i = 0) to end (i = T):  start + i · (end − start)/T.
struct LinearMomentum {
  double start = 0.994;
  double end = 1.0;
  std::int64_t total_steps = 1;

  double operator()(std::int64_t i) const {
    return start + static_cast<double>(i) * (end - start) / static_cast<double>(total_steps);
  }
};

// Which weight decay optimizer step s uses. The Tactile-JEPA reference code steps its weight-decay
// scheduler after each update, so step s ≥ 1 uses wd(s) and step 0 the optimizer's constructor
// value (TrainingSchedule::wd_initial; its config: 0.05, while wd(0) = 0.04); I-JEPA's loop steps
// it before each update, so step s uses wd(s + 1).
enum class WeightDecayTiming { reference, ijepa };

// The names (JSON, text).
constexpr auto json_names(WeightDecayTiming) {
  return std::array{std::pair<std::string_view, WeightDecayTiming>{"reference", WeightDecayTiming::reference},
                    std::pair<std::string_view, WeightDecayTiming>{"ijepa", WeightDecayTiming::ijepa}};
}
inline const char* to_string(WeightDecayTiming t) { return enum_name(t); }

// The three schedules of a run, indexed by the optimizer step s = 0, 1, ..., T − 1.
struct TrainingSchedule {
  WarmupCosineLr lr;
  CosineWeightDecay wd;
  LinearMomentum momentum;
  WeightDecayTiming wd_timing = WeightDecayTiming::reference;
  // Step 0's weight decay under the reference timing: the optimizer's constructor value; < 0: wd(0).
  double wd_initial = -1;

  // The paper's schedule (Sec. IV-D, training details) for a run of `epochs` × `steps_per_epoch`
  // steps with `warmup_epochs` of warm-up.
  static TrainingSchedule reference(std::int64_t epochs, std::int64_t steps_per_epoch,
                                    std::int64_t warmup_epochs) {
    require<ConfigError>(epochs > 0, "TrainingSchedule: epochs = ", epochs, ", expected > 0");
    require<ConfigError>(steps_per_epoch > 0, "TrainingSchedule: steps_per_epoch = ", steps_per_epoch,
                         ", expected > 0");
    require<ConfigError>(warmup_epochs >= 0 && warmup_epochs <= epochs, "TrainingSchedule: warmup_epochs = ",
                         warmup_epochs, ", expected in [0, epochs = ", epochs, "]");
    const std::int64_t total = epochs * steps_per_epoch;
    TrainingSchedule s;
    s.lr.warmup_steps = warmup_epochs * steps_per_epoch;
    s.lr.total_steps = total;
    s.wd.total_steps = total;
    s.momentum.total_steps = total;
    return s;
  }

  std::int64_t total_steps() const { return lr.total_steps; }
  // The value optimizer step s uses: the learning rate's scheduler was advanced first; the weight
  // decay's by wd_timing.
  double lr_at(std::int64_t s) const { return lr(s + 1); }
  double wd_at(std::int64_t s) const {
    if (wd_timing == WeightDecayTiming::ijepa) return wd(s + 1);
    return s == 0 && wd_initial >= 0 ? wd_initial : wd(s);
  }
  // The EMA momentum applied after optimizer step s.
  double momentum_at(std::int64_t s) const { return momentum(s); }

  void validate() const {
    require<ConfigError>(lr.total_steps > 0, "TrainingSchedule: lr.total_steps = ", lr.total_steps,
                         ", expected > 0");
    require<ConfigError>(lr.warmup_steps >= 0 && lr.warmup_steps <= lr.total_steps,
                         "TrainingSchedule: lr.warmup_steps = ", lr.warmup_steps, ", expected in [0, ",
                         lr.total_steps, "]");
    require<ConfigError>(wd.total_steps > 0, "TrainingSchedule: wd.total_steps = ", wd.total_steps,
                         ", expected > 0");
    require<ConfigError>(momentum.total_steps > 0, "TrainingSchedule: momentum.total_steps = ",
                         momentum.total_steps, ", expected > 0");
    require<ConfigError>(momentum.start >= 0.0 && momentum.start <= 1.0 && momentum.end >= 0.0 &&
                             momentum.end <= 1.0,
                         "TrainingSchedule: momentum from ", momentum.start, " to ", momentum.end,
                         ", expected both in [0, 1]");
  }
};

}  // namespace tjepa
