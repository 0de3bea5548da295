// Layouts: the builders, the built-in skins (counts and structure pinned), CSV files.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace {

std::vector<int> sorted_neighbors(const tjepa::TaxelGraph& g, int i) {
  std::vector<int> v(g.neighbors(i).begin(), g.neighbors(i).end());
  std::sort(v.begin(), v.end());
  return v;
}


// A fresh scratch directory per test run, removed at exit.
std::filesystem::path scratch() {
  struct Dir {
    std::filesystem::path path = std::filesystem::temp_directory_path() / ("tjepa_graph_" + std::to_string(::getpid()));
    Dir() { std::filesystem::create_directories(path); }
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path;
}

std::filesystem::path write_text(const std::string& name, const std::string& text) {
  const auto p = scratch() / name;
  std::ofstream(p, std::ios::binary) << text;
  return p;
}

void check_same_skin(const tjepa::Skin& a, const tjepa::Skin& b) {
  CHECK(a.layout.dim == b.layout.dim);
  CHECK(a.layout.ids == b.layout.ids);
  CHECK(a.layout.coords == b.layout.coords);  // bit-exact
  CHECK(a.layout.part == b.layout.part);
  CHECK(a.layout.group == b.layout.group);
  CHECK(a.layout.row == b.layout.row);
  CHECK(a.layout.col == b.layout.col);
  CHECK(a.layout.part_names == b.layout.part_names);
  CHECK(a.layout.group_names == b.layout.group_names);
  CHECK(a.layout.group_part == b.layout.group_part);
  CHECK(a.graph.edges() == b.graph.edges());  // weights bit-exact
}

int group_id(const tjepa::TaxelLayout& l, const std::string& name) {
  auto it = std::find(l.group_names.begin(), l.group_names.end(), name);
  REQUIRE(it != l.group_names.end());
  return static_cast<int>(it - l.group_names.begin());
}

}  // namespace

