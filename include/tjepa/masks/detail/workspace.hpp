#pragma once
// Scratch buffers of the mask samplers, owned by the caller and reused from sample to sample so
// that the per-sample path allocates nothing once the buffers have grown to the graph's size.
#include <algorithm>
#include <cstdint>
#include <vector>

namespace tjepa::detail {

// A set of token ids with O(1) clear: a token is in the set when its stamp equals the epoch.
class EpochMarks {
 public:
  void resize(int n) {
    if (static_cast<int>(stamp_.size()) < n) stamp_.resize(n, 0);
  }
  // Empties the set.
  void clear() {
    if (++epoch_ == 0) {  // wrapped: old stamps could alias the new epoch
      std::fill(stamp_.begin(), stamp_.end(), 0u);
      epoch_ = 1;
    }
  }
  bool test(int i) const { return stamp_[i] == epoch_; }
  void set(int i) { stamp_[i] = epoch_; }
  // Inserts i; returns false if it was already there.
  bool insert(int i) {
    if (stamp_[i] == epoch_) return false;
    stamp_[i] = epoch_;
    return true;
  }

 private:
  std::vector<std::uint32_t> stamp_;
  std::uint32_t epoch_ = 1;
};

// One Dijkstra frontier entry: ordered by distance, then by a random key (the tie-break).
struct FrontierItem {
  double dist;
  std::uint64_t key;
  int node;
};
// std::push_heap builds a max-heap: "less" means farther (or, at equal distance, larger key).
struct FrontierFarther {
  bool operator()(const FrontierItem& a, const FrontierItem& b) const {
    return a.dist > b.dist || (a.dist == b.dist && a.key > b.key);
  }
};

}  // namespace tjepa::detail

namespace tjepa {

// Per-thread scratch of the mask samplers: pass the same one to every call on a thread.
struct MaskWorkspace {
  detail::EpochMarks picked;    // tokens already in the mask being built
  detail::EpochMarks reached;   // Dijkstra: tokens with a tentative distance
  detail::EpochMarks settled;   // Dijkstra: tokens settled
  detail::EpochMarks excluded;  // the union of a sample's targets
  std::vector<double> dist;     // [N] Dijkstra tentative distances
  std::vector<std::uint64_t> key;  // [N] Dijkstra random tie-break key, drawn when first reached
  std::vector<detail::FrontierItem> frontier;
  std::vector<int> perm;        // [N] partial Fisher–Yates scratch
  std::vector<int> order;       // [G] group order scratch

  void resize(int n) {
    picked.resize(n);
    reached.resize(n);
    settled.resize(n);
    excluded.resize(n);
    if (static_cast<int>(dist.size()) < n) dist.resize(n);
    if (static_cast<int>(key.size()) < n) key.resize(n);
    if (static_cast<int>(perm.size()) < n) perm.resize(n);
    frontier.reserve(static_cast<std::size_t>(n) * 4);
  }
};

}  // namespace tjepa
