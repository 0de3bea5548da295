#pragma once
// MAE, the Sparsh-skin baseline of the paper's evaluation (Sec. IV-C): the same encoder as
// Tactile-JEPA's context encoder (tokenizer, position table, ViT blocks, final norm:
// JepaModel::context's layout, built by the same add_context_encoder), pre-trained by masked
// reconstruction of the tokenizer's input (the preprocessed taxel windows) instead of predicting
// embeddings.
//
// Legend: B samples, N tokens, K visible tokens, M = N − K masked tokens, d the encoder's width,
// pd the decoder's width, W = m·τ values per token row (the token width).
//
//   tokens = tokenizer(θ, x)                        x [B, N, W] → [B, N, d]
//   z      = encoder(θ, tokens; visible)            [B, K, d]   (drop-path, cache for backward)
//   pred   = decoder(φ, z, pos_dec at masked)       [B, M, W]   the Predictor, out_dim = W
//   y      = x[masked]                              [B, M, W]
//   y      ← (y − mean) / sqrt(var + 1e-6) per row  optional (MAE's norm_pix_loss)
//   L      = mean over (B, M, W) of (pred − y)²     masked tokens only (MAE)
//
// The decoder is the Predictor module (model/predictor.hpp): the visible embeddings projected to
// pd, then for each masked token its decoder position row plus a learned mask token, blocks,
// norm, and a projection to W. Differences from He et al.'s decoder, on purpose: the decoder adds
// no position to the visible embeddings (the encoder's output already carries its position
// table, as in Tactile-JEPA's predictor), its blocks have no biases, and it returns the masked
// rows only (MAE computes all rows and keeps the loss on the masked ones; the same loss). Its
// position table is its own, learned (MAE: fixed sin-cos), as a skin has no pixel grid.
// Sparsh-skin also concatenates taxel coordinates to the input (paper, Sec. IV-C); here the
// encoder's position table alone says where a token is, so that the encoder is exactly
// Tactile-JEPA's.
//
// Parameter names: the encoder's are JepaModel::context's ("context_encoder." + patch_embed.*,
// pos_embed, blocks.*, norm.*), so the probe and checkpoint code read either model's encoder; the
// decoder's are "decoder." + the Predictor's names (input_projection.*, mask_token, blocks.*,
// norm.*, output_projection.*) and pos_embed [1, N, pd].
//
// MaeObjective trains it through the Trainer (MaeTrainer): zero grads, forward, backward, clip,
// AdamW, as the JEPA step without the EMA (MAE has no target encoder). A NaN or Inf in the loss
// or gradient throws NumericError before any parameter changes.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/collator.hpp"
#include "tjepa/masks/uniform_masking.hpp"
#include "tjepa/kernels/gather.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/clip.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/jepa_model.hpp"
#include "tjepa/train/loss.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

// MAE's norm_pix_loss eps (its target normalization divides by sqrt(var + 1e-6)).
inline constexpr double mae_target_norm_eps = 1e-6;

struct MaeConfig : ContextEncoderConfig {
  // in_dim = encoder.dim; out_dim = token_width() (0 is read as that). The default is Tactile-
  // JEPA's predictor (4 blocks of width 192, 3 heads): the two methods spend the same compute
  // outside the encoder. Light next to the 12-block encoder, as MAE's decoder is.
  PredictorConfig decoder;
  // Share of the N tokens hidden from the encoder: ⌊N·mask_ratio⌋ masked (MAE's default 0.75).
  double mask_ratio = 0.75;
  // Each target row standardized over its W values (MAE's norm_pix_loss; biased variance, eps
  // 1e-6). Off by default: on a skin most taxels are idle in a window, and standardizing an idle
  // taxel's row blows its sensor noise up to unit variance, which no context predicts.
  bool norm_targets = false;
  // Stochastic depth in the encoder's blocks. MAE pre-trains without it (the reference
  // implementation, E-Kovtun/tactile, trains Tactile-JEPA with 0.3); the decoder has none.
  double drop_path = 0.0;
  double clip_grad_norm = 10.0;  // as the JEPA step, for the same budget
  // The decoder's position rows at the masked tokens: its own learned table (decoder.pos_embed
  // [1, N, pd], false) or the encoder's (true; needs decoder.dim = encoder.dim, and the rows then
  // get the decoder's gradient too). The encoder's rows put the masked tokens in the coordinates
  // the visible embeddings were built in; an own table must first learn to agree with them.
  bool decoder_pos_from_encoder = false;

