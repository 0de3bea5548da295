#pragma once
// Layout files. A node CSV lists the taxels, one a line, in the data's taxel order; an edge CSV
// lists the graph's undirected edges by taxel id.
//
//   # Allegro hand          <- comments and blank lines are skipped
//   id,x,y,part,group,row,col,notes   <- header: columns chosen by name, extra columns ignored
//   0,12.5,120.3,hand,thumb_tip,0,0,first
//
//   src,dst,weight          <- weight optional: without it, the coordinate distance (or 1)
//   0,1,5.1666
//
// Node columns (names configurable): id (default: line order 0..N-1), x, y, z (mm, optional;
// x and y go together), part and group (names, optional: one part "skin", one group per part),
// row and col (optional; empty or -1: none). Parts are numbered in order of first appearance,
// groups by (part, name) in order of first appearance. Without a header row, fields are read in
// the writer's order: id,x,y[,z],part,group[,row,col] (5 to 8 fields). Errors name the file, the
// line and what was wrong. The writers emit exactly what the readers read back.
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "tjepa/core/atomic_write.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/layout/detail/csv_table.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

struct NodeCsvColumns {
  std::string id = "id", x = "x", y = "y", z = "z", part = "part", group = "group", row = "row", col = "col";
};

struct EdgeCsvColumns {
  std::string src = "src", dst = "dst", weight = "weight";
};

namespace detail {

// Column name -> field index, from the header row if the first row names any of `names`,
// otherwise from `fallback` (positional). Returns whether a header was found.
inline bool csv_columns(const std::vector<CsvRow>& rows, const std::vector<std::string>& names,
                        const std::vector<std::string>& fallback, std::map<std::string, int>& col) {
  col.clear();
  bool header = false;
  for (const auto& f : rows[0].fields)
    for (const auto& n : names) header = header || f == n;
  if (header) {
    for (std::size_t k = 0; k < rows[0].fields.size(); ++k) col.emplace(rows[0].fields[k], static_cast<int>(k));
  } else {
    for (std::size_t k = 0; k < fallback.size(); ++k) col.emplace(fallback[k], static_cast<int>(k));
  }
  return header;
}

}  // namespace detail

