#pragma once
// `tjepa eval --trials TABLE`: the paper's downstream protocol (Sec. IV-D, Table 3) on the user's
// own labelled trials (docs/real_data.md, "The protocol"):
//
//   data     the table's split (trials.hpp): pre-training and heads see the training and
//            validation trials only, the test trials are scored; windows never cross a trial;
//            preprocessing fitted on the training recordings
//   rows     constant; ridge on raw windows; the random initial encoder, frozen; the same encoder
//            trained end to end with the head; MAE, DINO (its teacher) and BYOL (T-DEX's image of
//            the skin's frame, AlexNet, the online network) pre-trained on the training windows
//            with Tactile-JEPA's budget (steps, batch, schedule), frozen; Tactile-JEPA, frozen (the
//            target encoder). Every encoder starts from the same initialization
//            (make_jepa_model's, seed s). Each frozen encoder is also read linearly (ridge on its
//            group-mean embeddings, "<row>, linear"), apart from what a head learns to find
//   heads    the probe head (ProbeHead, one pooling, one rate) trained with early stopping on a
//            validation split by trial, the same number of steps at every label share; on a share
//            of fewer than head_folds_below labelled trials, its epochs chosen by head_folds-fold
//            cross-validation by trial, then trained on every labelled trial (train_head, folds)
//   labels   for each share f of label_fractions: the labelled trials are a seeded draw of f of
//            the training trials, per class (at least 2 of each class; regression: at least 4),
//            the same draw for every row at one head seed; the share is what self-supervised
//            pre-training is for (paper, Sec. I)
//   protocol for each pre-training seed s: pre-train, then head_seeds heads per row and share (head
//            seed s·1000 + h, which also draws the labelled trials); one table per share
//            (downstream/score_table.hpp): mean ± sd over seeds of the head-averaged scores, per
//            window and per trial (its windows' outputs averaged), Welch's one-sided test of the
//            best two rows and of Tactile-JEPA against random init and against end to end
//
// Everything is a function of the options: the same options give the same tables (at the same
// thread count).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <ostream>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/baselines/byol.hpp>
#include <tjepa/baselines/dino.hpp>
#include <tjepa/baselines/mae.hpp>
#include <tjepa/tjepa.hpp>

#include "label_probe.hpp"
#include "output.hpp"
#include "probe.hpp"
#include "setup.hpp"
#include "trials.hpp"

