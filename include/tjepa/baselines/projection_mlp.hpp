#pragma once
// ProjectionMlp: BYOL's projector and predictor (Grill et al. 2020; the reference code's MLP in
// tactile_ssl/algorithm/byol.py): Linear, BatchNorm1d, ReLU, Linear.
//
//   a  = x W₀ᵀ + b₀                                   x [M, in] → [M, hidden]
//   â  = (a − μ) / √(σ² + eps)                        μ, σ² over the M rows (biased), per column
//   h  = relu(γ ⊙ â + β)
//   out = h W₁ᵀ + b₁                                  [M, out]
//
// BatchNorm runs in training mode: the statistics are the batch's, as BYOL uses its online and
// target networks (both in train mode in the reference). So the rows of a batch interact and a
// forward needs M >= 2. Running statistics (PyTorch's running_mean / running_var buffers) are not
// kept: nothing here evaluates a projector in eval mode (the downstream reads the encoder).
//
// PyTorch names (prefix "" by default): net.0.{weight [hidden, in], bias}, net.1.{weight, bias}
// [hidden] (BatchNorm's γ, β), net.3.{weight [out, hidden], bias}. Linear layers start as
// PyTorch's default, U(±1/√fan_in) for weight and bias; γ = 1, β = 0.
#include <algorithm>
#include <cmath>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/layers.hpp"

namespace tjepa {

struct ProjectionMlpConfig {
  int in_dim = 9216;
  int hidden = 4096;
  int out_dim = 256;
  double eps = 1e-5;  // BatchNorm1d's

  void validate() const {
    require<ConfigError>(in_dim > 0 && hidden > 0 && out_dim > 0 && eps > 0, "ProjectionMlp: in_dim ", in_dim,
                         ", hidden ", hidden, ", out_dim ", out_dim, ", eps ", eps, ", expected all > 0");
  }
};

template <class T>
struct ProjectionMlpCache {
  int M = 0;
  AlignedVector<T> xhat, h;   // [M, hidden] â and relu(γ â + β)
  AlignedVector<T> rstd;      // [hidden] 1 / √(σ² + eps)
  AlignedVector<T> dh;        // backward scratch
  std::vector<double> s0, s1; // [hidden] column sums (statistics, in double)
};

// A Linear layer registered with PyTorch's default initialization.
template <class T>
LinearParams torch_default_linear(ParamSet<T>& ps, const std::string& name, int in, int out) {
  LinearParams p;
  p.in = in, p.out = out, p.has_bias = true;
  const double bound = 1.0 / std::sqrt(double(in));
  p.weight = ps.add(name + ".weight", {out, in}, ParamInit::uniform, bound);
  p.bias = ps.add(name + ".bias", {out}, ParamInit::uniform, bound);
  return p;
}

struct ProjectionMlp {
  ProjectionMlpConfig config;
  LinearParams fc0, fc1;
  ParamId gamma, beta;

  ProjectionMlp() = default;
  template <class T>
  ProjectionMlp(ParamSet<T>& ps, const ProjectionMlpConfig& c, const std::string& prefix = "") : config(c) {
    c.validate();
    fc0 = torch_default_linear(ps, prefix + "net.0", c.in_dim, c.hidden);
    gamma = ps.add(prefix + "net.1.weight", {c.hidden}, ParamInit::ones);
    beta = ps.add(prefix + "net.1.bias", {c.hidden}, ParamInit::zeros);
    fc1 = torch_default_linear(ps, prefix + "net.3", c.hidden, c.out_dim);
  }

  // x [M, in] → out [M, out] with the batch's statistics; the cache keeps what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int M, T* out, std::type_identity_t<ProjectionMlpCache<T>>& c) const {
    check_params(ps, beta, "ProjectionMlp::forward");
    require<ShapeError>(M >= 2 && x && out, "ProjectionMlp::forward: M = ", M,
                        ", expected >= 2 rows (BatchNorm's batch statistics) and non-null x, out");
    const int H = config.hidden;
    const std::size_t MH = std::size_t(M) * H;
    c.M = M;
    T* a = detail::grow(c.xhat, MH);
    T* h = detail::grow(c.h, MH);
    T* rstd = detail::grow(c.rstd, std::size_t(H));
    fc0.forward(ps, x, a, M);
    // Column statistics in double, row by row (contiguous reads).
    std::vector<double>&mean = c.s0, &var = c.s1;
    mean.assign(std::size_t(H), 0.0), var.assign(std::size_t(H), 0.0);
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < H; ++j) mean[std::size_t(j)] += double(a[std::size_t(i) * H + j]);
    for (double& m : mean) m /= M;
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < H; ++j) {
        const double d = double(a[std::size_t(i) * H + j]) - mean[std::size_t(j)];
        var[std::size_t(j)] += d * d;
      }
    for (int j = 0; j < H; ++j) rstd[j] = T(1.0 / std::sqrt(var[std::size_t(j)] / M + config.eps));
    const T* g = ps.value(gamma);
    const T* bt = ps.value(beta);
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < H; ++j) {
        const std::size_t k = std::size_t(i) * H + j;
        a[k] = T((double(a[k]) - mean[std::size_t(j)]) * double(rstd[j]));
        h[k] = std::max(T(0), g[j] * a[k] + bt[j]);
      }
    fc1.forward(ps, h, out, M);
  }

  // dout [M, out] → parameter gradients (added) and dx [M, in] += (may be nullptr).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, const T* x, std::type_identity_t<T>* dx, ProjectionMlpCache<T>& c) const {
    check_params(ps, beta, "ProjectionMlp::backward");
    require<ConfigError>(c.M > 0, "ProjectionMlp::backward: the cache holds no forward pass");
    const int M = c.M, H = config.hidden;
    const std::size_t MH = std::size_t(M) * H;
    T* dh = detail::grow(c.dh, MH);
    std::fill(dh, dh + MH, T(0));
    fc1.backward(ps, dout, c.h.data(), dh, M);
    // Through the ReLU and the affine: dy = dh where h > 0; dγ += Σ dy â; dβ += Σ dy; dâ = γ dy.
    const T* g = ps.value(gamma);
    T* dg = ps.grad(gamma);
    T* db = ps.grad(beta);
    const T* xhat = c.xhat.data();
    std::vector<double>&sum_d = c.s0, &sum_dx = c.s1;
    sum_d.assign(std::size_t(H), 0.0), sum_dx.assign(std::size_t(H), 0.0);
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < H; ++j) {
        const std::size_t k = std::size_t(i) * H + j;
        const T dy = c.h[k] > T(0) ? dh[k] : T(0);
        dg[j] += dy * xhat[k];
        db[j] += dy;
        dh[k] = g[j] * dy;  // dâ
        sum_d[std::size_t(j)] += double(dh[k]);
        sum_dx[std::size_t(j)] += double(dh[k]) * double(xhat[k]);
      }
    // da = rstd / M · (M dâ − Σ dâ − â Σ(dâ â)), in place of dâ.
    for (int i = 0; i < M; ++i)
      for (int j = 0; j < H; ++j) {
        const std::size_t k = std::size_t(i) * H + j;
        dh[k] = T(double(c.rstd[std::size_t(j)]) / M *
                  (M * double(dh[k]) - sum_d[std::size_t(j)] - double(xhat[k]) * sum_dx[std::size_t(j)]));
      }
    fc0.backward(ps, dh, x, dx, M);
    c.M = 0;
  }
};

}  // namespace tjepa
