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
    tok_.forward(ps_, x, B, tokens_buf, train ? &tok_cache_ : nullptr, ws_);
    EncoderOptions opt;
    if (train) opt.drop_path = DropPath{drop_path_, noise_()};
    enc_.forward(ps_, tokens_buf, B, nullptr, N, out, train ? &enc_cache_ : nullptr, ws_, opt);
    return out;
  }
  // dx [B, L, d]: the probe's gradient at the embeddings of the last training forward.
  void backward(const T* dx) {
    const std::size_t M = static_cast<std::size_t>(enc_cache_.B) * tokens() * dim();
    T* dtok = detail::grow(dtokens_, M);
    std::fill(dtok, dtok + M, T(0));
    enc_.backward(ps_, dx, dtok, enc_cache_, ws_);
    tok_.backward(ps_, dtok, static_cast<T*>(nullptr), tok_cache_, ws_);
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

}  // namespace tjepa
