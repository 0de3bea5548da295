#pragma once
// `tjepa probe --task regression|classification`: probes for the user's own labels (motor
// positions, object ids, anything per frame or per trial), on the user's recordings.
//
// Labels: one per trial of a trial table (data/trial_table.hpp), or one row per frame of a
// recording (a .npy [T] or [T, K], or text with a header detected and --label-columns), a
// window's label then being its last frame's. Regression: K outputs, every value finite.
// Classification: class names or ids; a negative id marks a frame without a class and its windows
// are left out; the classes are the ids (names) present, so a stray id adds one class, listed.
// Rows, each scored on the held-out windows, and on the held-out trials when there are trials
// (a trial's windows' outputs averaged: class scores or logits, regression values):
//   constant                 the training mean / the majority class;
//   ridge on raw windows     closed-form ridge on pad sums and taxel means (downstream/ridge.hpp);
//   <encoder>, linear        ridge on the frozen embeddings' group means, λ chosen on validation;
//   <encoder>, probe (P)     a probe head (ProbeHead) on the frozen embeddings, trained with early
//                            stopping, its pooling P (attentive, the paper's, or taxel) and learning
//                            rate chosen on the validation split (one pooling given: "<encoder>,
//                            attentive" or "<encoder>, taxel probe");
// for a random initialization of the checkpoint's architecture and for the checkpoint's encoder.
// Validation splits are drawn by trial (by the targets' SampleGroups) when there are trials. With
// repeats, one head per seed, averaged with their standard deviation. Optionally only windows in
// contact count (keep_contact_windows; off by default). Flagged: a head whose best validation loss
// is not 2 % below the constant's on the same split (it learned nothing), a row no better than the
// constant on the held-out windows, a split whose windows hold one class, a probe that reads more
// than 2 points (2 % RMSE) less than the linear read-out of the same embeddings, and a head still
// improving at the epoch limit.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <memory>
#include <ostream>
#include <set>
#include <span>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/downstream/ridge.hpp>
#include <tjepa/downstream/score_table.hpp>
#include <tjepa/tjepa.hpp>

#include "output.hpp"
#include "setup.hpp"

