#pragma once
// The downstream heads' objective (attentive probe heads, the sequence head, the end-to-end
// baseline), trained early-stopped by the Trainer (train/trainer.hpp):
//   - a seeded split holds out validation_fraction of the training samples (validation_split):
//     whole groups of samples, stratified (when the targets carry SampleGroups: the grasp episodes,
//     stratified by object, so that no episode has samples on both sides); else random samples,
//     or (validation_blocks > 0) contiguous blocks of samples in their order, with
//     validation_gap samples on each side of a block left out of both sets, for samples in
//     recording order whose neighbours are alike or overlap (windows of one grasp, sequences of
//     windows that start a few windows apart)
//   - AdamW on the trainable parts, mini-batches of the fitting samples in a seeded order per
//     epoch; the learning rate rises linearly from lr/10 over warmup_epochs, then stays at lr
//     (a cosine would need the epoch count that early stopping decides)
//   - after each epoch the validation loss; the parameters of the epoch with the lowest one are
//     kept, and the loop stops after `patience` epochs without a new lowest, or at max_epochs
//   - at the end the kept parameters are restored in every part (the optimizer's moments are not)
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/train/objective.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

struct HeadTrainConfig {
  int max_epochs = 100;
  int patience = 10;                 // epochs without a lower validation loss before stopping
  double validation_fraction = 0.2;  // of the training samples, held out for early stopping
  int validation_blocks = 0;         // 0: random samples; k > 0: k contiguous blocks (samples in order)
  int validation_gap = 0;            // samples left out on each side of a validation block
  bool validation_groups = true;     // split by the targets' SampleGroups when they have them
  int batch = 32;
  double lr = 1e-3;
  int warmup_epochs = 1;
  double weight_decay = 0.05;
  double class_weight = 1.0;         // weight of the cross-entropy against the regression MSE
  double clip_grad_norm = 10.0;
  // Heads with classes: stop on the validation top-1 error (the loss breaking ties) instead of the
  // validation loss. The cross-entropy of a few held-out episodes can rise while their accuracy
  // still improves (confident mistakes on an atypical episode). Regression heads ignore it.
  bool stop_on_error = false;
  // folds > 1: the epoch count is chosen by k-fold cross-validation (validation_folds: every
  // sample, or group, validates once), the folds trained side by side and stopped together on the
  // mean of their validation values (patience applies to the mean); the head then trains on every
  // sample for that many epochs (train_head). One small validation split can be unrepresentative
  // and stop a head at its first epochs; the mean of k rarely is.
  int folds = 1;
  std::uint64_t seed = 0;            // head init, split and data order

  void validate() const {
    require<ConfigError>(max_epochs > 0, "HeadTrainConfig: max_epochs = ", max_epochs, ", expected > 0");
    require<ConfigError>(patience > 0, "HeadTrainConfig: patience = ", patience, ", expected > 0");
    require<ConfigError>(validation_fraction > 0 && validation_fraction < 1, "HeadTrainConfig: validation_fraction = ",
                         validation_fraction, ", expected in (0, 1)");
    require<ConfigError>(validation_blocks >= 0, "HeadTrainConfig: validation_blocks = ", validation_blocks,
                         ", expected >= 0");
    require<ConfigError>(validation_gap >= 0, "HeadTrainConfig: validation_gap = ", validation_gap, ", expected >= 0");
    require<ConfigError>(batch > 0, "HeadTrainConfig: batch = ", batch, ", expected > 0");
    require<ConfigError>(lr > 0 && std::isfinite(lr), "HeadTrainConfig: lr = ", lr, ", expected finite > 0");
    require<ConfigError>(warmup_epochs >= 0, "HeadTrainConfig: warmup_epochs = ", warmup_epochs, ", expected >= 0");
    require<ConfigError>(weight_decay >= 0, "HeadTrainConfig: weight_decay = ", weight_decay, ", expected >= 0");
    require<ConfigError>(class_weight >= 0, "HeadTrainConfig: class_weight = ", class_weight, ", expected >= 0");
    require<ConfigError>(clip_grad_norm > 0, "HeadTrainConfig: clip_grad_norm = ", clip_grad_norm, ", expected > 0");
    require<ConfigError>(folds >= 1, "HeadTrainConfig: folds = ", folds, ", expected >= 1");
    require<ConfigError>(folds == 1 || validation_blocks == 0, "HeadTrainConfig: folds = ", folds,
                         " with validation_blocks = ", validation_blocks, "; cross-validation folds are groups or "
                         "random samples, not blocks");
  }
};

