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
// row and col (optional; empty or -1: none), column (optional: the recording's taxel slot this
// taxel reads, when the sensor's driver writes another order than the file's; TaxelLayout::column).
// Taxels of one part at the same coordinates are an error naming both lines. A header without the
// default names may use the reference's socks names (global_node_id, visual_x, visual_y, side,
// section; src_global_node_id, dst_global_node_id, visual_distance: detail::node_column_aliases). Parts are numbered in order of first appearance,
// groups by (part, name) in order of first appearance. Without a header row, fields are read in
// the writer's order: id,x,y[,z],part,group[,row,col] (5 to 8 fields). Errors name the file, the
// line and what was wrong. The writers emit exactly what the readers read back.
#include <algorithm>
#include <filesystem>
#include <initializer_list>
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
  std::string id = "id", x = "x", y = "y", z = "z", part = "part", group = "group", row = "row", col = "col",
              column = "column";
};

struct EdgeCsvColumns {
  std::string src = "src", dst = "dst", weight = "weight";
};

// The column names of a layout CSV and its edges CSV.
struct LayoutCsvColumns {
  NodeCsvColumns nodes;
  EdgeCsvColumns edges;
};

// Column names from "key=name,..." (node keys id, x, y, z, part, group, row, col, column; edge
// keys src, dst, weight), e.g. for the reference's socks files "id=global_node_id,x=visual_x,
// y=visual_y,part=side,src=src_global_node_id,dst=dst_global_node_id,weight=visual_distance".
// Empty: the defaults.
inline LayoutCsvColumns parse_csv_columns(const std::string& spec) {
  LayoutCsvColumns c;
  NodeCsvColumns& n = c.nodes;
  EdgeCsvColumns& e = c.edges;
  std::size_t at = 0;
  while (at < spec.size()) {
    const std::size_t end = std::min(spec.find(',', at), spec.size());
    const std::string item = spec.substr(at, end - at);
    const std::size_t eq = item.find('=');
    require<ConfigError>(eq != std::string::npos && eq > 0 && eq + 1 < item.size(), "layout columns '", spec,
                         "': '", item, "' is not key=name");
    const std::string key = item.substr(0, eq), name = item.substr(eq + 1);
    std::string* field = key == "id" ? &n.id : key == "x" ? &n.x : key == "y" ? &n.y : key == "z" ? &n.z
                       : key == "part" ? &n.part : key == "group" ? &n.group : key == "row" ? &n.row
                       : key == "col" ? &n.col : key == "column" ? &n.column : key == "src" ? &e.src
                       : key == "dst" ? &e.dst : key == "weight" ? &e.weight : nullptr;
    require<ConfigError>(field != nullptr, "layout columns '", spec, "': unknown key '", key,
                         "', expected id, x, y, z, part, group, row, col, column, src, dst or weight");
    *field = name;
    at = end + 1;
  }
  return c;
}

