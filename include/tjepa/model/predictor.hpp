#pragma once
// Predictor (paper, Sec. III-B; the reference implementation's SignalJEPAPredictor with
// pos_embed_fn="given", E-Kovtun/tactile, tactile_ssl/algorithm/xela_jepa.py):
//
//   e = ctx · W_inᵀ + b                                   ctx [Bc, K, d_in] → e [Bc, K, pd]
//   x[b] = [ e[b mod Bc] ; pos[t[b, j]] + mask_token ]    x [B, K + t, pd], B = Bc · R
//   x ← blocks(x)        (no biases inside, no drop-path)
//   out[b, j] = norm(x[b, K + j]) · W_outᵀ + b           out [B, t, d_out], target rows only
// d_out = d_in unless PredictorConfig::out_dim says otherwise (the MAE decoder: the token width).
//
// No position is added to the context embeddings (as in the reference). pos [N, pd] is a table
// given by the caller: the target encoder's pos_embed by default (no gradient), or the context
// encoder's (pass dpos to backward to get its gradient). The R target sets of a batch are tiled:
// row b of targets uses context b mod Bc, the reference's "(p k b)" order, so ctx is embedded once.
//
// PyTorch names (prefix "predictor." by default): input_projection.{weight [pd, d_in], bias},
// mask_token [1, 1, pd] (zero init), blocks.{i}.norm1, blocks.{i}.attn.qkv.weight [3pd, pd],
// blocks.{i}.attn.proj.weight, blocks.{i}.norm2, blocks.{i}.mlp.fc1.weight, blocks.{i}.mlp.fc2.weight,
// norm.*, output_projection.{weight [d_out, pd], bias}.
#include <algorithm>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/model/block.hpp"
#include "tjepa/model/position_table.hpp"

namespace tjepa {

struct PredictorConfig {
  int in_dim = 192;  // the encoder's width d
  int dim = 192;     // pd
  int depth = 4;
  int heads = 3;
  double mlp_ratio = 4.0;
  bool bias = false;  // biases inside the blocks (the reference has none)
  double eps = kernels::layer_norm_eps;
  // Width of each output row; 0: in_dim (JEPA predicts embeddings). The MAE decoder
  // (baselines/mae.hpp) sets the token width m·τ: it reconstructs the tokenizer's input.
  int out_dim = 0;
  int output_width() const { return out_dim > 0 ? out_dim : in_dim; }
};

template <class T>
struct PredictorCache {
  int Bc = 0, K = 0, B = 0, t = 0;
  std::vector<int> targets;     // [B, t]
  AlignedVector<T> ctx;         // [Bc, K, d_in] copy
  BlockStackCache<T> stack;
  AlignedVector<T> rows, normed;  // [B·t, pd] blocks' output at the targets, after norm
  AlignedVector<T> mean, rstd;    // [B·t]
};

// The predictor's input: the context encoder's output ctx [Bc, K, d_in]; the position table pos
// [N, pd] whose rows mark the targets; the target token ids targets [B, t]. B is a multiple of Bc:
// sample b reads context b mod Bc, so the targets of one batch run as one pass over the tiled
// context.
template <class T>
struct PredictorInput {
  const T* ctx = nullptr;
  int Bc = 0, K = 0;
  const T* pos = nullptr;
  int N = 0;
  const int* targets = nullptr;
  int B = 0, t = 0;
};

struct Predictor {
  PredictorConfig config;
  LinearParams input_projection, output_projection;
  ParamId mask_token;
  BlockStack stack;
  NormParams norm;

  Predictor() = default;
  template <class T>
  Predictor(ParamSet<T>& ps, const PredictorConfig& c, const std::string& prefix = "predictor.") : config(c) {
    require<ConfigError>(c.in_dim > 0 && c.dim > 0 && c.heads > 0 && c.dim % c.heads == 0, "Predictor: in_dim ",
                         c.in_dim, ", dim ", c.dim, ", heads ", c.heads, ", expected dim a positive multiple of heads");
    require<ConfigError>(c.out_dim >= 0, "Predictor: out_dim ", c.out_dim, ", expected >= 0 (0: in_dim)");
    input_projection = LinearParams::add(ps, prefix + "input_projection", c.in_dim, c.dim, true);
    mask_token = ps.add(prefix + "mask_token", {1, 1, c.dim}, ParamInit::zeros);
    BlockConfig bc{c.dim, c.heads, c.mlp_ratio, c.bias, c.bias, c.bias, c.eps};
    stack = BlockStack::add(ps, prefix + "blocks.", c.depth, bc);
    norm = NormParams::add(ps, prefix + "norm", c.dim, c.eps);
    output_projection = LinearParams::add(ps, prefix + "output_projection", c.dim, c.output_width(), true);
  }

  // in → out [B, t, d_out]: inference.
  template <class T>
  void forward(const ParamSet<T>& ps, const PredictorInput<std::type_identity_t<T>>& in, T* out, Workspace<T>& ws) const {
    run(ps, in, out, nullptr, ws);
  }
  // The same, keeping in `cache` what backward needs.
  template <class T>
  void forward(const ParamSet<T>& ps, const PredictorInput<std::type_identity_t<T>>& in, T* out,
               std::type_identity_t<PredictorCache<T>>& cache, Workspace<T>& ws) const {
    run(ps, in, out, &cache, ws);
  }

