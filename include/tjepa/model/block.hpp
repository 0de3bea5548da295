#pragma once
// Pre-norm transformer Block (timm / DINOv2 / the reference's NestedTensorBlock) and a stack of
// them, forward and backward side by side.
//
//   x_mid = x     + dp₁ · attn(norm1(x))        PyTorch: blocks.{i}.norm1, blocks.{i}.attn.{qkv,proj}
//   x_out = x_mid + dp₂ · mlp(norm2(x_mid))     PyTorch: blocks.{i}.norm2, blocks.{i}.mlp.{fc1,fc2}
// dp = drop-path scale per sample (1 when the rate is 0; a dropped branch is not computed at all,
// forward or backward, so rate 0.3 saves ~30% of the work). Shapes: x [B, L, d], M = B·L rows.
#include <algorithm>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/attention.hpp"
#include "tjepa/kernels/drop_path.hpp"
#include "tjepa/model/mlp.hpp"

namespace tjepa {

struct BlockConfig {
  int dim = 192;
  int heads = 3;
  double mlp_ratio = 4.0;
  bool qkv_bias = true, proj_bias = true, ffn_bias = true;
  double eps = kernels::layer_norm_eps;
  int hidden() const { return static_cast<int>(dim * mlp_ratio); }
};

// Stochastic depth of one forward: rate 0 (the default) costs nothing.
struct DropPath {
  double rate = 0.0;
  std::uint64_t seed = 0;  // sample b draws from Rng(seed, first_sample + b): pass a new seed every step
  std::uint64_t first_sample = 0;  // the batch's offset in a larger batch (data parallel shards)
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
// nullptr, x_mid = x_out = x_in, h_pre = h = nullptr: the MLP runs row-tiled without them).
template <class T>
struct BlockBuffers {
  T *ln1, *mean1, *rstd1, *qkv, *att, *lse, *x_mid, *ln2, *mean2, *rstd2, *h_pre, *h;
  const T *scale1, *scale2;  // [B] drop-path scales, nullptr = keep all
};

// Activations of a BlockStack's forward that its backward needs.
template <class T>
struct BlockStackCache {
  int B = 0, L = 0, keep_from = 0;
  AlignedVector<T> xs;                          // [depth+1, M, d] residual stream, block inputs + output
  AlignedVector<T> ln1, att, x_mid, ln2;        // [depth, M, d] (the last block's att, x_mid, ln2,
                                                // h_pre, mean2, rstd2 hold kept rows only)
  AlignedVector<T> qkv;                         // [depth, M, 3d]
  AlignedVector<T> h_pre;                       // [depth, M, hidden]
  AlignedVector<T> mean1, rstd1, mean2, rstd2;  // [depth, M]
  AlignedVector<T> lse;                         // [depth, B, H, L]
  AlignedVector<T> scales;                      // [depth, 2, B], empty without drop-path
  std::vector<std::uint8_t> key_valid;          // [B, L] copy, empty = every key valid
};

// The rows a BlockStack runs: x [B, L, d]; key_valid [B, L] (nonzero = a real token) or nullptr;
// the block outputs kept are rows [keep_from, L) of each sample.
template <class T>
struct StackInput {
  const T* x = nullptr;
  int batch = 0, length = 0;
  const std::uint8_t* key_valid = nullptr;
  int keep_from = 0;
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

