#pragma once
// Pre-norm transformer Block (timm / DINOv2 / the reference's NestedTensorBlock) and a stack of
// them, forward and backward side by side.
//
//   x_mid = x     + dp₁ · attn(norm1(x))        PyTorch: blocks.{i}.norm1, blocks.{i}.attn.{qkv,proj}
//   x_out = x_mid + dp₂ · mlp(norm2(x_mid))     PyTorch: blocks.{i}.norm2, blocks.{i}.mlp.{fc1,fc2}
// dp = drop-path scale per sample (1 when the rate is 0). Shapes: x [B, L, d], M = B·L rows.
#include <algorithm>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/attention.hpp"
#include "tjepa/model/kernels/drop_path.hpp"
#include "tjepa/model/mlp.hpp"

namespace tjepa {

struct BlockConfig {
  int dim = 192;
  int heads = 3;
  double mlp_ratio = 4.0;
  bool qkv_bias = true, proj_bias = true, ffn_bias = true;
  double eps = layer_norm_eps;
  int hidden() const { return static_cast<int>(dim * mlp_ratio); }
};

// Stochastic depth of one forward: rate 0 (the default) costs nothing.
struct DropPath {
  double rate = 0.0;
  std::uint64_t seed = 0;  // sample b draws from Rng(seed, b): pass a new seed every step
};

struct Block {
  NormParams norm1;
  SelfAttention attn;
  NormParams norm2;
  Mlp mlp;

  template <class T>
  static Block add(ParamSet<T>& ps, const std::string& name, const BlockConfig& c) {
    Block b;
    b.norm1 = NormParams::add(ps, name + ".norm1", c.dim, c.eps);
    b.attn = SelfAttention::add(ps, name + ".attn", c.dim, c.heads, c.qkv_bias, c.proj_bias);
    b.norm2 = NormParams::add(ps, name + ".norm2", c.dim, c.eps);
    b.mlp = Mlp::add(ps, name + ".mlp", c.dim, c.hidden(), c.ffn_bias);
    return b;
  }
};

// Activations one block keeps for backward (training), or scratch (inference: mean/rstd/lse
// nullptr, x_mid = x_out = x_in, h_pre doubles as the activation).
template <class T>
struct BlockBuffers {
  T *ln1, *mean1, *rstd1, *qkv, *att, *lse, *x_mid, *ln2, *mean2, *rstd2, *h_pre, *h;
  const T *scale1, *scale2;  // [B] drop-path scales, nullptr = keep all
};

// Activations of a BlockStack's forward that its backward needs.
template <class T>
struct BlockStackCache {
  int B = 0, L = 0;
  AlignedVector<T> xs;                          // [depth+1, M, d] residual stream, block inputs + output
  AlignedVector<T> ln1, att, x_mid, ln2;        // [depth, M, d]
  AlignedVector<T> qkv;                         // [depth, M, 3d]
  AlignedVector<T> h_pre;                       // [depth, M, hidden]
  AlignedVector<T> mean1, rstd1, mean2, rstd2;  // [depth, M]
  AlignedVector<T> lse;                         // [depth, B, H, L]
  AlignedVector<T> scales;                      // [depth, 2, B], empty without drop-path
  std::vector<std::uint8_t> key_valid;          // [B, L] copy, empty = every key valid
};

struct BlockStack {
  std::vector<Block> blocks;
  BlockConfig config;

  template <class T>
  static BlockStack add(ParamSet<T>& ps, const std::string& prefix, int depth, const BlockConfig& c) {
    require<ConfigError>(depth >= 0, prefix, ": depth ", depth, ", expected >= 0");
    BlockStack s;
    s.config = c;
    for (int i = 0; i < depth; ++i) s.blocks.push_back(Block::add(ps, prefix + std::to_string(i), c));
    return s;
  }
  int depth() const { return static_cast<int>(blocks.size()); }

