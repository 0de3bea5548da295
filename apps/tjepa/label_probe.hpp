#pragma once
// `tjepa probe --task regression|classification`: probes for the user's own labels (motor
// positions, object ids, anything per frame), on the user's recordings.
//
// Labels: one row per frame of the recording (a .npy [T] or [T, K], or text with a header
// detected and --label-columns), a window's label is its last frame's. Regression: K outputs, every
// value finite. Classification: one column of class ids; a negative id marks a frame without a
// class and its windows are left out.
// Rows, each scored on the held-out recording:
//   constant               the training mean / the majority class;
//   ridge on raw windows   closed-form ridge on pad sums and taxel means (downstream/ridge.hpp);
//   random encoder         the checkpoint's architecture at a random initialization, frozen;
//   this checkpoint        its target (or context) encoder, frozen.
// Heads are attentive probes trained with early stopping on a validation split of the training
// windows (train_head); with repeats, one per seed, averaged with their standard deviation.
// Optionally only windows in contact count (keep_contact_windows; off by default). A head whose best validation loss is not 2 % below the constant's on the
// same split is flagged (it learned nothing), as is a row no better than the constant on the
// held-out windows and a split whose windows hold one class.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/downstream/ridge.hpp>
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
  Recording r = read_recording(path, f);
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
};

inline WindowLabels window_labels(const WindowSource& src, const Recording& frames, LabelTask task, int classes,
                                  const std::string& file) {
  WindowLabels w;
  const int K = frames.taxels();
  if (task == LabelTask::classification)
    require<ShapeError>(K == 1, file, ": ", K, " label columns, a classification takes one (the class id; choose it ",
                        "with --label-columns)");
  w.targets.regression = task == LabelTask::regression ? K : 0;
  w.targets.classes = task == LabelTask::classification ? classes : 0;
  for (std::int64_t i = 0; i < src.size(); ++i) {
    const int last = src.start_of(i) + src.length() - 1;
    if (task == LabelTask::classification) {
      const float c = frames(last, 0, 0);
      require<DataError>(c == std::floor(c), file, ": frame ", last, " has class ", c, ", expected an integer id");
      if (c < 0) continue;
      w.window.push_back(i);
      w.targets.label.push_back(static_cast<int>(c));
    } else {
      w.window.push_back(i);
      for (int k = 0; k < K; ++k) w.targets.value.push_back(frames(last, k, 0));
    }
  }
  require<DataError>(w.window.size() >= 4, file, ": ", w.window.size(), " labelled windows, expected at least 4");
  return w;
}

// Keeps the windows of w with at least min_frames frames in which some taxel's preprocessed
// reading (what the encoder sees) has a norm over its axes above threshold.
inline void keep_contact_windows(WindowLabels& w, const WindowSource& src, int min_frames, double threshold,
                                 const std::string& file) {
  const int R = w.targets.regression;
  WindowLabels kept;
  kept.targets.regression = R;
  kept.targets.classes = w.targets.classes;
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
      kept.window.push_back(w.window[i]);
      if (R > 0)
        kept.targets.value.insert(kept.targets.value.end(), w.targets.value.begin() + std::ptrdiff_t(i * R),
                                  w.targets.value.begin() + std::ptrdiff_t((i + 1) * R));
      else
        kept.targets.label.push_back(w.targets.label[i]);
    }
  }
  require<DataError>(kept.window.size() >= 4, file, ": ", kept.window.size(), " of ", w.window.size(),
                     " labelled windows have ", min_frames, " frames in contact (a taxel above ", threshold,
                     "), expected at least 4: lower --min-contact or --contact-threshold");
  w = std::move(kept);
}

struct LabelProbeRow {
  std::string name;
  std::vector<double> rmse;         // regression: per output
  double accuracy = std::numeric_limits<double>::quiet_NaN();
  // Heads with repeats > 1: the mean over the repeats that did not diverge (rmse, accuracy), the
  // sample standard deviation of the mean RMSE (regression) or the top-1 (classification).
  int repeats = 1;
  double sd = std::numeric_limits<double>::quiet_NaN();
  double validation = std::numeric_limits<double>::quiet_NaN();  // heads: best validation loss
  int best_epoch = -1, epochs = 0;
  std::string flag;                 // why the row says little ("" = nothing to say)
  double seconds = 0;
};

