#pragma once
// The pieces of MaskWorkspace (masks/workspace.hpp): sets with O(1) clear, the Dijkstra frontier,
// token sorting.
#include <algorithm>
#include <bit>
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

// One Dijkstra frontier entry: a 128-bit key, compared as one integer (branch-free, which is what
// makes the heap fast): high 64 bits = the distance's bits (a non-negative double's bit pattern
// orders like its value), low 64 bits = the tie-break word (random 32-bit key of the node << 32) |
// node, so equal distances pop in random order and the node rides along.
struct FrontierItem {
  __uint128_t key;
  static FrontierItem make(double dist, std::uint64_t tie) {
    return {(static_cast<__uint128_t>(std::bit_cast<std::uint64_t>(dist)) << 64) | tie};
  }
  double dist() const { return std::bit_cast<double>(static_cast<std::uint64_t>(key >> 64)); }
  int node() const { return static_cast<int>(static_cast<std::uint32_t>(key)); }
};
inline bool nearer(const FrontierItem& a, const FrontierItem& b) { return a.key < b.key; }

// A binary min-heap over a caller-owned vector (no allocation once it has grown).
class Frontier {
 public:
  void clear() { h_.clear(); }
  bool empty() const { return h_.empty(); }
  void reserve(std::size_t n) { h_.reserve(n); }
  void push(FrontierItem x) {
    std::size_t i = h_.size();
    h_.push_back(x);
    while (i > 0) {
      const std::size_t parent = (i - 1) / 2;
      if (!nearer(x, h_[parent])) break;
      h_[i] = h_[parent];
      i = parent;
    }
    h_[i] = x;
  }
  FrontierItem pop() {
    const FrontierItem top = h_[0];
    const FrontierItem last = h_.back();
    h_.pop_back();
    const std::size_t n = h_.size();
    if (n > 0) {
      std::size_t i = 0;
      for (;;) {
        std::size_t c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n) c += static_cast<std::size_t>(nearer(h_[c + 1], h_[c]));
        if (!nearer(h_[c], last)) break;
        h_[i] = h_[c];
        i = c;
      }
      h_[i] = last;
    }
    return top;
  }

 private:
  std::vector<FrontierItem> h_;
};

// Writes the m distinct token ids src[0..m) to dst in ascending order through a bitset of the
// N tokens ((N + 63) / 64 words, all zero on entry and on return): O(m + N/64), no comparisons.
inline void sort_tokens(const int* src, int m, std::uint64_t* bits, int words, int* dst) {
  for (int k = 0; k < m; ++k) bits[src[k] >> 6] |= std::uint64_t{1} << (src[k] & 63);
  for (int wi = 0; wi < words; ++wi) {
    std::uint64_t word = bits[wi];
    bits[wi] = 0;
    while (word != 0) {
      *dst++ = (wi << 6) + std::countr_zero(word);
      word &= word - 1;
    }
  }
}

}  // namespace tjepa::detail