// Samples 0..S−1 split into fitting and validation ids: a seeded shuffle, the last
// round(fraction·S) are the validation ids. Both parts are non-empty (fitting at least 2).
struct ValidationSplit {
  std::vector<std::int64_t> fit, validation;
};

// blocks = 0: round(fraction·S) random samples are held out. blocks = k > 0: [0, S) is cut into k
// equal segments and each holds one contiguous validation block (round(fraction·S / k) samples)
// at a seeded offset; the `gap` samples on each side of a block are in neither set (at least 2
// fitting samples remain: S − blocks·(per + 2·gap) >= 2 is required).
namespace detail {
inline constexpr std::uint64_t validation_salt = 0x76616c6964ull;  // "valid"
}

inline ValidationSplit split_for_validation(int S, double fraction, std::uint64_t seed, int blocks = 0, int gap = 0) {
  require<ConfigError>(fraction > 0 && fraction < 1, "split_for_validation: fraction = ", fraction,
                       ", expected in (0, 1)");
  require<ConfigError>(blocks >= 0 && gap >= 0, "split_for_validation: blocks = ", blocks, ", gap = ", gap,
                       ", expected >= 0");
  const int n_val = static_cast<int>(std::lround(fraction * S));
  require<DataError>(n_val >= 1 && S - n_val >= 2, "split_for_validation: ", S, " samples cannot be split ",
                     1 - fraction, " / ", fraction, " into fitting and validation samples");
  if (blocks > 0) {
    const int per = std::max(1, static_cast<int>(std::lround(static_cast<double>(n_val) / blocks)));
    const int segment = S / blocks;
    const std::int64_t used = static_cast<std::int64_t>(blocks) * (per + 2 * static_cast<std::int64_t>(gap));
    require<DataError>(segment >= per && static_cast<std::int64_t>(S) - used >= 2, "split_for_validation: ", S,
                       " samples cannot hold ", blocks, " validation blocks of ", per, " with gaps of ", gap,
                       " and 2 fitting samples");
    Rng rng(seed, detail::validation_salt);
    std::vector<char> role(static_cast<std::size_t>(S), 'f');  // f fit, v validation, g gap
    std::vector<int> starts;
    for (int b = 0; b < blocks; ++b) {
      starts.push_back(b * segment + static_cast<int>(rng.below(static_cast<std::uint64_t>(segment - per + 1))));
      for (int i = starts.back(); i < starts.back() + per; ++i) role[static_cast<std::size_t>(i)] = 'v';
    }
    for (const int start : starts)
      for (int i = std::max(0, start - gap); i < std::min(S, start + per + gap); ++i)
        if (role[static_cast<std::size_t>(i)] == 'f') role[static_cast<std::size_t>(i)] = 'g';
    ValidationSplit s;
    for (int i = 0; i < S; ++i) {
      if (role[static_cast<std::size_t>(i)] == 'f') s.fit.push_back(i);
      if (role[static_cast<std::size_t>(i)] == 'v') s.validation.push_back(i);
    }
    return s;
  }
  std::vector<std::int64_t> order(static_cast<std::size_t>(S));
  for (int i = 0; i < S; ++i) order[static_cast<std::size_t>(i)] = i;
  Rng(seed, detail::validation_salt).shuffle(std::span<std::int64_t>(order));
  ValidationSplit s;
  s.fit.assign(order.begin(), order.end() - n_val);
  s.validation.assign(order.end() - n_val, order.end());
  return s;
}

// Groups of alike samples (the windows of one grasp episode) and their strata (the episode's
// object): a grouped split puts every group whole on one side.
struct SampleGroups {
  std::vector<std::int64_t> group;  // [S] group id per sample; empty: no groups
  std::vector<int> stratum;         // [S] stratum per sample, the same within a group; empty: one stratum
  std::vector<std::int64_t> held;   // groups that are the validation split (a trial table's val
                                    // trials); empty: drawn by split_by_groups

  bool empty() const { return group.empty(); }
  void validate(const char* who, int S) const {
    if (empty()) {
      require<ShapeError>(stratum.empty(), who, ": ", stratum.size(), " strata without groups");
      return;
    }
    require<ShapeError>(group.size() == static_cast<std::size_t>(S) && (stratum.empty() || stratum.size() == group.size()),
                        who, ": ", group.size(), " group ids and ", stratum.size(), " strata for ", S,
                        " samples, expected ", S, " group ids and 0 or ", S, " strata");
  }
};

