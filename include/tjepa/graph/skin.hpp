#pragma once
// Skin: a TaxelLayout together with the TaxelGraph built on it (node i of the graph is taxel i of
// the layout; the graph's part and group arrays are the layout's). What every built-in layout and
// builder returns.
#include <span>
#include <utility>
#include <vector>

#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

struct Skin {
  TaxelLayout layout;
  TaxelGraph graph;
  int size() const { return layout.size(); }
};

// The graph over a layout's taxels with the given edges (indices into the layout, not ids).
// Validates both.
inline TaxelGraph make_graph(const TaxelLayout& layout, std::span<const Edge> edges) {
  layout.validate();
  return TaxelGraph(layout.size(), edges, layout.part, layout.group);
}

inline Skin make_skin(TaxelLayout layout, std::span<const Edge> edges) {
  TaxelGraph g = make_graph(layout, edges);
  return Skin{std::move(layout), std::move(g)};
}

// Sets every edge's weight to the Euclidean distance (mm) between its taxels' coordinates.
inline void set_distance_weights(const TaxelLayout& layout, std::span<Edge> edges) {
  require<ConfigError>(layout.has_coords(), "set_distance_weights: the layout has no coordinates");
  for (Edge& e : edges) {
    require<DataError>(e.src >= 0 && e.src < layout.size() && e.dst >= 0 && e.dst < layout.size(),
                       "set_distance_weights: edge (", e.src, " -> ", e.dst,
                       ") names an unknown taxel, expected indices in [0, ", layout.size(), ")");
    e.weight = layout.distance(e.src, e.dst);
  }
}

}  // namespace tjepa
