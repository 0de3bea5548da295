#pragma once
// JepaObjective: Tactile-JEPA pre-training as an Objective (train/objective.hpp), and
// JepaTrainer<T> = Trainer<JepaObjective<T>>, the loop that trains it.
//
//   JepaTrainer<float> trainer(*model, source, skin.graph, cfg);  // masks over the taxel graph
//   trainer.checkpoint = "runs/x/checkpoint.safetensors";
//   trainer.run();                                               // or trainer.resume(path); run()
//
// Step s on the windows `ids` of a batch of B (a shard [first, first + n) of it when data
// parallel):
//   x      = to_tokens(windows ids)                                  [n, N, W]
//   masks  = collator.sample(B, streams::masks(seed), s)             sample i from stream s·B + i,
//                                                                    then this shard's rows
//   loss   = JepaStep::forward(x, masks, streams::noise(seed, s), first)
//   update = JepaStep::update(AdamW, cfg.schedule.build(), s)        clip, AdamW, EMA
// The config metadata of its checkpoints: {"objective": "jepa", "train": TrainConfig::to_json(),
// "model": JepaConfig::to_json()}, which load_trained_model (train/trained_model.hpp) reads.
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/jepa_step.hpp"
#include "tjepa/train/objective.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

// The config metadata of a checkpoint of `model` trained with `cfg`.
inline nlohmann::json run_metadata(const TrainConfig& cfg, const JepaConfig& model) {
  return {{"objective", "jepa"}, {"train", cfg.to_json()}, {"model", model.to_json()}};
}

template <class T, class Source = WindowSource>
class JepaObjective {
 public:
  using value_type = T;
  using stats_type = JepaStepStats;

  // The model and source must outlive the objective. The masks are drawn over `graph` (one node
  // per token) as config.masks says; `grid` places the tokens on a grid for
  // MaskConfig::scheme = ijepa_blocks. loss: JepaStep's loss (empty: config.loss).
  JepaObjective(JepaModel<T>& model, const Source& source, const TaxelGraph& graph, TrainConfig config,
                JepaLoss<T> loss = {}, std::optional<GridPlacement> grid = std::nullopt)
      : JepaObjective(model, source, MaskCollator(graph, (config.validate(), config.masks), std::move(grid)),
                      config, std::move(loss)) {}

  // With a collator of the caller's: the run's masks become the collator's, so that its
  // checkpoints record the masks drawn.
  JepaObjective(JepaModel<T>& model, const Source& source, MaskCollator collator, TrainConfig config,
                JepaLoss<T> loss = {})
      : data((config.validate(), source), config.seed, config.batch), model_(model), collator_(std::move(collator)),
        cfg_(std::move(config)), step_(model, cfg_.step, std::move(loss)), optimizer_(model.trainable(), cfg_.adamw),
        schedule_(cfg_.schedule.build()) {
    cfg_.masks = collator_.config();
    require<ConfigError>(collator_.num_tokens() == model_.num_tokens(), "JepaObjective: the mask graph has ",
                         collator_.num_tokens(), " tokens, the model ", model_.num_tokens());
    // One truth for the model's shape: the config's keys describe the model being trained.
    const JepaConfig& mc = model_.config;
    require<ConfigError>(mc.encoder.dim == cfg_.model.dim && mc.encoder.depth == cfg_.model.depth &&
                             mc.encoder.heads == cfg_.model.heads && mc.predictor.depth == cfg_.model.predictor_depth,
                         "JepaObjective: the model has dim ", mc.encoder.dim, ", depth ", mc.encoder.depth, ", heads ",
                         mc.encoder.heads, ", predictor_depth ", mc.predictor.depth, "; the config says ", cfg_.model.dim,
                         ", ", cfg_.model.depth, ", ", cfg_.model.heads, ", ", cfg_.model.predictor_depth);
    require<ConfigError>(mc.in_dim % cfg_.data.tau == 0, "JepaObjective: the model reads windows of ", mc.in_dim,
                         " values per taxel, not a multiple of the config's tau = ", cfg_.data.tau);
  }
  JepaObjective(const JepaObjective&) = delete;
  JepaObjective& operator=(const JepaObjective&) = delete;

  WindowBatches<T, Source> data;  // the windows and how they become tokens (data.to_tokens)

  JepaModel<T>& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  const MaskCollator& collator() const { return collator_; }
  const TrainingSchedule& schedule() const { return schedule_; }
  JepaStep<T>& step() { return step_; }
  const MaskBatch& masks() const { return masks_; }  // the last step's masks of the whole batch

  // The Objective interface (train/objective.hpp).
  std::int64_t num_samples() const { return data.size(); }
  int batch_size() const { return cfg_.batch; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  std::vector<std::int64_t> epoch_order(std::uint64_t epoch) const { return data.epoch_order(epoch); }
  void zero_grad() { step_.zero_grad(); }
  double forward(const StepBatch& b) {
    require<ConfigError>(model_.config.group_size.empty() || data.to_tokens,
                         "JepaObjective: a grouped tokenizer needs its own data.to_tokens");
    const T* x = data.tokens(b.ids, model_.num_tokens(), model_.token_width());
    collator_.sample_into(masks_, b.batch, streams::masks(cfg_.seed), static_cast<std::uint64_t>(b.step));
    const std::uint64_t noise = streams::noise(cfg_.seed, b.step);
    if (b.size() == b.batch) return step_.forward(x, b.batch, masks_, noise).loss;
    masks_.slice_into(shard_masks_, b.first, b.size());
    return step_.forward(x, b.size(), shard_masks_, noise, static_cast<std::uint64_t>(b.first)).loss;
  }
  void backward() { step_.backward(); }
  void all_reduce(const DataParallel<T>& dp, int count, int B) {
    require<ConfigError>(!cfg_.step.standardize_targets, "JepaObjective: standardize_targets uses the whole batch's "
                         "statistics, which a data-parallel shard does not have");
    step_.all_reduce(dp, count, B);
  }
  JepaStepStats update(std::int64_t s) { return step_.update(optimizer_, schedule_, s); }
  std::vector<PrefixedParams<T>> parts() { return model_.parts(); }
  AdamW<T>& optimizer() { return optimizer_; }
  nlohmann::json metadata() const { return run_metadata(cfg_, model_.config); }

 private:
  JepaModel<T>& model_;
  MaskCollator collator_;
  TrainConfig cfg_;
  JepaStep<T> step_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  MaskBatch masks_, shard_masks_;
};

template <class T, class Source = WindowSource>
using JepaTrainer = Trainer<JepaObjective<T, Source>>;

}  // namespace tjepa
