#pragma once
// Encoder (paper, Sec. III-B; ViT-Tiny, Sec. IV-D): position table, pre-norm blocks, final
// LayerNorm.
//
//   x[b, k] = tokens[b, c[b, k]] + pos_embed[c[b, k]]      c = context indices [B, K] (or all N)
//             (+ taxeltype_embed[type[c[b, k]]] when the config gives token types)
//   x ← blocks(x);  out = norm(x)                           out [B, K, d]
//
// The same Encoder object runs the context encoder (on a subset of tokens, with gradients) and
// the EMA target encoder (all tokens, no cache) on two ParamSets of the same layout.
//
// PyTorch names (the reference's SignalTransformer, prefix "" by default):
//   pos_embed [1, N, d]; blocks.{i}.norm1.{weight,bias} [d]; blocks.{i}.attn.qkv.{weight [3d, d],
//   bias [3d]}; blocks.{i}.attn.proj.{weight [d, d], bias}; blocks.{i}.norm2.*;
//   blocks.{i}.mlp.fc1.{weight [4d, d], bias}; blocks.{i}.mlp.fc2.{weight [d, 4d], bias}; norm.*;
//   taxeltype_embed [types, d] (the reference's XelaTransformer: rows 4x4, 4x6, curved pad), with
//   token types only. The predictor reads pos_embed alone, without the type rows, as there.
// The tokenizer (tokenizer.hpp) registers its own names (patch_embed.* / tokenizer.*).
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/block.hpp"
#include "tjepa/model/position_table.hpp"

namespace tjepa {

struct EncoderConfig {
  int num_tokens = 368;  // N: rows of the position table
  int dim = 192;
  int depth = 12;
  int heads = 3;
  double mlp_ratio = 4.0;
  bool bias = true;  // qkv / proj / fc1 / fc2 biases
  double eps = kernels::layer_norm_eps;
  // A learned row per token type added to every token (the reference's taxel-type embedding):
  // token_type [N] in [0, token_types); empty (and token_types 0): none.
  std::vector<int> token_type = {};
  int token_types = 0;
};

// What the encoder reads: tokens [batch, N, d] and the context's token indices [batch, K]
// (empty: all N tokens in order).
template <class T>
struct EncoderInput {
  const T* tokens = nullptr;
  int batch = 0;
  std::span<const int> context = {};
};

struct EncoderOptions {
  DropPath drop_path;                         // the reference trains with rate 0.3
  const std::uint8_t* key_valid = nullptr;    // [B, K] padding mask (nonzero = real token) or nullptr
};

template <class T>
struct EncoderCache {
  int B = 0, K = 0;
  std::vector<int> context;  // [B, K] copy; empty = all tokens
  BlockStackCache<T> stack;
  AlignedVector<T> mean, rstd;  // [B·K] final norm statistics
};

struct Encoder {
  EncoderConfig config;
  PositionTable pos;
  BlockStack stack;
  NormParams norm;
  ParamId type_embed;  // valid only with token types

  Encoder() = default;
  template <class T>
  Encoder(ParamSet<T>& ps, const EncoderConfig& c, const std::string& prefix = "") : config(c) {
    require<ConfigError>(c.num_tokens > 0, "Encoder: num_tokens ", c.num_tokens, ", expected > 0");
    require<ConfigError>(c.dim > 0 && c.heads > 0 && c.dim % c.heads == 0, "Encoder: dim ", c.dim,
                         " and heads ", c.heads, ", expected dim a positive multiple of heads");
    require<ConfigError>(c.token_types >= 0 && (c.token_type.empty() == (c.token_types == 0)) &&
                             (c.token_type.empty() || static_cast<int>(c.token_type.size()) == c.num_tokens),
                         "Encoder: ", c.token_type.size(), " token types over ", c.token_types,
                         " rows, expected none, or num_tokens = ", c.num_tokens, " over token_types > 0 rows");
    for (std::size_t i = 0; i < c.token_type.size(); ++i)
      require<ConfigError>(c.token_type[i] >= 0 && c.token_type[i] < c.token_types, "Encoder: token_type[", i,
                           "] = ", c.token_type[i], ", expected in [0, ", c.token_types, ")");
    pos = PositionTable::add(ps, prefix + "pos_embed", c.num_tokens, c.dim);
    if (c.token_types > 0) type_embed = ps.add(prefix + "taxeltype_embed", {c.token_types, c.dim}, ParamInit::trunc_normal);
    BlockConfig bc{c.dim, c.heads, c.mlp_ratio, c.bias, c.bias, c.bias, c.eps};
    stack = BlockStack::add(ps, prefix + "blocks.", c.depth, bc);
    norm = NormParams::add(ps, prefix + "norm", c.dim, c.eps);
  }
  int dim() const { return config.dim; }
  int num_tokens() const { return config.num_tokens; }
  // The position table (the predictor reads the target encoder's rows by default).
  ParamId pos_embed() const { return pos.table; }

