#pragma once
// Where a downstream head reads its token embeddings: a Features object serves sample ids
// s ∈ [0, size()) as x [B, L, d] (the head trainers are templates over it).
//   FrozenFeatures   precomputed embeddings [S, L, d] of a frozen encoder (embed_windows): only
//                    the head trains
//   EncoderFeatures  a tokenizer + encoder run on the windows at every step and trained with the
//                    head (end to end)
//   RowFeatures      rows of another Features object (a task's samples among a table's rows)
// Interface: tokens(), dim(), size(), trainable() (the ParamSet to train with the head, or
// nullptr), forward(ids, train) → x [B, L, d], backward(dx [B, L, d]) after a training forward.
#include <algorithm>
#include <cmath>
#include <string>
#include <cstdint>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/model/encoder.hpp"
#include "tjepa/model/tokenizer.hpp"
#include "tjepa/train/loss.hpp"

namespace tjepa {

// Precomputed embeddings of a frozen encoder: [S, L, d].
template <class T>
class FrozenFeatures {
 public:
  FrozenFeatures(AlignedVector<T> embeddings, int tokens, int dim)
      : x_(std::move(embeddings)), L_(tokens), d_(dim) {
    require<ShapeError>(tokens > 0 && dim > 0 && x_.size() % (static_cast<std::size_t>(tokens) * dim) == 0,
                        "FrozenFeatures: ", x_.size(), " values, expected a multiple of tokens*dim = ", tokens, "*",
                        dim);
  }
  int tokens() const { return L_; }
  int dim() const { return d_; }
  int size() const { return static_cast<int>(x_.size() / (static_cast<std::size_t>(L_) * d_)); }
  // All embeddings, [size, tokens, dim].
  std::span<const T> embeddings() const { return x_; }
  ParamSet<T>* trainable() { return nullptr; }

  // x [B, L, d] of samples ids.
  const T* forward(std::span<const std::int64_t> ids, bool /*train*/) {
    const std::size_t per = static_cast<std::size_t>(L_) * d_;
    T* out = detail::grow(batch_, ids.size() * per);
    for (std::size_t b = 0; b < ids.size(); ++b)
      std::copy_n(x_.data() + static_cast<std::size_t>(ids[b]) * per, per, out + b * per);
    return out;
  }
  void backward(const T* /*dx*/) {}

 private:
  AlignedVector<T> x_, batch_;
  int L_, d_;
};

// A tokenizer + encoder over the windows of a source, trained with the probe (end to end).
// Sample s is window windows[s] of the source. Windows are float, so T is float.
template <class T>
class EncoderFeatures {
  static_assert(std::is_same_v<T, float>, "EncoderFeatures: windows are float");

 public:
  EncoderFeatures(ParamSet<T>& params, const Tokenizer& tokenizer, const Encoder& encoder, const WindowSource& src,
                  std::vector<std::int64_t> windows, double drop_path = 0.0)
      : ps_(params), tok_(tokenizer), enc_(encoder), src_(src), windows_(std::move(windows)), drop_path_(drop_path) {
    require<ShapeError>(tokenizer.num_tokens == encoder.num_tokens() &&
                            static_cast<std::size_t>(tokenizer.width) == static_cast<std::size_t>(src.length()) * src.axes(),
                        "EncoderFeatures: tokenizer of ", tokenizer.num_tokens, " tokens × ", tokenizer.width,
                        " values, encoder of ", encoder.num_tokens(), " tokens, windows of ", src.taxels(), " taxels × ",
                        src.length() * src.axes(), " values");
  }
  int tokens() const { return enc_.num_tokens(); }
  int dim() const { return enc_.dim(); }
  int size() const { return static_cast<int>(windows_.size()); }
  ParamSet<T>* trainable() { return &ps_; }

