#pragma once
// Drop-path (stochastic depth, timm's drop_path with scale_by_keep): a residual branch is kept or
// dropped for a whole sample, x[b] += scale[b] · branch[b], with scale[b] = keep ? 1/(1 - p) : 0.
// Each sample draws from its own Rng stream, so results do not depend on the thread count, and
// backward reuses the stored scales. Rate 0 never reaches these functions: the blocks then fuse
// the residual add into the GEMM.
#include <cstddef>
#include <cstdint>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/core/detail/parallel.hpp"

namespace tjepa::kernels {

// scale[site, b] for `sites` residual branches (2 per block) of B samples. Sample b draws one
// uniform per site, in site order, from its own stream Rng(seed, first_sample + b): a shard of a
// batch (first_sample its offset) draws what the same samples draw in the whole batch.
template <class T>
void drop_path_sample(T* scale, int sites, int B, double rate, std::uint64_t seed, std::uint64_t first_sample = 0) {
  require<ConfigError>(rate >= 0.0 && rate < 1.0, "drop_path_sample: rate ", rate, ", expected [0, 1)");
  const double keep = 1.0 - rate;
  for (int b = 0; b < B; ++b) {
    Rng rng(seed, first_sample + std::uint64_t(b));
    for (int s = 0; s < sites; ++s) scale[std::size_t(s) * B + b] = rng.uniform() < keep ? T(1.0 / keep) : T(0);
  }
}

namespace ref {
template <class T>
void drop_path_forward(T* x, const T* branch, const T* scale, int B, std::size_t per_sample) {
  for (int b = 0; b < B; ++b)
    for (std::size_t i = 0; i < per_sample; ++i) x[b * per_sample + i] += scale[b] * branch[b * per_sample + i];
}
template <class T>
void drop_path_backward(T* dbranch, const T* dx, const T* scale, int B, std::size_t per_sample) {
  for (int b = 0; b < B; ++b)
    for (std::size_t i = 0; i < per_sample; ++i) dbranch[b * per_sample + i] += scale[b] * dx[b * per_sample + i];
}
}  // namespace ref

// x[B, per_sample] += scale[b] · branch[B, per_sample]
template <class T>
void drop_path_forward(T* x, const T* branch, const T* scale, int B, std::size_t per_sample) {
  TJEPA_OMP(omp parallel for schedule(static) if (B > 1 && B * per_sample > detail::parallel_grain))
  for (int b = 0; b < B; ++b) {
    if (scale[b] == T(0)) continue;
    T* xb = x + std::size_t(b) * per_sample;
    const T* yb = branch + std::size_t(b) * per_sample;
    const T s = scale[b];
    detail::simd_axpy(s, yb, xb, per_sample);
  }
}

// Differentiates x += scale[b] · branch: dbranch[b] += scale[b] · dx[b].
template <class T>
void drop_path_backward(T* dbranch, const T* dx, const T* scale, int B, std::size_t per_sample) {
  TJEPA_OMP(omp parallel for schedule(static) if (B > 1 && B * per_sample > detail::parallel_grain))
  for (int b = 0; b < B; ++b) {
    if (scale[b] == T(0)) continue;
    T* gb = dbranch + std::size_t(b) * per_sample;
    const T* xb = dx + std::size_t(b) * per_sample;
    const T s = scale[b];
    for (std::size_t i = 0; i < per_sample; ++i) gb[i] += s * xb[i];
  }
}

}  // namespace tjepa::kernels
