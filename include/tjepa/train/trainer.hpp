#pragma once
// Trainer: the one training loop, for any Objective (train/objective.hpp): JEPA pre-training
// (JepaTrainer), MAE (MaeTrainer), the downstream heads (train_head), a user's own objective.
//
//   for s in [step, total): epoch e = s / S, batch b = s % S   (S = full batches per epoch)
//     ids   = objective.epoch_order(e)[b·B : (b+1)·B]          this rank's shard of it
//     objective.zero_grad(); loss = objective.forward({ids, B, first, s}); objective.backward()
//     objective.all_reduce(parallel, |ids|, B)                  data parallel only
//     stats = objective.update(s)                               NaN stop, clipping, optimizer
//     on_step(stats), a log line every log_every steps, a checkpoint every checkpoint_every steps
//     at an epoch's end, an early-stopped objective validates; the best epoch's parameters are
//     kept and restored at the end, and the loop stops after `patience` epochs without a better one
//
// The objective's data order, masks and noise are functions of (seed, step), so save → resume →
// continue reproduces an uninterrupted run bit for bit at the same thread count, whichever
// program (a user's, `tjepa pretrain`, `tjepa demo`) wrote or reads the checkpoint. Checkpoints
// are written atomically after successful steps only, so a NaN (NumericError) leaves the last
// good one in place.
//
// A checkpoint (io/checkpoint.hpp) holds the objective's parameter sets and optimizer moments,
// the step, `extras` (the data statistics in extras.normalization), the early-stopping record and
// best parameters (prefix "best."), and the config metadata: objective.metadata() plus
// {"version": checkpoint_metadata_version}. resume() continues only a run whose metadata agrees
// key by key; a file without "version" (version 1) is a JEPA run's.
//
// Data parallel (train/data_parallel.hpp, dist/mpi.hpp): with `parallel` set, each rank runs its
// shard of each global batch and the objective's all_reduce sums the gradients before the
// update; rank 0 alone logs and writes checkpoints, and any rank count resumes any checkpoint.
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <ostream>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/hash.hpp"
#include "tjepa/core/json.hpp"
#include "tjepa/io/checkpoint.hpp"
#include "tjepa/train/data_parallel.hpp"
#include "tjepa/train/objective.hpp"

namespace tjepa {

// The validation record of an early-stopped run.
struct EarlyStoppingRecord {
  std::vector<double> train_loss;       // [epochs run] mean training loss per epoch
  std::vector<double> validation_loss;  // [epochs run] after each epoch
  int best_epoch = -1;                  // 0-based epoch whose parameters are kept
  double best_validation = std::numeric_limits<double>::infinity();
  int epochs() const { return static_cast<int>(validation_loss.size()); }

  nlohmann::json to_json() const {
    return {{"train_loss", train_loss}, {"validation_loss", validation_loss}, {"best_epoch", best_epoch},
            {"best_validation", best_epoch >= 0 ? best_validation : 0.0}};
  }
};

template <Objective O>
class Trainer {
 public:
  using objective_type = O;
  using T = typename O::value_type;
  using stats_type = typename O::stats_type;

  // Builds the objective in place from args (the model, the data and the config it trains with,
  // all of which must outlive the trainer).
  template <class... Args>
    requires std::constructible_from<O, Args...>
  explicit Trainer(Args&&... args) : objective_(std::forward<Args>(args)...) {
    steps_per_epoch_ = objective_.num_samples() / objective_.batch_size();
    require<DataError>(steps_per_epoch_ > 0, "Trainer: the objective has ", objective_.num_samples(),
                       " samples, fewer than one batch of ", objective_.batch_size());
    total_steps_ = objective_.total_steps();
    require<ConfigError>(total_steps_ >= 0, "Trainer: the objective runs ", total_steps_, " steps");
  }
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  std::function<void(const stats_type&)> on_step;  // after every step (loss curves, progress)
  std::ostream* log = nullptr;                      // a log line every log_every steps (0: none)
  std::int64_t log_every = 0;
  std::filesystem::path checkpoint;                 // where run() saves; empty: no checkpoints
  std::int64_t checkpoint_every = 0;                // steps between checkpoints; 0: at each epoch's end
  CheckpointState extras;                           // stored with every checkpoint: data statistics, metadata
  DataParallel<T> parallel;                         // this process's rank (default: alone)

