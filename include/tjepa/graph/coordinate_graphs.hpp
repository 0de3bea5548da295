#pragma once
// Graphs from coordinates, for skins known only by where their taxels are:
//   knn_edges:    each taxel joined to its k nearest taxels (the union, so symmetric: a taxel may
//                 end up with more than k neighbours);
//   radius_edges: every pair of taxels closer than a radius;
//   relative_neighbour_edges: the relative neighbourhood graph, taxels i and j joined unless a
//                 third taxel k is nearer to both (max(d_ik, d_jk) < (1 - tolerance)·d_ij). It needs
//                 no spacing: on a grid of any pitch, square or not, it gives the 4-neighbour
//                 edges (the diagonal has a closer witness), on a hexagonal sheet the 6-neighbour
//                 ones (the tolerance keeps the equilateral triangles' edges against rounding), and
//                 an isolated taxel joins only its nearest neighbours. Candidates are each taxel's
//                 `candidates` nearest; a witness is always nearer, so it is exact for them.
// All stay inside a part unless across_parts is set (two hands must not be joined by accident),
// weigh each edge by its length (mm), and break distance ties on the lower index. Brute force,
// O(N^2): meant for building a layout once, not for a hot loop.
#include <algorithm>
#include <cmath>
#include <set>
#include <span>
#include <tuple>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

inline std::vector<Edge> knn_edges(const TaxelLayout& l, int k, bool across_parts = false) {
  l.validate();
  require<ConfigError>(l.has_coords(), "knn_edges: the layout has no coordinates");
  require<ConfigError>(k > 0, "knn_edges: k = ", k, ", expected > 0");
  const int n = l.size();
  std::vector<int> part_size(l.num_parts(), 0);
  for (int i = 0; i < n; ++i) ++part_size[l.part[i]];
  for (int p = 0; p < l.num_parts(); ++p) {
    const int cand = (across_parts ? n : part_size[p]) - 1;
    require<ConfigError>(k <= cand, "knn_edges: k = ", k, " is larger than the ", cand, " candidate neighbours in ",
                         across_parts ? std::string("the layout") : "part '" + l.part_names[p] + "'");
  }
  std::set<std::pair<int, int>> pairs;
  std::vector<std::pair<double, int>> d;
  for (int i = 0; i < n; ++i) {
    d.clear();
    for (int j = 0; j < n; ++j)
      if (j != i && (across_parts || l.part[j] == l.part[i])) d.emplace_back(l.distance(i, j), j);
    std::partial_sort(d.begin(), d.begin() + k, d.end());
    for (int t = 0; t < k; ++t) pairs.emplace(std::min(i, d[t].second), std::max(i, d[t].second));
  }
  std::vector<Edge> out;
  out.reserve(pairs.size());
  for (const auto& [a, b] : pairs) out.push_back({a, b, l.distance(a, b)});
  return out;
}

inline std::vector<Edge> radius_edges(const TaxelLayout& l, double radius, bool across_parts = false) {
  l.validate();
  require<ConfigError>(l.has_coords(), "radius_edges: the layout has no coordinates");
  require<ConfigError>(std::isfinite(radius) && radius > 0, "radius_edges: radius ", radius, ", expected > 0 (mm)");
  std::vector<Edge> out;
  for (int i = 0; i < l.size(); ++i)
    for (int j = i + 1; j < l.size(); ++j)
      if ((across_parts || l.part[i] == l.part[j])) {
        const double d = l.distance(i, j);
        if (d <= radius) out.push_back({i, j, d});
      }
  return out;
}

// Relative neighbourhood edges among `members` (indices into l), which must hold distinct points.
inline std::vector<Edge> relative_neighbour_edges(const TaxelLayout& l, std::span<const int> members,
                                                  double tolerance = 0.05, int candidates = 16) {
  require<ConfigError>(l.has_coords(), "relative_neighbour_edges: the layout has no coordinates");
  require<ConfigError>(tolerance >= 0 && tolerance < 1, "relative_neighbour_edges: tolerance ", tolerance,
                       ", expected in [0, 1)");
  require<ConfigError>(candidates >= 1, "relative_neighbour_edges: candidates ", candidates, ", expected >= 1");
  const int m = static_cast<int>(members.size());
  std::set<std::pair<int, int>> pairs;
  std::vector<std::pair<double, int>> near;  // (distance, position in members), nearest first
  for (int a = 0; a < m; ++a) {
    near.clear();
    for (int b = 0; b < m; ++b)
      if (b != a) near.emplace_back(l.distance(members[a], members[b]), b);
    const int c = std::min<int>(candidates, static_cast<int>(near.size()));
    std::partial_sort(near.begin(), near.begin() + c, near.end());
    for (int t = 0; t < c; ++t) {
      const auto [dab, b] = near[t];
      bool witness = false;
      // A witness k has d_ak < d_ab, so it is one of the nearer candidates.
      for (int u = 0; u < t && !witness; ++u) {
        const int k = near[u].second;
        witness = std::max(near[u].first, l.distance(members[b], members[k])) < (1.0 - tolerance) * dab;
      }
      if (!witness) pairs.emplace(std::min(members[a], members[b]), std::max(members[a], members[b]));
    }
  }
  std::vector<Edge> out;
  out.reserve(pairs.size());
  for (const auto& [i, j] : pairs) out.push_back({i, j, l.distance(i, j)});
  return out;
}

}  // namespace tjepa
