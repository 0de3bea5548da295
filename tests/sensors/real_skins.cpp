// Real sensors: the orders their drivers write (XELA xServer, the reference code), graphs inferred
// from real coordinates (anisotropic pads, outliers, duplicates, far pads, hexagonal sheets), and
// order files.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace {

// XELA's index arrays of the curved-tip Allegro hand, as NYU-robot-learning/Xela-Sensor-Controllers-
// Openteach (xela_sensors/src/xela_sensors/utils.py) lists them: entry [r][c] is the xServer
// point_id of the taxel in row r, column c of the sensor, -1 where a fingertip has no cell. The
// index fingertip's row 0 is given there as [-1, 101, 83, -1, 1]; its columns (101, 102, ... and
// 83, 84, ...) place it as below.
using Rows = std::vector<std::vector<int>>;
const std::map<std::string, Rows>& xela_arrays() {
  static const std::map<std::string, Rows> a = {
      {"palm_0", {{119, 140, 148, 152, 160, 181}, {120, 141, 149, 153, 161, 182}, {121, 142, 150, 154, 162, 183},
                  {122, 143, 151, 155, 163, 184}}},
      {"palm_1", {{238, 250, 258, 270, 295, 321}, {239, 251, 259, 271, 296, 322}, {240, 252, 260, 272, 297, 323},
                  {241, 253, 261, 273, 298, 324}}},
      {"palm_2", {{242, 254, 262, 274, 299, 325}, {243, 255, 263, 275, 300, 326}, {244, 256, 264, 276, 301, 327},
                  {245, 257, 265, 277, 302, 328}}},
      {"index_tip", {{-1, -1, 101, 83, -1, -1}, {-1, 123, 102, 84, 66, -1}, {144, 124, 103, 85, 67, 62},
                     {145, 125, 104, 86, 68, 63}, {146, 126, 105, 87, 69, 64}, {147, 127, 106, 88, 70, 65}}},
      {"middle_tip", {{-1, -1, 203, 185, -1, -1}, {-1, 221, 204, 186, 164, -1}, {246, 222, 205, 187, 165, 156},
                      {247, 223, 206, 188, 166, 157}, {248, 224, 207, 189, 167, 158}, {249, 225, 208, 190, 168, 159}}},
      {"ring_tip", {{-1, -1, 329, 303, -1, -1}, {-1, 347, 330, 304, 278, -1}, {364, 348, 331, 305, 279, 266},
                    {365, 349, 332, 306, 280, 267}, {366, 350, 333, 307, 281, 268}, {367, 351, 334, 308, 282, 269}}},
      {"thumb_tip", {{-1, -1, 31, 17, -1, -1}, {-1, 45, 32, 18, 4, -1}, {58, 46, 33, 19, 5, 0},
                     {59, 47, 34, 20, 6, 1}, {60, 48, 35, 21, 7, 2}, {61, 49, 36, 22, 8, 3}}},
      {"thumb_1", {{50, 37, 23, 9}, {51, 38, 24, 10}, {52, 39, 25, 11}, {53, 40, 26, 12}}},
      {"thumb_2", {{54, 41, 27, 13}, {55, 42, 28, 14}, {56, 43, 29, 15}, {57, 44, 30, 16}}},
      {"index_1", {{128, 107, 89, 71}, {129, 108, 90, 72}, {130, 109, 91, 73}, {131, 110, 92, 74}}},
      {"index_2", {{132, 111, 93, 75}, {133, 112, 94, 76}, {134, 113, 95, 77}, {135, 114, 96, 78}}},
      {"index_3", {{136, 115, 97, 79}, {137, 116, 98, 80}, {138, 117, 99, 81}, {139, 118, 100, 82}}},
      {"middle_1", {{226, 209, 191, 169}, {227, 210, 192, 170}, {228, 211, 193, 171}, {229, 212, 194, 172}}},
      {"middle_2", {{230, 213, 195, 173}, {231, 214, 196, 174}, {232, 215, 197, 175}, {233, 216, 198, 176}}},
      {"middle_3", {{234, 217, 199, 177}, {235, 218, 200, 178}, {236, 219, 201, 179}, {237, 220, 202, 180}}},
      {"ring_1", {{352, 335, 309, 283}, {353, 336, 310, 284}, {354, 337, 311, 285}, {355, 338, 312, 286}}},
      {"ring_2", {{356, 339, 313, 287}, {357, 340, 314, 288}, {358, 341, 315, 289}, {359, 342, 316, 290}}},
      {"ring_3", {{360, 343, 317, 291}, {361, 344, 318, 292}, {362, 345, 319, 293}, {363, 346, 320, 294}}}};
  return a;
}