namespace detail {
// The distinct groups of g in order of first appearance, and each stratum's (in ascending order)
// groups in that order; a group with samples of two strata is an error.
struct GroupStrata {
  std::vector<std::int64_t> ids;
  std::map<int, std::vector<std::int64_t>> by_stratum;
};
inline GroupStrata group_strata(const SampleGroups& g, const char* who) {
  GroupStrata out;
  std::map<std::int64_t, int> stratum_of;
  for (std::size_t i = 0; i < g.group.size(); ++i) {
    const int st = g.stratum.empty() ? 0 : g.stratum[i];
    const auto [at, added] = stratum_of.emplace(g.group[i], st);
    if (added) {
      out.ids.push_back(g.group[i]);
      out.by_stratum[st].push_back(g.group[i]);
    } else {
      require<DataError>(at->second == st, who, ": group ", g.group[i], " has samples of strata ", at->second, " and ",
                         st, ", expected one stratum per group");
    }
  }
  return out;
}
}  // namespace detail

// Validation by groups: each stratum's groups (in order of first appearance) are shuffled with the
// seed and round(fraction·n) of its n groups are held out, at least one where n >= 2 and never
// all; if that holds out nothing (every stratum has one group), one seeded group of all; groups
// given in g.held are held out instead of drawn (fraction and seed unused). Every
// sample of a held-out group is a validation sample, the rest fit (both in sample order).
inline ValidationSplit split_by_groups(const SampleGroups& g, double fraction, std::uint64_t seed) {
  require<ConfigError>(fraction > 0 && fraction < 1, "split_by_groups: fraction = ", fraction, ", expected in (0, 1)");
  require<DataError>(!g.empty(), "split_by_groups: no groups");
  g.validate("split_by_groups", static_cast<int>(g.group.size()));
  detail::GroupStrata gs = detail::group_strata(g, "split_by_groups");
  const std::vector<std::int64_t>& ids = gs.ids;
  require<DataError>(ids.size() >= 2, "split_by_groups: ", ids.size(),
                     " group(s), expected at least 2 (one to fit on, one to validate on)");
  Rng rng(seed, detail::validation_salt);
  std::vector<std::int64_t> held;
  for (auto& [st, mine] : gs.by_stratum) {
    rng.shuffle(std::span<std::int64_t>(mine));
    const auto n = static_cast<long>(mine.size());
    const long k = n < 2 ? 0 : std::clamp(std::lround(fraction * static_cast<double>(n)), 1L, n - 1);
    held.insert(held.end(), mine.begin(), mine.begin() + k);
  }
  if (held.empty()) held.push_back(ids[static_cast<std::size_t>(rng.below(ids.size()))]);
  if (!g.held.empty()) held = g.held;  // given: the draw above is not used
  std::sort(held.begin(), held.end());
  ValidationSplit s;
  for (std::size_t i = 0; i < g.group.size(); ++i)
    (std::binary_search(held.begin(), held.end(), g.group[i]) ? s.validation : s.fit).push_back(static_cast<std::int64_t>(i));
  require<DataError>(s.fit.size() >= 2 && !s.validation.empty(), "split_by_groups: ", s.fit.size(),
                     " fitting and ", s.validation.size(), " validation samples, expected at least 2 and 1");
  return s;
}

// The split a head trains with: by the targets' groups when there are some and
// cfg.validation_groups, else split_for_validation with cfg's fraction, blocks and gap.
inline ValidationSplit validation_split(int S, const HeadTrainConfig& cfg, const SampleGroups& groups) {
  if (cfg.validation_groups && !groups.empty()) {
    require<ConfigError>(cfg.validation_blocks == 0, "validation_split: the targets have groups and validation_blocks = ",
                         cfg.validation_blocks, "; validate by groups (validation_blocks = 0) or by blocks "
                         "(validation_groups = false)");
    groups.validate("validation_split", S);
    return split_by_groups(groups, cfg.validation_fraction, cfg.seed);
  }
  return split_for_validation(S, cfg.validation_fraction, cfg.seed, cfg.validation_blocks, cfg.validation_gap);
}

