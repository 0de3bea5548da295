#pragma once
// The JEPA training step (paper, Sec. III-B; training details in Sec. IV-D) as verbs, the way
// llm.c reads:
//
//   JepaStep<float> step(model, cfg);          // loss: cfg.loss, or any JepaLoss callable
//   step.zero_grad();
//   step.forward(x, B, masks, noise_seed);     // the loss; keeps what backward needs
//   step.backward();                           // adds ∂L/∂θ into the trainable gradients
//   step.update(opt, schedule, s);             // clip, AdamW at step s's rates, EMA
//
// forward computes
//   tokens  = tokenizer(θ, x)                     x [B, N, W] → [B, N, d]
//   z       = encoder(θ, tokens; context)         [B, K, d]      (drop-path, cache for backward)
//   h       = encoder(θ̄, tokenizer(θ̄, x))         [B, N, d]      target encoder: no cache, no grad
//   h       ← LayerNorm_no_affine(h)              optional (I-JEPA)
//   h       ← standardized per token over B        optional (standardize_columns)
//   for each group of R targets of equal size t (order of first appearance):
//     p     = predictor(φ, z tiled R times, pos rows at the targets)   [R·B, t, d]
//     L_j   = loss(p_j, h[targets_j])             one per target j, with ∂L_j/∂p_j
//   L       = mean_j L_j
// and backward runs the predictor, the context encoder, the position table and the tokenizer
// backwards. The position rows the predictor adds are the target encoder's (the reference; no
// gradient) or, as an option, the context encoder's (then they get the predictor's gradient too).
// update throws NumericError on a NaN or Inf loss or gradient before any parameter changes.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/kernels/gather.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/ema.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/data_parallel.hpp"
#include "tjepa/train/health.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/loss.hpp"
#include "tjepa/train/objective.hpp"

namespace tjepa {

struct JepaStepConfig {
  JepaLossKind loss = JepaLossKind::mse;  // the loss when JepaStep is given no callable
  bool normalize_targets = false;         // I-JEPA's LayerNorm without affine on the targets
  // Each target token's each dimension standardized over the batch (standardize_columns; after
  // normalize_targets if both): what every sample's embedding shares at a token (its position)
  // is removed, and what is left is what the samples differ in. Not in the reference. Needs B ≥ 2.
  bool standardize_targets = false;
  bool predictor_pos_from_context = false;  // reference: the target encoder's position table
  // Stochastic depth in every block: off by default, as a short run (TrainConfig's default reads
  // this one); the reference's 0.3 is TrainConfig::reference()'s.
  double drop_path = 0.0;
  bool target_drop_path = true;           // the reference's target encoder runs in train mode too
  double clip_grad_norm = 10.0;
  // The products' arithmetic in every forward and backward of the step (Workspace::precision):
  // bf16 operands with fp32 accumulation, or fp32. Parameters, gradients, optimizer state, EMA,
  // attention, norms and the loss stay fp32 either way.
  Precision precision = Precision::fp32;

