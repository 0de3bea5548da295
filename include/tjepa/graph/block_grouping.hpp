#pragma once
// Block grouping (the DECO-50 scheme of the paper's Sec. IV-D, "Taxel grouping", as the reference
// implementation builds it: E-Kovtun/tactile, tactile_ssl/data/deco_geometry.py): every region of
// a grid layout is cut into 2 x 2 blocks (n_g = 4); a 3 x 3 region is cut into a 2 x 2 block (its
// rows 0-1, cols 0-1) and the L-shaped rest (n_g = 5). Tokens come region by region in layout
// order, blocks row-major inside a region, members row-major inside a block. On the Inspire hand:
// 264 tokens per hand.
#include <algorithm>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/skin.hpp"

namespace tjepa {

inline Grouping block_grouping(const Skin& skin, GroupWeights weights = GroupWeights::unit) {
  const TaxelLayout& l = skin.layout;
  require<ConfigError>(l.has_cells(), "block_grouping: the layout has no (row, col) cells");
  std::vector<std::vector<int>> groups;
  for (int g = 0; g < l.num_groups(); ++g) {
    const auto t = l.taxels_of_group(g);
    int rows = 0, cols = 0;
    for (int i : t) {
      require<DataError>(l.row[i] >= 0 && l.col[i] >= 0, "block_grouping: taxel ", l.ids[i], " of region '",
                         l.group_names[g], "' has no (row, col) cell");
      rows = std::max(rows, l.row[i] + 1);
      cols = std::max(cols, l.col[i] + 1);
    }
    std::vector<int> cell(static_cast<std::size_t>(rows) * cols, -1);
    for (int i : t) cell[static_cast<std::size_t>(l.row[i]) * cols + l.col[i]] = i;
    const bool full = std::find(cell.begin(), cell.end(), -1) == cell.end() &&
                      static_cast<std::size_t>(rows) * cols == t.size();
    require<DataError>(full, "block_grouping: region '", l.group_names[g], "' has ", t.size(), " taxels, not a full ",
                       rows, " x ", cols, " grid");
    auto at = [&](int r, int c) { return cell[static_cast<std::size_t>(r) * cols + c]; };
    if (rows == 3 && cols == 3) {
      groups.push_back({at(0, 0), at(0, 1), at(1, 0), at(1, 1)});
      groups.push_back({at(0, 2), at(1, 2), at(2, 0), at(2, 1), at(2, 2)});
      continue;
    }
    require<DataError>(rows % 2 == 0 && cols % 2 == 0, "block_grouping: region '", l.group_names[g], "' is ", rows,
                       " x ", cols, ", expected even sides (2 x 2 blocks) or 3 x 3");
    for (int r = 0; r < rows; r += 2)
      for (int c = 0; c < cols; c += 2) groups.push_back({at(r, c), at(r, c + 1), at(r + 1, c), at(r + 1, c + 1)});
  }
  return make_grouping(skin, groups, weights);
}

}  // namespace tjepa
