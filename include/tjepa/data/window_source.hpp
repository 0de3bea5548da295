#pragma once
// WindowSource: the windows of one or more recordings, served as batches [B, N, τ, m] with their
// labels, preprocessed as they are gathered. This is where data enter training, so a NaN or Inf in a
// gathered batch throws DataError naming the recording, frame, taxel and axis.
//
//   WindowSource src(recording, WindowSpec{10}, frame_labels, preprocessor);
//   WindowBatch batch;
//   auto order = src.epoch_order(seed, epoch);              // a shuffled permutation of the windows
//   for (std::int64_t b = 0; b < src.batches_per_epoch(256); ++b)
//     src.gather(std::span(order).subspan(b * 256, 256), batch);  // batch.x is [256, N, τ, m]
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/hash.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/data/labels.hpp"
#include "tjepa/data/preprocessor.hpp"
#include "tjepa/data/recording.hpp"
#include "tjepa/data/window.hpp"

namespace tjepa {

struct WindowBatch {
  int batch = 0, taxels = 0, length = 0, axes = 0;
  AlignedVector<float> x;               // [B, N, τ, m]
  std::vector<std::int64_t> window;     // [B] window ids in the source
  // Labels, empty when the source has none.
  std::vector<float> force;             // [B, 3] N, pad frame (shear u, shear v, normal)
  std::vector<float> location;          // [B, 3] mm
  std::vector<int> indenter;            // [B] class, -1: no contact
  std::vector<int> pad;                 // [B] -1: no contact
  std::vector<int> contact_frames;      // [B]
  bool has_labels() const { return !indenter.empty(); }
  std::size_t per_window() const { return static_cast<std::size_t>(taxels) * length * axes; }
};

class WindowSource {
 public:
  // labels: per recording, one FrameLabel per frame, or empty (no labels at all).
  WindowSource(std::vector<Recording> recordings, WindowSpec spec, std::vector<std::vector<FrameLabel>> labels = {},
               std::optional<Preprocessor> pre = std::nullopt)
      : recs_(std::move(recordings)), labels_(std::move(labels)), spec_(spec), pre_(std::move(pre)) {
    spec_.validate();
    require<ConfigError>(!recs_.empty(), "WindowSource: no recordings");
    require<ShapeError>(labels_.empty() || labels_.size() == recs_.size(), "WindowSource: labels for ",
                        labels_.size(), " recordings, expected ", recs_.size(), " (or none)");
    for (std::size_t r = 0; r < recs_.size(); ++r) {
      const Recording& rec = recs_[r];
      require<ShapeError>(rec.taxels() == recs_[0].taxels() && rec.axes() == recs_[0].axes(), "WindowSource: ",
                          name(r), " has ", rec.taxels(), " taxels and ", rec.axes(), " axes, the first has ",
                          recs_[0].taxels(), " and ", recs_[0].axes());
      require<ShapeError>(labels_.empty() || labels_[r].size() == static_cast<std::size_t>(rec.frames()),
                          "WindowSource: ", name(r), " has ", rec.frames(), " frames but ", labels_.empty() ? 0 : labels_[r].size(),
                          " frame labels");
      // Frames holding a NaN/Inf reading, when such windows are left out.
      std::vector<int> bad_before(static_cast<std::size_t>(rec.frames()) + 1, 0);  // prefix counts
      if (spec_.skip_non_finite) {
        const std::size_t per = static_cast<std::size_t>(rec.taxels()) * rec.axes();
        for (int t = 0; t < rec.frames(); ++t) {
          const bool bad = find_non_finite(std::span<const float>(rec.frame(t), per)) != per;
          bad_before[static_cast<std::size_t>(t) + 1] = bad_before[static_cast<std::size_t>(t)] + bad;
        }
      }
      for (std::int64_t t : window_starts(rec.frames(), spec_)) {
        if (bad_before[static_cast<std::size_t>(t + spec_.length)] != bad_before[static_cast<std::size_t>(t)]) {
          ++dropped_;
          continue;
        }
        windows_.push_back({static_cast<int>(r), static_cast<int>(t)});
      }
    }
    require<DataError>(!windows_.empty(), "WindowSource: no window of ", spec_.length,
                       " frames fits in the recordings (longest has ", longest(), " frames",
                       dropped_ > 0 ? ", " + std::to_string(dropped_) + " windows left out for NaN/Inf readings" : "",
                       ")");
    if (pre_) require<ConfigError>(pre_->ready(), "WindowSource: the preprocessor is not fitted");
  }
  WindowSource(Recording recording, WindowSpec spec, std::vector<FrameLabel> labels = {},
               std::optional<Preprocessor> pre = std::nullopt)
      : WindowSource(one(std::move(recording)), spec, labels.empty() ? std::vector<std::vector<FrameLabel>>{}
                                                                     : std::vector<std::vector<FrameLabel>>{std::move(labels)},
                     std::move(pre)) {}

