#pragma once
// The JEPA training step (REFERENCE §5), composed from the building blocks:
//
//   tokens  = tokenizer(θ, x)                     x [B, N, W] → [B, N, d]
//   z       = encoder(θ, tokens; context)         [B, K, d]      (drop-path, cache for backward)
//   h       = encoder(θ̄, tokenizer(θ̄, x))         [B, N, d]      target encoder: no cache, no grad
//   h       ← LayerNorm_no_affine(h)              optional (I-JEPA)
//   h       ← standardized per token over B        optional (standardize_columns)
//   for each group of R targets of equal size t (order of first appearance):
//     p     = predictor(φ, z tiled R times, pos rows at the targets)   [R·B, t, d]
//     L_j   = mean over (B, t, d) of ℓ(p_j − h[targets_j])            one per target j
//   L       = mean_j L_j
// and backward through the predictor, the context encoder, the position table and the tokenizer.
// The position rows the predictor adds are the target encoder's (the reference; no gradient) or,
// as an option, the context encoder's (then they get the predictor's gradient too).
//
// jepa_train_step adds the optimizer: zero grads, forward/backward, clip at 10, AdamW with the
// scheduled lr and weight decay, EMA of the target encoder. A NaN or Inf in the loss or gradient
// throws NumericError before any parameter changes.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/model/kernels/gather.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/ema.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/health.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/loss.hpp"

namespace tjepa {

struct JepaStepConfig {
  JepaLossKind loss = JepaLossKind::mse;
  bool normalize_targets = false;         // I-JEPA's LayerNorm without affine on the targets
  // Each target token's each dimension standardized over the batch (standardize_columns; after
  // normalize_targets if both). Not in the reference. On a skin whose taxels are idle in most
  // windows, an encoder that embeds each taxel by its position alone predicts the plain targets
  // almost perfectly (the simulated Allegro hand with graph positions: loss 1e-4, spread over
  // samples 0.048 → 0.006); standardized, a token's position predicts nothing, and only what the
  // samples differ in (the contacts) can lower the loss. Needs B ≥ 2.
  bool standardize_targets = false;
  bool predictor_pos_from_context = false;  // reference: the target encoder's position table
  double drop_path = 0.3;                 // the reference's stochastic depth in every block
  bool target_drop_path = true;           // the reference's target encoder runs in train mode too
  double clip_grad_norm = 10.0;
  // λ ≥ 0: each target token's error is weighted by 1 + λ·a/ā, a = the mean square of the token's
  // input row x[b, n, :] (preprocessed, so an idle taxel reads ≈ 0) and ā its mean over the batch;
  // the loss stays a weighted mean. 0 is the reference's plain mean. On a skin where most taxels
  // are idle in every window, the plain mean is mostly the error at idle tokens, which are trivially
  // predictable; λ moves the loss's weight to the tokens in contact.
  double activity_weight = 0.0;