  O& objective() { return objective_; }
  const O& objective() const { return objective_; }
  std::int64_t step() const { return step_; }
  std::int64_t steps_per_epoch() const { return steps_per_epoch_; }
  std::int64_t total_steps() const { return total_steps_; }
  bool stopped_early() const { return stopped_; }
  const EarlyStoppingRecord& record() const { return record_; }

  // Runs until the objective's last step (or an early stop), or at most max_steps steps (< 0: no
  // limit); returns their stats. An early-stopped objective ends with its best parameters.
  std::vector<stats_type> run(std::int64_t max_steps = -1) {
    std::vector<stats_type> out;
    const std::int64_t end = max_steps < 0 ? total_steps_ : std::min(total_steps_, step_ + max_steps);
    while (step_ < end && !stopped_) {
      out.push_back(train_one());
      const stats_type& st = out.back();
      ++step_;
      epoch_loss_ += st.loss;
      if (step_ % steps_per_epoch_ == 0) end_epoch();
      if (on_step) on_step(st);
      const bool lead = parallel.rank == 0;
      if (lead && log && log_every > 0 && (st.step % log_every == 0 || step_ == total_steps_)) {
        *log << "step " << st.step + 1 << "/" << total_steps_ << " epoch " << st.step / steps_per_epoch_ << " ";
        st.write(*log);
        *log << "\n";
      }
      const std::int64_t every = checkpoint_every > 0 ? checkpoint_every : steps_per_epoch_;
      if (lead && !checkpoint.empty() && (step_ % every == 0 || step_ == total_steps_ || stopped_)) save(checkpoint);
    }
    if (step_ == total_steps_ || stopped_) restore_best();
    return out;
  }

  // The config metadata of this run's checkpoints.
  nlohmann::json metadata() const {
    nlohmann::json m = objective_.metadata();
    m["version"] = checkpoint_metadata_version;
    return m;
  }

  // Writes a checkpoint that resume() continues from exactly.
  void save(const std::filesystem::path& path) {
    CheckpointState st = extras;
    st.step = step_;
    st.config = metadata();
    std::vector<PrefixedParams<T>> parts = objective_.parts();
    if constexpr (EarlyStoppedObjective<O>) {
      st.metadata["early_stopping"] = record_.to_json().dump();
      st.metadata["early_stopping.epoch_loss"] = nlohmann::json(epoch_loss_).dump();
      st.metadata["early_stopping.stopped"] = stopped_ ? "1" : "0";
      for (std::size_t j = 0; j < best_.size(); ++j) parts.push_back({"best." + parts[j].prefix, &best_[j]});
    }
    save_checkpoint<T>(path, parts, &objective_.optimizer(), st);
  }