// The point_id XELA's arrays give the taxel at tjepa's (pad, row, col): a fingertip's row 0 in
// XELA's numbering is its 2-cell dome row, tjepa's row 5 (the reference's fingertip order); columns,
// phalanx and palm pads are as tjepa's.
int xela_point_id(const std::string& pad, int row, int col) {
  const Rows& a = xela_arrays().at(pad);
  const int n = static_cast<int>(a.size());
  const int r = pad.ends_with("_tip") ? n - 1 - row : row;
  return a[static_cast<std::size_t>(r)][static_cast<std::size_t>(col)];
}

std::set<std::pair<int, int>> in_group_edges(const tjepa::Skin& s) {
  std::set<std::pair<int, int>> e;
  for (const auto& ed : s.graph.edges())
    if (s.layout.group[ed.src] == s.layout.group[ed.dst]) e.emplace(std::min(ed.src, ed.dst), std::max(ed.src, ed.dst));
  return e;
}

// A grid pad's 4-neighbour pairs over the layout's (row, col) cells of group g.
std::set<std::pair<int, int>> grid_pairs(const tjepa::TaxelLayout& l, int g) {
  std::set<std::pair<int, int>> e;
  const auto t = l.taxels_of_group(g);
  for (int i : t)
    for (int j : t)
      if (i < j && std::abs(l.row[i] - l.row[j]) + std::abs(l.col[i] - l.col[j]) == 1) e.emplace(i, j);
  return e;
}

}  // namespace

