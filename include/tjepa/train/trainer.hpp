#pragma once
// Trainer: the pre-training loop, small enough to read in one sitting and copy.
//
//   for s in [step, cfg.steps): epoch e = s / S, batch b = s % S   (S = full batches per epoch)
//     windows  = source.epoch_order(seed ^ data salt, e)[b·B : (b+1)·B]   gathered, preprocessed
//     x        = to_tokens(windows)                                      [B, N, W] the tokenizer's input
//     masks    = collator.sample(B, seed ^ mask salt, s)                 sample i from stream s·B + i
//     stats    = step.train(optimizer, schedule, s, x, masks, noise = Rng(seed ^ noise salt, s)())
//     on_step(stats), a log line every log_every steps, a checkpoint every checkpoint_every steps
//
// Data order, masks and drop-path noise are functions of (seed, step), so save → resume →
// continue reproduces an uninterrupted run bit for bit at the same thread count, whichever
// program (a user's, `tjepa pretrain`, `tjepa demo`) wrote or reads the checkpoint. Checkpoints
// are written atomically after successful steps only, so a NaN (NumericError) leaves the last
// good one in place.
//
// A checkpoint (io/checkpoint.hpp) holds the three parameter sets, AdamW's moments, the step, the
// data statistics in `extras.normalization`, and the config metadata
//   {"train": TrainConfig::to_json(), "model": JepaConfig::to_json()}
// which load_trained_model (train/trained_model.hpp) reads back.
//
// Data parallel (train/data_parallel.hpp, dist/mpi.hpp): with `parallel` set, each rank gathers
// only its shard of each global batch, draws the whole batch's masks and keeps its rows, runs
// forward and backward on its shard, and JepaStep::all_reduce sums the gradients before the
// update; rank 0 alone logs and writes checkpoints, and any rank count resumes any checkpoint.
//
// Every piece works alone: the model, JepaStep, AdamW, the schedules, the checkpoint functions;
// this class only strings them together.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/data_parallel.hpp"
#include "tjepa/train/jepa_step.hpp"

namespace tjepa {

// The config metadata of a checkpoint of `model` trained with `cfg`.
inline nlohmann::json run_metadata(const TrainConfig& cfg, const JepaConfig& model) {
  return {{"train", cfg.to_json()}, {"model", model.to_json()}};
}

template <class T, class Source = WindowSource>
class Trainer {
 public:
  // Salts of the three streams drawn from cfg.seed.
  static constexpr std::uint64_t kDataSalt = 0x6A65706164617461ull;   // "jepadata"
  static constexpr std::uint64_t kMaskSalt = 0x6A6570616D61736Bull;   // "jepamask"
  static constexpr std::uint64_t kNoiseSalt = 0x6A6570616E6F6973ull;  // "jepanois"

  // The model and source must outlive the trainer; the optimizer's moments live here. The masks
  // are drawn over `graph` (one node per token) as cfg.masks() says; `grid` places the tokens on
  // a grid for MaskConfig::scheme = ijepa_blocks. loss: JepaStep's loss (empty: cfg.loss).
  Trainer(JepaModel<T>& model, const Source& source, const TaxelGraph& graph, TrainConfig config,
          JepaLoss<T> loss = {}, std::optional<GridPlacement> grid = std::nullopt)
      : Trainer(model, source, MaskCollator(graph, config.masks(), std::move(grid)), std::move(config),
                std::move(loss)) {}

