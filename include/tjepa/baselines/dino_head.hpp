#pragma once
// DinoHead: DINO's projection head (Caron et al. 2021; DINOv2's DINOHead, which Sparsh-skin and
// the Tactile-JEPA reference code use for their DINO baseline): an MLP to a bottleneck, an L2
// normalization, and a weight-normalized linear layer onto the prototypes.
//
//   a₀ = x W₀ᵀ + b₀,  h₀ = gelu(a₀)                  x [M, in] → [M, hidden]
//   a₁ = h₀ W₁ᵀ + b₁, h₁ = gelu(a₁)                  [M, hidden]
//   z  = h₁ W₂ᵀ + b₂                                  [M, bottleneck]
//   ẑ  = z / max(‖z‖, eps)                            each row (F.normalize, eps 1e-12)
//   V̂ₖ = Vₖ / ‖Vₖ‖                                     each prototype row (weight_norm with g = 1)
//   out = ẑ V̂ᵀ                                         [M, prototypes], no bias
//
// The reference keeps weight_norm's gain g fixed at 1 (norm_last_layer), so the prototypes are
// the direction of V alone; only V (last_layer.weight_v) is a parameter here.
//
// PyTorch names (DINOHead, prefix "" by default): mlp.0.{weight [hidden, in], bias},
// mlp.2.{weight [hidden, hidden], bias}, mlp.4.{weight [bottleneck, hidden], bias},
// last_layer.weight_v [prototypes, bottleneck] (weight_g [prototypes, 1] is all ones there).
// The reference sizes are hidden 2048, bottleneck 256, prototypes 65536.
#include <algorithm>
#include <cmath>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/kernels/gelu.hpp"
#include "tjepa/model/layers.hpp"

namespace tjepa {

struct DinoHeadConfig {
  int in_dim = 192;
  int hidden = 2048;
  int bottleneck = 256;
  int prototypes = 65536;
  double eps = 1e-12;  // of the bottleneck's L2 normalization

  void validate() const {
    require<ConfigError>(in_dim > 0 && hidden > 0 && bottleneck > 0 && prototypes > 0, "DinoHead: in_dim ", in_dim,
                         ", hidden ", hidden, ", bottleneck ", bottleneck, ", prototypes ", prototypes,
                         ", expected all > 0");
  }
};

template <class T>
struct DinoHeadCache {
  int M = 0;
  AlignedVector<T> a0, h0, a1, h1;  // [M, hidden]
  AlignedVector<T> z, zhat;         // [M, bottleneck]
  AlignedVector<T> znorm;           // [M] max(‖z‖, eps)
  AlignedVector<T> vhat, vnorm;     // [P, bottleneck] the normalized prototypes, [P] ‖Vₖ‖
  AlignedVector<T> dh, dz, dv;      // backward scratch
};

struct DinoHead {
  DinoHeadConfig config;
  LinearParams fc0, fc1, fc2;
  ParamId weight_v;

  DinoHead() = default;
  template <class T>
  DinoHead(ParamSet<T>& ps, const DinoHeadConfig& c, const std::string& prefix = "") : config(c) {
    c.validate();
    fc0 = LinearParams::add(ps, prefix + "mlp.0", c.in_dim, c.hidden, true);
    fc1 = LinearParams::add(ps, prefix + "mlp.2", c.hidden, c.hidden, true);
    fc2 = LinearParams::add(ps, prefix + "mlp.4", c.hidden, c.bottleneck, true);
    weight_v = ps.add(prefix + "last_layer.weight_v", {c.prototypes, c.bottleneck}, ParamInit::trunc_normal);
  }

  // x [M, in] → out [M, prototypes]; the cache keeps what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int M, T* out, std::type_identity_t<DinoHeadCache<T>>& c) const {
    check_params(ps, weight_v, "DinoHead::forward");
    require<ShapeError>(M > 0 && x && out, "DinoHead::forward: M = ", M, ", expected > 0 rows and non-null x, out");
    const int H = config.hidden, Z = config.bottleneck, P = config.prototypes;
    const std::size_t MH = std::size_t(M) * H, MZ = std::size_t(M) * Z;
    c.M = M;
    T* a0 = detail::grow(c.a0, MH);
    T* h0 = detail::grow(c.h0, MH);
    T* a1 = detail::grow(c.a1, MH);
    T* h1 = detail::grow(c.h1, MH);
    T* z = detail::grow(c.z, MZ);
    T* zhat = detail::grow(c.zhat, MZ);
    T* zn = detail::grow(c.znorm, std::size_t(M));
    fc0.forward(ps, x, a0, M);
    kernels::gelu_forward(h0, a0, MH);
    fc1.forward(ps, h0, a1, M);
    kernels::gelu_forward(h1, a1, MH);
    fc2.forward(ps, h1, z, M);
    normalize_rows(z, zhat, zn, M, Z, T(config.eps));
    T* vhat = detail::grow(c.vhat, std::size_t(P) * Z);
    T* vn = detail::grow(c.vnorm, std::size_t(P));
    normalize_rows(ps.value(weight_v), vhat, vn, P, Z, T(0));
    kernels::linear_forward(out, zhat, vhat, static_cast<const T*>(nullptr), M, Z, P, kernels::WeightPlan{});
  }

