#pragma once
// Tokenizer (paper eq. 1, Sec. III-B): a token's window of values → R^d by an affine map, then
// LayerNorm. Tokens are rows of x [B, G, W]:
//   per taxel: one map shared by all N taxels, W = m·τ.
//     PyTorch: patch_embed.proj.{weight [d, m, τ], bias [d]}, patch_embed.norm.{weight, bias}.
//     The reference's patch_embed.proj is a Conv1d with weight [d, m, τ], registered with that
//     shape so a strict load_state_dict accepts it: flattened, its column index is axis·τ + frame,
//     so rows must hold a taxel's window axis-major (data/window_source.hpp's windows_to_tokens) to load
//     it 1:1. `padding` p is that Conv1d's temporal zero padding (2 in the reference's checkpoints
//     without a `_temporal_patch_version` marker, 0 after): with kernel = stride = τ and 2p < τ it
//     yields one chunk that reads p zeros and then frames 0..τ−p−1, so row value axis·τ + f is
//     x[axis·τ + f − p] (0 for f < p) and the last p frames are never read.
//   grouped (DECO-50): one map and one LayerNorm per group size n (4 and 5), W = n_max·k with
//     k = τ·m values per taxel; a group of size n uses the first n·k values of its row (the rest
//     is padding). PyTorch (the reference's DecoHypertaxelTokenizer, mode "direct"):
//     tokenizer.direct{n}.0.{weight [d, n·k], bias} (Linear), tokenizer.direct{n}.1.* (LayerNorm);
//     its column index is frame·n + member (m = 1), and (frame·n + member)·m + axis for m > 1:
//     the rows gather_groups (data/grouped_gather.hpp) builds from a window batch [B, N, τ, m].
#include <algorithm>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/layers.hpp"
#include "tjepa/model/workspace.hpp"

namespace tjepa {

template <class T>
struct TokenizerCache {
  int B = 0;
  // Per map: inputs [B·G_n, n·k], pre-norm outputs [B·G_n, d], norm statistics [B·G_n].
  std::vector<AlignedVector<T>> x, pre, mean, rstd;
};

struct Tokenizer {
  struct Map {
    LinearParams proj;
    NormParams norm;
    std::vector<int> tokens;  // token indices this map embeds; empty = all tokens (per taxel)
  };
  std::vector<Map> maps;
  int num_tokens = 0, width = 0, dim = 0;
  int axes = 0, frames = 0, padding = 0;  // per taxel: m, τ and the temporal padding p

  // Per-taxel tokenizer for N taxels with m axes × τ frames each (rows axis-major, m·τ values).
  template <class T>
  static Tokenizer per_taxel(ParamSet<T>& ps, int N, int axes, int frames, int dim, double eps = kernels::layer_norm_eps,
                             const std::string& prefix = "patch_embed.", int padding = 0) {
    require<ConfigError>(N > 0 && axes > 0 && frames > 0 && dim > 0, "Tokenizer::per_taxel: N = ", N,
                         ", axes = ", axes, ", frames = ", frames, ", dim = ", dim, ", expected all > 0");
    require<ConfigError>(padding >= 0 && 2 * padding < frames, "Tokenizer::per_taxel: padding = ", padding,
                         ", expected 0 <= 2·padding < frames = ", frames, " (one time chunk per window)");
    Tokenizer t;
    t.num_tokens = N;
    t.width = axes * frames;
    t.dim = dim;
    t.axes = axes;
    t.frames = frames;
    t.padding = padding;
    t.maps.push_back({LinearParams::add(ps, prefix + "proj", t.width, dim, true, {dim, axes, frames}),
                      NormParams::add(ps, prefix + "norm", dim, eps), {}});
    return t;
  }

  // Grouped tokenizer: group_size[g] taxels in token g, k values per taxel.
  template <class T>
  static Tokenizer grouped(ParamSet<T>& ps, const std::vector<int>& group_size, int k, int dim,
                           double eps = kernels::layer_norm_eps, const std::string& prefix = "tokenizer.") {
    require<ConfigError>(!group_size.empty() && k > 0 && dim > 0, "Tokenizer::grouped: ", group_size.size(),
                         " groups, k = ", k, ", dim = ", dim, ", expected all > 0");
    Tokenizer t;
    t.num_tokens = static_cast<int>(group_size.size());
    t.dim = dim;
    std::vector<int> sizes;
    for (std::size_t g = 0; g < group_size.size(); ++g) {
      require<ConfigError>(group_size[g] > 0, "Tokenizer::grouped: group_size[", g, "] = ", group_size[g],
                           ", expected > 0");
      if (std::find(sizes.begin(), sizes.end(), group_size[g]) == sizes.end()) sizes.push_back(group_size[g]);
    }
    std::sort(sizes.begin(), sizes.end());
    t.width = sizes.back() * k;
    for (int n : sizes) {
      Map m{LinearParams::add(ps, prefix + "direct" + std::to_string(n) + ".0", n * k, dim, true),
            NormParams::add(ps, prefix + "direct" + std::to_string(n) + ".1", dim, eps), {}};
      for (std::size_t g = 0; g < group_size.size(); ++g)
        if (group_size[g] == n) m.tokens.push_back(static_cast<int>(g));
      t.maps.push_back(std::move(m));
    }
    return t;
  }

