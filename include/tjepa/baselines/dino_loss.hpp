#pragma once
// DINO's losses (Caron et al. 2021; DINOv2 and iBOT as the Tactile-JEPA reference code uses them
// for its DINO baseline), each with its gradient.
//
// Teacher targets: pₜ = softmax((t − c) / τₜ) over the P prototypes, c the center.
// Cross-entropy of a student row s against a teacher row pₜ:
//   ℓ(s, pₜ) = −Σₖ pₜₖ log softmax(s / τₛ)ₖ,   ∂ℓ/∂s = (softmax(s / τₛ) − pₜ) / τₛ
// (The center c follows the teacher's rows: c ← m c + (1 − m) mean, after each step; dino_update.)
// KoLeo (Sablayrolles et al. 2019; DINOv2's regularizer on the class tokens): the rows
// x̂ᵢ = xᵢ / max(‖xᵢ‖, 1e-8) of one view, nᵢ = argmax_{j≠i} x̂ᵢ·x̂ⱼ,
//   L = −mean_i log(‖x̂ᵢ − x̂ₙᵢ‖ + 1e-8)
// with the nearest neighbours held fixed for the gradient (as autograd does).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

// probs [M, P] = softmax((logits − center) / temperature) per row.
template <class T>
void dino_teacher_probs(T* probs, const T* logits, const T* center, int M, int P, double temperature) {
  const T inv = T(1.0 / temperature);
  for (int m = 0; m < M; ++m) {
    const T* l = logits + std::size_t(m) * P;
    T* p = probs + std::size_t(m) * P;
    T mx = -std::numeric_limits<T>::infinity();
    for (int k = 0; k < P; ++k) mx = std::max(mx, (l[k] - center[k]) * inv);
    T s = 0;
    for (int k = 0; k < P; ++k) s += (p[k] = std::exp((l[k] - center[k]) * inv - mx));
    for (int k = 0; k < P; ++k) p[k] /= s;
  }
}

// Σ over the M rows of ℓ(student, teacher) at student temperature τₛ; dstudent [M, P] +=
// scale · ∂/∂student (may be nullptr).
template <class T>
double dino_cross_entropy(const T* student, const T* teacher, int M, int P, double student_temperature, T* dstudent,
                          double scale) {
  const double inv = 1.0 / student_temperature;
  double total = 0;
  std::vector<double> q(static_cast<std::size_t>(P));
  for (int m = 0; m < M; ++m) {
    const T* s = student + std::size_t(m) * P;
    const T* t = teacher + std::size_t(m) * P;
    double mx = -std::numeric_limits<double>::infinity();
    for (int k = 0; k < P; ++k) mx = std::max(mx, double(s[k]) * inv);
    double z = 0;
    for (int k = 0; k < P; ++k) z += (q[std::size_t(k)] = std::exp(double(s[k]) * inv - mx));
    const double logz = std::log(z) + mx;
    for (int k = 0; k < P; ++k) total -= double(t[k]) * (double(s[k]) * inv - logz);
    if (dstudent) {
      T* ds = dstudent + std::size_t(m) * P;
      for (int k = 0; k < P; ++k) ds[k] += T(scale * inv * (q[std::size_t(k)] / z - double(t[k])));
    }
  }
  return total;
}

inline constexpr double koleo_eps = 1e-8;

// KoLeo over the M rows of x [M, D] (M ≥ 2); dx [M, D] += scale · ∂L/∂x (may be nullptr).
template <class T>
double koleo_loss(const T* x, int M, int D, T* dx, double scale) {
  require<ShapeError>(M >= 2 && D > 0, "koleo_loss: M = ", M, ", D = ", D, ", expected M >= 2 rows of D > 0");
  std::vector<double> xh(std::size_t(M) * D), norm(static_cast<std::size_t>(M));
  for (int i = 0; i < M; ++i) {
    double s = 0;
    for (int j = 0; j < D; ++j) s += double(x[std::size_t(i) * D + j]) * double(x[std::size_t(i) * D + j]);
    norm[std::size_t(i)] = std::max(std::sqrt(s), koleo_eps);
    for (int j = 0; j < D; ++j) xh[std::size_t(i) * D + j] = double(x[std::size_t(i) * D + j]) / norm[std::size_t(i)];
  }
  std::vector<double> dxh(dx ? xh.size() : 0, 0.0);
  double loss = 0;
  for (int i = 0; i < M; ++i) {
    int nn = -1;
    double best = -std::numeric_limits<double>::infinity();
    for (int k = 0; k < M; ++k) {
      if (k == i) continue;
      double dot = 0;
      for (int j = 0; j < D; ++j) dot += xh[std::size_t(i) * D + j] * xh[std::size_t(k) * D + j];
      if (dot > best) best = dot, nn = k;
    }
    double dist2 = 0;
    for (int j = 0; j < D; ++j) {
      const double e = xh[std::size_t(i) * D + j] - xh[std::size_t(nn) * D + j];
      dist2 += e * e;
    }
    const double dist = std::sqrt(dist2);
    loss -= std::log(dist + koleo_eps) / M;
    if (dx && dist > 0) {
      const double g = -1.0 / (M * (dist + koleo_eps) * dist);  // ∂/∂e of −log(‖e‖ + eps)/M, times e
      for (int j = 0; j < D; ++j) {
        const double e = xh[std::size_t(i) * D + j] - xh[std::size_t(nn) * D + j];
        dxh[std::size_t(i) * D + j] += g * e;
        dxh[std::size_t(nn) * D + j] -= g * e;
      }
    }
  }
  if (dx)
    for (int i = 0; i < M; ++i) {
      double dot = 0;
      for (int j = 0; j < D; ++j) dot += xh[std::size_t(i) * D + j] * dxh[std::size_t(i) * D + j];
      const bool clamped = norm[std::size_t(i)] <= koleo_eps;
      for (int j = 0; j < D; ++j) {
        const double g = (dxh[std::size_t(i) * D + j] - (clamped ? 0.0 : xh[std::size_t(i) * D + j] * dot)) /
                         norm[std::size_t(i)];
        dx[std::size_t(i) * D + j] += T(scale * g);
      }
    }
  return loss;
}

}  // namespace tjepa
