#pragma once
// Early stopping, the training loop every downstream head of the evaluation protocol shares
// (attentive probe heads, the sequence head, the end-to-end baseline):
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
#include <limits>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"

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
  }
};

// The learning curve of one early-stopped training.
struct HeadTrainResult {
  std::vector<double> train_loss;       // [epochs run] mean training loss per epoch
  std::vector<double> validation_loss;  // [epochs run] validation loss (the stopping criterion) after each epoch
  int best_epoch = -1;                  // 0-based epoch whose parameters were restored
  double best_validation = std::numeric_limits<double>::infinity();
  int epochs() const { return static_cast<int>(validation_loss.size()); }
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

// Validation by groups: each stratum's groups (in order of first appearance) are shuffled with the
// seed and round(fraction·n) of its n groups are held out, at least one where n >= 2 and never
// all; if that holds out nothing (every stratum has one group), one seeded group of all. Every
// sample of a held-out group is a validation sample, the rest fit (both in sample order).
inline ValidationSplit split_by_groups(const SampleGroups& g, double fraction, std::uint64_t seed) {
  require<ConfigError>(fraction > 0 && fraction < 1, "split_by_groups: fraction = ", fraction, ", expected in (0, 1)");
  require<DataError>(!g.empty(), "split_by_groups: no groups");
  g.validate("split_by_groups", static_cast<int>(g.group.size()));
  std::vector<std::int64_t> ids;  // distinct groups, in order of first appearance
  std::vector<int> strata;        // their strata
  for (std::size_t i = 0; i < g.group.size(); ++i) {
    const int st = g.stratum.empty() ? 0 : g.stratum[i];
    const auto at = std::find(ids.begin(), ids.end(), g.group[i]);
    if (at == ids.end()) {
      ids.push_back(g.group[i]);
      strata.push_back(st);
    } else {
      require<DataError>(strata[static_cast<std::size_t>(at - ids.begin())] == st, "split_by_groups: group ",
                         g.group[i], " has samples of strata ", strata[static_cast<std::size_t>(at - ids.begin())],
                         " and ", st, ", expected one stratum per group");
    }
  }
  require<DataError>(ids.size() >= 2, "split_by_groups: ", ids.size(),
                     " group(s), expected at least 2 (one to fit on, one to validate on)");
  std::vector<int> sorted = strata;
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  Rng rng(seed, detail::validation_salt);
  std::vector<std::int64_t> held;
  for (const int st : sorted) {
    std::vector<std::int64_t> mine;
    for (std::size_t j = 0; j < ids.size(); ++j)
      if (strata[j] == st) mine.push_back(ids[j]);
    rng.shuffle(std::span<std::int64_t>(mine));
    const auto n = static_cast<long>(mine.size());
    const long k = n < 2 ? 0 : std::clamp(std::lround(fraction * static_cast<double>(n)), 1L, n - 1);
    held.insert(held.end(), mine.begin(), mine.begin() + k);
  }
  if (held.empty()) held.push_back(ids[static_cast<std::size_t>(rng.below(ids.size()))]);
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

// The loop at the top of this file. step(ids) runs forward and backward on a batch of fitting
// ids (the parts' gradients are zeroed before) and returns its loss; validate() returns the
// validation loss of the current parameters.
template <class T, class Step, class Validate>
HeadTrainResult train_with_early_stopping(const std::vector<PrefixedParams<T>>& parts,
                                          std::span<const std::int64_t> fit_ids, const HeadTrainConfig& cfg,
                                          Step&& step, Validate&& validate) {
  cfg.validate();
  require<DataError>(!fit_ids.empty(), "train_with_early_stopping: no fitting samples");
  AdamW<T> opt(parts);
  const int S = static_cast<int>(fit_ids.size()), B = std::min(cfg.batch, S);
  const std::int64_t per_epoch = S / B, warmup = static_cast<std::int64_t>(cfg.warmup_epochs) * per_epoch;
  std::vector<AlignedVector<T>> best(parts.size());
  std::vector<std::int64_t> order(fit_ids.begin(), fit_ids.end());
  HeadTrainResult r;
  std::int64_t k = 0;
  for (int e = 0; e < cfg.max_epochs; ++e) {
    std::copy(fit_ids.begin(), fit_ids.end(), order.begin());
    Rng(cfg.seed, 0x65706f6368ull /* "epoch" */ + static_cast<std::uint64_t>(e)).shuffle(std::span<std::int64_t>(order));
    double total = 0;
    for (std::int64_t i = 0; i < per_epoch; ++i, ++k) {
      for (const auto& p : parts) p.params->zero_grad();
      const double loss = step(std::span<const std::int64_t>(order.data() + i * B, static_cast<std::size_t>(B)));
      require<NumericError>(std::isfinite(loss), "train_with_early_stopping: epoch ", e, ", step ", i, ": the loss is ",
                            loss);
      clip_grad_norm<T>(parts, cfg.clip_grad_norm);
      const double lr = k < warmup ? cfg.lr * (0.1 + 0.9 * static_cast<double>(k + 1) / static_cast<double>(warmup))
                                   : cfg.lr;
      opt.step(lr, cfg.weight_decay);
      total += loss;
    }
    const double v = validate();
    require<NumericError>(!std::isnan(v), "train_with_early_stopping: epoch ", e, ": the validation loss is NaN");
    r.train_loss.push_back(total / static_cast<double>(per_epoch));
    r.validation_loss.push_back(v);
    if (v < r.best_validation) {
      r.best_validation = v;
      r.best_epoch = e;
      for (std::size_t j = 0; j < parts.size(); ++j) {
        const auto vals = parts[j].params->values();
        best[j].assign(vals.begin(), vals.end());
      }
    } else if (e - r.best_epoch >= cfg.patience) {
      break;
    }
  }
  if (r.best_epoch >= 0)
    for (std::size_t j = 0; j < parts.size(); ++j) std::ranges::copy(best[j], parts[j].params->values().begin());
  return r;
}

}  // namespace tjepa
