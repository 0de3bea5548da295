#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

}  // namespace

TEST_SUITE("graph") {
  TEST_CASE("TaxelGraph stores a CSR with sorted neighbours, parts and components") {
    // Two parts: a path 0-1-2 and an edge 3-4.
    std::vector<tjepa::Edge> e = {{1, 0, 1.0}, {1, 2, 2.0}, {4, 3, 0.5}};
    tjepa::TaxelGraph g(5, e, {0, 0, 0, 1, 1});
    CHECK(g.num_nodes() == 5);
    CHECK(g.num_edges() == 3);
    CHECK(g.degree(1) == 2);
    CHECK(std::vector<int>(g.neighbors(1).begin(), g.neighbors(1).end()) == std::vector<int>{0, 2});
    CHECK(g.weights(1)[1] == 2.0);
    CHECK(g.num_parts() == 2);
    CHECK(g.num_components() == 2);
    CHECK(g.component(0) == g.component(2));
    CHECK(g.component(3) != g.component(0));
    CHECK(g.component_size(g.component(4)) == 2);
    auto back = g.edges();
    CHECK(back.size() == 3);
    CHECK(back[0] == tjepa::Edge{0, 1, 1.0});
  }

  TEST_CASE("TaxelGraph rejects bad input with a message that names it") {
    std::vector<tjepa::Edge> none;
    CHECK_THROWS_WITH_AS(tjepa::TaxelGraph(0, none), doctest::Contains("empty layout"), tjepa::DataError);
    std::vector<tjepa::Edge> unknown = {{0, 7, 1.0}};
    CHECK_THROWS_WITH_AS(tjepa::TaxelGraph(3, unknown), doctest::Contains("unknown taxel"), tjepa::DataError);
    std::vector<tjepa::Edge> loop = {{1, 1, 1.0}};
    CHECK_THROWS_WITH_AS(tjepa::TaxelGraph(3, loop), doctest::Contains("self loop"), tjepa::DataError);
    std::vector<tjepa::Edge> neg = {{0, 1, -1.0}};
    CHECK_THROWS_WITH_AS(tjepa::TaxelGraph(3, neg), doctest::Contains("weight -1"), tjepa::DataError);
    std::vector<tjepa::Edge> nan = {{0, 1, std::nan("")}};
    CHECK_THROWS_AS(tjepa::TaxelGraph(3, nan), tjepa::DataError);
    std::vector<tjepa::Edge> dup = {{0, 1, 1.0}, {1, 0, 1.0}};
    CHECK_THROWS_WITH_AS(tjepa::TaxelGraph(3, dup), doctest::Contains("duplicate edge"), tjepa::DataError);
    CHECK_THROWS_AS(tjepa::TaxelGraph(3, none, {0, 1}), tjepa::ShapeError);
  }

  TEST_CASE("SVG: one disc per taxel, one line per edge, bridges dashed, fills and highlights") {
    const auto skin = tjepa::layouts::allegro_xela();
    const int n = skin.size();
    const std::string svg = tjepa::svg_string(skin);
    CHECK(svg.starts_with("<svg "));
    CHECK(svg.ends_with("</svg>\n"));
    CHECK(count(svg, "<circle cx") == static_cast<std::size_t>(n) + 18);  // taxels + legend swatches
    CHECK(count(svg, "<line ") == skin.graph.num_edges());
    CHECK(count(svg, "stroke-dasharray") == 68u);  // the bridges
    CHECK(count(svg, ">palm_2<") == 1u);            // legend names the groups

    tjepa::SvgOptions o;
    o.fill.assign(n, "");
    for (int i = 0; i < 10; ++i) o.fill[i] = "#123456";
    o.highlights.push_back({{0, 1, 2}, "#abcdef", "target <0>"});
    o.highlights.push_back({{2, 3}, "#fedcba", ""});
    o.title = "mask";
    const std::string m = tjepa::svg_string(skin, o);
    CHECK(count(m, "fill=\"#123456\"") == 10u);
    CHECK(count(m, "fill=\"#dddddd\"") == static_cast<std::size_t>(n - 10));
    CHECK(count(m, "stroke=\"#abcdef\"") == 2u);  // the group and its legend swatch
    CHECK(count(m, "target &lt;0&gt;") == 1u);
    CHECK(count(m, "<circle cx") == static_cast<std::size_t>(n) + 3 + 2 + 1);

    tjepa::SvgOptions v;
    v.value.resize(n);
    for (int i = 0; i < n; ++i) v.value[i] = i;
    v.value[5] = std::nan("");
    const std::string vs = tjepa::svg_string(skin, v);
    CHECK(count(vs, tjepa::viridis(0.0)) >= 2u);   // taxel 0 and the legend
    CHECK(count(vs, tjepa::viridis(1.0)) >= 2u);
    CHECK(count(vs, "fill=\"#dddddd\"") == 1u);   // the NaN

    tjepa::SvgOptions bad;
    bad.fill.assign(3, "red");
    CHECK_THROWS_WITH_AS(tjepa::svg_string(skin, bad), doctest::Contains("fill has 3 colours"), tjepa::ShapeError);
    tjepa::SvgOptions bad_h;
    bad_h.highlights.push_back({{n}, "red", "x"});
    CHECK_THROWS_WITH_AS(tjepa::svg_string(skin, bad_h), doctest::Contains("names taxel 368"), tjepa::DataError);
  }

  TEST_CASE("SVG: layouts without coordinates are drawn from their cells") {
    auto skin = tjepa::layouts::two_part_skin();
    skin.layout.dim = 0;
    skin.layout.coords.clear();
    const auto pos = tjepa::drawing_positions(skin.layout);
    for (int i = 0; i < skin.size(); ++i) CHECK(pos[2 * i + 1] == skin.layout.row[i]);
    tjepa::SvgOptions o;
    o.color_by = tjepa::SvgColorBy::part;
    const std::string svg = tjepa::svg_string(skin, o);
    CHECK(count(svg, tjepa::category_color(1)) == static_cast<std::size_t>(skin.layout.taxels_of_part(1).size()) + 1);
  }

  TEST_CASE("colors: viridis ends and categorical cycling") {
    CHECK(tjepa::viridis(0.0) == "#440154");
    CHECK(tjepa::viridis(1.0) == "#fde725");
    CHECK(tjepa::viridis(-3.0) == "#440154");
    CHECK(tjepa::category_color(0) == tjepa::category_color(20));
    CHECK(tjepa::category_color(0) != tjepa::category_color(1));
  }

  TEST_CASE("docs/allegro_layout.svg is the library's current drawing of the Allegro layout") {
    // TJEPA_UPDATE_DOCS=1 rewrites the committed picture; otherwise it must match.
    const std::filesystem::path doc = std::filesystem::path(TJEPA_SOURCE_DIR) / "docs" / "allegro_layout.svg";
    tjepa::SvgOptions o;
    o.title = "Xela uSkin on the Allegro hand: 368 taxels, 18 pads, 638 edges (dashed: bridges)";
    o.group_labels = true;
    const std::string svg = tjepa::svg_string(tjepa::layouts::allegro_xela(), o);
    if (std::getenv("TJEPA_UPDATE_DOCS")) {
      std::filesystem::create_directories(doc.parent_path());
      tjepa::write_svg(doc, tjepa::layouts::allegro_xela(), o);
    }
    CHECK(slurp(doc) == svg);
  }
}
