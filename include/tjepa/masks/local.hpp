#pragma once
// Local masks: a connected region of t tokens. The seed is uniform over the tokens whose piece
// (connected component inside one part, see domain.hpp) holds at least t tokens; the region grows
// by Dijkstra over the edge weights and keeps the first t settled tokens. Ties in distance (every
// edge of a regular grid has the same weight) are broken by a random key drawn for each token when
// Dijkstra first reaches it, so equal-distance rings are filled in random order.
#include <algorithm>
#include <span>

#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/masks/workspace.hpp"
#include "tjepa/masks/domain.hpp"

namespace tjepa {

namespace detail {
// Dijkstra from `seed`, never leaving the seed's part; writes the first out.size() settled tokens
// to out in settle order and returns how many it found (fewer only if the piece is smaller).
inline int grow_region(const TaxelGraph& g, int seed, Rng& rng, MaskWorkspace& ws, std::span<int> out) {
  const int* offsets = g.offsets().data();
  const int* adj = g.adjacency().data();
  const double* w = g.edge_weights().data();
  const int* parts = g.parts().data();
  const int part = parts[seed];
  const int want = static_cast<int>(out.size());
  const std::uint32_t reached = ws.next_dijkstra_epoch(), settled = reached + 1;
  std::uint32_t* state = ws.state.data();
  double* dist = ws.dist.data();
  std::uint64_t* tie = ws.tie.data();
  auto draw_tie = [&](int v) { return (rng() & 0xFFFFFFFF00000000ull) | static_cast<std::uint32_t>(v); };
  ws.frontier.clear();
  state[seed] = reached;
  dist[seed] = 0.0;
  tie[seed] = draw_tie(seed);
  ws.frontier.push(FrontierItem::make(0.0, tie[seed]));
  int found = 0;
  while (found < want && !ws.frontier.empty()) {
    const FrontierItem top = ws.frontier.pop();
    const int u = top.node();
    const double du = top.dist();
    if (state[u] == settled || du != dist[u]) continue;  // stale entry
    state[u] = settled;
    out[found++] = u;
    for (int k = offsets[u]; k < offsets[u + 1]; ++k) {
      const int v = adj[k];
      if (parts[v] != part || state[v] == settled) continue;
      const double d = du + w[k];
      if (state[v] != reached) {
        state[v] = reached;
        tie[v] = draw_tie(v);
      } else if (d >= dist[v]) {
        continue;
      }
      dist[v] = d;
      ws.frontier.push(FrontierItem::make(d, tie[v]));
    }
  }
  return found;
}
}  // namespace detail

// A local mask of out.size() = t tokens of domain d, written to out in settle order (unsorted).
// ws must be resized to g.num_nodes(). Throws if t is out of [1, |d|] or no piece holds t tokens.
inline void sample_local_mask(const TaxelGraph& g, const MaskDomain& d, Rng& rng, MaskWorkspace& ws,
                              std::span<int> out) {
  const int t = static_cast<int>(out.size());
  require<ConfigError>(t >= 1 && t <= d.size(), "sample_local_mask: t = ", t,
                       ", expected 1 <= t <= ", d.size(), " (tokens of part ", d.part(), ")");
  const int eligible = d.num_seeds(t);
  require<DataError>(eligible > 0, "sample_local_mask: no connected piece of part ", d.part(),
                     " holds t = ", t, " tokens (largest: ", d.largest_piece(),
                     "); lower the target ratio or connect the layout");
  const int seed = d.seed(static_cast<int>(rng.below(static_cast<std::uint64_t>(eligible))));
  detail::grow_region(g, seed, rng, ws, out);
}

}  // namespace tjepa
