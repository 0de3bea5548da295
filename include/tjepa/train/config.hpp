#pragma once
// TrainConfig: everything that defines a pre-training run, composed of the modules' configs:
//   data      DataConfig       the skin and its windows (read by the `tjepa` command and the data layer)
//   model     ModelConfig      the encoder's and predictor's sizes (model_config() gives the JepaConfig)
//   masks     MaskConfig       the mask sampler's (masks/config.hpp)
//   step      JepaStepConfig   the loss, stochastic depth, clipping, precision (train/jepa_step.hpp)
//   adamw     AdamWConfig      AdamW's betas and eps (optim/adamw.hpp)
//   schedule  ScheduleConfig   steps, learning rate, weight decay and EMA schedules (build(): TrainingSchedule)
//   batch, seed
// Each setting has one default, in the module's config. The JSON form is flat, one key per
// setting ({"steps": 2000, "beta2": 0.99, "precision": "bf16", "context_ratio": [0.5, 0.9]}), so
// that run files, command-line overrides and checkpoints name settings the same way;
// for_each_field is the table from keys to fields.
// The Trainer, `tjepa pretrain`, `tjepa demo` and checkpoints all use it: a checkpoint stores it
// under "train" in its config metadata, and Trainer::resume continues only a run with an equal one.
//
//   TrainConfig c = TrainConfig::from_file("run.json");   // unknown keys and wrong types throw
//   c.update({{"steps", 2000}, {"beta2", 0.99}}, "command line");
//   c.schedule.steps = 3000;                               // or set the module config's field
//   c.validate();                                          // every bad value named by its key
//
// The defaults are a short run on one machine (a peak rate above the reference's 1e-4, which is
// set for 500 epochs); TrainConfig::reference gives the paper's training setup (Sec. IV-D) for a data set size.
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/graph/spectral_positions.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/jepa_step.hpp"

namespace tjepa {

// The skin a run trains on and its windows. The `tjepa` command reads the skin; the library
// takes the layout and recordings as objects.
struct DataConfig {
  // A built-in layout's name or a layout CSV; its edges CSV ("": built in, or inferred from the
  // coordinates by the bridge rule connect | near | none); the CSV's column names
  // ("x=visual_x,y=visual_y"; "": the defaults); the order of the recordings' taxel columns ("":
  // the layout's own; "xserver" or "reference" for the Allegro hand; or an order CSV of id,column).
  std::string layout = "allegro";
  std::string layout_edges, layout_columns, bridges = "connect", taxel_order;
  int tau = 10;  // frames per window
  // DriftTracker's time constant in frames for recordings with a no-contact baseline; 0 = off
  // (the reference's one fixed baseline).
  double drift_time_constant = 0.0;
};

// The model's free sizes; the rest of the JepaConfig follows from the skin (TrainConfig::model_config).
struct ModelConfig {
  int dim = 96, depth = 4, heads = 3;  // the encoder's width, depth and heads
  int predictor_depth = 2;             // the predictor's depth (its width and heads are the encoder's)
  double tokenizer_bias_std = 1.0;     // JepaConfig::tokenizer_bias_std (the reference: 0)
  // The position table's start: 0 = the reference's N(0, 0.02²); k > 0 = the graph's k smallest
  // Laplacian eigenvectors at RMS position_scale (graph_positions).
  int position_eigenvectors = 0;
  double position_scale = 1.0;
};

// The schedules of a run, in optimizer steps: warm-up from start_lr to lr, then cosine to
// final_lr; cosine-increasing weight decay; the target encoder's EMA momentum, linear.
struct ScheduleConfig {
  std::int64_t steps = 600, warmup_steps = 60;
  double lr = 1e-3, start_lr = 1e-4, final_lr = 1e-5;
  double wd_start = 0.04, wd_end = 0.4;
  // Which step of the weight-decay schedule an update uses: the Tactile-JEPA code's (update s at
  // wd(s)) or I-JEPA's loop (wd(s + 1)).
  WeightDecayTiming wd_timing = TrainingSchedule{}.wd_timing;
  // The first update's weight decay under the reference timing: the reference's AdamW
  // constructor value (its optim_cfg weight_decay); -1: wd(0) = wd_start.
  double wd_initial = 0.05;
  double ema_start = 0.99, ema_end = 1.0;