TEST_SUITE("sensors") {
  TEST_CASE("Allegro xServer order: values written in point_id order land on their (pad / row / col) / all 368") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    const tjepa::TaxelLayout& l = skin.layout;
    const std::vector<int> column = tjepa::layouts::allegro::xserver_columns();
    REQUIRE(column.size() == 368u);
    std::set<int> seen(column.begin(), column.end());
    CHECK(seen.size() == 368u);
    CHECK(*seen.begin() == 0);
    CHECK(*seen.rbegin() == 367);
    for (int j = 0; j < l.size(); ++j) {
      const std::string& pad = l.group_names[l.group[j]];
      INFO(pad, " row ", l.row[j], " col ", l.col[j]);
      CHECK(column[j] == xela_point_id(pad, l.row[j], l.col[j]));
    }
    // A recording in xServer order: point p reads (1000 p, 1000 p + 1, 1000 p + 2).
    tjepa::Recording rec(2, 368, 3);
    for (int t = 0; t < 2; ++t)
      for (int p = 0; p < 368; ++p)
        for (int a = 0; a < 3; ++a) rec.at(t, p, a) = static_cast<float>(1000 * p + a + t);
    tjepa::TaxelLayout ordered = l;
    ordered.column = column;
    ordered.validate();
    const tjepa::Recording in_order = tjepa::select_taxels(rec, ordered.column);
    int right = 0;
    for (int j = 0; j < 368; ++j) {
      const int p = xela_point_id(l.group_names[l.group[j]], l.row[j], l.col[j]);
      right += in_order(1, j, 2) == static_cast<float>(1000 * p + 3);
    }
    CHECK(right == 368);
    // Read as if it were tjepa's order, nearly every taxel would be wrong.
    int unmoved = 0, same_pad = 0;
    for (int j = 0; j < 368; ++j) unmoved += column[j] == j, same_pad += l.group[column[j]] == l.group[j];
    CHECK(unmoved == 2);
    CHECK(same_pad == 74);
  }

  TEST_CASE("Allegro reference order: pads as tjepa / fingertip rows reversed (6 of 30 per tip in place)") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    const tjepa::TaxelLayout& l = skin.layout;
    const std::vector<int> column = tjepa::layouts::allegro::reference_columns();
    REQUIRE(column.size() == 368u);
    CHECK(std::set<int>(column.begin(), column.end()).size() == 368u);
    for (int j = 0; j < l.size(); ++j) {
      const std::string& pad = l.group_names[l.group[j]];
      const int first = l.taxels_of_group(l.group[j])[0];
      INFO(pad, " taxel ", j);
      CHECK(l.group[column[j]] == l.group[j]);  // pads stay in place
      if (!pad.ends_with("_tip")) {
        CHECK(column[j] == j);
        continue;
      }
      // The reference lists a tip's cells from the dome: row 5 (2 cells), row 4 (4), rows 3..0.
      const int row_first[6] = {24, 18, 12, 6, 2, 0};
      const int k = column[j] - first;
      const int r = l.row[j], c = l.col[j];
      const int lo = r == 4 ? 1 : r == 5 ? 2 : 0;
      CHECK(k == row_first[r] + (c - lo));
    }
    for (const char* tip : {"thumb_tip", "index_tip", "middle_tip", "ring_tip"}) {
      const auto t = l.taxels_of_group(static_cast<int>(
          std::find(l.group_names.begin(), l.group_names.end(), tip) - l.group_names.begin()));
      int same = 0;
      for (int j : t) same += column[j] == j;
      CHECK(same == 6);
    }
    // The reference's taxel types (taxeltype_embed rows: 4x4, 4x6, curved) follow the pads, in its
    // order and so in tjepa's.
    const std::vector<int> type = tjepa::layouts::allegro::reference_taxel_types();
    REQUIRE(type.size() == 368u);
    for (int j = 0; j < l.size(); ++j) {
      const std::size_t n = l.taxels_of_group(l.group[j]).size();
      CHECK(type[j] == (n == 30 ? 2 : n == 24 ? 1 : 0));
      CHECK(type[column[j]] == type[j]);
    }
  }

  TEST_CASE("Allegro graph: the reference's 17 pad pairs / short bridges / and its own edges from coordinates") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    const tjepa::TaxelLayout& l = skin.layout;
    auto id = [&](const char* n) {
      return static_cast<int>(std::find(l.group_names.begin(), l.group_names.end(), n) - l.group_names.begin());
    };
    std::set<std::pair<int, int>> pairs;
    for (const auto& e : skin.graph.edges())
      if (l.group[e.src] != l.group[e.dst])
        pairs.emplace(std::min(l.group[e.src], l.group[e.dst]), std::max(l.group[e.src], l.group[e.dst]));
    // tactile_ssl/graph/utils.py: thumb base - ahr_palm_1 (group 16), index and middle bases -
    // ahr_palm_2 (15), ring base - ahr_palm_3 (17), palm 16 - 15 - 17.
    const std::set<std::pair<int, int>> reference = {
        {0, 1}, {1, 2}, {2, 16}, {3, 4}, {4, 5}, {5, 6}, {6, 15}, {7, 8}, {8, 9},
        {9, 10}, {10, 15}, {11, 12}, {12, 13}, {13, 14}, {14, 17}, {15, 16}, {15, 17}};
    CHECK(pairs == reference);
    CHECK(id("thumb_2") == 2);
    CHECK(id("palm_1") == 16);
    // The drawing keeps every bridged pair close and no two pads overlapping.
    for (const auto& e : skin.graph.edges())
      if (l.group[e.src] != l.group[e.dst]) CHECK(e.weight < 16.0);
    for (int i = 0; i < l.size(); ++i)
      for (int j = i + 1; j < l.size(); ++j)
        if (l.group[i] != l.group[j]) CHECK(l.distance(i, j) > 2.0);
    // Inferred from the coordinates alone (fingertip rows 6.5 mm apart, columns 5.17 mm): every pad
    // keeps its full 4-neighbour grid, curved rows included, and the hand is one piece.
    tjepa::TaxelLayout bare = l;
    bare.row.clear();
    bare.col.clear();
    const tjepa::InferredSkin inferred = tjepa::skin_from_coordinates(bare);
    CHECK(inferred.warnings.empty());
    CHECK(inferred.skin.graph.num_components() == 1);
    CHECK(in_group_edges(inferred.skin) == in_group_edges(skin));
    std::size_t grid = 0;
    for (int g = 0; g < l.num_groups(); ++g) grid += grid_pairs(l, g).size();
    CHECK(in_group_edges(skin).size() == grid);
    CHECK(grid == 570u);
  }

  TEST_CASE("inferred graphs: anisotropic and hexagonal pads / an outlier / far pads / duplicates") {
    using tjepa::TaxelLayout;
    auto layout = [](const std::vector<std::array<double, 2>>& xy, std::vector<int> group = {}) {
      TaxelLayout l;
      l.dim = 2;
      const int n = static_cast<int>(xy.size());
      if (group.empty()) group.assign(static_cast<std::size_t>(n), 0);
      const int G = *std::max_element(group.begin(), group.end()) + 1;
      for (int i = 0; i < n; ++i) {
        l.ids.push_back(i);
        l.coords.insert(l.coords.end(), {xy[static_cast<std::size_t>(i)][0], xy[static_cast<std::size_t>(i)][1]});
        l.part.push_back(0);
        l.group.push_back(group[static_cast<std::size_t>(i)]);
      }
      l.part_names = {"skin"};
      for (int g = 0; g < G; ++g) l.group_names.push_back("pad" + std::to_string(g)), l.group_part.push_back(0);
      return l;
    };
    // A 6 x 5 pad, rows 6.5 mm apart and columns 5.17 mm: 4-neighbours in both directions.
    std::vector<std::array<double, 2>> xy;
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 5; ++c) xy.push_back({c * 5.17, r * 6.5});
    const auto aniso = tjepa::skin_from_coordinates(layout(xy));
    CHECK(aniso.skin.graph.num_edges() == 6u * 4 + 5u * 5);
    for (const auto& e : aniso.skin.graph.edges()) {
      const double d = e.weight;
      CHECK((std::abs(d - 5.17) < 1e-9 || std::abs(d - 6.5) < 1e-9));
    }
    // One misplaced taxel: a warning naming it, and it joins its nearest neighbours only.
    auto with_outlier = xy;
    with_outlier.push_back({90.0, 95.0});
    const auto out = tjepa::skin_from_coordinates(layout(with_outlier));
    REQUIRE(out.warnings.size() == 1u);
    CHECK(out.warnings[0].find("taxel 30 ") != std::string::npos);
    CHECK(out.skin.graph.neighbors(30).size() <= 3u);
    CHECK(out.skin.graph.num_edges() <= 49u + 3u);
    // A hexagonal sheet: 6 neighbours inside.
    std::vector<std::array<double, 2>> hex;
    for (int r = 0; r < 7; ++r)
      for (int c = 0; c < 7; ++c) hex.push_back({4.0 * c + (r % 2) * 2.0, r * 4.0 * std::sqrt(3.0) / 2.0});
    const auto h = tjepa::skin_from_coordinates(layout(hex));
    CHECK(h.skin.graph.neighbors(3 * 7 + 3).size() == 6u);
    // Two pads 30 mm apart (far beyond twice their 4 mm pitch): connect bridges them, near does not
    // (and warns that the part falls into two pieces), none neither.
    std::vector<std::array<double, 2>> two;
    std::vector<int> grp;
    for (int p = 0; p < 2; ++p)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) two.push_back({p * 38.0 + c * 4.0, r * 4.0}), grp.push_back(p);
    const auto connect = tjepa::skin_from_coordinates(layout(two, grp));
    CHECK(connect.skin.graph.num_components() == 1);
    CHECK(connect.warnings.empty());
    int bridges = 0;
    for (const auto& e : connect.skin.graph.edges()) bridges += connect.skin.layout.group[e.src] != connect.skin.layout.group[e.dst];
    CHECK(bridges == 4);
    tjepa::CoordinateSkinOptions near;
    near.bridges = tjepa::BridgeRule::near;
    const auto n = tjepa::skin_from_coordinates(layout(two, grp), near);
    CHECK(n.skin.graph.num_components() == 2);
    REQUIRE(n.warnings.size() == 1u);
    CHECK(n.warnings[0].find("2 unconnected pieces") != std::string::npos);
    CHECK(n.warnings[0].find("pad1") != std::string::npos);
    near.bridges = tjepa::BridgeRule::none;
    CHECK(tjepa::skin_from_coordinates(layout(two, grp), near).skin.graph.num_components() == 2);
    // Pads 6 mm apart are bridged by near too.
    for (std::size_t i = 9; i < two.size(); ++i) two[i][0] -= 32.0;
    CHECK(tjepa::skin_from_coordinates(layout(two, grp), near).skin.graph.num_components() == 2);  // none
    near.bridges = tjepa::BridgeRule::near;
    CHECK(tjepa::skin_from_coordinates(layout(two, grp), near).skin.graph.num_components() == 1);
    // Two taxels at one place: an error naming both.
    auto dup = xy;
    dup.push_back(xy[7]);
    CHECK_THROWS_WITH_AS(tjepa::skin_from_coordinates(layout(dup)),
                         doctest::Contains("taxels 7 and 30 of part 'skin' have the same coordinates"), tjepa::DataError);
  }

  TEST_CASE("layout CSV: duplicate coordinates name both lines / column and order files / the socks' column names") {
    tjepa_test::TempDir t("real_skins");
    {
      std::ofstream(t / "dup.csv") << "id,x,y\n0,0,0\n1,1,0\n# a comment\n2,0,1\n3,1,0\n";
    }
    CHECK_THROWS_WITH_AS(tjepa::read_layout_csv(t / "dup.csv"),
                         doctest::Contains("dup.csv:6: taxel 3 has the same coordinates as taxel 1 (line 3)"),
                         tjepa::FileError);
    // A column field: taxel 10 reads the recording's column 2, and so on.
    {
      std::ofstream(t / "col.csv") << "id,x,y,column\n10,0,0,2\n11,1,0,0\n12,0,1,1\n";
      std::ofstream(t / "badcol.csv") << "id,x,y,column\n10,0,0,2\n11,1,0,2\n12,0,1,1\n";
    }
    const tjepa::TaxelLayout l = tjepa::read_layout_csv(t / "col.csv");
    CHECK(l.column == std::vector<int>{2, 0, 1});
    CHECK(tjepa::layout_csv_string(l).find("id,x,y,part,group,column\n10,0,0,skin,skin,2\n") == 0);
    CHECK_THROWS_WITH_AS(tjepa::read_layout_csv(t / "badcol.csv"),
                         doctest::Contains("taxels 10 and 11 both read column 2"), tjepa::FileError);
    // An order file, and what it refuses.
    {
      std::ofstream(t / "order.csv") << "id,column\n12,0\n10,1\n11,2\n";
      std::ofstream(t / "missing.csv") << "id,column\n12,0\n10,1\n";
      std::ofstream(t / "unknown.csv") << "id,column\n12,0\n10,1\n99,2\n";
      std::ofstream(t / "twice.csv") << "12,0\n10,1\n11,0\n";
    }
    CHECK(tjepa::read_taxel_order_csv(t / "order.csv", l) == std::vector<int>{1, 2, 0});
    CHECK_THROWS_WITH_AS(tjepa::read_taxel_order_csv(t / "missing.csv", l),
                         doctest::Contains("no column for taxel id 11"), tjepa::FileError);
    CHECK_THROWS_WITH_AS(tjepa::read_taxel_order_csv(t / "unknown.csv", l),
                         doctest::Contains("unknown.csv:4: taxel id 99 is not in the layout"), tjepa::FileError);
    CHECK_THROWS_WITH_AS(tjepa::read_taxel_order_csv(t / "twice.csv", l),
                         doctest::Contains("twice.csv:3: column 0 is already read by line 1"), tjepa::FileError);
    // The reference's socks files: sensor_map.csv (global_node_id, side, visual_x, visual_y, ...)
    // and edges.csv (src_global_node_id, dst_global_node_id, visual_distance), two 3 x 3 feet
    // drawn over each other.
    {
      std::ofstream m(t / "sensor_map.csv");
      m << "global_node_id,side_node_id,side,source_touch,grid_row,grid_col,flat_index,visual_x,visual_y,section\n";
      std::ofstream e(t / "edges.csv");
      e << "edge_id,side,src_global_node_id,dst_global_node_id,src_flat_index,dst_flat_index,grid_distance,visual_distance\n";
      int id = 0, edge = 0;
      for (const char* side : {"left", "right"}) {
        const int first = id;
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c, ++id)
            m << id << ',' << id - first << ',' << side << ",touch,"  << r << ',' << c << ',' << r * 32 + c << ','
              << -6.1 + 0.418 * c << ',' << 7.78 - 1.07 * r << ",0\n";
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) {
            const int a = first + r * 3 + c;
            if (c < 2) e << edge++ << ',' << side << ',' << a << ',' << a + 1 << ",0,0,1.0,0.418\n";
            if (r < 2) e << edge++ << ',' << side << ',' << a << ',' << a + 3 << ",0,0,1.0,1.07\n";
          }
      }
    }
    const auto [nc, ec] = tjepa::parse_csv_columns(
        "id=global_node_id,x=visual_x,y=visual_y,part=side,src=src_global_node_id,dst=dst_global_node_id,"
        "weight=visual_distance");
    const tjepa::Skin socks = tjepa::read_skin_csv(t / "sensor_map.csv", t / "edges.csv", nc, ec);
    CHECK(socks.layout.num_parts() == 2);
    CHECK(socks.graph.num_edges() == 24u);
    CHECK(socks.graph.num_components() == 2);  // one per sock
    CHECK(tjepa::component_warnings(socks).empty());
    // The same files read with their own names recognized, no column names given.
    const tjepa::Skin plain = tjepa::read_skin_csv(t / "sensor_map.csv", t / "edges.csv");
    CHECK(plain.graph.edges() == socks.graph.edges());
    CHECK(plain.layout.part_names == std::vector<std::string>{"left", "right"});
    CHECK(plain.layout.coords == socks.layout.coords);
    // Without the edges file the graph is inferred: the same 4-neighbour grid per sock.
    const tjepa::InferredSkin inferred = tjepa::read_skin_coordinates_csv(t / "sensor_map.csv", nc);
    CHECK(inferred.skin.graph.num_edges() == 24u);
    CHECK(inferred.skin.graph.num_components() == 2);
    CHECK_THROWS_WITH_AS(tjepa::parse_csv_columns("x=visual_x,colour=red"), doctest::Contains("unknown key 'colour'"),
                         tjepa::ConfigError);
  }

  TEST_CASE("a glove's grid with holes: 4-neighbour edges / one piece per hand") {
    // The live cells of one hand of a knitted glove (9 x 11 cells, '#' live), both hands as parts.
    const std::vector<std::string> mask = {"......###..", "#########..", "###########", "###########",
                                           "###########", "###########", "###########", "#########..",
                                           "#########.."};
    tjepa::TaxelLayout l;
    l.dim = 2;
    l.part_names = {"left", "right"};
    l.group_names = {"left", "right"};
    l.group_part = {0, 1};
    int live = 0;
    for (int hand = 0; hand < 2; ++hand)
      for (int r = 0; r < 9; ++r)
        for (int c = 0; c < 11; ++c)
          if (mask[static_cast<std::size_t>(r)][static_cast<std::size_t>(c)] == '#') {
            l.ids.push_back(static_cast<int>(l.ids.size()));
            l.coords.insert(l.coords.end(), {c * 10.0, r * 10.0});  // the hands drawn over each other
            l.part.push_back(hand);
            l.group.push_back(hand);
            live += hand == 0;
          }
    const tjepa::InferredSkin s = tjepa::skin_from_coordinates(l);
    CHECK(s.warnings.empty());
    CHECK(s.skin.graph.num_components() == 2);
    std::size_t grid = 0;
    for (int r = 0; r < 9; ++r)
      for (int c = 0; c < 11; ++c) {
        auto on = [&](int rr, int cc) {
          return rr < 9 && cc < 11 && mask[static_cast<std::size_t>(rr)][static_cast<std::size_t>(cc)] == '#';
        };
        if (on(r, c)) grid += on(r, c + 1) + on(r + 1, c);
      }
    CHECK(live == 85);
    CHECK(s.skin.graph.num_edges() == 2 * grid);
  }

  TEST_CASE("SVG: coordinates in cm stay readable / parts drawn over each other are laid out side by side") {
    tjepa::TaxelLayout l;
    l.dim = 2;
    l.part_names = {"left", "right"};
    l.group_names = {"left", "right"};
    l.group_part = {0, 1};
    for (int p = 0; p < 2; ++p)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {  // two 3 x 3 feet at 0.5 (cm) pitch, in one frame
          l.ids.push_back(static_cast<int>(l.ids.size()));
          l.coords.insert(l.coords.end(), {0.5 * c, 0.5 * r});
          l.part.push_back(p);
          l.group.push_back(p);
        }
    const auto pos = tjepa::drawing_positions(l);
    double right0 = -1e9, left1 = 1e9;
    for (int i = 0; i < 9; ++i) right0 = std::max(right0, pos[2 * i]);
    for (int i = 9; i < 18; ++i) left1 = std::min(left1, pos[2 * i]);
    CHECK(left1 > right0);
    const tjepa::InferredSkin s = tjepa::skin_from_coordinates(l);
    const std::string svg = tjepa::svg_string(s.skin, tjepa::SvgOptions{});
    const auto at = svg.find("<circle");
    REQUIRE(at != std::string::npos);
    const auto rpos = svg.find(" r=\"", at);
    CHECK(std::stod(svg.substr(rpos + 4)) >= 4.0);  // radius in px
  }
}