  nlohmann::json to_json() const {
    return {{"loss", to_string(loss)},       {"normalize_targets", normalize_targets},
            {"precision", precision_name(precision)},
            {"standardize_targets", standardize_targets},
            {"predictor_pos_from_context", predictor_pos_from_context},
            {"drop_path", drop_path},        {"target_drop_path", target_drop_path},
            {"clip_grad_norm", clip_grad_norm}};
  }
};

// Caller-visible buffers and caches of one step: the activation-sized buffers grow to the largest
// shape seen and are reused, so steady-state steps allocate only a few small index vectors.
template <class T>
struct JepaWorkspace {
  // The targets of one size t, predicted in one predictor pass of R·B rows.
  struct TargetGroup {
    std::vector<int> targets;        // [R] target indices into the MaskBatch
    int t = 0;
    std::vector<int> idx;            // [R·B, t] target token ids
    PredictorCache<T> cache;
    AlignedVector<T> pred, y, dpred; // [R·B, t, d] predictions, targets, ∂L/∂pred
  };
  Workspace<T> ws;
  TokenizerCache<T> tokenizer_cache;
  EncoderCache<T> context_cache;
  AlignedVector<T> tokens;      // [B, N, d] the context encoder's tokens; then their gradient
  AlignedVector<T> h;           // [B, N, d] target embeddings
  AlignedVector<T> z, dz;       // [B, K, d] context embeddings and their gradient
  std::vector<TargetGroup> groups;
  std::size_t num_groups = 0;   // groups[0, num_groups) belong to the last forward
  ColumnMoments token_moments;  // of the target embeddings as [B·N, d] (target_std)
  ColumnMoments sample_moments; // as [B, N·d] (target_sample_std)
  // Times the phases of each step when set (bench/scale.cpp): zero_grad, target tokenizer, target
  // encoder, target statistics, context tokenizer, context encoder, then per target group predictor
  // forward and loss, then predictor backward (per group), context encoder backward, tokenizer
  // backward, clip, AdamW, EMA. nullptr: off (a phase then costs one test of the pointer).
  StageClock* clock = nullptr;
  void mark(const char* phase) {
    if (clock) clock->mark(phase);
  }
};

// What the forward pass found.
struct JepaLossResult {
  double loss = 0;
  double target_std = 0;
  double target_sample_std = 0;
  std::vector<double> target_losses;  // [num targets]
};

namespace detail {
inline void check_masks(const MaskBatch& masks, int B, int N) {
  require<ShapeError>(masks.B == B, "JEPA step: masks for B = ", masks.B, " samples, batch has ", B);
  require<ShapeError>(masks.K > 0 && masks.context.size() == static_cast<std::size_t>(B) * masks.K,
                      "JEPA step: context of ", masks.context.size(), " indices, expected B·K = ", B, "·", masks.K);
  require<ShapeError>(masks.num_targets() > 0, "JEPA step: no targets");
  for (int v : masks.context)
    require<ShapeError>(v >= 0 && v < N, "JEPA step: context token ", v, ", expected in [0, ", N, ")");
  for (int j = 0; j < masks.num_targets(); ++j) {
    const TargetSet& ts = masks.targets[static_cast<std::size_t>(j)];
    require<ShapeError>(ts.size > 0 && ts.indices.size() == static_cast<std::size_t>(B) * ts.size,
                        "JEPA step: target ", j, " holds ", ts.indices.size(), " indices, expected B·t = ", B, "·",
                        ts.size);
    for (int v : ts.indices)
      require<ShapeError>(v >= 0 && v < N, "JEPA step: target ", j, " token ", v, ", expected in [0, ", N, ")");
  }
}
}  // namespace detail

template <class T>
class JepaStep {
 public:
  // The model must outlive the step. loss: the regression loss of one target (empty: cfg.loss).
  explicit JepaStep(JepaModel<T>& model, JepaStepConfig cfg = {}, JepaLoss<T> loss = {})
      : model_(model), cfg_(cfg), loss_(loss ? std::move(loss) : jepa_loss_of<T>(cfg.loss)) {
    w_.ws.precision = cfg.precision;
  }

  const JepaStepConfig& config() const { return cfg_; }
  JepaWorkspace<T>& workspace() { return w_; }
  const JepaLossResult& result() const { return result_; }

  // Sets the trainable gradients (context encoder and predictor) to 0.
  void zero_grad() {
    model_.context.zero_grad();
    model_.predictor_params.zero_grad();
    w_.mark("zero_grad");
  }