  // x_in [B, L, d] → x_out [B, L, d] (may alias x_in). cache == nullptr: inference, nothing kept.
  // key_valid [B, L] (nonzero = attend) or nullptr.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x_in, T* x_out, int B, int L, const std::uint8_t* key_valid,
               const DropPath& dp, std::type_identity_t<BlockStackCache<T>>* cache, Workspace<T>& ws) const {
    const int d = config.dim, hid = config.hidden(), H = config.heads, D = depth();
    const std::size_t M = std::size_t(B) * L, Md = M * d;
    const bool drop = dp.rate > 0.0 && D > 0;
    T* scales = nullptr;
    if (drop) {
      scales = detail::grow(cache ? cache->scales : ws.scales, std::size_t(D) * 2 * B);
      drop_path_sample(scales, 2 * D, B, dp.rate, dp.seed);
    } else if (cache) {
      cache->scales.clear();
    }
    T* branch = drop ? detail::grow(ws.branch, Md) : nullptr;
    if (!cache) {
      if (x_out != x_in) std::copy(x_in, x_in + Md, x_out);
      BlockBuffers<T> buf{detail::grow(ws.ln, Md), nullptr, nullptr, detail::grow(ws.qkv, 3 * Md),
                          detail::grow(ws.att, Md), nullptr, x_out, detail::grow(ws.ln, Md), nullptr, nullptr,
                          detail::grow(ws.hidden, M * hid), nullptr, nullptr, nullptr};
      buf.h = buf.h_pre;
      for (int i = 0; i < D; ++i) {
        if (drop) {
          buf.scale1 = scales + std::size_t(2 * i) * B;
          buf.scale2 = scales + std::size_t(2 * i + 1) * B;
        }
        block_forward(ps, blocks[std::size_t(i)], x_out, x_out, B, L, key_valid, buf, branch, ws);
      }
      return;
    }
    BlockStackCache<T>& c = *cache;
    c.B = B;
    c.L = L;
    if (key_valid)
      c.key_valid.assign(key_valid, key_valid + M);
    else
      c.key_valid.clear();
    T* xs = detail::grow(c.xs, (D + 1) * Md);
    std::copy(x_in, x_in + Md, xs);
    T *ln1 = detail::grow(c.ln1, D * Md), *att = detail::grow(c.att, D * Md);
    T *xm = detail::grow(c.x_mid, D * Md), *ln2 = detail::grow(c.ln2, D * Md);
    T *qkv = detail::grow(c.qkv, D * 3 * Md), *hp = detail::grow(c.h_pre, D * M * hid);
    T *m1 = detail::grow(c.mean1, D * M), *r1 = detail::grow(c.rstd1, D * M);
    T *m2 = detail::grow(c.mean2, D * M), *r2 = detail::grow(c.rstd2, D * M);
    T* lse = detail::grow(c.lse, std::size_t(D) * B * H * L);
    T* h = detail::grow(ws.hidden, M * hid);
    const std::uint8_t* kv = c.key_valid.empty() ? nullptr : c.key_valid.data();
    for (int i = 0; i < D; ++i) {
      const std::size_t o = std::size_t(i) * Md, r = std::size_t(i) * M;
      BlockBuffers<T> buf{ln1 + o, m1 + r, r1 + r, qkv + 3 * o, att + o, lse + std::size_t(i) * B * H * L,
                          xm + o, ln2 + o, m2 + r, r2 + r, hp + std::size_t(i) * M * hid, h,
                          drop ? scales + std::size_t(2 * i) * B : nullptr,
                          drop ? scales + std::size_t(2 * i + 1) * B : nullptr};
      block_forward(ps, blocks[std::size_t(i)], xs + o, xs + o + Md, B, L, kv, buf, branch, ws);
    }
    if (x_out != xs + D * Md) std::copy(xs + D * Md, xs + (D + 1) * Md, x_out);
  }