  // The paper's encoder (ViT-Tiny, Sec. IV-D) with the default decoder and masking.
  static MaeConfig reference(int num_tokens, int in_dim, int axes = 1) {
    return reference_for<MaeConfig>(num_tokens, in_dim, axes);
  }

  // W: values per token row of the tokenizer's input (grouped tokens: the largest group's).
  int token_width() const {
    return group_size.empty() ? in_dim : *std::max_element(group_size.begin(), group_size.end()) * in_dim;
  }

  void validate() const {
    validate_encoder("MaeConfig");
    require<ConfigError>(decoder.in_dim == encoder.dim, "MaeConfig: decoder.in_dim = ", decoder.in_dim,
                         ", expected encoder.dim = ", encoder.dim);
    require<ConfigError>(decoder.out_dim == 0 || decoder.out_dim == token_width(), "MaeConfig: decoder.out_dim = ",
                         decoder.out_dim, ", expected 0 or the token width m·τ = ", token_width(),
                         " (the decoder reconstructs the tokenizer's input)");
    const int N = encoder.num_tokens, masked = static_cast<int>(std::floor(N * mask_ratio));
    require<ConfigError>(mask_ratio > 0.0 && mask_ratio < 1.0 && masked >= 1 && masked < N,
                         "MaeConfig: mask_ratio = ", mask_ratio, " masks ", masked, " of ", N,
                         " tokens, expected a ratio in (0, 1) that masks 1..", N - 1);
    require<ConfigError>(drop_path >= 0.0 && drop_path < 1.0, "MaeConfig: drop_path = ", drop_path,
                         ", expected in [0, 1)");
    require<ConfigError>(clip_grad_norm > 0.0, "MaeConfig: clip_grad_norm = ", clip_grad_norm, ", expected > 0");
    require<ConfigError>(!decoder_pos_from_encoder || decoder.dim == encoder.dim, "MaeConfig: decoder.dim = ",
                         decoder.dim, " with decoder_pos_from_encoder, expected encoder.dim = ", encoder.dim);
  }

  nlohmann::json to_json() const {
    nlohmann::json j = encoder_json();
    j["decoder"] = tjepa::to_json(decoder);
    j["mask_ratio"] = mask_ratio;
    j["norm_targets"] = norm_targets;
    j["drop_path"] = drop_path;
    j["clip_grad_norm"] = clip_grad_norm;
    j["decoder_pos_from_encoder"] = decoder_pos_from_encoder;
    return j;
  }
};

template <class T>
class MaeModel {
 public:
  MaeConfig config;  // decoder.out_dim filled in with the token width
  ParamSet<T> context, decoder_params;
  Tokenizer tokenizer;
  Encoder encoder;
  Predictor decoder;
  PositionTable decoder_pos;  // decoder_params' pos_embed [1, N, pd]; none with decoder_pos_from_encoder

  // Builds the modules and initializes them as the reference implementation does (init_params, model/init.hpp) (seeded). The encoder's values are
  // those of JepaModel(c, seed).context for the same encoder config and seed: both methods start
  // from the same encoder.
  MaeModel(const MaeConfig& c, std::uint64_t seed) : config(c) {
    c.validate();
    config.decoder.out_dim = c.token_width();
    add_context_encoder(context, c, tokenizer, encoder);
    decoder = Predictor(decoder_params, config.decoder, "");
    if (!c.decoder_pos_from_encoder)
      decoder_pos = PositionTable::add(decoder_params, "pos_embed", c.encoder.num_tokens, c.decoder.dim);
    context.allocate();
    decoder_params.allocate();
    init_context_encoder(context, tokenizer, c, seed);
    init_params(decoder_params, seed ^ 0x6465636f6465725full);  // "decoder_": an unrelated stream
  }

  // Overwrites the encoder's position table with rows [N, d] (row-major), as
  // JepaModel::set_positions (e.g. graph_positions). Init only. The decoder's table is its own.
  void set_positions(std::span<const double> rows) {
    detail::check_position_rows(rows, num_tokens(), dim(), "MaeModel::set_positions");
    std::copy(rows.begin(), rows.end(), context.value(encoder.pos_embed()));
  }