// The constant's validation loss on the split a head sees: the fit split's mean (0 in the head's
// standardized units) and the fit split's class frequencies as logits.
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

// The flag of a head: not clearly better than the constant (by 2 %) on its own validation split.
// A head that predicts the uniform class distribution can edge out the constant's class
// frequencies on a split whose frequencies differ; 2 % keeps it flagged.
inline std::string head_flag(double validation, double constant) {
  if (!std::isfinite(validation)) return "diverged (validation loss not finite)";
  if (validation > 0.98 * constant)
    return "no better than the constant on validation (loss " + std::to_string(validation) + " against " +
           std::to_string(constant) + ")";
  return "";
}

// The flag of any row against the constant row on the held-out windows.
inline std::string held_out_flag(const LabelProbeRow& row, const LabelProbeRow& constant) {
  if (std::isfinite(row.accuracy) && row.accuracy <= constant.accuracy)
    return "held-out top-1 no better than the majority class";
  if (!row.rmse.empty()) {
    double a = 0, b = 0;
    for (std::size_t k = 0; k < row.rmse.size(); ++k) a += row.rmse[k], b += constant.rmse[k];
    if (!(a < b)) return "held-out RMSE no better than the constant";
  }
  return "";
}

inline int distinct_classes(std::span<const int> labels) {
  std::vector<int> seen;
  for (int c : labels)
    if (std::find(seen.begin(), seen.end(), c) == seen.end()) seen.push_back(c);
  return static_cast<int>(seen.size());
}

inline void score_row(LabelProbeRow& row, const std::vector<double>& pred_value, const std::vector<int>& pred_class,
                      const HeadTargets& test) {
  const int S = test.size(), R = test.regression;
  if (R > 0) row.rmse = rmse_per_column(pred_value.data(), static_cast<std::size_t>(R), test.value.data(), S, R);
  if (test.classes > 0) {
    int right = 0;
    for (int s = 0; s < S; ++s) right += pred_class[static_cast<std::size_t>(s)] == test.label[static_cast<std::size_t>(s)];
    row.accuracy = static_cast<double>(right) / S;
  }
}