  // dx [B, L, d]: on entry ∂L/∂x_out, on return ∂L/∂x_in. Parameter gradients are added to ps.
  template <class T>
  void backward(ParamSet<T>& ps, T* dx, const BlockStackCache<T>& c, Workspace<T>& ws) const {
    const int d = config.dim, hid = config.hidden(), H = config.heads, D = depth(), B = c.B, L = c.L;
    const std::size_t M = std::size_t(B) * L, Md = M * d;
    const bool drop = !c.scales.empty();
    const std::uint8_t* kv = c.key_valid.empty() ? nullptr : c.key_valid.data();
    T* dbranch = drop ? detail::grow(ws.dbranch, Md) : nullptr;
    T* dln = detail::grow(ws.dln, Md);
    T* dqkv = detail::grow(ws.dqkv, 3 * Md);
    T* h = detail::grow(ws.hidden2, M * hid);
    T* dh = detail::grow(ws.dhidden, M * hid);
    T* datt = detail::grow(ws.att, Md);  // forward scratch, free during backward
    for (int i = D - 1; i >= 0; --i) {
      const Block& blk = blocks[std::size_t(i)];
      const std::size_t o = std::size_t(i) * Md, r = std::size_t(i) * M;
      const T* s1 = drop ? c.scales.data() + std::size_t(2 * i) * B : nullptr;
      const T* s2 = drop ? c.scales.data() + std::size_t(2 * i + 1) * B : nullptr;
      // x_out = x_mid + s2 · mlp(ln2),  ln2 = norm2(x_mid)
      const T* g2 = dx;
      if (s2) {
        std::fill(dbranch, dbranch + Md, T(0));
        drop_path_backward(dbranch, dx, s2, B, std::size_t(L) * d);
        g2 = dbranch;
      }
      std::fill(dln, dln + Md, T(0));
      blk.mlp.backward(ps, g2, c.ln2.data() + o, c.h_pre.data() + std::size_t(i) * M * hid, h, dh, dln, int(M));
      blk.norm2.backward(ps, dln, c.x_mid.data() + o, c.mean2.data() + r, c.rstd2.data() + r, dx, int(M));
      // x_mid = x_in + s1 · attn(ln1),  ln1 = norm1(x_in)
      const T* g1 = dx;
      if (s1) {
        std::fill(dbranch, dbranch + Md, T(0));
        drop_path_backward(dbranch, dx, s1, B, std::size_t(L) * d);
        g1 = dbranch;
      }
      std::fill(dln, dln + Md, T(0));
      blk.attn.backward(ps, g1, c.ln1.data() + o, B, L, kv, c.qkv.data() + 3 * o, c.att.data() + o,
                        c.lse.data() + std::size_t(i) * B * H * L, dqkv, datt, dln, ws);
      blk.norm1.backward(ps, dln, c.xs.data() + o, c.mean1.data() + r, c.rstd1.data() + r, dx, int(M));
    }
  }

 private:
  // One block, x_in → x_out (x_out may alias x_in when buf.x_mid does too).
  template <class T>
  static void block_forward(const ParamSet<T>& ps, const Block& blk, const T* x_in, T* x_out, int B, int L,
                            const std::uint8_t* key_valid, const BlockBuffers<T>& buf, T* branch,
                            Workspace<T>& ws) {
    const int M = B * L;
    const std::size_t Md = std::size_t(M) * blk.attn.dim(), per_sample = std::size_t(L) * blk.attn.dim();
    blk.norm1.forward(ps, x_in, buf.ln1, buf.mean1, buf.rstd1, M);
    if (buf.x_mid != x_in) std::copy(x_in, x_in + Md, buf.x_mid);
    if (buf.scale1) {
      blk.attn.forward(ps, buf.ln1, B, L, key_valid, buf.qkv, buf.att, buf.lse, branch, false, ws);
      drop_path_forward(buf.x_mid, branch, buf.scale1, B, per_sample);
    } else {
      blk.attn.forward(ps, buf.ln1, B, L, key_valid, buf.qkv, buf.att, buf.lse, buf.x_mid, true, ws);
    }
    blk.norm2.forward(ps, buf.x_mid, buf.ln2, buf.mean2, buf.rstd2, M);
    if (x_out != buf.x_mid) std::copy(buf.x_mid, buf.x_mid + Md, x_out);
    if (buf.scale2) {
      blk.mlp.forward(ps, buf.ln2, buf.h_pre, buf.h, branch, M, false);
      drop_path_forward(x_out, branch, buf.scale2, B, per_sample);
    } else {
      blk.mlp.forward(ps, buf.ln2, buf.h_pre, buf.h, x_out, M, true);
    }
  }
};

}  // namespace tjepa