// k folds for cross-validation: by the targets' groups when there are some and
// cfg.validation_groups (each stratum's groups shuffled with the seed and dealt in turn to the
// folds, the deal running on across strata, so that the folds are balanced per stratum), else the
// samples shuffled and dealt. Every sample validates in exactly one fold; each fold has a
// validation sample and 2 fitting ones.
inline std::vector<ValidationSplit> validation_folds(int S, const HeadTrainConfig& cfg, const SampleGroups& groups) {
  const int k = cfg.folds;
  require<ConfigError>(k >= 2, "validation_folds: folds = ", k, ", expected >= 2");
  std::vector<int> fold_of(static_cast<std::size_t>(S));
  Rng rng(cfg.seed, detail::validation_salt);
  if (cfg.validation_groups && !groups.empty()) {
    groups.validate("validation_folds", S);
    detail::GroupStrata gs = detail::group_strata(groups, "validation_folds");
    require<DataError>(static_cast<int>(gs.ids.size()) >= k, "validation_folds: ", gs.ids.size(), " group(s) for ", k,
                       " folds, expected at least one group a fold");
    std::map<std::int64_t, int> fold_of_group;
    int next = 0;
    for (auto& [st, ids] : gs.by_stratum) {
      rng.shuffle(std::span<std::int64_t>(ids));
      for (const std::int64_t g : ids) fold_of_group[g] = next++ % k;
    }
    for (int i = 0; i < S; ++i) fold_of[static_cast<std::size_t>(i)] = fold_of_group[groups.group[static_cast<std::size_t>(i)]];
  } else {
    require<DataError>(S >= k, "validation_folds: ", S, " samples for ", k, " folds");
    std::vector<std::int64_t> order(static_cast<std::size_t>(S));
    for (int i = 0; i < S; ++i) order[static_cast<std::size_t>(i)] = i;
    rng.shuffle(std::span<std::int64_t>(order));
    for (int j = 0; j < S; ++j) fold_of[static_cast<std::size_t>(order[static_cast<std::size_t>(j)])] = j % k;
  }
  std::vector<ValidationSplit> out(static_cast<std::size_t>(k));
  for (int i = 0; i < S; ++i)
    for (int f = 0; f < k; ++f) (fold_of[static_cast<std::size_t>(i)] == f ? out[static_cast<std::size_t>(f)].validation
                                                                            : out[static_cast<std::size_t>(f)].fit)
                                    .push_back(i);
  for (int f = 0; f < k; ++f)
    require<DataError>(out[static_cast<std::size_t>(f)].fit.size() >= 2 && !out[static_cast<std::size_t>(f)].validation.empty(),
                       "validation_folds: fold ", f, " has ", out[static_cast<std::size_t>(f)].fit.size(), " fitting and ",
                       out[static_cast<std::size_t>(f)].validation.size(), " validation samples, expected at least 2 and 1");
  return out;
}

// The epoch whose mean over the folds' validation curves is lowest, over the epochs every fold
// ran (train_head's folds all run the same epochs); the record of the choice: the mean curve, that
// epoch, its value.
inline EarlyStoppingRecord mean_validation_curve(const std::vector<EarlyStoppingRecord>& folds) {
  require<DataError>(!folds.empty(), "mean_validation_curve: no folds");
  std::size_t L = folds.front().validation_loss.size();
  for (const auto& r : folds) L = std::min(L, r.validation_loss.size());
  require<DataError>(L > 0, "mean_validation_curve: a fold ran no epoch");
  EarlyStoppingRecord m;
  m.validation_loss.assign(L, 0.0);
  for (const auto& r : folds)
    for (std::size_t e = 0; e < L; ++e) m.validation_loss[e] += r.validation_loss[e] / static_cast<double>(folds.size());
  for (std::size_t e = 0; e < L; ++e)
    if (m.validation_loss[e] < m.best_validation) m.best_validation = m.validation_loss[e], m.best_epoch = static_cast<int>(e);
  require<DataError>(m.best_epoch >= 0, "mean_validation_curve: no finite validation loss");
  return m;
}

// A head's training as an early-stopped Objective: `forward(ids)` runs the head (and a trainable
// encoder) forward on a batch of fitting ids and returns its loss, keeping what `backward()`
// needs; `backward()` adds the gradients into the parts; `validate()` returns the validation
// loss of the current parameters. train_head and train_sequence_head build one; so can a head of
// a user's. Single process: its loss may use its batch's statistics (no all_reduce).
template <class T>
class HeadObjective {
 public:
  using value_type = T;
  using stats_type = StepStats;