namespace tjepa::cli {

enum class LabelTask { regression, classification };

inline LabelTask parse_label_task(const std::string& s) {
  if (s == "regression") return LabelTask::regression;
  require<ConfigError>(s == "classification", "--task '", s, "', expected regression or classification");
  return LabelTask::classification;
}

// Frame labels [T, K] from a file, checked against the recording's frame count.
inline Recording read_label_frames(const std::filesystem::path& path, const std::string& columns, int frames) {
  DataFormat f;
  f.axes = 1;
  f.columns = columns;
  Recording r;
  if (path.extension() == ".npy" && path_exists(path) && read_npy_header(path).shape.size() == 1) {
    NpyArray a = read_npy(path, NpyReadOptions{.require_finite = true, .map = false});  // [T]: one column
    r = Recording(static_cast<int>(a.shape[0]), 1, 1, AlignedVector<float>(a.values.values().begin(), a.values.values().end()),
                  a.source);
    require<ConfigError>(columns.empty() || columns == "0" || columns == "0:1", path.string(),
                         ": --label-columns '", columns, "' for a [T] label array, which has one column");
  } else {
    r = read_recording(path, f);
  }
  if (path.extension() == ".npy" && r.axes() > 1) {  // [T, K, m] read as is: flatten to [T, K·m]
    r = Recording(r.frames(), r.taxels() * r.axes(), 1, AlignedVector<float>(r.values().begin(), r.values().end()),
                  r.source());
  }
  require<ShapeError>(r.frames() == frames, path.string(), ": labels for ", r.frames(), " frames, the recording has ",
                      frames, " (one label row per frame)");
  return r;
}

// The labelled windows of a source: ids, and their targets for a head.
struct WindowLabels {
  std::vector<std::int64_t> window;
  HeadTargets targets;
  std::vector<int> trial;  // [S] the trial of each window (an index into the trial names); empty: none
};

// Labels from per-frame label rows: window i of src (of recording `frames` for all windows, or with
// per_recording, frames[recording_of(i)]) takes its last frame's. class_ids: the classes' ids in
// order (classification); a window's class is the position of its id there.
inline WindowLabels window_labels(const WindowSource& src, std::span<const Recording> per_recording, LabelTask task,
                                  std::span<const int> class_ids, const std::string& file) {
  WindowLabels w;
  require<ShapeError>(per_recording.size() == src.recordings().size(), file, ": labels for ", per_recording.size(),
                      " recordings, the source has ", src.recordings().size());
  const int K = per_recording[0].taxels();
  const int classes = static_cast<int>(class_ids.size());
  if (task == LabelTask::classification)
    require<ShapeError>(K == 1, per_recording[0].source(), ": ", K,
                        " label columns, a classification takes one (the class id; choose it with --label-columns)");
  w.targets.regression = task == LabelTask::regression ? K : 0;
  w.targets.classes = task == LabelTask::classification ? classes : 0;
  for (std::int64_t i = 0; i < src.size(); ++i) {
    const int last = src.start_of(i) + src.length() - 1;
    const Recording& frames = per_recording[static_cast<std::size_t>(src.recording_of(i))];
    if (task == LabelTask::classification) {
      const float c = frames(last, 0, 0);
      require<DataError>(c == std::floor(c), frames.source(), ": frame ", last, " has class ", c,
                         ", expected an integer id");
      if (c < 0) continue;
      const auto at = std::find(class_ids.begin(), class_ids.end(), static_cast<int>(c));
      require<DataError>(at != class_ids.end(), frames.source(), ": frame ", last, " has class ", c,
                         ", not one of the classes");
      w.window.push_back(i);
      w.targets.label.push_back(static_cast<int>(at - class_ids.begin()));
    } else {
      w.window.push_back(i);
      for (int k = 0; k < K; ++k) w.targets.value.push_back(frames(last, k, 0));
    }
  }
  require<DataError>(w.window.size() >= 4, file, ": ", w.window.size(), " labelled windows, expected at least 4");
  return w;
}

// The class ids of per-frame class labels (non-negative, integer), sorted.
inline std::vector<int> frame_class_ids(std::span<const Recording> label_frames) {
  std::vector<int> ids;
  for (const Recording& f : label_frames)
    for (int t = 0; t < f.frames(); ++t) {
      const float c = f(t, 0, 0);
      require<DataError>(c == std::floor(c) && std::abs(c) < 1e9f, f.source(), ": frame ", t, " has class ", c,
                         ", expected an integer id");
      if (c >= 0 && std::find(ids.begin(), ids.end(), static_cast<int>(c)) == ids.end()) ids.push_back(static_cast<int>(c));
    }
  std::sort(ids.begin(), ids.end());
  return ids;
}

// Keeps the windows of w with at least min_frames frames in which some taxel's preprocessed
// reading (what the encoder sees) has a norm over its axes above threshold.
// The windows kept[0], kept[1], ... of w (indices into w), with their targets, trials and groups.
inline WindowLabels select_windows(const WindowLabels& w, std::span<const std::size_t> kept) {
  WindowLabels k;
  const int R = w.targets.regression;
  k.targets.regression = R, k.targets.classes = w.targets.classes, k.targets.groups.held = w.targets.groups.held;
  for (std::size_t u : kept) {
    k.window.push_back(w.window[u]);
    if (!w.trial.empty()) k.trial.push_back(w.trial[u]);
    for (int a = 0; a < R; ++a) k.targets.value.push_back(w.targets.value[u * R + a]);
    if (w.targets.classes > 0) k.targets.label.push_back(w.targets.label[u]);
    if (!w.targets.groups.empty()) {
      k.targets.groups.group.push_back(w.targets.groups.group[u]);
      if (!w.targets.groups.stratum.empty()) k.targets.groups.stratum.push_back(w.targets.groups.stratum[u]);
    }
  }
  return k;
}

inline void keep_contact_windows(WindowLabels& w, const WindowSource& src, int min_frames, double threshold,
                                 const std::string& file) {
  std::vector<std::size_t> kept;
  WindowBatch wb;
  const std::size_t chunk = 256;
  for (std::size_t first = 0; first < w.window.size(); first += chunk) {
    const std::size_t n = std::min(chunk, w.window.size() - first);
    src.gather(std::span<const std::int64_t>(w.window.data() + first, n), wb);
    const int N = wb.taxels, L = wb.length, m = wb.axes;
    for (std::size_t b = 0; b < n; ++b) {
      int frames = 0;
      for (int j = 0; j < L; ++j) {
        bool contact = false;
        for (int t = 0; t < N && !contact; ++t) {
          const float* x = wb.x.data() + b * wb.per_window() + (static_cast<std::size_t>(t) * L + j) * m;
          double sq = 0;
          for (int a = 0; a < m; ++a) sq += double(x[a]) * x[a];
          contact = sq > threshold * threshold;
        }
        frames += contact;
      }
      if (frames < min_frames) continue;
      const std::size_t i = first + b;
      kept.push_back(i);
    }
  }
  require<DataError>(kept.size() >= 4, file, ": ", kept.size(), " of ", w.window.size(),
                     " labelled windows have ", min_frames, " frames in contact (a taxel above ", threshold,
                     "), expected at least 4: lower --min-contact or --contact-threshold");
  w = select_windows(w, kept);
}

// What a row scores: RMSE per regression output and top-1 (NaN without classes).
struct LabelScores {
  std::vector<double> rmse;
  double accuracy = std::numeric_limits<double>::quiet_NaN();
  // The score repeats are averaged and compared by: top-1 with classes, else the mean RMSE.
  double primary() const {
    if (std::isfinite(accuracy) || rmse.empty()) return accuracy;
    double s = 0;
    for (double e : rmse) s += e / static_cast<double>(rmse.size());
    return s;
  }
};

struct LabelProbeRow {
  std::string name;
  LabelScores window, trial;        // held-out windows; held-out trials (empty without trials)
  // The scores of each run: one, or with repeats > 1 each repeat that did not diverge (window and
  // trial above are then their mean); none when every repeat diverged.
  struct Run {
    LabelScores window, trial;
  };
  std::vector<Run> runs;
  double validation = std::numeric_limits<double>::quiet_NaN();  // heads: best validation loss
  int best_epoch = -1, epochs = 0;
  double lr = std::numeric_limits<double>::quiet_NaN();      // probes: the learning rate used
  std::string pooling;                                       // probes: the pooling used (attentive, taxel)
  struct Tried {
    std::string pooling;
    double lr, validation;
  };
  std::vector<Tried> tried;                                  // the poolings and rates tried, their validation loss
  double lambda = std::numeric_limits<double>::quiet_NaN();  // ridge rows: the λ chosen on validation
  std::string flag;                 // why the row says little ("" = nothing to say)
  double seconds = 0;
  std::vector<double> outputs;      // [S, R + C] of the first repeat: values and class scores (predictions)
  std::shared_ptr<const ProbeHead<float>> head;  // probes: the first repeat's head (what --save writes)
  std::vector<float> center_shift;  // probes with centred tokens: the shift added to the embeddings
};

inline double constant_validation_loss(const HeadTargets& t, const HeadTrainConfig& cfg) {
  const ValidationSplit split = validation_split(t.size(), cfg, t.groups);
  const int R = t.regression, C = t.classes;
  const ColumnScaler s = R > 0 ? ColumnScaler::fit(t.value, R, split.fit) : ColumnScaler{};
  std::vector<double> p(static_cast<std::size_t>(C), 1.0);  // add-one counts
  if (C > 0)
    for (std::int64_t i : split.fit) p[static_cast<std::size_t>(t.label[static_cast<std::size_t>(i)])] += 1;
  const int B = static_cast<int>(split.validation.size()), out = R + C;
  std::vector<double> y(static_cast<std::size_t>(B) * out, 0.0), z(static_cast<std::size_t>(B) * R);
  std::vector<int> lab(static_cast<std::size_t>(C > 0 ? B : 0));
  for (int b = 0; b < B; ++b) {
    const auto i = static_cast<std::size_t>(split.validation[static_cast<std::size_t>(b)]);
    for (int a = 0; a < R; ++a) z[static_cast<std::size_t>(b) * R + a] = s.standardize(t.value[i * R + a], a);
    for (int c = 0; c < C; ++c) y[static_cast<std::size_t>(b) * out + R + c] = std::log(p[static_cast<std::size_t>(c)]);
    if (C > 0) lab[static_cast<std::size_t>(b)] = t.label[i];
  }
  const auto [f, ce] = detail::head_loss<double, double>(y.data(), static_cast<std::size_t>(out), z.data(), lab.data(), B,
                                                          R, C, cfg.class_weight, nullptr);
  return f + cfg.class_weight * ce;
}

inline std::string head_flag(double validation, double constant) {
  if (!std::isfinite(validation)) return "diverged (validation loss not finite)";
  if (validation > 0.98 * constant)
    return "no better than the constant on validation (loss " + std::to_string(validation) + " against " +
           std::to_string(constant) + ")";
  return "";
}

// The flag of any row against the constant row on the held-out windows.
inline std::string held_out_flag(const LabelProbeRow& row, const LabelProbeRow& constant) {
  if (std::isfinite(row.window.accuracy) && row.window.accuracy <= constant.window.accuracy)
    return "held-out top-1 no better than the majority class";
  if (!row.window.rmse.empty() && !(row.window.primary() < constant.window.primary()))
    return "held-out RMSE no better than the constant";
  return "";
}

// The flag of an attentive probe that reads less than the linear read-out of the same embeddings:
// more than 2 points of top-1 or 2 % of RMSE, at window or trial level.
inline std::string under_read_flag(const LabelProbeRow& attentive, const LabelProbeRow& linear) {
  std::string s;
  auto check = [&](const LabelScores& a, const LabelScores& l, const char* level) {
    if (std::isfinite(a.accuracy) && std::isfinite(l.accuracy) && a.accuracy < l.accuracy - 0.02) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "reads %.1f points less than the linear read-out per %s", 100 * (l.accuracy - a.accuracy),
                    level);
      s += (s.empty() ? "" : "; ") + std::string(buf);
    } else if (!std::isfinite(a.accuracy) && !a.rmse.empty() && !l.rmse.empty() && a.primary() > 1.02 * l.primary()) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "RMSE %.0f %% above the linear read-out per %s", 100 * (a.primary() / l.primary() - 1),
                    level);
      s += (s.empty() ? "" : "; ") + std::string(buf);
    }
  };
  check(attentive.window, linear.window, "window");
  check(attentive.trial, linear.trial, "trial");
  return s.empty() || attentive.name.find(", attentive") == std::string::npos ? s : s + " (--probe-pooling auto or taxel reads each taxel)";
}

