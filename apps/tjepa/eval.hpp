#pragma once
// tjepa eval and tjepa demo: the downstream protocol on the simulated grasping hand
// (eval/grasp_eval.hpp) or, with --trials, on the user's labelled trials (trial_eval.hpp), printed
// and written as results.md, results.json, results.svg.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include <tjepa/eval.hpp>

#include "options.hpp"
#include "output.hpp"
#include "setup.hpp"
#include "trial_eval.hpp"

namespace tjepa::cli {

struct EvalOptions {
  GraspEvalConfig eval;
  std::string out = "runs/eval";
  std::string command = "tjepa eval";  // the command line, written into results.md
  bool force = false;
  bool quiet = false;
  // --trials: the protocol on labelled trials (trial_eval.hpp), pre-training with eval.train.
  bool on_trials = false;
  TrialEvalOptions trial;
};

// The demo: one pre-training seed, one head per task, rows constant / ridge / random / end to
// end / Tactile-JEPA, sized to run in minutes rather than hours (docs/evaluation.md, "The demo"):
// the end-to-end heads stop after 2 epochs, which the row's name says (the protocol's limits
// allow up to 200 epochs), and the linear read-out table is left to `tjepa eval`.
inline EvalOptions demo_eval_options(std::uint64_t seed) {
  EvalOptions o;
  GraspEvalConfig& c = o.eval;
  c.data_seed = seed;
  c.seeds = {seed};
  c.head_seeds = 1;
  c.mae = false;
  c.dino = false;
  c.byol = false;
  c.ablation = false;
  c.linear_readout = false;
  c.heads.end_to_end_max_epochs = 2;
  c.heads.end_to_end_patience = 2;
  o.out = "runs/demo";
  o.command = "tjepa demo";
  o.force = true;
  return o;
}

// tjepa eval --trials: the tables of every label share, rewritten after each pre-training seed.
inline int run_trial_eval_command(const EvalOptions& o, std::ostream& out) {
  const std::filesystem::path dir = o.out;
  out << "tjepa " << version_string << " " << o.command << ": " << o.trial.seeds.size() << " pre-training seed(s) x "
      << o.trial.head_seeds << " head(s) per row and label share; " << max_threads() << " thread(s)\n" << std::flush;
  OutputFiles::check_new(dir / "results.json", o.force);
  auto write = [&](const TrialEvalResult& r) {  // the folder made at the first write: a bad flag leaves none
    make_directories(dir);
    std::string md = "# " + o.command + "\n";
    nlohmann::json j = r.info;
    j["command"] = o.command;
    j["tables"] = nlohmann::json::array();
    for (const ScoreTable& t : r.tables) {
      md += "\n" + t.markdown();
      j["tables"].push_back(t.to_json());
    }
    write_file_atomic(dir / "results.md", md);
    write_file_atomic(dir / "results.json", j.dump(2));
    write_file_atomic(dir / "results.svg", r.tables.front().svg());
    return md;
  };
  NullStream null;
  const TrialEvalResult r = run_trial_eval(o.trial, o.eval.train, o.quiet ? null : out, write);
  out << "\n" << write(r);
  out << "total " << format_duration(r.info["total_seconds"].get<double>()) << "; wrote " << dir.string()
      << "/{results.md, results.json, results.svg}\n";
  return 0;
}

inline int run_eval(const EvalOptions& o, std::ostream& out) {
  if (o.on_trials) return run_trial_eval_command(o, out);
  o.eval.validate();
  const std::filesystem::path dir = o.out;
  out << "tjepa " << version_string << " " << o.command << ": " << o.eval.seeds.size() << " pre-training seed(s) x "
      << o.eval.head_seeds << " head(s) per task; " << max_threads() << " thread(s)\n" << std::flush;
  const auto t0 = std::chrono::steady_clock::now();
  OutputFiles::check_new(dir / "results.json", o.force);
  make_directories(dir);
  // The tables so far, rewritten (atomically) after every pre-training seed.
  auto write = [&](const GraspEvalResult& r) {
    std::string md = "# " + o.command + "\n\n" + r.main.markdown();
    if (!r.ablation.rows.empty()) md += "\n" + r.ablation.markdown();
    if (!r.linear.rows.empty()) md += "\n" + r.linear.markdown();
    if (!r.ablation_linear.rows.empty()) md += "\n" + r.ablation_linear.markdown();
    write_file_atomic(dir / "results.md", md);
    nlohmann::json j = r.info;
    j["command"] = o.command;
    j["main"] = r.main.to_json();
    if (!r.ablation.rows.empty()) j["ablation"] = r.ablation.to_json();
    if (!r.linear.rows.empty()) j["linear"] = r.linear.to_json();
    if (!r.ablation_linear.rows.empty()) j["ablation_linear"] = r.ablation_linear.to_json();
    write_file_atomic(dir / "results.json", j.dump(2));
    write_file_atomic(dir / "results.svg", r.main.svg());
    if (!r.ablation.rows.empty()) write_file_atomic(dir / "ablation.svg", r.ablation.svg());
    return md;
  };
  const GraspEvalResult r = run_grasp_eval(
      o.eval,
      [&](const std::string& line) {
        if (!o.quiet) {
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          out << "[" << format_duration(s) << "] " << line << "\n" << std::flush;
        }
      },
      write);
  out << "\n" << write(r);
  out << "total " << format_duration(r.info["total_seconds"].get<double>()) << "; wrote " << dir.string()
      << "/{results.md, results.json, results.svg" << (r.ablation.rows.empty() ? "" : ", ablation.svg") << "}\n";
  return 0;
}

// What `tjepa eval` parses: the options, a JSON pre-training config (--config) and the flags that
// override its keys.
struct EvalCommand {
  EvalCommand() = default;
  // add_eval_command's callbacks hold references into this object: it stays where it is.
  EvalCommand(const EvalCommand&) = delete;
  EvalCommand& operator=(const EvalCommand&) = delete;

