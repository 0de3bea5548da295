#pragma once
// Joining skins: several skins (two hands, two feet) become one, their taxels concatenated in
// order, parts and groups renumbered and prefixed by the skin's name. No edge joins two skins, so
// every part stays its own connected component.
#include <algorithm>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/skin.hpp"

namespace tjepa {

// names[k] names skin k: a one-part skin's part is called names[k], and every group and every
// part of a multi-part skin becomes "names[k]/<old name>". Ids are shifted so they stay unique:
// skin k's ids start after the largest id of skins 0..k-1. Coordinates are kept as they are (the
// skins' own drawings must not overlap if they are to be drawn together).
inline Skin join_skins(std::span<const Skin> skins, std::span<const std::string> names) {
  require<ConfigError>(!skins.empty(), "join_skins: no skins to join");
  require<ShapeError>(names.size() == skins.size(), "join_skins: ", names.size(), " names for ", skins.size(),
                      " skins, expected one each");
  TaxelLayout out;
  out.dim = skins[0].layout.dim;
  bool cells = false;
  for (const Skin& s : skins) {
    require<ConfigError>(s.layout.dim == out.dim, "join_skins: coordinate dimensions differ (", s.layout.dim,
                         " vs ", out.dim, ")");
    cells = cells || s.layout.has_cells();
  }
  std::vector<Edge> edges;
  int id_base = 0;
  for (std::size_t k = 0; k < skins.size(); ++k) {
    const TaxelLayout& l = skins[k].layout;
    const int taxel_base = out.size(), part_base = out.num_parts(), group_base = out.num_groups();
    for (int p = 0; p < l.num_parts(); ++p)
      out.part_names.push_back(l.num_parts() == 1 ? names[k] : names[k] + "/" + l.part_names[p]);
    for (int g = 0; g < l.num_groups(); ++g) {
      out.group_names.push_back(names[k] + "/" + l.group_names[g]);
      out.group_part.push_back(part_base + l.group_part[g]);
    }
    int max_id = -1;
    for (int i = 0; i < l.size(); ++i) {
      out.ids.push_back(id_base + l.ids[i]);
      max_id = std::max(max_id, l.ids[i]);
      out.part.push_back(part_base + l.part[i]);
      out.group.push_back(group_base + l.group[i]);
      if (cells) {
        out.row.push_back(l.has_cells() ? l.row[i] : -1);
        out.col.push_back(l.has_cells() ? l.col[i] : -1);
      }
    }
    out.coords.insert(out.coords.end(), l.coords.begin(), l.coords.end());
    id_base += max_id + 1;
    for (const Edge& e : skins[k].graph.edges()) edges.push_back({e.src + taxel_base, e.dst + taxel_base, e.weight});
  }
  return make_skin(std::move(out), edges);
}

}  // namespace tjepa