  std::int64_t size() const { return static_cast<std::int64_t>(windows_.size()); }
  // Windows left out because they hold a NaN/Inf reading (WindowSpec::skip_non_finite).
  std::int64_t dropped() const { return dropped_; }
  int taxels() const { return recs_[0].taxels(); }
  int axes() const { return recs_[0].axes(); }
  int length() const { return spec_.length; }
  const WindowSpec& spec() const { return spec_; }
  bool has_labels() const { return !labels_.empty(); }
  const std::vector<Recording>& recordings() const { return recs_; }
  const std::optional<Preprocessor>& preprocessor() const { return pre_; }
  // Recording index and first frame of window i.
  int recording_of(std::int64_t i) const { return windows_.at(static_cast<std::size_t>(i)).rec; }
  int start_of(std::int64_t i) const { return windows_.at(static_cast<std::size_t>(i)).start; }

  WindowLabel label(std::int64_t i) const {
    require<ConfigError>(has_labels(), "WindowSource::label: the source has no labels");
    const Window& w = windows_.at(static_cast<std::size_t>(i));
    return window_label(std::span<const FrameLabel>(labels_[w.rec]).subspan(w.start, spec_.length));
  }

  // Windows with at least min_frames frames in contact (for probes that need a contact).
  std::vector<std::int64_t> windows_with_contact(int min_frames) const {
    std::vector<std::int64_t> out;
    for (std::int64_t i = 0; i < size(); ++i)
      if (label(i).contact_frames >= min_frames) out.push_back(i);
    return out;
  }

