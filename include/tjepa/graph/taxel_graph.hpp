#pragma once
// TaxelGraph: the weighted undirected graph G = (V, E) over a sensor's tokens (taxels, or groups of
// taxels), in CSR form. Every node also knows its part (a connected piece of the embodiment: a
// hand, a foot) and its group (its pad or region), which the global masks stratify over.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

// One undirected edge; the graph stores it in both directions.
struct Edge {
  int src = 0;
  int dst = 0;
  double weight = 1.0;
  friend bool operator==(const Edge&, const Edge&) = default;
};

class TaxelGraph {
 public:
  TaxelGraph() = default;

  // n nodes, undirected edges (each pair at most once, in either orientation), and per node its
  // part and group (empty: all 0). Throws on an empty graph, unknown nodes, self loops, duplicate
  // edges, negative or non-finite weights, and part/group ids that are negative.
  TaxelGraph(int n, std::span<const Edge> edges, std::vector<int> part = {},
             std::vector<int> group = {})
      : n_(n), part_(std::move(part)), group_(std::move(group)) {
    require<DataError>(n > 0, "TaxelGraph: number of nodes ", n, ", expected > 0 (empty layout)");
    if (part_.empty()) part_.assign(n, 0);
    if (group_.empty()) group_.assign(n, 0);
    require<ShapeError>(static_cast<int>(part_.size()) == n, "TaxelGraph: part has ", part_.size(),
                        " entries, expected ", n);
    require<ShapeError>(static_cast<int>(group_.size()) == n, "TaxelGraph: group has ",
                        group_.size(), " entries, expected ", n);
    for (int i = 0; i < n; ++i) {
      require<DataError>(part_[i] >= 0, "TaxelGraph: node ", i, " has part ", part_[i], ", expected >= 0");
      require<DataError>(group_[i] >= 0, "TaxelGraph: node ", i, " has group ", group_[i], ", expected >= 0");
    }
    num_parts_ = *std::max_element(part_.begin(), part_.end()) + 1;
    num_groups_ = *std::max_element(group_.begin(), group_.end()) + 1;

    std::vector<int> deg(n, 0);
    for (std::size_t e = 0; e < edges.size(); ++e) {
      const Edge& ed = edges[e];
      require<DataError>(ed.src >= 0 && ed.src < n && ed.dst >= 0 && ed.dst < n, "TaxelGraph: edge ",
                         e, " (", ed.src, " -> ", ed.dst, ") names an unknown taxel, expected ids in [0, ",
                         n, ")");
      require<DataError>(ed.src != ed.dst, "TaxelGraph: edge ", e, " is a self loop on taxel ", ed.src);
      require<DataError>(std::isfinite(ed.weight) && ed.weight >= 0, "TaxelGraph: edge ", e, " (",
                         ed.src, " -> ", ed.dst, ") has weight ", ed.weight,
                         ", expected a finite value >= 0");
      ++deg[ed.src];
      ++deg[ed.dst];
    }
    offsets_.assign(n + 1, 0);
    for (int i = 0; i < n; ++i) offsets_[i + 1] = offsets_[i] + deg[i];
    adj_.resize(offsets_[n]);
    w_.resize(offsets_[n]);
    std::vector<int> fill(offsets_.begin(), offsets_.end() - 1);
    for (const Edge& ed : edges) {
      adj_[fill[ed.src]] = ed.dst;
      w_[fill[ed.src]++] = ed.weight;
      adj_[fill[ed.dst]] = ed.src;
      w_[fill[ed.dst]++] = ed.weight;
    }
    // Sort each neighbour list by id (deterministic order) and reject duplicates.
    std::vector<std::pair<int, double>> tmp;
    for (int i = 0; i < n; ++i) {
      tmp.clear();
      for (int k = offsets_[i]; k < offsets_[i + 1]; ++k) tmp.emplace_back(adj_[k], w_[k]);
      std::sort(tmp.begin(), tmp.end());
      for (std::size_t k = 1; k < tmp.size(); ++k)
        require<DataError>(tmp[k].first != tmp[k - 1].first, "TaxelGraph: duplicate edge ", i,
                           " -- ", tmp[k].first);
      for (std::size_t k = 0; k < tmp.size(); ++k) {
        adj_[offsets_[i] + k] = tmp[k].first;
        w_[offsets_[i] + k] = tmp[k].second;
      }
    }
    compute_components();
  }

