#pragma once
// Parameter sets for the optimizer and checkpoint tests.
#include <cstdint>

#include <tjepa/tjepa.hpp>

namespace tjepa_test {

// A small stand-in for a model: names and shapes as the reference encoder has them.
template <class T>
tjepa::ParamSet<T> make_params(std::uint64_t seed, int d = 6) {
  tjepa::ParamSet<T> ps;
  ps.add("pos_embed", {1, 5, d});
  ps.add("blocks.0.norm1.weight", {d});
  ps.add("blocks.0.norm1.bias", {d});
  ps.add("blocks.0.attn.qkv.weight", {3 * d, d});
  ps.add("blocks.0.attn.qkv.bias", {3 * d});
  ps.add("mask_token", {1, 1, d});
  ps.allocate();
  tjepa::Rng rng(seed);
  for (std::size_t i = 0; i < ps.count(); ++i)
    for (auto& v : ps.value_span(ps.id(i))) v = static_cast<T>(rng.normal());
  return ps;
}

template <class T>
void fill_grads(tjepa::ParamSet<T>& ps, std::uint64_t seed, double scale = 1.0) {
  tjepa::Rng rng(seed);
  for (std::size_t i = 0; i < ps.count(); ++i)
    for (auto& g : ps.grad_span(ps.id(i))) g = static_cast<T>(scale * rng.normal());
}

}  // namespace tjepa_test
