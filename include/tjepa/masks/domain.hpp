#pragma once
// MaskDomain: the tokens a target is drawn from (the whole sensor, or one part), with what the
// samplers need precomputed: the tokens of each group (for stratified global masks) and the tokens
// ordered by the size of their connected piece (for the seeds of local masks).
//
// A "piece" is a connected component of the graph once the edges between different parts are
// dropped: a local mask grows inside the piece of its seed, so it is connected and lies in one part.
#include <algorithm>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/taxel_graph.hpp"

namespace tjepa {

struct GraphPieces {
  std::vector<int> piece;  // [N] piece id of each token
  std::vector<int> size;   // [P] tokens per piece
};

inline GraphPieces part_pieces(const TaxelGraph& g) {
  const int n = g.num_nodes();
  GraphPieces out;
  out.piece.assign(n, -1);
  std::vector<int> stack;
  for (int s = 0; s < n; ++s) {
    if (out.piece[s] >= 0) continue;
    const int id = static_cast<int>(out.size.size());
    out.size.push_back(0);
    out.piece[s] = id;
    stack.push_back(s);
    while (!stack.empty()) {
      const int u = stack.back();
      stack.pop_back();
      ++out.size[id];
      for (int v : g.neighbors(u))
        if (out.piece[v] < 0 && g.part(v) == g.part(u)) {
          out.piece[v] = id;
          stack.push_back(v);
        }
    }
  }
  return out;
}

class MaskDomain {
 public:
  MaskDomain() = default;
  // The tokens of `part` (-1: every token) of g; pieces from part_pieces(g).
  MaskDomain(const TaxelGraph& g, const GraphPieces& pieces, int part) : part_(part) {
    require<ConfigError>(part >= -1 && part < g.num_parts(), "MaskDomain: part ", part,
                         ", expected -1 (whole sensor) or a part in [0, ", g.num_parts(), ")");
    for (int i = 0; i < g.num_nodes(); ++i)
      if (part < 0 || g.part(i) == part) tokens_.push_back(i);
    require<DataError>(!tokens_.empty(), "MaskDomain: part ", part, " holds no token");

    // Seeds: largest piece first; ties by token id, so the order is deterministic.
    seeds_ = tokens_;
    std::stable_sort(seeds_.begin(), seeds_.end(), [&](int a, int b) {
      return pieces.size[pieces.piece[a]] > pieces.size[pieces.piece[b]];
    });
    seed_piece_size_.resize(seeds_.size());
    for (std::size_t k = 0; k < seeds_.size(); ++k)
      seed_piece_size_[k] = pieces.size[pieces.piece[seeds_[k]]];

    // Groups present in the domain, in increasing group id, as CSR.
    std::vector<int> count(g.num_groups(), 0);
    for (int i : tokens_) ++count[g.group(i)];
    std::vector<int> slot(g.num_groups(), -1);
    group_offsets_.assign(1, 0);
    for (int gr = 0; gr < g.num_groups(); ++gr)
      if (count[gr] > 0) {
        slot[gr] = static_cast<int>(group_offsets_.size()) - 1;
        group_offsets_.push_back(group_offsets_.back() + count[gr]);
      }
    group_tokens_.resize(tokens_.size());
    std::vector<int> fill(group_offsets_.begin(), group_offsets_.end() - 1);
    for (int i : tokens_) group_tokens_[fill[slot[g.group(i)]]++] = i;
  }

  int part() const { return part_; }
  int size() const { return static_cast<int>(tokens_.size()); }
  std::span<const int> tokens() const { return tokens_; }  // ascending ids
  int token(int k) const { return tokens_[k]; }

  // Tokens whose piece holds at least t tokens (the eligible seeds of a local mask of size t):
  // seed(0) .. seed(num_seeds(t) - 1).
  int num_seeds(int t) const {
    // seed_piece_size_ is non-increasing: find the first entry < t.
    const auto it = std::partition_point(seed_piece_size_.begin(), seed_piece_size_.end(),
                                         [t](int s) { return s >= t; });
    return static_cast<int>(it - seed_piece_size_.begin());
  }
  int seed(int k) const { return seeds_[k]; }
  int largest_piece() const { return seed_piece_size_.front(); }

  int num_groups() const { return static_cast<int>(group_offsets_.size()) - 1; }
  std::span<const int> group_tokens(int k) const {
    return {group_tokens_.data() + group_offsets_[k],
            static_cast<std::size_t>(group_offsets_[k + 1] - group_offsets_[k])};
  }

 private:
  int part_ = -1;
  std::vector<int> tokens_;
  std::vector<int> seeds_, seed_piece_size_;
  std::vector<int> group_offsets_{0}, group_tokens_;
};

}  // namespace tjepa
