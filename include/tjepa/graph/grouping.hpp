#pragma once
// Grouping: adjacent taxels gathered into group tokens (n_g = 4-5 taxels each on DECO-50), so
// attention runs over G ≈ N / n_g tokens instead of N taxels.
//
// A Grouping holds, for G group tokens and n_max = the largest group size:
//   members  [G, n_max]  taxel indices, padded with -1
//   valid    [G, n_max]  1 where members is a taxel
//   sizes    [G]         n_g of each token (the tokenizer has one affine map per size)
//   part     [G]         the part (hand) of each token
//   region   [G]         the layout group (pad, region) holding the token's taxels (for a token
//                        spanning regions: the one holding most of them, lowest id on ties)
//   token_of [N]         the token of each taxel
//   graph                the coarse group graph over the G tokens: tokens g != h adjacent when a
//                        taxel edge joins them (bridges included); graph.part(g) = part[g],
//                        graph.group(g) = region[g], so stratified global masks over the tokens
//                        draw one token per region. Weights 1 by default.
// gather_indices(τ, m) turns a window [N, τ, m] into tokens [G, n_max·τ·m].
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <map>
#include <span>
#include <utility>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/skin.hpp"
#include "tjepa/graph/taxel_graph.hpp"

namespace tjepa {

enum class GroupWeights {
  unit,               // every group edge weighs 1 (the reference)
  centroid_distance,  // distance (mm) between the two tokens' coordinate centroids
};

struct Grouping {
  int num_taxels = 0;
  int max_size = 0;
  std::vector<int> members;
  std::vector<std::uint8_t> valid;
  std::vector<int> sizes;
  std::vector<int> part;
  std::vector<int> region;
  std::vector<int> token_of;
  TaxelGraph graph;

  int num_groups() const { return static_cast<int>(sizes.size()); }
  std::span<const int> members_of(int g) const {
    return {members.data() + static_cast<std::size_t>(g) * max_size, static_cast<std::size_t>(sizes[g])};
  }

  // Per-taxel values [N] from per-token values [G] (e.g. a mask's colours, to draw it on the layout).
  template <class T>
  std::vector<T> per_taxel(std::span<const T> per_token) const {
    require<ShapeError>(static_cast<int>(per_token.size()) == num_groups(), "Grouping::per_taxel: ",
                        per_token.size(), " values, expected one per token (", num_groups(), ")");
    std::vector<T> out;
    out.reserve(token_of.size());
    for (int t : token_of) out.push_back(per_token[t]);
    return out;
  }

