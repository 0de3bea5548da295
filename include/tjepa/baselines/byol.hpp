#pragma once
// BYOL as T-DEX runs it (Guzey et al. 2023), the BYOL baseline of the paper's Table 3, following
// the Tactile-JEPA reference code's "paper-like" Xela BYOL (BYOLModule and XelaBYOLDataset in
// tactile_ssl): each window's middle frame drawn as an image (baselines/taxel_image.hpp), two
// augmented views of it, an online network that predicts the target network's projection of the
// other view.
//
// Legend: B windows, S the image side, A the skin's axes (the image's channels), F the encoder's
// output (256·6·6 = 9216 at AlexNet's widths), P the projection, H the MLPs' hidden width.
//
//   v₁, v₂      = two augmented images of each window's frame `frame` (T-DEX's augmentations)
//   f           = alexnet(θ, [v₁; v₂])                  [2B, F]   (baselines/alexnet.hpp)
//   zᵢ          = projector(θ, fᵢ),  pᵢ = predictor(θ, zᵢ)  [B, P] each view its own batch
//   z'ᵢ         = projector(ξ, alexnet(ξ, vᵢ))           the target network, no gradient
//   L           = mean_b [ℓ(p₁, z'₂) + ℓ(p₂, z'₁)],  ℓ(p, z) = 2 − 2 p·z / (‖p‖ ‖z‖)
//   update      = clip, AdamW on θ (encoder, projector, predictor); ξ ← m ξ + (1 − m) θ for the
//                 encoder and the projector (m = momentum, constant)
//
// Defaults are the reference's: projection 1024, hidden 4096, momentum 0.99, image 224, crop and
// blur with probability 0.5. Differences, on purpose: AlexNet starts from random weights (no
// ImageNet weights can be fetched here; the reference loads torchvision's); AdamW, learning rate,
// weight decay, batch and steps are the run's (TrainConfig), so that every baseline of the
// protocol has one budget (the reference: Adam 1e-3, weight decay 1e-5, batch 1024); the images of
// standardized windows clamp at ±range standard deviations rather than ±500 raw counts.
//
// Data parallel as PyTorch's DistributedDataParallel: BatchNorm's statistics are each rank's
// shard's (as without SyncBatchNorm), so R ranks train like R BatchNorm batches of B / R.
//
// Parameter names: "online_encoder." (torchvision's features.0/3/6/8/10), "online_projector."
// and "online_predictor." (net.0/1/3, baselines/projection_mlp.hpp); the target's "target_encoder."
// and "target_projector.". A checkpoint holds all five, so a resumed run continues bit for bit.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <ostream>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/baselines/taxel_image.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/baselines/alexnet.hpp"
#include "tjepa/model/init.hpp"
#include "tjepa/baselines/projection_mlp.hpp"
#include "tjepa/optim/adamw.hpp"
#include "tjepa/optim/ema.hpp"
#include "tjepa/optim/schedule.hpp"
#include "tjepa/train/config.hpp"
#include "tjepa/train/objective.hpp"
#include "tjepa/train/trainer.hpp"

namespace tjepa {

struct ByolConfig {
  AlexNetConfig encoder;   // in_channels = the skin's axes; encoder.image_size = image.image_size
  TaxelImageConfig image;  // the views
  int projection = 1024;   // P
  int hidden = 4096;       // H of the projector and the predictor
  double momentum = 0.99;  // of the target's EMA, constant
  double bn_eps = 1e-5;
  double clip_grad_norm = 10.0;
  int frame = -1;  // the window's frame drawn; -1: the middle one (τ/2)

  ProjectionMlpConfig projector() const { return {encoder.out_dim(), hidden, projection, bn_eps}; }
  ProjectionMlpConfig predictor() const { return {projection, hidden, projection, bn_eps}; }

  void validate() const {
    encoder.validate();
    image.validate(encoder.in_channels);
    require<ConfigError>(encoder.image_size == image.image_size, "ByolConfig: encoder.image_size = ",
                         encoder.image_size, ", image.image_size = ", image.image_size, ", expected equal");
    projector().validate();
    predictor().validate();
    require<ConfigError>(momentum >= 0 && momentum <= 1, "ByolConfig: momentum = ", momentum, ", expected in [0, 1]");
    require<ConfigError>(clip_grad_norm > 0, "ByolConfig: clip_grad_norm = ", clip_grad_norm, ", expected > 0");
    require<ConfigError>(frame >= -1, "ByolConfig: frame = ", frame, ", expected >= 0 or -1 (the middle)");
  }