namespace tjepa::cli {

struct TrialEvalOptions {
  TrialOptions trials;
  double test_fraction = 0.2;          // a table without a split column: the share of trials held out
  DataFormat format;
  std::string task = "classification";  // or regression (the table's labels are numbers)
  std::string preprocess = "auto";
  std::vector<std::uint64_t> seeds{0, 1, 2};  // pre-training seeds
  int head_seeds = 3;                          // heads per row, share and pre-training seed
  std::vector<double> label_fractions{1.0, 0.1, 0.03};
  int max_windows = 0;       // training windows the heads draw from (a seeded subset; 0: all)
  int max_test_windows = 0;  // held-out windows scored (a seeded subset; 0: all)
  // The heads: this many steps at most, early stopping after patience_steps without a lower
  // validation loss, at every label share (an epoch of 1 % of the trials is a few steps).
  // Classification heads stop on the validation top-1 error, the loss breaking ties: the
  // cross-entropy of held-out slides rises with confident mistakes while their accuracy still
  // improves (FabricSlide at 10 %: kept at epoch 2 on the loss, 26 %; at epoch 57 on the error, 85 %).
  HeadTrainConfig head{.max_epochs = 1, .patience = 1, .batch = 32, .lr = 1e-3, .stop_on_error = true};
  int head_steps = 10000, head_patience_steps = 3000;
  int end_to_end_steps = 3000, end_to_end_patience_steps = 1000;
  // Shares of fewer labelled trials than head_folds_below: every head (frozen and end to end)
  // picks its epochs by cross-validation over head_folds folds of trials (1: one validation split).
  // A fifth of a few dozen trials is too few to stop on: on FabricSlide at 10 % (73 slides, about
  // 2 of each fabric held out) the single split's heads read 85, 77 and 25 % on the error (3 seeds),
  // the 3-fold ones 77, 69 and 80 %.
  int head_folds = 3, head_folds_below = 200;
  PoolingKind pooling = PoolingKind::taxel;
  bool ridge = true, random = true, end_to_end = true, mae = true, dino = true, byol = true, jepa = true;
  bool linear = true;
  double mae_mask_ratio = 0.75;
  int byol_image_size = 224;
};

// The labelled trials and their windows, read and split once.
struct TrialEvalData {
  Skin skin;
  std::string preprocess;  // resolved
  std::optional<WindowSource> train_src, test_src;
  WindowLabels train, test;  // train: the heads' pool of training windows
  int train_trials = 0, test_trials = 0, pretrain_windows = 0;
  std::vector<std::string> class_names;
};

inline TrialEvalData read_trial_eval_data(const TrialEvalOptions& o, const TrainConfig& run, std::ostream& out) {
  const LabelTask task = parse_label_task(o.task);
  TrialEvalData d{load_skin(SkinSpec::of(run), &out), "", {}, {}, {}, {}, 0, 0, 0, {}};
  const TrialTable table = read_trial_table(o.trials.table);
  require<ConfigError>(!table.labels_are_files(), o.trials.table,
                       ": per-frame label files; tjepa eval takes one label per trial (tjepa probe reads label files)");
  const TrialSplits sp = split_trials(table, o.test_fraction, o.trials.seed);
  out << "trials: " << describe_split(table, sp) << "\n";
  require<DataError>(!sp.test.empty(), o.trials.table, ": no test trial to hold out (", sp.how, ")");
  const int tau = run.data.tau;
  TrialRecordings tr = read_trials(table, sp.fit(), o.format, d.skin, tau, "training trials", out);
  TrialRecordings te = read_trials(table, sp.test, o.format, d.skin, tau, "test trials", out);
  const PreprocessChoice picked = choose_preprocessing(o.preprocess, tr.recordings);
  d.preprocess = picked.mode;
  out << "preprocessing: " << picked.mode << " (" << picked.reason << ")\n";
  const Preprocessor pre = fit_preprocessor(picked.mode, nullptr, tr.recordings);
  d.train_src.emplace(tr.recordings, window_spec(tau, o.format), std::vector<std::vector<FrameLabel>>{}, pre);
  d.test_src.emplace(te.recordings, window_spec(tau, o.format), std::vector<std::vector<FrameLabel>>{}, pre);
  note_dropped(*d.train_src, "training trials", out);
  note_dropped(*d.test_src, "test trials", out);
  std::vector<int> class_of_trial, class_ids;
  std::vector<float> value_of_trial;
  if (task == LabelTask::classification) {
    const TrialClasses c = trial_classes(table);
    d.class_names = c.names, class_of_trial = c.of_trial;
    for (std::size_t k = 0; k < c.names.size(); ++k) class_ids.push_back(static_cast<int>(k));
    require<DataError>(class_ids.size() >= 2, o.trials.table, ": ", class_ids.size(), " class(es), expected at least two");
  } else {
    value_of_trial = trial_values(table);
  }
  d.train = trial_window_labels(table, tr, *d.train_src, task, class_of_trial, value_of_trial, {}, class_ids);
  d.test = trial_window_labels(table, te, *d.test_src, task, class_of_trial, value_of_trial, {}, class_ids);
  d.test.targets.groups = {};
  d.pretrain_windows = static_cast<int>(d.train_src->size());
  d.train_trials = static_cast<int>(tr.recordings.size()), d.test_trials = static_cast<int>(te.recordings.size());
  limit_windows(d.train, o.max_windows, 0x706f6f6cull);  // "pool"
  limit_windows(d.test, o.max_test_windows, 0x74657374ull);  // "test"
  return d;
}

// The labelled share of the training windows w: a seeded draw of `fraction` of its trials, per class
// (at least 2 trials of each class, all when it has fewer) or, without classes, of all trials (at
// least 4). The indices of the windows kept, in order. fraction 1: all.
inline std::vector<std::size_t> label_share(const WindowLabels& w, double fraction, std::uint64_t seed) {
  std::vector<std::size_t> rows;
  if (fraction >= 1) {
    for (std::size_t i = 0; i < w.window.size(); ++i) rows.push_back(i);
    return rows;
  }
  const bool classes = w.targets.classes > 0;
  std::map<int, std::vector<int>> trials_of;  // stratum -> its trials, in order of first appearance
  std::set<int> seen;
  for (std::size_t i = 0; i < w.trial.size(); ++i)
    if (seen.insert(w.trial[i]).second) trials_of[classes ? w.targets.label[i] : 0].push_back(w.trial[i]);
  Rng rng(seed, 0x6c6162656c73ull);  // "labels"
  std::set<int> kept;
  for (auto& [stratum, ts] : trials_of) {
    rng.shuffle(std::span<int>(ts));
    const long floor = classes ? 2 : 4;
    const long n = static_cast<long>(ts.size());
    const long k = std::min(n, std::max(floor, std::lround(fraction * static_cast<double>(n))));
    kept.insert(ts.begin(), ts.begin() + k);
  }
  for (std::size_t i = 0; i < w.trial.size(); ++i)
    if (kept.count(w.trial[i])) rows.push_back(i);
  return rows;
}

// A label share's windows as head targets: the rows of w, their groups' validation trials kept only
// when the share holds one of them.
inline WindowLabels share_labels(const WindowLabels& w, std::span<const std::size_t> rows) {
  WindowLabels s = select_windows(w, rows);
  std::vector<std::int64_t>& held = s.targets.groups.held;
  const std::set<std::int64_t> groups(s.targets.groups.group.begin(), s.targets.groups.group.end());
  std::erase_if(held, [&](std::int64_t g) { return !groups.count(g); });
  return s;
}

// The table of one label share: top-1 and trial top-1, or RMSE and trial RMSE (per output, and
// their mean with several); samples are pre-training seeds.
inline ScoreTable trial_eval_table(const WindowLabels& test, double fraction, int trials, int of_trials, int windows) {
  ScoreTable t = label_score_table({}, test, windows);
  const int R = test.targets.regression, C = test.targets.classes;
  const std::set<int> test_trials(test.trial.begin(), test.trial.end());
  char buf[256];
  std::snprintf(buf, sizeof buf, "Labelled training trials: %g %% (%d of %d trials, %d windows); ", 100 * fraction, trials,
                of_trials, windows);
  t.title = buf + (R > 0 ? std::to_string(R) + " regression output(s)" : std::to_string(C) + " classes") + "; " +
            std::to_string(test.window.size()) + " held-out windows of " + std::to_string(test_trials.size()) + " trials";
  t.sample_name = "seeds";
  t.columns.clear();
  t.note_column = false;
  t.contrasts = {{"Tactile-JEPA, frozen", "random init, frozen"},
                 {"Tactile-JEPA, linear", "random init, linear"}};
  return t;
}

struct TrialEvalResult {
  std::vector<ScoreTable> tables;  // one per label share, in label_fractions' order
  nlohmann::json info;
};

// The scores of a head's outputs [S, R + C] on the test windows, in the table's metric order
// (label_score_table): per output RMSE, mean RMSE (R > 1), trial mean RMSE; top-1, trial top-1.
inline std::vector<double> trial_eval_scores(const std::vector<double>& y, const WindowLabels& test) {
  LabelProbeRow row;
  score_row(row, y, test);
  const int R = test.targets.regression, C = test.targets.classes;
  std::vector<double> v(row.window.rmse.begin(), row.window.rmse.end());
  if (R > 1) v.push_back(row.window.primary());
  if (R > 0) v.push_back(row.trial.primary());
  if (C > 0) v.push_back(row.window.accuracy), v.push_back(row.trial.accuracy);
  return v;
}

inline TrialEvalResult run_trial_eval(const TrialEvalOptions& o, const TrainConfig& run_config, std::ostream& out,
                                      const std::function<void(const TrialEvalResult&)>& after_seed = {}) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  auto seconds = [](clock::time_point a) { return std::chrono::duration<double>(clock::now() - a).count(); };
  auto say = [&](const std::string& s) { out << "[" << format_duration(seconds(t0)) << "] " << s << "\n" << std::flush; };
  require<ConfigError>(!o.seeds.empty() && o.head_seeds > 0, "tjepa eval: ", o.seeds.size(), " seeds and ", o.head_seeds,
                       " head seeds, expected at least one of each");
  require<ConfigError>(!o.label_fractions.empty(), "tjepa eval: no --label-fractions");
  for (double f : o.label_fractions)
    require<ConfigError>(f > 0 && f <= 1, "--label-fractions: ", f, ", expected in (0, 1]");
  require<ConfigError>(o.head_steps > 0 && o.head_patience_steps > 0 && o.end_to_end_steps > 0 &&
                           o.end_to_end_patience_steps > 0,
                       "tjepa eval: head steps and patience must be > 0");
  require<ConfigError>(!o.byol || o.byol_image_size >= 63, "--byol-image-size ", o.byol_image_size,
                       ", expected >= 63 (AlexNet's smallest input)");
  run_config.validate();
  const TrialEvalData d = read_trial_eval_data(o, run_config, out);
  const WindowSource& src = *d.train_src;
  const WindowSource& test_src = *d.test_src;
  const WindowLabels& pool = d.train;
  const WindowLabels& test = d.test;
  const TaxelGraph& graph = d.skin.graph;
  const TaxelLayout& layout = d.skin.layout;
  const int axes = src.axes(), R = test.targets.regression, C = test.targets.classes;
  say("pre-training on " + std::to_string(d.pretrain_windows) + " windows of the " + std::to_string(d.train_trials) +
      " training trials; heads on " + std::to_string(pool.window.size()) + " of them; " +
      std::to_string(test.window.size()) + " held-out windows of " + std::to_string(d.test_trials) + " trials");