  TrainingSchedule build() const {
    TrainingSchedule s;
    s.lr = WarmupCosineLr{start_lr, lr, final_lr, warmup_steps, steps};
    s.wd = CosineWeightDecay{wd_start, wd_end, steps};
    s.momentum = LinearMomentum{ema_start, ema_end, steps};
    s.wd_timing = wd_timing;
    s.wd_initial = wd_initial;
    s.validate();
    return s;
  }
};

struct TrainConfig {
  DataConfig data;
  ModelConfig model;
  MaskConfig masks;
  JepaStepConfig step;
  AdamWConfig adamw;
  ScheduleConfig schedule;
  int batch = 32;
  std::uint64_t seed = 0;  // init, data order, masks, drop-path noise

  // Calls f(key, field) for every setting of the JSON form: one table serves to_json, update and
  // the unknown-key check. MaskConfig::num_threads is not a setting (results never depend on it).
  template <class Self, class F>
  static void for_each_field(Self& c, F&& f) {
    auto& d = c.data;
    f("layout", d.layout), f("layout_edges", d.layout_edges), f("layout_columns", d.layout_columns);
    f("bridges", d.bridges), f("taxel_order", d.taxel_order), f("tau", d.tau);
    f("drift_time_constant", d.drift_time_constant);
    auto& m = c.model;
    f("dim", m.dim), f("depth", m.depth), f("heads", m.heads), f("predictor_depth", m.predictor_depth);
    f("tokenizer_bias_std", m.tokenizer_bias_std), f("position_eigenvectors", m.position_eigenvectors);
    f("position_scale", m.position_scale);
    auto& k = c.masks;
    f("context_ratio", k.context_ratio), f("target_ratio", k.target_ratio);
    f("local_targets", k.num_local), f("global_targets", k.num_global);
    f("local_targets_per_part", k.num_local_per_part), f("global_targets_per_part", k.num_global_per_part);
    f("part_targets", k.part_targets), f("global_sampling", k.global_sampling);
    f("context_sampling", k.context_sampling), f("mask_scheme", k.scheme);
    f("block_target_scale", k.blocks.target_scale), f("block_target_aspect", k.blocks.target_aspect);
    f("block_context_scale", k.blocks.context_scale), f("block_context_aspect", k.blocks.context_aspect);
    f("block_targets", k.blocks.num_targets);
    f("min_context_tokens", k.min_context_tokens), f("min_context_ratio", k.min_context_ratio);
    f("mask_max_tries", k.max_tries);
    auto& st = c.step;
    f("loss", st.loss), f("normalize_targets", st.normalize_targets);
    f("standardize_targets", st.standardize_targets);
    f("predictor_pos_from_context", st.predictor_pos_from_context);
    f("drop_path", st.drop_path), f("target_drop_path", st.target_drop_path);
    f("clip_grad_norm", st.clip_grad_norm), f("precision", st.precision);
    auto& s = c.schedule;
    f("steps", s.steps), f("warmup_steps", s.warmup_steps), f("batch", c.batch);
    f("lr", s.lr), f("start_lr", s.start_lr), f("final_lr", s.final_lr);
    f("wd_start", s.wd_start), f("wd_end", s.wd_end), f("weight_decay_timing", s.wd_timing);
    f("wd_initial", s.wd_initial);
    f("beta1", c.adamw.beta1), f("beta2", c.adamw.beta2), f("eps", c.adamw.eps);
    f("ema_start", s.ema_start), f("ema_end", s.ema_end), f("seed", c.seed);
  }

  nlohmann::json to_json() const {
    nlohmann::json j = nlohmann::json::object();
    for_each_field(*this, [&](const char* key, const auto& v) { j[key] = json_value(v); });
    return j;
  }

