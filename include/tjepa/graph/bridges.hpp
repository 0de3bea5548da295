#pragma once
// Bridges: edges between two adjacent groups (pads, regions) of a layout. For each listed pair of
// groups, the k closest cross-group taxel pairs by Euclidean distance (the reference uses k = 4),
// weighted by that distance (mm). Ties break on (taxel a, taxel b), so the result is deterministic.
#include <algorithm>
#include <cmath>
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
  std::vector<std::tuple<double, int, int>> best;
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
    // The k best (squared distance, lower taxel, higher taxel), kept sorted by insertion: the
    // candidate lists are large (palm x pad: ~9000 pairs) and k is small.
    best.clear();
    for (int i : A)
      for (int j : B) {
        double d2 = 0;
        for (int ax = 0; ax < layout.dim; ++ax) {
          const double d = layout.coords[static_cast<std::size_t>(i) * layout.dim + ax] -
                           layout.coords[static_cast<std::size_t>(j) * layout.dim + ax];
          d2 += d * d;
        }
        const bool full = static_cast<int>(best.size()) == k;
        if (full && d2 > std::get<0>(best.back())) continue;
        const std::tuple<double, int, int> c(d2, std::min(i, j), std::max(i, j));
        if (full && !(c < best.back())) continue;
        if (full) best.pop_back();
        best.insert(std::upper_bound(best.begin(), best.end(), c), c);
      }
    for (const auto& [d2, a, b] : best) out.push_back({a, b, std::sqrt(d2)});
  }
  return out;
}

}  // namespace tjepa
