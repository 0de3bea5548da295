#pragma once
// The Objective concept: what Trainer (train/trainer.hpp) needs of a training objective. JEPA
// (JepaObjective), MAE (MaeObjective), the downstream heads (HeadObjective) and a user's own
// objective (examples/custom_objective.cpp) all implement it, and one Trainer gives every one of
// them checkpoints, resume, data parallelism, logging and the NaN stop.
//
// An objective owns its data binding, its parameters and its optimizer state. Each optimizer
// step s the Trainer hands it the sample ids of this rank's share of the global batch:
//
//   o.zero_grad();
//   double loss = o.forward(StepBatch{ids, B, first, s});  // gathers ids, draws its masks and noise
//   o.backward();                                          // adds ∂L/∂θ into the gradients
//   o.all_reduce(dp, ids.size(), B);                       // data parallel only (optional member)
//   stats = o.update(s);                                   // the NaN stop, clipping, AdamW, EMA...
//
// and asks it for the order of its samples in an epoch (a function of the seed and the epoch
// only, so that a resumed run draws the same batches), the parameter sets and the optimizer a
// checkpoint holds, and the metadata a resume must agree with. An objective without all_reduce
// cannot run data parallel (the Trainer refuses, naming it): one whose loss needs statistics of
// the whole batch. An objective with `double validate()` and `int patience() const` is
// early-stopped: the Trainer validates after every epoch, keeps the parameters of the best epoch,
// stops after `patience` epochs without a better one and restores the best at the end.
//
// Streams: the data order, masks and drop-path noise of a run are drawn from its seed through
// three salts (streams::data, streams::masks, streams::noise), the same for every objective, so
// JEPA and MAE pre-trained with one seed see the same windows in the same order.
#include <cmath>
#include <concepts>
#include <cstdint>
#include <functional>
#include <ostream>
#include <span>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/prefixed_params.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/model/stage_clock.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/data_parallel.hpp"
#include "tjepa/train/health.hpp"

namespace tjepa {

// This rank's share of one optimizer step's global batch.
struct StepBatch {
  std::span<const std::int64_t> ids;  // sample ids of this rank's shard, in batch order
  int batch = 0;                      // B, the global batch
  int first = 0;                      // the shard's offset in the global batch
  std::int64_t step = 0;              // optimizer step s (0-based)

