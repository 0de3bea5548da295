// Layouts: the builders, the built-in skins (counts and structure pinned), CSV files.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace {

std::vector<int> sorted_neighbors(const tjepa::TaxelGraph& g, int i) {
  std::vector<int> v(g.neighbors(i).begin(), g.neighbors(i).end());
  std::sort(v.begin(), v.end());
  return v;
}

// True when the given nodes induce a connected subgraph of g.
bool induces_connected(const tjepa::TaxelGraph& g, const std::vector<int>& nodes) {
  if (nodes.empty()) return false;
  std::set<int> in(nodes.begin(), nodes.end()), seen{nodes[0]};
  std::vector<int> stack{nodes[0]};
  while (!stack.empty()) {
    const int u = stack.back();
    stack.pop_back();
    for (int v : g.neighbors(u))
      if (in.count(v) && seen.insert(v).second) stack.push_back(v);
  }
  return seen.size() == in.size();
}

int group_id(const tjepa::TaxelLayout& l, const std::string& name) {
  auto it = std::find(l.group_names.begin(), l.group_names.end(), name);
  REQUIRE(it != l.group_names.end());
  return static_cast<int>(it - l.group_names.begin());
}

}  // namespace

TEST_SUITE("graph") {
  TEST_CASE("grid pads: 4- and 8-neighbour edges between live cells, pitch weights") {
    tjepa::GridPad pad(3, 4, 2.0, 3.0);
    auto e4 = tjepa::grid_edges(pad, pad.cell_index());
    CHECK(e4.size() == 3u * 3 + 2u * 4);
    for (const auto& e : e4) CHECK((e.weight == 2.0 || e.weight == 3.0));
    pad.eight_neighbours = true;
    auto e8 = tjepa::grid_edges(pad, pad.cell_index());
    CHECK(e8.size() == e4.size() + 2u * 2 * 3);
    CHECK(std::count_if(e8.begin(), e8.end(), [](const tjepa::Edge& e) {
            return std::abs(e.weight - std::sqrt(13.0)) < 1e-12;
          }) == 12);
    // A mask: a 3 x 3 ring (centre dead) has 8 taxels and 8 edges, one cycle.
    auto ring = tjepa::GridPad(3, 3).with_live({1, 1, 1, 1, 0, 1, 1, 1, 1});
    CHECK(ring.num_live() == 8);
    auto er = tjepa::grid_edges(ring, ring.cell_index());
    CHECK(er.size() == 8u);
    tjepa::TaxelGraph g(8, er);
    for (int i = 0; i < 8; ++i) CHECK(g.degree(i) == 2);
    CHECK(g.num_components() == 1);
  }

  TEST_CASE("grid pads and builders reject bad input") {
    auto bad = tjepa::GridPad(2, 2).with_live({1, 1, 1});
    CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("live mask has 3 cells"), tjepa::ShapeError);
    auto empty = tjepa::GridPad(2, 2).with_live({0, 0, 0, 0});
    CHECK_THROWS_WITH_AS(empty.validate(), doctest::Contains("empty pad"), tjepa::DataError);
    tjepa::GridPad zero(0, 2);
    CHECK_THROWS_AS(zero.validate(), tjepa::ConfigError);
    tjepa::GridPad neg(2, 2, -1.0);
    CHECK_THROWS_WITH_AS(neg.validate(), doctest::Contains("pitch -1"), tjepa::ConfigError);

    tjepa::LayoutBuilder b;
    const int p = b.add_part("p");
    const int g0 = b.add_grid_pad("a", p, tjepa::GridPad(1, 2), {0, 0});
    const int g1 = b.add_grid_pad("b", p, tjepa::GridPad(1, 1), {0, 5});
    CHECK_THROWS_WITH_AS(b.add_bridges({{g0, g1}}, 3), doctest::Contains("larger than the 2 candidate"),
                         tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(b.add_bridges({{g0, g0}}, 1), doctest::Contains("to itself"), tjepa::ConfigError);
    CHECK_THROWS_AS(b.add_bridges({{g0, 9}}, 1), tjepa::ConfigError);
    CHECK_THROWS_AS(b.add_group("x", 3), tjepa::ConfigError);
    b.add_bridges({{g0, g1}}, 2);
    auto skin = b.build();
    CHECK(skin.graph.num_edges() == 3u);
    CHECK(skin.graph.num_components() == 1);

    tjepa::LayoutBuilder empty_part;
    empty_part.add_part("used");
    empty_part.add_part("unused");
    empty_part.add_grid_pad("g", 0, tjepa::GridPad(2, 2));
    CHECK_THROWS_WITH_AS(empty_part.build(), doctest::Contains("'unused' has no taxels (empty part)"),
                         tjepa::DataError);
    tjepa::LayoutBuilder nothing;
    CHECK_THROWS_WITH_AS(nothing.build(), doctest::Contains("empty layout"), tjepa::DataError);
  }

  TEST_CASE("TaxelLayout::validate names duplicate ids, NaN coordinates and foreign groups") {
    tjepa::LayoutBuilder b;
    const int p = b.add_part("p");
    b.add_grid_pad("g", p, tjepa::GridPad(2, 2));
    tjepa::TaxelLayout l = b.layout();
    CHECK_NOTHROW(l.validate());
    auto dup = l;
    dup.ids[2] = dup.ids[0];
    CHECK_THROWS_WITH_AS(dup.validate(), doctest::Contains("duplicate taxel id 0"), tjepa::DataError);
    auto nan = l;
    nan.coords[3] = std::nan("");
    CHECK_THROWS_WITH_AS(nan.validate(), doctest::Contains("non-finite coordinate"), tjepa::DataError);
    auto foreign = l;
    foreign.part_names.push_back("q");
    foreign.group_names.push_back("h");
    foreign.group_part.push_back(1);
    foreign.part[1] = 1;
    CHECK_THROWS_WITH_AS(foreign.validate(), doctest::Contains("belongs to part 'p'"), tjepa::DataError);
    auto range = l;
    range.group[0] = 7;
    CHECK_THROWS_WITH_AS(range.validate(), doctest::Contains("has group 7"), tjepa::DataError);
  }

  TEST_CASE("Allegro/Xela: 368 taxels, 18 pads in the reference order, 570 + 68 edges, 1 component") {
    const auto skin = tjepa::layouts::allegro_xela();
    const auto& l = skin.layout;
    const auto& g = skin.graph;
    CHECK(l.size() == 368);
    CHECK(g.num_nodes() == 368);
    CHECK(l.num_parts() == 1);
    CHECK(l.num_groups() == 18);
    CHECK(g.num_groups() == 18);
    CHECK(g.num_components() == 1);
    CHECK(g.num_edges() == 638u);

    // Pads in order: thumb tip, thumb pads; index, middle, ring tip-to-base; palm. Taxels of a pad
    // are contiguous.
    const std::vector<std::string> order = {
        "thumb_tip", "thumb_1",  "thumb_2",  "index_tip", "index_1",  "index_2",
        "index_3",   "middle_tip", "middle_1", "middle_2", "middle_3", "ring_tip",
        "ring_1",    "ring_2",   "ring_3",   "palm_0",    "palm_1",   "palm_2"};
    CHECK(l.group_names == order);
    for (int i = 1; i < l.size(); ++i) CHECK(l.group[i] >= l.group[i - 1]);
    std::map<int, int> size;
    for (int i = 0; i < l.size(); ++i) ++size[l.group[i]];
    for (int pad = 0; pad < 18; ++pad) {
      const std::string& n = order[pad];
      const int want = n.ends_with("_tip") ? 30 : n.starts_with("palm") ? 24 : 16;
      CHECK_MESSAGE(size[pad] == want, n);
    }

    // 570 intra-pad edges: 48 per fingertip, 24 per phalanx pad, 38 per palm pad.
    std::map<int, int> intra;
    std::map<std::pair<int, int>, int> bridges;
    for (const auto& e : g.edges()) {
      const int a = l.group[e.src], c = l.group[e.dst];
      if (a == c) ++intra[a];
      else ++bridges[{std::min(a, c), std::max(a, c)}];
      CHECK(e.weight == doctest::Approx(l.distance(e.src, e.dst)));
      CHECK(e.weight > 0);
    }
    int total_intra = 0;
    for (int pad = 0; pad < 18; ++pad) {
      const std::string& n = order[pad];
      const int want = n.ends_with("_tip") ? 48 : n.starts_with("palm") ? 38 : 24;
      CHECK_MESSAGE(intra[pad] == want, n);
      total_intra += intra[pad];
    }
    CHECK(total_intra == 570);

    // 17 adjacent pad pairs, k = 4 bridges each.
    const std::vector<std::pair<std::string, std::string>> adjacent = {
        {"thumb_tip", "thumb_1"}, {"thumb_1", "thumb_2"}, {"thumb_2", "palm_0"},
        {"index_tip", "index_1"}, {"index_1", "index_2"}, {"index_2", "index_3"}, {"index_3", "palm_0"},
        {"middle_tip", "middle_1"}, {"middle_1", "middle_2"}, {"middle_2", "middle_3"}, {"middle_3", "palm_1"},
        {"ring_tip", "ring_1"}, {"ring_1", "ring_2"}, {"ring_2", "ring_3"}, {"ring_3", "palm_2"},
        {"palm_0", "palm_1"}, {"palm_1", "palm_2"}};
    CHECK(bridges.size() == 17u);
    for (const auto& [a, c] : adjacent) {
      const int ga = group_id(l, a), gc = group_id(l, c);
      const std::pair<int, int> key(std::min(ga, gc), std::max(ga, gc));
      INFO(a, "-", c);
      CHECK(bridges[key] == 4);
    }
    // Bridges join physically close taxels (the drawing keeps adjacent pads within ~15 mm).
    for (const auto& e : g.edges())
      if (l.group[e.src] != l.group[e.dst]) CHECK(e.weight < 16.0);
    // The pad sizes of the reference: phalanx pitch 4.667 mm.
    const int i1 = l.taxels_of_group(group_id(l, "index_1"))[0];
    CHECK(g.weights(i1)[0] == doctest::Approx(4.667));
  }

  TEST_CASE("Allegro/Xela: every neighbourhood on a fingertip's irregular rows") {
    const auto skin = tjepa::layouts::allegro_xela();
    const auto& l = skin.layout;
    // Fingertip cells in taxel order: rows 0-3 full (0..23), row 4 cols 1-4 (24..27), row 5 cols
    // 2-3 (28, 29). Neighbours (local indices) of the taxels of rows 3-5; they have no bridges.
    std::vector<std::pair<int, int>> cells;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 6; ++c) cells.emplace_back(r, c);
    for (int c = 1; c <= 4; ++c) cells.emplace_back(4, c);
    cells.emplace_back(5, 2);
    cells.emplace_back(5, 3);
    const std::map<int, std::vector<int>> expected = {
        {18, {12, 19}},         {19, {13, 18, 20, 24}}, {20, {14, 19, 21, 25}}, {21, {15, 20, 22, 26}},
        {22, {16, 21, 23, 27}}, {23, {17, 22}},         {24, {19, 25}},         {25, {20, 24, 26, 28}},
        {26, {21, 25, 27, 29}}, {27, {22, 26}},         {28, {25, 29}},         {29, {26, 28}}};
    for (const char* tip : {"thumb_tip", "index_tip", "middle_tip", "ring_tip"}) {
      const auto taxels = l.taxels_of_group(group_id(l, tip));
      REQUIRE(taxels.size() == 30u);
      const int first = taxels[0];
      for (int k = 0; k < 30; ++k) {
        CHECK(taxels[k] == first + k);
        CHECK(l.row[first + k] == cells[k].first);
        CHECK(l.col[first + k] == cells[k].second);
      }
      for (const auto& [k, nb] : expected) {
        std::vector<int> want;
        for (int v : nb) want.push_back(first + v);
        CHECK_MESSAGE(sorted_neighbors(skin.graph, first + k) == want, tip, " local taxel ", k);
      }
      // Row 5 is the tip: farther from the next pad than row 0.
      const int next = l.taxels_of_group(group_id(l, tip) + 1)[0];
      CHECK(l.distance(first + 29, next) > l.distance(first, next));
    }
  }

  TEST_CASE("generic grid skin: a sheet cut into blocks") {
    const auto s = tjepa::layouts::grid_skin();  // 12 x 16 at 4 mm, 4 x 4 blocks
    CHECK(s.size() == 192);
    CHECK(s.graph.num_edges() == 12u * 15 + 11u * 16);
    CHECK(s.layout.num_groups() == 12);
    CHECK(s.graph.num_components() == 1);
    for (int gidx = 0; gidx < 12; ++gidx) {
      CHECK(s.layout.taxels_of_group(gidx).size() == 16u);
      CHECK(induces_connected(s.graph, s.layout.taxels_of_group(gidx)));
    }
    for (const auto& e : s.graph.edges()) CHECK(e.weight == 4.0);
    tjepa::layouts::GridSkinOptions o;
    o.rows = 5;
    o.cols = 7;
    o.pitch = 1.0;
    o.group_rows = 2;
    o.group_cols = 3;
    o.eight_neighbours = true;
    const auto s8 = tjepa::layouts::grid_skin(o);
    CHECK(s8.graph.num_edges() == 5u * 6 + 4u * 7 + 2u * 4 * 6);
    CHECK(s8.layout.num_groups() == 3 * 3);
    CHECK(s8.layout.taxels_of_group(8).size() == 1u);  // the 1 x 1 corner block
  }

  TEST_CASE("generic two-part skin: two irregular parts, two components, connected groups") {
    const auto s = tjepa::layouts::two_part_skin();
    const auto& l = s.layout;
    CHECK(l.num_parts() == 2);
    CHECK(s.graph.num_parts() == 2);
    CHECK(s.graph.num_components() == 2);
    const auto left = l.taxels_of_part(0), right = l.taxels_of_part(1);
    CHECK(left.size() != right.size());
    CHECK(left.size() < 14u * 8);  // irregular: a masked grid
    CHECK(s.graph.component_size(s.graph.component(left[0])) == static_cast<int>(left.size()));
    CHECK(s.graph.component(left[0]) != s.graph.component(right[0]));
    CHECK(l.num_groups() == 6);
    for (int gidx = 0; gidx < 6; ++gidx) {
      const auto t = l.taxels_of_group(gidx);
      CHECK(t.size() >= 8u);
      CHECK_MESSAGE(induces_connected(s.graph, t), l.group_names[gidx]);
      for (int i : t) CHECK(l.part[i] == l.group_part[gidx]);
    }
  }
}