// The flag of a head that ran to the epoch limit with its best validation loss in the last 5 % of
// its epochs: it was still improving when training stopped. Not when that loss is already under
// 1 % of the constant's (constant): a head that fits validation to 0.001 keeps shaving digits.
inline std::string epoch_limit_flag(const LabelProbeRow& head, const HeadTrainConfig& cfg, double constant) {
  if (head.best_epoch < 0 || head.epochs < cfg.max_epochs || head.best_epoch + 1 <= head.epochs - std::max(1, head.epochs / 20) ||
      !(head.validation >= 0.01 * constant))
    return "";
  return "still improving at the epoch limit (" + std::to_string(head.epochs) + " epochs): raise --epochs";
}

inline int distinct_classes(std::span<const int> labels) {
  std::vector<int> seen;
  for (int c : labels)
    if (std::find(seen.begin(), seen.end(), c) == seen.end()) seen.push_back(c);
  return static_cast<int>(seen.size());
}

// Scores of outputs [S, R + C] (values, then class scores) against the targets of S samples.
inline LabelScores score_outputs(const std::vector<double>& y, const HeadTargets& t) {
  const int S = t.size(), R = t.regression, C = t.classes, out = R + C;
  LabelScores s;
  if (R > 0) s.rmse = rmse_per_column(y.data(), static_cast<std::size_t>(out), t.value.data(), S, R);
  if (C > 0) {
    int right = 0;
    for (int i = 0; i < S; ++i) {
      const double* r = y.data() + static_cast<std::size_t>(i) * out + R;
      right += static_cast<int>(std::max_element(r, r + C) - r) == t.label[static_cast<std::size_t>(i)];
    }
    s.accuracy = static_cast<double>(right) / S;
  }
  return s;
}

