#include <doctest/doctest.h>

#include <tjepa/graph/taxel_graph.hpp>

#include <vector>

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
}
