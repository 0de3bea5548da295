#pragma once
// TrainConfig: everything that defines a pre-training run, in one flat struct with one JSON form.
// It is the flat view of the modules' configs: masks() gives the MaskConfig, step() the
// JepaStepConfig, adamw() the AdamWConfig, schedule() the TrainingSchedule, model() the
// JepaConfig. Each setting that a module's config has takes its default from there (one default
// per setting); the others are the run's own (data, model size, schedule, seed).
// The Trainer, `tjepa pretrain`, `tjepa demo` and checkpoints all use it: a checkpoint stores it
// under "train" in its config metadata, and Trainer::resume continues only a run with an equal one.
//
//   TrainConfig c = TrainConfig::from_file("run.json");   // unknown keys and wrong types throw
//   c.update({{"steps", 2000}, {"beta2", 0.99}}, "command line");
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

struct TrainConfig {
  // Data.
  // The skin (recorded, not read here; the `tjepa` command reads it): a built-in layout's name or
  // a layout CSV; its edges CSV ("": built in, or inferred from the coordinates by the bridge rule
  // connect | near | none); the CSV's column names ("x=visual_x,y=visual_y"; "": the defaults);
  // the order of the recordings' taxel columns ("": the layout's own; "xserver" or "reference" for
  // the Allegro hand; or an order CSV of id,column).
  std::string layout = "allegro";
  std::string layout_edges, layout_columns, bridges = "connect", taxel_order;
  int tau = 10;                    // frames per window
  // DriftTracker's time constant in frames for recordings with a no-contact baseline; 0 = off
  // (the reference's one fixed baseline).
  double drift_time_constant = 0.0;
  // Model (JepaConfig): encoder width, depth, heads; the predictor's depth (its width is the encoder's).
  int dim = 96, depth = 4, heads = 3, predictor_depth = 2;
  double tokenizer_bias_std = 1.0;  // JepaConfig::tokenizer_bias_std (the reference: 0)
  // The position table's start: 0 = the reference's N(0, 0.02²); k > 0 = the graph's k smallest
  // Laplacian eigenvectors at RMS position_scale (graph_positions).
  int position_eigenvectors = 0;
  double position_scale = 1.0;
  // Masks (MaskConfig).
  std::array<double, 2> context_ratio{MaskConfig{}.context_ratio.lo, MaskConfig{}.context_ratio.hi};
  std::array<double, 2> target_ratio{MaskConfig{}.target_ratio.lo, MaskConfig{}.target_ratio.hi};
  int local_targets = MaskConfig{}.num_local, global_targets = MaskConfig{}.num_global;
  int min_context_tokens = MaskConfig{}.min_context_tokens;
  // Objective (JepaStepConfig).
  std::string loss = to_string(JepaStepConfig{}.loss);  // "mse" (the reference) or "smooth_l1" (I-JEPA)
  bool normalize_targets = JepaStepConfig{}.normalize_targets;
  bool standardize_targets = JepaStepConfig{}.standardize_targets;
  bool predictor_pos_from_context = JepaStepConfig{}.predictor_pos_from_context;
  double drop_path = JepaStepConfig{}.drop_path;
  bool target_drop_path = JepaStepConfig{}.target_drop_path;
  double clip_grad_norm = JepaStepConfig{}.clip_grad_norm;
  // Of the products: "fp32" or "bf16" (JepaStepConfig::precision).
  std::string precision = precision_name(JepaStepConfig{}.precision);
  // Optimizer and schedules (in optimizer steps).
  std::int64_t steps = 600, warmup_steps = 60;
  int batch = 32;
  double lr = 1e-3, start_lr = 1e-4, final_lr = 1e-5;  // warm-up start_lr → lr, then cosine to final_lr
  double wd_start = 0.04, wd_end = 0.4;                // cosine-increasing weight decay
  // Which step of the weight-decay schedule an update uses: "reference" (the Tactile-JEPA code's:
  // update s at wd(s)) or "ijepa" (I-JEPA's loop: wd(s + 1)); TrainingSchedule::wd_timing.
  std::string weight_decay_timing = to_string(TrainingSchedule{}.wd_timing);
  // The first update's weight decay under the reference timing: the reference's AdamW constructor
  // value (its optim_cfg weight_decay); -1: wd(0) = wd_start. TrainingSchedule::wd_initial.
  double wd_initial = 0.05;
  double beta1 = AdamWConfig{}.beta1, beta2 = AdamWConfig{}.beta2, eps = AdamWConfig{}.eps;  // AdamW
  double ema_start = 0.99, ema_end = 1.0;              // the target encoder's EMA momentum, linear
  std::uint64_t seed = 0;                              // init, data order, masks, drop-path noise