  nlohmann::json to_json() const {
    return {{"image_size", image.image_size},
            {"channels", encoder.in_channels},
            {"widths", encoder.widths},
            {"pooled", encoder.pooled},
            {"range", image.range},
            {"crop", {image.crop_probability, image.crop_scale, image.crop_ratio}},
            {"blur", {image.blur_probability, image.blur_sigma}},
            {"normalize", {image.mean, image.std}},
            {"projection", projection},
            {"hidden", hidden},
            {"momentum", momentum},
            {"bn_eps", bn_eps},
            {"clip_grad_norm", clip_grad_norm},
            {"frame", frame}};
  }
};

// The BYOL config of a run on windows standardized per axis with `axes` channels: the
// reference's sizes, images clamped at ±3 standard deviations, the run's gradient clipping.
inline ByolConfig byol_config(const TrainConfig& cfg, int axes) {
  ByolConfig c;
  c.encoder.in_channels = axes;
  c.image = TaxelImageConfig::for_channels(axes);
  c.image.range = 3.0;
  c.clip_grad_norm = cfg.step.clip_grad_norm;
  return c;
}

template <class T>
class ByolModel {
 public:
  ByolConfig config;
  ParamSet<T> online, projector_params, predictor_params, target, target_projector;
  AlexNet encoder;
  ProjectionMlp projector, predictor;

  ByolModel(const ByolConfig& c, std::uint64_t seed) : config(c) {
    c.validate();
    encoder = AlexNet(online, c.encoder);
    projector = ProjectionMlp(projector_params, c.projector());
    predictor = ProjectionMlp(predictor_params, c.predictor());
    for (ParamSet<T>* ps : {&online, &projector_params, &predictor_params}) ps->allocate();
    init_params(online, seed);
    init_params(projector_params, seed ^ 0x62796f6c70726f6aull);  // "byolproj"
    init_params(predictor_params, seed ^ 0x62796f6c70726564ull);  // "byolpred"
    target = online;
    target_projector = projector_params;
  }

  int feature_dim() const { return config.encoder.out_dim(); }

  // What AdamW and gradient clipping see.
  std::vector<PrefixedParams<T>> trainable() {
    return {{"online_encoder.", &online}, {"online_projector.", &projector_params}, {"online_predictor.", &predictor_params}};
  }
  // What a checkpoint holds.
  std::vector<PrefixedParams<T>> parts() {
    auto p = trainable();
    p.push_back({"target_encoder.", &target});
    p.push_back({"target_projector.", &target_projector});
    return p;
  }
};

// ℓ(p, z) = 2 − 2 p̂·ẑ per row of p, z [M, P] (F.normalize's eps 1e-12), summed with weight
// `scale`; dp [M, P] += scale · ∂ℓ/∂p. Returns scale · Σ ℓ.
template <class T>
double byol_cosine_loss(const T* p, const T* z, int M, int P, double scale, T* dp) {
  double total = 0;
  for (int i = 0; i < M; ++i) {
    const T* pi = p + std::size_t(i) * P;
    const T* zi = z + std::size_t(i) * P;
    double pp = 0, zz = 0, pz = 0;
    for (int k = 0; k < P; ++k) pp += double(pi[k]) * pi[k], zz += double(zi[k]) * zi[k], pz += double(pi[k]) * zi[k];
    const double np = std::max(std::sqrt(pp), 1e-12), nz = std::max(std::sqrt(zz), 1e-12);
    const double cos = pz / (np * nz);
    total += scale * (2 - 2 * cos);
    if (!dp) continue;
    // ∂cos/∂p = (ẑ − cos p̂) / ‖p‖ (p̂ = p / ‖p‖ when ‖p‖ > eps; else ẑ / eps).
    T* di = dp + std::size_t(i) * P;
    const bool clamped = std::sqrt(pp) <= 1e-12;
    for (int k = 0; k < P; ++k) {
      const double g = clamped ? double(zi[k]) / nz / np : (double(zi[k]) / nz - cos * double(pi[k]) / np) / np;
      di[k] += T(-2 * scale * g);
    }
  }
  return total;
}

struct ByolStepStats : StepStats {
  double momentum = 0;  // the target's EMA momentum this step used