  // [G, n_max·τ·m] indices into a window x flattened from [N, τ, m] (x[i, t, a] at i·τ·m + t·m + a):
  // token g's row lists its members' τ·m values one member after the other, in members order.
  // Padded slots (size < n_max) hold the sentinel N·τ·m: append one zero to the flattened window
  // (N·τ·m + 1 values) and gather, so padding reads 0.
  std::vector<int> gather_indices(int tau, int m) const {
    require<ConfigError>(tau > 0 && m > 0, "Grouping::gather_indices: tau = ", tau, ", m = ", m,
                         ", expected both > 0");
    const long long tm = static_cast<long long>(tau) * m;
    require<ConfigError>(static_cast<long long>(num_taxels) * tm < INT_MAX, "Grouping::gather_indices: N·τ·m = ",
                         static_cast<long long>(num_taxels) * tm, " does not fit an int index");
    const int stride = static_cast<int>(tm), sentinel = num_taxels * stride;
    std::vector<int> idx(static_cast<std::size_t>(num_groups()) * max_size * stride);
    std::size_t o = 0;
    for (int g = 0; g < num_groups(); ++g)
      for (int j = 0; j < max_size; ++j) {
        const int i = members[static_cast<std::size_t>(g) * max_size + j];
        for (int k = 0; k < stride; ++k) idx[o++] = i >= 0 ? i * stride + k : sentinel;
      }
    return idx;
  }
};

// Builds a Grouping from explicit groups of taxel indices. Throws unless every taxel is in exactly
// one group, no group is empty, each group lies inside one part and is connected in the taxel graph.
inline Grouping make_grouping(const Skin& skin, const std::vector<std::vector<int>>& groups,
                              GroupWeights weights = GroupWeights::unit) {
  const TaxelLayout& l = skin.layout;
  const TaxelGraph& tg = skin.graph;
  const int n = l.size(), G = static_cast<int>(groups.size());
  require<ShapeError>(tg.num_nodes() == n, "make_grouping: graph has ", tg.num_nodes(), " nodes, layout ", n);
  require<ConfigError>(G > 0, "make_grouping: no groups");
  Grouping out;
  out.num_taxels = n;
  out.token_of.assign(n, -1);
  out.sizes.resize(G);
  out.part.resize(G);
  out.region.resize(G);
  for (int g = 0; g < G; ++g) {
    require<DataError>(!groups[g].empty(), "make_grouping: group ", g, " is empty");
    out.sizes[g] = static_cast<int>(groups[g].size());
    out.max_size = std::max(out.max_size, out.sizes[g]);
    for (int i : groups[g]) {
      require<DataError>(i >= 0 && i < n, "make_grouping: group ", g, " names taxel ", i, ", expected in [0, ", n, ")");
      require<DataError>(out.token_of[i] < 0, "make_grouping: taxel ", l.ids[i], " is in groups ", out.token_of[i],
                         " and ", g, ", expected exactly one");
      out.token_of[i] = g;
    }
  }
  for (int i = 0; i < n; ++i)
    require<DataError>(out.token_of[i] >= 0, "make_grouping: taxel ", l.ids[i], " is in no group");

  // Part, region, and connectivity of each group.
  std::map<int, int> votes;
  for (int g = 0; g < G; ++g) {
    const auto& mem = groups[g];
    out.part[g] = l.part[mem[0]];
    votes.clear();
    for (int i : mem) {
      require<DataError>(l.part[i] == out.part[g], "make_grouping: group ", g, " spans parts '",
                         l.part_names[out.part[g]], "' and '", l.part_names[l.part[i]], "'");
      ++votes[l.group[i]];
    }
    int best = -1;
    for (const auto& [region, count] : votes)
      if (best < 0 || count > votes[best]) best = region;
    out.region[g] = best;
    require<DataError>(induces_connected(tg, mem), "make_grouping: group ", g, " (", out.sizes[g],
                       " taxels, first id ", l.ids[mem[0]], ") is not connected in the taxel graph");
  }

  const std::size_t nm = out.max_size;
  out.members.assign(static_cast<std::size_t>(G) * nm, -1);
  out.valid.assign(static_cast<std::size_t>(G) * nm, 0);
  for (int g = 0; g < G; ++g)
    for (std::size_t j = 0; j < groups[g].size(); ++j) {
      out.members[g * nm + j] = groups[g][j];
      out.valid[g * nm + j] = 1;
    }

  // Lift the taxel edges to tokens, each token pair once.
  std::vector<std::pair<int, int>> pairs;
  for (int u = 0; u < n; ++u)
    for (int v : tg.neighbors(u)) {
      const int a = out.token_of[u], b = out.token_of[v];
      if (u < v && a != b) pairs.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  std::vector<double> centroid;
  if (weights == GroupWeights::centroid_distance) {
    require<ConfigError>(l.has_coords(), "make_grouping: centroid_distance weights need coordinates");
    centroid.assign(static_cast<std::size_t>(G) * l.dim, 0.0);
    for (int g = 0; g < G; ++g)
      for (int i : groups[g])
        for (int a = 0; a < l.dim; ++a) centroid[static_cast<std::size_t>(g) * l.dim + a] += l.coord(i, a) / out.sizes[g];
  }
  std::vector<Edge> edges;
  edges.reserve(pairs.size());
  for (const auto& [a, b] : pairs) {
    double w = 1.0;
    if (weights == GroupWeights::centroid_distance) {
      double s = 0;
      for (int d = 0; d < l.dim; ++d) {
        const double x = centroid[static_cast<std::size_t>(a) * l.dim + d] - centroid[static_cast<std::size_t>(b) * l.dim + d];
        s += x * x;
      }
      w = std::sqrt(s);
    }
    edges.push_back({a, b, w});
  }
  out.graph = TaxelGraph(G, edges, out.part, out.region);
  return out;
}

}  // namespace tjepa
