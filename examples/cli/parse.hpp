#pragma once
// The command line of `tjepa eval` (and the pre-training overrides every training subcommand
// shares), apart from main so that the tests parse what a user types.
#include <CLI/CLI.hpp>

#include <string>

#include <nlohmann/json.hpp>

#include "eval.hpp"
#include "setup.hpp"

namespace tjepa::cli {

// --<flag> VALUE sets key in the JSON of TrainConfig overrides.
template <class T>
void run_override(CLI::App* app, const std::string& flag, const std::string& key, nlohmann::json& j,
                  const std::string& help) {
  app->add_option_function<T>(flag, [&j, key](const T& v) { j[key] = v; }, help);
}

// The options of how recordings are read (DataFormat).
inline void add_data_format(CLI::App* app, DataFormat& f) {
  app->add_option("--axes", f.axes, "axes per taxel of text recordings")->capture_default_str();
  app->add_option("--columns", f.columns, "text recordings: the columns of the taxels' values, e.g. 0:60 (end exclusive)");
  app->add_option("--skip-rows", f.skip_rows, "text recordings: header lines to skip (-1: detect one)")->capture_default_str();
  app->add_option("--non-finite", f.non_finite, "NaN/Inf readings: error | hold (last finite value) | interpolate | zero | drop (the windows that hold one)")
      ->capture_default_str();
}

inline void add_run_overrides(CLI::App* app, nlohmann::json& j) {
  run_override<std::string>(app, "--layout", "layout", j, "built-in layout (allegro, grid, two-part) or layout CSV");
  run_override<std::string>(app, "--edges", "layout_edges", j, "edges CSV of a layout CSV (default: inferred)");
  run_override<std::string>(app, "--layout-columns", "layout_columns", j,
                            "the layout CSV's column names, e.g. x=visual_x,y=visual_y");
  run_override<std::string>(app, "--bridges", "bridges", j, "inferred graphs: connect | near | none");
  run_override<std::string>(app, "--order", "taxel_order", j,
                            "recordings' taxel order: xserver | reference (allegro) | id,column CSV");
  run_override<int>(app, "--tau", "tau", j, "frames per window");
  run_override<int>(app, "--dim", "dim", j, "encoder width d");
  run_override<int>(app, "--depth", "depth", j, "encoder blocks");
  run_override<int>(app, "--heads", "heads", j, "attention heads");
  run_override<int>(app, "--predictor-depth", "predictor_depth", j, "predictor blocks");
  run_override<int>(app, "--steps", "steps", j, "optimizer steps");
  run_override<int>(app, "--batch", "batch", j, "windows per step");
  run_override<int>(app, "--warmup", "warmup_steps", j, "learning-rate warm-up steps");
  run_override<double>(app, "--lr", "lr", j, "peak learning rate");
  run_override<double>(app, "--drop-path", "drop_path", j, "stochastic depth rate");
  run_override<std::string>(app, "--precision", "precision", j, "arithmetic of the products: fp32 or bf16 (AVX512-BF16)");
  run_override<double>(app, "--ema-start", "ema_start", j, "initial EMA momentum of the target encoder");
  run_override<double>(app, "--tokenizer-bias", "tokenizer_bias_std", j, "std of the tokenizer's initial bias (reference: 0)");
  run_override<std::uint64_t>(app, "--seed", "seed", j, "random seed (init, masks, data order, simulation)");
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

  // The options to run: config file, then flags, applied to the pre-training config; the command
  // line recorded for results.md.
  // notes: where the note of a shortened warm-up goes (nullptr: nowhere).
  EvalOptions resolve(int argc, const char* const* argv, std::ostream* notes = nullptr) const {
    EvalOptions o = options;
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
  run_override<int>(eval, "--steps", "steps", ev.overrides, "pre-training steps");
  run_override<int>(eval, "--warmup", "warmup_steps", ev.overrides, "pre-training warm-up steps");
  run_override<int>(eval, "--batch", "batch", ev.overrides, "pre-training batch");
  run_override<int>(eval, "--dim", "dim", ev.overrides, "encoder width d");
  run_override<int>(eval, "--depth", "depth", ev.overrides, "encoder blocks");
  run_override<std::string>(eval, "--precision", "precision", ev.overrides,
                            "arithmetic of the pre-training products: fp32 or bf16 (AVX512-BF16)");
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
          "--probe-pooling", [&e](const std::string& v) { e.heads.probe_pooling.kind = tjepa::parse_pooling(v); },
          "the object and force probes' pooling of a window: attentive (the paper's, default) or taxel (per-taxel read-out)")
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
  return eval;
}

}  // namespace tjepa::cli
