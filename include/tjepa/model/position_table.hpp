#pragma once
// PositionTable: a learned row e_i ∈ R^d per token, PyTorch `pos_embed` [1, N, d], added to the
// tokens before masking (paper, Sec. III-B). Rows are read by token index, so the context encoder
// adds the rows of its context tokens and the predictor reads the rows of its targets.
#include <string>

#include "tjepa/kernels/gather.hpp"
#include "tjepa/core/param_set.hpp"

namespace tjepa {

struct PositionTable {
  ParamId table;
  int rows = 0, dim = 0;

  template <class T>
  static PositionTable add(ParamSet<T>& ps, const std::string& name, int rows, int dim) {
    PositionTable p;
    p.rows = rows;
    p.dim = dim;
    p.table = ps.add(name, {1, rows, dim}, ParamInit::trunc_normal);
    return p;
  }

  // x[b, k, :] += e[idx[b, k]] for x [B, K, d]; idx == nullptr means idx[b, k] = k (K = rows).
  template <class T>
  void forward(const ParamSet<T>& ps, T* x, const int* idx, int B, int K) const {
    if (idx) {
      kernels::gather_add_rows(x, ps.value(table), 0, idx, B, K, dim);
      return;
    }
    const std::size_t n = std::size_t(rows) * dim;
    const T* e = ps.value(table);
    for (int b = 0; b < B; ++b)
      for (std::size_t i = 0; i < n; ++i) x[b * n + i] += e[i];
  }
  // Differentiates forward: grad e[idx[b, k]] += dx[b, k, :].
  template <class T>
  void backward(ParamSet<T>& ps, const T* dx, const int* idx, int B, int K) const {
    if (idx) {
      kernels::scatter_add_rows(ps.grad(table), 0, dx, idx, B, K, dim);
      return;
    }
    const std::size_t n = std::size_t(rows) * dim;
    T* g = ps.grad(table);
    for (int b = 0; b < B; ++b)
      for (std::size_t i = 0; i < n; ++i) g[i] += dx[b * n + i];
  }
};

// Throws ShapeError unless every idx[i] lies in [0, n).
inline void check_indices(const int* idx, std::size_t count, int n, const char* where, const char* name) {
  for (std::size_t i = 0; i < count; ++i)
    require<ShapeError>(idx[i] >= 0 && idx[i] < n, where, ": ", name, "[", i, "] = ", idx[i], ", expected [0, ", n,
                        ")");
}

}  // namespace tjepa