// The rows of a label probe (see the top). encoder: the checkpoint's encoder to probe.
inline std::vector<LabelProbeRow> label_probe_rows(const TrainedModel& m, const ParamSet<float>& encoder_params,
                                                   const std::string& encoder_name, const WindowSource& train_src,
                                                   const WindowLabels& train, const WindowSource& test_src,
                                                   const WindowLabels& test, const Skin& skin,
                                                   const HeadTrainConfig& cfg, bool quiet, int repeats = 1) {
  require<ConfigError>(repeats >= 1, "label probe: repeats = ", repeats, ", expected >= 1");
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
  // constant
  {
    LabelProbeRow row;
    row.name = "constant (train mean / majority)";
    row.flag = join(one_class, one_class_test);
    const auto constant = ConstantBaseline::fit(tr.value, R, tr.label, C);
    const std::vector<double> v = constant.values(static_cast<std::size_t>(te.size()));
    const std::vector<int> c = constant.classes(static_cast<std::size_t>(te.size()));
    score_row(row, v, c, te);
    row.validation = constant_validation_loss(tr, cfg);
    rows.push_back(row);
  }
  const double constant = rows.front().validation;
  // ridge on raw windows
  {
    const auto t0 = std::chrono::steady_clock::now();
    auto features = [&](const WindowSource& src, const std::vector<std::int64_t>& ids) {
      WindowBatch wb;
      src.gather(ids, wb);
      return window_features(wb, layout.group, layout.num_groups());
    };
    const Eigen::MatrixXd Xtr = features(train_src, train.window), Xte = features(test_src, test.window);
    LabelProbeRow row;
    row.name = "ridge on raw windows";
    row.flag = one_class;
    std::vector<double> v;
    std::vector<int> c;
    if (R > 0) {
      Eigen::MatrixXd Y(tr.size(), R);
      for (int s = 0; s < tr.size(); ++s)
        for (int a = 0; a < R; ++a) Y(s, a) = tr.value[static_cast<std::size_t>(s) * R + a];
      const RidgeModel rm = fit_ridge(Xtr, Y, ridge_lambdas, cfg.validation_fraction, cfg.seed);
      const Eigen::MatrixXd P = predict(rm, Xte);
      for (int s = 0; s < te.size(); ++s)
        for (int a = 0; a < R; ++a) v.push_back(P(s, a));
    }
    if (C > 0) {
      const RidgeModel rm = fit_ridge_classifier(Xtr, tr.label, C, ridge_lambdas, cfg.validation_fraction, cfg.seed);
      c = predict_class(rm, Xte);
    }
    score_row(row, v, c, te);
    row.flag = join(row.flag, held_out_flag(row, rows.front()));
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rows.push_back(row);
  }
  // frozen encoders: a random initialization of the same architecture, and the checkpoint's
  auto head_row = [&](const std::string& name, const ParamSet<float>& params) {
    const auto t0 = std::chrono::steady_clock::now();
    const JepaModel<float>& model = *m.model;
    ProgressLine bar("  embed " + name, tr.size() + te.size(), quiet);
    auto etr = embed_windows(params, model.tokenizer, model.encoder, train_src, train.window, 32,
                             [&](std::int64_t d, std::int64_t) { bar.update(d, d, ""); });
    auto ete = embed_windows(params, model.tokenizer, model.encoder, test_src, test.window, 32,
                             [&](std::int64_t d, std::int64_t) { bar.update(tr.size() + d, tr.size() + d, ""); });
    FrozenFeatures<float> ftr(std::move(etr), model.num_tokens(), model.dim());
    FrozenFeatures<float> fte(std::move(ete), model.num_tokens(), model.dim());
    // One head per repeat (seeds cfg.seed, cfg.seed + 1, ...); a diverged one is left out of the mean.
    std::vector<LabelProbeRow> runs;
    int diverged = 0;
    for (int rep = 0; rep < repeats; ++rep) {
      HeadTrainConfig c_rep = cfg;
      c_rep.seed = cfg.seed + static_cast<std::uint64_t>(rep);
      ProbeHead<float> head(model.dim(), m.config.model.heads, R, C, c_rep.seed);
      const HeadTrainResult fit = train_head(head, ftr, tr, c_rep);
      LabelProbeRow row;
      row.name = name;
      row.validation = fit.best_validation;
      row.best_epoch = fit.best_epoch;
      row.epochs = fit.epochs();
      const std::vector<float> y = predict_head(head, fte, te.size());
      std::vector<double> v;
      std::vector<int> c;
      const int out = R + C;
      for (int s = 0; s < te.size(); ++s) {
        const float* r = y.data() + static_cast<std::size_t>(s) * out;
        for (int a = 0; a < R; ++a) v.push_back(r[a]);
        if (C > 0) c.push_back(static_cast<int>(std::max_element(r + R, r + out) - (r + R)));
      }
      score_row(row, v, c, te);
      if (!std::isfinite(row.validation) && repeats > 1) {
        ++diverged;
        continue;
      }
      runs.push_back(std::move(row));
    }
    if (runs.empty()) {  // every repeat diverged: the first one's row, flagged
      LabelProbeRow row;
      row.name = name;
      row.repeats = repeats;
      row.flag = "all " + std::to_string(repeats) + " repeats diverged (validation loss not finite)";
      row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      return row;
    }
    LabelProbeRow row = runs.front();
    row.repeats = repeats;
    if (runs.size() > 1) {
      const double k = static_cast<double>(runs.size());
      const auto score = [&](const LabelProbeRow& r) {
        if (R == 0) return r.accuracy;
        double s = 0;
        for (double e : r.rmse) s += e / static_cast<double>(r.rmse.size());
        return s;
      };
      double mean_score = 0, ss = 0, val = 0;
      for (const auto& r : runs) mean_score += score(r) / k, val += r.validation / k;
      for (const auto& r : runs) ss += (score(r) - mean_score) * (score(r) - mean_score);
      for (std::size_t a = 0; a < row.rmse.size(); ++a) {
        row.rmse[a] = 0;
        for (const auto& r : runs) row.rmse[a] += r.rmse[a] / k;
      }
      if (C > 0) {
        row.accuracy = 0;
        for (const auto& r : runs) row.accuracy += r.accuracy / k;
      }
      row.validation = val;
      row.sd = std::sqrt(ss / (k - 1));
    }
    row.flag = join(join(one_class, head_flag(row.validation, constant)), held_out_flag(row, rows.front()));
    if (diverged > 0)
      row.flag = join(row.flag, std::to_string(diverged) + " of " + std::to_string(repeats) +
                                    " repeats diverged and are left out of the mean");
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return row;
  };
  const auto random = make_jepa_model(m.config, skin.graph, m.model->config.in_dim / m.config.data.tau,
                                      m.config.seed ^ 0x72616e646f6dull);  // "random"
  rows.push_back(head_row("random encoder (frozen)", random->target));
  rows.push_back(head_row(encoder_name + " encoder (frozen)", encoder_params));
  return rows;
}

