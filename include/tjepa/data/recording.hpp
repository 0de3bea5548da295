#pragma once
// Recording: a skin's signal over time, X ∈ R^{T×N×m} (frames, taxels, axes), row-major with the
// axes contiguous: value (t, n, a) sits at (t·N + n)·m + a. This is the layout of a NumPy array of
// shape [T, N, m] and of a text file whose rows are frames.
//
// The values are shared, copy-on-write float storage: copying a Recording or taking a frame range
// is free, and a recording read from a .npy file can stay memory-mapped (read-only) for its whole
// life. mutable_data() makes a private copy first when the values are mapped or shared.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/data/detail/float_storage.hpp"

namespace tjepa {

class Recording {
 public:
  Recording() = default;

  // frames × taxels × axes owned values, all `value`.
  Recording(int frames, int taxels, int axes, float value = 0.0f)
      : frames_(frames), taxels_(taxels), axes_(axes) {
    check_dims("Recording", frames, taxels, axes);
    storage_ = detail::FloatStorage(size(), value);
  }

  // Takes ownership of values laid out [frames, taxels, axes].
  Recording(int frames, int taxels, int axes, AlignedVector<float>&& values, std::string source = {})
      : frames_(frames), taxels_(taxels), axes_(axes), source_(std::move(source)) {
    check_dims("Recording", frames, taxels, axes);
    require<ShapeError>(values.size() == size(), "Recording: ", values.size(),
                        " values, expected frames*taxels*axes = ", frames, "*", taxels, "*", axes, " = ",
                        size());
    storage_ = detail::FloatStorage(std::move(values));
  }

  // Wraps existing storage (used by the readers for memory-mapped files).
  Recording(int frames, int taxels, int axes, detail::FloatStorage storage, std::string source)
      : frames_(frames), taxels_(taxels), axes_(axes), storage_(std::move(storage)), source_(std::move(source)) {
    check_dims("Recording", frames, taxels, axes);
    require<ShapeError>(storage_.size() == size(), "Recording: storage holds ", storage_.size(),
                        " values, expected ", size());
  }

  int frames() const { return frames_; }
  int taxels() const { return taxels_; }
  int axes() const { return axes_; }
  std::size_t size() const {
    return static_cast<std::size_t>(frames_) * static_cast<std::size_t>(taxels_) * static_cast<std::size_t>(axes_);
  }
  bool empty() const { return size() == 0; }
  // Where the values came from (a file name, "simulated", ...), for error messages.
  const std::string& source() const { return source_; }
  void set_source(std::string s) { source_ = std::move(s); }

  const float* data() const { return storage_.data(); }
  std::span<const float> values() const { return storage_.values(); }
  // Frame t: [taxels, axes].
  const float* frame(int t) const { return data() + static_cast<std::size_t>(t) * taxels_ * axes_; }
  float operator()(int t, int n, int a) const {
    return data()[(static_cast<std::size_t>(t) * taxels_ + n) * axes_ + a];
  }

  // Writable values (copies first if mapped or shared).
  float* mutable_data() { return storage_.mutable_data(); }
  float& at(int t, int n, int a) {
    return mutable_data()[(static_cast<std::size_t>(t) * taxels_ + n) * axes_ + a];
  }
  // True while the values are a read-only mapping or shared with another Recording.
  bool shares_values() const { return storage_.shared(); }

  // Frames [begin, end) as a Recording sharing these values (no copy): train/validation splits.
  Recording frames_range(int begin, int end) const {
    require<ConfigError>(0 <= begin && begin <= end && end <= frames_, "Recording::frames_range: [", begin,
                         ", ", end, ") is not inside [0, ", frames_, ")");
    const std::size_t per = static_cast<std::size_t>(taxels_) * axes_;
    return Recording(end - begin, taxels_, axes_, storage_.slice(begin * per, (end - begin) * per), source_);
  }

 private:
  static void check_dims(const char* who, int frames, int taxels, int axes) {
    require<ShapeError>(frames >= 0 && taxels > 0 && axes > 0, who, ": shape [", frames, ", ", taxels, ", ",
                        axes, "], expected frames >= 0, taxels > 0, axes > 0");
  }

