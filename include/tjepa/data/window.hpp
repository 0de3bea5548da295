#pragma once
// Windowing: training sees windows of τ frames, X[t:t+τ] (paper, Sec. III-A), starting every
// `stride` frames (non-overlapping, stride = τ, in the reference implementation: E-Kovtun/tactile,
// tactile_ssl/data/xela/preprocessing.py). A window is handed to the model taxel-major, [N, τ, m],
// so each taxel's τ·m values are contiguous: the tokenizer's input (paper eq. 1).
//
// Window starts are t = 0, stride, 2·stride, ... with t + τ <= T: every window that fits. (The
// reference's index, arange(0, T − T mod τ − τ, stride), leaves out the last full window.)
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/recording.hpp"

namespace tjepa {

struct WindowSpec {
  int length = 10;  // τ, frames per window
  int stride = 0;   // frames between window starts; 0: length (non-overlapping)
  // Leave out the windows that hold a NaN/Inf reading (NonFinite::drop); otherwise such a window
  // is a DataError when it is gathered.
  bool skip_non_finite = false;

  int step() const { return stride > 0 ? stride : length; }
  void validate() const {
    require<ConfigError>(length > 0, "WindowSpec: length (tau) = ", length, ", expected > 0");
    require<ConfigError>(stride >= 0, "WindowSpec: stride = ", stride, ", expected >= 0 (0: stride = length)");
  }
};

inline std::vector<std::int64_t> window_starts(int frames, const WindowSpec& spec) {
  spec.validate();
  std::vector<std::int64_t> s;
  for (std::int64_t t = 0; t + spec.length <= frames; t += spec.step()) s.push_back(t);
  return s;
}

// out [N, τ, m] = rec[start : start + τ] transposed from [τ, N, m].
inline void copy_window(const Recording& rec, int start, int length, float* out) {
  const int n_tax = rec.taxels(), m = rec.axes();
  const std::size_t row = static_cast<std::size_t>(length) * m;
  for (int j = 0; j < length; ++j) {
    const float* f = rec.frame(start + j);
    float* o = out + static_cast<std::size_t>(j) * m;
    for (int n = 0; n < n_tax; ++n, f += m, o += row)
      for (int a = 0; a < m; ++a) o[a] = f[a];
  }
}

}  // namespace tjepa
