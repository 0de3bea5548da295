#pragma once
// The ridge baseline of the downstream protocol: closed-form ridge regression on hand-crafted
// features of the raw windows, the floor every learned encoder must beat.
//
// Features of a window x [N, τ, m] (window_features), with ḡ the mean over the window's τ frames:
//   pad sums     f[g·m + a]       = Σ_{n in group g} ḡ(x[n, :, a])      [G·m]  (the pad's load)
//   taxel means  f[G·m + n·m + a] = ḡ(x[n, :, a])                       [N·m]
// Model (fit_ridge), all in double:
//   z = (x − μ) / σ               per feature, μ, σ from the rows the weights are fitted on
//                                 (σ = 1 for a constant feature)
//   ŷ = z·W + b                   b = mean of the fitted targets (the intercept is not penalized)
//   W = argmin ‖Z W − (Y − b)‖² + λ‖W‖²  = (ZᵀZ + λI)⁻¹ Zᵀ(Y − b)        (primal, p ≤ n)
//                                       = Zᵀ (ZZᵀ + λI)⁻¹ (Y − b)       (dual, p > n)
// λ is chosen from a grid: a seeded split holds out validation_fraction of the rows (or, given
// SampleGroups, of each stratum's groups: split_by_groups, downstream/early_stopping.hpp); for each λ
// the model is fitted on the rest and scored on the held-out rows (mean squared error over rows
// and outputs; for the classifier: the error rate, ties broken by the squared error); the best λ
// (the smallest on ties) is then refitted on all rows. Classification is ridge on one-hot targets,
// the predicted class the argmax.
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/downstream/early_stopping.hpp"
#include "tjepa/data/window_source.hpp"

namespace tjepa {

namespace detail {
// The number of samples S of embeddings [S, N, d]; throws unless the size is a multiple of N·d
// and every row is in [0, S).
inline std::int64_t embedding_samples(std::span<const float> embeddings, int N, int d, std::span<const std::int64_t> rows,
                                      const char* who) {
  require<ShapeError>(N > 0 && d > 0 && embeddings.size() % (static_cast<std::size_t>(N) * d) == 0, who, ": ",
                      embeddings.size(), " values, expected a multiple of N*d = ", N, "*", d);
  const auto S = static_cast<std::int64_t>(embeddings.size() / (static_cast<std::size_t>(N) * d));
  for (std::int64_t r : rows) require<DataError>(r >= 0 && r < S, who, ": row ", r, ", expected in [0, ", S, ")");
  return S;
}
// Sample r of embeddings [S, N, d] as an [N, d] expression in double.
inline auto embedding_sample(std::span<const float> embeddings, std::int64_t r, int N, int d) {
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  return Eigen::Map<const RowMajor>(embeddings.data() + static_cast<std::size_t>(r) * N * d, N, d).cast<double>();
}
}  // namespace detail

// Linear read-outs of a frozen encoder's embeddings [S, N, d] (embed_windows), features for ridge:
//   group means       [G·d] per sample: the mean embedding of each pad's (group's) tokens — what
//                     each pad holds, not where on the pad (group_mean_embeddings)
//   token components  [N·k] per sample: each token's embedding minus its mean over the fitting
//                     samples, projected on the k leading principal directions of those residuals
//                     (pooled over tokens and fitting samples) — where on the skin, at k numbers per
//                     taxel (TokenComponents; k = 3 keeps as many as a raw window's 3 axes)

// Group means for samples `rows`. group [N]: each token's group in [0, num_groups); every group
// must hold a token.
inline Eigen::MatrixXd group_mean_embeddings(std::span<const float> embeddings, int N, int d,
                                             std::span<const std::int64_t> rows, std::span<const int> group,
                                             int num_groups) {
  detail::embedding_samples(embeddings, N, d, rows, "group_mean_embeddings");
  require<ShapeError>(group.size() == static_cast<std::size_t>(N), "group_mean_embeddings: group has ", group.size(),
                      " entries, expected one per token (", N, ")");
  require<ConfigError>(num_groups > 0, "group_mean_embeddings: num_groups = ", num_groups, ", expected > 0");
  std::vector<int> count(static_cast<std::size_t>(num_groups), 0);
  for (int n = 0; n < N; ++n) {
    require<DataError>(group[n] >= 0 && group[n] < num_groups, "group_mean_embeddings: group[", n, "] = ", group[n],
                       ", expected in [0, ", num_groups, ")");
    ++count[static_cast<std::size_t>(group[n])];
  }
  for (int g = 0; g < num_groups; ++g)
    require<DataError>(count[static_cast<std::size_t>(g)] > 0, "group_mean_embeddings: group ", g, " has no token");
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(rows.size()), static_cast<Eigen::Index>(num_groups) * d);
  for (std::size_t r = 0; r < rows.size(); ++r)
    for (int n = 0; n < N; ++n) {
      const float* x = embeddings.data() + (static_cast<std::size_t>(rows[r]) * N + n) * d;
      const double w = 1.0 / count[static_cast<std::size_t>(group[n])];
      const Eigen::Index c0 = static_cast<Eigen::Index>(group[n]) * d;
      for (int i = 0; i < d; ++i) f(static_cast<Eigen::Index>(r), c0 + i) += w * x[i];
    }
  return f;
}