  int frames_ = 0;
  int taxels_ = 0;
  int axes_ = 0;
  detail::FloatStorage storage_;
  std::string source_;
};

// The recording with its taxels taken from the given slots: taxel i of the result is taxel
// slots[i] of rec (a layout's column order, or a subset). Frames and axes are kept.
inline Recording select_taxels(const Recording& rec, std::span<const int> slots) {
  require<ShapeError>(!slots.empty(), "select_taxels: no taxel slots given");
  for (std::size_t i = 0; i < slots.size(); ++i)
    require<ShapeError>(slots[i] >= 0 && slots[i] < rec.taxels(), "select_taxels: ",
                        rec.source().empty() ? std::string("recording") : rec.source(), " has ", rec.taxels(),
                        " taxels, but taxel ", i, " reads column ", slots[i]);
  const int T = rec.frames(), N = static_cast<int>(slots.size()), m = rec.axes();
  AlignedVector<float> v(static_cast<std::size_t>(T) * N * m);
  for (int t = 0; t < T; ++t)
    for (int i = 0; i < N; ++i)
      std::memcpy(v.data() + (static_cast<std::size_t>(t) * N + i) * m, rec.frame(t) + static_cast<std::size_t>(slots[i]) * m,
                  sizeof(float) * static_cast<std::size_t>(m));
  return Recording(T, N, m, std::move(v), rec.source());
}

// Index of the first NaN/Inf in values, or size() when all are finite. Blocks are screened with an
// integer test on the exponent bits (vectorizes), then searched only if one holds a bad value.
inline std::size_t find_non_finite(std::span<const float> values) {
  constexpr std::size_t block = 1024;
  for (std::size_t b0 = 0; b0 < values.size(); b0 += block) {
    const std::size_t b1 = std::min(values.size(), b0 + block);
    std::uint32_t bad = 0;
    for (std::size_t i = b0; i < b1; ++i) {
      std::uint32_t bits;
      std::memcpy(&bits, &values[i], sizeof bits);
      bad |= static_cast<std::uint32_t>((bits & 0x7f800000u) == 0x7f800000u);
    }
    if (bad)
      for (std::size_t i = b0; i < b1; ++i)
        if (!std::isfinite(values[i])) return i;
  }
  return values.size();
}

// What to do with NaN/Inf readings: stop (an error naming where), hold the taxel-axis's last finite
// reading (0 before the first), interpolate linearly in time between the finite readings around
// the gap (the nearest one at either end), write 0, or drop: keep them in the recording and leave
// out every window that holds one (WindowSpec::skip_non_finite; statistics skip them).
enum class NonFinite { error, hold, interpolate, zero, drop };

inline NonFinite parse_non_finite(const std::string& s) {
  if (s == "hold") return NonFinite::hold;
  if (s == "interpolate") return NonFinite::interpolate;
  if (s == "zero") return NonFinite::zero;
  if (s == "drop") return NonFinite::drop;
  require<ConfigError>(s == "error", "non-finite policy '", s, "', expected error, hold, interpolate, zero or drop");
  return NonFinite::error;
}

// Applies the policy; returns how many readings it replaced (error: throws at the first, with
// require_finite's message; drop: replaces nothing and returns 0).
inline std::size_t replace_non_finite(Recording& rec, NonFinite policy, const std::string& where);

// Throws DataError naming the frame, taxel and axis of the first NaN/Inf: `where` says which step
// wanted finite data ("WindowSource", "read_npy", ...).
inline void require_finite(const Recording& rec, const std::string& where) {
  const std::size_t i = find_non_finite(rec.values());
  if (i == rec.size()) return;
  const std::size_t per = static_cast<std::size_t>(rec.taxels()) * rec.axes();
  const float v = rec.values()[i];
  fail<DataError>(where, ": ", rec.source().empty() ? std::string("recording") : rec.source(), " holds ", v,
                  " at frame ", i / per, ", taxel ", (i % per) / rec.axes(), ", axis ", i % rec.axes(),
                  " (value index ", i, "), expected finite values");
}

inline std::size_t replace_non_finite(Recording& rec, NonFinite policy, const std::string& where) {
  if (policy == NonFinite::drop || find_non_finite(rec.values()) == rec.size()) return 0;
  if (policy == NonFinite::error) require_finite(rec, where);
  const std::size_t per = static_cast<std::size_t>(rec.taxels()) * rec.axes();
  float* v = rec.mutable_data();
  std::size_t replaced = 0;
  if (policy == NonFinite::interpolate) {
    const int T = rec.frames();
    for (std::size_t k = 0; k < per; ++k) {
      auto at = [&](int t) -> float& { return v[static_cast<std::size_t>(t) * per + k]; };
      int prev = -1;
      for (int t = 0; t <= T; ++t) {
        if (t < T && !std::isfinite(at(t))) continue;
        // frames prev+1 .. t-1 are a gap between finite readings prev and t (either may be missing)
        for (int g = prev + 1; g < t; ++g, ++replaced) {
          if (prev < 0 && t == T)
            fail<DataError>(where, ": ", rec.source().empty() ? std::string("recording") : rec.source(), " taxel ",
                            k / rec.axes(), ", axis ", k % rec.axes(), " has no finite reading to interpolate from");
          at(g) = prev < 0 ? at(t) : t == T ? at(prev)
                                            : at(prev) + (at(t) - at(prev)) * static_cast<float>(g - prev) /
                                                             static_cast<float>(t - prev);
        }
        prev = t;
      }
    }
    return replaced;
  }
  std::vector<float> last(per, 0.0f);
  for (int t = 0; t < rec.frames(); ++t)
    for (std::size_t k = 0; k < per; ++k) {
      float& x = v[static_cast<std::size_t>(t) * per + k];
      if (std::isfinite(x)) {
        last[k] = x;
      } else {
        x = policy == NonFinite::hold ? last[k] : 0.0f;
        ++replaced;
      }
    }
  return replaced;
}

}  // namespace tjepa
