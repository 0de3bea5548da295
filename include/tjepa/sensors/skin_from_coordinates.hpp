#pragma once
// A skin from a layout CSV that has coordinates but no edges: the graph is inferred from where the
// taxels are.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/text_reader.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/layout_builder.hpp"

namespace tjepa {

// A layout CSV: a header naming the columns, then one taxel per row. Columns: x, y (mm), and
// optionally z, id, part, group (names or numbers; default one part / one group). Edges: inside a
// group, taxels closer than 1.2 x the group's nearest-neighbour spacing (4-neighbours on a grid);
// between two groups of one part whose closest taxels are within 2 x that spacing, the k = 4
// closest pairs (as the built-in layouts' bridges). Weights: distance in mm.
inline Skin read_skin_coordinates_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  require<FileError>(static_cast<bool>(in), "cannot open layout file '", path.string(), "'");
  std::string line;
  std::vector<std::string_view> f;
  std::vector<std::string> cols;
  int lineno = 0;
  auto where = [&] { return path.string() + ":" + std::to_string(lineno); };
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    detail::split_fields(line, ',', f);
    for (auto s : f) {
      std::string c(s);
      c.erase(0, c.find_first_not_of(" \t\r"));
      c.erase(c.find_last_not_of(" \t\r") + 1);
      cols.push_back(c);
    }
    break;
  }
  auto col = [&](const char* name) {
    const auto it = std::find(cols.begin(), cols.end(), name);
    return it == cols.end() ? -1 : static_cast<int>(it - cols.begin());
  };
  const int cx = col("x"), cy = col("y"), cz = col("z"), cid = col("id"), cp = col("part"), cg = col("group");
  require<FileError>(cx >= 0 && cy >= 0, path.string(), ": the header must name columns x and y (got '",
                     line, "')");
  const int dim = cz >= 0 ? 3 : 2;
  LayoutBuilder b(dim);
  std::map<std::string, int> parts, groups;
  std::vector<int> group_part;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
    detail::split_fields(line, ',', f);
    require<FileError>(f.size() == cols.size(), where(), ": ", f.size(), " fields, expected ", cols.size());
    auto text = [&](int c) {
      std::string s(f[static_cast<std::size_t>(c)]);
      s.erase(0, s.find_first_not_of(" \t\r"));
      s.erase(s.find_last_not_of(" \t\r") + 1);
      return s;
    };
    auto number = [&](int c) {
      float v = 0;
      require<FileError>(detail::parse_float(text(c), v) && std::isfinite(v), where(), ": column '", cols[c],
                         "' = '", text(c), "', expected a finite number");
      return static_cast<double>(v);
    };
    const std::string pname = cp >= 0 ? text(cp) : "part0";
    if (!parts.contains(pname)) parts.emplace(pname, b.add_part(pname));
    const std::string gname = cg >= 0 ? text(cg) : "group0";
    if (!groups.contains(gname)) {
      groups.emplace(gname, b.add_group(gname, parts.at(pname)));
      group_part.push_back(parts.at(pname));
    }
    require<FileError>(group_part[static_cast<std::size_t>(groups.at(gname))] == parts.at(pname), where(),
                       ": group '", gname, "' appears in two parts");
    double xyz[3] = {number(cx), number(cy), cz >= 0 ? number(cz) : 0.0};
    const int id = cid >= 0 ? static_cast<int>(number(cid)) : -1;
    b.add_taxel(groups.at(gname), std::span<const double>(xyz, static_cast<std::size_t>(dim)), -1, -1, id);
  }
  const TaxelLayout& l = b.layout();
  require<FileError>(l.size() >= 2, path.string(), ": ", l.size(), " taxels, expected at least 2");
  const int G = l.num_groups();
  std::vector<std::vector<int>> members(static_cast<std::size_t>(G));
  for (int i = 0; i < l.size(); ++i) members[static_cast<std::size_t>(l.group[i])].push_back(i);
  std::vector<double> spacing(static_cast<std::size_t>(G), 0.0);
  for (int g = 0; g < G; ++g) {
    const auto& m = members[static_cast<std::size_t>(g)];
    double nn_max = 0;  // the group's spacing: the largest nearest-neighbour distance
    for (int i : m) {
      double nn = std::numeric_limits<double>::infinity();
      for (int j : m)
        if (j != i) nn = std::min(nn, l.distance(i, j));
      if (std::isfinite(nn)) nn_max = std::max(nn_max, nn);
    }
    spacing[static_cast<std::size_t>(g)] = nn_max;
    for (std::size_t a = 0; a < m.size(); ++a)
      for (std::size_t c = a + 1; c < m.size(); ++c)
        if (l.distance(m[a], m[c]) <= 1.2 * nn_max) b.add_edge(m[a], m[c]);
  }
  std::vector<GroupPair> pairs;
  for (int g = 0; g < G; ++g)
    for (int h = g + 1; h < G; ++h) {
      if (group_part[static_cast<std::size_t>(g)] != group_part[static_cast<std::size_t>(h)]) continue;
      double best = std::numeric_limits<double>::infinity();
      for (int i : members[static_cast<std::size_t>(g)])
        for (int j : members[static_cast<std::size_t>(h)]) best = std::min(best, l.distance(i, j));
      const double s = std::max(spacing[static_cast<std::size_t>(g)], spacing[static_cast<std::size_t>(h)]);
      if (best <= 2.0 * s) pairs.push_back({g, h});
    }
  for (const auto& p : pairs) {
    const auto k = std::min<std::size_t>(4, members[static_cast<std::size_t>(p.a)].size() *
                                                members[static_cast<std::size_t>(p.b)].size());
    b.add_bridges(std::span<const GroupPair>(&p, 1), static_cast<int>(k));
  }
  return b.build();
}

}  // namespace tjepa
