#pragma once
// tjepa layout: draw a built-in or CSV layout, its graph, groups or sampled masks to SVG;
// print a summary (or JSON), export the layout with its order.
#include <CLI/CLI.hpp>

#include <cstdint>
#include <iostream>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/tjepa.hpp>

#include "output.hpp"
#include "setup.hpp"

namespace tjepa::cli {

struct LayoutOptions {
  std::string layout = "allegro";  // built-in name or CSV path
  std::string edges;               // edges CSV of a CSV layout ("": inferred)
  std::string columns;             // the layout CSV's column names, "x=visual_x,y=visual_y"
  std::string bridges = "connect"; // inferred graphs: connect | near | none
  std::string order;               // taxel column order: "", xserver, reference, or an id,column CSV
  std::string export_csv;          // write the layout (order included) here, its edges beside it
  bool strict = false;             // graph warnings are errors
  std::string svg;                 // output SVG ("" = none)
  std::string draw = "graph";      // graph | groups | parts | masks
  std::uint64_t seed = 0;          // masks: which batch to draw
  bool json = false;               // machine-readable summary
  bool force = false;
};

inline int run_layout(const LayoutOptions& o, std::ostream& out) {
  std::ostringstream warnings;
  const Skin skin = load_skin({o.layout, o.edges, o.columns, o.bridges, o.order, o.strict}, &warnings);
  if (!o.json) out << warnings.str();
  const TaxelGraph& g = skin.graph;
  int bridges = 0;
  for (const Edge& e : g.edges()) bridges += skin.layout.group[e.src] != skin.layout.group[e.dst];
  nlohmann::json j = {{"layout", o.layout},         {"taxels", g.num_nodes()},          {"edges", g.num_edges()},
                      {"bridges", bridges},         {"parts", skin.layout.num_parts()}, {"groups", skin.layout.num_groups()},
                      {"components", g.num_components()}};
  j["warnings"] = nlohmann::json::array();
  std::istringstream warning_lines(warnings.str());
  for (std::string line; std::getline(warning_lines, line);) j["warnings"].push_back(line);
  SvgOptions svg;
  svg.title = o.layout + ": " + std::to_string(g.num_nodes()) + " taxels";
  if (o.draw == "groups") {
    svg.color_by = SvgColorBy::group;
    svg.group_labels = true;
  } else if (o.draw == "parts") {
    svg.color_by = SvgColorBy::part;
  } else if (o.draw == "masks") {
    const MaskCollator collator(g);
    const MaskBatch m = collator.sample(1, o.seed, 0);
    svg.fill.assign(static_cast<std::size_t>(g.num_nodes()), "#dddddd");
    for (int i : m.context_row(0)) svg.fill[static_cast<std::size_t>(i)] = "#1f77b4";
    static const char* colors[] = {"#d62728", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2"};
    nlohmann::json targets = nlohmann::json::array();
    for (int k = 0; k < m.num_targets(); ++k) {
      const TargetSet& t = m.targets[static_cast<std::size_t>(k)];
      const auto row = t.row(0);
      svg.highlights.push_back({std::vector<int>(row.begin(), row.end()), colors[k % 6],
                                std::string(to_string(t.kind)) + " target " + std::to_string(k)});
      targets.push_back({{"kind", to_string(t.kind)}, {"size", t.size}});
    }
    svg.title += ", context (blue) and targets";
    j["masks"] = {{"context", m.K}, {"targets", targets}};
  } else {
    require<ConfigError>(o.draw == "graph", "--draw '", o.draw, "', expected graph, groups, parts or masks");
  }
  const std::string export_edges =
      o.export_csv.empty() ? std::string() : (std::filesystem::path(o.export_csv).replace_extension(".edges.csv")).string();
  if (!o.svg.empty() || !o.export_csv.empty()) {
    OutputFiles files;
    if (!o.svg.empty()) {
      OutputFiles::check_new(o.svg, o.force);
      write_file_atomic(files.add(o.svg), svg_string(skin, svg));
      j["svg"] = o.svg;
    }
    if (!o.export_csv.empty()) {
      require<ConfigError>(std::filesystem::path(o.export_csv).extension() == ".csv", "--export '", o.export_csv,
                           "', expected a .csv file name");
      OutputFiles::check_new(o.export_csv, o.force);
      OutputFiles::check_new(export_edges, o.force);
      write_layout_csv(files.add(o.export_csv), skin.layout);
      write_edges_csv(files.add(export_edges), skin.layout, skin.graph);
      j["export"] = {{"layout", o.export_csv}, {"edges", export_edges}};
    }
    files.commit();
  }
  if (o.json) {
    out << j.dump(2) << '\n';
    return 0;
  }
  out << "layout " << o.layout << ": " << g.num_nodes() << " taxels, " << g.num_edges() << " edges (" << bridges
      << " between groups), " << skin.layout.num_parts() << " part(s), " << skin.layout.num_groups()
      << " group(s), " << g.num_components() << " component(s)\n";
  if (j.contains("masks")) {
    out << "masks (seed " << o.seed << "): context " << j["masks"]["context"].get<int>() << " tokens; targets";
    for (const auto& t : j["masks"]["targets"]) out << ' ' << t["kind"].get<std::string>() << ':' << t["size"].get<int>();
    out << '\n';
  }
  if (!o.svg.empty()) out << "wrote " << o.svg << '\n';
  if (!o.export_csv.empty())
    out << "wrote " << o.export_csv << " and " << export_edges << " (read them back with --layout " << o.export_csv
        << " --edges " << export_edges << ")\n";
  return 0;
}


// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_layout_command(CLI::App& app, LayoutOptions& o) {
  CLI::App* sub = app.add_subcommand("layout", "Draw a layout, its graph, groups or sampled masks; print a summary");
  sub->add_option("layout", o.layout, "built-in layout (allegro, grid, two-part) or layout CSV")->capture_default_str();
  sub->add_option("--svg", o.svg, "write an SVG drawing here");
  sub->add_option("--draw", o.draw, "graph | groups | parts | masks")->capture_default_str();
  sub->add_option("--mask-seed", o.seed, "seed of the drawn masks");
  sub->add_flag("--json", o.json, "machine-readable summary on stdout");
  sub->add_flag("--force", o.force, "overwrite the SVG / exported files");
  sub->add_option("--edges", o.edges, "edges CSV of a layout CSV (src,dst[,weight]); default: inferred");
  sub->add_option("--layout-columns", o.columns, "the layout CSV's column names, e.g. x=visual_x,y=visual_y");
  sub->add_option("--bridges", o.bridges, "inferred graphs: connect | near | none")->capture_default_str();
  sub->add_option("--order", o.order, "recordings' taxel order: xserver | reference (allegro) | id,column CSV");
  sub->add_option("--export", o.export_csv, "write the layout as CSV (order included), its edges to *.edges.csv");
  sub->add_flag("--strict", o.strict, "warnings about the graph are errors");
  return sub;
}

}  // namespace tjepa::cli