namespace detail {

// Other files' names for a column, tried when the configured name is the default and the header
// does not have it: the Tactile-JEPA reference's socks files (global_node_id, visual_x, visual_y,
// side, section; src_global_node_id, dst_global_node_id, visual_distance) and common spellings.
inline void apply_column_aliases(const std::vector<std::string>& header, std::string& name, const char* standard,
                                 std::initializer_list<const char*> aliases) {
  auto has = [&](const std::string& n) { return std::find(header.begin(), header.end(), n) != header.end(); };
  if (name != standard || has(name)) return;
  for (const char* a : aliases)
    if (has(a)) {
      name = a;
      return;
    }
}

inline NodeCsvColumns node_column_aliases(const std::vector<std::string>& header, NodeCsvColumns c) {
  apply_column_aliases(header, c.id, "id", {"global_node_id", "node_id", "taxel_id"});
  apply_column_aliases(header, c.x, "x", {"visual_x", "pos_x"});
  apply_column_aliases(header, c.y, "y", {"visual_y", "pos_y"});
  apply_column_aliases(header, c.z, "z", {"visual_z", "pos_z"});
  apply_column_aliases(header, c.part, "part", {"side", "hand"});
  apply_column_aliases(header, c.group, "group", {"section", "pad", "region"});
  return c;
}

inline EdgeCsvColumns edge_column_aliases(const std::vector<std::string>& header, EdgeCsvColumns c) {
  apply_column_aliases(header, c.src, "src", {"src_global_node_id", "source", "src_id"});
  apply_column_aliases(header, c.dst, "dst", {"dst_global_node_id", "target", "dst_id"});
  apply_column_aliases(header, c.weight, "weight", {"visual_distance", "distance", "length"});
  return c;
}

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

inline TaxelLayout read_layout_csv(const std::filesystem::path& path, const NodeCsvColumns& columns = {}) {
  const auto rows = detail::read_csv_rows(path);
  require<FileError>(!rows.empty(), path.string(), ": no taxels (empty layout)");
  const NodeCsvColumns c = detail::node_column_aliases(rows[0].fields, columns);
  std::vector<std::string> fallback;
  switch (rows[0].fields.size()) {
    case 5: fallback = {c.id, c.x, c.y, c.part, c.group}; break;
    case 6: fallback = {c.id, c.x, c.y, c.z, c.part, c.group}; break;
    case 7: fallback = {c.id, c.x, c.y, c.part, c.group, c.row, c.col}; break;
    case 8: fallback = {c.id, c.x, c.y, c.z, c.part, c.group, c.row, c.col}; break;
    default: break;
  }
  std::map<std::string, int> col;
  const bool header =
      detail::csv_columns(rows, {c.id, c.x, c.y, c.z, c.part, c.group, c.row, c.col, c.column}, fallback, col);
  require<FileError>(header || !fallback.empty(), detail::where(path, rows[0].line), "no header row naming the columns (",
                     c.id, ", ", c.x, ", ", c.y, ", ", c.part, ", ", c.group, ", ...), and ", rows[0].fields.size(),
                     " fields where a header-less file has 5 to 8 (id,x,y[,z],part,group[,row,col])");
  auto find = [&](const std::string& n) { return col.count(n) ? col.at(n) : -1; };
  const int ci = find(c.id), cx = find(c.x), cy = find(c.y), cz = find(c.z), cp = find(c.part), cg = find(c.group),
            cr = find(c.row), cc = find(c.col), cn = find(c.column);
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
  std::map<std::pair<int, std::vector<double>>, std::pair<long long, int>> place;  // (part, x) -> (id, line)
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
    if (l.dim > 0) {
      std::vector<double> x(l.coords.end() - l.dim, l.coords.end());
      const auto [same, fresh_place] = place.emplace(std::pair{p, std::move(x)}, std::pair{id, row.line});
      require<FileError>(fresh_place, at, "taxel ", id, " has the same coordinates as taxel ", same->second.first,
                         " (line ", same->second.second, ") in part '", part_name, "'");
    }
    if (cn >= 0) {
      const long long v = detail::parse_integer(path, row.line, c.column, f[cn]);
      require<FileError>(v >= 0 && v < 1000000000LL, at, "column '", c.column, "': ", v, " is not a column index");
      l.column.push_back(static_cast<int>(v));
    }
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
  try {
    l.validate();
  } catch (const Error& e) {
    fail<FileError>(path.string(), ": ", e.what());
  }
  return l;
}

// The edges of an edge CSV, as indices into `layout` (whose ids the file names).
inline std::vector<Edge> read_edges_csv(const std::filesystem::path& path, const TaxelLayout& layout,
                                        const EdgeCsvColumns& columns = {}) {
  const auto rows = detail::read_csv_rows(path);
  std::vector<Edge> edges;
  if (rows.empty()) return edges;
  const EdgeCsvColumns c = detail::edge_column_aliases(rows[0].fields, columns);
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

// An order CSV: for each taxel id of `layout`, the recording's column it is read from ("id,column"
// rows, a header optional). Every id once, every column in [0, N) once. Returns TaxelLayout::column.
inline std::vector<int> read_taxel_order_csv(const std::filesystem::path& path, const TaxelLayout& layout) {
  const auto rows = detail::read_csv_rows(path);
  require<FileError>(!rows.empty(), path.string(), ": empty order file, expected id,column rows");
  const bool header = rows[0].fields.size() == 2 && rows[0].fields[0] == "id" && rows[0].fields[1] == "column";
  std::unordered_map<long long, int> index;
  for (int i = 0; i < layout.size(); ++i) index.emplace(layout.ids[i], i);
  const int n = layout.size();
  std::vector<int> column(static_cast<std::size_t>(n), -1), line_of_column(static_cast<std::size_t>(n), 0);
  for (std::size_t r = header ? 1 : 0; r < rows.size(); ++r) {
    const auto& row = rows[r];
    const auto at = detail::where(path, row.line);
    require<FileError>(row.fields.size() == 2, at, row.fields.size(), " fields, expected 2 (id,column)");
    const long long id = detail::parse_integer(path, row.line, "id", row.fields[0]);
    const long long c = detail::parse_integer(path, row.line, "column", row.fields[1]);
    require<FileError>(index.count(id), at, "taxel id ", id, " is not in the layout");
    require<FileError>(c >= 0 && c < n, at, "column ", c, ", expected in [0, ", n, ")");
    const int i = index.at(id);
    require<FileError>(column[static_cast<std::size_t>(i)] < 0, at, "taxel id ", id, " is given twice");
    require<FileError>(line_of_column[static_cast<std::size_t>(c)] == 0, at, "column ", c, " is already read by line ",
                       line_of_column[static_cast<std::size_t>(c)]);
    column[static_cast<std::size_t>(i)] = static_cast<int>(c);
    line_of_column[static_cast<std::size_t>(c)] = row.line;
  }
  for (int i = 0; i < n; ++i)
    require<FileError>(column[static_cast<std::size_t>(i)] >= 0, path.string(), ": no column for taxel id ", layout.ids[i],
                       " (the order file must name all ", n, " taxels)");
  return column;
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
  if (l.has_columns()) out += ",column";
  out += "\n";
  for (int i = 0; i < l.size(); ++i) {
    auto field = [&out](const std::string& f) {
      out += ',';
      out += f;
    };
    out += std::to_string(l.ids[i]);
    for (int a = 0; a < l.dim; ++a) field(detail::format_real(l.coord(i, a)));
    field(detail::csv_field(l.part_names[l.part[i]]));
    field(detail::csv_field(l.group_names[l.group[i]]));
    if (l.has_cells()) field(std::to_string(l.row[i])), field(std::to_string(l.col[i]));
    if (l.has_columns()) field(std::to_string(l.column[i]));
    out += '\n';
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
