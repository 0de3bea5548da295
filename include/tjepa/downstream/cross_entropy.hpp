#pragma once
// Softmax cross-entropy for classification heads (the probe's indenter logits), forward and
// gradient together, numerically as PyTorch's F.cross_entropy(logits, labels) with mean reduction.
//
//   p[b, :] = softmax(logits[b, :])                         logits [B, C] (row stride ld)
//   loss    = −(1/B) Σ_b log p[b, labels[b]]
//   ∂loss/∂logits[b, c] = (p[b, c] − [c == labels[b]]) / B
#include <cmath>
#include <cstddef>

#include "tjepa/core/error.hpp"

namespace tjepa {

// Returns the mean loss. dlogits (row stride ldd), if not null, receives scale · ∂loss/∂logits
// (overwritten, not added). Labels outside [0, C) throw DataError.
template <class T>
double softmax_cross_entropy(const T* logits, std::size_t ld, const int* labels, int B, int C, T* dlogits,
                             std::size_t ldd, double scale = 1.0) {
  require<ShapeError>(B > 0 && C > 1, "softmax_cross_entropy: B = ", B, ", C = ", C, ", expected B > 0, C > 1");
  double total = 0.0;
  for (int b = 0; b < B; ++b) {
    const int y = labels[b];
    require<DataError>(y >= 0 && y < C, "softmax_cross_entropy: labels[", b, "] = ", y, ", expected in [0, ", C, ")");
    const T* z = logits + static_cast<std::size_t>(b) * ld;
    double zmax = static_cast<double>(z[0]);
    for (int c = 1; c < C; ++c) zmax = std::max(zmax, static_cast<double>(z[c]));
    double sum = 0.0;
    for (int c = 0; c < C; ++c) sum += std::exp(static_cast<double>(z[c]) - zmax);
    const double log_sum = std::log(sum) + zmax;  // log Σ exp z
    total += log_sum - static_cast<double>(z[y]);
    if (!dlogits) continue;
    T* g = dlogits + static_cast<std::size_t>(b) * ldd;
    for (int c = 0; c < C; ++c) {
      const double p = std::exp(static_cast<double>(z[c]) - log_sum);
      g[c] = static_cast<T>(scale * (p - (c == y ? 1.0 : 0.0)) / B);
    }
  }
  return total / B;
}

}  // namespace tjepa
