#pragma once
// The target encoder's exponential moving average of the context encoder, after every optimizer
// step:  θ̄ ← m·θ̄ + (1 − m)·θ. Both ParamSets have the same layout (the target encoder is built by
// the same code), so the update is one loop over the flat buffers.
#include <cstddef>

#include "tjepa/core/error.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/param_set.hpp"

namespace tjepa {

template <class T>
void ema_update(ParamSet<T>& target, const ParamSet<T>& context, double momentum) {
  require<ConfigError>(momentum >= 0.0 && momentum <= 1.0, "ema_update: momentum = ", momentum,
                       ", expected in [0, 1]");
  require<ShapeError>(target.same_layout(context),
                      "ema_update: target and context ParamSets differ in names, shapes or offsets");
  T* tv = target.values().data();
  const T* cv = context.values().data();
  const T m = static_cast<T>(momentum);
  const T one_minus_m = static_cast<T>(1.0 - momentum);
  const auto n = static_cast<std::ptrdiff_t>(target.flat_size());
  TJEPA_OMP(omp parallel for schedule(static) if (target.flat_size() > detail::parallel_grain))
  for (std::ptrdiff_t i = 0; i < n; ++i) tv[i] = m * tv[i] + one_minus_m * cv[i];
}

}  // namespace tjepa