  // x [B, G, width] → out [B, G, dim]: inference.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int B, T* out, Workspace<T>& ws) const {
    run(ps, x, B, out, nullptr, ws);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, int B, T* out, std::type_identity_t<TokenizerCache<T>>& cache,
               Workspace<T>& ws) const {
    run(ps, x, B, out, &cache, ws);
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const T* x, int B, T* out, std::type_identity_t<TokenizerCache<T>>* cache, Workspace<T>& ws) const {
    check_params(ps, maps.back().norm.bias, "Tokenizer::forward");
    require<ShapeError>(B > 0, "Tokenizer::forward: B = ", B, ", expected > 0");
    if (cache) {
      cache->B = B;
      for (auto* v : {&cache->x, &cache->pre, &cache->mean, &cache->rstd}) v->resize(maps.size());
    }
    for (std::size_t i = 0; i < maps.size(); ++i) {
      const Map& m = maps[i];
      const int G = m.tokens.empty() ? num_tokens : static_cast<int>(m.tokens.size());
      const int M = B * G, in = m.proj.in;
      const T* xm = x;
      if (!m.tokens.empty() || cache || padding > 0) {
        T* buf = detail::grow(cache ? cache->x[i] : ws.rows, std::size_t(M) * in);
        gather_columns(buf, x, B, m.tokens, in);
        xm = buf;
      }
      T* pre = detail::grow(cache ? cache->pre[i] : ws.rows2, std::size_t(M) * dim);
      m.proj.forward(ps, xm, pre, M, ws.weights());
      T* mean = cache ? detail::grow(cache->mean[i], std::size_t(M)) : nullptr;
      T* rstd = cache ? detail::grow(cache->rstd[i], std::size_t(M)) : nullptr;
      if (m.tokens.empty()) {
        m.norm.forward(ps, pre, out, mean, rstd, M);
        continue;
      }
      T* y = detail::grow(ws.branch, std::size_t(M) * dim);
      m.norm.forward(ps, pre, y, mean, rstd, M);
      for (int b = 0; b < B; ++b)
        for (int j = 0; j < G; ++j) {
          const T* src = y + (std::size_t(b) * G + j) * dim;
          std::copy(src, src + dim, out + (std::size_t(b) * num_tokens + m.tokens[std::size_t(j)]) * dim);
        }
    }
  }

 public:
  // dout [B, G, dim] → parameter gradients only.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, const TokenizerCache<T>& c, Workspace<T>& ws) const {
    backward(ps, dout, static_cast<T*>(nullptr), c, ws);
  }
  // dout [B, G, dim] → parameter gradients and dx [B, G, width] += (may be nullptr; padding
  // columns get nothing).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, std::type_identity_t<T>* dx, const TokenizerCache<T>& c, Workspace<T>& ws) const {
    check_params(ps, maps.back().norm.bias, "Tokenizer::backward");
    require<ConfigError>(c.B > 0, "Tokenizer::backward: the cache holds no forward pass");
    const int B = c.B;
    for (std::size_t i = 0; i < maps.size(); ++i) {
      const Map& m = maps[i];
      const int G = m.tokens.empty() ? num_tokens : static_cast<int>(m.tokens.size());
      const int M = B * G, in = m.proj.in;
      const T* dy = dout;
      if (!m.tokens.empty()) {
        T* buf = detail::grow(ws.drows, std::size_t(M) * dim);
        for (int b = 0; b < B; ++b)
          for (int j = 0; j < G; ++j) {
            const T* src = dout + (std::size_t(b) * num_tokens + m.tokens[std::size_t(j)]) * dim;
            std::copy(src, src + dim, buf + (std::size_t(b) * G + j) * dim);
          }
        dy = buf;
      }
      T* dpre = detail::grow(ws.dln, std::size_t(M) * dim);
      std::fill(dpre, dpre + std::size_t(M) * dim, T(0));
      // pre = x · Wᵀ + b, out = norm(pre): the norm's input is pre (kept in the cache).
      m.norm.backward(ps, dy, c.pre[i].data(), c.mean[i].data(), c.rstd[i].data(), dpre, M);
      T* dxm = nullptr;
      if (dx) {
        dxm = detail::grow(ws.dbranch, std::size_t(M) * in);
        std::fill(dxm, dxm + std::size_t(M) * in, T(0));
      }
      m.proj.backward(ps, dpre, c.x[i].data(), dxm, M);
      if (!dx) continue;
      for (int b = 0; b < B; ++b)
        for (int j = 0; j < G; ++j) {
          const int g = m.tokens.empty() ? j : m.tokens[std::size_t(j)];
          const T* src = dxm + (std::size_t(b) * G + j) * in;
          T* dst = dx + (std::size_t(b) * num_tokens + g) * width;
          if (padding == 0) {
            for (int q = 0; q < in; ++q) dst[q] += src[q];
            continue;
          }
          for (int a = 0; a < axes; ++a)
            for (int f = padding; f < frames; ++f) dst[a * frames + f - padding] += src[a * frames + f];
        }
    }
  }

 private:
  // buf[b·G + j, :in] = x[b, tokens[j], :in] (tokens empty: all tokens), each axis's frames
  // shifted by the temporal padding.
  template <class T>
  void gather_columns(T* buf, const T* x, int B, const std::vector<int>& tokens, int in) const {
    const int G = tokens.empty() ? num_tokens : static_cast<int>(tokens.size());
    for (int b = 0; b < B; ++b)
      for (int j = 0; j < G; ++j) {
        const int g = tokens.empty() ? j : tokens[std::size_t(j)];
        const T* src = x + (std::size_t(b) * num_tokens + g) * width;
        T* dst = buf + (std::size_t(b) * G + j) * in;
        if (padding == 0) {
          std::copy(src, src + in, dst);
          continue;
        }
        for (int a = 0; a < axes; ++a)
          for (int f = 0; f < frames; ++f) dst[a * frames + f] = f < padding ? T(0) : src[a * frames + f - padding];
      }
  }
};

}  // namespace tjepa