  // The JEPA loss of batch x [B, N, W] (W = model.token_width()) with its masks; keeps what
  // backward needs. noise_seed drives drop-path: the same seed gives the same result. A shard of
  // a larger batch passes its offset first_sample, so its samples draw the batch's noise.
  const JepaLossResult& forward(const T* x, int B, const MaskBatch& masks, std::uint64_t noise_seed,
                                std::uint64_t first_sample = 0) {
    JepaModel<T>& model = model_;
    const int N = model.num_tokens(), d = model.dim(), K = masks.K;
    require<ShapeError>(B > 0, "JepaStep::forward: B = ", B, ", expected > 0");
    require<ShapeError>(x != nullptr, "JepaStep::forward: x is null");
    detail::check_masks(masks, B, N);
    backward_ready_ = false;
    B_ = B;
    K_ = K;
    const std::size_t BN = static_cast<std::size_t>(B) * N;
    Rng noise(noise_seed);
    const DropPath context_dp{cfg_.drop_path, noise(), first_sample};
    const DropPath target_dp{cfg_.target_drop_path ? cfg_.drop_path : 0.0, noise(), first_sample};

    // Target encoder on every token: no cache, no gradient.
    T* h = detail::grow(w_.h, BN * d);
    T* tokens = detail::grow(w_.tokens, BN * d);
    model.tokenizer.forward(model.target, x, B, tokens, w_.ws);
    w_.mark("target tokenizer");
    model.encoder.forward(model.target, {tokens, B}, h, w_.ws, EncoderOptions{target_dp, nullptr});
    w_.mark("target encoder");
    JepaLossResult& result = result_;
    w_.token_moments = column_moments(h, BN, d);
    result.target_std = w_.token_moments.mean_std();
    // h as [B, N·d]: the spread over the batch at each token and dimension.
    w_.sample_moments = column_moments(h, static_cast<std::size_t>(B), N * d);
    result.target_sample_std = w_.sample_moments.mean_std();
    if (cfg_.normalize_targets) normalize_rows(h, BN, d);
    if (cfg_.standardize_targets) {
      require<ConfigError>(B >= 2, "JepaStep: standardize_targets needs a batch of at least 2 samples, got ", B);
      standardize_columns(h, static_cast<std::size_t>(B), static_cast<std::size_t>(N) * d);
    }
    w_.mark("target statistics");

    // Context encoder on the context tokens.
    T* z = detail::grow(w_.z, static_cast<std::size_t>(B) * K * d);
    model.tokenizer.forward(model.context, x, B, tokens, w_.tokenizer_cache, w_.ws);
    w_.mark("context tokenizer");
    model.encoder.forward(model.context, {tokens, B, masks.context}, z, w_.context_cache, w_.ws, EncoderOptions{context_dp, nullptr});
    w_.mark("context encoder");

    const int num_targets = masks.num_targets();
    result.target_losses.assign(static_cast<std::size_t>(num_targets), 0.0);
    std::vector<char> done(static_cast<std::size_t>(num_targets), 0);
    w_.num_groups = 0;
    for (int first = 0; first < num_targets; ++first) {
      if (done[static_cast<std::size_t>(first)]) continue;
      if (w_.groups.size() <= w_.num_groups) w_.groups.emplace_back();
      auto& g = w_.groups[w_.num_groups++];
      g.t = masks.targets[static_cast<std::size_t>(first)].size;
      g.targets.clear();
      for (int j = first; j < num_targets; ++j)
        if (!done[static_cast<std::size_t>(j)] && masks.targets[static_cast<std::size_t>(j)].size == g.t) {
          g.targets.push_back(j);
          done[static_cast<std::size_t>(j)] = 1;
        }
      const int R = static_cast<int>(g.targets.size()), t = g.t;
      const std::size_t rows = static_cast<std::size_t>(B) * t;  // one target's rows
      int* idx = detail::grow(g.idx, R * rows);
      for (int r = 0; r < R; ++r) {
        const auto& src = masks.targets[static_cast<std::size_t>(g.targets[static_cast<std::size_t>(r)])].indices;
        std::copy(src.begin(), src.end(), idx + r * rows);
      }
      T* pred = detail::grow(g.pred, R * rows * d);
      T* y = detail::grow(g.y, R * rows * d);
      T* dpred = detail::grow(g.dpred, R * rows * d);
      // Row r·B + b of the tiled batch predicts target r of sample b from context b.
      model.predictor.forward(model.predictor_params, {z, B, K, position_rows(), N, idx, R * B, t}, pred, g.cache, w_.ws);
      w_.mark("predictor forward");
      for (int r = 0; r < R; ++r)
        kernels::gather_rows(y + r * rows * d, h, static_cast<std::size_t>(N) * d, idx + r * rows, B, t, d);
      for (int r = 0; r < R; ++r) {
        const std::size_t off = r * rows * d, n = rows * d;
        const double l = loss_(std::span<const T>(pred + off, n), std::span<const T>(y + off, n), rows, d,
                               std::span<T>(dpred + off, n));
        // L = mean_j L_j: each target's gradient is scaled by 1 / num_targets.
        const T scale = static_cast<T>(1.0 / num_targets);
        detail::simd_scale(scale, dpred + off, dpred + off, n);
        result.target_losses[static_cast<std::size_t>(g.targets[static_cast<std::size_t>(r)])] = l;
      }
      w_.mark("loss");
    }
    double sum = 0;
    for (double l : result.target_losses) sum += l;
    result.loss = sum / num_targets;
    backward_ready_ = true;
    return result;
  }

