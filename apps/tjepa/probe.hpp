#pragma once
// tjepa probe: probes on a frozen checkpoint. With the simulated skin's labels (or a [T, 4]
// label file), force and indenter against a constant and a random encoder; with --task, the
// user's own labels (label_probe.hpp).
//
// Every command writes its files through OutputFiles: on an error nothing it wrote is left.
#include <CLI/CLI.hpp>

#include <array>
#include <chrono>
#include <iostream>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <tuple>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/downstream/head_file.hpp>
#include <tjepa/downstream/probe_labels.hpp>
#include <tjepa/eval.hpp>

#include "label_probe.hpp"
#include "output.hpp"
#include "options.hpp"
#include "setup.hpp"
#include "trials.hpp"

namespace tjepa::cli {

// ---------------------------------------------------------------------------------------------
// Probes (shared by `probe` and `demo`)

// Held-out metrics of a force + indenter probe.
struct ProbeMetrics {
  std::array<double, force_axes> force_rmse{};  // N, per axis (shear u, shear v, normal)
  double indenter_accuracy = 0;
  double majority_accuracy = 0;                 // chance level: the most frequent class
  int windows = 0;
};

struct ProbeRow {
  std::string name;
  std::vector<ProbeMetrics> runs;  // one probe, or the repeats averaged into the row
  std::vector<double> lr;          // each run's learning rate (none for the constant)
  double seconds = 0;
  std::string flag;                // why the row says little ("" = nothing to say)
  std::shared_ptr<const ProbeHead<float>> head;  // a frozen probe's first head (what --save writes)
  std::vector<float> center_shift;               // with --center-tokens: the shift added to the embeddings
};

// Repeated probes as one row: other probe seeds, and for a random encoder other initializations.
// One probe on 600 labelled windows moves by as much as the differences between encoders; the
// table compares means. A repeat whose head diverged is left out (and the row says so), unless
// all did.
inline ProbeRow average_rows(std::string name, const std::vector<ProbeRow>& repeats) {
  require<ConfigError>(!repeats.empty(), "average_rows: no probes");
  ProbeRow row{std::move(name), {}, {}, 0, {}, repeats.front().head, repeats.front().center_shift};
  std::vector<const ProbeRow*> kept;
  for (const ProbeRow& r : repeats)
    if (r.flag.find("diverged") == std::string::npos) kept.push_back(&r);
  if (kept.size() < repeats.size())
    row.flag = std::to_string(repeats.size() - kept.size()) + " of " + std::to_string(repeats.size()) + " repeats diverged" +
               (kept.empty() ? "" : ", left out of the mean");
  if (kept.empty())
    for (const ProbeRow& r : repeats) kept.push_back(&r);
  for (const ProbeRow* r : kept) {
    row.runs.insert(row.runs.end(), r->runs.begin(), r->runs.end());
    row.lr.insert(row.lr.end(), r->lr.begin(), r->lr.end());
  }
  for (const ProbeRow& r : repeats) row.seconds += r.seconds;
  return row;
}

// The rows as a score table (downstream/score_table.hpp): RMSE per force axis and their mean,
// indenter top-1, a sample per repeat ("mean ± sd"), the learning rates beside.
inline ScoreTable probe_score_table(const std::vector<ProbeRow>& rows) {
  ScoreTable t;
  t.row_header = "encoder";
  t.sample_name = "repeats";
  t.columns = {"probe lr"};
  auto rmse = [](std::string key, std::string name, bool primary) {
    return ScoreMetric{std::move(key), std::move(name), "N", false, primary, 1, "%.3f", "%.3f"};
  };
  t.metrics = {rmse("force_rmse_u", "RMSE u", false), rmse("force_rmse_v", "RMSE v", false),
               rmse("force_rmse_n", "RMSE n", false), rmse("force_rmse", "RMSE avg", true),
               ScoreMetric{"indenter_accuracy", "indenter top-1", "%", true, true, 100, "%.1f", "%.1f"}};
  for (const ProbeRow& r : rows) {
    ScoreRow& row = t.row(r.name);
    for (const ProbeMetrics& m : r.runs)
      row.runs.push_back({{m.force_rmse[0], m.force_rmse[1], m.force_rmse[2],
                           (m.force_rmse[0] + m.force_rmse[1] + m.force_rmse[2]) / 3, m.indenter_accuracy}});
    std::string lrs;
    for (double lr : r.lr) {
      char buf[16];
      std::snprintf(buf, sizeof buf, "%.0e", lr);
      if (!lrs.empty()) lrs += ',';
      lrs += buf;
    }
    row.cells = {lrs.empty() ? "-" : lrs};
    row.note = r.flag;
    row.info = {{"lr", r.lr}, {"seconds", r.seconds}};
    if (!r.runs.empty())
      row.info.update({{"windows", r.runs.front().windows}, {"majority_accuracy", r.runs.front().majority_accuracy}});
  }
  return t;
}

// The mean-force / majority-class row: what a probe must beat to have learned anything.
inline ProbeRow constant_baseline(const ProbeLabels& train, const ProbeLabels& test, int classes) {
  const std::vector<double> y =
      ConstantBaseline::fit(train.force, force_axes, train.indenter, classes).outputs(static_cast<std::size_t>(test.size()));
  ProbeMetrics m;
  const auto rm = rmse_per_column(y.data(), static_cast<std::size_t>(force_axes + classes), test.force.data(),
                                  test.size(), force_axes);
  std::copy(rm.begin(), rm.end(), m.force_rmse.begin());
  m.indenter_accuracy = accuracy(y.data() + force_axes, static_cast<std::size_t>(force_axes + classes),
                                 test.indenter.data(), test.size(), classes);
  m.majority_accuracy = majority_accuracy(test.indenter.data(), test.size(), classes);
  m.windows = test.size();
  return ProbeRow{"constant (train mean / majority)", {m}, {}, 0, {}, nullptr, {}};
}

// A probe head (3 force outputs + the indenter logits) trained early-stopped on the frozen
// encoder's embeddings of the training windows (train_head: a validation split of them decides
// the epoch), scored on the held-out windows. repeats > 1: that many heads (seeds cfg.seed,
// cfg.seed + 1, ...) on the same embeddings, averaged (average_rows). center_tokens: each token's
// resting embedding is removed first (center_token_embeddings, fitted on the training windows).
inline ProbeRow frozen_probe(const std::string& name, const ParamSet<float>& params, const Tokenizer& tok,
                             const Encoder& enc, const WindowSource& train_src, const ProbeLabels& train,
                             const WindowSource& test_src, const ProbeLabels& test, const HeadTrainConfig& cfg,
                             int heads, bool quiet, int repeats = 1, bool center_tokens = false) {
  require<ConfigError>(repeats >= 1, "frozen_probe: repeats = ", repeats, ", expected >= 1");
  ProgressLine embed_progress("  embed " + name, train.size() + test.size(), quiet);
  const auto t0 = std::chrono::steady_clock::now();
  auto emb_train = embed_windows(params, tok, enc, train_src, train.window, 32, [&](std::int64_t d, std::int64_t) {
    embed_progress.update(d, d, "");
  });
  auto emb_test = embed_windows(params, tok, enc, test_src, test.window, 32, [&](std::int64_t d, std::int64_t) {
    embed_progress.update(train.size() + d, train.size() + d, "");
  });
  const double embed_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<float> shift;
  if (center_tokens) {
    const std::span<float> test_span(emb_test);
    shift = center_token_embeddings<float>(emb_train, std::span<const std::span<float>>(&test_span, 1), enc.num_tokens(),
                                           enc.dim());
  }
  FrozenFeatures<float> ftrain(std::move(emb_train), enc.num_tokens(), enc.dim());
  FrozenFeatures<float> ftest(std::move(emb_test), enc.num_tokens(), enc.dim());
  const HeadTargets train_targets = head_targets(train, num_indenter_shapes);
  const HeadTargets test_targets = head_targets(test, num_indenter_shapes);
  std::vector<ProbeRow> runs;
  for (int r = 0; r < repeats; ++r) {
    const auto t1 = std::chrono::steady_clock::now();
    HeadTrainConfig c = cfg;
    c.seed = cfg.seed + static_cast<std::uint64_t>(r);
    const std::string label = repeats > 1 ? name + " #" + std::to_string(r + 1) : name;
    ProbeHead<float> head(enc.dim(), heads, force_axes, num_indenter_shapes, c.seed);
    const HeadTrainResult fit = train_head(head, ftrain, train_targets, c);
    if (!quiet)
      std::cerr << "  probe " << label << ": best epoch " << fit.best_epoch + 1 << " of " << fit.epochs()
                << " (validation loss " << fit.best_validation << ")\n";
    const HeadMetrics hm = evaluate_head(head, ftest, test_targets);
    ProbeRow row{label, {ProbeMetrics{}}, {c.lr}, 0, {}, nullptr, {}};
    if (!std::isfinite(fit.best_validation)) row.flag = "diverged (validation loss not finite)";
    ProbeMetrics& m = row.runs.front();
    std::copy_n(hm.rmse.begin(), force_axes, m.force_rmse.begin());
    m.indenter_accuracy = hm.accuracy;
    m.majority_accuracy = hm.majority_accuracy;
    m.windows = hm.samples;
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count() +
                  (r == 0 ? embed_seconds : 0.0);
    if (r == 0) {
      row.head = std::make_shared<const ProbeHead<float>>(std::move(head));
      row.center_shift = shift;
    }
    runs.push_back(std::move(row));
  }
  if (repeats == 1) return runs.front();
  return average_rows(name, runs);
}

// ---------------------------------------------------------------------------------------------
// tjepa probe

// The probes' training unless told otherwise: 60 epochs of batch 32 at rate 1e-3, early-stopped.
inline HeadTrainConfig default_probe_config() { return {.max_epochs = 60, .batch = 32, .lr = 1e-3}; }

struct ProbeOptions {
  std::string checkpoint;
  std::string encoder = "target";          // target | context
  // Labelled data: files, or simulated (the layout's simulated skin) when empty.
  // With --task, several files each: one recording each, paired with its labels in order.
  std::vector<std::string> train_data, train_labels, test_data, test_labels;
  DataFormat format;                  // how recordings are read (axes, columns, header, NaN)
  std::uint64_t simulate_seed = 1;
  int simulate_train_frames = 20000, simulate_test_frames = 10000;  // the demo's (8000 + 4000 gave noisy results)
  // Frames in contact for a window to count; -1: 5 with the simulator's labels, 0 (off) with --task,
  // where a frame is in contact when a taxel's preprocessed reading has a norm over its axes above
  // contact_threshold (in the preprocessing's units: standard deviations after standardization).
  int min_contact = -1;
  double contact_threshold = 3.0;
  int max_windows = 0;                     // per split, 0 = all
  HeadTrainConfig probe = default_probe_config();  // early-stopped on a validation split
  int repeats = 1;                         // probes with seeds seed, seed + 1, ... averaged
  bool center_tokens = false;              // center_token_embeddings before the probe
  std::string task;                        // "": force + indenter labels; regression | classification: the user's
  std::string label_columns;               // the label files' columns (text), "a:b,..."
  std::string data, labels;                // --task: one recording and its labels, split in time instead of
  double test_fraction = 0.2;              //   train/test files: the last test_fraction of the frames is held out
  int trial_column = -1;                   // --data: the label file's column of each frame's trial id (-1: none)
  TrialOptions trials;                     // --trials TABLE: labelled trials (trials.hpp)
  std::vector<double> lr_grid{3e-4, 1e-3, 3e-3};  // --task: the attentive probe's rates, chosen on validation
  // --task: the probe's poolings, chosen on validation with the rate (auto: both; or one of them).
  std::vector<PoolingKind> poolings{PoolingKind::attentive, PoolingKind::taxel};
  std::string predictions;                 // --task: per-window and per-trial predictions CSV ("" = none)
  std::string out;                         // results JSON ("" = none)
  std::string save;                        // --task: the checkpoint encoder's probe head as a file ("" = none)
  bool force = false;
  bool quiet = false;
};

// The epochs of cfg raised to at least 10000 steps, and its patience to 3000, on `windows` training
// samples. The default epochs suit thousands of windows; on a few hundred an epoch is a handful of
// steps, and an attentive probe can sit at the uniform guess for a thousand steps before it starts
// to learn (iCub, 336 windows: at 3000 steps and 1000 of patience 3 seeds read 92.0 ± 9.8 %, at
// 13500 and 4500 96.0 ± 1.8 %, the best epoch of the first still the last).
inline HeadTrainConfig with_step_floor(HeadTrainConfig cfg, std::size_t windows) {
  const double fit = (1.0 - cfg.validation_fraction) * static_cast<double>(windows);
  const int per_epoch = std::max(1, static_cast<int>(std::ceil(fit / cfg.batch)));
  cfg.max_epochs = std::max(cfg.max_epochs, (10000 + per_epoch - 1) / per_epoch);
  cfg.patience = std::max(cfg.patience, (3000 + per_epoch - 1) / per_epoch);
  return cfg;
}

// A seeded subset of at most `limit` windows of w (0: all), kept in order.
inline void limit_windows(WindowLabels& w, int limit, std::uint64_t seed) {
  if (limit <= 0 || w.window.size() <= static_cast<std::size_t>(limit)) return;
  std::vector<std::int64_t> all(w.window.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::int64_t>(i);
  const std::vector<std::int64_t> pick = seeded_subset(std::move(all), limit, seed);
  w = select_windows(w, std::vector<std::size_t>(pick.begin(), pick.end()));
}

// The labelled windows of trials: each window takes its trial's label (class or value) or, with
// per-frame label files, its last frame's; grouped by the trial's group for validation splits,
// stratified by class where no group holds two classes; the table's val trials are the
// validation split. label_frames: the per-frame labels of each recording of src, or none.
inline WindowLabels trial_window_labels(const TrialTable& t, const TrialRecordings& trials, const WindowSource& src,
                                        LabelTask task, std::span<const int> class_of_trial,
                                        std::span<const float> value_of_trial, std::span<const Recording> label_frames,
                                        std::span<const int> class_ids) {
  WindowLabels w;
  if (!label_frames.empty()) {
    w = window_labels(src, label_frames, task, class_ids, t.source);
  } else {
    w.targets.regression = task == LabelTask::regression ? 1 : 0;
    w.targets.classes = task == LabelTask::classification ? static_cast<int>(class_ids.size()) : 0;
    for (std::int64_t i = 0; i < src.size(); ++i) {
      const auto trial = static_cast<std::size_t>(trials.trial[static_cast<std::size_t>(src.recording_of(i))]);
      w.window.push_back(i);
      if (task == LabelTask::classification) w.targets.label.push_back(class_of_trial[trial]);
      else w.targets.value.push_back(value_of_trial[trial]);
    }
  }
  const std::vector<std::int64_t> gid = t.group_ids();
  std::map<std::int64_t, int> class_of_group;
  bool stratify = task == LabelTask::classification;
  for (std::size_t s = 0; s < w.window.size(); ++s) {
    const int trial = trials.trial[static_cast<std::size_t>(src.recording_of(w.window[s]))];
    w.trial.push_back(trial);
    const std::int64_t g = gid[static_cast<std::size_t>(trial)];
    w.targets.groups.group.push_back(g);
    if (stratify) {
      const auto [at, fresh] = class_of_group.emplace(g, w.targets.label[s]);
      stratify = fresh || at->second == w.targets.label[s];
    }
  }
  if (stratify) w.targets.groups.stratum = w.targets.label;
  for (std::size_t i = 0; i < t.size(); ++i)
    if (t.trials[i].split == TrialSplit::val) {
      const std::int64_t g = gid[i];
      if (std::find(w.targets.groups.held.begin(), w.targets.groups.held.end(), g) == w.targets.groups.held.end())
        w.targets.groups.held.push_back(g);
    }
  return w;
}

// tjepa probe --task: the user's own labels (label_probe.hpp), from a trial table, one recording
// split in time, or a training and a held-out recording.
inline int run_label_probe(const ProbeOptions& o, std::ostream& out) {
  const LabelTask task = parse_label_task(o.task);
  const bool trials = !o.trials.table.empty();
  const bool one_file = !o.data.empty() || !o.labels.empty();
  const bool two_files = !o.train_data.empty() || !o.test_data.empty() || !o.train_labels.empty() || !o.test_labels.empty();
  require<ConfigError>(trials + one_file + two_files == 1,
                       "--task needs one of: --trials TABLE; --data and --labels (split in time by --test-fraction); "
                       "or --train-data, --train-labels, --test-data and --test-labels");
  require<ConfigError>(!one_file || (!o.data.empty() && !o.labels.empty()), "--data needs --labels and --labels --data");
  require<ConfigError>(o.trial_column < 0 || one_file, "--trial-column is for one recording of concatenated trials "
                       "(--data and --labels); a trial table (--trials) or separate files are trials already");
  require<ConfigError>(!two_files || (!o.train_data.empty() && !o.train_labels.empty() && !o.test_data.empty() &&
                                      !o.test_labels.empty()),
                       "--train-data needs --train-labels, --test-data and --test-labels");
  require<ConfigError>(o.test_fraction > 0 && o.test_fraction < 1, "--test-fraction ", o.test_fraction,
                       ", expected in (0, 1)");
  if (!o.predictions.empty()) OutputFiles::check_new(o.predictions, o.force);
  TrainedModel m = load_trained_model(o.checkpoint);
  const JepaModel<float>& model = *m.model;
  const Skin skin = load_skin(SkinSpec::of(m.config));
  const int tau = m.config.data.tau;
  std::vector<Recording> train_recs, test_recs, train_frames, test_frames;  // frames: per-frame labels per recording
  std::string train_labels, test_labels;  // the label sources, for messages
  std::optional<TrialTable> table;
  TrialRecordings train_trials, test_trials;
  std::vector<int> class_of_trial, class_ids;
  std::vector<float> value_of_trial;
  std::vector<std::string> class_names, names;
  if (trials) {
    table = read_trial_table(o.trials.table);
    const TrialSplits sp = split_trials(*table, o.test_fraction, o.trials.seed);
    out << "trials: " << describe_split(*table, sp) << "\n";
    require<DataError>(!sp.test.empty(), o.trials.table, ": no test trial to hold out (", sp.how, ")");
    const std::vector<int> fit = sp.fit();
    train_trials = read_trials(*table, fit, o.format, skin, tau, "training trials", out);
    test_trials = read_trials(*table, sp.test, o.format, skin, tau, "test trials", out);
    train_recs = train_trials.recordings, test_recs = test_trials.recordings;
    names = trial_names(*table);
    train_labels = test_labels = o.trials.table;
    if (table->labels_are_files()) {
      for (auto [recs, frames, ids] : {std::tuple{&train_trials, &train_frames, 0}, std::tuple{&test_trials, &test_frames, 1}})
        for (std::size_t k = 0; k < recs->recordings.size(); ++k)
          frames->push_back(read_label_frames(table->trials[static_cast<std::size_t>(recs->trial[k])].label_file,
                                              o.label_columns, recs->recordings[k].frames()));
    } else if (task == LabelTask::classification) {
      const TrialClasses c = trial_classes(*table);
      class_names = c.names, class_of_trial = c.of_trial;
      for (std::size_t k = 0; k < c.names.size(); ++k) class_ids.push_back(static_cast<int>(k));
    } else {
      value_of_trial = trial_values(*table);
    }
  } else if (one_file && o.trial_column >= 0) {
    // One recording of concatenated trials, a label column holding each frame's trial id: each
    // trial is a recording of its own, and the split is by trial as for a trial table.
    require<ConfigError>(!o.label_columns.empty(), "--trial-column ", o.trial_column,
                         " needs --label-columns: which of ", o.labels, "'s columns are the labels");
    require<ConfigError>(!std::ranges::count(parse_column_ranges(o.label_columns), o.trial_column), "--trial-column ",
                         o.trial_column, " is one of --label-columns '", o.label_columns, "'");
    const Recording rec = in_layout_order(read_recording(o.data, o.format), skin, o.data);
    const Recording lab = read_label_frames(o.labels, o.label_columns, rec.frames());
    const Recording ids = read_label_frames(o.labels, std::to_string(o.trial_column), rec.frames());
    const std::vector<FrameTrial> segments = frame_trials(ids.values(), o.labels + " (--trial-column " +
                                                                            std::to_string(o.trial_column) + ")");
    table.emplace();
    table->source = o.labels;
    for (const FrameTrial& f : segments) {
      Trial t;
      t.file = o.data;
      t.line = f.begin;
      // The split stratifies by the trial's label: with classes, its frames' majority class.
      std::map<float, int> votes;
      for (int k = f.begin; k < f.end && task == LabelTask::classification; ++k) ++votes[lab(k, 0, 0)];
      t.label = votes.empty() ? "frames " + std::to_string(f.begin)
                              : std::to_string(std::ranges::max_element(votes, {}, [](auto& v) { return v.second; })->first);
      table->trials.push_back(std::move(t));
      char id[32];
      std::snprintf(id, sizeof id, "%g", f.id);
      names.push_back(std::filesystem::path(o.data).filename().string() + " trial " + id);
    }
    const TrialSplits sp = split_trials(*table, o.test_fraction, o.trials.seed);
    out << "trials: " << segments.size() << " in " << o.data << " by --trial-column " << o.trial_column << ": "
        << describe_split(*table, sp) << "\n";
    require<DataError>(!sp.test.empty(), o.labels, ": no test trial to hold out (", sp.how, ")");
    const std::vector<int> fit = sp.fit();
    for (auto [which, r, frames, what] : {std::tuple{std::span<const int>(fit), &train_trials, &train_frames, "training trials"},
                                          std::tuple{std::span<const int>(sp.test), &test_trials, &test_frames, "test trials"}}) {
      auto segment = [&](int i) -> const FrameTrial& { return segments[static_cast<std::size_t>(i)]; };
      *r = keep_trials(
          which, [&](int i) { return rec.frames_range(segment(i).begin, segment(i).end); },
          [&](int i) { return names[static_cast<std::size_t>(i)]; }, tau, what, o.labels, out);
      for (int i : r->trial) frames->push_back(lab.frames_range(segment(i).begin, segment(i).end));
    }
    train_recs = train_trials.recordings, test_recs = test_trials.recordings;
    train_labels = test_labels = o.labels;
  } else if (one_file) {
    // One session: the first frames train, the last test_fraction are held out (no window crosses).
    const Recording rec = in_layout_order(read_recording(o.data, o.format), skin, o.data);
    const Recording lab = read_label_frames(o.labels, o.label_columns, rec.frames());
    const int cut = static_cast<int>(std::lround(rec.frames() * (1.0 - o.test_fraction)));
    require<DataError>(cut >= 2 * tau && rec.frames() - cut >= 2 * tau, o.data, ": ", rec.frames(),
                       " frames split at ", cut, " leave fewer than two windows of ", tau, " frames on a side");
    train_recs = {rec.frames_range(0, cut)}, test_recs = {rec.frames_range(cut, rec.frames())};
    train_frames = {lab.frames_range(0, cut)}, test_frames = {lab.frames_range(cut, rec.frames())};
    train_labels = test_labels = o.labels;
    out << "note: one recording split in time at frame " << cut << "; for separate trials (grasps, strokes) give a "
        << "trial table (--trials), which keeps each trial whole on one side\n";
  } else {
    // Training and held-out recordings, each its own (no window crosses two), with its labels.
    for (auto [data, labels, recs, frames, flag] :
         {std::tuple{&o.train_data, &o.train_labels, &train_recs, &train_frames, "--train"},
          std::tuple{&o.test_data, &o.test_labels, &test_recs, &test_frames, "--test"}}) {
      require<ConfigError>(data->size() == labels->size(), flag, "-data has ", data->size(), " file(s) and ", flag,
                           "-labels ", labels->size(), ": one label file per recording, in the same order");
      for (std::size_t k = 0; k < data->size(); ++k) {
        recs->push_back(in_layout_order(read_recording((*data)[k], o.format), skin, (*data)[k]));
        frames->push_back(read_label_frames((*labels)[k], o.label_columns, recs->back().frames()));
      }
    }
    auto join = [](const std::vector<std::string>& v) {
      std::string s;
      for (const std::string& f : v) s += (s.empty() ? "" : ", ") + f;
      return s;
    };
    train_labels = join(o.train_labels), test_labels = join(o.test_labels);
  }
  for (const auto* recs : {&train_recs, &test_recs})
    for (const Recording& r : *recs) require_fits(r, m);
  if (!train_frames.empty()) {
    for (const Recording& f : test_frames)
      require<ShapeError>(f.taxels() == train_frames[0].taxels(), f.source(), ": ", f.taxels(), " label columns, ",
                          train_frames[0].source(), " has ", train_frames[0].taxels());
    if (task == LabelTask::classification) {
      std::vector<Recording> all = train_frames;
      all.insert(all.end(), test_frames.begin(), test_frames.end());
      class_ids = frame_class_ids(all);
      for (int c : class_ids) class_names.push_back(std::to_string(c));
    }
  }
  require<DataError>(task == LabelTask::regression || class_ids.size() >= 2, train_labels, " and ", test_labels, ": ",
                     class_ids.size(), " class(es), expected at least two");
  for (Recording& r : train_recs) m.track(r);
  for (Recording& r : test_recs) m.track(r);
  const WindowSource train_src(train_recs, window_spec(tau, o.format), {}, m.pre);
  const WindowSource test_src(test_recs, window_spec(tau, o.format), {}, m.pre);
  note_dropped(train_src, "training data", out);
  note_dropped(test_src, "held-out data", out);
  WindowLabels train, test;
  if (table) {
    train = trial_window_labels(*table, train_trials, train_src, task, class_of_trial, value_of_trial, train_frames, class_ids);
    test = trial_window_labels(*table, test_trials, test_src, task, class_of_trial, value_of_trial, test_frames, class_ids);
    test.targets.groups = {};
  } else {
    train = window_labels(train_src, train_frames, task, class_ids, train_labels);
    test = window_labels(test_src, test_frames, task, class_ids, test_labels);
  }
  if (o.min_contact > 0) {
    const auto before = std::make_pair(train.window.size(), test.window.size());
    keep_contact_windows(train, train_src, o.min_contact, o.contact_threshold, train_labels);
    keep_contact_windows(test, test_src, o.min_contact, o.contact_threshold, test_labels);
    out << "contact filter: windows with at least " << o.min_contact << " frames in which a taxel's reading exceeds "
        << o.contact_threshold << ": " << train.window.size() << " of " << before.first << " training, "
        << test.window.size() << " of " << before.second << " held-out\n";
  }
  if (o.max_windows > 0) {
    limit_windows(train, o.max_windows, o.probe.seed);
    limit_windows(test, o.max_windows, o.probe.seed + 1);
    out << "--max-windows " << o.max_windows << ": " << train.window.size() << " training and " << test.window.size()
        << " held-out windows kept (a seeded subset)\n";
  }
  if (task == LabelTask::classification) {
    // The classes with their windows; a held-out class that training never shows counts as wrong.
    const int C = static_cast<int>(class_ids.size());
    std::vector<int> n_train(static_cast<std::size_t>(C), 0), n_test(static_cast<std::size_t>(C), 0);
    for (int c : train.targets.label) ++n_train[static_cast<std::size_t>(c)];
    for (int c : test.targets.label) ++n_test[static_cast<std::size_t>(c)];
    out << "classes (training / held-out windows):";
    for (int c = 0; c < C; ++c)
      out << (c ? ", " : " ") << class_names[static_cast<std::size_t>(c)] << " " << n_train[static_cast<std::size_t>(c)]
          << "/" << n_test[static_cast<std::size_t>(c)];
    out << "\n";
    for (int c = 0; c < C; ++c)
      if (n_train[static_cast<std::size_t>(c)] == 0 && n_test[static_cast<std::size_t>(c)] > 0)
        out << "warning: class " << class_names[static_cast<std::size_t>(c)] << " has " << n_test[static_cast<std::size_t>(c)]
            << " held-out windows and no training window: no head can predict it, they count as wrong\n";
  }
  out << "probe for " << o.task << " labels on " << o.checkpoint << ": " << train.window.size() << " training and "
      << test.window.size() << " held-out windows\n";
  HeadTrainConfig cfg = o.probe;
  const HeadTrainConfig defaults = default_probe_config();
  if (cfg.max_epochs == defaults.max_epochs && cfg.patience == defaults.patience) {
    cfg = with_step_floor(cfg, train.window.size());
    if (cfg.max_epochs != defaults.max_epochs)
      out << "note: heads train up to " << cfg.max_epochs << " epochs with a patience of " << cfg.patience
          << " (at least 10000 and 3000 steps; --epochs and --patience set them)\n";
  }
  LabelProbeSettings set;
  set.lr_grid = o.lr_grid, set.poolings = o.poolings, set.center_tokens = o.center_tokens, set.repeats = o.repeats,
  set.quiet = o.quiet;
  const std::vector<LabelProbeRow> rows = label_probe_rows(
      m, o.encoder == "target" ? model.target : model.context, o.encoder, train_src, train, test_src, test, skin,
      cfg, set);
  const int n_train_trials = table ? static_cast<int>(train_trials.recordings.size()) : 0;
  const ScoreTable results = label_score_table(rows, test, static_cast<int>(train.window.size()), n_train_trials);
  out << results.markdown();
  OutputFiles files;
  if (!o.out.empty()) {
    const nlohmann::json scores = results.to_json();
    nlohmann::json j{{"checkpoint", o.checkpoint},
                     {"task", o.task},
                     {"train_windows", train.window.size()},
                     {"repeats", o.repeats},
                     {"test_windows", test.window.size()},
                     {"probe", {{"lr_grid", o.lr_grid.empty() ? std::vector<double>{cfg.lr} : o.lr_grid},
                                {"max_epochs", cfg.max_epochs}, {"patience", cfg.patience}, {"batch", cfg.batch},
                                {"validation_fraction", cfg.validation_fraction}, {"center_tokens", o.center_tokens},
                                {"poolings", [&] {
                                   std::vector<std::string> v;
                                   for (PoolingKind k : o.poolings) v.push_back(to_string(k));
                                   return v;
                                 }()}}},
                     {"metrics", scores["metrics"]},
                     {"results", scores["rows"]},
                     {"comparisons", scores["comparisons"]}};
    if (!class_names.empty()) j["classes"] = class_names;
    if (table) {
      j["trials"] = {{"table", trials ? o.trials.table : o.labels}, {"train", train_trials.recordings.size()},
                     {"test", test_trials.recordings.size()}};
      std::vector<std::string> held;
      for (int i : test_trials.trial) held.push_back(names[static_cast<std::size_t>(i)]);
      j["trials"]["test_files"] = held;
    }
    write_file_atomic(files.add(o.out), j.dump(2));
  }
  if (!o.predictions.empty()) {
    if (names.empty())
      for (std::size_t r = 0; r < test_recs.size(); ++r) names.push_back(std::to_string(r));
    write_file_atomic(files.add(o.predictions), label_predictions_csv(rows, test_src, test, class_names, names));
  }
  if (!o.save.empty()) {
    // The checkpoint encoder's probe (the last row): the pooling and rate chosen, its first repeat.
    const LabelProbeRow& probe = rows.back();
    require<DataError>(probe.head != nullptr, "--save: ", probe.name, " has no head to save (", probe.flag, ")");
    HeadInfo info;
    info.task = o.task;
    info.class_names = task == LabelTask::classification ? class_names : std::vector<std::string>{};
    info.tau = tau;
    info.stride = train_src.spec().step();
    info.encoder = encoder_fingerprint(m, o.encoder == "target" ? model.target : model.context);
    info.encoder_file = o.checkpoint;
    info.center_shift = probe.center_shift;
    save_head(files.add(o.save), *probe.head, info);
    out << "wrote " << o.save << ": " << probe.name << ", encoder " << info.encoder << "\n";
  }
  files.commit();
  return 0;
}

inline int run_probe(const ProbeOptions& o, std::ostream& out) {
  require<ConfigError>(!o.checkpoint.empty(), "--checkpoint is required");
  require<ConfigError>(o.encoder == "target" || o.encoder == "context", "--encoder '", o.encoder,
                       "', expected target or context");
  if (!o.out.empty()) OutputFiles::check_new(o.out, o.force);
  if (!o.save.empty()) OutputFiles::check_new(o.save, o.force);
  if (!o.task.empty()) return run_label_probe(o, out);
  require<ConfigError>(o.trials.table.empty() && o.predictions.empty() && o.data.empty() && o.labels.empty() &&
                           o.trial_column < 0 && o.poolings.size() == 2,
                       "--trials, --predictions, --data, --labels, --trial-column and --probe-pooling are for your own labels: give --task regression ",
                       "or classification");
  TrainedModel m = load_trained_model(o.checkpoint);
  JepaModel<float>& model = *m.model;
  Recording train_rec, test_rec;
  std::vector<FrameLabel> train_lab, test_lab;
  const Skin skin = load_skin(SkinSpec::of(m.config));
  if (o.train_data.empty()) {
    require<ConfigError>(o.test_data.empty(), "--test-data needs --train-data too");
    // The sensor the checkpoint was pre-trained on (seeded by its run's seed: the same offsets and
    // gains, so its baseline applies), with new events from --simulate-seed.
    SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, m.config.seed);
    sim.reseed(o.simulate_seed);
    auto a = sim.record(o.simulate_train_frames);
    auto b = sim.record(o.simulate_test_frames);
    train_rec = std::move(a.recording);
    train_lab = std::move(a.labels);
    test_rec = std::move(b.recording);
    test_lab = std::move(b.labels);
  } else {
    require<ConfigError>(!o.train_labels.empty() && !o.test_data.empty() && !o.test_labels.empty(),
                         "--train-data needs --train-labels, --test-data and --test-labels");
    for (const auto* v : {&o.train_data, &o.train_labels, &o.test_data, &o.test_labels})
      require<ConfigError>(v->size() == 1, "the force and indenter probe takes one file for each of --train-data, "
                           "--train-labels, --test-data and --test-labels, got ", v->size(), " for one of them; several "
                           "recordings are for --task");
    train_rec = in_layout_order(read_recording(o.train_data[0], o.format), skin, o.train_data[0]);
    train_lab = read_frame_labels(o.train_labels[0], train_rec.frames());
    test_rec = in_layout_order(read_recording(o.test_data[0], o.format), skin, o.test_data[0]);
    test_lab = read_frame_labels(o.test_labels[0], test_rec.frames());
  }
  for (const Recording* r : {&train_rec, &test_rec}) require_fits(*r, m);
  m.track(train_rec);
  m.track(test_rec);
  const WindowSource train_src(train_rec, window_spec(m.config.data.tau, o.format), train_lab, m.pre);
  const WindowSource test_src(test_rec, window_spec(m.config.data.tau, o.format), test_lab, m.pre);
  note_dropped(train_src, "training recording", out);
  note_dropped(test_src, "held-out recording", out);
  const ProbeLabels train = ProbeLabels::from_source(
      train_src, labelled_windows(train_src, o.min_contact < 0 ? 5 : o.min_contact, o.max_windows, o.probe.seed));
  const ProbeLabels test = ProbeLabels::from_source(
      test_src, labelled_windows(test_src, o.min_contact < 0 ? 5 : o.min_contact, o.max_windows, o.probe.seed + 1));
  for (int c : train.indenter)
    require<DataError>(c < num_indenter_shapes, "indenter class ", c, " in the training labels, expected < ",
                       num_indenter_shapes);
  out << "probe on the frozen " << o.encoder << " encoder of " << o.checkpoint << ": " << train.size()
      << " training windows, " << test.size() << " held-out windows\n";
  const ParamSet<float>& ps = o.encoder == "target" ? model.target : model.context;
  std::vector<ProbeRow> rows{constant_baseline(train, test, num_indenter_shapes),
                             frozen_probe(o.encoder + " encoder (frozen)", ps, model.tokenizer, model.encoder,
                                          train_src, train, test_src, test, o.probe, m.config.model.heads, o.quiet,
                                          o.repeats, o.center_tokens)};
  for (const auto& [labels, which] : {std::pair{&train, "training"}, std::pair{&test, "held-out"}})
    if (distinct_classes(labels->indenter) < 2)
      for (ProbeRow& r : rows)
        r.flag += std::string(r.flag.empty() ? "" : "; ") + "the " + which + " windows hold one indenter class";
  const ScoreTable table = probe_score_table(rows);
  out << table.markdown();
  OutputFiles files;
  if (!o.out.empty()) {
    const nlohmann::json scores = table.to_json();
    write_file_atomic(files.add(o.out), nlohmann::json{{"checkpoint", o.checkpoint}, {"metrics", scores["metrics"]},
                                                       {"results", scores["rows"]}, {"comparisons", scores["comparisons"]}}
                                            .dump(2));
  }
  if (!o.save.empty()) {
    // The checkpoint encoder's probe (force u, v, normal in N, then the indenter's logits), its first repeat.
    const ProbeRow& probe = rows.back();
    require<DataError>(probe.head != nullptr, "--save: ", probe.name, " has no head to save");
    HeadInfo info;
    info.task = "force and indenter";
    info.output_names = {"force_u", "force_v", "force_normal"};
    for (int c = 0; c < num_indenter_shapes; ++c) info.class_names.push_back(indenter_name(c));
    info.tau = m.config.data.tau;
    info.stride = train_src.spec().step();
    info.encoder = encoder_fingerprint(m, ps);
    info.encoder_file = o.checkpoint;
    info.center_shift = probe.center_shift;
    save_head(files.add(o.save), *probe.head, info);
    out << "wrote " << o.save << ": " << probe.name << ", encoder " << info.encoder << "\n";
  }
  files.commit();
  return 0;
}

// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_probe_command(CLI::App& app, ProbeOptions& o) {
  CLI::App* sub = app.add_subcommand("probe", "Train and evaluate probes on a frozen checkpoint: force and indenter, or your own labels (--task)");
  sub->add_option("--checkpoint", o.checkpoint, "checkpoint of `tjepa pretrain`")->required();
  sub->add_option("--encoder", o.encoder, "target | context")->capture_default_str();
  sub->add_option("--train-data", o.train_data, "labelled training recording(s) (default: simulated; several with --task)");
  sub->add_option("--train-labels", o.train_labels,
                    "labels per frame: [T, 4] .npy (force u, v, normal, indenter class or -1), or with --task your own");
  sub->add_option("--task", o.task, "your own labels: regression (any number of columns) | classification (class ids)");
  sub->add_option("--label-columns", o.label_columns, "text label files: the label columns, e.g. 1:3");
  sub->add_option("--data", o.data, "with --task: one recording, split in time (--test-fraction)");
  sub->add_option("--labels", o.labels, "with --task and --data: its labels, one row per frame");
  sub->add_option("--test-fraction", o.test_fraction, "with --data: the last fraction of frames held out; with --trials and no split column: the share of trials")
      ->capture_default_str();
  sub->add_option("--trial-column", o.trial_column,
                  "with --task, --data and --labels: the label file's column (0-based) of each frame's trial id; trials "
                  "are split whole (--test-fraction of them, --split-seed) instead of in time")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--test-data", o.test_data, "held-out recording(s)");
  sub->add_option("--test-labels", o.test_labels, "held-out labels, one file per --test-data recording");
  sub->add_option("--simulate-seed", o.simulate_seed, "seed of the simulated labelled data")->capture_default_str();
  sub->add_option("--simulate-train-frames", o.simulate_train_frames, "simulated labelled frames to train on")
      ->capture_default_str()->check(CLI::Range(1, 1 << 30));
  sub->add_option("--simulate-test-frames", o.simulate_test_frames, "simulated held-out frames")
      ->capture_default_str()->check(CLI::Range(1, 1 << 30));
  sub->add_option("--min-contact", o.min_contact,
                    "frames in contact for a window to count (default: 5 with simulated labels, off with --task)");
  sub->add_option("--contact-threshold", o.contact_threshold,
                    "--task: a frame is in contact when a taxel's preprocessed reading exceeds this norm")
      ->capture_default_str();
  sub->add_option("--max-windows", o.max_windows, "labelled windows per split (0: all)")->capture_default_str();
  sub->add_option("--epochs", o.probe.max_epochs, "probe epoch limit (early stopping)")->capture_default_str();
  sub->add_option("--patience", o.probe.patience, "epochs without a better validation loss before stopping")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  sub->add_option("--batch", o.probe.batch, "probe batch")->capture_default_str();
  sub->add_option("--repeats", o.repeats, "probes with seeds seed, seed+1, ... averaged (mean ± sd)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  sub->add_option_function<double>(
         "--lr", [&o](double lr) { o.probe.lr = lr, o.lr_grid = {lr}; },
         "probe learning rate (--task: instead of choosing one of --lr-grid on the validation split)")
      ->default_str(std::to_string(o.probe.lr));
  sub->add_option("--lr-grid", o.lr_grid, "--task: the attentive probe's learning rates (1e-3,3e-3 or 1e-3 3e-3), the best on validation kept")
      ->delimiter(',')
      ->capture_default_str();
  sub->add_option("--predictions", o.predictions, "--task: write one row per held-out window and per trial here (CSV)");
  add_trial_options(sub, o.trials);
  sub->add_option_function<std::string>(
      "--probe-pooling",
      [&o](const std::string& v) {
        o.poolings = v == "auto" ? std::vector<PoolingKind>{PoolingKind::attentive, PoolingKind::taxel}
                                 : std::vector<PoolingKind>{parse_pooling(v)};
      },
      "--task: the probe's pooling of a window: auto (default: attentive and taxel, the better on validation), "
      "attentive (the paper's) or taxel (per-taxel read-out)")
      ->check(CLI::IsMember({"auto", "attentive", "taxel"}));
  add_data_format(sub, o.format);
  sub->add_option("--out", o.out, "write the results as JSON here");
  sub->add_option("--save", o.save,
                  "write the checkpoint encoder's probe head here (safetensors: its first repeat; --task: the pooling and "
                  "rate chosen), with task, class or output names, tau, stride and the encoder's fingerprint, for tjepa run");
  sub->add_flag("--force", o.force, "overwrite --out");
  sub->add_flag("--quiet", o.quiet, "no progress line");
  sub->add_flag("--center-tokens", o.center_tokens,
                  "the probe reads each token's embedding minus its training mean (center_token_embeddings)");
  return sub;
}

}  // namespace tjepa::cli
