#pragma once
// Grouped gather: packs each group's taxel windows into one token's input row, for sensors with
// too many taxels to give each its own token (DECO-50: 2×2 blocks, groups of 4 and 5). This is the
// one place the grouped-token layout is defined; the grouped Tokenizer (model/tokenizer.hpp) reads
// exactly these rows.
//
//   in    [B, N, τ, m]        a WindowBatch's x as it is: x[b, i, t, a]
//   index [G, n_max]          taxel ids of group g (e.g. Grouping::members), padded with -1 at the
//                             end of the row; n_g = the number of taxel ids in row g
//   out   [B, G, n_max·τ·m]   row g: out[b, g, (t·n_g + j)·m + a] = in[b, index[g, j], t, a] for
//                             j < n_g, then zeros up to n_max·τ·m
//
// Why this order: the reference's DecoHypertaxelTokenizer ("direct" mode) takes x [B, τ, G, 5]
// (m = 1, member slots padded to 5) and feeds x[:, :, g, :n].permute(0, 2, 1, 3).reshape(.., τ·n)
// to tokenizer.direct{n}: column frame·n + member, the first n·τ values of the row, and a
// Linear(n·τ → d) per group size. The reference has no m > 1; here the m values of one taxel at
// one frame stay adjacent (x read as [B, τ, G, n, m], permuted the same way), so m = 1 is the
// reference exactly and the tokenizer weight of a size-n map reads [d, τ, n, m] flattened.
// gather_groups_backward is the adjoint (a scatter-add), for when the input needs a gradient.
#include <algorithm>
#include <cstddef>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

// Throws unless index has groups·group_size entries, each -1 or a taxel id in [0, taxels), every
// row starts with a taxel and has its padding only at the end, and no taxel appears twice.
inline void check_group_index(std::span<const int> index, int groups, int group_size, int taxels) {
  require<ShapeError>(groups > 0 && group_size > 0, "gather_groups: index shape [", groups, ", ", group_size,
                      "], expected positive dimensions");
  require<ShapeError>(index.size() == static_cast<std::size_t>(groups) * group_size, "gather_groups: index has ",
                      index.size(), " entries, expected groups*group_size = ", groups, "*", group_size);
  std::vector<char> seen(static_cast<std::size_t>(taxels), 0);
  for (std::size_t k = 0; k < index.size(); ++k) {
    const std::size_t g = k / group_size, j = k % group_size;
    const int t = index[k];
    require<DataError>(t >= -1 && t < taxels, "gather_groups: index[", g, "][", j, "] = ", t,
                       ", expected -1 (padding) or a taxel id in [0, ", taxels, ")");
    if (t < 0) {
      require<DataError>(j > 0, "gather_groups: index[", g, "][0] = -1, expected a taxel (group ", g, " is empty)");
      continue;
    }
    require<DataError>(j == 0 || index[k - 1] >= 0, "gather_groups: index[", g, "][", j, "] = ", t,
                       " follows padding, expected the padding (-1) only at the end of the row");
    require<DataError>(!seen[t], "gather_groups: taxel ", t, " appears in more than one group slot (index[", g,
                       "][", j, "])");
    seen[t] = 1;
  }
}

namespace detail {
// n_g: the taxel ids at the front of one index row.
inline int group_members(const int* row, int group_size) {
  int n = 0;
  while (n < group_size && row[n] >= 0) ++n;
  return n;
}
}  // namespace detail

// out[b, g, (t·n_g + j)·m + a] = in[b, index[g, j], t, a]; columns from n_g·τ·m on are 0.
// In and Out may differ (float windows into a double model).
template <class In, class Out>
void gather_groups(const In* in, std::size_t batch, int taxels, int frames, int axes, const int* index, int groups,
                   int group_size, Out* out) {
  const std::size_t m = static_cast<std::size_t>(axes), L = static_cast<std::size_t>(frames) * m;
  const std::size_t W = static_cast<std::size_t>(group_size) * L;
  for (std::size_t b = 0; b < batch; ++b) {
    const In* xb = in + b * taxels * L;
    for (int g = 0; g < groups; ++g) {
      const int* row = index + static_cast<std::size_t>(g) * group_size;
      const int n = detail::group_members(row, group_size);
      Out* o = out + (b * groups + g) * W;
      for (int t = 0; t < frames; ++t)
        for (int j = 0; j < n; ++j, o += m) {
          const In* src = xb + static_cast<std::size_t>(row[j]) * L + t * m;
          for (std::size_t a = 0; a < m; ++a) o[a] = static_cast<Out>(src[a]);
        }
      std::fill(o, out + (b * groups + g + 1) * W, Out(0));
    }
  }
}

// The adjoint: d_in[b, index[g, j], t, a] += d_out[b, g, (t·n_g + j)·m + a]; padding is dropped.
template <class T>
void gather_groups_backward(T* d_in, const T* d_out, std::size_t batch, int taxels, int frames, int axes,
                            const int* index, int groups, int group_size) {
  const std::size_t m = static_cast<std::size_t>(axes), L = static_cast<std::size_t>(frames) * m;
  const std::size_t W = static_cast<std::size_t>(group_size) * L;
  for (std::size_t b = 0; b < batch; ++b) {
    T* db = d_in + b * taxels * L;
    for (int g = 0; g < groups; ++g) {
      const int* row = index + static_cast<std::size_t>(g) * group_size;
      const int n = detail::group_members(row, group_size);
      const T* o = d_out + (b * groups + g) * W;
      for (int t = 0; t < frames; ++t)
        for (int j = 0; j < n; ++j, o += m) {
          T* dst = db + static_cast<std::size_t>(row[j]) * L + t * m;
          for (std::size_t a = 0; a < m; ++a) dst[a] += o[a];
        }
    }
  }
}

}  // namespace tjepa