  const T* forward(std::span<const std::int64_t> ids, bool train) {
    ids_.clear();
    for (std::int64_t s : ids) ids_.push_back(windows_.at(static_cast<std::size_t>(s)));
    src_.gather(ids_, batch_);
    const int B = static_cast<int>(ids.size()), N = tokens(), d = dim();
    const std::size_t M = static_cast<std::size_t>(B) * N * d;
    windows_to_tokens(batch_, rows_);
    const T* x = rows_.data();
    T* tokens_buf = detail::grow(tokens_, M);
    T* out = detail::grow(out_, M);
    if (train) {
      tok_.forward(ps_, x, B, tokens_buf, tok_cache_, ws_);
      enc_.forward(ps_, {tokens_buf, B}, out, enc_cache_, ws_,
                   EncoderOptions{.drop_path = DropPath{drop_path_, noise_()}, .register_rows = false});
    } else {
      tok_.forward(ps_, x, B, tokens_buf, ws_);
      enc_.forward(ps_, {tokens_buf, B}, out, ws_, EncoderOptions{.register_rows = false});
    }
    return out;
  }
  // dx [B, L, d]: the probe's gradient at the embeddings of the last training forward.
  void backward(const T* dx) {
    const std::size_t M = static_cast<std::size_t>(enc_cache_.B) * tokens() * dim();
    T* dtok = detail::grow(dtokens_, M);
    std::fill(dtok, dtok + M, T(0));
    enc_.backward(ps_, dx, dtok, enc_cache_, ws_);
    tok_.backward(ps_, dtok, tok_cache_, ws_);
  }

 private:
  ParamSet<T>& ps_;
  const Tokenizer& tok_;
  const Encoder& enc_;
  const WindowSource& src_;
  std::vector<std::int64_t> windows_, ids_;
  double drop_path_;
  Rng noise_{0x656e64326564ull};  // "end2end": drop-path seeds
  WindowBatch batch_;
  Workspace<T> ws_;
  TokenizerCache<T> tok_cache_;
  EncoderCache<T> enc_cache_;
  AlignedVector<T> rows_, tokens_, out_, dtokens_;
};

// Sample s of this view is row rows[s] of `base` (which must outlive it): one feature table
// serves several tasks that each use some of its rows.
template <class Base>
class RowFeatures {
 public:
  using value_type = std::remove_cvref_t<decltype(*std::declval<Base&>().forward(std::span<const std::int64_t>{}, false))>;

  RowFeatures(Base& base, std::span<const std::int64_t> rows) : base_(base), rows_(rows.begin(), rows.end()) {
    for (std::int64_t r : rows_)
      require<ShapeError>(r >= 0 && r < base.size(), "RowFeatures: row ", r, ", the features hold ", base.size());
  }
  int tokens() const { return base_.tokens(); }
  int dim() const { return base_.dim(); }
  int size() const { return static_cast<int>(rows_.size()); }
  auto* trainable() { return base_.trainable(); }
  const value_type* forward(std::span<const std::int64_t> ids, bool train) {
    ids_.clear();
    for (std::int64_t s : ids) ids_.push_back(rows_.at(static_cast<std::size_t>(s)));
    return base_.forward(ids_, train);
  }
  void backward(const value_type* dx) { base_.backward(dx); }