// Token components (see above), fitted on samples `rows` of the training embeddings.
struct TokenComponents {
  Eigen::MatrixXd mean;              // [N, d] each token's mean embedding over the fitting samples
  Eigen::MatrixXd directions;        // [d, k] leading principal directions of the residuals, first first
  Eigen::VectorXd variance_share;    // [k] share of the residuals' variance along each direction

  int tokens() const { return static_cast<int>(mean.rows()); }
  int dim() const { return static_cast<int>(mean.cols()); }
  int components() const { return static_cast<int>(directions.cols()); }

  static TokenComponents fit(std::span<const float> embeddings, int N, int d, std::span<const std::int64_t> rows, int k) {
    detail::embedding_samples(embeddings, N, d, rows, "TokenComponents::fit");
    require<ConfigError>(k > 0 && k <= d, "TokenComponents::fit: k = ", k, ", expected in [1, d = ", d, "]");
    require<DataError>(rows.size() >= 2, "TokenComponents::fit: ", rows.size(), " samples, expected at least 2");
    TokenComponents t;
    t.mean = Eigen::MatrixXd::Zero(N, d);
    for (std::int64_t r : rows) t.mean += detail::embedding_sample(embeddings, r, N, d);
    t.mean /= static_cast<double>(rows.size());
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(d, d), R(N, d);
    for (std::int64_t r : rows) {
      R = detail::embedding_sample(embeddings, r, N, d) - t.mean;
      C.noalias() += R.transpose() * R;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(C);  // eigenvalues ascending
    require<NumericError>(es.info() == Eigen::Success, "TokenComponents::fit: the eigen-decomposition failed");
    const double total = es.eigenvalues().sum();
    require<DataError>(total > 0, "TokenComponents::fit: the embeddings do not vary over the samples");
    t.directions = es.eigenvectors().rightCols(k).rowwise().reverse();
    t.variance_share = es.eigenvalues().tail(k).reverse() / total;
    return t;
  }

  // Features [rows, N·k] of samples `rows` of embeddings [S, N, d]: feature n·k + j is token n's
  // residual along direction j.
  Eigen::MatrixXd features(std::span<const float> embeddings, std::span<const std::int64_t> rows) const {
    const int N = tokens(), d = dim(), k = components();
    detail::embedding_samples(embeddings, N, d, rows, "TokenComponents::features");
    Eigen::MatrixXd f(static_cast<Eigen::Index>(rows.size()), static_cast<Eigen::Index>(N) * k);
    Eigen::MatrixXd P(N, k);
    for (std::size_t r = 0; r < rows.size(); ++r) {
      P.noalias() = (detail::embedding_sample(embeddings, rows[r], N, d) - mean) * directions;
      for (int n = 0; n < N; ++n) f.row(static_cast<Eigen::Index>(r)).segment(static_cast<Eigen::Index>(n) * k, k) = P.row(n);
    }
    return f;
  }
};

// Features [B, G·m + N·m] of a batch of windows (see the top). group [N]: each taxel's pad /
// group in [0, num_groups) (TaxelLayout::group).
inline Eigen::MatrixXd window_features(const WindowBatch& wb, std::span<const int> group, int num_groups) {
  const int B = wb.batch, N = wb.taxels, tau = wb.length, m = wb.axes;
  require<ShapeError>(B > 0 && N > 0 && tau > 0 && m > 0 && wb.x.size() == static_cast<std::size_t>(B) * wb.per_window(),
                      "window_features: a batch of ", B, " windows of ", N, " taxels x ", tau, " frames x ", m,
                      " axes with ", wb.x.size(), " values, expected a non-empty [B, N, tau, m]");
  require<ShapeError>(group.size() == static_cast<std::size_t>(N), "window_features: group has ", group.size(),
                      " entries, expected one per taxel (", N, ")");
  require<ConfigError>(num_groups > 0, "window_features: num_groups = ", num_groups, ", expected > 0");
  for (int n = 0; n < N; ++n)
    require<DataError>(group[n] >= 0 && group[n] < num_groups, "window_features: group[", n, "] = ", group[n],
                       ", expected in [0, ", num_groups, ")");
  const int G = num_groups;
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(B, static_cast<Eigen::Index>(G + N) * m);
  for (int b = 0; b < B; ++b)
    for (int n = 0; n < N; ++n) {
      const float* w = wb.x.data() + (static_cast<std::size_t>(b) * N + n) * tau * m;  // [τ, m]
      for (int a = 0; a < m; ++a) {
        double s = 0;
        for (int t = 0; t < tau; ++t) s += w[static_cast<std::size_t>(t) * m + a];
        const double mean = s / tau;
        f(b, static_cast<Eigen::Index>(G) * m + static_cast<Eigen::Index>(n) * m + a) = mean;
        f(b, static_cast<Eigen::Index>(group[n]) * m + a) += mean;
      }
    }
  return f;
}

// The λ grid the protocol and the command's probes choose from.
inline constexpr std::array<double, 9> ridge_lambdas{1e-2, 1e-1, 1, 10, 1e2, 1e3, 1e4, 1e5, 1e6};

struct RidgeModel {
  Eigen::RowVectorXd mean, scale;  // [p] feature standardization: z = (x − mean) / scale
  Eigen::MatrixXd weight;          // [p, k]
  Eigen::RowVectorXd bias;         // [k]
  double lambda = 0;               // the chosen λ
  // [lambdas] validation score per λ (lower is better): the mean squared error (fit_ridge), the
  // error rate + a tie-break below 1/n_validation (fit_ridge_classifier); empty from fit_ridge_at.
  std::vector<double> validation;

