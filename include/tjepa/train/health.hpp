#pragma once
// Training health: the numbers that make collapse and divergence visible at every step.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tjepa/core/detail/parallel.hpp"

namespace tjepa {

// What one JEPA training step reports.
struct JepaStepStats {
  std::int64_t step = 0;        // optimizer step index s (0-based)
  double loss = 0;              // mean over targets of each target's mean loss
  double lr = 0, weight_decay = 0, momentum = 0;  // the schedule values this step used
  double grad_norm = 0;         // joint gradient norm before clipping
  double target_std = 0;        // std of the target encoder's embeddings over tokens, mean over dims
  // Std over the batch's samples at each token and dim, averaged: how much the target embeddings
  // depend on the input. An encoder that ignores its input and embeds each taxel by its position
  // alone (a collapse target_std cannot see: positions differ) drives it to 0. On sparse contact
  // data it is small (most taxels are idle in every window) and grows as pre-training learns.
  double target_sample_std = 0;
  std::vector<double> target_losses;  // [num targets]
};

// Std over the M rows of each of the d columns of x [M, d], averaged over the columns: a
// collapsed encoder (every token embedded alike) drives it to 0. Summed in double in fixed
// row chunks, so the result does not depend on the thread count.
template <class T>
double embedding_std(const T* x, std::size_t M, int d) {
  if (M < 2) return 0.0;
  constexpr std::size_t chunk = 256;
  const std::size_t chunks = (M + chunk - 1) / chunk;
  const std::size_t D = static_cast<std::size_t>(d);
  std::vector<double> s1(chunks * D, 0.0), s2(chunks * D, 0.0);
  const auto count = static_cast<std::ptrdiff_t>(chunks);
  // Pass 1: column means; pass 2: squared deviations (stable for large offsets).
  TJEPA_OMP(omp parallel for schedule(static) if (M * D > detail::parallel_grain))
  for (std::ptrdiff_t c = 0; c < count; ++c) {
    double* acc = s1.data() + static_cast<std::size_t>(c) * D;
    const std::size_t end = std::min(M, (static_cast<std::size_t>(c) + 1) * chunk);
    for (std::size_t m = static_cast<std::size_t>(c) * chunk; m < end; ++m)
      for (std::size_t j = 0; j < D; ++j) acc[j] += static_cast<double>(x[m * D + j]);
  }
  std::vector<double> mean(D, 0.0);
  for (std::size_t c = 0; c < chunks; ++c)
    for (std::size_t j = 0; j < D; ++j) mean[j] += s1[c * D + j];
  for (auto& v : mean) v /= static_cast<double>(M);
  TJEPA_OMP(omp parallel for schedule(static) if (M * D > detail::parallel_grain))
  for (std::ptrdiff_t c = 0; c < count; ++c) {
    double* acc = s2.data() + static_cast<std::size_t>(c) * D;
    const std::size_t end = std::min(M, (static_cast<std::size_t>(c) + 1) * chunk);
    for (std::size_t m = static_cast<std::size_t>(c) * chunk; m < end; ++m)
      for (std::size_t j = 0; j < D; ++j) {
        const double e = static_cast<double>(x[m * D + j]) - mean[j];
        acc[j] += e * e;
      }
  }
  double total = 0;
  for (std::size_t j = 0; j < D; ++j) {
    double v = 0;
    for (std::size_t c = 0; c < chunks; ++c) v += s2[c * D + j];
    total += std::sqrt(v / static_cast<double>(M - 1));  // unbiased, as torch.std
  }
  return total / static_cast<double>(d);
}

}  // namespace tjepa
