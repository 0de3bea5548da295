#pragma once
// Grouped gather: packs each group's taxel windows into one token's input, for sensors with too many
// taxels to give each its own token (DECO-50: 2×2 blocks, groups of 4 and 5).
//
//   in    [B, N, L]           L = τ·m values per taxel (a batch [B, N, τ, m] as it is)
//   index [G, n_g]            taxel ids of group g, padded with -1 to the largest group size n_g
//   out   [B, G, n_g·L]       group g's taxels in index order; a padding slot holds zeros
//
// The index is a plain int array so any grouping (e.g. the graph's Grouping) can feed it.
// gather_groups_backward is the adjoint (a scatter-add), for when the input needs a gradient.
#include <algorithm>
#include <cstddef>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

// Throws unless index has groups·group_size entries, each -1 or a taxel id in [0, taxels), and no
// taxel appears twice.
inline void check_group_index(std::span<const int> index, int groups, int group_size, int taxels) {
  require<ShapeError>(groups > 0 && group_size > 0, "gather_groups: index shape [", groups, ", ", group_size,
                      "], expected positive dimensions");
  require<ShapeError>(index.size() == static_cast<std::size_t>(groups) * group_size, "gather_groups: index has ",
                      index.size(), " entries, expected groups*group_size = ", groups, "*", group_size);
  std::vector<char> seen(static_cast<std::size_t>(taxels), 0);
  for (std::size_t k = 0; k < index.size(); ++k) {
    const int t = index[k];
    require<DataError>(t >= -1 && t < taxels, "gather_groups: index[", k / group_size, "][", k % group_size, "] = ", t,
                       ", expected -1 (padding) or a taxel id in [0, ", taxels, ")");
    if (t < 0) continue;
    require<DataError>(!seen[t], "gather_groups: taxel ", t, " appears in more than one group slot (index[",
                       k / group_size, "][", k % group_size, "])");
    seen[t] = 1;
  }
}

// out[b, g, j·L + l] = in[b, index[g, j], l], or 0 where index[g, j] = -1.
template <class T>
void gather_groups(const T* in, std::size_t batch, int taxels, int per_taxel, const int* index, int groups,
                   int group_size, T* out) {
  const std::size_t L = static_cast<std::size_t>(per_taxel);
  for (std::size_t b = 0; b < batch; ++b) {
    const T* xb = in + b * taxels * L;
    T* ob = out + b * static_cast<std::size_t>(groups) * group_size * L;
    for (int s = 0; s < groups * group_size; ++s, ob += L) {
      const int t = index[s];
      if (t < 0)
        std::fill_n(ob, L, T(0));
      else
        std::copy_n(xb + static_cast<std::size_t>(t) * L, L, ob);
    }
  }
}

// The adjoint: d_in[b, index[g, j], l] += d_out[b, g, j·L + l]; padding slots are dropped.
template <class T>
void gather_groups_backward(T* d_in, const T* d_out, std::size_t batch, int taxels, int per_taxel, const int* index,
                            int groups, int group_size) {
  const std::size_t L = static_cast<std::size_t>(per_taxel);
  for (std::size_t b = 0; b < batch; ++b) {
    T* db = d_in + b * taxels * L;
    const T* gb = d_out + b * static_cast<std::size_t>(groups) * group_size * L;
    for (int s = 0; s < groups * group_size; ++s, gb += L) {
      const int t = index[s];
      if (t < 0) continue;
      T* d = db + static_cast<std::size_t>(t) * L;
      for (std::size_t l = 0; l < L; ++l) d[l] += gb[l];
    }
  }
}

}  // namespace tjepa
