// Mask sampling on small hand-built graphs: each sampler alone, then the collator's documented
// properties over many seeds, determinism, the I-JEPA blocks and the configuration errors.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include <numeric>
#include <set>
#include <vector>

#include "check_masks.hpp"

using namespace masks_test;

TEST_SUITE("masks") {
  TEST_CASE("part_pieces drops the edges between parts") {
    // 0-1-2 in part 0, 3-4 in part 1, plus a cross-part edge 2-3.
    std::vector<tjepa::Edge> e = {{0, 1, 1}, {1, 2, 1}, {2, 3, 1}, {3, 4, 1}};
    tjepa::TaxelGraph g(5, e, {0, 0, 0, 1, 1});
    CHECK(g.num_components() == 1);
    const auto pc = tjepa::part_pieces(g);
    CHECK(pc.size.size() == 2);
    CHECK(pc.piece[0] == pc.piece[2]);
    CHECK(pc.piece[2] != pc.piece[3]);
    CHECK(pc.size[pc.piece[4]] == 2);
    tjepa::MaskDomain whole(g, pc, -1), p1(g, pc, 1);
    CHECK(whole.size() == 5);
    CHECK(whole.num_seeds(3) == 3);  // only part 0's piece holds 3
    CHECK(whole.num_seeds(4) == 0);
    CHECK(p1.size() == 2);
    CHECK(p1.num_seeds(2) == 2);
  }

  TEST_CASE("local masks are Dijkstra balls of exactly t connected tokens in one part") {
    // A weighted graph: two grids of different pitch in two parts, plus random weights.
    GridSpec a{6, 7, 3, 3, 1.0}, b{5, 5, 5, 5, 2.5};
    std::vector<tjepa::Edge> e;
    std::vector<int> p, gr;
    add_grid(a, 0, 0, e, p, gr);
    add_grid(b, 1, 10, e, p, gr);
    tjepa::Rng wr(7);
    for (auto& ed : e) ed.weight *= 0.5 + wr.uniform();
    // A cross-part edge: local masks must still not cross it.
    e.push_back({0, 42, 0.01});
    tjepa::TaxelGraph g(static_cast<int>(p.size()), e, p, gr);
    const auto pieces = tjepa::part_pieces(g);
    tjepa::MaskDomain whole(g, pieces, -1), part1(g, pieces, 1);
    tjepa::MaskWorkspace ws;
    ws.resize(g.num_nodes());
    tjepa::Rng rng(3);
    std::vector<int> out;
    for (int t : {1, 2, 5, 13, 25, 30}) {
      for (int rep = 0; rep < 40; ++rep) {
        out.assign(t, -1);
        tjepa::sample_local_mask(g, whole, rng, ws, out);
        std::set<int> s(out.begin(), out.end());
        REQUIRE(static_cast<int>(s.size()) == t);
        REQUIRE(connected(g, out));
        for (int v : out) REQUIRE(g.part(v) == g.part(out[0]));
        REQUIRE(is_dijkstra_ball(g, out));
        if (t <= part1.size()) {
          tjepa::sample_local_mask(g, part1, rng, ws, out);
          for (int v : out) REQUIRE(g.part(v) == 1);
          REQUIRE(connected(g, out));
        }
      }
    }
    // t = 30 > 25 tokens of part 1: only part 0 (42 tokens) can hold it.
    for (int rep = 0; rep < 20; ++rep) {
      out.assign(30, -1);
      tjepa::sample_local_mask(g, whole, rng, ws, out);
      REQUIRE(g.part(out[0]) == 0);
    }
    out.assign(43, -1);
    CHECK_THROWS_WITH_AS(tjepa::sample_local_mask(g, whole, rng, ws, out),
                         doctest::Contains("no connected piece"), tjepa::DataError);
    out.assign(26, -1);
    CHECK_THROWS_WITH_AS(tjepa::sample_local_mask(g, part1, rng, ws, out),
                         doctest::Contains("expected 1 <= t <= 25"), tjepa::ConfigError);
  }

  TEST_CASE("local masks break distance ties at random") {
    // On a unit grid from a fixed seed the ring at distance 1 has 4 tokens: with t = 3 the mask
    // keeps the seed and 2 of them, and every pair must occur.
    GridSpec s{3, 3, 3, 3, 1.0};
    auto g = grid_graph(s);
    tjepa::MaskWorkspace ws;
    ws.resize(g.num_nodes());
    tjepa::Rng rng(11);
    std::set<std::vector<int>> shapes;
    std::vector<int> out(3);
    for (int rep = 0; rep < 3000; ++rep) {
      tjepa::detail::grow_region(g, 4, rng, ws, out);  // seed: the centre
      REQUIRE(out[0] == 4);
      std::vector<int> v(out.begin(), out.end());
      std::sort(v.begin(), v.end());
      shapes.insert(v);
    }
    CHECK(shapes.size() == 6);  // C(4, 2)
  }

  TEST_CASE("global masks: stratified covers every group then fills uniformly and t < G picks t groups") {
    GridSpec s{12, 12, 3, 4, 1.0};  // 4 x 3 = 12 groups of 12 tokens
    auto g = grid_graph(s);
    const auto pieces = tjepa::part_pieces(g);
    tjepa::MaskDomain d(g, pieces, -1);
    REQUIRE(d.num_groups() == 12);
    tjepa::MaskWorkspace ws;
    ws.resize(g.num_nodes());
    tjepa::Rng rng(5);
    std::vector<int> hits(g.num_nodes(), 0);
    for (int t : {1, 5, 11, 12, 13, 40, 100, 144}) {
      std::vector<int> out(t);
      for (int rep = 0; rep < 50; ++rep) {
        tjepa::sample_global_mask(d, tjepa::GlobalSampling::stratified, rng, ws, out);
        std::set<int> toks(out.begin(), out.end()), groups;
        REQUIRE(static_cast<int>(toks.size()) == t);
        for (int v : out) groups.insert(g.group(v));
        REQUIRE(static_cast<int>(groups.size()) >= std::min(t, 12));
        if (t < 12) REQUIRE(static_cast<int>(groups.size()) == t);
        for (int v : out) ++hits[v];
        tjepa::sample_global_mask(d, tjepa::GlobalSampling::uniform, rng, ws, out);
        toks = std::set<int>(out.begin(), out.end());
        REQUIRE(static_cast<int>(toks.size()) == t);
      }
    }
    for (int v = 0; v < g.num_nodes(); ++v) CHECK(hits[v] > 0);
  }

  TEST_CASE("uniform global masks are uniform: each token's frequency near t/N") {
    GridSpec s{10, 10, 5, 5, 1.0};
    auto g = grid_graph(s);
    const auto pieces = tjepa::part_pieces(g);
    tjepa::MaskDomain d(g, pieces, -1);
    tjepa::MaskWorkspace ws;
    ws.resize(g.num_nodes());
    tjepa::Rng rng(9);
    for (int t : {20, 70}) {  // rejection and Fisher–Yates paths
      std::vector<int> out(t), hits(100, 0);
      const int reps = 4000;
      for (int rep = 0; rep < reps; ++rep) {
        tjepa::sample_global_mask(d, tjepa::GlobalSampling::uniform, rng, ws, out);
        for (int v : out) ++hits[v];
      }
      const double p = t / 100.0, sd = std::sqrt(reps * p * (1 - p));
      for (int v = 0; v < 100; ++v) CHECK(std::abs(hits[v] - reps * p) < 5 * sd);
    }
  }

  TEST_CASE("contexts: uniform drops the excluded tokens and local grows one region per part") {
    auto g = two_part_graph({6, 6, 3, 3, 1.0}, {4, 6, 2, 3, 1.0});  // 36 + 24 tokens
    const auto pieces = tjepa::part_pieces(g);
    std::vector<tjepa::MaskDomain> parts{{g, pieces, 0}, {g, pieces, 1}};
    tjepa::MaskWorkspace ws;
    ws.resize(g.num_nodes());
    tjepa::Rng rng(2);
    std::vector<int> out(60);
    ws.excluded.clear();
    for (int v = 0; v < 60; v += 3) ws.excluded.set(v);
    for (int rep = 0; rep < 50; ++rep) {
      const int kept = tjepa::sample_uniform_context(60, 30, rng, ws, out);
      std::set<int> s(out.begin(), out.begin() + kept);
      REQUIRE(static_cast<int>(s.size()) == kept);
      for (int v : s) REQUIRE(v % 3 != 0);
      CHECK(kept <= 30);
    }
    ws.excluded.clear();
    for (int c : {10, 30, 45}) {
      const int kept = tjepa::sample_local_context(g, parts, c, rng, ws, out);
      REQUIRE(kept == c);  // nothing excluded
      std::vector<int> p0, p1;
      for (int k = 0; k < kept; ++k) (g.part(out[k]) == 0 ? p0 : p1).push_back(out[k]);
      CHECK(static_cast<int>(p0.size()) == static_cast<int>(std::lround(c * 36.0 / 60)));
      CHECK(connected(g, p0));
      CHECK(connected(g, p1));
    }
  }

  TEST_CASE("collator on a one-part grid: shapes and sizes and disjointness and minimum and coverage") {
    GridSpec s{20, 20, 5, 5, 1.0};  // 400 tokens, 16 groups
    auto cfg = one_thread();
    tjepa::MaskCollator col(grid_graph(s), cfg);
    CHECK(col.num_targets() == 4);
    CHECK(col.min_context() == 60);  // max(32, ceil(0.15 * 400))
    std::vector<int> local_hits(400, 0), global_hits(400, 0);
    const int B = 16;
    for (std::uint64_t step = 0; step < 60; ++step) {
      const auto b = col.sample(B, 1234, step);
      const auto sizes = col.batch_sizes(1234, step);
      CHECK(sizes.context >= 200);
      CHECK(sizes.context < 360);
      CHECK(sizes.target[0] >= 40);
      CHECK(sizes.target[0] < 72);
      for (int j = 1; j < 4; ++j) CHECK(sizes.target[j] == sizes.target[0]);  // one t per batch
      CHECK(b.targets[0].kind == tjepa::TargetKind::local);
      CHECK(b.targets[1].kind == tjepa::TargetKind::local);
      CHECK(b.targets[2].kind == tjepa::TargetKind::global);
      CHECK(b.targets[3].kind == tjepa::TargetKind::global);
      for (const auto& ts : b.targets) CHECK(ts.part == -1);
      check_batch(col, b, B, sizes);
      for (const auto& ts : b.targets)
        for (int v : ts.indices) ++(ts.kind == tjepa::TargetKind::local ? local_hits : global_hits)[v];
    }
    for (int v = 0; v < 400; ++v) {
      CHECK(local_hits[v] > 0);
      CHECK(global_hits[v] > 0);
    }
  }

  TEST_CASE("small skins (4 to 127 tokens) sample with the defaults: the context minimum scales and t >= 1") {
    // min_context_tokens -1 (the default): min(32, floor(floor(N * 0.5) / 2)), at least
    // ceil(0.15 N) and 1; from 128 tokens on it is 32, as before.
    const std::vector<std::pair<GridSpec, int>> skins = {
        {{2, 2, 2, 2, 1.0}, 1},  {{1, 5, 1, 5, 1.0}, 1},  {{2, 4, 2, 2, 1.0}, 2},  {{2, 5, 2, 5, 1.0}, 2},
        {{4, 4, 2, 2, 1.0}, 4},  {{4, 5, 4, 5, 1.0}, 5},  {{4, 8, 4, 4, 1.0}, 8},  {{8, 8, 4, 4, 1.0}, 16},
        {{8, 15, 4, 5, 1.0}, 30}, {{8, 16, 4, 4, 1.0}, 32}, {{20, 20, 5, 5, 1.0}, 60}};
    for (const auto& [s, min_context] : skins) {
      const int n = s.rows * s.cols;
      CAPTURE(n);
      tjepa::MaskCollator col(grid_graph(s), one_thread());
      CHECK(col.min_context() == min_context);
      for (std::uint64_t step = 0; step < 40; ++step) {
        const auto sizes = col.batch_sizes(7, step);
        for (int t : sizes.target) CHECK(t >= 1);
        check_batch(col, col.sample(8, 7, step), 8, sizes);
      }
    }
    // An explicit minimum is kept as given.
    auto cfg = one_thread();
    cfg.min_context_tokens = 32;
    CHECK_THROWS_WITH_AS(tjepa::MaskCollator(grid_graph({4, 5, 4, 5, 1.0}), cfg),
                         doctest::Contains("the context minimum max(32"), tjepa::ConfigError);
  }

  TEST_CASE("collator on a two-part graph: per-part targets of floor(n_part * s) tokens") {
    auto g = two_part_graph({16, 16, 4, 4, 1.0}, {12, 10, 4, 5, 1.0});  // 256 + 120
    tjepa::MaskCollator col(g, one_thread());
    REQUIRE(col.per_part());
    REQUIRE(col.num_targets() == 4);
    std::vector<int> hits(g.num_nodes(), 0);
    bool sizes_differ = false;
    for (std::uint64_t step = 0; step < 80; ++step) {
      const auto b = col.sample(8, 99, step);
      const auto sizes = col.batch_sizes(99, step);
      check_batch(col, b, 8, sizes);
      const int parts[4] = {0, 0, 1, 1};
      const tjepa::TargetKind kinds[4] = {tjepa::TargetKind::local, tjepa::TargetKind::global,
                                          tjepa::TargetKind::local, tjepa::TargetKind::global};
      for (int j = 0; j < 4; ++j) {
        CHECK(b.targets[j].part == parts[j]);
        CHECK(b.targets[j].kind == kinds[j]);
        const int np = parts[j] == 0 ? 256 : 120;
        CHECK(b.targets[j].size >= static_cast<int>(std::floor(np * 0.10)));
        CHECK(b.targets[j].size <= static_cast<int>(std::floor(np * 0.18)));
      }
      CHECK(b.targets[0].size == b.targets[1].size);
      CHECK(b.targets[2].size == b.targets[3].size);
      // s is drawn per part: the two parts' ratios are not tied together.
      if (std::abs(b.targets[0].size / 256.0 - b.targets[2].size / 120.0) > 0.02) sizes_differ = true;
      for (const auto& ts : b.targets)
        for (int v : ts.indices) ++hits[v];
    }
    CHECK(sizes_differ);
    for (int v = 0; v < g.num_nodes(); ++v) CHECK(hits[v] > 0);
  }

  TEST_CASE("summarize_mask_sizes: the range and mean of what the batches draw / per-part targets on parts of 12 tokens") {
    auto g = two_part_graph({16, 16, 4, 4, 1.0}, {12, 10, 4, 5, 1.0});  // 256 + 120
    tjepa::MaskCollator col(g, one_thread());
    const tjepa::MaskSizeSummary m = tjepa::summarize_mask_sizes(col, 99, 64);
    int lo = 1 << 30, hi = 0, clo = 1 << 30, chi = 0;
    double sum = 0, csum = 0;
    for (std::uint64_t step = 0; step < 64; ++step) {
      const auto z = col.batch_sizes(99, step);
      clo = std::min(clo, z.context), chi = std::max(chi, z.context), csum += z.context;
      for (int t : z.target) lo = std::min(lo, t), hi = std::max(hi, t), sum += t;
    }
    CHECK(m.batches == 64);
    CHECK(m.target_min == lo);
    CHECK(m.target_max == hi);
    CHECK(m.target_mean == doctest::Approx(sum / (64.0 * col.num_targets())));
    CHECK(m.context_min == clo);
    CHECK(m.context_max == chi);
    CHECK(m.context_mean == doctest::Approx(csum / 64));
    CHECK(m.target_min >= 12);   // floor(120 * 0.10)
    CHECK(m.target_max <= 46);   // floor(256 * 0.18)
    // Two parts of 12 tokens: floor(12 * U(0.10, 0.18)) is 1 or 2, mostly 1.
    auto small = two_part_graph({4, 3, 4, 4, 1.0}, {4, 3, 4, 4, 1.0});
    const tjepa::MaskSizeSummary s = tjepa::summarize_mask_sizes(tjepa::MaskCollator(small, one_thread()), 7);
    CHECK(s.target_min == 1);
    CHECK(s.target_max == 2);
    CHECK(s.target_mean < 1.5);
    CHECK_THROWS_AS(tjepa::summarize_mask_sizes(col, 7, 0), tjepa::ConfigError);
  }

  TEST_CASE("ablations on a two-part graph: 4 local or 4 global or local context or whole-sensor targets") {
    auto g = two_part_graph({16, 16, 4, 4, 1.0}, {14, 14, 7, 7, 1.0});  // 256 + 196
    struct Case {
      int nl, ng;
      tjepa::PartTargets pt;
      tjepa::ContextSampling cs;
      tjepa::GlobalSampling gs;
    };
    const Case cases[] = {
        {4, 0, tjepa::PartTargets::whole, tjepa::ContextSampling::uniform, tjepa::GlobalSampling::stratified},
        {0, 4, tjepa::PartTargets::whole, tjepa::ContextSampling::uniform, tjepa::GlobalSampling::uniform},
        {2, 2, tjepa::PartTargets::whole, tjepa::ContextSampling::local, tjepa::GlobalSampling::stratified},
        {4, 0, tjepa::PartTargets::whole, tjepa::ContextSampling::local, tjepa::GlobalSampling::stratified},
        {2, 2, tjepa::PartTargets::automatic, tjepa::ContextSampling::local, tjepa::GlobalSampling::stratified},
    };
    for (const Case& k : cases) {
      auto cfg = one_thread();
      cfg.num_local = k.nl;
      cfg.num_global = k.ng;
      cfg.part_targets = k.pt;
      cfg.context_sampling = k.cs;
      cfg.global_sampling = k.gs;
      if (k.cs == tjepa::ContextSampling::local) cfg.context_ratio = {0.6, 0.9};
      tjepa::MaskCollator col(g, cfg);
      CHECK(col.num_targets() == (k.pt == tjepa::PartTargets::whole ? k.nl + k.ng : 4));
      for (std::uint64_t step = 0; step < 20; ++step) {
        const auto b = col.sample(8, 5, step);
        check_batch(col, b, 8, col.batch_sizes(5, step));
        int locals = 0;
        for (const auto& ts : b.targets) locals += ts.kind == tjepa::TargetKind::local;
        CHECK(locals == (k.pt == tjepa::PartTargets::whole ? k.nl : 2));
      }
    }
  }

  TEST_CASE("determinism: same seed gives the same masks whatever the thread count") {
    auto g = two_part_graph({16, 16, 4, 4, 1.0}, {12, 10, 4, 5, 1.0});
    tjepa::MaskConfig one, four;
    one.num_threads = 1;
    four.num_threads = 4;
    tjepa::MaskCollator a(g, one), b(g, four);
    for (std::uint64_t step : {0u, 1u, 17u}) {
      const auto x = a.sample(32, 77, step), y = b.sample(32, 77, step);
      CHECK(x.K == y.K);
      CHECK(x.context == y.context);
      for (int j = 0; j < 4; ++j) CHECK(x.targets[j].indices == y.targets[j].indices);
      const auto z = a.sample(32, 78, step);
      CHECK(z.context != x.context);
      // sample_into reuses the buffers and gives the same batch.
      tjepa::MaskBatch r = a.sample(32, 1, 1);
      a.sample_into(r, 32, 77, step);
      CHECK(r.context == x.context);
      CHECK(r.targets[3].indices == x.targets[3].indices);
    }
    // Sample i does not depend on the other samples of the batch (its own stream), so a
    // sample's targets are the same whether drawn alone or in a batch of the same size.
    const auto full = a.sample(4, 5, 3);
    const auto again = a.sample(4, 5, 3);
    CHECK(full.targets[0].indices == again.targets[0].indices);
  }

  TEST_CASE("I-JEPA blocks on a full grid are exact h x w rectangles that reach the last row and column") {
    GridSpec s{14, 14, 7, 7, 1.0};
    auto cfg = one_thread();
    cfg.scheme = tjepa::TargetScheme::ijepa_blocks;
    cfg.min_context_tokens = 10;
    cfg.min_context_ratio = 0.0;
    tjepa::MaskCollator col(grid_graph(s), cfg, grid_placement(s));
    CHECK(col.num_targets() == 4);
    bool last_row = false, last_col = false, first_row = false, first_col = false;
    for (std::uint64_t step = 0; step < 100; ++step) {
      const auto b = col.sample(8, 3, step);
      const auto sizes = col.batch_sizes(3, step);
      check_batch(col, b, 8, sizes);
      const auto sh = sizes.target_block;
      // I-JEPA's shape: area in [0.15, 0.2] of 196 cells, aspect in [0.75, 1.5].
      CHECK(sh.h * sh.w >= 20);
      CHECK(sh.h * sh.w <= 49);
      for (const auto& ts : b.targets) {
        CHECK(ts.kind == tjepa::TargetKind::block);
        CHECK(ts.size == sh.h * sh.w);  // full grid: no cut
        for (int i = 0; i < 8; ++i) {
          const auto row = ts.row(i);
          int rmin = 99, rmax = -1, cmin = 99, cmax = -1;
          for (int v : row) {
            rmin = std::min(rmin, v / 14), rmax = std::max(rmax, v / 14);
            cmin = std::min(cmin, v % 14), cmax = std::max(cmax, v % 14);
          }
          CHECK(rmax - rmin + 1 == sh.h);  // a rectangle
          CHECK(cmax - cmin + 1 == sh.w);
          last_row |= rmax == 13;
          last_col |= cmax == 13;
          first_row |= rmin == 0;
          first_col |= cmin == 0;
        }
      }
    }
    CHECK(last_row);
    CHECK(last_col);
    CHECK(first_row);
    CHECK(first_col);
  }

  TEST_CASE("I-JEPA blocks on a sparse atlas: targets cut to the batch's smallest") {
    // Two pads with a gap column between them, placed from coordinates.
    std::vector<double> xy;
    GridSpec pad{6, 5, 6, 5, 1.0};
    std::vector<tjepa::Edge> e;
    std::vector<int> p, gr;
    add_grid(pad, 0, 0, e, p, gr);
    add_grid(pad, 0, 1, e, p, gr);
    for (int k = 0; k < 2; ++k)
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 5; ++c) {
          xy.push_back(2.0 * (c + 6 * k));  // pitch 2, column 5 empty
          xy.push_back(-2.0 * r);
        }
    e.push_back({4, 30, 2.0});
    tjepa::TaxelGraph g(60, e, p, gr);
    auto gp = tjepa::GridPlacement::from_points(xy, 2.0);
    CHECK(gp.rows == 6);
    CHECK(gp.cols == 11);
    CHECK(gp.row[30 + 7] == 1);
    CHECK(gp.col[30 + 7] == 8);
    auto cfg = one_thread();
    cfg.scheme = tjepa::TargetScheme::ijepa_blocks;
    cfg.min_context_tokens = 5;
    cfg.min_context_ratio = 0;
    tjepa::MaskCollator col(g, cfg, gp);
    for (std::uint64_t step = 0; step < 30; ++step) check_batch(col, col.sample(6, 8, step), 6, col.batch_sizes(8, step));
  }

  TEST_CASE("bad configurations throw with a message that names the problem") {
    auto g = grid_graph({20, 20, 5, 5, 1.0});
    auto make = [&](auto edit) {
      auto c = one_thread();
      edit(c);
      return tjepa::MaskCollator(g, c);
    };
    using CE = tjepa::ConfigError;
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.target_ratio = {0.0, 0.1}; }),
                         doctest::Contains("target_ratio = [0, 0.1]"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.context_ratio = {0.5, 1.0}; }),
                         doctest::Contains("context_ratio"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.target_ratio = {0.2, 0.1}; }),
                         doctest::Contains("lo <= hi"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.num_local = 0, c.num_global = 0; }),
                         doctest::Contains("at least one target"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.num_global = 500; }),
                         doctest::Contains("more than the 400 tokens"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.min_context_tokens = 250; }),
                         doctest::Contains("fewer than its minimum 250"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.max_tries = 0; }), doctest::Contains("max_tries"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.min_context_ratio = std::nan(""); }),
                         doctest::Contains("min_context_ratio = nan"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.target_ratio = {0.1, std::nan("")}; }),
                         doctest::Contains("target_ratio"), CE);
    CHECK_THROWS_WITH_AS(make([](auto& c) { c.scheme = tjepa::TargetScheme::ijepa_blocks; }),
                         doctest::Contains("needs a grid placement"), CE);
    // Local targets larger than any connected piece.
    auto split = two_part_graph({10, 10, 5, 5, 1.0}, {10, 10, 5, 5, 1.0});
    tjepa::MaskConfig c;
    c.part_targets = tjepa::PartTargets::whole;
    c.target_ratio = {0.4, 0.6};  // t up to 120 of 200, parts of 100
    CHECK_THROWS_WITH_AS(tjepa::MaskCollator(split, c), doctest::Contains("largest connected piece"), CE);
    // A context that cannot keep its minimum once the targets are removed: fails after the
    // tries, saying why.
    auto tight = one_thread();
    tight.context_ratio = {0.5, 0.5};
    tight.target_ratio = {0.17, 0.18};
    tight.min_context_tokens = 190;
    tight.max_tries = 3;
    tjepa::MaskCollator col(g, tight);
    CHECK_THROWS_WITH_AS(col.sample(4, 1, 0), doctest::Contains("of the 190 tokens it needs"), CE);
    CHECK_THROWS_WITH_AS(col.sample(0, 1, 0), doctest::Contains("batch_size = 0"), CE);
  }
}