  // Overrides the settings j names. An unknown key or a value of the wrong type throws ConfigError
  // naming `source` and the key; nothing changes then. Values are checked by validate().
  void update(const nlohmann::json& j, const std::string& source) {
    require<ConfigError>(j.is_object(), source, ": expected a JSON object of run settings, got ", j.type_name());
    std::set<std::string> known;
    for_each_field(*this, [&](const char* key, const auto&) { known.insert(key); });
    for (const auto& [k, v] : j.items())
      if (!known.contains(k)) {
        std::string list;
        for (const auto& name : known) list += (list.empty() ? "" : ", ") + name;
        fail<ConfigError>(source, ": unknown key '", k, "' (known: ", list, ")");
      }
    TrainConfig next = *this;
    for_each_field(next, [&](const char* key, auto& field) {
      if (j.contains(key)) json_read(j, key, field, source);
    });
    *this = std::move(next);
  }

  static TrainConfig from_json(const nlohmann::json& j, const std::string& source) {
    TrainConfig c;
    c.update(j, source);
    return c;
  }

  void update_from_file(const std::filesystem::path& path) {
    std::ifstream in(path);
    require<FileError>(static_cast<bool>(in), "cannot open config file '", path.string(), "'");
    const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    update(json_parse(text, path.string()), path.string());
  }
  static TrainConfig from_file(const std::filesystem::path& path) {
    TrainConfig c;
    c.update_from_file(path);
    return c;
  }

  // The paper's training setup (Sec. IV-D) for a data set of steps_per_epoch batches of 256: 500 epochs, 30 of warm-up,
  // lr 1e-5 → 1e-4 → 1e-6, EMA 0.994 → 1, drop-path 0.3, ViT-Tiny with a 4-block predictor.
  static TrainConfig reference(std::int64_t steps_per_epoch) {
    require<ConfigError>(steps_per_epoch > 0, "TrainConfig::reference: steps_per_epoch = ", steps_per_epoch,
                         ", expected > 0");
    TrainConfig c;
    c.model.dim = 192, c.model.depth = 12, c.model.heads = 3, c.model.predictor_depth = 4;
    c.model.tokenizer_bias_std = 0.0;
    c.step.drop_path = 0.3;
    c.batch = 256;
    c.schedule.steps = 500 * steps_per_epoch;
    c.schedule.warmup_steps = 30 * steps_per_epoch;
    c.schedule.lr = 1e-4, c.schedule.start_lr = 1e-5, c.schedule.final_lr = 1e-6;
    c.schedule.ema_start = 0.994;
    return c;
  }

