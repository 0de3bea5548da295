#pragma once
// Encoder (paper, Sec. III-B; ViT-Tiny, Sec. IV-D): position table, pre-norm blocks, final
// LayerNorm.
//
//   x[b, k] = tokens[b, c[b, k]] + pos_embed[c[b, k]]      c = context indices [B, K] (or all N)
//             (+ taxeltype_embed[type[c[b, k]]] when the config gives token types)
//   x[b, k] = mask_token                                   where the input marks it masked (optional)
//   x[b] ← [register_tokens; x[b]]                         R rows before the tokens (optional)
//   x ← blocks(x);  out = norm(x)                           out [B, R + K, d]
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
//   register_tokens [1, R, d] and mask_token [1, 1, d] (DINOv2's names), when configured.
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
  // R learned rows (register_tokens [1, R, d]) put before every sample's tokens, without a
  // position: the output is then [B, R + K, d]. DINO reads row 0 as its class token.
  int register_tokens = 0;
  // A learned row (mask_token [1, 1, d]) that replaces the tokens EncoderInput::masked marks,
  // after their position was added (DINO's masked student view).
  bool mask_token = false;
};

// What the encoder reads: tokens [batch, N, d] and the context's token indices [batch, K]
// (empty: all N tokens in order).
template <class T>
struct EncoderInput {
  const T* tokens = nullptr;
  int batch = 0;
  std::span<const int> context = {};
  // [batch, K], nonzero: the token is replaced by the mask token (config.mask_token); empty: none.
  std::span<const std::uint8_t> masked = {};
};

struct EncoderOptions {
  DropPath drop_path = {};                    // the reference trains with rate 0.3
  const std::uint8_t* key_valid = nullptr;    // [B, R + K] padding mask (nonzero = real token) or nullptr
  // With register tokens: out holds them (true, [B, R + K, d]) or the K token rows alone (false,
  // [B, K, d]: what a probe of the taxels reads).
  bool register_rows = true;
};

template <class T>
struct EncoderCache {
  int B = 0, K = 0;
  std::vector<int> context;  // [B, K] copy; empty = all tokens
  std::vector<std::uint8_t> masked;  // [B, K] copy; empty = none
  bool register_rows = true;         // out held the register rows (EncoderOptions::register_rows)
  BlockStackCache<T> stack;
  AlignedVector<T> mean, rstd;  // [B·(R + K)] final norm statistics
};