  // With a collator of the caller's (mask ablations beyond TrainConfig's keys).
  Trainer(JepaModel<T>& model, const Source& source, MaskCollator collator, TrainConfig config, JepaLoss<T> loss = {})
      : model_(model), source_(source), collator_(std::move(collator)), cfg_(std::move(config)),
        step_fn_(model, (cfg_.validate(), cfg_.step()), std::move(loss)), optimizer_(model.trainable(), cfg_.adamw()) {
    require<ConfigError>(collator_.num_tokens() == model_.num_tokens(), "Trainer: the mask graph has ",
                         collator_.num_tokens(), " tokens, the model ", model_.num_tokens());
    steps_per_epoch_ = source_.batches_per_epoch(cfg_.batch);
    require<DataError>(steps_per_epoch_ > 0, "Trainer: the source holds ", source_.size(),
                       " windows, fewer than one batch of ", cfg_.batch);
    // One truth for the model's shape: the config's keys describe the model being trained.
    const JepaConfig& mc = model_.config;
    require<ConfigError>(mc.encoder.dim == cfg_.dim && mc.encoder.depth == cfg_.depth &&
                             mc.encoder.heads == cfg_.heads && mc.predictor.depth == cfg_.predictor_depth,
                         "Trainer: the model has dim ", mc.encoder.dim, ", depth ", mc.encoder.depth, ", heads ",
                         mc.encoder.heads, ", predictor_depth ", mc.predictor.depth, "; the config says ", cfg_.dim,
                         ", ", cfg_.depth, ", ", cfg_.heads, ", ", cfg_.predictor_depth);
    require<ConfigError>(mc.in_dim % cfg_.tau == 0, "Trainer: the model reads windows of ", mc.in_dim,
                         " values per taxel, not a multiple of the config's tau = ", cfg_.tau);
    schedule_ = cfg_.schedule();
  }
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  // Batch → tokenizer input [B, N, W]; empty: windows_to_tokens, which suits a per-taxel
  // tokenizer. For grouped tokens set it to gather the groups (data/grouped_gather.hpp).
  std::function<void(const WindowBatch&, AlignedVector<T>&)> to_tokens;
  // Called after every step (e.g. to collect the loss curve or print progress).
  std::function<void(const JepaStepStats&)> on_step;
  std::ostream* log = nullptr;               // a log line every log_every steps (0: none)
  std::int64_t log_every = 0;
  std::filesystem::path checkpoint;          // where run() saves; empty: no checkpoints
  std::int64_t checkpoint_every = 0;         // steps between checkpoints; 0: at each epoch's end
  CheckpointState extras;                    // stored with every checkpoint: normalization statistics, metadata
  DataParallel<T> parallel;                  // this process's rank among the data-parallel ranks (default: alone)