  TrialEvalResult res;
  res.info = {{"trials", {{"table", o.trials.table}, {"train", d.train_trials}, {"test", d.test_trials}}},
              {"task", o.task},
              {"preprocess", d.preprocess},
              {"windows", {{"pretrain", d.pretrain_windows}, {"heads", pool.window.size()}, {"test", test.window.size()}}},
              {"train", run_config.to_json()},
              {"seeds", o.seeds},
              {"head_seeds", o.head_seeds},
              {"label_fractions", o.label_fractions},
              {"heads", {{"pooling", to_string(o.pooling)}, {"lr", o.head.lr}, {"batch", o.head.batch},
                         {"steps", o.head_steps}, {"patience_steps", o.head_patience_steps},
                         {"end_to_end_steps", o.end_to_end_steps},
                         {"end_to_end_patience_steps", o.end_to_end_patience_steps},
                         {"stop_on_error", o.head.stop_on_error}, {"folds", o.head_folds},
                         {"folds_below_trials", o.head_folds_below}}},
              {"mae_mask_ratio", o.mae_mask_ratio},
              {"byol_image_size", o.byol_image_size},
              {"pretraining", nlohmann::json::array()},
              {"head_training", nlohmann::json::array()}};
  if (!d.class_names.empty()) res.info["classes"] = d.class_names;