struct Encoder {
  EncoderConfig config;
  PositionTable pos;
  BlockStack stack;
  NormParams norm;
  ParamId type_embed;  // valid only with token types
  ParamId registers;   // valid only with register tokens
  ParamId mask;        // valid only with a mask token

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
    require<ConfigError>(c.register_tokens >= 0, "Encoder: register_tokens ", c.register_tokens, ", expected >= 0");
    if (c.register_tokens > 0)
      registers = ps.add(prefix + "register_tokens", {1, c.register_tokens, c.dim}, ParamInit::trunc_normal);
    if (c.mask_token) mask = ps.add(prefix + "mask_token", {1, 1, c.dim}, ParamInit::trunc_normal);
    BlockConfig bc{c.dim, c.heads, c.mlp_ratio, c.bias, c.bias, c.bias, c.eps};
    stack = BlockStack::add(ps, prefix + "blocks.", c.depth, bc);
    norm = NormParams::add(ps, prefix + "norm", c.dim, c.eps);
  }
  int dim() const { return config.dim; }
  int num_tokens() const { return config.num_tokens; }
  // The position table (the predictor reads the target encoder's rows by default).
  ParamId pos_embed() const { return pos.table; }

  // in.tokens [B, N, d] → out [B, R + K, d] (R = config.register_tokens): inference (no allocation once the shape was seen).
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

  // dout (as out: [B, R + K, d], or [B, K, d] without the register rows) → parameter gradients
  // (added to ps) only.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, const EncoderCache<T>& cache, Workspace<T>& ws) const {
    backward(ps, dout, static_cast<T*>(nullptr), cache, ws);
  }
  // The same, and dtokens [B, N, d] += (may be nullptr).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, std::type_identity_t<T>* dtokens, const EncoderCache<T>& cache, Workspace<T>& ws) const {
    check_params(ps, norm.bias, "Encoder::backward");
    require<ConfigError>(cache.B > 0, "Encoder::backward: the cache holds no forward pass");
    const int N = config.num_tokens, d = config.dim, B = cache.B, K = cache.K, R = config.register_tokens;
    const std::size_t M = std::size_t(B) * K, ML = std::size_t(B) * (R + K);
    if (!cache.register_rows) {  // dout [B, K, d]: zeros at the register rows it did not hold
      T* full = detail::grow(ws.registers, ML * d);
      for (int b = 0; b < B; ++b) {
        T* fb = full + std::size_t(b) * (R + K) * d;
        std::fill(fb, fb + std::size_t(R) * d, T(0));
        std::copy(dout + std::size_t(b) * K * d, dout + std::size_t(b + 1) * K * d, fb + std::size_t(R) * d);
      }
      dout = full;
    }
    T* g = detail::grow(ws.dx, ML * d);
    detail::parallel_fill(g, g + ML * d, T(0));
    norm.backward(ps, dout, cache.stack.xs.data() + std::size_t(stack.depth()) * ML * d, cache.mean.data(),
                  cache.rstd.data(), g, int(ML));
    stack.backward(ps, g, cache.stack, ws);
    if (R > 0) {  // the register rows' gradient, then the token rows alone, [B, K, d]
      T* dreg = ps.grad(registers);
      T* gk = detail::grow(ws.drows, M * d);
      for (int b = 0; b < B; ++b) {
        const T* gb = g + std::size_t(b) * (R + K) * d;
        detail::simd_add(gb, dreg, std::size_t(R) * d);
        std::copy(gb + std::size_t(R) * d, gb + std::size_t(R + K) * d, gk + std::size_t(b) * K * d);
      }
      g = gk;
    }
    if (!cache.masked.empty()) {  // masked rows: the mask token's gradient; nothing reaches their token
      T* dm = ps.grad(mask);
      for (std::size_t i = 0; i < M; ++i)
        if (cache.masked[i]) {
          T* gi = g + i * d;
          for (int c = 0; c < d; ++c) dm[c] += gi[c], gi[c] = T(0);
        }
    }
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
    require<ShapeError>(in.masked.empty() || (config.mask_token && in.masked.size() == std::size_t(B) * K),
                        "Encoder::forward: ", in.masked.size(), " masked flags, expected none",
                        config.mask_token ? "" : " (the encoder has no mask token)",
                        config.mask_token ? " or batch·K" : "");
    const T* tokens = in.tokens;
    const int R = config.register_tokens;
    const std::size_t M = std::size_t(B) * K, ML = std::size_t(B) * (R + K);
    T* x = detail::grow(R > 0 ? ws.rows : ws.x, M * d);  // the token rows; with registers assembled below
    if (context)
      kernels::gather_rows(x, tokens, std::size_t(N) * d, context, B, K, d);
    else
      detail::parallel_copy(tokens, tokens + M * d, x);
    pos.forward(ps, x, context, B, K);
    if (config.token_types > 0)
      kernels::gather_add_rows(x, ps.value(type_embed), 0, type_rows(context, B, K, ws), B, K, d);
    if (!in.masked.empty()) {
      const T* u = ps.value(mask);
      for (std::size_t i = 0; i < M; ++i)
        if (in.masked[i]) std::copy(u, u + d, x + i * d);
    }
    if (R > 0) {
      T* xl = detail::grow(ws.x, ML * d);
      const T* reg = ps.value(registers);
      for (int b = 0; b < B; ++b) {
        T* xb = xl + std::size_t(b) * (R + K) * d;
        std::copy(reg, reg + std::size_t(R) * d, xb);
        std::copy(x + std::size_t(b) * K * d, x + std::size_t(b + 1) * K * d, xb + std::size_t(R) * d);
      }
      x = xl;
    }
    ws.mark("embed");
    if (cache) {
      cache->B = B;
      cache->K = K;
      if (context)
        cache->context.assign(context, context + M);
      else
        cache->context.clear();
      cache->masked.assign(in.masked.begin(), in.masked.end());
    }
    const StackInput<T> stack_rows{x, B, R + K, opt.key_valid};
    if (cache)
      stack.forward(ps, stack_rows, x, opt.drop_path, cache->stack, ws);
    else
      stack.forward(ps, stack_rows, x, opt.drop_path, ws);
    T* mean = cache ? detail::grow(cache->mean, ML) : nullptr;
    T* rstd = cache ? detail::grow(cache->rstd, ML) : nullptr;
    const bool all_rows = R == 0 || opt.register_rows;
    if (cache) cache->register_rows = all_rows;
    T* normed = all_rows ? out : detail::grow(ws.registers, ML * d);
    norm.forward(ps, x, normed, mean, rstd, int(ML));
    if (!all_rows)
      for (int b = 0; b < B; ++b)
        std::copy(normed + (std::size_t(b) * (R + K) + R) * d, normed + std::size_t(b + 1) * (R + K) * d,
                  out + std::size_t(b) * K * d);
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
