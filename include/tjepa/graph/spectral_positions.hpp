#pragma once
// Graph positions: a starting point for the learned position table that already knows which taxels
// are neighbours (Laplacian eigenmaps, as graph transformers use for positional encodings).
//
// The reference initializes the table e_i ∈ R^d with N(0, 0.02²) and learns it, so at first
// attention cannot tell a token's neighbours from the rest. Rows built from the graph give it that
// locality from step 0:
//
//   A        adjacency of the graph, unweighted (1 per edge: works the same for any layout's units)
//   L        = I − D^{-1/2} A D^{-1/2}, the symmetric normalized Laplacian (isolated nodes: 0 rows)
//   U [N, k] its eigenvectors for the k smallest eigenvalues, each column unit-norm with its
//            largest-magnitude entry positive (a deterministic sign); smooth over the graph, so
//            neighbours get close rows; a two-part sensor's first eigenvectors tell the parts apart
//   P [k, d] N(0, 1) from Rng(seed, "graphpos")
//   E        = U·P, rescaled to RMS `scale` over all entries
//
// E's rows are what graph_positions returns; JepaModel::set_positions writes them into the context
// and target position tables, which then train as before (init only: checkpoints are unchanged).
// Off by default: with rows this informative, the MSE objective can be met from the position alone
// (docs/formats.md, "Notes on some keys"; measured at commit a4abc0b).
// Cost: a dense N×N symmetric eigendecomposition, O(N³): a few ms at N = 368, seconds at N = 2124.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "tjepa/core/detail/vendor.hpp"
#include <Eigen/Eigenvalues>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/graph/taxel_graph.hpp"

namespace tjepa {

struct LaplacianEigenmaps {
  Eigen::MatrixXd vectors;  // [N, k] unit-norm columns
  Eigen::VectorXd values;   // [k] ascending, in [0, 2]
};

// The k eigenvectors of the symmetric normalized Laplacian with the smallest eigenvalues.
inline LaplacianEigenmaps laplacian_eigenmaps(const TaxelGraph& g, int k) {
  const int n = g.num_nodes();
  require<ConfigError>(k >= 1 && k <= n, "laplacian_eigenmaps: k = ", k, ", expected in [1, ", n,
                       "] (the graph has ", n, " nodes)");
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(n, n);
  std::vector<double> inv_sqrt_deg(static_cast<std::size_t>(n), 0.0);
  for (int i = 0; i < n; ++i)
    if (g.degree(i) > 0) inv_sqrt_deg[static_cast<std::size_t>(i)] = 1.0 / std::sqrt(static_cast<double>(g.degree(i)));
  for (int i = 0; i < n; ++i) {
    if (g.degree(i) > 0) L(i, i) = 1.0;
    for (int j : g.neighbors(i))
      L(i, j) = -inv_sqrt_deg[static_cast<std::size_t>(i)] * inv_sqrt_deg[static_cast<std::size_t>(j)];
  }
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(L);
  require<NumericError>(solver.info() == Eigen::Success, "laplacian_eigenmaps: the eigensolver did not converge (",
                        n, " nodes)");
  LaplacianEigenmaps out{solver.eigenvectors().leftCols(k), solver.eigenvalues().head(k)};
  for (int c = 0; c < k; ++c) {
    Eigen::Index at = 0;
    out.vectors.col(c).cwiseAbs().maxCoeff(&at);
    if (out.vectors(at, c) < 0) out.vectors.col(c) *= -1.0;
  }
  return out;
}

// Position rows [N, dim] (row-major) from the graph's k smallest Laplacian eigenvectors, RMS `scale`.
inline std::vector<double> graph_positions(const TaxelGraph& g, int dim, int k, double scale, std::uint64_t seed) {
  require<ConfigError>(dim > 0, "graph_positions: dim = ", dim, ", expected > 0");
  require<ConfigError>(std::isfinite(scale) && scale > 0, "graph_positions: scale = ", scale, ", expected > 0");
  const LaplacianEigenmaps eig = laplacian_eigenmaps(g, k);
  Rng r(seed, 0x6772617068706f73ull);  // "graphpos"
  Eigen::MatrixXd P(k, dim);
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < dim; ++j) P(i, j) = r.normal();
  const Eigen::MatrixXd E = eig.vectors * P;  // [N, dim]
  const double rms = std::sqrt(E.squaredNorm() / static_cast<double>(E.size()));
  require<NumericError>(rms > 0, "graph_positions: all rows are zero (", g.num_nodes(), " nodes, k = ", k, ")");
  std::vector<double> rows(static_cast<std::size_t>(E.size()));
  for (int i = 0; i < E.rows(); ++i)
    for (int j = 0; j < dim; ++j) rows[static_cast<std::size_t>(i) * dim + j] = scale * E(i, j) / rms;
  return rows;
}

}  // namespace tjepa