  // The labelled share of each fraction at each head seed, and its head config.
  struct Share {
    std::vector<std::size_t> rows;
    std::vector<std::int64_t> windows;  // their window ids
    WindowLabels labels;
  };
  auto share_of = [&](double f, std::uint64_t h) {
    Share s;
    s.rows = label_share(pool, f, h);
    s.labels = share_labels(pool, s.rows);
    s.windows = s.labels.window;
    return s;
  };
  auto trials_of = [](const Share& sh) {
    return static_cast<int>(std::set<int>(sh.labels.trial.begin(), sh.labels.trial.end()).size());
  };
  auto folds_of = [&](const Share& sh) { return trials_of(sh) < o.head_folds_below ? o.head_folds : 1; };
  auto head_config = [&](const Share& sh, std::size_t windows, std::uint64_t h, int steps, int patience) {
    HeadTrainConfig c = o.head;
    c.folds = folds_of(sh);
    const double fit = (1.0 - c.validation_fraction) * static_cast<double>(windows);
    const int per_epoch = std::max(1, static_cast<int>(fit / c.batch));
    c.max_epochs = std::max(1, (steps + per_epoch - 1) / per_epoch);
    c.patience = std::max(1, (patience + per_epoch - 1) / per_epoch);
    c.seed = h;
    return c;
  };
  for (std::size_t k = 0; k < o.label_fractions.size(); ++k) {
    const Share s = share_of(o.label_fractions[k], 0);
    const int trials = trials_of(s);
    res.tables.push_back(
        trial_eval_table(test, o.label_fractions[k], trials, d.train_trials, static_cast<int>(s.rows.size())));
    if (o.end_to_end)
      res.tables.back().contrasts.push_back({"Tactile-JEPA, frozen", "end to end"});
  }
  auto head_seeds_of = [&](std::uint64_t s) {
    std::vector<std::uint64_t> h;
    for (int i = 0; i < o.head_seeds; ++i) h.push_back(s * 1000 + static_cast<std::uint64_t>(i));
    return h;
  };
  auto features_of = [&](const WindowSource& from, std::span<const std::int64_t> ids) {
    WindowBatch wb;
    from.gather(ids, wb);
    return window_features(wb, layout.group, layout.num_groups());
  };
  const Eigen::MatrixXd raw_test = o.ridge ? features_of(test_src, test.window) : Eigen::MatrixXd();
  const Eigen::MatrixXd raw_pool = o.ridge ? features_of(src, pool.window) : Eigen::MatrixXd();
  auto rows_of = [](const Eigen::MatrixXd& X, std::span<const std::size_t> rows) {
    Eigen::MatrixXd Y(static_cast<Eigen::Index>(rows.size()), X.cols());
    for (std::size_t i = 0; i < rows.size(); ++i) Y.row(static_cast<Eigen::Index>(i)) = X.row(static_cast<Eigen::Index>(rows[i]));
    return Y;
  };