  // in.x [B, L, d] → x_out [B, Lk, d], Lk = L - in.keep_from: the block outputs of rows
  // [keep_from, L) of each sample (keep_from = 0: all rows, and x_out may alias in.x). The last
  // block then computes attention queries, proj and MLP for the kept rows only: the predictor keeps
  // just its target rows. Nothing kept for a backward.
  template <class T>
  void forward(const ParamSet<T>& ps, const StackInput<std::type_identity_t<T>>& in, T* x_out, const DropPath& dp,
               Workspace<T>& ws) const {
    run(ps, in.x, x_out, in.batch, in.length, in.key_valid, dp, static_cast<BlockStackCache<T>*>(nullptr), ws,
        in.keep_from);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const StackInput<std::type_identity_t<T>>& in, T* x_out, const DropPath& dp,
               std::type_identity_t<BlockStackCache<T>>& cache, Workspace<T>& ws) const {
    run(ps, in.x, x_out, in.batch, in.length, in.key_valid, dp, &cache, ws, in.keep_from);
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const T* x_in, T* x_out, int B, int L, const std::uint8_t* key_valid,
           const DropPath& dp, BlockStackCache<T>* cache, Workspace<T>& ws, int keep_from) const {
    require<ShapeError>(keep_from >= 0 && keep_from < L, "BlockStack::forward: keep_from = ", keep_from,
                        ", expected [0, ", L, ")");
    const int d = config.dim, hid = config.hidden(), H = config.heads, D = depth(), Lk = L - keep_from;
    const std::size_t M = std::size_t(B) * L, Md = M * d, Mk = std::size_t(B) * Lk;
    const bool drop = dp.rate > 0.0 && D > 0;
    T* scales = nullptr;
    if (drop) {
      scales = detail::grow(cache ? cache->scales : ws.scales, std::size_t(D) * 2 * B);
      kernels::drop_path_sample(scales, 2 * D, B, dp.rate, dp.seed, dp.first_sample);
    } else if (cache) {
      cache->scales.clear();
    }
    auto scale = [&](int i, int k) { return drop ? scales + std::size_t(2 * i + k) * B : nullptr; };
    T* branch = drop ? detail::grow(ws.branch, Md) : nullptr;
    if (D == 0) {
      keep_rows(x_out, x_in, B, L, keep_from, d);
      if (cache) {
        cache->B = B;
        cache->L = L;
        cache->keep_from = keep_from;
      }
      return;
    }
    if (!cache) {
      // The residual stream runs in place: in x_out when every row is kept, else in scratch
      // until the last block writes the kept rows to x_out.
      T* x = keep_from == 0 ? x_out : detail::grow(ws.stream, Md);
      if (x != x_in) detail::parallel_copy(x_in, x_in + Md, x);
      if (!drop && keep_from == 0 && forward_owned(ps, x, B, L, key_valid, ws)) return;
      for (int i = 0; i < D; ++i) {
        const bool last = i == D - 1;
        T* out = last ? x_out : x;
        BlockBuffers<T> buf{detail::grow(ws.ln, Md), nullptr, nullptr, detail::grow(ws.qkv, 3 * Md),
                            detail::grow(ws.att, Md), nullptr, out, detail::grow(ws.ln, Md), nullptr, nullptr,
                            nullptr, nullptr, scale(i, 0), scale(i, 1)};
        block_forward(ps, blocks[std::size_t(i)], x, out, B, L, last ? keep_from : 0, key_valid, buf, branch, ws);
      }
      return;
    }
    BlockStackCache<T>& c = *cache;
    c.B = B;
    c.L = L;
    c.keep_from = keep_from;
    if (key_valid)
      c.key_valid.assign(key_valid, key_valid + M);
    else
      c.key_valid.clear();
    T* xs = detail::grow(c.xs, (D + 1) * Md);
    detail::parallel_copy(x_in, x_in + Md, xs);
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
                          xm + o, ln2 + o, m2 + r, r2 + r, hp + std::size_t(i) * M * hid, h, scale(i, 0), scale(i, 1)};
      block_forward(ps, blocks[std::size_t(i)], xs + o, xs + o + Md, B, L, i == D - 1 ? keep_from : 0, kv, buf,
                    branch, ws);
    }
    const T* y = xs + D * Md;
    if (x_out != y) detail::parallel_copy(y, y + Mk * d, x_out);
  }