inline TaxelLayout read_layout_csv(const std::filesystem::path& path, const NodeCsvColumns& c = {}) {
  const auto rows = detail::read_csv_rows(path);
  require<FileError>(!rows.empty(), path.string(), ": no taxels (empty layout)");
  std::vector<std::string> fallback;
  switch (rows[0].fields.size()) {
    case 5: fallback = {c.id, c.x, c.y, c.part, c.group}; break;
    case 6: fallback = {c.id, c.x, c.y, c.z, c.part, c.group}; break;
    case 7: fallback = {c.id, c.x, c.y, c.part, c.group, c.row, c.col}; break;
    case 8: fallback = {c.id, c.x, c.y, c.z, c.part, c.group, c.row, c.col}; break;
    default: break;
  }
  std::map<std::string, int> col;
  const bool header = detail::csv_columns(rows, {c.id, c.x, c.y, c.z, c.part, c.group, c.row, c.col}, fallback, col);
  require<FileError>(header || !fallback.empty(), detail::where(path, rows[0].line), "no header row naming the columns (",
                     c.id, ", ", c.x, ", ", c.y, ", ", c.part, ", ", c.group, ", ...), and ", rows[0].fields.size(),
                     " fields where a header-less file has 5 to 8 (id,x,y[,z],part,group[,row,col])");
  auto find = [&](const std::string& n) { return col.count(n) ? col.at(n) : -1; };
  const int ci = find(c.id), cx = find(c.x), cy = find(c.y), cz = find(c.z), cp = find(c.part), cg = find(c.group),
            cr = find(c.row), cc = find(c.col);
  require<FileError>((cx < 0) == (cy < 0), path.string(), ": has column '", cx < 0 ? c.y : c.x, "' but not '",
                     cx < 0 ? c.x : c.y, "'");
  require<FileError>(cz < 0 || cx >= 0, path.string(), ": has column '", c.z, "' but no '", c.x, "' and '", c.y, "'");
  require<FileError>((cr < 0) == (cc < 0), path.string(), ": has column '", cr < 0 ? c.col : c.row, "' but not '",
                     cr < 0 ? c.row : c.col, "'");

  TaxelLayout l;
  l.dim = cx < 0 ? 0 : (cz < 0 ? 2 : 3);
  std::map<std::string, int> part_of;
  std::map<std::pair<int, std::string>, int> group_of;
  std::unordered_map<long long, int> id_line;
  const std::size_t width = header ? rows[0].fields.size() : fallback.size();
  for (std::size_t r = header ? 1 : 0; r < rows.size(); ++r) {
    const auto& row = rows[r];
    const auto at = detail::where(path, row.line);
    require<FileError>(row.fields.size() == width, at, row.fields.size(), " fields, expected ", width,
                       header ? " (as many as the header)" : "");
    const auto& f = row.fields;
    const long long id = ci >= 0 ? detail::parse_integer(path, row.line, c.id, f[ci]) : static_cast<long long>(l.size());
    require<FileError>(id >= 0 && id <= 2147483647LL, at, "id ", id, " is out of range [0, 2^31)");
    const auto [it, fresh] = id_line.emplace(id, row.line);
    require<FileError>(fresh, at, "duplicate taxel id ", id, " (first on line ", it->second, ")");
    l.ids.push_back(static_cast<int>(id));
    const int axes[3] = {cx, cy, cz};
    const std::string* axis_names[3] = {&c.x, &c.y, &c.z};
    for (int a = 0; a < l.dim; ++a) {
      const double v = detail::parse_real(path, row.line, *axis_names[a], f[axes[a]]);
      require<FileError>(std::isfinite(v), at, "taxel ", id, " has a non-finite coordinate ", *axis_names[a], " = ", f[axes[a]]);
      l.coords.push_back(v);
    }
    const std::string part_name = cp >= 0 ? f[cp] : "skin";
    require<FileError>(!part_name.empty(), at, "empty part name");
    const auto pit = part_of.emplace(part_name, static_cast<int>(l.part_names.size())).first;
    if (pit->second == static_cast<int>(l.part_names.size())) l.part_names.push_back(part_name);
    const int p = pit->second;
    const std::string group_name = cg >= 0 ? f[cg] : part_name;
    require<FileError>(!group_name.empty(), at, "empty group name");
    const auto git = group_of.emplace(std::pair{p, group_name}, static_cast<int>(l.group_names.size())).first;
    if (git->second == static_cast<int>(l.group_names.size())) {
      l.group_names.push_back(group_name);
      l.group_part.push_back(p);
    }
    l.part.push_back(p);
    l.group.push_back(git->second);
    if (cr >= 0) {
      auto cell = [&](int k, const std::string& name) {
        if (f[k].empty()) return -1;
        const long long v = detail::parse_integer(path, row.line, name, f[k]);
        require<FileError>(v >= -1 && v < 1000000, at, "column '", name, "': ", v, " is not a cell index (or -1)");
        return static_cast<int>(v);
      };
      l.row.push_back(cell(cr, c.row));
      l.col.push_back(cell(cc, c.col));
    }
  }
  require<FileError>(l.size() > 0, path.string(), ": no taxels (empty layout)");
  l.validate();
  return l;
}