  int num_nodes() const { return n_; }
  std::size_t num_edges() const { return adj_.size() / 2; }  // undirected

  std::span<const int> neighbors(int i) const {
    return {adj_.data() + offsets_[i], static_cast<std::size_t>(offsets_[i + 1] - offsets_[i])};
  }
  std::span<const double> weights(int i) const {
    return {w_.data() + offsets_[i], static_cast<std::size_t>(offsets_[i + 1] - offsets_[i])};
  }
  int degree(int i) const { return offsets_[i + 1] - offsets_[i]; }

  // CSR arrays: neighbours of i are adjacency()[offsets()[i] .. offsets()[i+1]).
  const std::vector<int>& offsets() const { return offsets_; }
  const std::vector<int>& adjacency() const { return adj_; }
  const std::vector<double>& edge_weights() const { return w_; }

  int part(int i) const { return part_[i]; }
  int group(int i) const { return group_[i]; }
  const std::vector<int>& parts() const { return part_; }
  const std::vector<int>& groups() const { return group_; }
  int num_parts() const { return num_parts_; }
  int num_groups() const { return num_groups_; }

  int component(int i) const { return comp_[i]; }
  const std::vector<int>& components() const { return comp_; }
  int num_components() const { return static_cast<int>(comp_size_.size()); }
  int component_size(int c) const { return comp_size_[c]; }

  // Each undirected edge once, src < dst, sorted.
  std::vector<Edge> edges() const {
    std::vector<Edge> out;
    out.reserve(num_edges());
    for (int i = 0; i < n_; ++i)
      for (int k = offsets_[i]; k < offsets_[i + 1]; ++k)
        if (i < adj_[k]) out.push_back({i, adj_[k], w_[k]});
    return out;
  }

 private:
  void compute_components() {
    comp_.assign(n_, -1);
    comp_size_.clear();
    std::vector<int> stack;
    for (int s = 0; s < n_; ++s) {
      if (comp_[s] >= 0) continue;
      const int c = static_cast<int>(comp_size_.size());
      comp_size_.push_back(0);
      comp_[s] = c;
      stack.push_back(s);
      while (!stack.empty()) {
        const int u = stack.back();
        stack.pop_back();
        ++comp_size_[c];
        for (int v : neighbors(u))
          if (comp_[v] < 0) {
            comp_[v] = c;
            stack.push_back(v);
          }
      }
    }
  }

  int n_ = 0;
  std::vector<int> offsets_{0}, adj_;
  std::vector<double> w_;
  std::vector<int> part_, group_;
  int num_parts_ = 0, num_groups_ = 0;
  std::vector<int> comp_, comp_size_;
};

// Whether the nodes induce a connected subgraph of g (false for no nodes). Nodes must be distinct
// and in [0, g.num_nodes()).
inline bool induces_connected(const TaxelGraph& g, std::span<const int> nodes) {
  if (nodes.empty()) return false;
  std::vector<int> in(nodes.begin(), nodes.end()), stack{nodes[0]};
  std::sort(in.begin(), in.end());
  std::vector<std::uint8_t> reached(in.size(), 0);
  reached[std::lower_bound(in.begin(), in.end(), nodes[0]) - in.begin()] = 1;
  std::size_t count = 1;
  while (!stack.empty()) {
    const int u = stack.back();
    stack.pop_back();
    for (int v : g.neighbors(u)) {
      const auto it = std::lower_bound(in.begin(), in.end(), v);
      if (it == in.end() || *it != v || reached[it - in.begin()]) continue;
      reached[it - in.begin()] = 1;
      ++count;
      stack.push_back(v);
    }
  }
  return count == in.size();
}

}  // namespace tjepa