// The trials' view of windows: per trial (in order of first appearance), the mean of its windows'
// outputs, and its target: the mean value, the majority class of its windows.
struct TrialView {
  std::vector<int> trial;      // [trials] trial ids
  std::vector<double> outputs; // [trials, R + C]
  HeadTargets targets;
};

inline TrialView trial_view(const std::vector<double>& y, const HeadTargets& t, std::span<const int> trial_of) {
  const int S = t.size(), R = t.regression, C = t.classes, out = R + C;
  require<ShapeError>(trial_of.size() == static_cast<std::size_t>(S), "trial_view: ", trial_of.size(),
                      " trial ids for ", S, " windows");
  TrialView v;
  v.targets.regression = R, v.targets.classes = C;
  std::vector<int> count;
  std::vector<std::vector<int>> votes;
  std::vector<double> sum_value;
  for (int i = 0; i < S; ++i) {
    const int id = trial_of[static_cast<std::size_t>(i)];
    auto at = std::find(v.trial.begin(), v.trial.end(), id);
    if (at == v.trial.end()) {
      v.trial.push_back(id);
      v.outputs.resize(v.outputs.size() + static_cast<std::size_t>(out), 0.0);
      sum_value.resize(sum_value.size() + static_cast<std::size_t>(R), 0.0);
      count.push_back(0);
      votes.emplace_back(static_cast<std::size_t>(C), 0);
      at = v.trial.end() - 1;
    }
    const auto k = static_cast<std::size_t>(at - v.trial.begin());
    ++count[k];
    for (int a = 0; a < out; ++a) v.outputs[k * out + a] += y[static_cast<std::size_t>(i) * out + a];
    for (int a = 0; a < R; ++a) sum_value[k * R + a] += t.value[static_cast<std::size_t>(i) * R + a];
    if (C > 0) ++votes[k][static_cast<std::size_t>(t.label[static_cast<std::size_t>(i)])];
  }
  for (std::size_t k = 0; k < v.trial.size(); ++k) {
    for (int a = 0; a < out; ++a) v.outputs[k * out + a] /= count[k];
    for (int a = 0; a < R; ++a) v.targets.value.push_back(static_cast<float>(sum_value[k * R + a] / count[k]));
    if (C > 0) v.targets.label.push_back(static_cast<int>(std::max_element(votes[k].begin(), votes[k].end()) - votes[k].begin()));
  }
  return v;
}