TEST_SUITE("sensors") {
  TEST_CASE("grid pads: 4- and 8-neighbour edges between live cells - pitch weights") {
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

  TEST_CASE("Allegro/Xela: 368 taxels - 18 pads in the reference order - 570 + 68 edges - 1 component") {
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

    // The reference's 17 pad pairs, k = 4 bridges each.
    const std::vector<std::pair<std::string, std::string>> adjacent = {
        {"thumb_tip", "thumb_1"}, {"thumb_1", "thumb_2"}, {"thumb_2", "palm_1"},
        {"index_tip", "index_1"}, {"index_1", "index_2"}, {"index_2", "index_3"}, {"index_3", "palm_0"},
        {"middle_tip", "middle_1"}, {"middle_1", "middle_2"}, {"middle_2", "middle_3"}, {"middle_3", "palm_0"},
        {"ring_tip", "ring_1"}, {"ring_1", "ring_2"}, {"ring_2", "ring_3"}, {"ring_3", "palm_2"},
        {"palm_0", "palm_1"}, {"palm_0", "palm_2"}};
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
      CHECK(tjepa::induces_connected(s.graph, s.layout.taxels_of_group(gidx)));
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

  TEST_CASE("generic two-part skin: two irregular parts - two components - connected groups") {
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
      CHECK_MESSAGE(tjepa::induces_connected(s.graph, t), l.group_names[gidx]);
      for (int i : t) CHECK(l.part[i] == l.group_part[gidx]);
    }
  }

  TEST_CASE("Inspire hand: 1062 taxels - 17 regions - 4-neighbour regions bridged - one component") {
    using tjepa::layouts::inspire::Side;
    for (Side side : {Side::left, Side::right}) {
      const auto s = tjepa::layouts::inspire_hand(side);
      const auto& l = s.layout;
      CHECK(l.size() == 1062);
      CHECK(l.num_parts() == 1);
      CHECK(l.part_names[0] == (side == Side::left ? "left" : "right"));
      CHECK(l.num_groups() == 17);
      CHECK(s.graph.num_components() == 1);
      // Region shapes of the reference implementation (E-Kovtun/tactile,
      // tactile_ssl/data/deco_geometry.py), in the documented order.
      const std::vector<std::tuple<std::string, int, int>> shapes = {
          {"little_tip", 3, 3}, {"little_nail", 12, 8}, {"little_pad", 10, 8},
          {"ring_tip", 3, 3},   {"ring_nail", 12, 8},   {"ring_pad", 10, 8},
          {"middle_tip", 3, 3}, {"middle_nail", 12, 8}, {"middle_pad", 10, 8},
          {"index_tip", 3, 3},  {"index_nail", 12, 8},  {"index_pad", 10, 8},
          {"thumb_tip", 3, 3},  {"thumb_nail", 12, 8},  {"thumb_middle", 3, 3},
          {"thumb_pad", 12, 8}, {"palm", 8, 14}};
      std::size_t intra_expected = 0;
      for (int gi = 0; gi < 17; ++gi) {
        const auto& [name, rows, cols] = shapes[gi];
        CHECK(l.group_names[gi] == name);
        const auto t = l.taxels_of_group(gi);
        CHECK(t.size() == static_cast<std::size_t>(rows * cols));
        CHECK(*std::max_element(l.row.begin() + t.front(), l.row.begin() + t.back() + 1) == rows - 1);
        CHECK(*std::max_element(l.col.begin() + t.front(), l.col.begin() + t.back() + 1) == cols - 1);
        intra_expected += static_cast<std::size_t>(rows * (cols - 1) + cols * (rows - 1));
      }
      CHECK(intra_expected == 1874u);
      std::size_t intra = 0;
      std::map<std::pair<int, int>, int> bridges;
      for (const auto& e : s.graph.edges()) {
        if (l.group[e.src] == l.group[e.dst]) ++intra;
        else ++bridges[{std::min(l.group[e.src], l.group[e.dst]), std::max(l.group[e.src], l.group[e.dst])}];
        CHECK(e.weight == doctest::Approx(l.distance(e.src, e.dst)));
      }
      CHECK(intra == intra_expected);
      CHECK(bridges.size() == 16u);  // 4 fingers x 3 + thumb 4
      for (const auto& [pair, k] : bridges) CHECK(k == 4);
      for (int f = 0; f < 4; ++f) {  // tip-nail, nail-pad, pad-palm
        CHECK(bridges.count({3 * f, 3 * f + 1}) == 1);
        CHECK(bridges.count({3 * f + 1, 3 * f + 2}) == 1);
        CHECK(bridges.count({3 * f + 2, 16}) == 1);
      }
      for (int k = 12; k < 16; ++k) CHECK(bridges.count({k, k + 1}) == 1);
    }
  }

  TEST_CASE("Inspire two hands: 2124 taxels in two parts - two components - regions named per hand") {
    const auto s = tjepa::layouts::inspire_hands();
    const auto& l = s.layout;
    CHECK(l.size() == 2124);
    CHECK(l.part_names == std::vector<std::string>{"left", "right"});
    CHECK(l.num_groups() == 34);
    CHECK(l.group_names[16] == "left/palm");
    CHECK(l.group_names[17] == "right/little_tip");
    CHECK(s.graph.num_components() == 2);
    for (int i = 0; i < 2124; ++i) {
      CHECK(l.part[i] == (i < 1062 ? 0 : 1));
      CHECK(l.ids[i] == i);
    }
    CHECK(s.graph.component_size(s.graph.component(0)) == 1062);
    CHECK(s.graph.num_edges() == 2u * (1874 + 64));
    for (const auto& e : s.graph.edges()) CHECK(l.part[e.src] == l.part[e.dst]);
    // The hands are drawn apart: the right hand lies 20 mm or more to the right of the left.
    double left_max = -1e9, right_min = 1e9;
    for (int i = 0; i < 1062; ++i) left_max = std::max(left_max, l.coord(i, 0));
    for (int i = 1062; i < 2124; ++i) right_min = std::min(right_min, l.coord(i, 0));
    CHECK(right_min - left_max > 20.0);
  }

  TEST_CASE("join_skins renumbers parts - groups and ids and rejects mismatched input") {
    const tjepa::Skin parts[2] = {tjepa::layouts::grid_skin(), tjepa::layouts::two_part_skin()};
    const std::string names[2] = {"sheet", "socks"};
    const auto j = tjepa::join_skins(parts, names);
    CHECK(j.size() == parts[0].size() + parts[1].size());
    CHECK(j.layout.part_names == std::vector<std::string>{"sheet", "socks/left", "socks/right"});
    CHECK(j.layout.group_names[12] == "socks/left/heel");
    CHECK(j.graph.num_components() == 3);
    CHECK(j.graph.num_edges() == parts[0].graph.num_edges() + parts[1].graph.num_edges());
    CHECK(j.layout.ids[parts[0].size()] == parts[0].size());
    const std::string one[1] = {"x"};
    CHECK_THROWS_WITH_AS(tjepa::join_skins(parts, one), doctest::Contains("1 names for 2 skins"), tjepa::ShapeError);
  }

  TEST_CASE("CSV round trip is exact for every built-in layout") {
    using tjepa::layouts::inspire::Side;
    const std::vector<std::pair<std::string, tjepa::Skin>> skins = {
        {"allegro", tjepa::layouts::allegro_xela()},
        {"inspire", tjepa::layouts::inspire_hands()},
        {"inspire_left", tjepa::layouts::inspire_hand(Side::left)},
        {"two_part", tjepa::layouts::two_part_skin()},
        {"grid", tjepa::layouts::grid_skin()}};
    for (const auto& [name, s] : skins) {
      INFO(name);
      const auto nodes = scratch() / (name + "_nodes.csv"), edges = scratch() / (name + "_edges.csv");
      tjepa::write_skin_csv(nodes, edges, s);
      const auto back = tjepa::read_skin_csv(nodes, edges);
      check_same_skin(s, back);
      // And once more: the written text is a fixed point.
      CHECK(tjepa::layout_csv_string(back.layout) == tjepa::layout_csv_string(s.layout));
    }
  }

  TEST_CASE("CSV: header - comments - blank lines - extra and reordered columns - quotes - custom names") {
    const auto nodes = write_text("n.csv",
                                  "# a small skin\n"
                                  "\n"
                                  "note, group ,taxel,y,x,part\n"
                                  "first,\"pad, A\",10,0,0,hand\n"
                                  "  ,\"pad, A\",11,0,3,hand   \n"
                                  "# between\n"
                                  "x,\"B \"\"q\"\"\",12,4,3,hand\n"
                                  "y,C,20,0,0,foot\n");
    tjepa::NodeCsvColumns nc;
    nc.id = "taxel";
    const auto l = tjepa::read_layout_csv(nodes, nc);
    CHECK(l.size() == 4);
    CHECK(l.ids == std::vector<int>{10, 11, 12, 20});
    CHECK(l.dim == 2);
    CHECK(l.coord(1, 0) == 3.0);
    CHECK(l.coord(2, 1) == 4.0);
    CHECK(l.part_names == std::vector<std::string>{"hand", "foot"});
    CHECK(l.group_names == std::vector<std::string>{"pad, A", "B \"q\"", "C"});
    CHECK(l.group_part == std::vector<int>{0, 0, 1});
    CHECK(!l.has_cells());
    // Edges by id; no weight column: the coordinate distance.
    const auto edges = write_text("e.csv", "src,dst\n10,11\n# c\n11,12\n");
    const auto e = tjepa::read_edges_csv(edges, l);
    REQUIRE(e.size() == 2u);
    CHECK(e[0].src == 0);
    CHECK(e[0].dst == 1);
    CHECK(e[0].weight == 3.0);
    CHECK(e[1].weight == 4.0);
    // A weight column with an empty cell falls back to the distance too.
    const auto we = tjepa::read_edges_csv(write_text("we.csv", "src,dst,weight\n10,11,\n11,12,0.5\n"), l);
    CHECK(we[0].weight == 3.0);
    CHECK(we[1].weight == 0.5);
    // Quoted names survive a round trip.
    tjepa::write_layout_csv(scratch() / "n2.csv", l);
    const auto l2 = tjepa::read_layout_csv(scratch() / "n2.csv");
    CHECK(l2.group_names == l.group_names);
    CHECK(l2.ids == l.ids);
    // Without coordinates, part or group: one part "skin", weights 1.
    const auto bare = tjepa::read_layout_csv(write_text("bare.csv", "id,extra\n0,a\n1,b\n2,c\n"));
    CHECK(bare.dim == 0);
    CHECK(bare.part_names == std::vector<std::string>{"skin"});
    CHECK(bare.num_groups() == 1);
    const auto be = tjepa::read_edges_csv(write_text("be.csv", "0,1\n1,2\n"), bare);  // header-less
    CHECK(be.size() == 2u);
    CHECK(be[1].weight == 1.0);
    // Header-less nodes in the writer's order: id,x,y,part,group,row,col.
    const auto hl = tjepa::read_layout_csv(write_text("hl.csv", "5,1.5,2,h,g,0,1\n6,1.5,3,h,g,1,1\n"));
    CHECK(hl.ids == std::vector<int>{5, 6});
    CHECK(hl.row == std::vector<int>{0, 1});
    CHECK(hl.col == std::vector<int>{1, 1});
    CHECK(hl.coord(1, 1) == 3.0);
  }

  TEST_CASE("CSV errors name the file - the line and the problem") {
    auto fails = [](const std::filesystem::path& nodes, const std::string& what) {
      INFO(what);
      CHECK_THROWS_WITH_AS(tjepa::read_layout_csv(nodes), doctest::Contains(what.c_str()), tjepa::FileError);
    };
    fails(scratch() / "missing.csv", "missing.csv: cannot open");
    fails(write_text("empty.csv", "# nothing\n\n"), "no taxels (empty layout)");
    fails(write_text("header_only.csv", "id,x,y\n"), "no taxels (empty layout)");
    fails(write_text("dup.csv", "id,x,y\n0,0,0\n1,1,0\n0,2,0\n"), "dup.csv:4: duplicate taxel id 0 (first on line 2)");
    fails(write_text("nan.csv", "id,x,y\n0,0,0\n1,nan,0\n"), "nan.csv:3: taxel 1 has a non-finite coordinate x");
    fails(write_text("word.csv", "id,x,y\n0,zero,0\n"), "word.csv:2: column 'x': 'zero' is not a number");
    fails(write_text("badid.csv", "id,x,y\n1.5,0,0\n"), "badid.csv:2: column 'id': '1.5' is not an integer");
    fails(write_text("width.csv", "id,x,y\n0,0,0\n1,0\n"), "width.csv:3: 2 fields, expected 3");
    fails(write_text("xonly.csv", "id,x\n0,0\n"), "has column 'x' but not 'y'");
    fails(write_text("quote.csv", "id,group\n0,\"open\n"), "quote.csv:2: unterminated quote");
    fails(write_text("noname.csv", "id,part\n0,\n"), "noname.csv:2: empty part name");
    fails(write_text("nohdr.csv", "0,1\n"), "no header row");

    const auto l = tjepa::read_layout_csv(write_text("ok.csv", "id,x,y\n0,0,0\n1,1,0\n2,2,0\n"));
    auto edge_fails = [&](const std::string& name, const std::string& text, const std::string& what) {
      INFO(what);
      CHECK_THROWS_WITH_AS(tjepa::read_edges_csv(write_text(name, text), l), doctest::Contains(what.c_str()), tjepa::FileError);
    };
    edge_fails("unknown.csv", "src,dst\n0,1\n1,9\n", "unknown.csv:3: edge to an unknown taxel: id 9");
    edge_fails("loop.csv", "src,dst\n2,2\n", "loop.csv:2: self loop on taxel 2");
    edge_fails("neg.csv", "src,dst,weight\n0,1,-2\n", "neg.csv:2: edge 0 -- 1 has weight -2");
    edge_fails("nanw.csv", "src,dst,weight\n0,1,nan\n", "nanw.csv:2: edge 0 -- 1 has weight nan");
    edge_fails("dupe.csv", "src,dst\n0,1\n1,0\n", "dupe.csv:3: duplicate edge 1 -- 0");
    edge_fails("cols.csv", "a,b,weight\n0,1,1\n", "no 'src' and 'dst' columns");
    // Fuzzing finding 1: a header-less file whose first row has one field (the 1-byte file "1").
    edge_fails("one.csv", "1", "one.csv:1: no header row naming the columns");
    edge_fails("one_field.csv", "0\n1\n", "1 field(s) where a header-less edge file has 2 or 3");
    CHECK(tjepa::read_edges_csv(write_text("none.csv", "# no edges\n"), l).empty());
  }

  TEST_CASE("kNN and radius graphs from coordinates - inside parts unless asked") {
    const auto grid = tjepa::layouts::grid_skin();  // 12 x 16 at 4 mm
    const auto r4 = tjepa::radius_edges(grid.layout, 4.0);
    CHECK(r4.size() == grid.graph.num_edges());
    CHECK(tjepa::make_graph(grid.layout, r4).edges() == grid.graph.edges());
    CHECK(tjepa::radius_edges(grid.layout, 4.0 * std::sqrt(2.0) + 1e-9).size() == 356u + 2u * 11 * 15);

    const auto two = tjepa::layouts::two_part_skin();
    const auto& l = two.layout;
    for (int k : {1, 3, 6}) {
      const auto e = tjepa::knn_edges(l, k);
      const auto g = tjepa::make_graph(l, e);
      CHECK(g.num_components() >= 2);
      for (const auto& ed : e) {
        CHECK(l.part[ed.src] == l.part[ed.dst]);
        CHECK(ed.weight == doctest::Approx(l.distance(ed.src, ed.dst)));
      }
      // Every taxel is joined to its k nearest taxels of its part (brute force check).
      for (int i = 0; i < l.size(); ++i) {
        CHECK(g.degree(i) >= k);
        std::vector<std::pair<double, int>> d;
        for (int j = 0; j < l.size(); ++j)
          if (j != i && l.part[j] == l.part[i]) d.emplace_back(l.distance(i, j), j);
        std::sort(d.begin(), d.end());
        const auto nb = sorted_neighbors(g, i);
        for (int t = 0; t < k; ++t) CHECK(std::binary_search(nb.begin(), nb.end(), d[t].second));
      }
    }
    // Across parts: the nearest taxel of the other part becomes reachable for large k.
    const int n0 = static_cast<int>(l.taxels_of_part(0).size());
    const auto across = tjepa::make_graph(l, tjepa::knn_edges(l, n0, true));
    CHECK(across.num_components() == 1);

    CHECK_THROWS_WITH_AS(tjepa::knn_edges(l, n0), doctest::Contains("larger than the"), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::knn_edges(l, 0), tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::radius_edges(l, -1.0), doctest::Contains("radius -1"), tjepa::ConfigError);
    auto flat = l;
    flat.dim = 0;
    flat.coords.clear();
    CHECK_THROWS_WITH_AS(tjepa::knn_edges(flat, 2), doctest::Contains("no coordinates"), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::radius_edges(flat, 1.0), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::bridge_edges(flat, std::vector<tjepa::GroupPair>{{0, 1}}, 1), tjepa::ConfigError);
  }
}
