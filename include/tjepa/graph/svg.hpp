#pragma once
// SVG drawings of a layout and its graph, to check a layout by eye and to draw masks.
//
// Taxels are discs at their coordinates (x right, y up; 3-D layouts are projected on x-y), edges
// are lines (bridges, i.e. edges between groups, dashed). A taxel's fill, by priority:
//   options.fill[i]   a CSS colour per taxel ("" = light grey), e.g. the masks a sampler drew;
//   options.value[i]  a number per taxel through viridis (NaN = light grey);
//   options.color_by  its group or its part, from a categorical palette.
// Highlights outline sets of taxels (a ring around each), e.g. context and targets, with a legend.
//
//   tjepa::SvgOptions o;
//   o.fill.assign(n, "#dddddd");  for (int i : context) o.fill[i] = "#1f77b4";
//   o.highlights.push_back({target0, "#d62728", "target 0"});
//   tjepa::write_svg("mask.svg", skin, o);
//
// Layouts without coordinates are drawn from (row, col) with groups side by side, or, without
// cells, as one square block of taxels per group.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "tjepa/core/atomic_write.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/graph/colors.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/taxel_graph.hpp"
#include "tjepa/layout/taxel_layout.hpp"

namespace tjepa {

enum class SvgColorBy { group, part };

struct SvgHighlight {
  std::vector<int> taxels;         // taxel indices to outline
  std::string color = "#d62728";   // CSS stroke colour
  std::string label;               // legend entry ("" = none)
};

struct SvgOptions {
  std::vector<std::string> fill;   // [N] CSS colours; wins over value and color_by when non-empty
  std::vector<double> value;       // [N] values drawn through viridis; NaN = no value
  double value_min = std::numeric_limits<double>::quiet_NaN();  // colormap range; NaN: data range
  double value_max = std::numeric_limits<double>::quiet_NaN();
  SvgColorBy color_by = SvgColorBy::group;
  std::vector<SvgHighlight> highlights;
  bool draw_edges = true;
  bool group_labels = false;       // write each group's name at its centroid
  std::string title;
  double px_per_mm = 0.0;          // drawing scale (coordinates are in mm); 0: 4, or what keeps a
                                   // taxel radius at least 4 px and the drawing at most 2000 px wide
  double radius = 0.0;             // taxel radius in mm; 0: 0.4 x the shortest edge
};

// s with &, <, >, " and ' escaped for XML text and attributes.
inline std::string xml_escape(std::string_view s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

namespace detail {


inline std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

}  // namespace detail

// [N, 2] drawing positions (mm): the coordinates' x-y, or a tiling of the groups when the layout
// has no coordinates (cells at 1 mm pitch, groups side by side with 2 mm gaps).
inline std::vector<double> drawing_positions(const TaxelLayout& l) {
  const int n = l.size();
  std::vector<double> pos(static_cast<std::size_t>(n) * 2);
  if (l.has_coords()) {
    for (int i = 0; i < n; ++i) {
      pos[2 * i] = l.coord(i, 0);
      pos[2 * i + 1] = l.coord(i, 1);
    }
    // Parts drawn in one frame (two feet, two hands over each other) are laid out side by side:
    // a part whose box overlaps an earlier part's moves right of them all.
    const int P = l.num_parts();
    std::vector<std::array<double, 4>> box(static_cast<std::size_t>(P), {1e300, 1e300, -1e300, -1e300});
    for (int i = 0; i < n; ++i) {
      auto& b = box[static_cast<std::size_t>(l.part[i])];
      b = {std::min(b[0], pos[2 * i]), std::min(b[1], pos[2 * i + 1]), std::max(b[2], pos[2 * i]),
           std::max(b[3], pos[2 * i + 1])};
    }
    double right = -1e300;
    bool overlap = false;
    for (int p = 1; p < P && !overlap; ++p)
      for (int q = 0; q < p && !overlap; ++q) {
        const auto &a = box[static_cast<std::size_t>(p)], &b = box[static_cast<std::size_t>(q)];
        overlap = a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3];
      }
    if (!overlap) return pos;
    std::vector<double> shift(static_cast<std::size_t>(P), 0.0);
    for (int p = 0; p < P; ++p) {
      const auto& b = box[static_cast<std::size_t>(p)];
      const double width = b[2] - b[0];
      if (p > 0) shift[static_cast<std::size_t>(p)] = right + 0.15 * std::max(width, 1e-9) - b[0];
      right = b[2] + shift[static_cast<std::size_t>(p)];
    }
    for (int i = 0; i < n; ++i) pos[2 * i] += shift[static_cast<std::size_t>(l.part[i])];
    return pos;
  }
  double x0 = 0;
  for (int g = 0; g < l.num_groups(); ++g) {
    const auto t = l.taxels_of_group(g);
    const bool cells = l.has_cells() && std::all_of(t.begin(), t.end(), [&](int i) { return l.row[i] >= 0 && l.col[i] >= 0; });
    const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(t.size()))));
    int width = 0;
    for (std::size_t k = 0; k < t.size(); ++k) {
      const int r = cells ? l.row[t[k]] : static_cast<int>(k) / side;
      const int c = cells ? l.col[t[k]] : static_cast<int>(k) % side;
      pos[2 * t[k]] = x0 + c;
      pos[2 * t[k] + 1] = r;
      width = std::max(width, c + 1);
    }
    x0 += width + 2;
  }
  return pos;
}