 public:
  // dx: on entry ∂L/∂x_out ([B, Lk, d] in its first B·Lk·d values), on return ∂L/∂x_in
  // [B, L, d] (dx holds B·L·d values). Parameter gradients are added to ps.
  template <class T>
  void backward(ParamSet<T>& ps, T* dx, const BlockStackCache<T>& c, Workspace<T>& ws) const {
    const int d = config.dim, hid = config.hidden(), H = config.heads, D = depth(), B = c.B, L = c.L;
    const int kf = c.keep_from, Lk = L - kf;
    const std::size_t M = std::size_t(B) * L, Md = M * d, Mk = std::size_t(B) * Lk;
    const bool drop = !c.scales.empty();
    const std::uint8_t* kv = c.key_valid.empty() ? nullptr : c.key_valid.data();
    T* dbranch = drop ? detail::grow(ws.dbranch, Md) : nullptr;
    T* dln = detail::grow(ws.dln, Md);
    T* dqkv = detail::grow(ws.dqkv, 3 * Md);
    T* datt = detail::grow(ws.att, Md);  // forward scratch, free during backward
    T* h = detail::grow(ws.hidden2, M * hid);
    T* dh = detail::grow(ws.dhidden, M * hid);
    // ∂L/∂x_out of the kept rows, while dx becomes the full-size gradient.
    T* g = dx;
    if (kf > 0) {
      g = detail::grow(ws.dkept, Mk * d);
      detail::parallel_copy(dx, dx + Mk * d, g);
      if (D == 0) {
        detail::parallel_fill(dx, dx + Md, T(0));
        scatter_kept_rows(dx, g, B, L, kf, d);
        return;
      }
    }
    for (int i = D - 1; i >= 0; --i) {
      const Block& blk = blocks[std::size_t(i)];
      const std::size_t o = std::size_t(i) * Md, r = std::size_t(i) * M;
      const int q_from = i == D - 1 ? kf : 0;
      const std::size_t per_sample = std::size_t(L - q_from) * d;
      T* gq = q_from > 0 ? g : dx;  // ∂L/∂x_out, then ∂L/∂x_mid, of this block's query rows
      const T* s1 = drop ? c.scales.data() + std::size_t(2 * i) * B : nullptr;
      const T* s2 = drop ? c.scales.data() + std::size_t(2 * i + 1) * B : nullptr;
      const int Lq = L - q_from;
      // x_out = x_mid + s2 · mlp(ln2), ln2 = norm2(x_mid): only samples whose branch was kept.
      for_each_kept_run(s2, B, [&](int b0, int b1) {
        const int n = b1 - b0, rows = n * Lq;
        const std::size_t q = std::size_t(b0) * Lq;
        const T* g2 = gq + q * d;
        if (s2) {
          detail::parallel_fill(dbranch + q * d, dbranch + (q + rows) * d, T(0));
          kernels::drop_path_backward(dbranch + q * d, gq + q * d, s2 + b0, n, per_sample);
          g2 = dbranch + q * d;
        }
        detail::parallel_fill(dln + q * d, dln + (q + rows) * d, T(0));
        blk.mlp.backward(ps, g2, c.ln2.data() + o + q * d, c.h_pre.data() + std::size_t(i) * M * hid + q * hid,
                         h + q * hid, dh + q * hid, dln + q * d, rows, ws.precision);
        ws.mark("mlp backward");
        blk.norm2.backward(ps, dln + q * d, c.x_mid.data() + o + q * d, c.mean2.data() + r + q,
                           c.rstd2.data() + r + q, gq + q * d, rows);
        ws.mark("norm2 backward");
      });
      // x_mid = x_in[query rows] + s1 · attn(ln1), ln1 = norm1(x_in)
      if (q_from > 0) {
        detail::parallel_fill(dx, dx + Md, T(0));
        scatter_kept_rows(dx, gq, B, L, q_from, d);
      }
      for_each_kept_run(s1, B, [&](int b0, int b1) {
        const int n = b1 - b0;
        const std::size_t f = std::size_t(b0) * L, q = std::size_t(b0) * Lq;
        const T* g1 = gq + q * d;
        if (s1) {
          detail::parallel_fill(dbranch + q * d, dbranch + (q + std::size_t(n) * Lq) * d, T(0));
          kernels::drop_path_backward(dbranch + q * d, gq + q * d, s1 + b0, n, per_sample);
          g1 = dbranch + q * d;
        }
        const AttentionRows rows{n, L, kv ? kv + f : nullptr, q_from};
        const AttentionSaved<T> saved{.qkv = const_cast<T*>(c.qkv.data()) + 3 * o + f * 3 * d,
                                      .att = const_cast<T*>(c.att.data()) + o + q * d,
                                      .lse = const_cast<T*>(c.lse.data()) + std::size_t(i) * B * H * L +
                                             std::size_t(b0) * H * L};
        detail::parallel_fill(dln + f * d, dln + (f + std::size_t(n) * L) * d, T(0));
        blk.attn.backward(ps, rows, g1, c.ln1.data() + o + f * d, saved,
                          AttentionScratch<T>{.dqkv = dqkv + f * 3 * d, .datt = datt + q * d}, dln + f * d, ws);
        blk.norm1.backward(ps, dln + f * d, c.xs.data() + o + f * d, c.mean1.data() + r + f, c.rstd1.data() + r + f,
                           dx + f * d, n * L);
        ws.mark("norm1 backward");
      });
    }
  }

