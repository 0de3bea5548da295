#pragma once
// Generic built-in skins for tests and first steps.
//   grid_skin: one part, a rows x cols sheet cut into rectangular groups (pads), 4-neighbour edges
//     over the whole sheet (8 as an option), weights = pitch (mm).
//   two_part_skin: two parts of different, irregular shapes (like a pair of sensor socks): each a
//     masked grid with 4-neighbour edges, cut into three groups (toe, mid, heel) by row bands. The
//     parts are not joined: the graph has two components.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/grid_pad.hpp"
#include "tjepa/sensors/layout_builder.hpp"

namespace tjepa::layouts {

struct GridSkinOptions {
  int rows = 12;
  int cols = 16;
  double pitch = 4.0;       // mm
  int group_rows = 4;       // each group is a group_rows x group_cols block (edge blocks may be smaller)
  int group_cols = 4;
  bool eight_neighbours = false;
};

namespace detail {
// Adds the live cells of `pad` as taxels of part `part`, the group of cell (r, c) given by
// group_of(r, c) (a group id of the builder), at origin + (c, r) * pitch, with the sheet's edges.
template <class GroupOf>
void add_sheet(LayoutBuilder& b, const GridPad& pad, double x0, double y0, GroupOf group_of) {
  pad.validate("sheet");
  std::vector<int> idx(static_cast<std::size_t>(pad.rows) * pad.cols, -1);
  for (int r = 0; r < pad.rows; ++r)
    for (int c = 0; c < pad.cols; ++c)
      if (pad.is_live(r, c))
        idx[static_cast<std::size_t>(r) * pad.cols + c] =
            b.add_taxel(group_of(r, c), {x0 + c * pad.pitch, y0 + r * pad.dy()}, r, c);
  for (const Edge& e : grid_edges(pad, idx)) b.add_edge(e.src, e.dst, e.weight);
}
}  // namespace detail

inline Skin grid_skin(const GridSkinOptions& o = {}) {
  require<ConfigError>(o.group_rows > 0 && o.group_cols > 0, "grid_skin: group size ", o.group_rows, " x ",
                       o.group_cols, ", expected both > 0");
  const GridPad sheet = GridPad(o.rows, o.cols, o.pitch).with_eight_neighbours(o.eight_neighbours);
  sheet.validate("grid_skin");
  LayoutBuilder b(2);
  const int p = b.add_part("skin");
  const int gr = (o.rows + o.group_rows - 1) / o.group_rows, gc = (o.cols + o.group_cols - 1) / o.group_cols;
  for (int i = 0; i < gr; ++i)
    for (int j = 0; j < gc; ++j) b.add_group("block_" + std::to_string(i) + "_" + std::to_string(j), p);
  detail::add_sheet(b, sheet, 0.0, 0.0, [&](int r, int c) { return (r / o.group_rows) * gc + c / o.group_cols; });
  return b.build();
}

// Two irregular parts: "left" on a 14 x 8 grid, "right" on a 13 x 8 grid with a notch in its
// side, both foot-like ellipses at 5 mm pitch, 50 mm apart.
inline Skin two_part_skin() {
  LayoutBuilder b(2);
  struct Shape {
    const char* name;
    int rows, cols;
    int notch_r0, notch_r1;  // rows whose outer two columns are cut away (none if r0 > r1)
  };
  const Shape shapes[2] = {{"left", 14, 8, 1, 0}, {"right", 13, 8, 5, 7}};
  double x0 = 0.0;
  for (const Shape& s : shapes) {
    const int p = b.add_part(s.name);
    GridPad pad(s.rows, s.cols, 5.0);
    pad.live.assign(static_cast<std::size_t>(s.rows) * s.cols, 0);
    const double cr = 0.5 * (s.rows - 1), cc = 0.5 * (s.cols - 1);
    for (int r = 0; r < s.rows; ++r)
      for (int c = 0; c < s.cols; ++c) {
        const double u = (r - cr) / (cr + 0.6), v = (c - cc) / (cc + 0.6);
        const bool notch = r >= s.notch_r0 && r <= s.notch_r1 && c < 2;
        pad.live[static_cast<std::size_t>(r) * s.cols + c] = u * u + v * v <= 1.0 && !notch;
      }
    const std::string n = s.name;
    const int heel = b.add_group(n + "/heel", p), mid = b.add_group(n + "/mid", p), toe = b.add_group(n + "/toe", p);
    const int band = s.rows / 3;
    detail::add_sheet(b, pad, x0, 0.0, [&](int r, int) { return r < band ? heel : (r < s.rows - band ? mid : toe); });
    x0 += s.cols * 5.0 + 50.0;
  }
  return b.build();
}

}  // namespace tjepa::layouts