inline std::string label_probe_markdown(const std::vector<LabelProbeRow>& rows, const HeadTargets& test, int train_windows) {
  const int R = test.regression, C = test.classes;
  std::string s = "### Probe: " + std::string(R > 0 ? std::to_string(R) + " regression output(s)" : "") +
                  (R > 0 && C > 0 ? " and " : "") + (C > 0 ? std::to_string(C) + " classes" : "") + ", " +
                  std::to_string(train_windows) + " training / " + std::to_string(test.size()) + " held-out windows\n\n";
  s += "| row |";
  for (int a = 0; a < R; ++a) s += " RMSE " + std::to_string(a) + " ↓ |";
  if (R > 1) s += " mean RMSE ↓ |";
  if (C > 0) s += " top-1 (%) ↑ |";
  s += " best epoch | note |\n|---|";
  for (int a = 0; a < R + (R > 1 ? 1 : 0) + (C > 0 ? 1 : 0) + 2; ++a) s += "---|";
  s += "\n";
  char buf[64];
  for (const auto& r : rows) {
    s += "| " + r.name + " |";
    double mean = 0;
    for (double v : r.rmse) {
      std::snprintf(buf, sizeof buf, " %.4g |", v);
      s += buf;
      mean += v / static_cast<double>(r.rmse.size());
    }
    const bool sd = std::isfinite(r.sd);
    if (R > 1) {
      std::snprintf(buf, sizeof buf, sd ? " %.4g ± %.2g |" : " %.4g |", mean, r.sd);
      s += buf;
    } else if (R == 1 && sd) {  // the one output's column carries the spread
      s.pop_back(), s.pop_back();
      std::snprintf(buf, sizeof buf, " ± %.2g |", r.sd);
      s += buf;
    }
    if (C > 0) {
      std::snprintf(buf, sizeof buf, sd ? " %.1f ± %.1f |" : " %.1f |", 100 * r.accuracy, 100 * r.sd);
      s += buf;
    }
    s += r.best_epoch >= 0 ? " " + std::to_string(r.best_epoch + 1) + " of " + std::to_string(r.epochs) + " |" : " - |";
    s += " " + (r.flag.empty() ? std::string() : "**" + r.flag + "**") + " |\n";
  }
  return s;
}

inline nlohmann::json label_probe_json(const std::vector<LabelProbeRow>& rows) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& r : rows) {
    nlohmann::json j = {{"row", r.name}, {"flag", r.flag}, {"seconds", r.seconds}};
    if (!r.rmse.empty()) j["rmse"] = r.rmse;
    if (std::isfinite(r.accuracy)) j["accuracy"] = r.accuracy;
    if (std::isfinite(r.validation)) j["validation_loss"] = r.validation;
    if (r.best_epoch >= 0) j["best_epoch"] = r.best_epoch + 1, j["epochs"] = r.epochs;
    if (r.repeats > 1) j["repeats"] = r.repeats;
    if (std::isfinite(r.sd)) j["sd"] = r.sd;
    a.push_back(std::move(j));
  }
  return a;
}

}  // namespace tjepa::cli