  std::int64_t step() const { return step_; }
  std::int64_t steps_per_epoch() const { return steps_per_epoch_; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  const TrainingSchedule& schedule() const { return schedule_; }
  const TrainConfig& config() const { return cfg_; }
  const MaskCollator& collator() const { return collator_; }
  AdamW<T>& optimizer() { return optimizer_; }
  JepaModel<T>& model() { return model_; }

  // Runs until the schedule ends, or at most max_steps steps (< 0: no limit); returns their stats.
  std::vector<JepaStepStats> run(std::int64_t max_steps = -1) {
    std::vector<JepaStepStats> out;
    const std::int64_t end = max_steps < 0 ? total_steps() : std::min(total_steps(), step_ + max_steps);
    while (step_ < end) {
      out.push_back(train_one());
      const JepaStepStats& st = out.back();
      ++step_;
      if (on_step) on_step(st);
      const bool lead = parallel.rank == 0;
      if (lead && log && log_every > 0 && (st.step % log_every == 0 || step_ == total_steps()))
        *log << "step " << st.step + 1 << "/" << total_steps() << " epoch " << st.step / steps_per_epoch_
             << " loss " << st.loss << " lr " << st.lr << " wd " << st.weight_decay << " ema " << st.momentum
             << " grad_norm " << st.grad_norm << " target_std " << st.target_std << "\n";
      const std::int64_t every = checkpoint_every > 0 ? checkpoint_every : steps_per_epoch_;
      if (lead && !checkpoint.empty() && (step_ % every == 0 || step_ == total_steps())) save(checkpoint);
    }
    return out;
  }

  // Writes a checkpoint that resume() continues from exactly.
  void save(const std::filesystem::path& path) const {
    CheckpointState st = extras;
    st.step = step_;
    st.config = run_metadata(cfg_, model_.config);
    const auto parts = model_.parts();
    save_checkpoint<T>(path, parts, &optimizer_, st);
  }

  // Continues from a checkpoint of a run with the same TrainConfig and model.
  void resume(const std::filesystem::path& path) {
    const SafetensorsFile file = load_safetensors(path);
    const auto it = file.metadata.find("config");
    require<FileError>(it != file.metadata.end(), path.string(), ": no 'config' metadata; not a tjepa checkpoint");
    const nlohmann::json saved = json_parse<FileError>(it->second, path.string() + ": metadata 'config'");
    const nlohmann::json now = run_metadata(cfg_, model_.config);
    for (const char* part : {"train", "model"}) {
      const nlohmann::json& a = now[part];
      const nlohmann::json b = json_get<nlohmann::json, FileError>(saved, part, path.string() + ": metadata 'config'");
      for (const auto& [key, value] : a.items())
        require<ConfigError>(b.contains(key) && b[key] == value, "Trainer::resume: ", path.string(),
                             " was written with ", part, ".", key, " = ", b.contains(key) ? b[key].dump() : "(none)",
                             ", this run has ", value.dump());
      for (const auto& [key, value] : b.items())
        require<ConfigError>(a.contains(key), "Trainer::resume: ", path.string(), " has ", part, ".", key,
                             ", which this run does not know");
    }
    const auto parts = model_.parts();
    CheckpointState st = load_checkpoint<T>(path, parts, &optimizer_);
    require<FileError>(st.step >= 0 && st.step <= total_steps(), path.string(), ": step ", st.step,
                       ", expected in [0, ", total_steps(), "]");
    step_ = st.step;
    extras.normalization = std::move(st.normalization);
    extras.metadata = std::move(st.metadata);
  }

 private:
  JepaStepStats train_one() {
    const std::int64_t s = step_;
    const std::int64_t epoch = s / steps_per_epoch_, b = s % steps_per_epoch_;
    if (epoch != order_epoch_) {
      order_ = source_.epoch_order(cfg_.seed ^ kDataSalt, static_cast<std::uint64_t>(epoch));
      order_epoch_ = epoch;
    }
    const std::size_t B = static_cast<std::size_t>(cfg_.batch);
    const Shard shard = parallel.active() ? parallel.shard(cfg_.batch) : Shard{0, cfg_.batch};
    const std::size_t n = static_cast<std::size_t>(shard.count);
    source_.gather(std::span<const std::int64_t>(order_).subspan(static_cast<std::size_t>(b) * B + shard.first, n),
                   batch_);
    if (to_tokens) {
      to_tokens(batch_, input_);
    } else {
      require<ConfigError>(model_.config.group_size.empty(), "Trainer: a grouped tokenizer needs its own to_tokens");
      windows_to_tokens(batch_, input_);
    }
    require<ShapeError>(input_.size() == n * model_.num_tokens() * model_.token_width(), "Trainer: to_tokens gave ",
                        input_.size(), " values, expected B·N·W = ", n, "·", model_.num_tokens(), "·",
                        model_.token_width());
    collator_.sample_into(masks_, cfg_.batch, cfg_.seed ^ kMaskSalt, static_cast<std::uint64_t>(s));
    const std::uint64_t noise = Rng(cfg_.seed ^ kNoiseSalt, static_cast<std::uint64_t>(s))();
    if (!parallel.active())
      return step_fn_.train(optimizer_, schedule_, s, input_.data(), cfg_.batch, masks_, noise);
    require<ConfigError>(!cfg_.standardize_targets, "Trainer: standardize_targets uses the whole batch's "
                         "statistics, which a data-parallel shard does not have");
    masks_.slice_into(shard_masks_, shard.first, shard.count);
    step_fn_.zero_grad();
    step_fn_.forward(input_.data(), shard.count, shard_masks_, noise, static_cast<std::uint64_t>(shard.first));
    step_fn_.backward();
    step_fn_.all_reduce(parallel, shard.count, cfg_.batch);
    JepaStepStats st = step_fn_.update(optimizer_, schedule_, s);
    if (parallel.agree && parallel.check_every > 0 && (s + 1) % parallel.check_every == 0) {
      std::uint64_t h = fingerprint_seed;
      for (const auto& part : model_.parts()) h = fingerprint<T>(part.params->values(), h);
      require<NumericError>(parallel.agree(h), "Trainer: after step ", s, " the data-parallel ranks hold different "
                            "parameters (their gradient sums differ); stopped before the next checkpoint");
    }
    return st;
  }

  JepaModel<T>& model_;
  const Source& source_;
  MaskCollator collator_;
  TrainConfig cfg_;
  JepaStep<T> step_fn_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  std::int64_t steps_per_epoch_ = 0;
  std::int64_t step_ = 0;
  // Buffers reused from step to step.
  std::vector<std::int64_t> order_;
  std::int64_t order_epoch_ = -1;
  WindowBatch batch_;
  AlignedVector<T> input_;
  MaskBatch masks_, shard_masks_;
};

}  // namespace tjepa