// The edges of an edge CSV, as indices into `layout` (whose ids the file names).
inline std::vector<Edge> read_edges_csv(const std::filesystem::path& path, const TaxelLayout& layout,
                                        const EdgeCsvColumns& c = {}) {
  const auto rows = detail::read_csv_rows(path);
  std::vector<Edge> edges;
  if (rows.empty()) return edges;
  std::map<std::string, int> col;
  const bool header = detail::csv_columns(rows, {c.src, c.dst, c.weight},
                                          rows[0].fields.size() >= 3 ? std::vector<std::string>{c.src, c.dst, c.weight}
                                                                     : std::vector<std::string>{c.src, c.dst},
                                          col);
  require<FileError>(col.count(c.src) && col.count(c.dst), path.string(), ": no '", c.src, "' and '", c.dst, "' columns");
  require<FileError>(header || rows[0].fields.size() >= 2, detail::where(path, rows[0].line), "no header row naming the columns (",
                     c.src, ", ", c.dst, "[, ", c.weight, "]), and ", rows[0].fields.size(),
                     " field(s) where a header-less edge file has 2 or 3 (src,dst[,weight])");
  const int cs = col.at(c.src), cd = col.at(c.dst), cw = col.count(c.weight) ? col.at(c.weight) : -1;
  std::unordered_map<long long, int> index;
  for (int i = 0; i < layout.size(); ++i) index.emplace(layout.ids[i], i);
  std::set<std::pair<int, int>> seen;
  const std::size_t width = rows[0].fields.size();
  for (std::size_t r = header ? 1 : 0; r < rows.size(); ++r) {
    const auto& row = rows[r];
    const auto at = detail::where(path, row.line);
    require<FileError>(row.fields.size() == width, at, row.fields.size(), " fields, expected ", width);
    const long long a = detail::parse_integer(path, row.line, c.src, row.fields[cs]);
    const long long b = detail::parse_integer(path, row.line, c.dst, row.fields[cd]);
    require<FileError>(index.count(a), at, "edge to an unknown taxel: id ", a, " is not in the layout");
    require<FileError>(index.count(b), at, "edge to an unknown taxel: id ", b, " is not in the layout");
    require<FileError>(a != b, at, "self loop on taxel ", a);
    const int i = index.at(a), j = index.at(b);
    require<FileError>(seen.emplace(std::min(i, j), std::max(i, j)).second, at, "duplicate edge ", a, " -- ", b);
    double w;
    if (cw >= 0 && !row.fields[cw].empty()) {
      w = detail::parse_real(path, row.line, c.weight, row.fields[cw]);
      require<FileError>(std::isfinite(w) && w >= 0, at, "edge ", a, " -- ", b, " has weight ", row.fields[cw],
                         ", expected a finite value >= 0");
    } else {
      w = layout.has_coords() ? layout.distance(i, j) : 1.0;
    }
    edges.push_back({i, j, w});
  }
  return edges;
}

inline Skin read_skin_csv(const std::filesystem::path& nodes, const std::filesystem::path& edges,
                          const NodeCsvColumns& nc = {}, const EdgeCsvColumns& ec = {}) {
  TaxelLayout l = read_layout_csv(nodes, nc);
  const auto e = read_edges_csv(edges, l, ec);
  return make_skin(std::move(l), e);
}

inline std::string layout_csv_string(const TaxelLayout& l) {
  l.validate();
  std::string out = "id";
  if (l.dim >= 2) out += ",x,y";
  if (l.dim == 3) out += ",z";
  out += ",part,group";
  if (l.has_cells()) out += ",row,col";
  out += "\n";
  for (int i = 0; i < l.size(); ++i) {
    out += std::to_string(l.ids[i]);
    for (int a = 0; a < l.dim; ++a) out += "," + detail::format_real(l.coord(i, a));
    out += "," + detail::csv_field(l.part_names[l.part[i]]) + "," + detail::csv_field(l.group_names[l.group[i]]);
    if (l.has_cells()) out += "," + std::to_string(l.row[i]) + "," + std::to_string(l.col[i]);
    out += "\n";
  }
  return out;
}

inline std::string edges_csv_string(const TaxelLayout& l, const TaxelGraph& g) {
  require<ShapeError>(g.num_nodes() == l.size(), "edges_csv_string: graph has ", g.num_nodes(), " nodes, layout ", l.size());
  std::string out = "src,dst,weight\n";
  for (const Edge& e : g.edges())
    out += std::to_string(l.ids[e.src]) + "," + std::to_string(l.ids[e.dst]) + "," + detail::format_real(e.weight) + "\n";
  return out;
}

inline void write_layout_csv(const std::filesystem::path& path, const TaxelLayout& l) {
  write_file_atomic(path, layout_csv_string(l));
}
inline void write_edges_csv(const std::filesystem::path& path, const TaxelLayout& l, const TaxelGraph& g) {
  write_file_atomic(path, edges_csv_string(l, g));
}
inline void write_skin_csv(const std::filesystem::path& nodes, const std::filesystem::path& edges, const Skin& s) {
  write_layout_csv(nodes, s.layout);
  write_edges_csv(edges, s.layout, s.graph);
}

}  // namespace tjepa
