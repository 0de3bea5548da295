#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
// Named here as well, so each module this file tests is traceable.
#include <tjepa/graph/spectral_positions.hpp>

#include "../support/files.hpp"

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace {

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (auto p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

}  // namespace

TEST_SUITE("graph") {
  TEST_CASE("TaxelGraph stores a CSR with sorted neighbours - parts and components") {
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

  TEST_CASE("induces_connected") {
    // A path 0-1-2-3 and an isolated 4.
    std::vector<tjepa::Edge> e = {{0, 1, 1.0}, {1, 2, 1.0}, {2, 3, 1.0}};
    tjepa::TaxelGraph g(5, e);
    CHECK(tjepa::induces_connected(g, std::vector<int>{2, 0, 1}));
    CHECK(!tjepa::induces_connected(g, std::vector<int>{0, 2}));
    CHECK(!tjepa::induces_connected(g, std::vector<int>{3, 4}));
    CHECK(tjepa::induces_connected(g, std::vector<int>{4}));
    CHECK(!tjepa::induces_connected(g, std::vector<int>{}));
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

  TEST_CASE("SVG: one disc per taxel - one line per edge - bridges dashed - fills and highlights") {
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
    CHECK(tjepa_test::read_file(doc) == svg);
  }

  TEST_CASE("DECO-50 grouping: 264 tokens per hand - 528 for two - sizes 4 and 5 - lifted group graph") {
    const auto s = tjepa::layouts::inspire_hands();
    const auto gr = tjepa::layouts::deco50_grouping(s);
    CHECK(gr.num_groups() == 528);
    CHECK(gr.max_size == 5);
    CHECK(gr.num_taxels == 2124);
    int per_hand[2] = {0, 0}, five = 0;
    std::vector<int> times(2124, 0);
    for (int g = 0; g < gr.num_groups(); ++g) {
      ++per_hand[gr.part[g]];
      CHECK((gr.sizes[g] == 4 || gr.sizes[g] == 5));
      five += gr.sizes[g] == 5;
      const auto mem = gr.members_of(g);
      for (int j = 0; j < gr.max_size; ++j) {
        CHECK(gr.valid[g * gr.max_size + j] == (j < gr.sizes[g]));
        if (j >= gr.sizes[g]) CHECK(gr.members[g * gr.max_size + j] == -1);
      }
      std::vector<int> m(mem.begin(), mem.end());
      CHECK(tjepa::induces_connected(s.graph, m));
      for (int i : m) {
        ++times[i];
        CHECK(s.layout.group[i] == gr.region[g]);  // blocks never straddle regions
        CHECK(gr.token_of[i] == g);
      }
    }
    CHECK(per_hand[0] == 264);
    CHECK(per_hand[1] == 264);
    CHECK(five == 2 * 6);  // one 5-group per 3 x 3 region: 5 tips + thumb middle, per hand
    for (int i = 0; i < 2124; ++i) CHECK(times[i] == 1);

    // The group graph: hands apart, part = hand, group = region (34), unit weights, and token
    // adjacency exactly the lifted taxel adjacency.
    const auto& gg = gr.graph;
    CHECK(gg.num_nodes() == 528);
    CHECK(gg.num_components() == 2);
    CHECK(gg.num_parts() == 2);
    CHECK(gg.num_groups() == 34);
    std::set<std::pair<int, int>> lifted;
    for (const auto& e : s.graph.edges()) {
      const int a = gr.token_of[e.src], b = gr.token_of[e.dst];
      if (a != b) lifted.insert({std::min(a, b), std::max(a, b)});
    }
    std::set<std::pair<int, int>> have;
    for (const auto& e : gg.edges()) {
      CHECK(e.weight == 1.0);
      have.insert({e.src, e.dst});
    }
    CHECK(have == lifted);
    std::set<int> regions_seen;
    for (int g = 0; g < 528; ++g) {
      CHECK(gg.part(g) == gr.part[g]);
      CHECK(gg.group(g) == gr.region[g]);
      regions_seen.insert(gg.group(g));
    }
    CHECK(regions_seen.size() == 34u);
    // Per-token values spread back to taxels (to draw token masks on the layout).
    std::vector<int> token_value(528);
    for (int g = 0; g < 528; ++g) token_value[g] = 7 * g;
    const auto taxel_value = gr.per_taxel<int>(token_value);
    for (int i = 0; i < 2124; ++i) CHECK(taxel_value[i] == 7 * gr.token_of[i]);
    CHECK_THROWS_AS(gr.per_taxel<int>(std::vector<int>(3)), tjepa::ShapeError);
    // Each 2 x 2 block of a 12 x 8 nail is a 6 x 4 grid of tokens: inner tokens have 4 neighbours
    // inside the region.
    const auto one = tjepa::layouts::deco50_grouping(tjepa::layouts::inspire_hand(tjepa::layouts::inspire::Side::left));
    CHECK(one.num_groups() == 264);
    CHECK(one.graph.num_components() == 1);
  }

  TEST_CASE("grow_grouping: connected groups of 4-5 covering every part of any layout") {
    const std::vector<std::pair<std::string, tjepa::Skin>> skins = {
        {"allegro", tjepa::layouts::allegro_xela()},
        {"two_part", tjepa::layouts::two_part_skin()},
        {"grid", tjepa::layouts::grid_skin()},
        {"inspire", tjepa::layouts::inspire_hands()},
        // Edges across the two parts must not pull groups across them.
        {"two_part_knn_across", [] {
           auto l = tjepa::layouts::two_part_skin().layout;
           const int n0 = static_cast<int>(l.taxels_of_part(0).size());
           auto e = tjepa::knn_edges(l, 4);
           for (const auto& x : tjepa::knn_edges(l, n0, true))
             if (l.part[x.src] != l.part[x.dst]) e.push_back(x);
           return tjepa::make_skin(l, e);
         }()}};
    for (const auto& [name, s] : skins) {
      for (auto [lo, hi] : {std::pair{4, 5}, std::pair{3, 4}, std::pair{6, 8}, std::pair{5, 6}, std::pair{8, 10}}) {
        INFO(name, " n_g in [", lo, ", ", hi, "]");
        const auto gr = tjepa::grow_grouping(s, lo, hi);
        std::vector<int> times(s.size(), 0);
        long long total = 0;
        for (int g = 0; g < gr.num_groups(); ++g) {
          CHECK(gr.sizes[g] >= lo);
          CHECK(gr.sizes[g] <= hi);
          const auto mem = gr.members_of(g);
          std::vector<int> m(mem.begin(), mem.end());
          CHECK(tjepa::induces_connected(s.graph, m));
          for (int i : m) {
            ++times[i];
            CHECK(s.layout.part[i] == gr.part[g]);
          }
          total += gr.sizes[g];
        }
        CHECK(total == s.size());
        CHECK(std::all_of(times.begin(), times.end(), [](int t) { return t == 1; }));
        CHECK(gr.graph.num_components() == s.graph.num_components());
        CHECK(gr.graph.num_parts() == s.layout.num_parts());
        // Deterministic.
        CHECK(tjepa::grow_grouping(s, lo, hi).members == gr.members);
      }
    }
  }

  TEST_CASE("grow_grouping on random blob-shaped parts - irregular - with holes and thin arms") {
    int attempted = 0, grouped = 0;
    for (std::uint64_t seed = 0; seed < 40; ++seed) {
      // A blob grown cell by cell from the centre of a 14 x 14 grid: connected, ragged.
      tjepa::Rng rng(seed);
      const int side = 14, want = 40 + static_cast<int>(rng.below(80));
      std::vector<std::uint8_t> live(side * side, 0);
      live[7 * side + 7] = 1;
      for (int have = 1; have < want;) {
        const int c = static_cast<int>(rng.below(side * side));
        if (live[c]) continue;
        const int r = c / side, q = c % side;
        const bool touches = (r > 0 && live[c - side]) || (r + 1 < side && live[c + side]) ||
                             (q > 0 && live[c - 1]) || (q + 1 < side && live[c + 1]);
        if (touches) live[c] = 1, ++have;
      }
      tjepa::LayoutBuilder b;
      b.add_grid_pad("blob", b.add_part("blob"), tjepa::GridPad(side, side).with_live(live));
      const auto s = b.build();
      REQUIRE(s.graph.num_components() == 1);
      for (auto [lo, hi] : {std::pair{4, 5}, std::pair{3, 5}}) {
        INFO("seed ", seed, " size ", s.size(), " n_g in [", lo, ", ", hi, "]");
        ++attempted;
        const auto gr = tjepa::grow_grouping(s, lo, hi);
        ++grouped;
        int total = 0;
        for (int g = 0; g < gr.num_groups(); ++g) {
          CHECK(gr.sizes[g] >= lo);
          CHECK(gr.sizes[g] <= hi);
          const auto mem = gr.members_of(g);
          CHECK(tjepa::induces_connected(s.graph, std::vector<int>(mem.begin(), mem.end())));
          total += gr.sizes[g];
        }
        CHECK(total == s.size());
      }
    }
    CHECK(grouped == attempted);
  }

  TEST_CASE("groupings reject what they cannot cover") {
    tjepa::LayoutBuilder b;
    const int p = b.add_part("p"), q = b.add_part("tiny");
    b.add_grid_pad("seven", p, tjepa::GridPad(1, 7), {0, 0});
    b.add_grid_pad("three", q, tjepa::GridPad(1, 3), {0, 10});
    const auto s = b.build();
    CHECK_THROWS_WITH_AS(tjepa::grow_grouping(s, 4, 5), doctest::Contains("cannot cover part 'p' of 7 taxels"),
                         tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::grow_grouping(s, 2, 2), doctest::Contains("cannot cover"), tjepa::ConfigError);
    CHECK_NOTHROW(tjepa::grow_grouping(s, 3, 4));
    CHECK_THROWS_AS(tjepa::grow_grouping(s, 5, 4), tjepa::ConfigError);
    // A star of three 2-taxel arms: 7 = 3 + 4 taxels, but no cut into connected groups of 3-4.
    {
      const std::vector<tjepa::Edge> e = {{0, 1, 1.0}, {1, 2, 1.0}, {0, 3, 1.0}, {3, 4, 1.0}, {0, 5, 1.0}, {5, 6, 1.0}};
      tjepa::TaxelLayout star;
      star.ids = {0, 1, 2, 3, 4, 5, 6};
      star.part.assign(7, 0);
      star.group.assign(7, 0);
      star.part_names = {"star"};
      star.group_names = {"all"};
      star.group_part = {0};
      const auto sk = tjepa::make_skin(star, e);
      CHECK_THROWS_WITH_AS(tjepa::grow_grouping(sk, 3, 4), doctest::Contains("could not cut part 'star'"),
                           tjepa::DataError);
      CHECK(tjepa::grow_grouping(sk, 2, 3).num_groups() == 3);  // two arms, and the centre with the third
    }
    CHECK_THROWS_WITH_AS(tjepa::block_grouping(s), doctest::Contains("expected even sides"), tjepa::DataError);

    // make_grouping: every taxel exactly once, connected, inside one part.
    CHECK_THROWS_WITH_AS(tjepa::make_grouping(s, {{0, 1, 2, 3, 4, 5, 6}, {7, 8}}), doctest::Contains("taxel 9 is in no group"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::make_grouping(s, {{0, 1, 2, 3, 4, 5, 6}, {7, 8, 9, 6}}),
                         doctest::Contains("is in groups 0 and 1"), tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::make_grouping(s, {{0, 2}, {1, 3, 4, 5, 6}, {7, 8, 9}}),
                         doctest::Contains("not connected"), tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::make_grouping(s, {{0, 1, 2, 3, 4, 5}, {6, 7, 8, 9}}), doctest::Contains("spans parts"),
                         tjepa::DataError);
    const auto ok = tjepa::make_grouping(s, {{0, 1, 2, 3}, {4, 5, 6}, {7, 8, 9}}, tjepa::GroupWeights::centroid_distance);
    CHECK(ok.graph.num_edges() == 1u);
    CHECK(ok.graph.weights(0)[0] == doctest::Approx(3.5));  // centroid x 1.5 vs 5 at 1 mm pitch
  }

  TEST_CASE("laplacian_eigenmaps: L v = λ v - orthonormal - ascending - deterministic signs") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    const tjepa::TaxelGraph& g = skin.graph;
    const int n = g.num_nodes(), k = 24;
    const tjepa::LaplacianEigenmaps e = tjepa::laplacian_eigenmaps(g, k);
    REQUIRE(e.vectors.rows() == n);
    REQUIRE(e.vectors.cols() == k);
    // The normalized Laplacian applied from the CSR directly, not from the solver's matrix.
    for (int c = 0; c < k; ++c) {
      double residual = 0;
      for (int i = 0; i < n; ++i) {
        double lv = e.vectors(i, c);
        for (int j : g.neighbors(i)) lv -= e.vectors(j, c) / std::sqrt(double(g.degree(i)) * g.degree(j));
        residual = std::max(residual, std::abs(lv - e.values(c) * e.vectors(i, c)));
      }
      CHECK(residual < 1e-9);
      if (c > 0) CHECK(e.values(c) >= e.values(c - 1));
      Eigen::Index at = 0;
      e.vectors.col(c).cwiseAbs().maxCoeff(&at);
      CHECK(e.vectors(at, c) > 0);
    }
    CHECK((e.vectors.transpose() * e.vectors - Eigen::MatrixXd::Identity(k, k)).cwiseAbs().maxCoeff() < 1e-9);
    CHECK(std::abs(e.values(0)) < 1e-12);  // one component: one zero eigenvalue
    CHECK(e.values(1) > 1e-6);
    CHECK(tjepa::laplacian_eigenmaps(g, k).vectors == e.vectors);
  }

  TEST_CASE("laplacian_eigenmaps: two parts give two zero eigenvalues - isolated taxels are allowed") {
    // Parts {0, 1, 2} (a path) and {3, 4} (an edge), and taxel 5 alone.
    std::vector<tjepa::Edge> edges = {{0, 1, 1.0}, {1, 2, 1.0}, {3, 4, 1.0}};
    const tjepa::TaxelGraph g(6, edges);
    const tjepa::LaplacianEigenmaps e = tjepa::laplacian_eigenmaps(g, 6);
    for (int c = 0; c < 3; ++c) CHECK(std::abs(e.values(c)) < 1e-12);
    CHECK(e.values(3) > 0.1);
    // The zero eigenspace is spanned by the parts' indicators (weighted by sqrt(degree)): no
    // eigenvector of it mixes a part's taxels unevenly against their degrees.
    for (int c = 0; c < 3; ++c) {
      CHECK(e.vectors(0, c) == doctest::Approx(e.vectors(2, c)).scale(1));
      CHECK(e.vectors(1, c) == doctest::Approx(std::sqrt(2.0) * e.vectors(0, c)).scale(1));
      CHECK(e.vectors(3, c) == doctest::Approx(e.vectors(4, c)).scale(1));
    }
  }

  TEST_CASE("graph_positions: neighbours get closer rows than strangers - RMS scale - seeded") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    const tjepa::TaxelGraph& g = skin.graph;
    const int n = g.num_nodes(), d = 48;
    const std::vector<double> p = tjepa::graph_positions(g, d, 32, 0.5, 7);
    REQUIRE(p.size() == std::size_t(n) * d);
    double ss = 0;
    for (double v : p) ss += v * v;
    CHECK(std::sqrt(ss / double(p.size())) == doctest::Approx(0.5).epsilon(1e-12));
    auto dist = [&](int a, int b) {
      double s = 0;
      for (int c = 0; c < d; ++c) s += (p[std::size_t(a) * d + c] - p[std::size_t(b) * d + c]) * (p[std::size_t(a) * d + c] - p[std::size_t(b) * d + c]);
      return std::sqrt(s);
    };
    double neighbour = 0, stranger = 0;
    int nn = 0, ns = 0;
    tjepa::Rng r(3);
    for (int i = 0; i < n; ++i) {
      for (int j : g.neighbors(i)) neighbour += dist(i, j), ++nn;
      const int j = static_cast<int>(r.below(std::uint64_t(n)));
      if (g.group(j) != g.group(i)) stranger += dist(i, j), ++ns;
    }
    neighbour /= nn;
    stranger /= ns;
    MESSAGE("mean row distance: neighbours " << neighbour << ", taxels of other pads " << stranger);
    CHECK(neighbour < 0.5 * stranger);
    CHECK(tjepa::graph_positions(g, d, 32, 0.5, 7) == p);
    CHECK(tjepa::graph_positions(g, d, 32, 0.5, 8) != p);
  }

  TEST_CASE("graph_positions and laplacian_eigenmaps reject bad sizes with a message") {
    const tjepa::Skin skin = tjepa::layouts::allegro_xela();
    CHECK_THROWS_WITH_AS(tjepa::laplacian_eigenmaps(skin.graph, 0), doctest::Contains("k = 0"), tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::laplacian_eigenmaps(skin.graph, 369), doctest::Contains("368 nodes"), tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::graph_positions(skin.graph, 0, 8, 1.0, 0), doctest::Contains("dim = 0"),
                         tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::graph_positions(skin.graph, 16, 8, NAN, 0), doctest::Contains("scale"),
                         tjepa::ConfigError);
  }
}