  // What each trained head did (results.json "head_training"): its epochs, the epoch kept and its
  // validation loss, so that a head kept at its first epochs is seen.
  auto record_head = [&](const std::string& row, std::uint64_t s, const Share& sh, std::uint64_t h,
                         const HeadTrainResult& r) {
    res.info["head_training"].push_back({{"row", row}, {"seed", s}, {"head_seed", h}, {"trials", trials_of(sh)},
                                 {"folds", folds_of(sh)},
                                 {"epochs", r.epochs()}, {"best_epoch", r.best_epoch},
                                 {"best_validation", r.best_epoch >= 0 ? r.best_validation : 0.0},
                                 {"first_validation", r.validation_loss.empty() ? 0.0 : r.validation_loss.front()}});
  };
  // Every (share, head seed) of seed s: fn(table, share, head seed) returns the head's scores.
  auto for_shares = [&](const std::string& name, std::uint64_t s, auto&& fn) {
    for (std::size_t k = 0; k < o.label_fractions.size(); ++k) {
      std::vector<std::vector<double>> heads;
      for (std::uint64_t h : head_seeds_of(s)) heads.push_back(fn(share_of(o.label_fractions[k], h), h));
      res.tables[k].row(name).runs.push_back(std::move(heads));
    }
    say("  " + name + ": done");
  };
  // A frozen encoder's rows: its probe heads on embeddings [pool, N, dim] and [test, N, dim], and
  // (linear: taxel tokens) the ridge on its group means.
  auto frozen_rows = [&](const std::string& name, std::uint64_t s, AlignedVector<float> etr, AlignedVector<float> ete,
                         int N, int dim, int attention_heads, bool linear) {
    if (linear && o.linear) {
      std::vector<std::int64_t> all_te(test.window.size());
      for (std::size_t i = 0; i < all_te.size(); ++i) all_te[i] = static_cast<std::int64_t>(i);
      const Eigen::MatrixXd Xte = group_mean_embeddings(ete, N, dim, all_te, layout.group, layout.num_groups());
      for_shares(name + ", linear", s, [&](const Share& sh, std::uint64_t h) {
        std::vector<std::int64_t> rows(sh.rows.begin(), sh.rows.end());
        HeadTrainConfig c = o.head;
        c.seed = h;
        return trial_eval_scores(
            ridge_outputs(group_mean_embeddings(etr, N, dim, rows, layout.group, layout.num_groups()), sh.labels.targets,
                          Xte, c)
                .y,
            test);
      });
    }
    FrozenFeatures<float> ftr(std::move(etr), N, dim), fte(std::move(ete), N, dim);
    for_shares(name + ", frozen", s, [&](const Share& sh, std::uint64_t h) {
      const std::vector<std::int64_t> rows(sh.rows.begin(), sh.rows.end());
      RowFeatures view(ftr, rows);
      ProbeHead<float> head(dim, attention_heads, R, C, h, 0, PoolingConfig{.kind = o.pooling, .tokens = N});
      record_head(name + ", frozen", s, sh, h,
                  train_head(head, view, sh.labels.targets, head_config(sh, rows.size(), h, o.head_steps, o.head_patience_steps)));
      const std::vector<float> y = predict_head(head, fte, fte.size());
      return trial_eval_scores(std::vector<double>(y.begin(), y.end()), test);
    });
  };
  auto seeded = [&](std::uint64_t s) {
    TrainConfig c = run_config;
    c.seed = s;
    return c;
  };
  auto same_start = [&](auto& model, const TrainConfig& cfg, std::uint64_t s) {
    if (cfg.model.position_eigenvectors > 0)
      model.set_positions(graph_positions(graph, cfg.model.dim, cfg.model.position_eigenvectors, cfg.model.position_scale, s));
  };
  // A trainer run to its end, a line every tenth of it; its losses logged.
  auto pretrain = [&](const std::string& name, std::uint64_t s, auto& trainer, std::int64_t steps, auto&& detail) {
    const auto t = clock::now();
    trainer.on_step = [&](const auto& st) {
      if ((st.step + 1) % std::max<std::int64_t>(1, steps / 10) == 0)
        say("  " + name + " seed " + std::to_string(s) + ": step " + std::to_string(st.step + 1) + "/" +
            std::to_string(steps) + ", loss " + std::to_string(st.loss) + detail(st));
    };
    const auto log = trainer.run();
    res.info["pretraining"].push_back({{"row", name}, {"seed", s}, {"first_loss", log.front().loss},
                                       {"last_loss", log.back().loss}, {"seconds", seconds(t)}});
    return log;
  };
  auto no_detail = [](const auto&) { return std::string(); };
  auto embed = [&](const ParamSet<float>& p, const Tokenizer& tok, const Encoder& enc) {
    return std::pair{embed_windows(p, tok, enc, src, pool.window), embed_windows(p, tok, enc, test_src, test.window)};
  };