  // The position rows [N, pd] the decoder adds at the masked tokens, and their gradient.
  const T* decoder_pos_rows() const {
    return config.decoder_pos_from_encoder ? context.value(encoder.pos_embed()) : decoder_params.value(decoder_pos.table);
  }
  T* decoder_pos_grad() {
    return config.decoder_pos_from_encoder ? context.grad(encoder.pos_embed()) : decoder_params.grad(decoder_pos.table);
  }

  int num_tokens() const { return config.encoder.num_tokens; }
  int dim() const { return config.encoder.dim; }
  // W: values per token row of the tokenizer's input x [B, N, W], and of the reconstruction.
  int token_width() const { return tokenizer.width; }

  // What AdamW and gradient clipping see; a checkpoint holds the same (no target encoder).
  std::vector<PrefixedParams<T>> trainable() { return {{"context_encoder.", &context}, {"decoder.", &decoder_params}}; }
  std::vector<PrefixedParams<T>> parts() { return trainable(); }
};

// Caller-owned buffers and caches of one step: grown to the largest shape seen and reused.
template <class T>
struct MaeWorkspace {
  Workspace<T> ws;
  TokenizerCache<T> tokenizer_cache;
  EncoderCache<T> encoder_cache;
  PredictorCache<T> decoder_cache;
  AlignedVector<T> tokens;          // [B, N, d] the tokenizer's output; then its gradient
  AlignedVector<T> z, dz;           // [B, K, d] visible embeddings and their gradient
  AlignedVector<T> pred, y, dpred;  // [B, M, W] reconstruction, target rows, ∂L/∂pred
  int B = 0;                        // the batch of the forward pass held; 0: none
};

namespace detail {
// The masks mae_forward reads: context [B, K] visible, one target [B, M] masked, ids in [0, N).
inline void check_mae_masks(const MaskBatch& masks, int B, int N) {
  require<ShapeError>(masks.B == B, "mae_forward: masks for B = ", masks.B, " samples, the batch has ", B);
  require<ShapeError>(masks.K > 0 && masks.context.size() == static_cast<std::size_t>(B) * masks.K,
                      "mae_forward: ", masks.context.size(), " visible tokens, expected B·K = ", B, "·", masks.K,
                      " with K > 0");
  require<ShapeError>(masks.num_targets() == 1, "mae_forward: ", masks.num_targets(),
                      " target sets, expected 1 (the masked tokens, as UniformMasking gives)");
  const TargetSet& m = masks.targets.front();
  require<ShapeError>(m.size > 0 && m.indices.size() == static_cast<std::size_t>(B) * m.size, "mae_forward: ",
                      m.indices.size(), " masked tokens, expected B·M = ", B, "·", m.size, " with M > 0");
  check_indices(masks.context.data(), masks.context.size(), N, "mae_forward", "visible");
  check_indices(m.indices.data(), m.indices.size(), N, "mae_forward", "masked");
}
}  // namespace detail

// The MAE loss of batch x [B, N, W] (W = model.token_width()) with masks.context the visible
// and masks.targets[0] the masked tokens. Keeps in w what mae_backward needs. noise_seed drives
// drop-path: the same seed gives the same loss. A shard of a larger batch passes its offset
// first_sample, so its samples draw the batch's noise.
template <class T>
double mae_forward(MaeModel<T>& model, const T* x, int B, const MaskBatch& masks, MaeWorkspace<T>& w,
                   std::uint64_t noise_seed, std::uint64_t first_sample = 0) {
  const int N = model.num_tokens(), d = model.dim(), W = model.token_width();
  require<ShapeError>(B > 0, "mae_forward: B = ", B, ", expected > 0");
  require<ShapeError>(x != nullptr, "mae_forward: x is null, expected [B, N, W] = [", B, ", ", N, ", ", W, "]");
  detail::check_mae_masks(masks, B, N);
  const int K = masks.K, M = masks.targets.front().size;
  const int* masked = masks.targets.front().indices.data();
  w.B = 0;  // nothing to differentiate until this pass is complete
  Rng noise(noise_seed);
  const DropPath dp{model.config.drop_path, noise(), first_sample};

  T* tokens = detail::grow(w.tokens, static_cast<std::size_t>(B) * N * d);
  T* z = detail::grow(w.z, static_cast<std::size_t>(B) * K * d);
  model.tokenizer.forward(model.context, x, B, tokens, w.tokenizer_cache, w.ws);
  model.encoder.forward(model.context, {tokens, B, masks.context}, z, w.encoder_cache, w.ws, EncoderOptions{dp, nullptr});

  const std::size_t rows = static_cast<std::size_t>(B) * M;
  T* pred = detail::grow(w.pred, rows * W);
  T* y = detail::grow(w.y, rows * W);
  T* dpred = detail::grow(w.dpred, rows * W);
  model.decoder.forward(model.decoder_params, {z, B, K, model.decoder_pos_rows(), N, masked, B, M}, pred, w.decoder_cache, w.ws);
  kernels::gather_rows(y, x, static_cast<std::size_t>(N) * W, masked, B, M, W);
  if (model.config.norm_targets) normalize_rows(y, rows, W, mae_target_norm_eps);
  // dpred = ∂L/∂pred, kept for mae_backward.
  const double loss = regression_loss(pred, y, dpred, rows * W, JepaLossKind::mse);
  w.B = B;
  return loss;
}

