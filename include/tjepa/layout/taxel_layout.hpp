#pragma once
// TaxelLayout: the N taxels of a skin in a fixed order (the order of the data's taxel axis). Each
// taxel has an id (as the user's files name it), a part (a connected piece of the embodiment: a
// hand, a foot), a group (its pad or region), optionally its (row, col) inside the group, and
// optionally 2-D or 3-D coordinates, and optionally the recording's column it is read from.
//
// Units: coordinates are in MILLIMETRES everywhere in tjepa (built-in layouts, builders, CSV files),
// so edge weights derived from them are distances in mm. The reference code uses metres; scaling
// all weights by one factor changes no mask (Dijkstra's order is scale-invariant).
#include <cmath>
#include <cstddef>
#include <string>
#include <unordered_set>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

struct TaxelLayout {
  // Coordinate dimension: 0 (no coordinates), 2 or 3.
  int dim = 0;
  std::vector<int> ids;                  // [N] user-facing ids, unique (default 0..N-1)
  std::vector<double> coords;            // [N, dim] row-major, mm; empty when dim == 0
  std::vector<int> part;                 // [N] in [0, P)
  std::vector<int> group;                // [N] in [0, G), global over all parts
  std::vector<int> row, col;             // [N] cell inside the group, -1 if none; empty: none at all
  std::vector<std::string> part_names;   // [P]
  std::vector<std::string> group_names;  // [G]
  std::vector<int> group_part;           // [G] the part each group lies in
  // [N] the taxel slot of a recording that taxel i reads (a permutation of 0..N-1): a sensor's
  // driver may write its taxels in another order than the layout's. Empty: slot i.
  std::vector<int> column;

  int size() const { return static_cast<int>(part.size()); }
  int num_parts() const { return static_cast<int>(part_names.size()); }
  int num_groups() const { return static_cast<int>(group_names.size()); }
  bool has_coords() const { return dim > 0; }
  bool has_cells() const { return !row.empty(); }
  bool has_columns() const { return !column.empty(); }

  // Coordinate a (0 = x, 1 = y, 2 = z) of taxel i; 0 beyond dim.
  double coord(int i, int a) const {
    return a < dim ? coords[static_cast<std::size_t>(i) * dim + a] : 0.0;
  }
  double distance(int i, int j) const {
    double s = 0;
    for (int a = 0; a < dim; ++a) {
      const double d = coord(i, a) - coord(j, a);
      s += d * d;
    }
    return std::sqrt(s);
  }

  // Taxel indices of group g / part p, in layout order.
  std::vector<int> taxels_of_group(int g) const {
    std::vector<int> out;
    for (int i = 0; i < size(); ++i)
      if (group[i] == g) out.push_back(i);
    return out;
  }
  std::vector<int> taxels_of_part(int p) const {
    std::vector<int> out;
    for (int i = 0; i < size(); ++i)
      if (part[i] == p) out.push_back(i);
    return out;
  }

  // Throws unless the layout is consistent: non-empty, array sizes agree, ids unique, coordinates
  // finite, part/group ids in range, every part and every group non-empty, each group inside the
  // part its group_part names.
  void validate() const {
    const int n = size();
    require<DataError>(n > 0, "TaxelLayout: no taxels (empty layout)");
    require<ConfigError>(dim == 0 || dim == 2 || dim == 3, "TaxelLayout: dim is ", dim,
                         ", expected 0, 2 or 3");
    require<ShapeError>(static_cast<int>(ids.size()) == n, "TaxelLayout: ids has ", ids.size(),
                        " entries, expected ", n);
    require<ShapeError>(coords.size() == static_cast<std::size_t>(n) * dim, "TaxelLayout: coords has ",
                        coords.size(), " values, expected N*dim = ", static_cast<std::size_t>(n) * dim);
    require<ShapeError>(static_cast<int>(group.size()) == n, "TaxelLayout: group has ", group.size(),
                        " entries, expected ", n);
    require<ShapeError>(row.empty() || (static_cast<int>(row.size()) == n &&
                                        static_cast<int>(col.size()) == n),
                        "TaxelLayout: row/col have ", row.size(), "/", col.size(),
                        " entries, expected 0 or ", n);
    require<ShapeError>(group_part.size() == group_names.size(), "TaxelLayout: group_part has ",
                        group_part.size(), " entries, expected one per group (", group_names.size(), ")");
    require<ShapeError>(column.empty() || static_cast<int>(column.size()) == n, "TaxelLayout: column has ",
                        column.size(), " entries, expected 0 or ", n);
    std::vector<int> reader(column.empty() ? 0 : static_cast<std::size_t>(n), -1);
    for (int i = 0; i < static_cast<int>(column.size()); ++i) {
      const int c = column[i];
      require<DataError>(c >= 0 && c < n, "TaxelLayout: taxel ", ids[i], " reads column ", c,
                         ", expected a column in [0, ", n, ")");
      require<DataError>(reader[c] < 0, "TaxelLayout: taxels ", ids[reader[c] < 0 ? 0 : reader[c]], " and ", ids[i],
                         " both read column ", c, ", expected each column once");
      reader[c] = i;
    }
    std::unordered_set<int> seen;
    seen.reserve(static_cast<std::size_t>(n) * 2);
    for (int i = 0; i < n; ++i)
      require<DataError>(seen.insert(ids[i]).second, "TaxelLayout: duplicate taxel id ", ids[i],
                         " (taxel ", i, ")");
    for (std::size_t k = 0; k < coords.size(); ++k)
      require<DataError>(std::isfinite(coords[k]), "TaxelLayout: taxel ", ids[k / dim],
                         " has a non-finite coordinate ", coords[k]);
    std::vector<int> part_count(part_names.size(), 0), group_count(group_names.size(), 0);
    for (int i = 0; i < n; ++i) {
      require<DataError>(part[i] >= 0 && part[i] < num_parts(), "TaxelLayout: taxel ", ids[i],
                         " has part ", part[i], ", expected in [0, ", num_parts(), ")");
      require<DataError>(group[i] >= 0 && group[i] < num_groups(), "TaxelLayout: taxel ", ids[i],
                         " has group ", group[i], ", expected in [0, ", num_groups(), ")");
      require<DataError>(group_part[group[i]] == part[i], "TaxelLayout: taxel ", ids[i], " is in part '",
                         part_names[part[i]], "' but its group '", group_names[group[i]],
                         "' belongs to part '", part_names[group_part[group[i]]], "'");
      ++part_count[part[i]];
      ++group_count[group[i]];
    }
    for (int p = 0; p < num_parts(); ++p)
      require<DataError>(part_count[p] > 0, "TaxelLayout: part '", part_names[p], "' has no taxels (empty part)");
    for (int g = 0; g < num_groups(); ++g)
      require<DataError>(group_count[g] > 0, "TaxelLayout: group '", group_names[g], "' has no taxels");
  }
};

}  // namespace tjepa