  void write(std::ostream& os) const {
    StepStats::write(os);
    os << " ema " << momentum;
  }
};

// Caller-owned buffers of one step.
template <class T>
struct ByolWorkspace {
  AlignedVector<T> images;                   // [2B, S, S, A]: view 1 of every window, then view 2
  AlignedVector<T> features, target_features;  // [2B, F]
  AlignedVector<T> z, p, target_z;           // [2B, P]
  AlignedVector<T> dp, dz, dfeatures;
  AlexNetCache<T> encoder_cache, target_cache;
  ProjectionMlpCache<T> projector_cache[2], predictor_cache[2], target_projector_cache[2];
  int B = 0;  // the batch of the forward pass held; 0: none
};

// The BYOL loss of 2B images [view 1 of B windows; view 2]; keeps in w what byol_backward needs.
template <class T>
double byol_forward(ByolModel<T>& model, const T* images, int B, ByolWorkspace<T>& w) {
  require<ShapeError>(B >= 2, "byol_forward: a batch of ", B, " windows, expected >= 2 (BatchNorm's statistics)");
  const int F = model.feature_dim(), P = model.config.projection;
  w.B = 0;
  T* f = detail::grow(w.features, std::size_t(2) * B * F);
  T* tf = detail::grow(w.target_features, std::size_t(2) * B * F);
  T* z = detail::grow(w.z, std::size_t(2) * B * P);
  T* p = detail::grow(w.p, std::size_t(2) * B * P);
  T* tz = detail::grow(w.target_z, std::size_t(2) * B * P);
  model.encoder.forward(model.online, images, 2 * B, f, w.encoder_cache);
  model.encoder.forward(model.target, images, 2 * B, tf, w.target_cache);
  for (int v = 0; v < 2; ++v) {  // each view its own BatchNorm batch, as the reference's two calls
    const std::size_t fo = std::size_t(v) * B * F, po = std::size_t(v) * B * P;
    model.projector.forward(model.projector_params, f + fo, B, z + po, w.projector_cache[v]);
    model.predictor.forward(model.predictor_params, z + po, B, p + po, w.predictor_cache[v]);
    model.projector.forward(model.target_projector, tf + fo, B, tz + po, w.target_projector_cache[v]);
  }
  T* dp = detail::grow(w.dp, std::size_t(2) * B * P);
  std::fill(dp, dp + std::size_t(2) * B * P, T(0));
  const std::size_t half = std::size_t(B) * P;
  double loss = byol_cosine_loss(p, tz + half, B, P, 1.0 / B, dp);
  loss += byol_cosine_loss(p + half, tz, B, P, 1.0 / B, dp + half);
  w.B = B;
  return loss;
}

// Adds ∂L/∂θ of the last byol_forward to the online network's gradients.
template <class T>
void byol_backward(ByolModel<T>& model, ByolWorkspace<T>& w) {
  require<ConfigError>(w.B > 0, "byol_backward: the workspace holds no forward pass, expected byol_forward first");
  const int B = w.B, F = model.feature_dim(), P = model.config.projection;
  T* dz = detail::grow(w.dz, std::size_t(2) * B * P);
  std::fill(dz, dz + std::size_t(2) * B * P, T(0));
  T* df = detail::grow(w.dfeatures, std::size_t(2) * B * F);
  std::fill(df, df + std::size_t(2) * B * F, T(0));
  for (int v = 0; v < 2; ++v) {
    const std::size_t fo = std::size_t(v) * B * F, po = std::size_t(v) * B * P;
    model.predictor.backward(model.predictor_params, w.dp.data() + po, w.z.data() + po, dz + po, w.predictor_cache[v]);
    model.projector.backward(model.projector_params, dz + po, w.features.data() + fo, df + fo, w.projector_cache[v]);
  }
  model.encoder.backward(model.online, df, w.encoder_cache);
  w.B = 0;
}

// The update after byol_backward: the NaN stop and clipping, AdamW, the target's EMA.
template <class T>
ByolStepStats byol_update(ByolModel<T>& model, AdamW<T>& opt, const TrainingSchedule& schedule, std::int64_t s,
                          double loss) {
  ByolStepStats st;
  clipped_adamw_step<T>(st, model.trainable(), opt, schedule, s, loss, model.config.clip_grad_norm, "BYOL");
  st.momentum = model.config.momentum;
  ema_update(model.target, model.online, st.momentum);
  ema_update(model.target_projector, model.projector_params, st.momentum);
  return st;
}

// The frame of a window BYOL draws: config.frame, or the middle one.
inline int byol_frame(const ByolConfig& c, int length) {
  const int t = c.frame < 0 ? length / 2 : c.frame;
  require<ConfigError>(t < length, "BYOL: frame ", t, " of windows of ", length, " frames");
  return t;
}

// Images [n, S, S, A] of frame `frame` of each window of wb, written straight into out when T is
// float; rng_of(b) is the stream that augments window b's image (nullptr: not augmented).
template <class T, class RngOf>
  requires std::is_invocable_r_v<Rng*, RngOf&, int>
void byol_images(TaxelImager& imager, const WindowBatch& wb, int frame, T* out, RngOf&& rng_of) {
  const std::size_t per = imager.image_values();
  std::vector<float> img(std::is_same_v<T, float> ? 0 : per);
  for (int b = 0; b < wb.batch; ++b) {
    const float* x = wb.x.data() + std::size_t(b) * wb.per_window() + std::size_t(frame) * std::size_t(wb.axes);
    T* dst = out + std::size_t(b) * per;
    if constexpr (std::is_same_v<T, float>) {
      imager.image(dst, x, std::size_t(wb.length) * std::size_t(wb.axes), 1, rng_of(b));
    } else {
      imager.image(img.data(), x, std::size_t(wb.length) * std::size_t(wb.axes), 1, rng_of(b));
      std::copy(img.begin(), img.end(), dst);
    }
  }
}
// The same with one stream for every image, drawn in order (nullptr: not augmented).
template <class T>
void byol_images(TaxelImager& imager, const WindowBatch& wb, int frame, T* out, Rng* rng) {
  byol_images(imager, wb, frame, out, [rng](int) { return rng; });
}

// BYOL pre-training as an Objective (train/objective.hpp), with the data order, schedule and
// AdamW of a JepaObjective of the same TrainConfig. canvas: where the skin's
// taxels sit in the image (TaxelCanvas::from_layout). Checkpoint metadata: {"objective": "byol",
// "train": cfg, "byol": config}.
template <class T>
class ByolObjective {
 public:
  using value_type = T;
  using stats_type = ByolStepStats;

