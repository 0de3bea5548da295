#pragma once
// Splits of a trial table by trial: every trial, and every trial of a group, lies whole on one
// side. The table's split column when it has one; else a seeded grouped split (split_by_groups)
// holding out test_fraction of the groups, stratified by label when every label names at least
// two groups and no group holds two labels (classes), not stratified otherwise (regression values,
// groups across labels). pretrain and probe call it with the same table, fraction and seed, so
// pre-training never sees the trials a probe holds out.
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/trial_table.hpp"
#include "tjepa/downstream/early_stopping.hpp"

namespace tjepa {

struct TrialSplits {
  std::vector<int> train, val, test;  // trial indices, in table order
  std::string how;                    // in words, for the log

  // The trials heads and pre-training see: training and validation, in table order.
  std::vector<int> fit() const {
    std::vector<int> f = train;
    f.insert(f.end(), val.begin(), val.end());
    std::sort(f.begin(), f.end());
    return f;
  }
};

inline TrialSplits split_trials(const TrialTable& t, double test_fraction, std::uint64_t seed) {
  TrialSplits s;
  if (t.has_split) {
    for (std::size_t i = 0; i < t.size(); ++i)
      (t.trials[i].split == TrialSplit::train ? s.train : t.trials[i].split == TrialSplit::val ? s.val : s.test)
          .push_back(static_cast<int>(i));
    s.how = "the table's split column";
  } else {
    require<ConfigError>(test_fraction > 0 && test_fraction < 1, "--test-fraction ", test_fraction,
                         ", expected in (0, 1)");
    const std::vector<std::string> keys = t.group_keys();
    SampleGroups g;
    g.group = t.group_ids();
    // Stratify by label when the labels are classes of whole groups.
    bool stratify = !t.labels_are_files();
    std::map<std::string, std::string> label_of_group;
    std::map<std::string, std::vector<std::string>> groups_of_label;
    for (std::size_t i = 0; stratify && i < t.size(); ++i) {
      const auto [at, fresh] = label_of_group.emplace(keys[i], t.trials[i].label);
      if (!fresh && at->second != t.trials[i].label) stratify = false;
      if (fresh) groups_of_label[t.trials[i].label].push_back(keys[i]);
    }
    for (const auto& [label, groups] : groups_of_label) stratify = stratify && groups.size() >= 2;
    if (stratify) {
      std::map<std::string, int> sid;
      for (const Trial& r : t.trials) g.stratum.push_back(sid.emplace(r.label, static_cast<int>(sid.size())).first->second);
    }
    const ValidationSplit v = split_by_groups(g, test_fraction, seed);
    s.train.assign(v.fit.begin(), v.fit.end());
    s.test.assign(v.validation.begin(), v.validation.end());
    s.how = std::string("a seeded split by ") + (t.has_group ? "group" : "trial") + (stratify ? ", stratified by label" : "") +
            " (test fraction " + std::to_string(test_fraction) + ", seed " + std::to_string(seed) + ")";
  }
  require<DataError>(!s.train.empty(), t.source, ": no training trial (", s.how, ")");
  // A group on both sides of the table's split cuts it.
  if (t.has_split && t.has_group) {
    std::map<std::string, std::pair<TrialSplit, std::size_t>> side;
    for (std::size_t i = 0; i < t.size(); ++i) {
      if (t.trials[i].group.empty()) continue;
      const auto [at, fresh] = side.emplace(t.trials[i].group, std::make_pair(t.trials[i].split, i));
      require<DataError>(fresh || at->second.first == t.trials[i].split, t.where(i), ": group '", t.trials[i].group,
                         "' is in split ", trial_split_name(t.trials[i].split), " here and in ",
                         trial_split_name(at->second.first), " at line ", t.trials[at->second.second].line,
                         "; a group lies whole on one side");
    }
  }
  return s;
}

}  // namespace tjepa