 private:
  // dst[b, j] = src[b, keep_from + j] for j < L - keep_from (a copy when keep_from = 0).
  template <class T>
  static void keep_rows(T* dst, const T* src, int B, int L, int keep_from, int d) {
    const std::size_t n = std::size_t(L - keep_from) * d;
    if (keep_from == 0 && dst == src) return;
    for (int b = 0; b < B; ++b) {
      const T* s = src + (std::size_t(b) * L + keep_from) * d;
      std::copy(s, s + n, dst + std::size_t(b) * n);
    }
  }
  // dst[b, keep_from + j] += src[b, j]
  template <class T>
  static void scatter_kept_rows(T* dst, const T* src, int B, int L, int keep_from, int d) {
    const std::size_t n = std::size_t(L - keep_from) * d;
    for (int b = 0; b < B; ++b) {
      T* o = dst + (std::size_t(b) * L + keep_from) * d;
      const T* s = src + std::size_t(b) * n;
      detail::simd_add(s, o, n);
    }
  }

  // Calls f(b0, b1) for each maximal run of samples [b0, b1) whose branch is kept (scale ≠ 0),
  // or once for all samples without drop-path: a dropped branch is never computed.
  template <class T, class F>
  static void for_each_kept_run(const T* scale, int B, F&& f) {
    if (!scale) {
      f(0, B);
      return;
    }
    for (int b = 0; b < B;) {
      if (scale[b] == T(0)) {
        ++b;
        continue;
      }
      int e = b;
      while (e < B && scale[e] != T(0)) ++e;
      f(b, e);
      b = e;
    }
  }

  // Inference in place on x [B, L, d] on several threads when the rows are few (detail::owns_rows:
  // batch 1 of a few hundred tokens) and the weights packed once (Workspace::frozen_weights): the
  // whole stack in one parallel region, each thread on its own rows from the first LayerNorm to the
  // last MLP. Only attention reads other threads' rows (every key and value of a sample), so a
  // block waits once, after qkv; qkv alternates between two buffers so that a thread a block ahead
  // never overwrites the keys another is still reading. The same kernels on the same rows as
  // block_forward, so the same bits. Returns false, having done nothing, where it does not apply.
  // Stage marks are thread 0's; "barrier" is its wait there for the other threads' qkv.
  template <class T>
  bool forward_owned(const ParamSet<T>& ps, T* x, int B, int L, const std::uint8_t* key_valid,
                     Workspace<T>& ws) const {
    if constexpr (!std::is_same_v<T, float>) {
      return false;
    } else {
      const int threads = detail::max_threads(), M = B * L, d = config.dim, hid = config.hidden();
      if (!ws.frozen_weights || !detail::owns_rows(M, threads)) return false;
      kernels::PackedWeights<float>& cache = *ws.weights();
      for (const Block& blk : blocks)  // packed here, once: the threads only read the cache
        for (const LinearParams* lp : {&blk.attn.qkv, &blk.attn.proj, &blk.mlp.fc1, &blk.mlp.fc2}) lp->plan(ps, &cache);
      const std::size_t Md = std::size_t(M) * d, tile = std::size_t(kernels::mlp_tile_rows) * hid;
      float* ln = detail::grow(ws.ln, Md);
      float* qkv2 = detail::grow(ws.qkv, 2 * 3 * Md);
      float* att = detail::grow(ws.att, Md);
      float* tiles = detail::grow(ws.mlp, std::size_t(threads) * tile);
      kernels::AttentionWorkspace<float>* aws = ws.attention_per_thread(blocks.front().attn.head_shape(L, 0));
      const AttentionRows rows{B, L, key_valid, 0};
      TJEPA_OMP(omp parallel num_threads(threads))
      {
        const int t = detail::thread_id(), n = detail::team_size();
        const int r0 = detail::row_begin(M, t, n), r1 = detail::row_begin(M, t + 1, n);
        const auto mark = [&](const char* stage) {
          if (t == 0) ws.mark(stage);
        };
        for (std::size_t i = 0; i < blocks.size(); ++i) {
          const Block& blk = blocks[i];
          float* qkv = qkv2 + (i % 2) * 3 * Md;
          blk.norm1.forward_rows(ps, x, ln, r0, r1);
          mark("norm1");
          blk.attn.qkv.forward_rows(ps, ln, qkv, r0, r1, cache);
          mark("qkv");
          TJEPA_OMP(omp barrier)
          mark("barrier");
          blk.attn.rows_forward(rows, AttentionSaved<float>{.qkv = qkv, .att = att, .lse = nullptr}, r0, r1, aws[t],
                                ws.precision);
          mark("attention");
          blk.attn.proj.forward_rows(ps, att, x, r0, r1, cache, x);
          mark("proj");
          blk.norm2.forward_rows(ps, x, ln, r0, r1);
          mark("norm2");
          blk.mlp.forward_rows(ps, ln, x, r0, r1, x, cache, tiles + std::size_t(t) * tile);
          mark("mlp");
        }
      }
      return true;
    }
  }