  void validate() const {
    auto check = [](bool ok, const char* key, const auto& value, const char* expected) {
      require<ConfigError>(ok, "config: ", key, " = ", json_value(value).dump(), ", expected ", expected);
    };
    auto finite_pos = [](double v) { return std::isfinite(v) && v > 0; };
    const DataConfig& d = data;
    check(d.tau > 0, "tau", d.tau, "> 0");
    check(d.drift_time_constant == 0 || (std::isfinite(d.drift_time_constant) && d.drift_time_constant >= 1),
          "drift_time_constant", d.drift_time_constant, "0 (off) or >= 1 frame");
    check(d.bridges == "connect" || d.bridges == "near" || d.bridges == "none", "bridges", d.bridges,
          "'connect', 'near' or 'none'");
    const ModelConfig& m = model;
    check(m.dim > 0, "dim", m.dim, "> 0");
    check(m.heads > 0 && m.dim % m.heads == 0, "heads", m.heads, "> 0 and dividing dim");
    check(m.depth > 0, "depth", m.depth, "> 0");
    check(m.predictor_depth > 0, "predictor_depth", m.predictor_depth, "> 0");
    check(m.tokenizer_bias_std >= 0 && std::isfinite(m.tokenizer_bias_std), "tokenizer_bias_std",
          m.tokenizer_bias_std, ">= 0");
    check(m.position_eigenvectors >= 0, "position_eigenvectors", m.position_eigenvectors,
          ">= 0 (0: a random table)");
    check(finite_pos(m.position_scale), "position_scale", m.position_scale, "> 0");
    const MaskConfig& k = masks;
    check(k.num_local >= 0 && k.num_global >= 0 && k.num_local + k.num_global > 0, "local_targets",
          std::array<int, 2>{k.num_local, k.num_global},
          "local_targets and global_targets >= 0 and at least one target");
    check(k.min_context_tokens >= 1 || k.min_context_tokens == -1, "min_context_tokens", k.min_context_tokens,
          ">= 1, or -1 (automatic: 32, or half the smallest context on a small skin)");
    validate_mask_config(k);
    const JepaStepConfig& st = step;
    check(st.drop_path >= 0 && st.drop_path < 1, "drop_path", st.drop_path, "in [0, 1)");
    check(finite_pos(st.clip_grad_norm), "clip_grad_norm", st.clip_grad_norm, "> 0");
    const ScheduleConfig& s = schedule;
    check(s.steps > 0, "steps", s.steps, "> 0");
    check(s.warmup_steps >= 0 && s.warmup_steps <= s.steps, "warmup_steps", s.warmup_steps, "in [0, steps]");
    check(batch > 0, "batch", batch, "> 0");
    check(finite_pos(s.lr), "lr", s.lr, "> 0");
    check(finite_pos(s.start_lr), "start_lr", s.start_lr, "> 0");
    check(finite_pos(s.final_lr), "final_lr", s.final_lr, "> 0");
    check(s.wd_start >= 0 && std::isfinite(s.wd_start), "wd_start", s.wd_start, ">= 0");
    check(s.wd_end >= 0 && std::isfinite(s.wd_end), "wd_end", s.wd_end, ">= 0");
    check(s.wd_initial == -1 || (s.wd_initial >= 0 && std::isfinite(s.wd_initial)), "wd_initial", s.wd_initial,
          ">= 0, or -1 (wd_start)");
    check(adamw.beta1 >= 0 && adamw.beta1 < 1, "beta1", adamw.beta1, "in [0, 1)");
    check(adamw.beta2 >= 0 && adamw.beta2 < 1, "beta2", adamw.beta2, "in [0, 1)");
    check(finite_pos(adamw.eps), "eps", adamw.eps, "> 0");
    check(s.ema_start >= 0 && s.ema_start <= 1, "ema_start", s.ema_start, "in [0, 1]");
    check(s.ema_end >= 0 && s.ema_end <= 1, "ema_end", s.ema_end, "in [0, 1]");
  }

  // The model over num_tokens tokens of m = axes values per frame.
  JepaConfig model_config(int num_tokens, int axes) const {
    JepaConfig c = JepaConfig::reference(num_tokens, data.tau * axes, axes);
    c.encoder.dim = model.dim;
    c.encoder.depth = model.depth;
    c.encoder.heads = model.heads;
    c.predictor.in_dim = model.dim;
    c.predictor.dim = model.dim;
    c.predictor.depth = model.predictor_depth;
    c.predictor.heads = model.heads;
    c.tokenizer_bias_std = model.tokenizer_bias_std;
    return c;
  }
};

// A new model for config c over `graph` (one token per node) of m = axes values per frame,
// initialized from init_seed (with graph positions when c.model.position_eigenvectors > 0).
template <class T = float>
std::unique_ptr<JepaModel<T>> make_jepa_model(const TrainConfig& c, const TaxelGraph& graph, int axes,
                                              std::uint64_t init_seed) {
  c.validate();
  auto m = std::make_unique<JepaModel<T>>(c.model_config(graph.num_nodes(), axes), init_seed);
  const ModelConfig& mc = c.model;
  if (mc.position_eigenvectors > 0) {
    require<ConfigError>(mc.position_eigenvectors <= graph.num_nodes(), "config: position_eigenvectors = ",
                         mc.position_eigenvectors, ", expected at most the ", graph.num_nodes(), " tokens");
    m->set_positions(graph_positions(graph, mc.dim, mc.position_eigenvectors, mc.position_scale, init_seed));
  }
  return m;
}

}  // namespace tjepa