  // dout [M, prototypes] → parameter gradients (added) and dx [M, in] += (may be nullptr).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, const T* x, std::type_identity_t<T>* dx, DinoHeadCache<T>& c) const {
    check_params(ps, weight_v, "DinoHead::backward");
    require<ConfigError>(c.M > 0, "DinoHead::backward: the cache holds no forward pass");
    const int M = c.M, H = config.hidden, Z = config.bottleneck, P = config.prototypes;
    const std::size_t MH = std::size_t(M) * H, MZ = std::size_t(M) * Z;
    // out = ẑ V̂ᵀ: dẑ = dout V̂, dV̂ = doutᵀ ẑ.
    T* dzhat = detail::grow(c.dz, MZ);
    std::fill(dzhat, dzhat + MZ, T(0));
    T* dvhat = detail::grow(c.dv, std::size_t(P) * Z);
    std::fill(dvhat, dvhat + std::size_t(P) * Z, T(0));
    kernels::linear_backward(dzhat, dvhat, static_cast<T*>(nullptr), dout, c.zhat.data(), c.vhat.data(), M, Z, P,
                             true, Precision::fp32);
    normalize_rows_backward(dvhat, c.vhat.data(), c.vnorm.data(), ps.grad(weight_v), P, Z, T(0), true);
    // ẑ = z / max(‖z‖, eps): dz (in place of dẑ).
    T* dz = detail::grow(c.z, MZ);  // z itself is no longer needed: reuse its storage for dz
    normalize_rows_backward(dzhat, c.zhat.data(), c.znorm.data(), dz, M, Z, T(config.eps), false);
    T* dh = detail::grow(c.dh, MH);
    std::fill(dh, dh + MH, T(0));
    fc2.backward(ps, dz, c.h1.data(), dh, M);
    T* da = c.h1.data();  // h₁ is no longer needed: its storage takes ∂a₁
    std::fill(da, da + MH, T(0));
    kernels::gelu_backward(da, dh, c.a1.data(), MH);
    std::fill(dh, dh + MH, T(0));
    fc1.backward(ps, da, c.h0.data(), dh, M);
    da = c.h0.data();
    std::fill(da, da + MH, T(0));
    kernels::gelu_backward(da, dh, c.a0.data(), MH);
    fc0.backward(ps, da, x, dx, M);
    c.M = 0;  // the cache's buffers were reused: one backward per forward
  }

 private:
  // y = x / max(‖x‖, eps) per row of [R, C]; norm[r] = max(‖x_r‖, eps).
  template <class T>
  static void normalize_rows(const T* x, T* y, T* norm, int R, int C, T eps) {
    for (int r = 0; r < R; ++r) {
      const T* xr = x + std::size_t(r) * C;
      T s = 0;
      for (int j = 0; j < C; ++j) s += xr[j] * xr[j];
      const T n = std::max(std::sqrt(s), eps);
      norm[r] = n;
      T* yr = y + std::size_t(r) * C;
      for (int j = 0; j < C; ++j) yr[j] = xr[j] / n;
    }
  }
  // dx (= or +=) of y = x / max(‖x‖, eps): (dy − y (y·dy)) / ‖x‖ where ‖x‖ > eps, else dy / eps.
  template <class T>
  static void normalize_rows_backward(const T* dy, const T* y, const T* norm, T* dx, int R, int C, T eps,
                                      bool accumulate) {
    for (int r = 0; r < R; ++r) {
      const T* dyr = dy + std::size_t(r) * C;
      const T* yr = y + std::size_t(r) * C;
      T* dxr = dx + std::size_t(r) * C;
      const bool clamped = norm[r] <= eps;
      T dot = 0;
      if (!clamped)
        for (int j = 0; j < C; ++j) dot += yr[j] * dyr[j];
      for (int j = 0; j < C; ++j) {
        const T g = (dyr[j] - yr[j] * dot) / norm[r];
        dxr[j] = accumulate ? dxr[j] + g : g;
      }
    }
  }
};

}  // namespace tjepa
