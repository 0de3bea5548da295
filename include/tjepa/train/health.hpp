#pragma once
// Training health: the numbers that make collapse and divergence visible at every step.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <ostream>
#include <vector>

#include "tjepa/core/detail/parallel.hpp"

namespace tjepa {

// What every objective's update reports (train/objective.hpp); objectives extend it.
struct StepStats {
  std::int64_t step = 0;            // optimizer step s (0-based)
  double loss = 0;                  // the batch's loss (over all ranks)
  double lr = 0, weight_decay = 0;  // the rates this step used
  double grad_norm = 0;             // joint gradient norm before clipping

  // The log line's fields after "step s/S epoch e".
  void write(std::ostream& os) const {
    os << "loss " << loss << " lr " << lr << " wd " << weight_decay << " grad_norm " << grad_norm;
  }
};

// What one JEPA training step reports: loss = mean over targets of each target's mean loss.
struct JepaStepStats : StepStats {
  double momentum = 0;          // the target encoder's EMA momentum this step used
  double target_std = 0;        // std of the target encoder's embeddings over tokens, mean over dims
  // Std over the batch's samples at each token and dim, averaged: how much the target embeddings
  // depend on the input. An encoder that ignores its input and embeds each taxel by its position
  // alone (a collapse target_std cannot see: positions differ) drives it to 0. On sparse contact
  // data it is small (most taxels are idle in every window) and grows as pre-training learns.
  double target_sample_std = 0;
  std::vector<double> target_losses;  // [num targets]

  void write(std::ostream& os) const {
    os << "loss " << loss << " lr " << lr << " wd " << weight_decay << " ema " << momentum << " grad_norm "
       << grad_norm << " target_std " << target_std;
  }
};

// Per-column moments of M rows: mean[j] and m2[j] = Σ_m (x[m, j] − mean[j])².
struct ColumnMoments {
  std::size_t rows = 0;
  std::vector<double> mean, m2;

  // Std over the rows of each column (unbiased, as torch.std), averaged over the columns; 0 for
  // fewer than 2 rows.
  double mean_std() const {
    if (rows < 2 || mean.empty()) return 0.0;
    double total = 0;
    for (double v : m2) total += std::sqrt(v / static_cast<double>(rows - 1));
    return total / static_cast<double>(mean.size());
  }
};

// The moments of the d columns of x [M, d]. Summed in double in fixed tasks of up to 256 rows ×
// 1024 columns (the columns split too, so that a few long rows, the targets as [B, N·d], keep
// every thread busy), so the result does not depend on the thread count; two passes (mean, then
// squared deviations), stable for large offsets.
template <class T>
ColumnMoments column_moments(const T* x, std::size_t M, int d) {
  ColumnMoments out;
  out.rows = M;
  const std::size_t D = static_cast<std::size_t>(d);
  out.mean.assign(D, 0.0);
  out.m2.assign(D, 0.0);
  if (M == 0) return out;
  constexpr std::size_t chunk = 256, width = 1024;
  const std::size_t chunks = (M + chunk - 1) / chunk, blocks = (D + width - 1) / width;
  std::vector<double> s1(chunks * D, 0.0), s2(chunks * D, 0.0);
  const auto tasks = static_cast<std::ptrdiff_t>(chunks * blocks);
  // Task t: rows of chunk t / blocks, columns of block t % blocks; acc (a chunk's sums) += f(m, j).
  auto each_task = [&](std::vector<double>& sums, auto&& f) {
    TJEPA_OMP(omp parallel for schedule(static) if (M * D > detail::parallel_grain))
    for (std::ptrdiff_t t = 0; t < tasks; ++t) {
      const std::size_t c = static_cast<std::size_t>(t) / blocks, j0 = static_cast<std::size_t>(t) % blocks * width;
      const std::size_t j1 = std::min(D, j0 + width), end = std::min(M, (c + 1) * chunk);
      double* acc = sums.data() + c * D;
      for (std::size_t m = c * chunk; m < end; ++m)
        for (std::size_t j = j0; j < j1; ++j) acc[j] += f(m, j);
    }
  };
  each_task(s1, [&](std::size_t m, std::size_t j) { return static_cast<double>(x[m * D + j]); });
  std::vector<double>& mean = out.mean;
  for (std::size_t c = 0; c < chunks; ++c)
    for (std::size_t j = 0; j < D; ++j) mean[j] += s1[c * D + j];
  for (auto& v : mean) v /= static_cast<double>(M);
  each_task(s2, [&](std::size_t m, std::size_t j) {
    const double e = static_cast<double>(x[m * D + j]) - mean[j];
    return e * e;
  });
  for (std::size_t j = 0; j < D; ++j)
    for (std::size_t c = 0; c < chunks; ++c) out.m2[j] += s2[c * D + j];
  return out;
}

// Std over the M rows of each of the d columns of x [M, d], averaged over the columns: a
// collapsed encoder (every token embedded alike) drives it to 0.
template <class T>
double embedding_std(const T* x, std::size_t M, int d) {
  if (M < 2) return 0.0;
  return column_moments(x, M, d).mean_std();
}

}  // namespace tjepa