// Window- and trial-level scores of a row's outputs.
inline void score_row(LabelProbeRow& row, std::vector<double> outputs, const WindowLabels& test) {
  row.window = score_outputs(outputs, test.targets);
  if (!test.trial.empty()) {
    const TrialView v = trial_view(outputs, test.targets, test.trial);
    row.trial = score_outputs(v.outputs, v.targets);
  }
  row.runs = {{row.window, row.trial}};
  row.outputs = std::move(outputs);
}

// The mean of repeated rows (all scored on the same held-out windows), each repeat's scores kept
// in runs (the table takes their spread).
inline LabelProbeRow mean_of_runs(std::vector<LabelProbeRow> runs) {
  LabelProbeRow row = runs.front();
  if (runs.size() < 2) return row;
  const double k = static_cast<double>(runs.size());
  auto mean = [&](auto get) {
    LabelScores m = get(runs.front());
    for (double& e : m.rmse) e = 0;
    if (std::isfinite(m.accuracy)) m.accuracy = 0;
    for (const auto& r : runs) {
      const LabelScores& s = get(r);
      for (std::size_t a = 0; a < m.rmse.size(); ++a) m.rmse[a] += s.rmse[a] / k;
      if (std::isfinite(m.accuracy)) m.accuracy += s.accuracy / k;
    }
    return m;
  };
  row.window = mean([](const LabelProbeRow& r) -> const LabelScores& { return r.window; });
  row.trial = mean([](const LabelProbeRow& r) -> const LabelScores& { return r.trial; });
  row.runs.clear();
  row.validation = 0;
  for (const auto& r : runs) {
    row.runs.push_back({r.window, r.trial});
    row.validation += r.validation / k;
  }
  return row;
}

// Ridge on features [S, p] of the training samples: outputs [S_test, R + C] for the test features
// (regression values, then one-hot class scores), λ chosen on a validation split (by the targets'
// groups when they have them, as the heads').
struct RidgeOutputs {
  std::vector<double> y;
  double lambda = std::numeric_limits<double>::quiet_NaN();
};
inline RidgeOutputs ridge_outputs(const Eigen::MatrixXd& Xtr, const HeadTargets& tr, const Eigen::MatrixXd& Xte,
                                  const HeadTrainConfig& cfg) {
  const int R = tr.regression, C = tr.classes, out = R + C;
  const auto S = static_cast<int>(Xte.rows());
  RidgeOutputs o;
  o.y.assign(static_cast<std::size_t>(S) * out, 0.0);
  if (R > 0) {
    Eigen::MatrixXd Y(tr.size(), R);
    for (int s = 0; s < tr.size(); ++s)
      for (int a = 0; a < R; ++a) Y(s, a) = tr.value[static_cast<std::size_t>(s) * R + a];
    const RidgeModel rm = fit_ridge(Xtr, Y, ridge_lambdas, cfg.validation_fraction, cfg.seed, tr.groups);
    const Eigen::MatrixXd P = predict(rm, Xte);
    for (int s = 0; s < S; ++s)
      for (int a = 0; a < R; ++a) o.y[static_cast<std::size_t>(s) * out + a] = P(s, a);
    o.lambda = rm.lambda;
  }
  if (C > 0) {
    const RidgeModel rm = fit_ridge_classifier(Xtr, tr.label, C, ridge_lambdas, cfg.validation_fraction, cfg.seed, tr.groups);
    const Eigen::MatrixXd P = predict(rm, Xte);
    for (int s = 0; s < S; ++s)
      for (int c = 0; c < C; ++c) o.y[static_cast<std::size_t>(s) * out + R + c] = P(s, c);
    o.lambda = rm.lambda;
  }
  return o;
}

// The settings of the heads beyond HeadTrainConfig: the learning rates to choose from on the
// validation split (empty: cfg.lr alone), and centring the token embeddings first.
struct LabelProbeSettings {
  std::vector<double> lr_grid;
  // The probe's poolings to choose from on the validation split with the rates (one: fixed):
  // attentive (the paper's) and taxel.
  std::vector<PoolingKind> poolings{PoolingKind::attentive, PoolingKind::taxel};
  bool center_tokens = false;
  int repeats = 1;
  bool quiet = false;
};

