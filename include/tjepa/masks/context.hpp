#pragma once
// The context: c tokens drawn before the targets' union (ws.excluded) is removed.
//   uniform (default): c uniform random tokens of the N.
//   local (the paper's † ablation): a connected Dijkstra region. On a sensor in several parts the
//     budget is split in proportion to the parts' sizes, c_p = round(c·(n_0+..+n_p)/N) -
//     round(c·(n_0+..+n_{p-1})/N), and each part grows its own region (one region cannot span
//     two unconnected parts), as the reference's two-hand connected context does.
// Both write the kept tokens to out in a uniformly random order, so that cutting a batch's
// contexts to a common length (keeping a prefix) keeps a random subset.
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/masks/workspace.hpp"
#include "tjepa/masks/domain.hpp"
#include "tjepa/masks/local.hpp"

namespace tjepa {

namespace detail {
// Part p's share of a local context of c tokens, given the parts' cumulative sizes before and
// through p: round(c·through/N) − round(c·before/N), so that the shares sum to c exactly.
inline int local_context_share(int c, long long before, long long through, int n) {
  const auto rounded = [&](long long cum) { return (2 * static_cast<long long>(c) * cum + n) / (2LL * n); };
  return static_cast<int>(rounded(through) - rounded(before));
}
}  // namespace detail

// c uniform random tokens of [0, n) minus ws.excluded, written to out[0, kept) in draw order.
// Returns kept. out must hold at least c entries.
inline int sample_uniform_context(int n, int c, Rng& rng, MaskWorkspace& ws, std::span<int> out) {
  require<ConfigError>(c >= 1 && c <= n, "sample_uniform_context: c = ", c, ", expected 1 <= c <= ", n);
  require<ShapeError>(static_cast<int>(out.size()) >= c, "sample_uniform_context: out holds ",
                      out.size(), " entries, expected >= c = ", c);
  for (int i = 0; i < n; ++i) ws.perm[i] = i;
  int kept = 0;
  for (int j = 0; j < c; ++j) {
    std::swap(ws.perm[j], ws.perm[j + static_cast<int>(rng.below(static_cast<std::uint64_t>(n - j)))]);
    const int v = ws.perm[j];
    if (!ws.excluded.test(v)) out[kept++] = v;
  }
  return kept;
}

// A local context of c tokens over the parts (one domain per part, in part order) minus
// ws.excluded, written to out[0, kept) in random order. Returns kept. Throws if a part has no
// connected piece large enough for its share of c.
inline int sample_local_context(const TaxelGraph& g, std::span<const MaskDomain> parts, int c, Rng& rng,
                                MaskWorkspace& ws, std::span<int> out) {
  const int n = g.num_nodes();
  require<ConfigError>(c >= 1 && c <= n, "sample_local_context: c = ", c, ", expected 1 <= c <= ", n);
  require<ShapeError>(static_cast<int>(out.size()) >= c, "sample_local_context: out holds ",
                      out.size(), " entries, expected >= c = ", c);
  int kept = 0;
  long long before = 0;
  for (const MaskDomain& d : parts) {
    const int cp = detail::local_context_share(c, before, before + d.size(), n);
    before += d.size();
    if (cp == 0) continue;
    const int eligible = d.num_seeds(cp);
    require<DataError>(eligible > 0, "sample_local_context: no connected piece of part ", d.part(),
                       " holds its context share of ", cp, " tokens (largest: ", d.largest_piece(),
                       "); lower the context ratio or use the uniform context");
    const int seed = d.seed(static_cast<int>(rng.below(static_cast<std::uint64_t>(eligible))));
    const std::span<int> region = out.subspan(kept, cp);
    detail::grow_region(g, seed, rng, ws, region);
    for (int v : region)
      if (!ws.excluded.test(v)) out[kept++] = v;
  }
  rng.shuffle(out.first(kept));
  return kept;
}

}  // namespace tjepa
