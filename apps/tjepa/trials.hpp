#pragma once
// Trial tables on the command line: `--trials TABLE` (data/trial_table.hpp) read by pretrain
// (its training trials), probe and embed. The split is split_trials' (the table's split column,
// or seeded and grouped by trial with --test-fraction and --split-seed), the same in every command.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include <tjepa/tjepa.hpp>

#include "setup.hpp"

namespace tjepa::cli {

struct TrialOptions {
  std::string table;           // "": no trial table
  double test_fraction = 0.2;  // without a split column: the share of trials (groups) held out
  std::uint64_t seed = 0;      // ... and the seed of that split
};

inline void add_trial_options(CLI::App* app, TrialOptions& t) {
  app->add_option("--trials", t.table, "trial table CSV: file,label[,split][,group], paths relative to the table");
  app->add_option("--split-seed", t.seed, "--trials without a split column: the seed of the split by trial")
      ->capture_default_str();
}

// The recordings of trials `ids`, in the layout's taxel order; trials shorter than tau give no
// window and are reported (how many, which) and left out. Each kept recording's trial is in `trial`.
struct TrialRecordings {
  std::vector<Recording> recordings;
  std::vector<int> trial;  // table index per recording
};

// The trials `ids` that have tau frames, each recording from get(i) (named name(i) in the note on
// the ones left out); source names the trials' origin in the error when none is long enough.
template <class Get, class Name>
TrialRecordings keep_trials(std::span<const int> ids, Get get, Name name, int tau, const std::string& what,
                            const std::string& source, std::ostream& out) {
  TrialRecordings r;
  std::vector<std::string> short_ones;
  for (int i : ids) {
    Recording rec = get(i);
    if (rec.frames() < tau) {
      short_ones.push_back(name(i) + " (" + std::to_string(rec.frames()) + " frames)");
      continue;
    }
    r.recordings.push_back(std::move(rec));
    r.trial.push_back(i);
  }
  if (!short_ones.empty()) {
    out << "note: " << what << ": " << short_ones.size() << " of " << ids.size() << " trials are shorter than tau = "
        << tau << " frames and give no window:";
    for (std::size_t k = 0; k < std::min<std::size_t>(short_ones.size(), 8); ++k) out << (k ? ", " : " ") << short_ones[k];
    if (short_ones.size() > 8) out << ", ...";
    out << "\n";
  }
  require<DataError>(!r.recordings.empty(), source, ": ", what, ": none of its ", ids.size(),
                     " trials has tau = ", tau, " frames");
  return r;
}

inline TrialRecordings read_trials(const TrialTable& t, std::span<const int> ids, const DataFormat& fmt,
                                   const Skin& skin, int tau, const std::string& what, std::ostream& out) {
  auto file = [&](int i) -> const std::filesystem::path& { return t.trials[static_cast<std::size_t>(i)].file; };
  return keep_trials(
      ids, [&](int i) { return in_layout_order(read_recording(file(i), fmt), skin, file(i).string()); },
      [&](int i) { return file(i).filename().string(); }, tau, what, t.source, out);
}

// The trials' names for messages and predictions: their files as the table writes them.
inline std::vector<std::string> trial_names(const TrialTable& t) {
  std::vector<std::string> n;
  const std::filesystem::path dir = std::filesystem::path(t.source).parent_path();
  for (const Trial& r : t.trials) n.push_back(std::filesystem::relative(r.file, dir.empty() ? "." : dir).generic_string());
  return n;
}

inline std::string describe_split(const TrialTable& t, const TrialSplits& s) {
  return std::to_string(s.train.size()) + " training, " + std::to_string(s.val.size()) + " validation and " +
         std::to_string(s.test.size()) + " test trials of " + std::to_string(t.size()) + " (" + s.how + ")";
}

}  // namespace tjepa::cli