  std::vector<std::uint64_t> dino_collapsed_seeds;
  for (std::uint64_t s : o.seeds) {
    say("pre-training seed " + std::to_string(s));
    const TrainConfig cfg = seeded(s);
    for_shares("constant", s, [&](const Share& sh, std::uint64_t) {
      const HeadTargets& t = sh.labels.targets;
      return trial_eval_scores(ConstantBaseline::fit(t.value, R, t.label, C).outputs(test.window.size()), test);
    });
    if (o.ridge)
      for_shares("ridge on raw windows", s, [&](const Share& sh, std::uint64_t h) {
        HeadTrainConfig c = o.head;
        c.seed = h;
        return trial_eval_scores(ridge_outputs(rows_of(raw_pool, sh.rows), sh.labels.targets, raw_test, c).y, test);
      });
    if (o.random || o.end_to_end) {
      auto model = make_jepa_model<float>(cfg, graph, axes, s);
      if (o.random) {
        auto [etr, ete] = embed(model->target, model->tokenizer, model->encoder);
        frozen_rows("random init", s, std::move(etr), std::move(ete), model->num_tokens(), model->dim(),
                    cfg.model.heads, true);
      }
      if (o.end_to_end)
        for_shares("end to end", s, [&](const Share& sh, std::uint64_t h) {
          ParamSet<float> copy = model->context;
          EncoderFeatures<float> ftr(copy, model->tokenizer, model->encoder, src, sh.windows);
          EncoderFeatures<float> fte(copy, model->tokenizer, model->encoder, test_src, test.window);
          ProbeHead<float> head(model->dim(), cfg.model.heads, R, C, h, 0,
                                PoolingConfig{.kind = o.pooling, .tokens = model->num_tokens()});
          record_head("end to end", s, sh, h,
                      train_head(head, ftr, sh.labels.targets,
                                 head_config(sh, sh.windows.size(), h, o.end_to_end_steps, o.end_to_end_patience_steps)));
          const std::vector<float> y = predict_head(head, fte, fte.size());
          return trial_eval_scores(std::vector<double>(y.begin(), y.end()), test);
        });
    }
    if (o.mae) {
      MaeModel<float> mae(mae_config(cfg, graph.num_nodes(), axes, o.mae_mask_ratio), s);
      same_start(mae, cfg, s);
      MaeTrainer<float> trainer(mae, src, cfg);
      pretrain("MAE", s, trainer, cfg.schedule.steps, no_detail);
      auto [etr, ete] = embed(mae.context, mae.tokenizer, mae.encoder);
      frozen_rows("MAE", s, std::move(etr), std::move(ete), mae.encoder.num_tokens(), mae.encoder.dim(), cfg.model.heads,
                  true);
    }
    if (o.dino) {
      DinoModel<float> dino(dino_config(cfg, graph.num_nodes(), axes), s);
      same_start(dino, cfg, s);
      DinoTrainer<float> trainer(dino, src, cfg);
      const auto log = pretrain("DINO", s, trainer, cfg.schedule.steps, [](const DinoStepStats& st) {
        return " (dino " + std::to_string(st.dino) + ", ibot " + std::to_string(st.ibot) + ", koleo " +
               std::to_string(st.koleo) + ")";
      });
      // Collapse: the class-token loss over the run's last tenth at ln P (a uniform student).
      const std::size_t tail = std::max<std::size_t>(1, log.size() / 10);
      double last = 0;
      for (std::size_t i = log.size() - tail; i < log.size(); ++i) last += log[i].dino / static_cast<double>(tail);
      const int P = dino.config.head.prototypes;
      const bool collapsed = dino_collapsed(last, P);
      nlohmann::json& entry = res.info["pretraining"].back();
      entry["last_dino"] = last, entry["uniform_dino"] = std::log(double(P)), entry["collapsed"] = collapsed;
      if (collapsed) {
        dino_collapsed_seeds.push_back(s);
        say("  DINO seed " + std::to_string(s) + ": collapsed (class-token loss " + std::to_string(last) +
            " = ln " + std::to_string(P) + ", the uniform prediction): its rows read an encoder it did not train");
      }
      auto [etr, ete] = embed(dino.teacher, dino.tokenizer, dino.encoder);
      frozen_rows("DINO", s, std::move(etr), std::move(ete), dino.encoder.num_tokens(), dino.encoder.dim(),
                  cfg.model.heads, true);
      if (!dino_collapsed_seeds.empty()) {
        std::string seeds;
        for (std::uint64_t c : dino_collapsed_seeds) seeds += (seeds.empty() ? "" : " ") + std::to_string(c);
        for (ScoreTable& table : res.tables)
          for (ScoreRow& r : table.rows)
            if (r.name.starts_with("DINO"))
              r.note = "collapsed in seed(s) " + seeds +
                       ": the class-token loss ended at ln P, a uniform student (pretraining in results.json)";
      }
    }
    if (o.byol) {
      ByolConfig bc = byol_config(cfg, axes);
      bc.encoder.image_size = bc.image.image_size = o.byol_image_size;
      ByolModel<float> byol(bc, s);
      const TaxelCanvas canvas = TaxelCanvas::from_layout(layout);
      ByolTrainer<float> trainer(byol, src, canvas, cfg);
      pretrain("BYOL", s, trainer, cfg.schedule.steps, no_detail);
      const int cells = byol.config.encoder.pooled * byol.config.encoder.pooled, Cw = byol.config.encoder.widths[4];
      int heads = cfg.model.heads;  // attention heads that split its channels
      while (Cw % heads != 0) --heads;
      frozen_rows("BYOL", s, byol_embed(byol, byol.online, canvas, src, pool.window),
                  byol_embed(byol, byol.online, canvas, test_src, test.window), cells, Cw, heads, false);
    }
    if (o.jepa) {
      auto model = make_jepa_model<float>(cfg, graph, axes, s);
      JepaTrainer<float> trainer(*model, src, graph, cfg);
      const auto log = pretrain("Tactile-JEPA", s, trainer, cfg.schedule.steps, [](const JepaStepStats& st) {
        return ", target std over samples " + std::to_string(st.target_sample_std);
      });
      nlohmann::json& entry = res.info["pretraining"].back();
      entry["first_target_sample_std"] = log.front().target_sample_std;
      entry["last_target_sample_std"] = log.back().target_sample_std;
      auto [etr, ete] = embed(model->target, model->tokenizer, model->encoder);
      frozen_rows("Tactile-JEPA", s, std::move(etr), std::move(ete), model->num_tokens(), model->dim(), cfg.model.heads,
                  true);
    }
    res.info["total_seconds"] = seconds(t0);
    if (after_seed) after_seed(res);
  }
  return res;
}

}  // namespace tjepa::cli