  // One block, x_in [B, L, d] → x_out [B, L - q_from, d]: attention queries, proj, norm2 and MLP
  // for the rows [q_from, L) of each sample only. With q_from = 0, x_out may alias x_in when
  // buf.x_mid does too. Under drop-path each branch runs on the samples that keep it.
  template <class T>
  static void block_forward(const ParamSet<T>& ps, const Block& blk, const T* x_in, T* x_out, int B, int L,
                            int q_from, const std::uint8_t* key_valid, const BlockBuffers<T>& buf, T* branch,
                            Workspace<T>& ws) {
    const int d = blk.attn.dim(), H = blk.attn.heads, hid = blk.mlp.hidden(), Lq = L - q_from;
    const std::size_t per_sample = std::size_t(Lq) * d;
    // Without drop-path on all rows the residual adds read their stream in the GEMM epilogues:
    // x_mid = x_in + attn, x_out = x_mid + mlp, no copies.
    const bool direct1 = !buf.scale1 && q_from == 0, direct2 = !buf.scale2;
    if (!direct1) keep_rows(buf.x_mid, x_in, B, L, q_from, d);
    for_each_kept_run(buf.scale1, B, [&](int b0, int b1) {
      const int n = b1 - b0;
      const std::size_t f = std::size_t(b0) * L, q = std::size_t(b0) * Lq;
      blk.norm1.forward(ps, x_in + f * d, buf.ln1 + f * d, buf.mean1 ? buf.mean1 + f : nullptr,
                        buf.rstd1 ? buf.rstd1 + f : nullptr, n * L);
      ws.mark("norm1");
      T* y = buf.scale1 ? branch + q * d : buf.x_mid + q * d;
      const AttentionSaved<T> saved{.qkv = buf.qkv + f * 3 * d, .att = buf.att + q * d,
                                    .lse = buf.lse ? buf.lse + std::size_t(b0) * H * L : nullptr};
      // y = x_in + attn (direct), x_mid += attn (x_mid holds the kept rows), or the bare branch
      const T* residual = direct1 ? x_in + f * d : buf.scale1 ? nullptr : y;
      blk.attn.forward(ps, AttentionRows{n, L, key_valid ? key_valid + f : nullptr, q_from}, buf.ln1 + f * d, saved, y,
                       ws, residual);
      if (buf.scale1) kernels::drop_path_forward(buf.x_mid + q * d, branch + q * d, buf.scale1 + b0, n, per_sample);
    });
    if (x_out != buf.x_mid && !direct2)
      detail::parallel_copy(buf.x_mid, buf.x_mid + std::size_t(B) * per_sample, x_out);
    for_each_kept_run(buf.scale2, B, [&](int b0, int b1) {
      const int n = b1 - b0, rows = n * Lq;
      const std::size_t q = std::size_t(b0) * Lq;
      blk.norm2.forward(ps, buf.x_mid + q * d, buf.ln2 + q * d, buf.mean2 ? buf.mean2 + q : nullptr,
                        buf.rstd2 ? buf.rstd2 + q : nullptr, rows);
      ws.mark("norm2");
      T* y = buf.scale2 ? branch + q * d : x_out + q * d;
      const T* residual = direct2 ? buf.x_mid + q * d : nullptr;
      if (buf.h)
        blk.mlp.forward(ps, buf.ln2 + q * d, buf.h_pre + q * hid, buf.h + q * hid, y, rows, residual, ws.weights());
      else
        blk.mlp.forward_tiled(ps, buf.ln2 + q * d, y, rows, residual, ws.mlp, ws.weights());
      ws.mark("mlp");
      if (buf.scale2) kernels::drop_path_forward(x_out + q * d, branch + q * d, buf.scale2 + b0, n, per_sample);
    });
  }
};

}  // namespace tjepa
