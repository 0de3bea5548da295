#pragma once
// LayoutBuilder: assembles a skin pad by pad. Parts and groups get names; grid pads are placed on a
// flat drawing (centre in mm, rotation in degrees) and bring their own 4-neighbour edges; bridges
// join adjacent pads; build() validates everything and returns the Skin.
//
//   LayoutBuilder b;
//   int hand = b.add_part("hand");
//   int tip = b.add_grid_pad("tip", hand, GridPad(4, 4, 4.7), {0, 30});
//   int pad = b.add_grid_pad("pad", hand, GridPad(4, 4, 4.7), {0, 0});
//   b.add_bridges({{tip, pad}}, 4);
//   Skin skin = b.build();
#include <cmath>
#include <initializer_list>
#include <numbers>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/bridges.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/grid_pad.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

// Where a grid pad sits on the drawing: its centre (mm) and a counter-clockwise rotation. In the
// pad's own frame, columns run along +x and rows along +y (row 0 at the bottom).
struct PadPlacement {
  double x = 0.0;
  double y = 0.0;
  double angle_deg = 0.0;
  double z = 0.0;  // used by 3-D layouts only
};

class LayoutBuilder {
 public:
  // dim: 2 or 3 (coordinates), or 0 (no coordinates: grid pads still give (row, col) and weights).
  explicit LayoutBuilder(int dim = 2) {
    require<ConfigError>(dim == 0 || dim == 2 || dim == 3, "LayoutBuilder: dim ", dim, ", expected 0, 2 or 3");
    l_.dim = dim;
  }

  int add_part(std::string name) {
    l_.part_names.push_back(std::move(name));
    return l_.num_parts() - 1;
  }
  int add_group(std::string name, int part) {
    require<ConfigError>(part >= 0 && part < l_.num_parts(), "LayoutBuilder::add_group: part ", part,
                         " for group '", name, "', expected in [0, ", l_.num_parts(), ")");
    l_.group_names.push_back(std::move(name));
    l_.group_part.push_back(part);
    return l_.num_groups() - 1;
  }

  // One taxel of group g; xyz holds dim values (ignored when dim == 0). Returns its index. Its id is
  // its index unless given.
  int add_taxel(int g, std::span<const double> xyz, int row = -1, int col = -1, int id = -1) {
    require<ConfigError>(g >= 0 && g < l_.num_groups(), "LayoutBuilder::add_taxel: group ", g,
                         ", expected in [0, ", l_.num_groups(), ")");
    require<ShapeError>(l_.dim == 0 || static_cast<int>(xyz.size()) == l_.dim,
                        "LayoutBuilder::add_taxel: ", xyz.size(), " coordinates, expected ", l_.dim);
    const int i = l_.size();
    l_.ids.push_back(id >= 0 ? id : i);
    for (int a = 0; a < l_.dim; ++a) l_.coords.push_back(xyz[a]);
    l_.part.push_back(l_.group_part[g]);
    l_.group.push_back(g);
    if (row >= 0 || col >= 0) any_cell_ = true;
    row_.push_back(row);
    col_.push_back(col);
    return i;
  }
  int add_taxel(int g, std::initializer_list<double> xyz, int row = -1, int col = -1, int id = -1) {
    return add_taxel(g, std::span<const double>(xyz.begin(), xyz.size()), row, col, id);
  }

  // A grid pad as a new group of `part`: its live cells in row-major order, their (row, col), their
  // coordinates from the placement, and the pad's grid edges. Returns the group id.
  int add_grid_pad(std::string name, int part, const GridPad& pad, const PadPlacement& at = {}) {
    pad.validate(name.c_str());
    const int g = add_group(std::move(name), part);
    const int first = l_.size();
    const double th = at.angle_deg * std::numbers::pi / 180.0, cs = std::cos(th), sn = std::sin(th);
    for (int r = 0; r < pad.rows; ++r)
      for (int c = 0; c < pad.cols; ++c) {
        if (!pad.is_live(r, c)) continue;
        const double lx = (c - 0.5 * (pad.cols - 1)) * pad.pitch;
        const double ly = (r - 0.5 * (pad.rows - 1)) * pad.dy();
        const double xyz[3] = {at.x + cs * lx - sn * ly, at.y + sn * lx + cs * ly, at.z};
        add_taxel(g, std::span<const double>(xyz, l_.dim), r, c);
      }
    const auto idx = pad.cell_index(first);
    for (const Edge& e : grid_edges(pad, idx)) edges_.push_back(e);
    return g;
  }

  // An explicit edge between taxel indices; a NaN weight means the coordinate distance.
  void add_edge(int a, int b, double weight = std::nan("")) {
    if (std::isnan(weight)) {
      require<ConfigError>(l_.has_coords(), "LayoutBuilder::add_edge: edge (", a, ", ", b,
                           ") has no weight and the layout has no coordinates");
      require<DataError>(a >= 0 && a < l_.size() && b >= 0 && b < l_.size(), "LayoutBuilder::add_edge: edge (", a,
                         ", ", b, ") names an unknown taxel, expected indices in [0, ", l_.size(), ")");
      weight = l_.distance(a, b);
    }
    edges_.push_back({a, b, weight});
  }

  // For each pair of groups, the k closest cross-group taxel pairs (see bridge_edges).
  void add_bridges(std::span<const GroupPair> pairs, int k = 4) {
    sync_cells();
    for (const Edge& e : bridge_edges(l_, pairs, k)) edges_.push_back(e);
  }
  void add_bridges(std::initializer_list<GroupPair> pairs, int k = 4) {
    add_bridges(std::span<const GroupPair>(pairs.begin(), pairs.size()), k);
  }

  const TaxelLayout& layout() {
    sync_cells();
    return l_;
  }
  const std::vector<Edge>& edges() const { return edges_; }

  Skin build() {
    sync_cells();
    return make_skin(l_, edges_);
  }

 private:
  void sync_cells() {
    if (any_cell_) {
      l_.row = row_;
      l_.col = col_;
    } else {
      l_.row.clear();
      l_.col.clear();
    }
  }

  TaxelLayout l_;
  std::vector<int> row_, col_;
  bool any_cell_ = false;
  std::vector<Edge> edges_;
};

}  // namespace tjepa