// The rows of a label probe (see the top). encoder: the checkpoint's encoder to probe.
inline std::vector<LabelProbeRow> label_probe_rows(const TrainedModel& m, const ParamSet<float>& encoder_params,
                                                   const std::string& encoder_name, const WindowSource& train_src,
                                                   const WindowLabels& train, const WindowSource& test_src,
                                                   const WindowLabels& test, const Skin& skin,
                                                   const HeadTrainConfig& cfg, const LabelProbeSettings& set) {
  require<ConfigError>(set.repeats >= 1, "label probe: repeats = ", set.repeats, ", expected >= 1");
  const TaxelLayout& layout = skin.layout;
  const HeadTargets& tr = train.targets;
  const HeadTargets& te = test.targets;
  const int R = tr.regression, C = tr.classes;
  std::vector<LabelProbeRow> rows;
  const std::string one_class =
      C > 0 && distinct_classes(tr.label) < 2 ? "the training windows hold one class" : "";
  const std::string one_class_test =
      C > 0 && distinct_classes(te.label) < 2 ? "the held-out windows hold one class" : "";
  auto join = [](std::string a, const std::string& b) { return a.empty() ? b : b.empty() ? a : a + "; " + b; };
  auto since = [](auto t0) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  // constant
  {
    LabelProbeRow row;
    row.name = "constant (train mean / majority)";
    row.flag = join(one_class, one_class_test);
    score_row(row, ConstantBaseline::fit(tr.value, R, tr.label, C).outputs(static_cast<std::size_t>(te.size())), test);
    row.validation = constant_validation_loss(tr, cfg);
    rows.push_back(row);
  }
  const double constant = rows.front().validation;
  // A ridge row on features [S, p] (ridge_outputs).
  auto ridge_row = [&](const std::string& name, const Eigen::MatrixXd& Xtr, const Eigen::MatrixXd& Xte) {
    LabelProbeRow row;
    row.name = name;
    RidgeOutputs r = ridge_outputs(Xtr, tr, Xte, cfg);
    row.lambda = r.lambda;
    score_row(row, std::move(r.y), test);
    row.flag = join(one_class, held_out_flag(row, rows.front()));
    return row;
  };
  {
    const auto t0 = std::chrono::steady_clock::now();
    auto features = [&](const WindowSource& src, const std::vector<std::int64_t>& ids) {
      WindowBatch wb;
      src.gather(ids, wb);
      return window_features(wb, layout.group, layout.num_groups());
    };
    rows.push_back(ridge_row("ridge on raw windows", features(train_src, train.window), features(test_src, test.window)));
    rows.back().seconds = since(t0);
  }
  // Frozen encoders: a random initialization of the same architecture, and the checkpoint's; each
  // read out linearly and by an attentive probe.
  auto encoder_rows = [&](const std::string& name, const ParamSet<float>& params) {
    auto t0 = std::chrono::steady_clock::now();
    const JepaModel<float>& model = *m.model;
    const int N = model.num_tokens(), d = model.dim();
    ProgressLine bar("  embed " + name, tr.size() + te.size(), set.quiet);
    auto etr = embed_windows(params, model.tokenizer, model.encoder, train_src, train.window, 32,
                             [&](std::int64_t k, std::int64_t) { bar.update(k, k, ""); });
    auto ete = embed_windows(params, model.tokenizer, model.encoder, test_src, test.window, 32,
                             [&](std::int64_t k, std::int64_t) { bar.update(tr.size() + k, tr.size() + k, ""); });
    std::vector<float> shift;
    if (set.center_tokens) {
      const std::span<float> test_span(ete);
      shift = center_token_embeddings<float>(etr, std::span<const std::span<float>>(&test_span, 1), N, d);
    }
    const double embed_seconds = since(t0);
    // linear read-out of the group means
    std::vector<std::int64_t> all_tr(static_cast<std::size_t>(tr.size())), all_te(static_cast<std::size_t>(te.size()));
    for (std::size_t s = 0; s < all_tr.size(); ++s) all_tr[s] = static_cast<std::int64_t>(s);
    for (std::size_t s = 0; s < all_te.size(); ++s) all_te[s] = static_cast<std::int64_t>(s);
    LabelProbeRow linear = ridge_row(name + ", linear", group_mean_embeddings(etr, N, d, all_tr, layout.group, layout.num_groups()),
                                     group_mean_embeddings(ete, N, d, all_te, layout.group, layout.num_groups()));
    linear.seconds = embed_seconds + since(t0);
    t0 = std::chrono::steady_clock::now();
    require<ConfigError>(!set.poolings.empty(), "label probe: no pooling to try");
    // A fixed pooling names the row by it; a choice says which won.
    auto probe_name = [&](PoolingKind k) {
      return set.poolings.size() > 1 ? name + ", probe (" + to_string(k) + ")" : name + (k == PoolingKind::taxel ? ", taxel probe" : ", attentive");
    };
    FrozenFeatures<float> ftr(std::move(etr), N, d);
    FrozenFeatures<float> fte(std::move(ete), N, d);
    // One head per pooling and learning rate of the grid (seed cfg.seed); the lowest validation
    // loss wins, and the repeats use its pooling and rate.
    auto fit = [&](PoolingKind kind, double lr, std::uint64_t seed) {
      HeadTrainConfig c = cfg;
      c.lr = lr, c.seed = seed;
      const PoolingConfig pc{.kind = kind, .tokens = N};
      auto head = std::make_shared<ProbeHead<float>>(d, m.config.model.heads, R, C, seed, 0, pc);
      const HeadTrainResult r = train_head(*head, ftr, tr, c);
      LabelProbeRow row;
      row.name = probe_name(kind);
      row.pooling = to_string(kind);
      row.validation = r.best_validation;
      row.best_epoch = r.best_epoch;
      row.epochs = r.epochs();
      row.lr = lr;
      const std::vector<float> yf = predict_head(*head, fte, te.size());
      score_row(row, std::vector<double>(yf.begin(), yf.end()), test);
      row.head = std::move(head);
      row.center_shift = shift;
      return row;
    };
    const std::vector<double> grid = set.lr_grid.empty() ? std::vector<double>{cfg.lr} : set.lr_grid;
    std::vector<LabelProbeRow> runs;
    std::vector<LabelProbeRow::Tried> tried;
    PoolingKind kind = set.poolings.front();
    for (PoolingKind k : set.poolings)
      for (double lr : grid) {
        LabelProbeRow r = fit(k, lr, cfg.seed);
        tried.push_back({r.pooling, lr, r.validation});
        if (runs.empty() || (std::isfinite(r.validation) && !(r.validation >= runs.front().validation)))
          runs.assign(1, std::move(r)), kind = k;
      }
    const double lr = runs.front().lr;
    int diverged = std::isfinite(runs.front().validation) ? 0 : 1;
    if (diverged && set.repeats > 1) runs.clear();
    for (int rep = 1; rep < set.repeats; ++rep) {
      LabelProbeRow r = fit(kind, lr, cfg.seed + static_cast<std::uint64_t>(rep));
      if (!std::isfinite(r.validation)) {
        ++diverged;
        continue;
      }
      runs.push_back(std::move(r));
    }
    LabelProbeRow probe;
    if (runs.empty()) {  // every repeat diverged
      probe.name = probe_name(kind);
      probe.flag = "all " + std::to_string(set.repeats) + " repeats diverged (validation loss not finite)";
    } else {
      probe = mean_of_runs(std::move(runs));
      probe.flag = join(join(one_class, head_flag(probe.validation, constant)), held_out_flag(probe, rows.front()));
      probe.flag = join(probe.flag, under_read_flag(probe, linear));
      probe.flag = join(probe.flag, epoch_limit_flag(probe, cfg, constant));
      if (diverged > 0 && set.repeats > 1)
        probe.flag = join(probe.flag, std::to_string(diverged) + " of " + std::to_string(set.repeats) +
                                              " repeats diverged and are left out of the mean");
    }
    probe.lr = lr;
    probe.pooling = to_string(kind);
    probe.tried = tried;
    probe.seconds = embed_seconds + since(t0);
    rows.push_back(std::move(linear));
    rows.push_back(std::move(probe));
  };
  const auto random = make_jepa_model(m.config, skin.graph, m.model->config.in_dim / m.config.data.tau,
                                      m.config.seed ^ 0x72616e646f6dull);  // "random"
  encoder_rows("random encoder (frozen)", random->target);
  encoder_rows(encoder_name + " encoder (frozen)", encoder_params);
  return rows;
}

