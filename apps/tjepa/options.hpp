#pragma once
// The options several subcommands share: the pre-training overrides (--steps, --dim, ...) and
// how recordings are read (--axes, --columns, ...).
#include <CLI/CLI.hpp>

#include <string>

#include <nlohmann/json.hpp>

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
  app->add_option("--lines-per-frame", f.lines_per_frame, "text recordings: lines that make one frame, their columns "
                  "joined (the iCub grasp dataset: 7)")->capture_default_str();
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

}  // namespace tjepa::cli