  // Calls f(key, field) for every field, in the JSON's order: one table serves to_json, update
  // and the unknown-key check.
  template <class Self, class F>
  static void for_each_field(Self& c, F&& f) {
    f("layout", c.layout), f("layout_edges", c.layout_edges), f("layout_columns", c.layout_columns);
    f("bridges", c.bridges), f("taxel_order", c.taxel_order), f("tau", c.tau), f("drift_time_constant", c.drift_time_constant);
    f("dim", c.dim), f("depth", c.depth), f("heads", c.heads), f("predictor_depth", c.predictor_depth);
    f("tokenizer_bias_std", c.tokenizer_bias_std), f("position_eigenvectors", c.position_eigenvectors);
    f("position_scale", c.position_scale);
    f("context_ratio", c.context_ratio), f("target_ratio", c.target_ratio);
    f("local_targets", c.local_targets), f("global_targets", c.global_targets);
    f("min_context_tokens", c.min_context_tokens);
    f("loss", c.loss), f("normalize_targets", c.normalize_targets), f("standardize_targets", c.standardize_targets);
    f("predictor_pos_from_context", c.predictor_pos_from_context);
    f("drop_path", c.drop_path), f("target_drop_path", c.target_drop_path), f("clip_grad_norm", c.clip_grad_norm);
    f("precision", c.precision);
    f("steps", c.steps), f("warmup_steps", c.warmup_steps), f("batch", c.batch);
    f("lr", c.lr), f("start_lr", c.start_lr), f("final_lr", c.final_lr);
    f("wd_start", c.wd_start), f("wd_end", c.wd_end), f("weight_decay_timing", c.weight_decay_timing);
    f("wd_initial", c.wd_initial);
    f("beta1", c.beta1), f("beta2", c.beta2), f("eps", c.eps);
    f("ema_start", c.ema_start), f("ema_end", c.ema_end), f("seed", c.seed);
  }

  nlohmann::json to_json() const {
    nlohmann::json j = nlohmann::json::object();
    for_each_field(*this, [&](const char* key, const auto& v) { j[key] = v; });
    return j;
  }