// The rows as a score table (downstream/score_table.hpp): per regression output its RMSE (and their
// mean with more than one), top-1 with classes, each also per trial with trials; a sample per
// repeat; best epoch and the row's flag beside; the row's settings in its JSON.
inline ScoreTable label_score_table(const std::vector<LabelProbeRow>& rows, const WindowLabels& test, int train_windows,
                                    int train_trials = 0) {
  const int R = test.targets.regression, C = test.targets.classes;
  const bool trials = !test.trial.empty();
  const int test_trials = static_cast<int>(std::set<int>(test.trial.begin(), test.trial.end()).size());
  ScoreTable t;
  t.title = "Probe: " + std::string(R > 0 ? std::to_string(R) + " regression output(s)" : "") + (R > 0 && C > 0 ? " and " : "") +
            (C > 0 ? std::to_string(C) + " classes" : "") + ", " + std::to_string(train_windows) + " training / " +
            std::to_string(test.targets.size()) + " held-out windows" +
            (trials ? " (" + std::to_string(train_trials) + " / " + std::to_string(test_trials) + " trials)" : "");
  t.row_header = "row";
  t.sample_name = "repeats";
  t.columns = {"best epoch"};
  t.note_column = true;
  auto rmse = [](std::string key, std::string name, bool primary) {
    return ScoreMetric{std::move(key), std::move(name), "", false, primary, 1, "%.4g", "%.2g"};
  };
  auto top1 = [](std::string key, std::string name) { return ScoreMetric{std::move(key), std::move(name), "%", true, true, 100, "%.1f", "%.1f"}; };
  for (int a = 0; a < R; ++a) t.metrics.push_back(rmse("rmse_" + std::to_string(a), "RMSE " + std::to_string(a), R == 1));
  if (R > 1) t.metrics.push_back(rmse("mean_rmse", "mean RMSE", true));
  if (R > 0 && trials) t.metrics.push_back(rmse("trial_rmse", "trial mean RMSE", true));
  if (C > 0) t.metrics.push_back(top1("top1", "top-1"));
  if (C > 0 && trials) t.metrics.push_back(top1("trial_top1", "trial top-1"));
  for (const LabelProbeRow& r : rows) {
    ScoreRow& row = t.row(r.name);
    for (const LabelProbeRow::Run& run : r.runs) {
      std::vector<double> v(run.window.rmse.begin(), run.window.rmse.end());
      if (R > 1) v.push_back(run.window.primary());
      if (R > 0 && trials) v.push_back(run.trial.primary());
      if (C > 0) v.push_back(run.window.accuracy);
      if (C > 0 && trials) v.push_back(run.trial.accuracy);
      row.runs.push_back({std::move(v)});
    }
    row.cells = {r.best_epoch >= 0 ? std::to_string(r.best_epoch + 1) + " of " + std::to_string(r.epochs) : "-"};
    row.note = r.flag;
    nlohmann::json& j = row.info;
    j["seconds"] = r.seconds;
    if (std::isfinite(r.validation)) j["validation_loss"] = r.validation;
    if (r.best_epoch >= 0) j["best_epoch"] = r.best_epoch + 1, j["epochs"] = r.epochs;
    if (std::isfinite(r.lr)) j["lr"] = r.lr;
    if (!r.pooling.empty()) j["pooling"] = r.pooling;
    if (!r.tried.empty()) {
      nlohmann::json tried = nlohmann::json::array();
      for (const auto& [pooling, lr, v] : r.tried)
        tried.push_back({{"pooling", pooling}, {"lr", lr}, {"validation_loss", std::isfinite(v) ? nlohmann::json(v) : nlohmann::json()}});
      j["tried"] = tried;
    }
    if (std::isfinite(r.lambda)) j["lambda"] = r.lambda;
  }
  return t;
}