  // Adds ∂L/∂θ of the last forward into the context encoder's and the predictor's gradients
  // (and, with predictor_pos_from_context, the position table's).
  void backward() {
    require<ConfigError>(backward_ready_, "JepaStep::backward: no forward pass to differentiate (call forward first)");
    JepaModel<T>& model = model_;
    const int N = model.num_tokens(), d = model.dim();
    const std::size_t BN = static_cast<std::size_t>(B_) * N, BKd = static_cast<std::size_t>(B_) * K_ * d;
    T* dz = detail::grow(w_.dz, BKd);
    std::fill(dz, dz + BKd, T(0));
    T* dpos = cfg_.predictor_pos_from_context ? model.context.grad(model.encoder.pos_embed()) : nullptr;
    for (std::size_t k = 0; k < w_.num_groups; ++k) {
      model.predictor.backward(model.predictor_params, w_.groups[k].dpred.data(), dz, dpos, w_.groups[k].cache, w_.ws);
      w_.mark("predictor backward");
    }
    // The context tokens' gradient reuses their buffer: the forward values are no longer needed.
    T* dtokens = w_.tokens.data();
    std::fill(dtokens, dtokens + BN * d, T(0));
    model.encoder.backward(model.context, dz, dtokens, w_.context_cache, w_.ws);
    w_.mark("context encoder backward");
    model.tokenizer.backward(model.context, dtokens, w_.tokenizer_cache, w_.ws);
    w_.mark("tokenizer backward");
    backward_ready_ = false;  // the token buffer now holds gradients
  }

  // Data parallel (train/data_parallel.hpp): this rank's forward and backward covered `count` of
  // the global batch's B samples. Scales the gradients by count / B and sums them over the ranks,
  // the loss likewise, so that update() sees the global batch's gradient and loss on every rank;
  // target_std and target_sample_std are recomputed from the ranks' summed column moments. Exact
  // for a loss that is a plain mean over the rows of a target (MSE, smooth-L1, a user's per-row
  // loss): it must not use statistics over the batch.
  void all_reduce(const DataParallel<T>& dp, int count, int B) {
    require<ConfigError>(!cfg_.standardize_targets,
                         "JepaStep::all_reduce: standardize_targets uses the whole batch's statistics; a shard "
                         "cannot compute them");
    JepaLossResult& r = result_;
    std::vector<double> stats{r.loss};
    stats.insert(stats.end(), r.target_losses.begin(), r.target_losses.end());
    const auto parts = model_.trainable();
    all_reduce_mean<T>(parts, stats, dp, count, B);
    r.loss = stats[0];
    std::copy(stats.begin() + 1, stats.end(), r.target_losses.begin());
    // Moments over all ranks' rows: Σ n·mean and Σ (m2 + n·mean²) per column, and Σ n.
    const auto combine = [&](ColumnMoments& m) {
      const std::size_t D = m.mean.size();
      const double n = static_cast<double>(m.rows);
      std::vector<double> v(2 * D + 1);
      for (std::size_t j = 0; j < D; ++j) {
        v[j] = n * m.mean[j];
        v[D + j] = m.m2[j] + n * m.mean[j] * m.mean[j];
      }
      v[2 * D] = n;
      dp.sum_stats(std::span<double>(v));
      m.rows = static_cast<std::size_t>(v[2 * D]);
      for (std::size_t j = 0; j < D; ++j) {
        m.mean[j] = v[j] / v[2 * D];
        m.m2[j] = std::max(0.0, v[D + j] - v[2 * D] * m.mean[j] * m.mean[j]);
      }
      return m.mean_std();
    };
    r.target_std = combine(w_.token_moments);
    r.target_sample_std = combine(w_.sample_moments);
  }

  // Optimizer step s (0-based) on the gradients: the non-finite check, clipping, AdamW with the
  // schedule's rate and weight decay at s, the target encoder's EMA. Returns the step's stats.
  JepaStepStats update(AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s) {
    const JepaLossResult& r = result_;
    JepaStepStats st;
    clipped_adamw_step<T>(st, model_.trainable(), opt, schedule, s, r.loss, cfg_.clip_grad_norm, "JEPA", w_.clock);
    st.momentum = schedule.momentum_at(s);
    st.target_std = r.target_std;
    st.target_sample_std = r.target_sample_std;
    st.target_losses = r.target_losses;
    ema_update(model_.target, model_.context, st.momentum);
    w_.mark("EMA");
    return st;
  }

  // zero_grad, forward, backward, update: one optimizer step s on batch x with its masks.
  JepaStepStats train(AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s, const T* x, int B,
                      const MaskBatch& masks, std::uint64_t noise_seed) {
    zero_grad();
    forward(x, B, masks, noise_seed);
    backward();
    return update(opt, schedule, s);
  }

 private:
  const T* position_rows() const {
    const ParamSet<T>& pos_set = cfg_.predictor_pos_from_context ? model_.context : model_.target;
    return pos_set.value(model_.encoder.pos_embed());
  }

  JepaModel<T>& model_;
  JepaStepConfig cfg_;
  JepaLoss<T> loss_;
  JepaWorkspace<T> w_;
  JepaLossResult result_;
  int B_ = 0, K_ = 0;
  bool backward_ready_ = false;
};

}  // namespace tjepa
