#pragma once
// Gradient-norm clipping over the trainable parts of a model (PyTorch's clip_grad_norm_ with the
// 2-norm): the norm is taken over all gradients together, and when it exceeds max_norm every
// gradient is scaled by max_norm / (norm + 1e-6). The reference clips at 10.
//
// The norm is summed in double in fixed-size chunks (detail::deterministic_sum_squares), so it is
// bitwise the same for any thread count (padding between tensors holds zero gradients and adds nothing).
#include <cmath>
#include <cstddef>
#include <initializer_list>
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/optim/detail/deterministic_sum.hpp"
#include "tjepa/core/param_set.hpp"
#include "tjepa/core/prefixed_params.hpp"

namespace tjepa {

// Sum of squared gradients of one ParamSet, in double.
template <class T>
double grad_sum_squares(const ParamSet<T>& params) {
  return detail::deterministic_sum_squares(params.grads().data(), params.flat_size());
}

// The 2-norm of all gradients of all parts.
template <class T>
double grad_norm(std::span<const PrefixedParams<T>> parts) {
  double s = 0.0;
  for (const auto& part : parts) s += grad_sum_squares(*part.params);
  return std::sqrt(s);
}

// Multiplies every gradient by `factor`.
template <class T>
void scale_grads(ParamSet<T>& params, T factor) {
  T* g = params.grads().data();
  detail::parallel_split(params.flat_size(),
                         [&](std::size_t b, std::size_t e) { detail::simd_scale(factor, g + b, g + b, e - b); });
}

// Clips the joint gradient norm of `parts` to max_norm; returns the norm before clipping (what
// the reference logs as grad_norm). A non-finite norm leaves the gradients as they are: the
// caller decides (the JEPA step stops with NumericError).
template <class T>
double clip_grad_norm(std::span<const PrefixedParams<T>> parts, double max_norm) {
  require<ConfigError>(max_norm > 0.0, "clip_grad_norm: max_norm = ", max_norm, ", expected > 0");
  const double norm = grad_norm(parts);
  if (!std::isfinite(norm)) return norm;
  const double coef = max_norm / (norm + 1e-6);
  if (coef < 1.0)
    for (const auto& part : parts) scale_grads(*part.params, static_cast<T>(coef));
  return norm;
}

template <class T>
double clip_grad_norm(ParamSet<T>& params, double max_norm) {
  const PrefixedParams<T> part{"", &params};
  return clip_grad_norm(std::span<const PrefixedParams<T>>(&part, 1), max_norm);
}

}  // namespace tjepa