  ByolObjective(ByolModel<T>& model, const WindowSource& source, TaxelCanvas canvas, TrainConfig config)
      : data((config.validate(), source), config.seed, config.batch), model_(model), cfg_(std::move(config)),
        imager_(std::move(canvas), model.config.encoder.in_channels, model.config.image),
        optimizer_(model.trainable(), cfg_.adamw), schedule_(cfg_.schedule.build()) {
    require<ShapeError>(source.axes() == model.config.encoder.in_channels, "ByolObjective: the windows have ",
                        source.axes(), " axes, the encoder takes ", model.config.encoder.in_channels, " channels");
    require<ShapeError>(imager_.canvas().taxels() == source.taxels(), "ByolObjective: the canvas places ",
                        imager_.canvas().taxels(), " taxels, the windows have ", source.taxels());
    frame_ = byol_frame(model.config, source.spec().length);
  }
  ByolObjective(const ByolObjective&) = delete;
  ByolObjective& operator=(const ByolObjective&) = delete;

  WindowBatches<T> data;

  ByolModel<T>& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  ByolWorkspace<T>& workspace() { return w_; }

  std::int64_t num_samples() const { return data.size(); }
  int batch_size() const { return cfg_.batch; }
  std::int64_t total_steps() const { return schedule_.total_steps(); }
  std::vector<std::int64_t> epoch_order(std::uint64_t epoch) const { return data.epoch_order(epoch); }
  void zero_grad() {
    for (const auto& part : model_.trainable()) part.params->zero_grad();
  }
  // Step s's views: view v of the global batch's sample g draws from its own stream (seed, s, v, g),
  // whichever rank holds it.
  double forward(const StepBatch& b) {
    data.source().gather(b.ids, windows_);
    const int B = b.size();
    const std::size_t per = imager_.image_values();
    T* images = detail::grow(w_.images, std::size_t(2) * B * per);
    for (int v = 0; v < 2; ++v) {
      Rng rng;
      byol_images(imager_, windows_, frame_, images + std::size_t(v) * B * per, [&](int i) {
        const std::uint64_t g = std::uint64_t(b.first + i), global = std::uint64_t(b.batch);
        rng = Rng(streams::masks(cfg_.seed) ^ 0x62796f6c76696577ull,  // "byolview"
                  (static_cast<std::uint64_t>(b.step) * 2 + std::uint64_t(v)) * global + g);
        return &rng;
      });
    }
    loss_ = byol_forward(model_, images, B, w_);
    return loss_;
  }
  void backward() { byol_backward(model_, w_); }
  // Data parallel as PyTorch's DistributedDataParallel runs BYOL: each rank's BatchNorm reads its
  // own shard (no SyncBatchNorm), the gradients and the loss are averaged over the global batch.
  void all_reduce(const DataParallel<T>& dp, int count, int B) {
    double stats[1] = {loss_};
    const auto parts = model_.trainable();
    all_reduce_mean<T>(parts, stats, dp, count, B);
    loss_ = stats[0];
  }
  ByolStepStats update(std::int64_t s) { return byol_update(model_, optimizer_, schedule_, s, loss_); }
  std::vector<PrefixedParams<T>> parts() { return model_.parts(); }
  AdamW<T>& optimizer() { return optimizer_; }
  nlohmann::json metadata() const {
    return {{"objective", "byol"}, {"train", cfg_.to_json()}, {"byol", model_.config.to_json()}};
  }