  // Overrides the fields j names. An unknown key or a value of the wrong type throws ConfigError
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
    c.dim = 192, c.depth = 12, c.heads = 3, c.predictor_depth = 4;
    c.tokenizer_bias_std = 0.0;
    c.drop_path = 0.3;
    c.batch = 256;
    c.steps = 500 * steps_per_epoch;
    c.warmup_steps = 30 * steps_per_epoch;
    c.lr = 1e-4, c.start_lr = 1e-5, c.final_lr = 1e-6;
    c.ema_start = 0.994;
    return c;
  }

  void validate() const {
    auto check = [](bool ok, const char* key, const auto& value, const char* expected) {
      require<ConfigError>(ok, "config: ", key, " = ", nlohmann::json(value).dump(), ", expected ", expected);
    };
    auto finite_pos = [](double v) { return std::isfinite(v) && v > 0; };
    check(tau > 0, "tau", tau, "> 0");
    check(drift_time_constant == 0 || (std::isfinite(drift_time_constant) && drift_time_constant >= 1),
          "drift_time_constant", drift_time_constant, "0 (off) or >= 1 frame");
    check(dim > 0, "dim", dim, "> 0");
    check(heads > 0 && dim % heads == 0, "heads", heads, "> 0 and dividing dim");
    check(depth > 0, "depth", depth, "> 0");
    check(predictor_depth > 0, "predictor_depth", predictor_depth, "> 0");
    check(tokenizer_bias_std >= 0 && std::isfinite(tokenizer_bias_std), "tokenizer_bias_std", tokenizer_bias_std,
          ">= 0");
    check(position_eigenvectors >= 0, "position_eigenvectors", position_eigenvectors, ">= 0 (0: a random table)");
    check(finite_pos(position_scale), "position_scale", position_scale, "> 0");
    check(local_targets >= 0 && global_targets >= 0 && local_targets + global_targets > 0, "local_targets",
          std::array<int, 2>{local_targets, global_targets},
          "local_targets and global_targets >= 0 and at least one target");
    check(min_context_tokens >= 1 || min_context_tokens == -1, "min_context_tokens", min_context_tokens,
          ">= 1, or -1 (automatic: 32, or half the smallest context on a small skin)");
    check(bridges == "connect" || bridges == "near" || bridges == "none", "bridges", bridges,
          "'connect', 'near' or 'none'");
    check(loss == "mse" || loss == "smooth_l1", "loss", loss, "'mse' or 'smooth_l1'");
    check(drop_path >= 0 && drop_path < 1, "drop_path", drop_path, "in [0, 1)");
    check(precision == "fp32" || precision == "bf16", "precision", precision, "'fp32' or 'bf16'");
    check(finite_pos(clip_grad_norm), "clip_grad_norm", clip_grad_norm, "> 0");
    check(steps > 0, "steps", steps, "> 0");
    check(warmup_steps >= 0 && warmup_steps <= steps, "warmup_steps", warmup_steps, "in [0, steps]");
    check(batch > 0, "batch", batch, "> 0");
    check(finite_pos(lr), "lr", lr, "> 0");
    check(finite_pos(start_lr), "start_lr", start_lr, "> 0");
    check(finite_pos(final_lr), "final_lr", final_lr, "> 0");
    check(wd_start >= 0 && std::isfinite(wd_start), "wd_start", wd_start, ">= 0");
    check(wd_end >= 0 && std::isfinite(wd_end), "wd_end", wd_end, ">= 0");
    check(weight_decay_timing == "reference" || weight_decay_timing == "ijepa", "weight_decay_timing",
          weight_decay_timing, "'reference' or 'ijepa'");
    check(wd_initial == -1 || (wd_initial >= 0 && std::isfinite(wd_initial)), "wd_initial", wd_initial,
          ">= 0, or -1 (wd_start)");
    check(beta1 >= 0 && beta1 < 1, "beta1", beta1, "in [0, 1)");
    check(beta2 >= 0 && beta2 < 1, "beta2", beta2, "in [0, 1)");
    check(finite_pos(eps), "eps", eps, "> 0");
    check(ema_start >= 0 && ema_start <= 1, "ema_start", ema_start, "in [0, 1]");
    check(ema_end >= 0 && ema_end <= 1, "ema_end", ema_end, "in [0, 1]");
    const MaskConfig m = masks();
    detail::check_ratio_range(m.context_ratio, "context_ratio");
    detail::check_ratio_range(m.target_ratio, "target_ratio");
  }

  // The model over num_tokens tokens of m = axes values per frame.
  JepaConfig model(int num_tokens, int axes) const {
    JepaConfig c = JepaConfig::reference(num_tokens, tau * axes, axes);
    c.encoder.dim = dim;
    c.encoder.depth = depth;
    c.encoder.heads = heads;
    c.predictor.in_dim = dim;
    c.predictor.dim = dim;
    c.predictor.depth = predictor_depth;
    c.predictor.heads = heads;
    c.tokenizer_bias_std = tokenizer_bias_std;
    return c;
  }
  MaskConfig masks() const {
    MaskConfig m;
    m.context_ratio = {context_ratio[0], context_ratio[1]};
    m.target_ratio = {target_ratio[0], target_ratio[1]};
    m.num_local = local_targets;
    m.num_global = global_targets;
    m.min_context_tokens = min_context_tokens;
    return m;
  }
  JepaStepConfig step() const {
    JepaStepConfig c;
    c.loss = loss == "smooth_l1" ? JepaLossKind::smooth_l1 : JepaLossKind::mse;
    c.normalize_targets = normalize_targets;
    c.standardize_targets = standardize_targets;
    c.predictor_pos_from_context = predictor_pos_from_context;
    c.drop_path = drop_path;
    c.target_drop_path = target_drop_path;
    c.clip_grad_norm = clip_grad_norm;
    c.precision = precision == "bf16" ? Precision::bf16 : Precision::fp32;
    return c;
  }
  AdamWConfig adamw() const { return AdamWConfig{beta1, beta2, eps}; }
  TrainingSchedule schedule() const {
    TrainingSchedule s;
    s.lr = WarmupCosineLr{start_lr, lr, final_lr, warmup_steps, steps};
    s.wd = CosineWeightDecay{wd_start, wd_end, steps};
    s.momentum = LinearMomentum{ema_start, ema_end, steps};
    s.wd_timing = weight_decay_timing == "ijepa" ? WeightDecayTiming::ijepa : WeightDecayTiming::reference;
    s.wd_initial = wd_initial;
    s.validate();
    return s;
  }
};

// A new model for config c over `graph` (one token per node) of m = axes values per frame,
// initialized from init_seed (with graph positions when c.position_eigenvectors > 0).
template <class T = float>
std::unique_ptr<JepaModel<T>> make_jepa_model(const TrainConfig& c, const TaxelGraph& graph, int axes,
                                              std::uint64_t init_seed) {
  c.validate();
  auto m = std::make_unique<JepaModel<T>>(c.model(graph.num_nodes(), axes), init_seed);
  if (c.position_eigenvectors > 0) {
    require<ConfigError>(c.position_eigenvectors <= graph.num_nodes(), "config: position_eigenvectors = ",
                         c.position_eigenvectors, ", expected at most the ", graph.num_nodes(), " tokens");
    m->set_positions(graph_positions(graph, c.dim, c.position_eigenvectors, c.position_scale, init_seed));
  }
  return m;
}

}  // namespace tjepa
