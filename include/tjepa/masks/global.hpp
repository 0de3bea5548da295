#pragma once
// Global masks: t tokens scattered over a domain.
//   stratified (default): one uniform token from each group (pad/region) of the domain, then
//     uniform tokens from the rest until t. When t is smaller than the number of groups G, t
//     distinct groups are chosen uniformly and each gives one token: the mask still spreads over
//     t different pads, the most coverage t tokens allow.
//   uniform: t distinct tokens uniform over the domain.
#include <numeric>
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/masks/config.hpp"
#include "tjepa/masks/workspace.hpp"
#include "tjepa/masks/domain.hpp"

namespace tjepa {

namespace detail {
inline std::uint64_t below(Rng& rng, int n) { return rng.below(static_cast<std::uint64_t>(n)); }

// Fills out[k..) with distinct uniform tokens of d not yet in ws.picked (and marks them).
inline void fill_uniform(const MaskDomain& d, int k, Rng& rng, MaskWorkspace& ws, std::span<int> out) {
  const int t = static_cast<int>(out.size());
  const int n = d.size();
  if (2 * t <= n) {
    // Rejection: at most half the domain is taken, so each draw succeeds with probability >= 1/2.
    while (k < t) {
      const int v = d.token(static_cast<int>(below(rng, n)));
      if (ws.picked.insert(v)) out[k++] = v;
    }
    return;
  }
  // Dense: partial Fisher–Yates over the tokens not picked yet.
  int m = 0;
  for (int v : d.tokens())
    if (!ws.picked.test(v)) ws.perm[m++] = v;
  for (int j = 0; k < t; ++j) {
    std::swap(ws.perm[j], ws.perm[j + static_cast<int>(below(rng, m - j))]);
    ws.picked.set(ws.perm[j]);
    out[k++] = ws.perm[j];
  }
}
}  // namespace detail

// A global mask of out.size() = t distinct tokens of d, written to out (unsorted).
// ws must be resized to the graph's number of tokens.
inline void sample_global_mask(const MaskDomain& d, GlobalSampling mode, Rng& rng, MaskWorkspace& ws,
                               std::span<int> out) {
  const int t = static_cast<int>(out.size());
  require<ConfigError>(t >= 1 && t <= d.size(), "sample_global_mask: t = ", t,
                       ", expected 1 <= t <= ", d.size(), " (tokens of part ", d.part(), ")");
  ws.picked.clear();
  int k = 0;
  if (mode == GlobalSampling::stratified) {
    const int groups = d.num_groups();
    if (t >= groups) {
      for (int gr = 0; gr < groups; ++gr) {
        const auto members = d.group_tokens(gr);
        const int v = members[detail::below(rng, static_cast<int>(members.size()))];
        ws.picked.set(v);
        out[k++] = v;
      }
    } else {
      ws.order.resize(groups);
      std::iota(ws.order.begin(), ws.order.end(), 0);
      for (int j = 0; j < t; ++j) {
        std::swap(ws.order[j], ws.order[j + static_cast<int>(detail::below(rng, groups - j))]);
        const auto members = d.group_tokens(ws.order[j]);
        const int v = members[detail::below(rng, static_cast<int>(members.size()))];
        ws.picked.set(v);
        out[k++] = v;
      }
    }
  }
  detail::fill_uniform(d, k, rng, ws, out);
}

}  // namespace tjepa