// The SVG document. graph may be null (no edges drawn).
inline std::string svg_string(const TaxelLayout& l, const TaxelGraph* graph, const SvgOptions& o = {}) {
  l.validate();
  const int n = l.size();
  require<ShapeError>(graph == nullptr || graph->num_nodes() == n, "svg_string: graph has ",
                      graph ? graph->num_nodes() : 0, " nodes, expected the layout's ", n);
  require<ShapeError>(o.fill.empty() || static_cast<int>(o.fill.size()) == n, "svg_string: fill has ",
                      o.fill.size(), " colours, expected one per taxel (", n, ")");
  require<ShapeError>(o.value.empty() || static_cast<int>(o.value.size()) == n, "svg_string: value has ",
                      o.value.size(), " entries, expected one per taxel (", n, ")");
  require<ConfigError>(o.px_per_mm >= 0 && std::isfinite(o.px_per_mm), "svg_string: px_per_mm ", o.px_per_mm,
                       ", expected > 0 (or 0: automatic)");
  for (const auto& h : o.highlights)
    for (int i : h.taxels)
      require<DataError>(i >= 0 && i < n, "svg_string: highlight '", h.label, "' names taxel ", i,
                         ", expected indices in [0, ", n, ")");
  const auto pos = drawing_positions(l);

  // Radius: 0.4 x the shortest edge (or nearest-neighbour distance without a graph).
  double r = o.radius;
  if (r <= 0) {
    double dmin = std::numeric_limits<double>::infinity();
    auto dist = [&](int a, int b) { return std::hypot(pos[2 * a] - pos[2 * b], pos[2 * a + 1] - pos[2 * b + 1]); };
    if (graph && graph->num_edges() > 0) {
      for (const Edge& e : graph->edges())
        if (dist(e.src, e.dst) > 0) dmin = std::min(dmin, dist(e.src, e.dst));
    } else {
      for (int a = 0; a < n; ++a)
        for (int b = a + 1; b < n; ++b)
          if (dist(a, b) > 0) dmin = std::min(dmin, dist(a, b));
    }
    r = std::isfinite(dmin) ? 0.4 * dmin : 1.0;
  }
  double xmin = std::numeric_limits<double>::infinity(), ymin = xmin, xmax = -xmin, ymax = -xmin;
  for (int i = 0; i < n; ++i) {
    xmin = std::min(xmin, pos[2 * i]);
    xmax = std::max(xmax, pos[2 * i]);
    ymin = std::min(ymin, pos[2 * i + 1]);
    ymax = std::max(ymax, pos[2 * i + 1]);
  }
  double s = o.px_per_mm;
  if (s <= 0) {  // automatic: coordinates in cm or m stay readable, a large sheet fits a screen
    s = 4.0;
    if (r * s < 4.0) s = 4.0 / r;
    const double extent = std::max(xmax - xmin, ymax - ymin);
    if (extent * s > 2000.0) s = 2000.0 / std::max(extent, 1e-12);
  }
  const double margin = 20.0 + 2 * r * s, title_h = o.title.empty() ? 0.0 : 28.0;

  // Fill colours and the legend entries that explain them.
  std::vector<std::string> fill(n);
  std::vector<std::pair<std::string, std::string>> legend;  // (colour, label), swatches
  std::string colorbar;                                     // value range text
  if (!o.fill.empty()) {
    for (int i = 0; i < n; ++i) fill[i] = o.fill[i].empty() ? "#dddddd" : o.fill[i];
  } else if (!o.value.empty()) {
    double lo = o.value_min, hi = o.value_max;
    if (std::isnan(lo) || std::isnan(hi)) {
      double dlo = std::numeric_limits<double>::infinity(), dhi = -dlo;
      for (double v : o.value)
        if (std::isfinite(v)) dlo = std::min(dlo, v), dhi = std::max(dhi, v);
      if (std::isnan(lo)) lo = std::isfinite(dlo) ? dlo : 0.0;
      if (std::isnan(hi)) hi = std::isfinite(dhi) ? dhi : 1.0;
    }
    const double span = hi > lo ? hi - lo : 1.0;
    for (int i = 0; i < n; ++i) fill[i] = viridis(std::isnan(o.value[i]) ? o.value[i] : (o.value[i] - lo) / span);
    legend.emplace_back(viridis(0.0), "min " + detail::fmt(lo));
    legend.emplace_back(viridis(1.0), "max " + detail::fmt(hi));
  } else if (o.color_by == SvgColorBy::part) {
    for (int i = 0; i < n; ++i) fill[i] = category_color(l.part[i]);
    for (int p = 0; p < l.num_parts(); ++p) legend.emplace_back(category_color(p), l.part_names[p]);
  } else {
    for (int i = 0; i < n; ++i) fill[i] = category_color(l.group[i]);
    if (l.num_groups() <= 24)
      for (int g = 0; g < l.num_groups(); ++g) legend.emplace_back(category_color(g), l.group_names[g]);
  }
  int legend_rows = static_cast<int>(legend.size());
  for (const auto& h : o.highlights) legend_rows += !h.label.empty();
  const double legend_w = legend_rows > 0 ? 170.0 : 0.0;

  const double width = (xmax - xmin) * s + 2 * margin + legend_w;
  const double height = std::max((ymax - ymin) * s + 2 * margin + title_h, title_h + 20.0 * legend_rows + 2 * margin);
  auto X = [&](double x) { return detail::fmt((x - xmin) * s + margin); };
  auto Y = [&](double y) { return detail::fmt((ymax - y) * s + margin + title_h); };

  std::string out;
  out.reserve(static_cast<std::size_t>(n) * 160 + 4096);
  out += "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + detail::fmt(width) + "\" height=\"" +
         detail::fmt(height) + "\" viewBox=\"0 0 " + detail::fmt(width) + " " + detail::fmt(height) +
         "\" font-family=\"sans-serif\">\n";
  out += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  if (!o.title.empty())
    out += "<text x=\"" + detail::fmt(margin) + "\" y=\"20\" font-size=\"16\">" + xml_escape(o.title) + "</text>\n";
  if (graph && o.draw_edges) {
    out += "<g class=\"edges\" stroke-linecap=\"round\">\n";
    for (const Edge& e : graph->edges()) {
      const bool bridge = l.group[e.src] != l.group[e.dst];
      out += "<line x1=\"" + X(pos[2 * e.src]) + "\" y1=\"" + Y(pos[2 * e.src + 1]) + "\" x2=\"" +
             X(pos[2 * e.dst]) + "\" y2=\"" + Y(pos[2 * e.dst + 1]) +
             (bridge ? "\" stroke=\"#444\" stroke-width=\"1.2\" stroke-dasharray=\"3 2\"/>\n"
                     : "\" stroke=\"#999\" stroke-width=\"0.8\"/>\n");
    }
    out += "</g>\n";
  }
  out += "<g class=\"taxels\" stroke=\"#333\" stroke-width=\"0.5\">\n";
  const std::string rad = detail::fmt(r * s);
  for (int i = 0; i < n; ++i)
    out += "<circle cx=\"" + X(pos[2 * i]) + "\" cy=\"" + Y(pos[2 * i + 1]) + "\" r=\"" + rad + "\" fill=\"" +
           fill[i] + "\"><title>taxel " + std::to_string(l.ids[i]) + " (" +
           xml_escape(l.group_names[l.group[i]]) + ")</title></circle>\n";
  out += "</g>\n";
  for (std::size_t h = 0; h < o.highlights.size(); ++h) {
    const auto& hl = o.highlights[h];
    // Nested rings when several highlights share a taxel: highlight h sits h rings further out.
    const std::string hr = detail::fmt(r * s + 2.0 + 2.5 * static_cast<double>(h));
    out += "<g class=\"highlight\" fill=\"none\" stroke=\"" + hl.color + "\" stroke-width=\"2\">\n";
    for (int i : hl.taxels)
      out += "<circle cx=\"" + X(pos[2 * i]) + "\" cy=\"" + Y(pos[2 * i + 1]) + "\" r=\"" + hr + "\"/>\n";
    out += "</g>\n";
  }
  if (o.group_labels) {
    out += "<g class=\"labels\" font-size=\"10\" text-anchor=\"middle\" fill=\"#000\">\n";
    for (int g = 0; g < l.num_groups(); ++g) {
      const auto t = l.taxels_of_group(g);
      double cx = 0, cy = 0;
      for (int i : t) cx += pos[2 * i], cy += pos[2 * i + 1];
      cx /= static_cast<double>(t.size());
      cy /= static_cast<double>(t.size());
      out += "<text x=\"" + X(cx) + "\" y=\"" + Y(cy) + "\" stroke=\"white\" stroke-width=\"3\" paint-order=\"stroke\">" +
             xml_escape(l.group_names[g]) + "</text>\n";
    }
    out += "</g>\n";
  }
  if (legend_rows > 0) {
    const double lx = (xmax - xmin) * s + 2 * margin;
    double ly = margin + title_h;
    out += "<g class=\"legend\" font-size=\"12\">\n";
    for (const auto& [colour, label] : legend) {
      out += "<circle cx=\"" + detail::fmt(lx + 6) + "\" cy=\"" + detail::fmt(ly) + "\" r=\"6\" fill=\"" + colour +
             "\" stroke=\"#333\" stroke-width=\"0.5\"/><text x=\"" + detail::fmt(lx + 18) + "\" y=\"" +
             detail::fmt(ly + 4) + "\">" + xml_escape(label) + "</text>\n";
      ly += 20;
    }
    for (const auto& hl : o.highlights) {
      if (hl.label.empty()) continue;
      out += "<circle cx=\"" + detail::fmt(lx + 6) + "\" cy=\"" + detail::fmt(ly) + "\" r=\"6\" fill=\"none\" stroke=\"" +
             hl.color + "\" stroke-width=\"2\"/><text x=\"" + detail::fmt(lx + 18) + "\" y=\"" + detail::fmt(ly + 4) +
             "\">" + xml_escape(hl.label) + "</text>\n";
      ly += 20;
    }
    out += "</g>\n";
  }
  out += "</svg>\n";
  return out;
}

inline std::string svg_string(const Skin& skin, const SvgOptions& o = {}) {
  return svg_string(skin.layout, &skin.graph, o);
}

// Writes the drawing to `path` atomically.
inline void write_svg(const std::filesystem::path& path, const TaxelLayout& l, const TaxelGraph* graph,
                      const SvgOptions& o = {}) {
  write_file_atomic(path, svg_string(l, graph, o));
}
inline void write_svg(const std::filesystem::path& path, const Skin& skin, const SvgOptions& o = {}) {
  write_svg(path, skin.layout, &skin.graph, o);
}

}  // namespace tjepa