  // in.tokens [B, N, d] → out [B, K, d]: inference (no allocation once the shape was seen).
  template <class T>
  void forward(const ParamSet<T>& ps, const EncoderInput<std::type_identity_t<T>>& in, T* out, Workspace<T>& ws,
               const EncoderOptions& opt = {}) const {
    run(ps, in, out, nullptr, ws, opt);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const EncoderInput<std::type_identity_t<T>>& in, T* out,
               std::type_identity_t<EncoderCache<T>>& cache, Workspace<T>& ws, const EncoderOptions& opt = {}) const {
    run(ps, in, out, &cache, ws, opt);
  }

  // dout [B, K, d] → parameter gradients (added to ps) and dtokens [B, N, d] += (may be nullptr).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, std::type_identity_t<T>* dtokens, const EncoderCache<T>& cache, Workspace<T>& ws) const {
    check_params(ps, norm.bias, "Encoder::backward");
    require<ConfigError>(cache.B > 0, "Encoder::backward: the cache holds no forward pass");
    const int N = config.num_tokens, d = config.dim, B = cache.B, K = cache.K;
    const std::size_t M = std::size_t(B) * K;
    T* g = detail::grow(ws.dx, M * d);
    detail::parallel_fill(g, g + M * d, T(0));
    norm.backward(ps, dout, cache.stack.xs.data() + std::size_t(stack.depth()) * M * d, cache.mean.data(),
                  cache.rstd.data(), g, int(M));
    stack.backward(ps, g, cache.stack, ws);
    const int* idx = cache.context.empty() ? nullptr : cache.context.data();
    pos.backward(ps, g, idx, B, K);
    if (config.token_types > 0) kernels::scatter_add_rows(ps.grad(type_embed), 0, g, type_rows(idx, B, K, ws), B, K, d);
    if (!dtokens) return;
    if (idx)
      kernels::scatter_add_rows(dtokens, std::size_t(N) * d, g, idx, B, K, d);
    else
      for (std::size_t i = 0; i < M * d; ++i) dtokens[i] += g[i];
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const EncoderInput<T>& in, T* out, std::type_identity_t<EncoderCache<T>>* cache, Workspace<T>& ws,
           const EncoderOptions& opt) const {
    const int N = config.num_tokens, d = config.dim, B = in.batch;
    check_params(ps, norm.bias, "Encoder::forward");
    require<ShapeError>(in.tokens && out, "Encoder::forward: null tokens or out");
    require<ShapeError>(B > 0, "Encoder::forward: batch = ", B, ", expected > 0");
    const int* context = in.context.empty() ? nullptr : in.context.data();
    require<ShapeError>(in.context.size() % std::size_t(B) == 0, "Encoder::forward: ", in.context.size(),
                        " context indices for batch ", B, ", expected a multiple of it");
    const int K = context ? static_cast<int>(in.context.size() / std::size_t(B)) : N;
    require<ShapeError>(K <= N, "Encoder::forward: K = ", K, " context tokens per sample, expected 1..", N);
    if (context) check_indices(context, std::size_t(B) * K, N, "Encoder::forward", "context");
    const T* tokens = in.tokens;
    const std::size_t M = std::size_t(B) * K;
    T* x = detail::grow(ws.x, M * d);
    if (context)
      kernels::gather_rows(x, tokens, std::size_t(N) * d, context, B, K, d);
    else
      detail::parallel_copy(tokens, tokens + M * d, x);
    pos.forward(ps, x, context, B, K);
    if (config.token_types > 0)
      kernels::gather_add_rows(x, ps.value(type_embed), 0, type_rows(context, B, K, ws), B, K, d);
    ws.mark("embed");
    if (cache) {
      cache->B = B;
      cache->K = K;
      if (context)
        cache->context.assign(context, context + M);
      else
        cache->context.clear();
    }
    stack.forward(ps, x, x, B, K, opt.key_valid, opt.drop_path, cache ? &cache->stack : nullptr, ws);
    T* mean = cache ? detail::grow(cache->mean, M) : nullptr;
    T* rstd = cache ? detail::grow(cache->rstd, M) : nullptr;
    norm.forward(ps, x, out, mean, rstd, int(M));
    ws.mark("norm");
  }

  // The type row of each of the B·K tokens (context indices, or all N in order), in ws.index.
  template <class T>
  const int* type_rows(const int* context, int B, int K, Workspace<T>& ws) const {
    ws.index.resize(std::size_t(B) * K);
    for (std::size_t i = 0; i < ws.index.size(); ++i)
      ws.index[i] = config.token_type[std::size_t(context ? context[i] : static_cast<int>(i % std::size_t(K)))];
    return ws.index.data();
  }
};

}  // namespace tjepa
