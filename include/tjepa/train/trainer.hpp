#pragma once
// Trainer: the reference training loop, small enough to read in one sitting and copy.
//
//   for s in [step, total): epoch e = s / S, batch b = s % S   (S = full batches per epoch)
//     windows  = source.epoch_order(seed, e)[b·B : (b+1)·B]     gathered, preprocessed
//     x        = to_tokens(windows)                              [B, N, W] the tokenizer's input
//     masks    = collator.sample(B, seed ^ mask salt, s)
//     stats    = jepa_train_step(model, optimizer, schedule, s, x, masks, noise = rng())
//     log, and every `checkpoint_every` steps (default: each epoch end) save the checkpoint
//
// Data order and masks are functions of (seed, step); drop-path noise comes from one generator
// whose state is checkpointed. So save → load → continue reproduces an uninterrupted run bit for
// bit at the same thread count. Checkpoints are written atomically after successful steps only,
// so a NaN (NumericError) leaves the last good one in place.
//
// Every piece works alone: the model, jepa_train_step, AdamW, the schedules, the checkpoint
// functions; this class only strings them together.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <ostream>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/jepa_step.hpp"

namespace tjepa {

struct TrainerConfig {
  int epochs = 500;
  int batch_size = 256;
  int warmup_epochs = 30;
  double start_lr = 1e-5, ref_lr = 1e-4, final_lr = 1e-6;  // warm-up from start_lr, cosine to final_lr
  double ref_wd = 0.04, final_wd = 0.4;                    // cosine-increasing weight decay
  double ema_start = 0.994, ema_end = 1.0;                 // EMA momentum, linear
  AdamWConfig adamw;
  JepaStepConfig step;
  std::uint64_t seed = 0;               // data order, masks and drop-path noise
  std::filesystem::path checkpoint;     // where the latest checkpoint goes; empty: no checkpoints
  std::int64_t checkpoint_every = 0;    // steps between checkpoints; 0: at the end of every epoch
  std::int64_t log_every = 0;           // steps between log lines; 0: no log lines

  nlohmann::json to_json() const {
    return {{"epochs", epochs},       {"batch_size", batch_size}, {"warmup_epochs", warmup_epochs},
            {"start_lr", start_lr},   {"ref_lr", ref_lr},         {"final_lr", final_lr},
            {"ref_wd", ref_wd},       {"final_wd", final_wd},     {"ema_start", ema_start},
            {"ema_end", ema_end},     {"betas", {adamw.beta1, adamw.beta2}}, {"eps", adamw.eps},
            {"step", step.to_json()}, {"seed", seed}};
  }
};

template <class T, class Source = WindowSource>
class Trainer {
 public:
  // Salt of the mask stream: batch s draws its masks from collator.sample(B, seed ^ salt, s).
  static constexpr std::uint64_t kMaskSalt = 0x6A6570616D61736Bull;  // "jepamask"

  // The model, source and collator must outlive the trainer; the optimizer's moments live here.
  Trainer(JepaModel<T>& model, const Source& source, const MaskCollator& collator, TrainerConfig config)
      : model_(model), source_(source), collator_(collator), cfg_(std::move(config)),
        optimizer_(model.trainable(), cfg_.adamw), rng_(cfg_.seed, 0x6E6F697365ull /* "noise" */) {
    require<ConfigError>(cfg_.batch_size > 0, "Trainer: batch_size = ", cfg_.batch_size, ", expected > 0");
    require<ConfigError>(collator_.num_tokens() == model_.num_tokens(), "Trainer: the collator's graph has ",
                         collator_.num_tokens(), " tokens, the model ", model_.num_tokens());
    steps_per_epoch_ = source_.batches_per_epoch(cfg_.batch_size);
    require<ConfigError>(steps_per_epoch_ > 0, "Trainer: the source holds ", source_.size(),
                         " windows, fewer than one batch of ", cfg_.batch_size);
    schedule_ = TrainingSchedule::reference(cfg_.epochs, steps_per_epoch_, cfg_.warmup_epochs);
    schedule_.lr.start_lr = cfg_.start_lr;
    schedule_.lr.ref_lr = cfg_.ref_lr;
    schedule_.lr.final_lr = cfg_.final_lr;
    schedule_.wd.ref_wd = cfg_.ref_wd;
    schedule_.wd.final_wd = cfg_.final_wd;
    schedule_.momentum.start = cfg_.ema_start;
    schedule_.momentum.end = cfg_.ema_end;
    schedule_.validate();
    to_tokens = [this](const WindowBatch& b, AlignedVector<T>& out) {
      require<ConfigError>(model_.config.group_size.empty(), "Trainer: a grouped tokenizer needs its own to_tokens");
      windows_to_tokens(b, out);
    };
  }

  // Batch → tokenizer input [B, N, W]; the default suits a per-taxel tokenizer. For grouped
  // tokens set it to gather the groups (data/grouped_gather.hpp).
  std::function<void(const WindowBatch&, AlignedVector<T>&)> to_tokens;
  // Called after every step (e.g. to collect the loss curve).
  std::function<void(const JepaStepStats&)> on_step;
  std::ostream* log = nullptr;   // log lines every cfg.log_every steps go here
  CheckpointState extras;        // stored with every checkpoint: normalization statistics, metadata