  HeadObjective(std::vector<PrefixedParams<T>> parts, std::vector<std::int64_t> fit_ids, HeadTrainConfig cfg,
                std::function<double(std::span<const std::int64_t>)> forward_fn, std::function<void()> backward_fn,
                std::function<double()> validate_fn, nlohmann::json metadata = nlohmann::json::object())
      : parts_((cfg.validate(), std::move(parts))), fit_(std::move(fit_ids)), cfg_(cfg),
        forward_(std::move(forward_fn)), backward_(std::move(backward_fn)), validate_(std::move(validate_fn)),
        metadata_(std::move(metadata)), optimizer_(parts_) {
    require<DataError>(!fit_.empty(), "HeadObjective: no fitting samples");
    require<ConfigError>(forward_ && backward_ && validate_, "HeadObjective: forward, backward and validate are "
                         "all needed");
    B_ = std::min(cfg_.batch, static_cast<int>(fit_.size()));
    per_epoch_ = static_cast<std::int64_t>(fit_.size()) / B_;
    warmup_ = static_cast<std::int64_t>(cfg_.warmup_epochs) * per_epoch_;
  }
  HeadObjective(const HeadObjective&) = delete;
  HeadObjective& operator=(const HeadObjective&) = delete;

  const HeadTrainConfig& config() const { return cfg_; }

  // The Objective interface (train/objective.hpp).
  std::int64_t num_samples() const { return static_cast<std::int64_t>(fit_.size()); }
  int batch_size() const { return B_; }
  std::int64_t total_steps() const { return static_cast<std::int64_t>(cfg_.max_epochs) * per_epoch_; }
  std::vector<std::int64_t> epoch_order(std::uint64_t e) const {
    std::vector<std::int64_t> order = fit_;
    Rng(cfg_.seed, epoch_salt + e).shuffle(std::span<std::int64_t>(order));
    return order;
  }
  void zero_grad() {
    for (const auto& p : parts_) p.params->zero_grad();
  }
  double forward(const StepBatch& b) { return loss_ = forward_(b.ids); }
  void backward() { backward_(); }
  StepStats update(std::int64_t k) {
    StepStats st;
    st.step = k;
    st.loss = loss_;
    st.grad_norm = clip_or_stop<T>(parts_, cfg_.clip_grad_norm, loss_, k, "head");
    st.lr = k < warmup_ ? cfg_.lr * (0.1 + 0.9 * static_cast<double>(k + 1) / static_cast<double>(warmup_)) : cfg_.lr;
    st.weight_decay = cfg_.weight_decay;
    optimizer_.step(st.lr, st.weight_decay);
    return st;
  }
  std::vector<PrefixedParams<T>> parts() { return parts_; }
  AdamW<T>& optimizer() { return optimizer_; }
  nlohmann::json metadata() const {
    nlohmann::json m{{"objective", "head"}, {"head", metadata_}};
    m["train"] = {{"max_epochs", cfg_.max_epochs},     {"patience", cfg_.patience},
                  {"validation_fraction", cfg_.validation_fraction}, {"batch", cfg_.batch},
                  {"lr", cfg_.lr},                     {"warmup_epochs", cfg_.warmup_epochs},
                  {"weight_decay", cfg_.weight_decay}, {"class_weight", cfg_.class_weight},
                  {"clip_grad_norm", cfg_.clip_grad_norm}, {"stop_on_error", cfg_.stop_on_error},
                  {"seed", cfg_.seed}};
    return m;
  }
  double validate() { return validate_(); }
  int patience() const { return cfg_.patience; }

 private:
  static constexpr std::uint64_t epoch_salt = 0x65706f6368ull;  // "epoch"
  std::vector<PrefixedParams<T>> parts_;
  std::vector<std::int64_t> fit_;
  HeadTrainConfig cfg_;
  std::function<double(std::span<const std::int64_t>)> forward_;
  std::function<void()> backward_;
  std::function<double()> validate_;
  nlohmann::json metadata_;
  AdamW<T> optimizer_;
  int B_ = 0;
  std::int64_t per_epoch_ = 0, warmup_ = 0;
  double loss_ = 0;
};

// The learning curve of one early-stopped training.
using HeadTrainResult = EarlyStoppingRecord;

}  // namespace tjepa
