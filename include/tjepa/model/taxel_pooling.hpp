#pragma once
// The taxel pooling: a window's N token embeddings → one vector, keeping where on the skin each
// feature sits (the attentive pooling is a function of the set of tokens and sees a taxel's place
// only through what its embedding says about it). Not in the paper; docs/evaluation.md
// ("Why the protocol is set this way") says why it exists. For x [M, N, d]:
//   z = proj(norm(x))          [M, N, d] → [M, N, k]   LayerNorm, then one Linear d → k shared by the taxels
//   p = fc(z as [M, N·k])      [M, d]                  a Linear over all N·k values
// PyTorch names (after the owner's prefix): norm.*, proj.* ([k, d]), fc.* ([d, N·k]).
#include <algorithm>
#include <string>

#include "tjepa/core/error.hpp"
#include "tjepa/model/layers.hpp"
#include "tjepa/model/workspace.hpp"

namespace tjepa {

enum class PoolingKind {
  attentive,  // one learned query cross-attends to the tokens (paper, Sec. IV-B)
  taxel,      // per-taxel projection to k values, then a linear map of all N·k of them
};

inline PoolingKind parse_pooling(const std::string& s) {
  if (s == "attentive") return PoolingKind::attentive;
  if (s == "taxel") return PoolingKind::taxel;
  throw ConfigError("pooling \"" + s + "\", expected attentive or taxel");
}
inline const char* to_string(PoolingKind p) { return p == PoolingKind::taxel ? "taxel" : "attentive"; }

// How a probe pools a window. tokens and components are read by the taxel pooling only.
struct PoolingConfig {
  PoolingKind kind = PoolingKind::attentive;
  int tokens = 0;      // N: the taxel pooling's fc reads N·k values, so it is built for one N
  int components = 3;  // k per taxel
};

template <class T>
struct TaxelPoolCache {
  AlignedVector<T> x, xn, mean, rstd, z;  // [M·N, d], [M·N, d], [M·N], [M·N], [M, N·k]
};

struct TaxelPooling {
  int tokens = 0, components = 0;
  NormParams norm;
  LinearParams proj, fc;

  template <class T>
  static TaxelPooling add(ParamSet<T>& ps, const std::string& prefix, int dim, const PoolingConfig& c, double eps) {
    require<ConfigError>(c.tokens > 0 && c.components > 0, "TaxelPooling: tokens ", c.tokens, ", components ",
                         c.components, ", expected > 0");
    TaxelPooling t;
    t.tokens = c.tokens;
    t.components = c.components;
    t.norm = NormParams::add(ps, prefix + "norm", dim, eps);
    t.proj = LinearParams::add(ps, prefix + "proj", dim, c.components, true);
    t.fc = LinearParams::add(ps, prefix + "fc", c.tokens * c.components, dim, true);
    return t;
  }

  // x [M, N, d] → p [M, d]: inference (scratch from ws).
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int M, int N, T* p, Workspace<T>& ws) const {
    run(ps, x, M, N, p, static_cast<TaxelPoolCache<T>*>(nullptr), ws);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int M, int N, T* p, TaxelPoolCache<T>& cache, Workspace<T>& ws) const {
    run(ps, x, M, N, p, &cache, ws);
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const T* x, int M, int N, T* p, TaxelPoolCache<T>* cache, Workspace<T>& ws) const {
    require<ShapeError>(N == tokens, "TaxelPooling::forward: windows of ", N, " tokens, the pooling was built for ",
                        tokens);
    const std::size_t rows = std::size_t(M) * N, d = std::size_t(norm.dim);
    if (cache) cache->x.assign(x, x + rows * d);
    T* xn = detail::grow(cache ? cache->xn : ws.ln, rows * d);
    norm.forward(ps, x, xn, cache ? detail::grow(cache->mean, rows) : nullptr,
                 cache ? detail::grow(cache->rstd, rows) : nullptr, int(rows));
    T* z = detail::grow(cache ? cache->z : ws.qkv, rows * components);
    proj.forward(ps, xn, z, int(rows));
    fc.forward(ps, z, p, M);
  }


 public:
  // dp [M, d] → parameter gradients and dx [M, N, d] += (may be nullptr), for the last forward of c.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dp, T* dx, int M, const TaxelPoolCache<T>& c, Workspace<T>& ws) const {
    const std::size_t rows = std::size_t(M) * tokens, d = std::size_t(norm.dim);
    T* dz = detail::grow(ws.dqkv, rows * components);
    std::fill(dz, dz + rows * components, T(0));
    fc.backward(ps, dp, c.z.data(), dz, M);
    T* dxn = detail::grow(ws.dbranch, rows * d);
    std::fill(dxn, dxn + rows * d, T(0));
    proj.backward(ps, dz, c.xn.data(), dxn, int(rows));
    norm.backward(ps, dxn, c.x.data(), c.mean.data(), c.rstd.data(), dx, int(rows));
  }
};

}  // namespace tjepa