// The predictions of every row (its first repeat) as CSV: one line per held-out window
// (level window: its trial, window id, first frame and length) and, with trials, one per trial
// (level trial: the mean of its windows' outputs). Classification: the class names of label and
// prediction; regression: label_k and prediction_k per output.
inline std::string label_predictions_csv(const std::vector<LabelProbeRow>& rows, const WindowSource& src,
                                         const WindowLabels& test, std::span<const std::string> class_names,
                                         std::span<const std::string> trial_names) {
  const int R = test.targets.regression, C = test.targets.classes, out = R + C;

  std::string s = "row,level,trial,window,first_frame,frames";
  if (C > 0) s += ",label,prediction";
  for (int a = 0; a < R; ++a) s += ",label_" + std::to_string(a) + ",prediction_" + std::to_string(a);
  s += "\n";
  char buf[64];
  auto values = [&](const std::vector<double>& y, std::size_t k, const HeadTargets& t) {
    std::string v;
    if (C > 0) {
      const double* r = y.data() + k * out + R;
      v += "," + csv_field(class_names[static_cast<std::size_t>(t.label[k])]) + "," +
           csv_field(class_names[static_cast<std::size_t>(std::max_element(r, r + C) - r)]);
    }
    for (int a = 0; a < R; ++a) {
      std::snprintf(buf, sizeof buf, ",%.7g,%.7g", static_cast<double>(t.value[k * R + a]), y[k * out + a]);
      v += buf;
    }
    return v;
  };
  for (const auto& r : rows) {
    if (r.outputs.empty()) continue;
    const std::string row = csv_field(r.name);
    for (std::size_t k = 0; k < static_cast<std::size_t>(test.targets.size()); ++k) {
      const std::int64_t w = test.window[k];
      const std::string trial = test.trial.empty() ? std::to_string(src.recording_of(w))
                                                   : csv_field(trial_names[static_cast<std::size_t>(test.trial[k])]);
      s += row + ",window," + trial + "," + std::to_string(w) + "," + std::to_string(src.start_of(w)) + "," +
           std::to_string(src.length()) + values(r.outputs, k, test.targets) + "\n";
    }
    if (test.trial.empty()) continue;
    const TrialView v = trial_view(r.outputs, test.targets, test.trial);
    for (std::size_t k = 0; k < v.trial.size(); ++k) {
      const auto first = std::find(test.trial.begin(), test.trial.end(), v.trial[k]) - test.trial.begin();
      const int frames = src.recordings()[static_cast<std::size_t>(src.recording_of(test.window[static_cast<std::size_t>(first)]))].frames();
      s += row + ",trial," + csv_field(trial_names[static_cast<std::size_t>(v.trial[k])]) + ",,," + std::to_string(frames) +
           values(v.outputs, k, v.targets) + "\n";
    }
  }
  return s;
}

}  // namespace tjepa::cli