  EvalOptions options;
  std::string config;
  nlohmann::json overrides = nlohmann::json::object();
  bool pooling_given = false;
  // The flags of one protocol only (set by add_eval_command): given with the other, an error.
  std::vector<CLI::Option*> grasp_only, trials_only;

  void check_flags(bool on_trials) const {
    for (const CLI::Option* f : on_trials ? grasp_only : trials_only)
      require<ConfigError>(f->count() == 0, "tjepa eval: ", f->get_name(), on_trials
                               ? " is for the simulated grasping hand's protocol, not --trials"
                               : " is for the protocol on labelled trials: give --trials TABLE");
    static const char* layout_keys[] = {"layout", "layout_edges", "layout_columns", "bridges", "taxel_order", "tau"};
    for (const char* k : layout_keys)
      require<ConfigError>(on_trials || !overrides.contains(k), "tjepa eval: the ", k,
                           " override is for --trials (the simulated protocol's hand is the Allegro's)");
    require<ConfigError>(!overrides.contains("seed"), "tjepa eval: --seed does not apply; it pre-trains with each of --seeds");
  }

  // The options to run: config file, then flags, applied to the pre-training config; the command
  // line recorded for results.md.
  // notes: where the note of a shortened warm-up goes (nullptr: nowhere).
  EvalOptions resolve(int argc, const char* const* argv, std::ostream* notes = nullptr) const {
    EvalOptions o = options;
    o.on_trials = !o.trial.trials.table.empty();
    check_flags(o.on_trials);
    if (o.on_trials) {  // the shared flags, and tjepa pretrain's defaults rather than the grasp protocol's
      TrialEvalOptions& t = o.trial;
      const GraspEvalConfig& e = o.eval;
      t.seeds = e.seeds, t.head_seeds = e.head_seeds, t.byol_image_size = e.byol_image_size;
      t.mae = e.mae, t.dino = e.dino, t.byol = e.byol, t.end_to_end = e.end_to_end, t.random = e.random, t.jepa = e.jepa;
      t.linear = e.linear_readout, t.ridge = e.ridge;
      if (pooling_given) t.pooling = e.heads.probe_pooling.kind;
      o.eval.train = TrainConfig{};
    }
    if (!config.empty()) o.eval.train.update_from_file(config);
    o.eval.train.update(overrides, "command line");
    NullStream null;
    fit_default_warmup(o.eval.train, overrides, notes ? *notes : null);
    o.command = "tjepa";
    for (int i = 1; i < argc; ++i) o.command += std::string(" ") + argv[i];
    return o;
  }
};

inline CLI::App* add_eval_command(CLI::App& app, EvalCommand& ev) {
  GraspEvalConfig& e = ev.options.eval;
  CLI::App* eval = app.add_subcommand(
      "eval", "The downstream protocol on the simulated grasping hand: seeds x heads, baselines, MAE, mask ablation");
  eval->add_option("--data-seed", e.data_seed, "seed of the simulated session")->capture_default_str();
  eval->add_option("--seeds", e.seeds, "pre-training seeds")->capture_default_str();
  eval->add_option("--head-seeds", e.head_seeds, "heads per task and pre-training seed")->capture_default_str();
  eval->add_option("--pretrain-frames", e.pretrain_frames, "unlabelled frames")->capture_default_str();
  eval->add_option("--train-frames", e.train_frames, "labelled training frames")->capture_default_str();
  eval->add_option("--test-frames", e.test_frames, "labelled held-out frames")->capture_default_str();
  eval->add_option("--max-object-windows", e.tasks.max_object_windows, "object samples per split (0: all)");
  eval->add_option("--max-force-windows", e.tasks.max_force_windows, "force samples per split (0: all)");
  eval->add_option("--max-pose-sequences", e.tasks.max_pose_sequences, "pose sequences per split (0: all)");
  eval->add_option("--head-epochs", e.heads.probe.max_epochs, "object and force probes' epoch limit (early stopping)")->capture_default_str();
  eval->add_option("--head-patience", e.heads.probe.patience, "object and force probes' patience (epochs)")->capture_default_str();
  eval->add_flag("--stop-on-error", e.heads.probe.stop_on_error,
                 "object probe: early stopping on the validation top-1 error instead of the loss");
  eval->add_option("--sequence-epochs", e.heads.sequence.max_epochs, "sequence head's epoch limit")->capture_default_str();
  eval->add_option("--sequence-patience", e.heads.sequence.patience, "sequence head's patience (epochs)")->capture_default_str();
  eval->add_option("--end-to-end-epochs", e.heads.end_to_end_max_epochs, "end-to-end epoch limit")->capture_default_str();
  eval->add_option("--end-to-end-patience", e.heads.end_to_end_patience,
                   "end-to-end patience (epochs; at most the probes' and the sequence head's own)")
      ->capture_default_str();
  eval->add_option("--config", ev.config, "JSON pre-training configuration (TrainConfig keys); flags override it");
  add_run_overrides(eval, ev.overrides);
  eval->add_flag("--no-mae", [&e](std::int64_t) { e.mae = false; }, "skip the MAE row");
  eval->add_flag("--no-dino", [&e](std::int64_t) { e.dino = false; }, "skip the DINO row");
  eval->add_flag("--no-byol", [&e](std::int64_t) { e.byol = false; }, "skip the BYOL row");
  eval->add_option("--byol-image-size", e.byol_image_size, "side of BYOL's images (T-DEX: 224, at least 63)");
  eval->add_flag("--no-ablation", [&e](std::int64_t) { e.ablation = false; }, "skip the mask ablation");
  eval->add_flag("--no-end-to-end", [&e](std::int64_t) { e.end_to_end = false; }, "skip the end-to-end row");
  eval->add_flag("--no-random", [&e](std::int64_t) { e.random = false; }, "skip the random-init row");
  eval->add_flag("--no-jepa", [&e](std::int64_t) { e.jepa = false; },
                 "skip the Tactile-JEPA row (with --no-ablation)");
  eval->add_flag("--no-linear", [&e](std::int64_t) { e.linear_readout = false; },
                 "skip the linear read-out table (ridge on each frozen encoder's pad-mean embeddings and token components)");
  eval->add_flag("--standardize-features", e.heads.standardize_features,
                 "the frozen rows' heads read the embeddings standardized per channel (statistics of the training windows)");
  eval->add_option_function<std::string>(
          "--probe-pooling",
          [&e, &ev](const std::string& v) {
            e.heads.probe_pooling.kind = tjepa::parse_pooling(v);
            ev.pooling_given = true;
          },
          "the probes' pooling of a window: attentive (the paper's; the grasp protocol's default) or taxel (per-taxel "
          "read-out; the default with --trials)")
      ->check(CLI::IsMember({"attentive", "taxel"}));
  eval->add_option_function<std::string>(
          "--sequence-pooling", [&e](const std::string& v) { e.heads.sequence_pooling.kind = tjepa::parse_pooling(v); },
          "the sequence head's pooling of each window: taxel (default) or attentive (the paper's; learns no pose here)")
      ->check(CLI::IsMember({"attentive", "taxel"}));
  eval->add_option_function<int>(
          "--pooling-components",
          [&e](int k) { e.heads.probe_pooling.components = e.heads.sequence_pooling.components = k; },
          "values per taxel of the taxel pooling (default 3)")
      ->check(CLI::PositiveNumber);
  eval->add_option("--out", ev.options.out, "output directory")->capture_default_str();
  eval->add_flag("--force", ev.options.force, "overwrite --out");
  eval->add_flag("--quiet", ev.options.quiet, "no progress lines");
  eval->add_option("--pretrain-cache", e.pretrain_cache,
                   "directory of pre-trained encoders kept between runs: a row and seed found there (same config, "
                   "data, threads and tjepa version) is read instead of pre-trained; new ones are written");
  for (const char* f : {"--data-seed", "--pretrain-frames", "--train-frames", "--test-frames", "--max-object-windows",
                        "--max-force-windows", "--max-pose-sequences", "--head-epochs", "--head-patience",
                        "--stop-on-error", "--sequence-epochs", "--sequence-patience", "--end-to-end-epochs",
                        "--end-to-end-patience", "--no-ablation", "--standardize-features", "--sequence-pooling",
                        "--pooling-components", "--pretrain-cache"})
    ev.grasp_only.push_back(eval->get_option(f));
  // The protocol on labelled trials (trial_eval.hpp).
  TrialEvalOptions& t = ev.options.trial;
  const std::size_t before = eval->get_options().size();
  add_trial_options(eval, t.trials);
  eval->add_option("--test-fraction", t.test_fraction, "--trials without a split column: the share of trials held out")
      ->capture_default_str();
  add_data_format(eval, t.format);
  eval->add_option("--task", t.task, "--trials: classification (the labels are classes) or regression (numbers)")
      ->check(CLI::IsMember({"classification", "regression"}))
      ->capture_default_str();
  eval->add_option("--preprocess", t.preprocess, "--trials: auto | baseline | standardize | none")->capture_default_str();
  eval->add_option("--label-fractions", t.label_fractions,
                   "--trials: shares of the training trials labelled for the heads (per class, at least 2 trials)")
      ->capture_default_str();
  eval->add_option("--max-windows", t.max_windows, "--trials: training windows the heads draw from (seeded; 0: all)")
      ->capture_default_str();
  eval->add_option("--max-test-windows", t.max_test_windows, "--trials: held-out windows scored (seeded; 0: all)")
      ->capture_default_str();
  eval->add_option("--head-steps", t.head_steps, "--trials: frozen heads' steps at most")->capture_default_str();
  eval->add_option("--head-patience-steps", t.head_patience_steps, "--trials: frozen heads' early-stopping patience (steps)")
      ->capture_default_str();
  eval->add_option("--head-lr", t.head.lr, "--trials: heads' learning rate")->capture_default_str();
  eval->add_option("--head-folds", t.head_folds,
                   "--trials: on shares of fewer labelled trials than --head-folds-below, heads pick their epochs by "
                   "cross-validation over this many folds of trials (1: one validation split)")
      ->check(CLI::Range(1, 20))
      ->capture_default_str();
  eval->add_option("--head-folds-below", t.head_folds_below, "--trials: see --head-folds")->capture_default_str();
  eval->add_option_function<std::string>(
          "--head-stop", [&t](const std::string& v) { t.head.stop_on_error = v == "error"; },
          "--trials: classification heads keep the epoch of the lowest validation top-1 error (the loss breaking "
          "ties; default) or of the lowest loss")
      ->check(CLI::IsMember({"error", "loss"}));
  eval->add_option("--end-to-end-steps", t.end_to_end_steps, "--trials: end-to-end heads' steps at most")
      ->capture_default_str();
  eval->add_option("--end-to-end-patience-steps", t.end_to_end_patience_steps,
                   "--trials: end-to-end early-stopping patience (steps)")
      ->capture_default_str();
  for (std::size_t k = before; k < eval->get_options().size(); ++k) ev.trials_only.push_back(eval->get_options()[k]);
  std::erase_if(ev.trials_only, [&](const CLI::Option* f) { return f->get_name() == "--trials"; });
  return eval;
}

// tjepa demo: tjepa eval cut to one seed and one head per task.
struct DemoOptions {
  std::uint64_t seed = 0;
  std::string out = "runs/demo";
  bool quiet = false;
  nlohmann::json overrides = nlohmann::json::object();  // --steps, --warmup
};

inline CLI::App* add_demo_command(CLI::App& app, DemoOptions& o) {
  CLI::App* sub = app.add_subcommand(
      "demo", "tjepa eval cut to one seed and one head per task: pre-train on the simulated grasping hand, then "
      "object / force / pose against baselines");
  sub->add_option("--seed", o.seed, "seed of everything (data, init, masks, heads)")->capture_default_str();
  sub->add_option("--out", o.out, "output directory")->capture_default_str();
  run_override<int>(sub, "--steps", "steps", o.overrides, "pre-training steps");
  run_override<int>(sub, "--warmup", "warmup_steps", o.overrides, "pre-training warm-up steps");
  sub->add_flag("--quiet", o.quiet, "no progress lines");
  return sub;
}

inline int run_demo(const DemoOptions& d, std::ostream& out) {
  EvalOptions o = demo_eval_options(d.seed);
  o.out = d.out;
  o.quiet = d.quiet;
  o.eval.train.update(d.overrides, "command line");
  fit_default_warmup(o.eval.train, d.overrides, out);
  return run_eval(o, out);
}

}  // namespace tjepa::cli
