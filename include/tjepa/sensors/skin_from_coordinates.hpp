#pragma once
// A skin from taxel coordinates alone: the graph is inferred from where the taxels are.
//
//   inside a group:   the relative neighbourhood graph (graph/coordinate_graphs.hpp): the
//                     4-neighbour grid of a pad whatever its row and column pitches, the
//                     6-neighbour sheet of a hexagonal one, and a misplaced taxel joined to its
//                     nearest neighbours only;
//   between groups:   bridges of the k closest cross-group pairs (as the built-in layouts), for
//                     BridgeRule::near: groups of one part whose closest taxels are within
//                     near_factor x the larger of their spacings (a group's spacing: the median
//                     distance of its taxels to their nearest neighbours);
//                     BridgeRule::connect (default): those, and then the group pairs of smallest
//                     closest distance that join each part into one piece (Kruskal over groups);
//                     BridgeRule::none: no bridges.
// Parts are never joined. Taxels of one part at the same coordinates are an error naming both;
// a taxel farther from its nearest neighbour than outlier_factor x its group's spacing, and a
// graph with more components than parts, are warnings (text for the user, nothing printed here).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <tuple>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/bridges.hpp"
#include "tjepa/graph/coordinate_graphs.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/csv.hpp"

namespace tjepa {

enum class BridgeRule { connect, near, none };

inline const char* to_string(BridgeRule r) {
  switch (r) {
    case BridgeRule::connect: return "connect";
    case BridgeRule::near: return "near";
    case BridgeRule::none: return "none";
  }
  return "?";
}
inline BridgeRule parse_bridge_rule(const std::string& s) {
  if (s == "connect") return BridgeRule::connect;
  if (s == "near") return BridgeRule::near;
  require<ConfigError>(s == "none", "bridge rule '", s, "', expected connect, near or none");
  return BridgeRule::none;
}

struct CoordinateSkinOptions {
  BridgeRule bridges = BridgeRule::connect;
  int bridge_pairs = 4;         // k closest cross-group pairs per bridged pair of groups
  double near_factor = 2.0;     // BridgeRule::near's reach, in group spacings
  double outlier_factor = 3.0;  // nearest neighbour beyond this many group spacings: a warning
  double tolerance = 0.05;      // relative_neighbour_edges' tolerance
};

// A skin and what the user should hear about it.
struct InferredSkin {
  Skin skin;
  std::vector<std::string> warnings;
};

// One line per part that falls into several components: its pieces, each by size and groups.
inline std::vector<std::string> component_warnings(const Skin& s) {
  const TaxelLayout& l = s.layout;
  const TaxelGraph& g = s.graph;
  std::vector<std::string> out;
  for (int p = 0; p < l.num_parts(); ++p) {
    std::map<int, std::pair<int, std::vector<std::string>>> pieces;  // component -> (taxels, groups)
    for (int i = 0; i < l.size(); ++i) {
      if (l.part[i] != p) continue;
      auto& [n, groups] = pieces[g.component(i)];
      ++n;
      const std::string& name = l.group_names[l.group[i]];
      if (std::find(groups.begin(), groups.end(), name) == groups.end()) groups.push_back(name);
    }
    if (pieces.size() < 2) continue;
    std::string text = "part '" + l.part_names[p] + "' falls into " + std::to_string(pieces.size()) +
                       " unconnected pieces:";
    int shown = 0;
    for (const auto& [c, piece] : pieces) {
      if (shown++ == 6) {
        text += " ...";
        break;
      }
      text += " {" + std::to_string(piece.first) + " taxels:";
      for (std::size_t k = 0; k < piece.second.size() && k < 4; ++k) text += " " + piece.second[k];
      if (piece.second.size() > 4) text += " ...";
      text += "}";
    }
    out.push_back(text + "; masks will not cross between them (add edges or bridges to join them)");
  }
  return out;
}

inline InferredSkin skin_from_coordinates(TaxelLayout l, const CoordinateSkinOptions& o = {}) {
  l.validate();
  require<ConfigError>(l.has_coords(), "skin_from_coordinates: the layout has no coordinates (x, y)");
  require<ConfigError>(o.bridge_pairs >= 1, "skin_from_coordinates: bridge_pairs ", o.bridge_pairs, ", expected >= 1");
  require<ConfigError>(o.near_factor > 0 && o.outlier_factor > 1, "skin_from_coordinates: near_factor ", o.near_factor,
                       " and outlier_factor ", o.outlier_factor, ", expected > 0 and > 1");
  InferredSkin r;
  // Duplicate coordinates inside a part.
  std::map<std::pair<int, std::vector<double>>, int> at;
  for (int i = 0; i < l.size(); ++i) {
    std::vector<double> x(l.coords.begin() + static_cast<std::ptrdiff_t>(i) * l.dim,
                          l.coords.begin() + static_cast<std::ptrdiff_t>(i + 1) * l.dim);
    const auto [it, fresh] = at.emplace(std::pair{l.part[i], std::move(x)}, i);
    require<DataError>(fresh, "taxels ", l.ids[it->second], " and ", l.ids[i], " of part '", l.part_names[l.part[i]],
                       "' have the same coordinates; each taxel needs its own place");
  }
  const int G = l.num_groups();
  std::vector<std::vector<int>> members(static_cast<std::size_t>(G));
  for (int i = 0; i < l.size(); ++i) members[static_cast<std::size_t>(l.group[i])].push_back(i);
  std::vector<Edge> edges;
  std::vector<double> spacing(static_cast<std::size_t>(G), 0.0);
  for (int g = 0; g < G; ++g) {
    const auto& m = members[static_cast<std::size_t>(g)];
    const auto e = relative_neighbour_edges(l, m, o.tolerance);
    edges.insert(edges.end(), e.begin(), e.end());
    if (m.size() < 2) continue;
    std::vector<double> nn(m.size(), std::numeric_limits<double>::infinity());
    for (std::size_t a = 0; a < m.size(); ++a)
      for (std::size_t b = 0; b < m.size(); ++b)
        if (a != b) nn[a] = std::min(nn[a], l.distance(m[a], m[b]));
    std::vector<double> sorted = nn;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double s = sorted[sorted.size() / 2];
    spacing[static_cast<std::size_t>(g)] = s;
    if (m.size() < 3) continue;
    for (std::size_t a = 0; a < m.size(); ++a)
      if (nn[a] > o.outlier_factor * s)
        r.warnings.push_back("taxel " + std::to_string(l.ids[m[a]]) + " of group '" + l.group_names[g] + "' is " +
                             std::to_string(nn[a]) + " from its nearest neighbour, " + std::to_string(nn[a] / s) +
                             " x the group's spacing " + std::to_string(s) +
                             ": check its coordinates (it joins only its nearest neighbours)");
  }
  // Closest distance of every pair of groups in one part.
  std::vector<std::tuple<double, int, int>> pairs;
  for (int g = 0; g < G; ++g)
    for (int h = g + 1; h < G; ++h) {
      if (l.group_part[static_cast<std::size_t>(g)] != l.group_part[static_cast<std::size_t>(h)]) continue;
      double best = std::numeric_limits<double>::infinity();
      for (int i : members[static_cast<std::size_t>(g)])
        for (int j : members[static_cast<std::size_t>(h)]) best = std::min(best, l.distance(i, j));
      pairs.emplace_back(best, g, h);
    }
  std::sort(pairs.begin(), pairs.end());
  std::vector<int> root(static_cast<std::size_t>(G));
  std::iota(root.begin(), root.end(), 0);
  auto find = [&](int g) {
    while (root[static_cast<std::size_t>(g)] != g) g = root[static_cast<std::size_t>(g)] = root[static_cast<std::size_t>(root[static_cast<std::size_t>(g)])];
    return g;
  };
  std::vector<GroupPair> bridged;
  auto bridge = [&](int g, int h) {
    bridged.push_back({g, h});
    root[static_cast<std::size_t>(find(g))] = find(h);
  };
  std::vector<bool> taken(pairs.size(), false);
  if (o.bridges != BridgeRule::none)
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const auto [d, g, h] = pairs[k];
      const double s = std::max(spacing[static_cast<std::size_t>(g)], spacing[static_cast<std::size_t>(h)]);
      if (d <= o.near_factor * s) {
        bridge(g, h);
        taken[k] = true;
      }
    }
  if (o.bridges == BridgeRule::connect)
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const auto [d, g, h] = pairs[k];
      if (!taken[k] && find(g) != find(h)) bridge(g, h);
    }
  for (const GroupPair& p : bridged) {
    const std::size_t cands = members[static_cast<std::size_t>(p.a)].size() * members[static_cast<std::size_t>(p.b)].size();
    const auto e = bridge_edges(l, std::span<const GroupPair>(&p, 1), static_cast<int>(std::min<std::size_t>(
                                                                           static_cast<std::size_t>(o.bridge_pairs), cands)));
    edges.insert(edges.end(), e.begin(), e.end());
  }
  // In-group edges and bridges join distinct pairs; listed in (lower, higher) taxel order.
  std::sort(edges.begin(), edges.end(), [](const Edge& a, const Edge& b) {
    return std::pair(std::min(a.src, a.dst), std::max(a.src, a.dst)) < std::pair(std::min(b.src, b.dst), std::max(b.src, b.dst));
  });
  r.skin = make_skin(std::move(l), edges);
  const auto more = component_warnings(r.skin);
  r.warnings.insert(r.warnings.end(), more.begin(), more.end());
  return r;
}

// A skin from a layout CSV (sensors/csv.hpp: columns by name, configurable) with the graph
// inferred from the coordinates, or read from an edges CSV when one is given.
inline InferredSkin read_skin_coordinates_csv(const std::filesystem::path& nodes, const NodeCsvColumns& columns = {},
                                              const CoordinateSkinOptions& o = {}) {
  TaxelLayout l = read_layout_csv(nodes, columns);
  require<FileError>(l.has_coords(), nodes.string(), ": no coordinates (columns '", columns.x, "' and '", columns.y,
                     "'), so the graph cannot be inferred; give an edges file");
  return skin_from_coordinates(std::move(l), o);
}

inline InferredSkin read_skin_csv_checked(const std::filesystem::path& nodes, const std::filesystem::path& edges,
                                          const NodeCsvColumns& nc = {}, const EdgeCsvColumns& ec = {}) {
  InferredSkin r{read_skin_csv(nodes, edges, nc, ec), {}};
  r.warnings = component_warnings(r.skin);
  return r;
}

}  // namespace tjepa
