#pragma once
// Initialization of a ParamSet as in the reference implementation (E-Kovtun/tactile,
// tactile_ssl/model/signal_transformer.py: timm's init_weights_vit_timm, which its
// SignalTransformer applies): Linear weights ~ N(0, 0.02²) truncated at ±2
// (absolute bounds, as torch.nn.init.trunc_normal_), biases 0, LayerNorm (1, 0), position table
// N(0, 0.02²) (trunc_normal_ with the same bounds), predictor mask token 0. The reference does
// NOT rescale proj / fc2 by depth (I-JEPA's fix_init_weight is not in its SignalTransformer), so
// neither do we. Tensor i draws from Rng(seed, i): the same seed gives the same parameters, and
// adding a tensor at the end changes no other.
#include <algorithm>
#include <cstdint>

#include "tjepa/core/random.hpp"
#include "tjepa/core/param_set.hpp"

namespace tjepa {

inline constexpr double init_std = 0.02;
inline constexpr double init_bound = 2.0;

template <class T>
void init_params(ParamSet<T>& ps, std::uint64_t seed) {
  require<ConfigError>(ps.allocated(), "init_params: the ParamSet is not allocated");
  for (std::size_t i = 0; i < ps.count(); ++i) {
    const ParamInfo& info = ps.infos()[i];
    auto v = ps.value_span(ps.id(i));
    switch (info.init) {
      case ParamInit::zeros: std::fill(v.begin(), v.end(), T(0)); break;
      case ParamInit::ones: std::fill(v.begin(), v.end(), T(1)); break;
      case ParamInit::trunc_normal: {
        Rng rng(seed, i);
        for (auto& x : v) x = T(rng.truncated_normal(0.0, init_std, -init_bound, init_bound));
        break;
      }
      case ParamInit::uniform: {
        Rng rng(seed, i);
        for (auto& x : v) x = T(rng.uniform(-info.bound, info.bound));
        break;
      }
    }
  }
}

}  // namespace tjepa