  nlohmann::json to_json() const {
    return {{"loss", to_string(loss)},       {"normalize_targets", normalize_targets},
            {"standardize_targets", standardize_targets},
            {"predictor_pos_from_context", predictor_pos_from_context},
            {"drop_path", drop_path},        {"target_drop_path", target_drop_path},
            {"clip_grad_norm", clip_grad_norm}, {"activity_weight", activity_weight}};
  }
};

// Caller-owned buffers and caches of one step: the activation-sized buffers grow to the largest
// shape seen and are reused, so steady-state steps allocate only a few small index vectors.
template <class T>
struct JepaWorkspace {
  Workspace<T> ws;
  TokenizerCache<T> tokenizer_cache;
  EncoderCache<T> context_cache;
  PredictorCache<T> predictor_cache;
  AlignedVector<T> tokens;      // [B, N, d] the context encoder's tokens; then their gradient
  AlignedVector<T> h;           // [B, N, d] target embeddings
  AlignedVector<T> z, dz;       // [B, K, d] context embeddings and their gradient
  AlignedVector<T> pred, y, dpred;  // [R·B, t, d] predictions, targets, ∂L/∂pred of a group
  std::vector<int> idx;         // [R·B, t] target token ids of a group
  std::vector<double> token_weight, row_weight;  // [B, N] and [R·B·t]: JepaStepConfig::activity_weight
};

// What the forward pass found.
struct JepaLossResult {
  double loss = 0;
  double target_std = 0;
  double target_sample_std = 0;
  std::vector<double> target_losses;  // [num targets]
};

namespace detail {
// JepaStepConfig::activity_weight: weight [BN] = 1 + λ·a/ā of the rows x [BN, W].
template <class T>
const double* activity_weights(const T* x, std::size_t BN, int W, double lambda, std::vector<double>& weight) {
  weight.resize(BN);
  for (std::size_t i = 0; i < BN; ++i) {
    double a = 0;
    for (int k = 0; k < W; ++k) a += static_cast<double>(x[i * W + k]) * static_cast<double>(x[i * W + k]);
    weight[i] = a / W;
  }
  double mean = 0;
  for (double a : weight) mean += a;
  mean /= static_cast<double>(BN);
  for (double& a : weight) a = 1.0 + (mean > 0 ? lambda * a / mean : 0.0);
  return weight.data();
}

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

// The JEPA loss of one batch; with backward = true its gradient is added to the context and
// predictor gradients (zero them first). x [B, N, W] is the tokenizer's input (W =
// model.token_width()). noise_seed drives drop-path: the same seed gives the same result.
template <class T>
JepaLossResult jepa_loss(JepaModel<T>& model, const T* x, int B, const MaskBatch& masks, JepaWorkspace<T>& w,
                         const JepaStepConfig& cfg, std::uint64_t noise_seed, bool backward = true) {
  const int N = model.num_tokens(), d = model.dim(), K = masks.K;
  require<ShapeError>(B > 0, "jepa_loss: B = ", B, ", expected > 0");
  detail::check_masks(masks, B, N);
  const std::size_t BN = static_cast<std::size_t>(B) * N;
  Rng noise(noise_seed);
  const DropPath context_dp{cfg.drop_path, noise()};
  const DropPath target_dp{cfg.target_drop_path ? cfg.drop_path : 0.0, noise()};

  // Target encoder on every token: no cache, no gradient.
  T* h = detail::grow(w.h, BN * d);
  T* tokens = detail::grow(w.tokens, BN * d);
  model.tokenizer.forward(model.target, x, B, tokens, nullptr, w.ws);
  model.encoder.forward(model.target, tokens, B, nullptr, N, h, nullptr, w.ws, EncoderOptions{target_dp, nullptr});
  JepaLossResult result;
  result.target_std = embedding_std(h, BN, d);
  // h as [B, N·d]: the spread over the batch at each token and dimension.
  result.target_sample_std = embedding_std(h, static_cast<std::size_t>(B), N * d);
  if (cfg.normalize_targets) normalize_rows(h, BN, d);
  if (cfg.standardize_targets) {
    require<ConfigError>(B >= 2, "jepa_loss: standardize_targets needs a batch of at least 2 samples, got ", B);
    standardize_columns(h, static_cast<std::size_t>(B), static_cast<std::size_t>(N) * d);
  }

  // Context encoder on the context tokens.
  T* z = detail::grow(w.z, static_cast<std::size_t>(B) * K * d);
  model.tokenizer.forward(model.context, x, B, tokens, backward ? &w.tokenizer_cache : nullptr, w.ws);
  model.encoder.forward(model.context, tokens, B, masks.context.data(), K, z, backward ? &w.context_cache : nullptr,
                        w.ws, EncoderOptions{context_dp, nullptr});
  T* dz = nullptr;
  if (backward) {
    dz = detail::grow(w.dz, static_cast<std::size_t>(B) * K * d);
    std::fill(dz, dz + static_cast<std::size_t>(B) * K * d, T(0));
  }

  const ParamSet<T>& pos_set = cfg.predictor_pos_from_context ? model.context : model.target;
  const T* pos = pos_set.value(model.encoder.pos_embed());
  T* dpos = backward && cfg.predictor_pos_from_context ? model.context.grad(model.encoder.pos_embed()) : nullptr;
  const int num_targets = masks.num_targets();
  const double* token_weight = nullptr;
  if (cfg.activity_weight > 0) {
    require<ConfigError>(std::isfinite(cfg.activity_weight), "jepa_loss: activity_weight = ", cfg.activity_weight);
    token_weight = detail::activity_weights(x, BN, model.token_width(), cfg.activity_weight, w.token_weight);
  }
  result.target_losses.assign(static_cast<std::size_t>(num_targets), 0.0);
  std::vector<char> done(static_cast<std::size_t>(num_targets), 0);
  for (int first = 0; first < num_targets; ++first) {
    if (done[static_cast<std::size_t>(first)]) continue;
    const int t = masks.targets[static_cast<std::size_t>(first)].size;
    std::vector<int> group;  // targets of this size, in order
    for (int j = first; j < num_targets; ++j)
      if (!done[static_cast<std::size_t>(j)] && masks.targets[static_cast<std::size_t>(j)].size == t) {
        group.push_back(j);
        done[static_cast<std::size_t>(j)] = 1;
      }
    const int R = static_cast<int>(group.size());
    const std::size_t rows = static_cast<std::size_t>(B) * t;  // one target's rows
    int* idx = detail::grow(w.idx, R * rows);
    for (int r = 0; r < R; ++r) {
      const auto& src = masks.targets[static_cast<std::size_t>(group[static_cast<std::size_t>(r)])].indices;
      std::copy(src.begin(), src.end(), idx + r * rows);
    }
    T* pred = detail::grow(w.pred, R * rows * d);
    T* y = detail::grow(w.y, R * rows * d);
    T* dpred = backward ? detail::grow(w.dpred, R * rows * d) : nullptr;
    // Row r·B + b of the tiled batch predicts target r of sample b from context b.
    model.predictor.forward(model.predictor_params, z, B, K, pos, N, idx, R * B, t, pred,
                            backward ? &w.predictor_cache : nullptr, w.ws);
    for (int r = 0; r < R; ++r) gather_rows(y + r * rows * d, h, static_cast<std::size_t>(N) * d, idx + r * rows, B, t, d);
    const double* row_weight = nullptr;
    if (token_weight) {
      w.row_weight.resize(R * rows);
      for (std::size_t q = 0; q < R * rows; ++q)
        w.row_weight[q] = token_weight[(q % rows) / t * N + idx[q]];
      row_weight = w.row_weight.data();
    }
    for (int r = 0; r < R; ++r) {
      const std::size_t off = r * rows * d;
      const double l = regression_loss(pred + off, y + off, dpred ? dpred + off : nullptr, rows * d, cfg.loss,
                                       1.0 / num_targets, row_weight ? row_weight + r * rows : nullptr, d);
      result.target_losses[static_cast<std::size_t>(group[static_cast<std::size_t>(r)])] = l;
    }
    if (backward) model.predictor.backward(model.predictor_params, dpred, dz, dpos, w.predictor_cache, w.ws);
  }
  double sum = 0;
  for (double l : result.target_losses) sum += l;
  result.loss = sum / num_targets;

  if (backward) {
    // The context tokens' gradient reuses their buffer: the forward values are no longer needed.
    std::fill(tokens, tokens + BN * d, T(0));
    model.encoder.backward(model.context, dz, tokens, w.context_cache, w.ws);
    model.tokenizer.backward(model.context, tokens, static_cast<T*>(nullptr), w.tokenizer_cache, w.ws);
  }
  return result;
}

// One optimizer step s (0-based) on batch x with its masks. See the header comment.
template <class T>
JepaStepStats jepa_train_step(JepaModel<T>& model, AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s,
                              const T* x, int B, const MaskBatch& masks, JepaWorkspace<T>& w,
                              const JepaStepConfig& cfg, std::uint64_t noise_seed) {
  model.context.zero_grad();
  model.predictor_params.zero_grad();
  JepaLossResult r = jepa_loss(model, x, B, masks, w, cfg, noise_seed, true);
  if (!std::isfinite(r.loss))
    fail<NumericError>("JEPA step ", s, ": the loss is ", r.loss,
                       "; training stopped before the update (parameters and checkpoints are unchanged)");
  const auto parts = model.trainable();
  const double norm = clip_grad_norm<T>(parts, cfg.clip_grad_norm);
  if (!std::isfinite(norm))
    fail<NumericError>("JEPA step ", s, ": the gradient norm is ", norm, " (loss ", r.loss,
                       "); training stopped before the update (parameters and checkpoints are unchanged)");
  JepaStepStats st;
  st.step = s;
  st.loss = r.loss;
  st.lr = schedule.lr_at(s);
  st.weight_decay = schedule.wd_at(s);
  st.momentum = schedule.momentum_at(s);
  st.grad_norm = norm;
  st.target_std = r.target_std;
  st.target_sample_std = r.target_sample_std;
  st.target_losses = std::move(r.target_losses);
  opt.step(st.lr, st.weight_decay);
  ema_update(model.target, model.context, st.momentum);
  return st;
}

}  // namespace tjepa