  // All window ids shuffled by Rng(seed, epoch): the same seed and epoch give the same order.
  std::vector<std::int64_t> epoch_order(std::uint64_t seed, std::uint64_t epoch) const {
    std::vector<std::int64_t> order(windows_.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<std::int64_t>(i);
    Rng rng(seed, epoch);
    rng.shuffle(std::span<std::int64_t>(order));
    return order;
  }
  // Full batches of size B in one epoch (the last partial batch is dropped).
  std::int64_t batches_per_epoch(int batch) const {
    require<ConfigError>(batch > 0, "WindowSource::batches_per_epoch: batch = ", batch, ", expected > 0");
    return size() / batch;
  }

  // Fills out with windows `ids`: out.x [B, N, τ, m], preprocessed, plus labels if any.
  void gather(std::span<const std::int64_t> ids, WindowBatch& out) const {
    const int B = static_cast<int>(ids.size());
    require<ConfigError>(B > 0, "WindowSource::gather: empty list of windows");
    for (std::size_t b = 0; b < ids.size(); ++b)
      require<ConfigError>(ids[b] >= 0 && ids[b] < size(), "WindowSource::gather: window id ", ids[b], " at position ",
                           b, ", expected in [0, ", size(), ")");
    out.batch = B;
    out.taxels = taxels();
    out.length = spec_.length;
    out.axes = axes();
    const std::size_t per = out.per_window();
    out.x.resize(per * B);
    out.window.assign(ids.begin(), ids.end());
    for (int b = 0; b < B; ++b) {
      const Window& w = windows_[static_cast<std::size_t>(ids[b])];
      copy_window(recs_[w.rec], w.start, spec_.length, out.x.data() + b * per);
    }
    if (pre_) pre_->apply(out.x.data(), static_cast<std::size_t>(B), taxels(), spec_.length, axes());
    const std::size_t bad = find_non_finite(std::span<const float>(out.x.data(), out.x.size()));
    if (bad != out.x.size()) {
      const int b = static_cast<int>(bad / per);
      const std::size_t k = bad % per;
      const int n = static_cast<int>(k / (static_cast<std::size_t>(spec_.length) * axes()));
      const int j = static_cast<int>((k / axes()) % spec_.length);
      const Window& w = windows_[static_cast<std::size_t>(ids[b])];
      fail<DataError>("WindowSource: ", name(w.rec), " gives ", out.x[bad], " at frame ", w.start + j, ", taxel ", n,
                      ", axis ", k % axes(), " (window ", ids[b], ")",
                      pre_ ? " after preprocessing" : "", "; expected finite data (enable nan_as_dropout in the "
                      "preprocessor to treat NaN as a drop-out)");
    }
    if (!has_labels()) {
      out.force.clear();
      out.location.clear();
      out.indenter.clear();
      out.pad.clear();
      out.contact_frames.clear();
      return;
    }
    out.force.resize(3 * static_cast<std::size_t>(B));
    out.location.resize(3 * static_cast<std::size_t>(B));
    out.indenter.resize(B);
    out.pad.resize(B);
    out.contact_frames.resize(B);
    for (int b = 0; b < B; ++b) {
      const WindowLabel l = label(ids[b]);
      for (int k = 0; k < 3; ++k) {
        out.force[3 * b + k] = l.force[k];
        out.location[3 * b + k] = l.location[k];
      }
      out.indenter[b] = l.indenter;
      out.pad[b] = l.pad;
      out.contact_frames[b] = l.contact_frames;
    }
  }

 private:
  struct Window {
    int rec;
    int start;
  };
  static std::vector<Recording> one(Recording r) {
    std::vector<Recording> v;
    v.push_back(std::move(r));
    return v;
  }
  std::string name(std::size_t r) const {
    return recs_[r].source().empty() ? "recording " + std::to_string(r) : recs_[r].source();
  }
  int longest() const {
    int m = 0;
    for (const auto& r : recs_) m = std::max(m, r.frames());
    return m;
  }

  std::vector<Recording> recs_;
  std::vector<std::vector<FrameLabel>> labels_;
  WindowSpec spec_;
  std::optional<Preprocessor> pre_;
  std::vector<Window> windows_;
  std::int64_t dropped_ = 0;
};

// Window batch [B, N, τ, m] → per-taxel tokenizer input [B, N, m·τ], each taxel's window
// axis-major (the reference's Conv1d patch embedding flattens its weight [d, m, τ] that way).
// Everything that feeds a per-taxel tokenizer from windows goes through here (training, embedding,
// probes), so a checkpoint means the same thing in every path and in PyTorch.
template <class T>
void windows_to_tokens(const WindowBatch& batch, AlignedVector<T>& out) {
  const int tau = batch.length, m = batch.axes;
  const std::size_t per = static_cast<std::size_t>(tau) * m;
  out.resize(static_cast<std::size_t>(batch.batch) * batch.taxels * per);
  for (std::size_t row = 0; row < static_cast<std::size_t>(batch.batch) * batch.taxels; ++row) {
    const float* src = batch.x.data() + row * per;
    T* dst = out.data() + row * per;
    for (int f = 0; f < tau; ++f)
      for (int a = 0; a < m; ++a) dst[static_cast<std::size_t>(a) * tau + f] = static_cast<T>(src[f * m + a]);
  }
}

// What a window source's windows are made of: every recording's values and the preprocessor's
// statistics (FNV-1a, core/hash.hpp). Equal sources give equal fingerprints; the pre-training
// cache (eval/pretrain_cache.hpp) keys its entries by it.
inline std::uint64_t fingerprint(const WindowSource& source) {
  std::uint64_t h = fingerprint_seed;
  for (const Recording& r : source.recordings()) h = fingerprint(r.values(), h);
  if (const auto& p = source.preprocessor())
    for (const std::vector<float>* v : {&p->baseline(), &p->mean(), &p->std()})
      h = fingerprint(std::span<const float>(*v), h);
  return h;
}

}  // namespace tjepa