 private:
  template <class T>
  void run(const ParamSet<T>& ps, const PredictorInput<T>& in, T* out, std::type_identity_t<PredictorCache<T>>* cache,
           Workspace<T>& ws) const {
    const int pd = config.dim, din = config.in_dim;
    const T* ctx = in.ctx;
    const T* pos = in.pos;
    const int* targets = in.targets;
    const int Bc = in.Bc, K = in.K, N = in.N, B = in.B, t = in.t;
    check_params(ps, output_projection.weight, "Predictor::forward");
    require<ShapeError>(ctx && pos && targets && out, "Predictor::forward: a null ctx, pos, targets or out");
    require<ShapeError>(Bc > 0 && K > 0 && t > 0 && N > 0, "Predictor::forward: Bc = ", Bc, ", K = ", K,
                        ", t = ", t, ", N = ", N, ", expected all > 0");
    require<ShapeError>(B > 0 && B % Bc == 0, "Predictor::forward: B = ", B, ", expected a multiple of Bc = ", Bc);
    check_indices(targets, std::size_t(B) * t, N, "Predictor::forward", "targets");
    const int L = K + t;
    const std::size_t M = std::size_t(B) * L, Mt = std::size_t(B) * t;
    T* e = detail::grow(ws.rows, std::size_t(Bc) * K * pd);
    input_projection.forward(ps, ctx, e, Bc * K);
    T* x = detail::grow(ws.x, M * pd);
    const T* u = ps.value(mask_token);
    TJEPA_OMP(omp parallel for schedule(static) if (std::size_t(B) * L * pd > detail::parallel_grain))
    for (int b = 0; b < B; ++b) {
      T* xb = x + std::size_t(b) * L * pd;
      const T* eb = e + std::size_t(b % Bc) * K * pd;
      std::copy(eb, eb + std::size_t(K) * pd, xb);
      for (int j = 0; j < t; ++j) {
        const T* p = pos + std::size_t(targets[std::size_t(b) * t + j]) * pd;
        T* r = xb + std::size_t(K + j) * pd;
        for (int c = 0; c < pd; ++c) r[c] = p[c] + u[c];
      }
    }
    if (cache) {
      cache->Bc = Bc;
      cache->K = K;
      cache->B = B;
      cache->t = t;
      cache->targets.assign(targets, targets + Mt);
      cache->ctx.assign(ctx, ctx + std::size_t(Bc) * K * din);
    }
    // Only the target rows leave the blocks (the last block computes nothing else), then go
    // through the final norm and the output projection.
    T* rows = cache ? detail::grow(cache->rows, Mt * pd) : detail::grow(ws.rows2, Mt * pd);
    const StackInput<T> stack_rows{x, B, L, nullptr, K};
    if (cache)
      stack.forward(ps, stack_rows, rows, DropPath{}, cache->stack, ws);
    else
      stack.forward(ps, stack_rows, rows, DropPath{}, ws);
    T* normed = cache ? detail::grow(cache->normed, Mt * pd) : rows;
    norm.forward(ps, rows, normed, cache ? detail::grow(cache->mean, Mt) : nullptr,
                 cache ? detail::grow(cache->rstd, Mt) : nullptr, int(Mt));
    output_projection.forward(ps, normed, out, int(Mt));
  }

 public:
  // dout [B, t, d_out] → parameter gradients, dctx [Bc, K, d_in] += and dpos [N, pd] += (either
  // may be nullptr: the default reads the target encoder's table, which takes no gradient).
  template <class T>
  void backward(ParamSet<T>& ps, const T* dout, std::type_identity_t<T>* dctx, std::type_identity_t<T>* dpos, const PredictorCache<T>& c,
                Workspace<T>& ws) const {
    check_params(ps, output_projection.weight, "Predictor::backward");
    require<ConfigError>(c.B > 0, "Predictor::backward: the cache holds no forward pass");
    const int pd = config.dim, Bc = c.Bc, K = c.K, B = c.B, t = c.t, L = K + t;
    const std::size_t M = std::size_t(B) * L, Mt = std::size_t(B) * t;
    T* dn = detail::grow(ws.drows, 2 * Mt * pd);
    T* drows = dn + Mt * pd;
    std::fill(dn, dn + 2 * Mt * pd, T(0));
    output_projection.backward(ps, dout, c.normed.data(), dn, int(Mt));
    norm.backward(ps, dn, c.rows.data(), c.mean.data(), c.rstd.data(), drows, int(Mt));
    T* g = detail::grow(ws.dx, M * pd);  // ∂L/∂(target rows of the last block), then ∂L/∂x
    std::copy(drows, drows + Mt * pd, g);
    stack.backward(ps, g, c.stack, ws);
    // x[b, K + j] = pos[t[b, j]] + u
    T* du = ps.grad(mask_token);
    for (int b = 0; b < B; ++b)
      for (int j = 0; j < t; ++j) {
        const T* gr = g + (std::size_t(b) * L + K + j) * pd;
        detail::simd_add(gr, du, std::size_t(pd));
        if (dpos) {
          T* dp = dpos + std::size_t(c.targets[std::size_t(b) * t + j]) * pd;
          detail::simd_add(gr, dp, std::size_t(pd));
        }
      }
    // x[b, :K] = e[b mod Bc]: the R tiles of a context add up.
    T* de = detail::grow(ws.rows, std::size_t(Bc) * K * pd);
    std::fill(de, de + std::size_t(Bc) * K * pd, T(0));
    for (int b = 0; b < B; ++b) {
      const T* gb = g + std::size_t(b) * L * pd;
      T* d = de + std::size_t(b % Bc) * K * pd;
      detail::simd_add(gb, d, std::size_t(K) * pd);
    }
    input_projection.backward(ps, de, c.ctx.data(), dctx, Bc * K);
  }
};

}  // namespace tjepa