  int features() const { return static_cast<int>(weight.rows()); }
  int outputs() const { return static_cast<int>(weight.cols()); }
};

// Predictions [n, k] for rows X [n, p].
inline Eigen::MatrixXd predict(const RidgeModel& model, const Eigen::MatrixXd& X) {
  require<ShapeError>(X.cols() == model.weight.rows(), "predict (ridge): X has ", X.cols(), " columns, the model ",
                      model.weight.rows(), " features");
  const Eigen::MatrixXd Z = (X.rowwise() - model.mean).array().rowwise() / model.scale.array();
  return (Z * model.weight).rowwise() + model.bias;
}

// Class per row: the argmax of the predicted one-hot scores (the first on ties).
inline std::vector<int> predict_class(const RidgeModel& model, const Eigen::MatrixXd& X) {
  const Eigen::MatrixXd s = predict(model, X);
  std::vector<int> c(static_cast<std::size_t>(s.rows()));
  for (Eigen::Index i = 0; i < s.rows(); ++i) s.row(i).maxCoeff(&c[static_cast<std::size_t>(i)]);
  return c;
}

// One-hot targets [n, C] of labels in [0, C).
inline Eigen::MatrixXd one_hot(std::span<const int> labels, int num_classes) {
  require<ConfigError>(num_classes > 1, "one_hot: num_classes = ", num_classes, ", expected > 1");
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(labels.size()), num_classes);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    require<DataError>(labels[i] >= 0 && labels[i] < num_classes, "one_hot: labels[", i, "] = ", labels[i],
                       ", expected in [0, ", num_classes, ")");
    Y(static_cast<Eigen::Index>(i), labels[i]) = 1;
  }
  return Y;
}

// The ridge solution at one λ > 0 on all rows of X [n, p], Y [n, k] (no selection).
inline RidgeModel fit_ridge_at(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, double lambda) {
  require<ShapeError>(X.rows() > 0 && X.cols() > 0 && Y.cols() > 0 && X.rows() == Y.rows(), "fit_ridge: X is ",
                      X.rows(), "x", X.cols(), ", Y is ", Y.rows(), "x", Y.cols(),
                      ", expected the same number of rows, all dimensions > 0");
  require<ConfigError>(lambda > 0 && std::isfinite(lambda), "fit_ridge: lambda = ", lambda, ", expected finite > 0");
  require<DataError>(X.allFinite() && Y.allFinite(), "fit_ridge: X or Y holds NaN or Inf, expected finite values");
  const double n = static_cast<double>(X.rows());
  RidgeModel r;
  r.lambda = lambda;
  r.mean = X.colwise().mean();
  const Eigen::MatrixXd Xc = X.rowwise() - r.mean;
  r.scale = (Xc.colwise().squaredNorm() / n).cwiseSqrt();
  for (Eigen::Index j = 0; j < r.scale.size(); ++j)
    if (!(r.scale(j) > 1e-12 * std::max(1.0, std::fabs(r.mean(j))))) r.scale(j) = 1;  // constant feature
  const Eigen::MatrixXd Z = Xc.array().rowwise() / r.scale.array();
  r.bias = Y.colwise().mean();
  const Eigen::MatrixXd Yc = Y.rowwise() - r.bias;
  if (Z.cols() <= Z.rows()) {
    Eigen::MatrixXd A = Z.transpose() * Z;
    A.diagonal().array() += lambda;
    r.weight = A.ldlt().solve(Z.transpose() * Yc);
  } else {
    Eigen::MatrixXd K = Z * Z.transpose();
    K.diagonal().array() += lambda;
    r.weight = Z.transpose() * K.ldlt().solve(Yc);
  }
  return r;
}

