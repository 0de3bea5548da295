#pragma once
// The JEPA regression loss between the predictor's output and the target encoder's embeddings
// at the same tokens (paper, Sec. III-B, the SSL objective), forward and gradient together.
//
//   mse (default, the reference's nn.MSELoss):   ℓ(e) = e²
//   smooth_l1 (I-JEPA, β = 1):                   ℓ(e) = ½e² if |e| < 1, else |e| − ½
// loss = mean over the n = B·t·d elements of ℓ(pred − target): a target's tokens and the
// embedding dimension, as PyTorch's reduction="mean". The option that goes with smooth_l1 in
// I-JEPA, re-normalizing the targets by a LayerNorm without affine (F.layer_norm(h, (d,)),
// eps 1e-5), is normalize_rows.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <functional>
#include <span>
#include <string_view>
#include <utility>

#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/enum_names.hpp"
#include "tjepa/optim/detail/deterministic_sum.hpp"

namespace tjepa {

enum class JepaLossKind { mse, smooth_l1 };

// The names (JSON, text).
constexpr auto json_names(JepaLossKind) {
  return std::array{std::pair<std::string_view, JepaLossKind>{"mse", JepaLossKind::mse},
                    std::pair<std::string_view, JepaLossKind>{"smooth_l1", JepaLossKind::smooth_l1}};
}
inline const char* to_string(JepaLossKind k) { return enum_name(k); }

// PyTorch's F.layer_norm default eps.
inline constexpr double target_norm_eps = 1e-5;

// x[m, :] ← (x[m, :] − mean) / sqrt(var + eps) for rows x [M, d] (biased variance), in place.
template <class T>
void normalize_rows(T* x, std::size_t M, int d, double eps = target_norm_eps) {
  const auto rows = static_cast<std::ptrdiff_t>(M);
  TJEPA_OMP(omp parallel for schedule(static) if (M * static_cast<std::size_t>(d) > detail::parallel_grain))
  for (std::ptrdiff_t m = 0; m < rows; ++m) {
    T* r = x + static_cast<std::size_t>(m) * d;
    double mu = 0;
    for (int c = 0; c < d; ++c) mu += r[c];
    mu /= d;
    double var = 0;
    for (int c = 0; c < d; ++c) var += (r[c] - mu) * (r[c] - mu);
    var /= d;
    const double rs = 1.0 / std::sqrt(var + eps);
    for (int c = 0; c < d; ++c) r[c] = static_cast<T>((r[c] - mu) * rs);
  }
}

namespace detail {
// Columns j0 .. j0 + n of x [M, D]: their means and biased variances, in double (two passes over
// the rows in order, so the same on any thread count).
template <class T>
void column_moments(const T* x, std::size_t M, std::size_t D, std::size_t j0, std::size_t n, double* mean, double* var) {
  std::fill(mean, mean + n, 0.0);
  std::fill(var, var + n, 0.0);
  for (std::size_t m = 0; m < M; ++m)
    for (std::size_t j = 0; j < n; ++j) mean[j] += static_cast<double>(x[m * D + j0 + j]);
  for (std::size_t j = 0; j < n; ++j) mean[j] /= static_cast<double>(M);
  for (std::size_t m = 0; m < M; ++m)
    for (std::size_t j = 0; j < n; ++j) {
      const double v = static_cast<double>(x[m * D + j0 + j]) - mean[j];
      var[j] += v * v;
    }
  for (std::size_t j = 0; j < n; ++j) var[j] /= static_cast<double>(M);
}
// x[m, j0 + j] ← (x[m, j0 + j] − mean[j]) · scale[j] for the M rows of x [M, D], in double (a large
// shared offset minus its mean keeps its digits).
template <class T>
void scale_columns(T* x, std::size_t M, std::size_t D, std::size_t j0, std::size_t n, const double* mean,
                   const double* scale) {
  for (std::size_t m = 0; m < M; ++m)
    for (std::size_t j = 0; j < n; ++j)
      x[m * D + j0 + j] = static_cast<T>((static_cast<double>(x[m * D + j0 + j]) - mean[j]) * scale[j]);
}
}  // namespace detail

// x[:, j] ← (x[:, j] − mean) / sqrt(var + eps) for x [M, D], each column over its M rows (biased
// variance), in place. For the targets h [B, N·d] (JepaStepConfig::standardize_targets), each
// token's each dimension over the batch: whatever a token's embedding holds for every sample (its
// position) is removed, and what is left is what differs between samples.
template <class T>
void standardize_columns(T* x, std::size_t M, std::size_t D, double eps = target_norm_eps) {
  constexpr std::size_t chunk = 512;
  const auto chunks = static_cast<std::ptrdiff_t>((D + chunk - 1) / chunk);
  TJEPA_OMP(omp parallel for schedule(static) if (M * D > detail::parallel_grain))
  for (std::ptrdiff_t c = 0; c < chunks; ++c) {
    const std::size_t j0 = static_cast<std::size_t>(c) * chunk, n = std::min(chunk, D - j0);
    double mean[chunk], inv_std[chunk];
    detail::column_moments(x, M, D, j0, n, mean, inv_std);  // the variance, then 1/std
    for (std::size_t j = 0; j < n; ++j) inv_std[j] = 1.0 / std::sqrt(inv_std[j] + eps);
    detail::scale_columns(x, M, D, j0, n, mean, inv_std);
  }
}

// Returns mean_i ℓ(pred_i − target_i) over n elements (summed in double, the same on any thread
// count). dpred, if not null, receives scale · ∂loss/∂pred (overwritten, not added).
// With row_weight [n / row_len] (row_len elements per row: a token's embedding), the mean is
// weighted by row: Σ_i w_row(i) ℓ_i / (row_len · Σ_r w_r); weights all equal give the plain mean.
template <class T>
double regression_loss(const T* pred, const T* target, T* dpred, std::size_t n, JepaLossKind kind,
                       double scale = 1.0, const double* row_weight = nullptr, std::size_t row_len = 1) {
  auto weight = [&](std::size_t i) { return row_weight ? row_weight[i / row_len] : 1.0; };
  double total_weight = static_cast<double>(n);
  if (row_weight)
    total_weight = static_cast<double>(row_len) *
                   detail::deterministic_sum(n / row_len, [&](std::size_t r) { return row_weight[r]; });
  const double inv_n = 1.0 / total_weight;
  const double sum = detail::deterministic_sum(n, [&](std::size_t i) {
    const double e = static_cast<double>(pred[i]) - static_cast<double>(target[i]);
    if (kind == JepaLossKind::mse) return weight(i) * e * e;
    const double a = std::abs(e);
    return weight(i) * (a < 1.0 ? 0.5 * e * e : a - 0.5);
  });
  if (dpred) {
    const double g = scale * inv_n;
    const auto count = static_cast<std::ptrdiff_t>(n);
    TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
    for (std::ptrdiff_t i = 0; i < count; ++i) {
      const double e = static_cast<double>(pred[i]) - static_cast<double>(target[i]);
      // ∂ℓ/∂e: 2e for mse; e inside the quadratic zone, sign(e) outside for smooth-L1.
      const double de = kind == JepaLossKind::mse ? 2.0 * e : (std::abs(e) < 1.0 ? e : (e > 0 ? 1.0 : -1.0));
      dpred[i] = static_cast<T>(g * weight(static_cast<std::size_t>(i)) * de);
    }
  }
  return sum * inv_n;
}

// The loss seam of JepaStep: the regression loss of one target, given its predictions and targets
// [rows, d] (row-major), returns the loss and writes ∂loss/∂pred into dpred (overwritten). The
// step averages the targets' losses (and scales their gradients) itself.
template <class T>
using JepaLoss = std::function<double(std::span<const T> pred, std::span<const T> target, std::size_t rows, int d,
                                      std::span<T> dpred)>;

// The built-in losses as JepaLoss callables: mean over rows·d of ℓ(pred − target).
template <class T>
JepaLoss<T> jepa_loss_of(JepaLossKind kind) {
  return [kind](std::span<const T> pred, std::span<const T> target, std::size_t, int, std::span<T> dpred) {
    return regression_loss(pred.data(), target.data(), dpred.data(), pred.size(), kind);
  };
}
template <class T>
JepaLoss<T> mse_loss() {
  return jepa_loss_of<T>(JepaLossKind::mse);
}
template <class T>
JepaLoss<T> smooth_l1_loss() {
  return jepa_loss_of<T>(JepaLossKind::smooth_l1);
}

}  // namespace tjepa
