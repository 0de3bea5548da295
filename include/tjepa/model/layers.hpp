#pragma once
// The two parameterized pieces every module is built from: a Linear (weight [out, in], optional
// bias [out]) and a LayerNorm (weight [C], bias [C]), as ParamIds registered under a PyTorch name.
// They hold no values: forward and backward read values and add gradients in a ParamSet of the
// same layout (the context encoder's, or the EMA target encoder's).
//
// Every module's forward and backward (here, in model/ and in downstream/) keep one contract:
// - forward writes its output; where it takes a `residual`, it writes y = residual + f(x) (the
//   residual may be y itself: y += f(x));
// - backward adds into every gradient it is given, the parameters' in the ParamSet and the
//   inputs', and never overwrites: one ParamSet::zero_grad and zeroed input-gradient buffers serve
//   a whole model. (BlockStack::backward, inside the encoder and predictor, is in place: its dx
//   enters as ∂L/∂x_out and leaves as ∂L/∂x_in.)
// Calls with many buffers take them in argument structs (AttentionRows, AttentionSaved,
// CrossAttentionSaved, PredictorInput), as the kernels take an AttentionShape.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "tjepa/kernels/layer_norm.hpp"
#include "tjepa/kernels/linear.hpp"
#include "tjepa/core/param_set.hpp"

namespace tjepa {

// Throws ConfigError unless ps is allocated and holds `id` where the module registered it: a cheap
// guard against running a module on a ParamSet of another layout.
template <class T>
void check_params(const ParamSet<T>& ps, const ParamId& id, const char* where) {
  require<ConfigError>(ps.allocated(), where, ": the ParamSet is not allocated");
  require<ConfigError>(id.index < ps.count() && ps.infos()[id.index].offset == id.offset &&
                           ps.infos()[id.index].size == id.size,
                       where, ": the ParamSet does not have this module's layout (parameter #", id.index, ")");
}

struct LinearParams {
  ParamId weight, bias;
  int in = 0, out = 0;
  bool has_bias = false;

  // weight_shape: the weight's PyTorch shape when it is not [out, in] but flattens to it (a
  // Conv1d's [out, C, k] with in = C·k); empty: [out, in].
  template <class T>
  static LinearParams add(ParamSet<T>& ps, const std::string& name, int in, int out, bool bias,
                          std::vector<std::int64_t> weight_shape = {}) {
    LinearParams p;
    p.in = in;
    p.out = out;
    p.has_bias = bias;
    if (weight_shape.empty()) weight_shape = {out, in};
    std::int64_t numel = 1;
    for (auto s : weight_shape) numel *= s;
    require<ConfigError>(!weight_shape.empty() && weight_shape[0] == out && numel == std::int64_t(out) * in,
                         "LinearParams::add: ", name, ".weight shape of ", weight_shape.size(),
                         " dims and ", numel, " values, expected [", out, ", ...] flattening to ", out, "x", in);
    p.weight = ps.add(name + ".weight", std::move(weight_shape), ParamInit::trunc_normal);
    if (bias) p.bias = ps.add(name + ".bias", {out}, ParamInit::zeros);
    return p;
  }
  template <class T>
  const T* b(const ParamSet<T>& ps) const { return has_bias ? ps.value(bias) : nullptr; }

  // How the forward products read the weight (kernels::PackedWeights: precision, packed once);
  // without a cache, fp32 packed per call.
  template <class T>
  kernels::WeightPlan plan(const ParamSet<T>& ps, kernels::PackedWeights<T>* cache) const {
    return cache ? cache->get(ps.value(weight), out, in) : kernels::WeightPlan{};
  }
  // Rows [m0, m1) of forward (of forward_residual with r: y = r + x · Wᵀ + b, r may equal y) on the
  // calling thread, from the weight as `cache` packed it: cache.get() has packed it before, so
  // that threads only read it here.
  void forward_rows(const ParamSet<float>& ps, const float* x, float* y, int m0, int m1,
                    kernels::PackedWeights<float>& cache, const float* r = nullptr) const {
    const kernels::WeightPlan p = cache.get(ps.value(weight), out, in);
    detail::compute_rows(p.precision, m1 - m0, out, in, x + std::size_t(m0) * in, p.packed, y + std::size_t(m0) * out,
                         {false, b(ps), nullptr, nullptr, r ? r + std::size_t(m0) * out : nullptr});
  }
  // out[M, out] = in[M, in] · Wᵀ + b. cache: Workspace::weights() (precision, frozen inference) or
  // nullptr (fp32).
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, T* y, int M, kernels::PackedWeights<T>* cache = nullptr) const {
    kernels::linear_forward(y, x, ps.value(weight), b(ps), M, in, out, plan(ps, cache));
  }
  // y[M, out] += x · Wᵀ + b (residual add fused into the GEMM)
  template <class T>
  void forward_accumulate(const ParamSet<T>& ps, const T* x, T* y, int M) const {
    kernels::linear_forward_accumulate(y, x, ps.value(weight), b(ps), M, in, out);
  }
  // y[M, out] = r[M, out] + x · Wᵀ + b (r may equal y)
  template <class T>
  void forward_residual(const ParamSet<T>& ps, const T* x, const T* r, T* y, int M,
                        kernels::PackedWeights<T>* cache = nullptr) const {
    kernels::linear_forward_residual(y, r, x, ps.value(weight), b(ps), M, in, out, plan(ps, cache));
  }
  // dx (may be nullptr) += dy · W; dW += dyᵀ · x; db += Σ dy. precision: of the two products.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, const T* x, T* dx, int M, Precision precision = Precision::fp32) const {
    kernels::linear_backward(dx, ps.grad(weight), has_bias ? ps.grad(bias) : nullptr, dy, x, ps.value(weight), M, in,
                             out, true, precision);
  }
};

struct NormParams {
  ParamId weight, bias;
  int dim = 0;
  double eps = kernels::layer_norm_eps;

  template <class T>
  static NormParams add(ParamSet<T>& ps, const std::string& name, int dim, double eps) {
    NormParams p;
    p.dim = dim;
    p.eps = eps;
    p.weight = ps.add(name + ".weight", {dim}, ParamInit::ones);
    p.bias = ps.add(name + ".bias", {dim}, ParamInit::zeros);
    return p;
  }
  // mean, rstd [M] may be nullptr (inference).
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, T* y, T* mean, T* rstd, int M) const {
    kernels::layer_norm_forward(y, mean, rstd, x, ps.value(weight), ps.value(bias), M, dim, T(eps));
  }
  // Rows [m0, m1) of an inference forward (no statistics) on the calling thread.
  template <class T>
  void forward_rows(const ParamSet<T>& ps, const T* x, T* y, int m0, int m1) const {
    kernels::layer_norm_forward_rows(y, static_cast<T*>(nullptr), static_cast<T*>(nullptr), x, ps.value(weight),
                                     ps.value(bias), m0, m1, dim, T(eps));
  }
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, const T* x, const T* mean, const T* rstd, T* dx, int M) const {
    kernels::layer_norm_backward(dx, ps.grad(weight), ps.grad(bias), dy, x, ps.value(weight), mean, rstd, M, dim);
  }
};

}  // namespace tjepa