namespace detail {
// The rows λ is chosen on: with groups, split_by_groups; else split_for_validation's random rows.
inline ValidationSplit ridge_split(int n, double validation_fraction, std::uint64_t seed, const SampleGroups& groups) {
  require<ConfigError>(validation_fraction > 0 && validation_fraction < 1, "fit_ridge: validation_fraction = ",
                       validation_fraction, ", expected in (0, 1)");
  if (groups.empty()) return split_for_validation(n, validation_fraction, seed);
  groups.validate("fit_ridge", n);
  return split_by_groups(groups, validation_fraction, seed);
}

// The λ of the grid with the lowest score(model fitted on the fit rows, validation rows), refitted
// on all rows; model.validation holds the scores.
template <class Score>
RidgeModel select_ridge(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, std::span<const double> lambdas,
                        double validation_fraction, std::uint64_t seed, const SampleGroups& groups, const Score& score) {
  require<ConfigError>(!lambdas.empty(), "fit_ridge: no lambdas to choose from");
  require<ShapeError>(X.rows() == Y.rows(), "fit_ridge: X has ", X.rows(), " rows, Y ", Y.rows());
  const ValidationSplit split = ridge_split(static_cast<int>(X.rows()), validation_fraction, seed, groups);
  auto rows = [](const Eigen::MatrixXd& M, const std::vector<std::int64_t>& ids) {
    Eigen::MatrixXd out(static_cast<Eigen::Index>(ids.size()), M.cols());
    for (std::size_t i = 0; i < ids.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = M.row(static_cast<Eigen::Index>(ids[i]));
    return out;
  };
  const Eigen::MatrixXd Xf = rows(X, split.fit), Yf = rows(Y, split.fit);
  const Eigen::MatrixXd Xv = rows(X, split.validation), Yv = rows(Y, split.validation);
  std::vector<double> scores;
  double best = std::numeric_limits<double>::infinity(), best_lambda = lambdas[0];
  for (double lambda : lambdas) {
    const double s = score(fit_ridge_at(Xf, Yf, lambda), Xv, Yv);
    scores.push_back(s);
    if (s < best || (s == best && lambda < best_lambda)) {
      best = s;
      best_lambda = lambda;
    }
  }
  RidgeModel model = fit_ridge_at(X, Y, best_lambda);
  model.validation = std::move(scores);
  return model;
}
}  // namespace detail

// Multi-output ridge regression, X [n, p], Y [n, k], λ from the grid by validation mean squared
// error (see the top). Returns the model refitted on all rows at the chosen λ.
inline RidgeModel fit_ridge(const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, std::span<const double> lambdas,
                            double validation_fraction, std::uint64_t seed, const SampleGroups& groups = {}) {
  return detail::select_ridge(X, Y, lambdas, validation_fraction, seed, groups,
                              [](const RidgeModel& m, const Eigen::MatrixXd& Xv, const Eigen::MatrixXd& Yv) {
                                return (predict(m, Xv) - Yv).squaredNorm() / static_cast<double>(Yv.size());
                              });
}

// Ridge classifier on one-hot targets of labels [n] in [0, num_classes); λ by validation error
// rate, ties broken by the squared error. predict_class gives the classes.
inline RidgeModel fit_ridge_classifier(const Eigen::MatrixXd& X, std::span<const int> labels, int num_classes,
                                       std::span<const double> lambdas, double validation_fraction,
                                       std::uint64_t seed, const SampleGroups& groups = {}) {
  require<ShapeError>(labels.size() == static_cast<std::size_t>(X.rows()), "fit_ridge_classifier: ", labels.size(),
                      " labels for ", X.rows(), " rows");
  return detail::select_ridge(
      X, one_hot(labels, num_classes), lambdas, validation_fraction, seed, groups,
      [](const RidgeModel& m, const Eigen::MatrixXd& Xv, const Eigen::MatrixXd& Yv) {
        const Eigen::MatrixXd s = predict(m, Xv);
        int wrong = 0;
        for (Eigen::Index i = 0; i < s.rows(); ++i) {
          Eigen::Index c = 0, y = 0;
          s.row(i).maxCoeff(&c);
          Yv.row(i).maxCoeff(&y);
          wrong += c != y;
        }
        // The error rate plus the squared error squeezed into [0, 1/n): it only breaks ties.
        const double mse = (s - Yv).squaredNorm() / static_cast<double>(Yv.size());
        return (static_cast<double>(wrong) + mse / (1 + mse)) / static_cast<double>(s.rows());
      });
}

}  // namespace tjepa
