#pragma once
// Bridges: edges between two adjacent groups (pads, regions) of a layout. For each listed pair of
// groups, the k closest cross-group taxel pairs by Euclidean distance (the reference uses k = 4),
// weighted by that distance (mm). Ties break on (taxel a, taxel b), so the result is deterministic.
#include <algorithm>
#include <span>
#include <tuple>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

struct GroupPair {
  int a = 0;
  int b = 0;
};

inline std::vector<Edge> bridge_edges(const TaxelLayout& layout, std::span<const GroupPair> pairs,
                                      int k = 4) {
  require<ConfigError>(layout.has_coords(), "bridge_edges: the layout has no coordinates");
  require<ConfigError>(k > 0, "bridge_edges: k = ", k, ", expected > 0");
  std::vector<std::vector<int>> members(layout.num_groups());
  for (int i = 0; i < layout.size(); ++i) members[layout.group[i]].push_back(i);
  std::vector<Edge> out;
  std::vector<std::tuple<double, int, int>> cand;
  for (const GroupPair& gp : pairs) {
    require<ConfigError>(gp.a >= 0 && gp.a < layout.num_groups() && gp.b >= 0 &&
                             gp.b < layout.num_groups(),
                         "bridge_edges: group pair (", gp.a, ", ", gp.b, ") names an unknown group, expected ids in [0, ",
                         layout.num_groups(), ")");
    require<ConfigError>(gp.a != gp.b, "bridge_edges: group pair (", gp.a, ", ", gp.b,
                         ") joins group '", layout.group_names[gp.a], "' to itself");
    const auto& A = members[gp.a];
    const auto& B = members[gp.b];
    const std::size_t cands = A.size() * B.size();
    require<ConfigError>(static_cast<std::size_t>(k) <= cands, "bridge_edges: k = ", k, " is larger than the ",
                         cands, " candidate pairs between groups '", layout.group_names[gp.a], "' and '",
                         layout.group_names[gp.b], "'");
    cand.clear();
    for (int i : A)
      for (int j : B) cand.emplace_back(layout.distance(i, j), std::min(i, j), std::max(i, j));
    std::partial_sort(cand.begin(), cand.begin() + k, cand.end());
    for (int t = 0; t < k; ++t)
      out.push_back({std::get<1>(cand[t]), std::get<2>(cand[t]), std::get<0>(cand[t])});
  }
  return out;
}

}  // namespace tjepa