 private:
  ByolModel<T>& model_;
  TrainConfig cfg_;
  TaxelImager imager_;
  AdamW<T> optimizer_;
  TrainingSchedule schedule_;
  ByolWorkspace<T> w_;
  WindowBatch windows_;
  int frame_ = 0;
  double loss_ = 0;
};

template <class T>
using ByolTrainer = Trainer<ByolObjective<T>>;

// The frozen encoder's features of windows `ids` of a source, as tokens: [n, cells, C], one token
// per cell of AlexNet's pooled map (cells = pooled², row-major), its C = widths[4] channels. The
// images are un-augmented. params: the online or the target encoder.
inline AlignedVector<float> byol_embed(const ByolModel<float>& model, const ParamSet<float>& params,
                                       const TaxelCanvas& canvas, const WindowSource& src,
                                       std::span<const std::int64_t> ids, int chunk = 64) {
  const ByolConfig& c = model.config;
  TaxelImager imager(canvas, c.encoder.in_channels, c.image);
  const int frame = byol_frame(c, src.spec().length), cells = c.encoder.pooled * c.encoder.pooled;
  const int C = c.encoder.widths[4], F = c.encoder.out_dim();
  AlignedVector<float> out(ids.size() * std::size_t(F));
  AlignedVector<float> images, feats;
  AlexNetCache<float> cache;
  WindowBatch wb;
  for (std::size_t i0 = 0; i0 < ids.size(); i0 += std::size_t(chunk)) {
    const std::size_t n = std::min<std::size_t>(std::size_t(chunk), ids.size() - i0);
    src.gather(ids.subspan(i0, n), wb);
    float* img = detail::grow(images, n * imager.image_values());
    byol_images(imager, wb, frame, img, nullptr);
    float* f = detail::grow(feats, n * std::size_t(F));
    model.encoder.forward(params, img, static_cast<int>(n), f, cache);
    for (std::size_t b = 0; b < n; ++b)  // (c, y, x) → tokens (y, x) of C channels
      for (int ch = 0; ch < C; ++ch)
        for (int q = 0; q < cells; ++q)
          out[(i0 + b) * std::size_t(F) + std::size_t(q) * C + std::size_t(ch)] = f[b * std::size_t(F) + std::size_t(ch) * cells + std::size_t(q)];
  }
  return out;
}

}  // namespace tjepa
