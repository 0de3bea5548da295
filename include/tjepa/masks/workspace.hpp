#pragma once
// Per-thread scratch of the mask samplers, owned by the caller and reused from sample to sample so
// that the per-sample path allocates nothing once the buffers have grown to the graph's size.
#include <cstdint>
#include <vector>

#include "tjepa/masks/detail/frontier.hpp"

namespace tjepa {

// Per-thread scratch of the mask samplers: pass the same one to every call on a thread.
struct MaskWorkspace {
  detail::EpochMarks picked;    // tokens already in the mask being built
  // Dijkstra state of token v: state[v] == epoch: reached (dist[v] and tie[v] valid);
  // epoch + 1: settled; anything else: not seen in this run. The epoch advances by 2 per run.
  std::vector<std::uint32_t> state;
  std::uint32_t epoch = 0;
  detail::EpochMarks excluded;  // the union of a sample's targets
  std::vector<double> dist;     // [N] Dijkstra tentative distances
  std::vector<std::uint64_t> tie;  // [N] Dijkstra tie-break word (random key, node), drawn when first reached
  detail::Frontier frontier;
  std::vector<int> perm;        // [N] partial Fisher–Yates scratch
  std::vector<int> order;       // [G] group order scratch
  std::vector<std::uint64_t> bits;  // [(N + 63) / 64] zero between uses (detail::sort_tokens)

  void resize(int n) {
    picked.resize(n);
    if (static_cast<int>(state.size()) < n) state.resize(n, 0);
    excluded.resize(n);
    if (static_cast<int>(dist.size()) < n) dist.resize(n);
    if (static_cast<int>(tie.size()) < n) tie.resize(n);
    if (static_cast<int>(perm.size()) < n) perm.resize(n);
    if (static_cast<int>(bits.size()) < (n + 63) / 64) bits.resize((n + 63) / 64, 0);
    frontier.reserve(static_cast<std::size_t>(n) * 4);
  }

  // Starts a Dijkstra run: returns the run's "reached" stamp (settled is that + 1).
  std::uint32_t next_dijkstra_epoch() {
    epoch += 2;
    if (epoch < 2) {  // wrapped
      std::fill(state.begin(), state.end(), 0u);
      epoch = 2;
    }
    return epoch;
  }
};

}  // namespace tjepa