  // Continues from a checkpoint of a run with the same objective, config and model.
  void resume(const std::filesystem::path& path) {
    const SafetensorsFile file = load_safetensors(path);
    const auto it = file.metadata.find("config");
    require<FileError>(it != file.metadata.end(), path.string(), ": no 'config' metadata; not a tjepa checkpoint");
    const nlohmann::json saved = json_parse<FileError>(it->second, path.string() + ": metadata 'config'");
    require<FileError>(saved.is_object(), path.string(), ": metadata 'config' is not a JSON object");
    const nlohmann::json now = objective_.metadata();
    const std::string saved_objective = checkpoint_objective(saved), objective = checkpoint_objective(now);
    require<ConfigError>(saved_objective == objective, "Trainer::resume: ", path.string(), " is a checkpoint of a '",
                         saved_objective, "' run, this run trains '", objective, "'");
    for (const auto& [part, a] : now.items()) {
      if (part == "objective") continue;
      require<FileError>(saved.contains(part), path.string(), ": metadata 'config' has no '", part, "'");
      const nlohmann::json& b = saved[part];
      if (!a.is_object()) {
        require<ConfigError>(a == b, "Trainer::resume: ", path.string(), " was written with ", part, " = ", b.dump(),
                             ", this run has ", a.dump());
        continue;
      }
      require<FileError>(b.is_object(), path.string(), ": metadata 'config'.", part, " is not a JSON object");
      const nlohmann::json& legacy = checkpoint_legacy_defaults();
      for (const auto& [key, value] : a.items()) {
        // A key the file predates: its legacy value (checkpoint_legacy_defaults) for run keys.
        const bool known = b.contains(key) || (part == "train" && legacy.contains(key));
        const nlohmann::json& saved_value = b.contains(key) ? b[key] : known ? legacy[key] : value;
        require<ConfigError>(known && saved_value == value, "Trainer::resume: ", path.string(), " was written with ",
                             part, ".", key, " = ", known ? saved_value.dump() : "(none)", ", this run has ",
                             value.dump());
      }
      for (const auto& [key, value] : b.items())
        require<ConfigError>(a.contains(key), "Trainer::resume: ", path.string(), " has ", part, ".", key,
                             ", which this run does not know");
    }
    std::vector<PrefixedParams<T>> parts = objective_.parts();
    EarlyStoppingRecord record;
    double epoch_loss = 0;
    bool stopped = false;
    std::vector<ParamSet<T>> best;
    if constexpr (EarlyStoppedObjective<O>) {
      const auto field = [&](const char* key) {
        const auto f = file.metadata.find(key);
        require<FileError>(f != file.metadata.end(), path.string(), ": no '", key,
                           "' metadata; not a checkpoint of an early-stopped run");
        return json_parse<FileError>(f->second, path.string() + ": metadata '" + key + "'");
      };
      const nlohmann::json r = field("early_stopping");
      const std::string where = path.string() + ": metadata 'early_stopping'";
      record.train_loss = json_get<std::vector<double>, FileError>(r, "train_loss", where);
      record.validation_loss = json_get<std::vector<double>, FileError>(r, "validation_loss", where);
      record.best_epoch = json_get<int, FileError>(r, "best_epoch", where);
      record.best_validation = json_get<double, FileError>(r, "best_validation", where);
      require<FileError>(record.train_loss.size() == record.validation_loss.size() && record.best_epoch >= -1 &&
                             record.best_epoch < record.epochs(),
                         where, ": ", record.train_loss.size(), " training and ", record.validation_loss.size(),
                         " validation losses with best epoch ", record.best_epoch);
      if (record.best_epoch < 0) record.best_validation = std::numeric_limits<double>::infinity();
      const nlohmann::json el = field("early_stopping.epoch_loss"), stop = field("early_stopping.stopped");
      require<FileError>(el.is_number() && (stop == 0 || stop == 1), where, ": epoch_loss ", el.dump(),
                         " and stopped ", stop.dump(), ", expected a number and 0 or 1");
      epoch_loss = el.get<double>();
      stopped = stop == 1;
      if (record.best_epoch >= 0) {
        for (const auto& p : objective_.parts()) best.push_back(*p.params);
        for (std::size_t j = 0; j < best.size(); ++j) parts.push_back({"best." + parts[j].prefix, &best[j]});
      }
    }
    CheckpointState st = load_checkpoint<T>(path, parts, &objective_.optimizer());
    require<FileError>(st.step >= 0 && st.step <= total_steps_, path.string(), ": step ", st.step,
                       ", expected in [0, ", total_steps_, "]");
    step_ = st.step;
    record_ = std::move(record);
    epoch_loss_ = epoch_loss;
    stopped_ = stopped;
    best_ = std::move(best);
    extras.normalization = std::move(st.normalization);
    extras.metadata = std::move(st.metadata);
    extras.metadata.erase("early_stopping");
    extras.metadata.erase("early_stopping.epoch_loss");
    extras.metadata.erase("early_stopping.stopped");
  }