// Adds ∂L/∂θ of the last mae_forward on w to the encoder's and decoder's gradients (zero them
// first; two calls add twice).
template <class T>
void mae_backward(MaeModel<T>& model, MaeWorkspace<T>& w) {
  require<ConfigError>(w.B > 0, "mae_backward: the workspace holds no forward pass, expected mae_forward first");
  const int N = model.num_tokens(), d = model.dim(), B = w.B, K = w.encoder_cache.K;
  T* dz = detail::grow(w.dz, static_cast<std::size_t>(B) * K * d);
  std::fill(dz, dz + static_cast<std::size_t>(B) * K * d, T(0));
  // pred = decoder(φ, z, pos_dec): into φ, the decoder's position rows and dz.
  model.decoder.backward(model.decoder_params, w.dpred.data(), dz, model.decoder_pos_grad(), w.decoder_cache, w.ws);
  // z = encoder(θ, tokens; visible), tokens = tokenizer(θ, x): the token buffer takes its gradient.
  T* dtokens = w.tokens.data();
  std::fill(dtokens, dtokens + static_cast<std::size_t>(B) * N * d, T(0));
  model.encoder.backward(model.context, dz, dtokens, w.encoder_cache, w.ws);
  model.tokenizer.backward(model.context, dtokens, w.tokenizer_cache, w.ws);
}

// What one MAE training step reports: loss = the mean squared reconstruction error over the
// masked tokens.
struct MaeStepStats : StepStats {};

// The update of MAE step s after backward: the NaN stop and clipping (clip_or_stop), then AdamW
// at the schedule's rate and weight decay for s. loss: the step's (over all ranks).
template <class T>
MaeStepStats mae_update(MaeModel<T>& model, AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s,
                        double loss) {
  MaeStepStats st;
  clipped_adamw_step<T>(st, model.trainable(), opt, schedule, s, loss, model.config.clip_grad_norm, "MAE");
  return st;
}

// zero_grad, mae_forward, mae_backward, mae_update: one optimizer step s on batch x [B, N, W]
// with its masks (what MaeObjective does each step, on arrays of the caller's).
template <class T>
MaeStepStats mae_train_step(MaeModel<T>& model, AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s,
                            const T* x, int B, const MaskBatch& masks, MaeWorkspace<T>& w, std::uint64_t noise_seed) {
  model.context.zero_grad();
  model.decoder_params.zero_grad();
  const double loss = mae_forward(model, x, B, masks, w, noise_seed);
  if (!std::isfinite(loss)) return mae_update(model, opt, schedule, s, loss);  // throws NumericError
  mae_backward(model, w);
  return mae_update(model, opt, schedule, s, loss);
}