  int size() const { return static_cast<int>(ids.size()); }
};

template <class O>
concept Objective = requires(O& o, const O& co, const StepBatch& b, std::int64_t s, std::uint64_t epoch) {
  typename O::value_type;
  typename O::stats_type;
  requires std::derived_from<typename O::stats_type, StepStats>;
  { co.num_samples() } -> std::convertible_to<std::int64_t>;
  { co.batch_size() } -> std::convertible_to<int>;
  { co.total_steps() } -> std::convertible_to<std::int64_t>;
  { co.epoch_order(epoch) } -> std::same_as<std::vector<std::int64_t>>;
  o.zero_grad();
  { o.forward(b) } -> std::convertible_to<double>;
  o.backward();
  { o.update(s) } -> std::same_as<typename O::stats_type>;
  { o.parts() } -> std::same_as<std::vector<PrefixedParams<typename O::value_type>>>;
  { o.optimizer() } -> std::same_as<AdamW<typename O::value_type>&>;
  { co.metadata() } -> std::same_as<nlohmann::json>;
};

template <class O>
concept DataParallelObjective =
    Objective<O> && requires(O& o, const DataParallel<typename O::value_type>& dp, int n, int B) { o.all_reduce(dp, n, B); };

template <class O>
concept EarlyStoppedObjective = Objective<O> && requires(O& o, const O& co) {
  { o.validate() } -> std::convertible_to<double>;
  { co.patience() } -> std::convertible_to<int>;
};

// The seeds of a run's three random streams.
namespace streams {
inline constexpr std::uint64_t data_salt = 0x6A65706164617461ull;   // "jepadata"
inline constexpr std::uint64_t mask_salt = 0x6A6570616D61736Bull;   // "jepamask"
inline constexpr std::uint64_t noise_salt = 0x6A6570616E6F6973ull;  // "jepanois"
// The epoch order's seed (WindowSource::epoch_order(data(seed), epoch)).
inline std::uint64_t data(std::uint64_t seed) { return seed ^ data_salt; }
// The mask sampler's seed (MaskCollator::sample(B, masks(seed), s)).
inline std::uint64_t masks(std::uint64_t seed) { return seed ^ mask_salt; }
// Step s's drop-path noise seed.
inline std::uint64_t noise(std::uint64_t seed, std::int64_t s) {
  return Rng(seed ^ noise_salt, static_cast<std::uint64_t>(s))();
}
}  // namespace streams

// The NaN stop and gradient clipping every objective's update starts with: throws NumericError
// (naming `who` and step s) on a non-finite loss or gradient norm before any parameter changes;
// returns the norm before clipping.
template <class T>
double clip_or_stop(std::span<const PrefixedParams<T>> parts, double max_norm, double loss, std::int64_t s,
                    const char* who) {
  if (!std::isfinite(loss))
    fail<NumericError>(who, " step ", s, ": the loss is ", loss,
                       "; training stopped before the update (parameters and checkpoints are unchanged)");
  const double norm = clip_grad_norm<T>(parts, max_norm);
  if (!std::isfinite(norm))
    fail<NumericError>(who, " step ", s, ": the gradient norm is ", norm, " (loss ", loss,
                       "); training stopped before the update (parameters and checkpoints are unchanged)");
  return norm;
}

// The update every objective's step starts with: the NaN stop and clipping (clip_or_stop), then
// AdamW at the schedule's rate and weight decay for step s. Fills st's step, loss, grad_norm, lr
// and weight_decay; what follows (an EMA, say) is the objective's. A clock, when given, gets the
// marks "clip" and "AdamW".
template <class T>
void clipped_adamw_step(StepStats& st, std::span<const PrefixedParams<T>> parts, AdamW<T>& opt,
                        const TrainingSchedule& schedule, std::int64_t s, double loss, double max_norm, const char* who,
                        StageClock* clock = nullptr) {
  st.step = s;
  st.loss = loss;
  st.grad_norm = clip_or_stop<T>(parts, max_norm, loss, s, who);
  if (clock) clock->mark("clip");
  st.lr = schedule.lr_at(s);
  st.weight_decay = schedule.wd_at(s);
  opt.step(st.lr, st.weight_decay);
  if (clock) clock->mark("AdamW");
}

// Data parallel, for an objective whose loss is a mean over the samples: this rank's gradients
// (of the mean over its `count` samples) are scaled by count / B and summed over the ranks, and
// so are `stats` (the loss and what else is a per-sample mean). Every rank then holds the global
// batch's gradient and mean loss.
template <class T>
void all_reduce_mean(std::span<const PrefixedParams<T>> parts, std::span<double> stats, const DataParallel<T>& dp,
                     int count, int B) {
  require<ConfigError>(dp.sum && dp.sum_stats, "all_reduce: the DataParallel has no sum functions");
  require<ShapeError>(count > 0 && count <= B, "all_reduce: ", count, " samples of a batch of ", B);
  const double share = static_cast<double>(count) / B;
  for (const auto& part : parts) {
    const std::span<T> g = part.params->grads();
    const T sc = static_cast<T>(share);
    for (T& v : g) v *= sc;
    dp.sum(g);
  }
  for (double& v : stats) v *= share;
  dp.sum_stats(stats);
}

// Windows of a WindowSource (or any source with its size, epoch_order and gather) as the
// tokenizer's input: what JEPA, MAE and a user's objective over windows share.
template <class T, class Source = WindowSource>
class WindowBatches {
 public:
  WindowBatches(const Source& source, std::uint64_t seed, int batch) : source_(source), seed_(seed), batch_(batch) {
    require<ConfigError>(batch > 0, "WindowBatches: batch = ", batch, ", expected > 0");
    require<DataError>(source.batches_per_epoch(batch) > 0, "the source holds ", source.size(),
                       " windows, fewer than one batch of ", batch);
  }

  // Batch → tokenizer input [B, N, W]; empty: windows_to_tokens, which suits a per-taxel
  // tokenizer. For grouped tokens set it to gather the groups (data/grouped_gather.hpp).
  std::function<void(const WindowBatch&, AlignedVector<T>&)> to_tokens;

  const Source& source() const { return source_; }
  std::int64_t size() const { return source_.size(); }
  int batch() const { return batch_; }
  std::vector<std::int64_t> epoch_order(std::uint64_t epoch) const {
    return source_.epoch_order(streams::data(seed_), epoch);
  }

  // The windows ids gathered and turned into the tokenizer's input [n, N, W] (n = ids.size()),
  // checked to hold n·N·W values.
  const T* tokens(std::span<const std::int64_t> ids, int N, int W) {
    source_.gather(ids, windows_);
    if (to_tokens) {
      to_tokens(windows_, x_);
    } else {
      windows_to_tokens(windows_, x_);
    }
    require<ShapeError>(x_.size() == ids.size() * static_cast<std::size_t>(N) * W, "to_tokens gave ", x_.size(),
                        " values, expected B·N·W = ", ids.size(), "·", N, "·", W);
    return x_.data();
  }
  const WindowBatch& windows() const { return windows_; }  // the last gathered windows

 private:
  const Source& source_;
  std::uint64_t seed_;
  int batch_;
  WindowBatch windows_;
  AlignedVector<T> x_;
};

}  // namespace tjepa