 private:
  stats_type train_one() {
    const std::int64_t s = step_;
    const std::int64_t epoch = s / steps_per_epoch_, b = s % steps_per_epoch_;
    if (epoch != order_epoch_) {
      order_ = objective_.epoch_order(static_cast<std::uint64_t>(epoch));
      require<ShapeError>(static_cast<std::int64_t>(order_.size()) >= steps_per_epoch_ * objective_.batch_size(),
                          "Trainer: the objective's epoch order holds ", order_.size(), " ids, expected at least ",
                          steps_per_epoch_ * objective_.batch_size());
      order_epoch_ = epoch;
    }
    const int B = objective_.batch_size();
    Shard shard{0, B};
    if (parallel.active()) {
      if constexpr (DataParallelObjective<O>) {
        shard = parallel.shard(B);
      } else {
        fail<ConfigError>("Trainer: this objective has no all_reduce (its loss needs the whole batch), so it "
                          "cannot run data parallel");
      }
    }
    const std::span<const std::int64_t> ids =
        std::span<const std::int64_t>(order_).subspan(static_cast<std::size_t>(b) * B + shard.first,
                                                      static_cast<std::size_t>(shard.count));
    objective_.zero_grad();
    const double loss = objective_.forward(StepBatch{ids, B, shard.first, s});
    if (!parallel.active() && !std::isfinite(loss))
      fail<NumericError>(checkpoint_objective(objective_.metadata()), " step ", s, ": the loss is ", loss,
                         "; training stopped before the update (parameters and checkpoints are unchanged)");
    objective_.backward();
    if constexpr (DataParallelObjective<O>)
      if (parallel.active()) objective_.all_reduce(parallel, shard.count, B);
    stats_type st = objective_.update(s);
    if (parallel.active() && parallel.agree && parallel.check_every > 0 && (s + 1) % parallel.check_every == 0) {
      std::uint64_t h = fingerprint_seed;
      for (const auto& part : objective_.parts()) h = fingerprint<T>(part.params->values(), h);
      require<NumericError>(parallel.agree(h), "Trainer: after step ", s, " the data-parallel ranks hold different "
                            "parameters (their gradient sums differ); stopped before the next checkpoint");
    }
    return st;
  }

  // An epoch's end: an early-stopped objective validates, keeps the best, maybe stops.
  void end_epoch() {
    if constexpr (EarlyStoppedObjective<O>) {
      const int e = static_cast<int>(step_ / steps_per_epoch_) - 1;
      const double v = objective_.validate();
      require<NumericError>(!std::isnan(v), "Trainer: epoch ", e, ": the validation loss is NaN");
      record_.train_loss.push_back(epoch_loss_ / static_cast<double>(steps_per_epoch_));
      record_.validation_loss.push_back(v);
      if (v < record_.best_validation) {
        record_.best_validation = v;
        record_.best_epoch = e;
        const auto parts = objective_.parts();
        best_.clear();
        for (const auto& p : parts) best_.push_back(*p.params);
      } else if (e - record_.best_epoch >= objective_.patience()) {
        stopped_ = true;
      }
    }
    epoch_loss_ = 0;
  }

  // The best epoch's parameters back in the objective (early-stopped objectives).
  void restore_best() {
    if (best_.empty()) return;
    const auto parts = objective_.parts();
    for (std::size_t j = 0; j < parts.size(); ++j) std::ranges::copy(best_[j].values(), parts[j].params->values().begin());
  }

  O objective_;
  std::int64_t steps_per_epoch_ = 0, total_steps_ = 0;
  std::int64_t step_ = 0;
  std::vector<std::int64_t> order_;
  std::int64_t order_epoch_ = -1;
  EarlyStoppingRecord record_;
  std::vector<ParamSet<T>> best_;  // the best epoch's parameters, one per part
  double epoch_loss_ = 0;          // the loss summed over this epoch's steps so far
  bool stopped_ = false;
};

}  // namespace tjepa