// The MAE config of a Tactile-JEPA run's encoder: the same tokenizer and encoder as
// cfg.model_config(num_tokens, axes), Tactile-JEPA's predictor shape as the decoder.
inline MaeConfig mae_config(const TrainConfig& cfg, int num_tokens, int axes, double mask_ratio = 0.75) {
  const JepaConfig j = cfg.model_config(num_tokens, axes);
  MaeConfig m = MaeConfig::reference(num_tokens, j.in_dim, axes);
  static_cast<ContextEncoderConfig&>(m) = static_cast<const ContextEncoderConfig&>(j);
  m.decoder = j.predictor;
  m.mask_ratio = mask_ratio;
  m.drop_path = cfg.step.drop_path;
  m.clip_grad_norm = cfg.step.clip_grad_norm;
  return m;
}

// MAE pre-training as an Objective (train/objective.hpp): the same budget, schedule, AdamW and
// windows in the same order as a JepaObjective with the same TrainConfig (the shared data
// stream), uniform masks drawn from (streams::masks(seed), step), drop-path from
// streams::noise(seed, step). Of cfg it reads the data order (seed, batch), the schedule (steps,
// warm-up, rates, weight decay) and AdamW's betas and eps; the model's shape, masking, drop-path
// and clipping are the MaeConfig's. Its checkpoints: {"objective": "mae", "train": cfg, "mae":
// the MaeConfig} in the config metadata, the encoder and decoder under "context_encoder." and
// "decoder.", AdamW's moments.
template <class T, class Source = WindowSource>
class MaeObjective {
 public:
  using value_type = T;
  using stats_type = MaeStepStats;

  // The model and source must outlive the objective.
  MaeObjective(MaeModel<T>& model, const Source& source, TrainConfig config)
      : data((config.validate(), source), config.seed, config.batch), model_(model), cfg_(std::move(config)),
        masking_(model.num_tokens(), model.config.mask_ratio), optimizer_(model.trainable(), cfg_.adamw),
        schedule_(cfg_.schedule.build()) {}
  MaeObjective(const MaeObjective&) = delete;
  MaeObjective& operator=(const MaeObjective&) = delete;

  WindowBatches<T, Source> data;  // the windows and how they become tokens (data.to_tokens)

  MaeModel<T>& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  const TrainingSchedule& schedule() const { return schedule_; }
  MaeWorkspace<T>& workspace() { return w_; }

  // The Objective interface (train/objective.hpp).
  std::int64_t num_samples() const { return data.size(); }
  int batch_size() const { return cfg_.batch; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  std::vector<std::int64_t> epoch_order(std::uint64_t epoch) const { return data.epoch_order(epoch); }
  void zero_grad() {
    model_.context.zero_grad();
    model_.decoder_params.zero_grad();
  }
  double forward(const StepBatch& b) {
    require<ConfigError>(model_.config.group_size.empty() || data.to_tokens,
                         "MaeObjective: a grouped tokenizer needs its own data.to_tokens");
    const T* x = data.tokens(b.ids, model_.num_tokens(), model_.token_width());
    masking_.sample_into(masks_, b.batch, streams::masks(cfg_.seed), static_cast<std::uint64_t>(b.step));
    const MaskBatch* masks = &masks_;
    if (b.size() != b.batch) {
      masks_.slice_into(shard_masks_, b.first, b.size());
      masks = &shard_masks_;
    }
    loss_ = mae_forward(model_, x, b.size(), *masks, w_, streams::noise(cfg_.seed, b.step),
                        static_cast<std::uint64_t>(b.first));
    return loss_;
  }
  void backward() { mae_backward(model_, w_); }
  void all_reduce(const DataParallel<T>& dp, int count, int B) {
    double stats[1] = {loss_};
    const auto parts = model_.trainable();
    all_reduce_mean<T>(parts, stats, dp, count, B);
    loss_ = stats[0];
  }
  MaeStepStats update(std::int64_t s) { return mae_update(model_, optimizer_, schedule_, s, loss_); }
  std::vector<PrefixedParams<T>> parts() { return model_.parts(); }
  AdamW<T>& optimizer() { return optimizer_; }
  nlohmann::json metadata() const {
    return {{"objective", "mae"}, {"train", cfg_.to_json()}, {"mae", model_.config.to_json()}};
  }

 private:
  MaeModel<T>& model_;
  TrainConfig cfg_;
  UniformMasking masking_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  MaeWorkspace<T> w_;
  MaskBatch masks_, shard_masks_;
  double loss_ = 0;
};

template <class T, class Source = WindowSource>
using MaeTrainer = Trainer<MaeObjective<T, Source>>;

}  // namespace tjepa
