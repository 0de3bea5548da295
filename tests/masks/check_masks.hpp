#pragma once
// Property checks shared by the masks tests: each asserts what the collator documents, on any
// graph. Included by the masks test files only.
#include <doctest/doctest.h>

#include <tjepa/masks/collator.hpp>

#include <algorithm>
#include <cmath>
#include <queue>
#include <set>
#include <vector>

namespace masks_test {

// A rows x cols 4-neighbour grid of unit-weight edges, token id offset + r*cols + c, all in `part`;
// group = (r / pad_rows) * ceil(cols / pad_cols) + c / pad_cols + group_offset.
struct GridSpec {
  int rows = 8, cols = 8;
  int pad_rows = 4, pad_cols = 4;
  double weight = 1.0;
};

// The tests' configuration: the defaults on one thread (CI's 2 cores are shared; the determinism
// test runs several threads on purpose).
inline tjepa::MaskConfig one_thread(tjepa::MaskConfig c = {}) {
  c.num_threads = 1;
  return c;
}

inline void add_grid(const GridSpec& s, int part, int group_offset, std::vector<tjepa::Edge>& edges,
                     std::vector<int>& parts, std::vector<int>& groups) {
  const int offset = static_cast<int>(parts.size());
  const int pads_per_row = (s.cols + s.pad_cols - 1) / s.pad_cols;
  for (int r = 0; r < s.rows; ++r)
    for (int c = 0; c < s.cols; ++c) {
      const int id = offset + r * s.cols + c;
      parts.push_back(part);
      groups.push_back(group_offset + (r / s.pad_rows) * pads_per_row + c / s.pad_cols);
      if (c + 1 < s.cols) edges.push_back({id, id + 1, s.weight});
      if (r + 1 < s.rows) edges.push_back({id, id + s.cols, s.weight});
    }
}

inline tjepa::TaxelGraph grid_graph(const GridSpec& s) {
  std::vector<tjepa::Edge> e;
  std::vector<int> p, g;
  add_grid(s, 0, 0, e, p, g);
  return tjepa::TaxelGraph(static_cast<int>(p.size()), e, p, g);
}

inline tjepa::GridPlacement grid_placement(const GridSpec& s) {
  tjepa::GridPlacement gp;
  gp.rows = s.rows;
  gp.cols = s.cols;
  for (int r = 0; r < s.rows; ++r)
    for (int c = 0; c < s.cols; ++c) {
      gp.row.push_back(r);
      gp.col.push_back(c);
    }
  return gp;
}

// Two unconnected grids (two parts), groups numbered over both.
inline tjepa::TaxelGraph two_part_graph(const GridSpec& a, const GridSpec& b) {
  std::vector<tjepa::Edge> e;
  std::vector<int> p, g;
  add_grid(a, 0, 0, e, p, g);
  const int g0 = *std::max_element(g.begin(), g.end()) + 1;
  add_grid(b, 1, g0, e, p, g);
  return tjepa::TaxelGraph(static_cast<int>(p.size()), e, p, g);
}

inline bool strictly_ascending_in_range(std::span<const int> row, int n) {
  for (std::size_t k = 0; k < row.size(); ++k) {
    if (row[k] < 0 || row[k] >= n) return false;
    if (k > 0 && row[k] <= row[k - 1]) return false;
  }
  return true;
}

// Whether the tokens induce a connected subgraph of g.
inline bool connected(const tjepa::TaxelGraph& g, std::span<const int> tokens) {
  if (tokens.empty()) return true;
  std::vector<char> in(g.num_nodes(), 0), seen(g.num_nodes(), 0);
  for (int v : tokens) in[v] = 1;
  std::vector<int> stack{tokens[0]};
  seen[tokens[0]] = 1;
  std::size_t count = 0;
  while (!stack.empty()) {
    const int u = stack.back();
    stack.pop_back();
    ++count;
    for (int v : g.neighbors(u))
      if (in[v] && !seen[v]) {
        seen[v] = 1;
        stack.push_back(v);
      }
  }
  return count == tokens.size();
}

// Shortest-path distances from s inside s's part.
inline std::vector<double> distances_from(const tjepa::TaxelGraph& g, int s) {
  std::vector<double> d(g.num_nodes(), INFINITY);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> q;
  d[s] = 0;
  q.push({0.0, s});
  while (!q.empty()) {
    auto [du, u] = q.top();
    q.pop();
    if (du > d[u]) continue;
    const auto nb = g.neighbors(u);
    const auto w = g.weights(u);
    for (std::size_t k = 0; k < nb.size(); ++k)
      if (g.part(nb[k]) == g.part(s) && du + w[k] < d[nb[k]]) {
        d[nb[k]] = du + w[k];
        q.push({d[nb[k]], nb[k]});
      }
  }
  return d;
}

// A Dijkstra ball: some token s of the set has every member no farther than every non-member.
inline bool is_dijkstra_ball(const tjepa::TaxelGraph& g, std::span<const int> tokens) {
  std::vector<char> in(g.num_nodes(), 0);
  for (int v : tokens) in[v] = 1;
  for (int s : tokens) {
    const auto d = distances_from(g, s);
    double inside = 0, outside = INFINITY;
    for (int v = 0; v < g.num_nodes(); ++v) {
      if (in[v]) inside = std::max(inside, d[v]);
      else outside = std::min(outside, d[v]);
    }
    if (inside <= outside + 1e-12) return true;
  }
  return false;
}

// Every documented property of one batch.
inline void check_batch(const tjepa::MaskCollator& col, const tjepa::MaskBatch& b, int B,
                        const tjepa::MaskBatchSizes& sizes) {
  const tjepa::TaxelGraph& g = col.graph();
  const int n = g.num_nodes();
  REQUIRE(b.B == B);
  REQUIRE(b.context.size() == static_cast<std::size_t>(B) * b.K);
  REQUIRE(b.num_targets() == col.num_targets());
  CHECK(b.K >= col.min_context());
  const bool blocks = col.config().scheme == tjepa::TargetScheme::ijepa_blocks;
  if (!blocks) CHECK(b.K <= sizes.context);
  for (int j = 0; j < b.num_targets(); ++j) {
    const auto& ts = b.targets[j];
    REQUIRE(ts.indices.size() == static_cast<std::size_t>(B) * ts.size);
    CHECK(ts.size >= 1);
    if (!blocks) CHECK(ts.size == sizes.target[j]);
  }
  std::vector<char> in_ctx(n);
  for (int i = 0; i < B; ++i) {
    CAPTURE(i);
    const auto ctx = b.context_row(i);
    REQUIRE(strictly_ascending_in_range(ctx, n));
    std::fill(in_ctx.begin(), in_ctx.end(), 0);
    for (int v : ctx) in_ctx[v] = 1;
    for (int j = 0; j < b.num_targets(); ++j) {
      CAPTURE(j);
      const auto& ts = b.targets[j];
      const auto row = ts.row(i);
      REQUIRE(strictly_ascending_in_range(row, n));
      bool disjoint = true, in_part = true, one_part = true;
      for (int v : row) {
        disjoint &= !in_ctx[v];
        in_part &= ts.part < 0 || g.part(v) == ts.part;
        one_part &= g.part(v) == g.part(row[0]);
      }
      REQUIRE(disjoint);
      REQUIRE(in_part);
      if (ts.kind == tjepa::TargetKind::local) {
        REQUIRE(one_part);
        REQUIRE(connected(g, row));
      }
      if (ts.kind == tjepa::TargetKind::global &&
          col.config().global_sampling == tjepa::GlobalSampling::stratified) {
        const tjepa::MaskDomain& d = col.domain(ts.part);
        std::set<int> groups;
        for (int v : row) groups.insert(g.group(v));
        // t >= G: every group of the domain; t < G: t different groups.
        REQUIRE(static_cast<int>(groups.size()) >= std::min(ts.size, d.num_groups()));
      }
    }
  }
}

}  // namespace masks_test