  std::int64_t step() const { return step_; }
  std::int64_t steps_per_epoch() const { return steps_per_epoch_; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  const TrainingSchedule& schedule() const { return schedule_; }
  const TrainerConfig& config() const { return cfg_; }
  AdamW<T>& optimizer() { return optimizer_; }

  // Runs until the schedule ends, or at most max_steps steps (< 0: no limit); returns their stats.
  std::vector<JepaStepStats> run(std::int64_t max_steps = -1) {
    std::vector<JepaStepStats> out;
    const std::int64_t end = max_steps < 0 ? total_steps() : std::min(total_steps(), step_ + max_steps);
    while (step_ < end) {
      out.push_back(train_one());
      const JepaStepStats& st = out.back();
      ++step_;
      if (on_step) on_step(st);
      if (log && cfg_.log_every > 0 && (st.step % cfg_.log_every == 0 || step_ == total_steps()))
        *log << "step " << st.step + 1 << "/" << total_steps() << " epoch " << st.step / steps_per_epoch_
             << " loss " << st.loss << " lr " << st.lr << " wd " << st.weight_decay << " ema " << st.momentum
             << " grad_norm " << st.grad_norm << " target_std " << st.target_std << "\n";
      const std::int64_t every = cfg_.checkpoint_every > 0 ? cfg_.checkpoint_every : steps_per_epoch_;
      if (!cfg_.checkpoint.empty() && (step_ % every == 0 || step_ == total_steps())) save(cfg_.checkpoint);
    }
    return out;
  }

  // Writes a checkpoint that resume() continues from exactly.
  void save(const std::filesystem::path& path) const {
    CheckpointState st = extras;
    st.step = step_;
    st.rng["trainer"] = rng_.state();
    st.config = config_json();
    const auto parts = model_.parts();
    save_checkpoint<T>(path, parts, &optimizer_, st);
  }

  // Continues from a checkpoint of a run with the same model, data size and schedule.
  void resume(const std::filesystem::path& path) {
    const SafetensorsFile file = load_safetensors(path);
    const auto it = file.metadata.find("config");
    require<FileError>(it != file.metadata.end(), path.string(), ": no config in the metadata");
    nlohmann::json saved;
    try {
      saved = nlohmann::json::parse(it->second);
    } catch (const nlohmann::json::exception& e) {
      fail<FileError>(path.string(), ": metadata 'config' is not valid JSON: ", e.what());
    }
    const nlohmann::json now = config_json();
    for (const char* key : {"model", "trainer", "steps_per_epoch"})
      require<ConfigError>(saved.contains(key) && saved[key] == now[key], "Trainer::resume: ", path.string(),
                           " was written with ", key, " = ", saved.contains(key) ? saved[key].dump() : "(none)",
                           ", this run has ", now[key].dump());
    const auto parts = model_.parts();
    CheckpointState st = load_checkpoint<T>(path, parts, &optimizer_);
    const auto r = st.rng.find("trainer");
    require<FileError>(r != st.rng.end(), path.string(), ": no generator state 'rng.trainer'");
    require<FileError>(st.step >= 0 && st.step <= total_steps(), path.string(), ": step ", st.step,
                       ", expected in [0, ", total_steps(), "]");
    rng_.set_state(r->second);
    step_ = st.step;
    extras.normalization = std::move(st.normalization);
    extras.metadata = std::move(st.metadata);
  }

 private:
  nlohmann::json config_json() const {
    return {{"model", model_.config.to_json()}, {"trainer", cfg_.to_json()}, {"steps_per_epoch", steps_per_epoch_}};
  }

  JepaStepStats train_one() {
    const std::int64_t s = step_;
    const std::int64_t epoch = s / steps_per_epoch_, b = s % steps_per_epoch_;
    if (epoch != order_epoch_) {
      order_ = source_.epoch_order(cfg_.seed, static_cast<std::uint64_t>(epoch));
      order_epoch_ = epoch;
    }
    const std::size_t B = static_cast<std::size_t>(cfg_.batch_size);
    source_.gather(std::span<const std::int64_t>(order_).subspan(static_cast<std::size_t>(b) * B, B), batch_);
    to_tokens(batch_, input_);
    require<ShapeError>(input_.size() == B * model_.num_tokens() * model_.token_width(), "Trainer: to_tokens gave ",
                        input_.size(), " values, expected B·N·W = ", B, "·", model_.num_tokens(), "·",
                        model_.token_width());
    collator_.sample_into(masks_, cfg_.batch_size, cfg_.seed ^ kMaskSalt, static_cast<std::uint64_t>(s));
    return jepa_train_step(model_, optimizer_, schedule_, s, input_.data(), cfg_.batch_size, masks_, ws_, cfg_.step,
                           rng_());
  }

  JepaModel<T>& model_;
  const Source& source_;
  const MaskCollator& collator_;
  TrainerConfig cfg_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  Rng rng_;
  std::int64_t steps_per_epoch_ = 0;
  std::int64_t step_ = 0;
  // Buffers reused from step to step.
  std::vector<std::int64_t> order_;
  std::int64_t order_epoch_ = -1;
  WindowBatch batch_;
  AlignedVector<T> input_;
  MaskBatch masks_;
  JepaWorkspace<T> ws_;
};

}  // namespace tjepa