 private:
  Base& base_;
  std::vector<std::int64_t> rows_, ids_;
};

namespace detail {
// Statistics fitted on `train` and applied to it and to `others`, in rows of `unit` values
// (unit_name says what a row is): returns train's row count.
template <class T>
std::size_t check_fit_and_apply(const char* who, std::span<T> train, std::span<const std::span<T>> others,
                                std::size_t unit, const std::string& unit_name) {
  require<ShapeError>(!train.empty() && train.size() % unit == 0, who, ": ", train.size(),
                      " training values, expected a positive multiple of ", unit_name);
  for (const auto& o : others)
    require<ShapeError>(o.size() % unit == 0, who, ": ", o.size(), " values, expected a multiple of ", unit_name);
  return train.size() / unit;
}
}  // namespace detail

// Each token's resting embedding, removed from frozen features before a probe: with μ_n the mean of
// token n's embedding over the training windows and μ̄ the mean of μ_n over tokens,
//   x[s, n, :] ← x[s, n, :] − μ_n + μ̄          for every window s of `train` and of each `other`
// (statistics from `train` only). What every window shows at a token (its position, the "no
// contact" embedding of an idle taxel) becomes one vector shared by all tokens, which the probe's
// softmax and its pooled value ignore; what the windows differ in is kept at its own scale. Without
// it, the attentive probe must learn from a few hundred labelled windows to look past per-token
// offsets: on the simulated Allegro hand a random encoder whose position rows have RMS 1 (graph
// positions) gave force RMSE 1.47 N against 0.97 N with the reference's RMS 0.02 rows, and a
// pre-trained encoder whose rows had grown stayed at the training mean.
// Returns the shift [tokens·dim] it added (what a saved head adds to new windows' embeddings).
template <class T>
std::vector<T> center_token_embeddings(std::span<T> train, std::span<const std::span<T>> others, int tokens, int dim) {
  require<ShapeError>(tokens > 0 && dim > 0, "center_token_embeddings: tokens = ", tokens, ", dim = ", dim,
                      ", expected > 0");
  const std::size_t per = static_cast<std::size_t>(tokens) * dim;
  const std::size_t S = detail::check_fit_and_apply("center_token_embeddings", train, others, per,
                                                    "tokens*dim = " + std::to_string(tokens) + "*" + std::to_string(dim));
  std::vector<double> mean(per, 0.0), shared(static_cast<std::size_t>(dim), 0.0);
  for (std::size_t s = 0; s < S; ++s)
    for (std::size_t i = 0; i < per; ++i) mean[i] += static_cast<double>(train[s * per + i]);
  for (std::size_t i = 0; i < per; ++i) {
    mean[i] /= static_cast<double>(S);
    shared[i % static_cast<std::size_t>(dim)] += mean[i] / tokens;
  }
  std::vector<T> shift(per);  // μ̄ − μ_n
  for (std::size_t i = 0; i < per; ++i) shift[i] = static_cast<T>(shared[i % static_cast<std::size_t>(dim)] - mean[i]);
  auto apply = [&](std::span<T> x) {
    for (std::size_t s = 0; s < x.size() / per; ++s)
      for (std::size_t i = 0; i < per; ++i) x[s * per + i] += shift[i];
  };
  for (const auto& o : others) apply(o);
  apply(train);
  return shift;
}

// Frozen features standardized per channel before a head (in the spirit of MAE's linear probe, a
// BatchNorm without affine parameters in front of the head, here applied to every token before the
// pooling, with fixed training statistics): with μ_c and σ_c the mean and standard deviation of
// channel c over every token of every training window,
//   x[s, n, c] ← (x[s, n, c] − μ_c) / sqrt(σ_c² + eps)     for every window of `train` and of each `other`
// (statistics from `train` only). An encoder whose tokens share one large vector (a random
// encoder's output LayerNorm, a pre-trained encoder's common offset) gives keys, values and
// LayerNorm inputs that differ across tokens and windows by a small fraction of their norm; the
// probe then spends its steps on that scale. Unlike center_token_embeddings, what differs between
// tokens (their positions) is kept. eps is absolute: a channel nearly constant in training is
// scaled by up to 1/sqrt(eps). Returns the statistics (μ_c, σ_c) [dim] each.
template <class T>
std::pair<std::vector<double>, std::vector<double>> standardize_channels(std::span<T> train,
                                                                         std::span<const std::span<T>> others, int dim,
                                                                         double eps = 1e-6) {
  require<ShapeError>(dim > 0, "standardize_channels: dim = ", dim, ", expected > 0");
  const auto D = static_cast<std::size_t>(dim);
  const std::size_t R = detail::check_fit_and_apply("standardize_channels", train, others, D, "dim = " + std::to_string(dim));
  std::vector<double> mean(D), sd(D), scale(D);
  detail::column_moments(train.data(), R, D, 0, D, mean.data(), sd.data());
  for (std::size_t c = 0; c < D; ++c) {
    scale[c] = 1.0 / std::sqrt(sd[c] + eps);
    sd[c] = std::sqrt(sd[c]);
    require<NumericError>(std::isfinite(mean[c]) && std::isfinite(sd[c]), "standardize_channels: channel ", c,
                          " has mean ", mean[c], " and sd ", sd[c], ", expected finite");
  }
  for (const auto& o : others) detail::scale_columns(o.data(), o.size() / D, D, 0, D, mean.data(), scale.data());
  detail::scale_columns(train.data(), train.size() / D, D, 0, D, mean.data(), scale.data());
  return {std::move(mean), std::move(sd)};
}

}  // namespace tjepa
