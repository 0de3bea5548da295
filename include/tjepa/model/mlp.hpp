#pragma once
// Mlp (timm's): fc1 [hidden, d] → exact GELU → fc2 [out, hidden] (out = d inside a block; the
// probe's output head has its own out). PyTorch names: <name>.fc1.*, <name>.fc2.*.
// fc1's bias and GELU are fused into its GEMM, fc2's output into the residual add.
#include <algorithm>
#include <string>

#include "tjepa/kernels/gelu.hpp"
#include "tjepa/model/layers.hpp"

namespace tjepa {

struct Mlp {
  LinearParams fc1, fc2;

  template <class T>
  static Mlp add(ParamSet<T>& ps, const std::string& name, int dim, int hidden, bool bias, int out = 0) {
    Mlp m;
    m.fc1 = LinearParams::add(ps, name + ".fc1", dim, hidden, bias);
    m.fc2 = LinearParams::add(ps, name + ".fc2", hidden, out > 0 ? out : dim, bias);
    return m;
  }
  int dim() const { return fc1.in; }
  int hidden() const { return fc1.out; }
  int out() const { return fc2.out; }

  // x [M, d] → y [M, out] = residual + mlp(x) (residual may equal y: y +=; nullptr: y = mlp(x)).
  // h_pre [M, hidden] receives fc1's output + bias (kept for backward), h [M, hidden] the
  // activation; h may equal h_pre. cache: Workspace::weights() or nullptr (fp32).
  template <class T>
  void forward(const ParamSet<T>& ps, const T* x, T* h_pre, T* h, T* y, int M, const T* residual = nullptr,
               kernels::PackedWeights<T>* cache = nullptr) const {
    kernels::linear_bias_gelu_forward(h, h_pre, x, ps.value(fc1.weight), fc1.b(ps), M, fc1.in, fc1.out,
                                      fc1.plan(ps, cache));
    if (residual)
      fc2.forward_residual(ps, h, residual, y, M, cache);
    else
      fc2.forward(ps, h, y, M, cache);
  }

  // Inference: y [M, out] = (residual +) mlp(x), row-tiled (kernels/linear.hpp's
  // kernels::mlp_forward_tiled): no [M, hidden] buffer. residual may equal y, or be nullptr. cache:
  // Workspace::weights() (precision, frozen inference) or nullptr (fp32).
  template <class T>
  void forward_tiled(const ParamSet<T>& ps, const T* x, T* y, int M, const T* residual, AlignedVector<T>& scratch,
                     kernels::PackedWeights<T>* cache = nullptr) const {
    kernels::mlp_forward_tiled(y, residual, x, ps.value(fc1.weight), fc1.b(ps), ps.value(fc2.weight), fc2.b(ps), M, fc1.in,
                      fc1.out, fc2.out, scratch, fc1.plan(ps, cache), fc2.plan(ps, cache));
  }

  // Rows [m0, m1) of forward_tiled on the calling thread, from weights `cache` packed before (as
  // LinearParams::forward_rows), through h, one [kernels::mlp_tile_rows, hidden] tile.
  void forward_rows(const ParamSet<float>& ps, const float* x, float* y, int m0, int m1, const float* residual,
                    kernels::PackedWeights<float>& cache, float* h) const {
    const kernels::WeightPlan p1 = fc1.plan(ps, &cache), p2 = fc2.plan(ps, &cache);
    kernels::mlp_forward_rows(y, residual, x, p1.precision, p1.packed, fc1.b(ps), p2.packed, fc2.b(ps), m0, m1, fc1.in,
                              fc1.out, fc2.out, h);
  }

  // dx [M, d] (may be nullptr) += ∂L/∂x given dy [M, out]; the parameters' gradients +=. h, dh
  // [M, hidden] are scratch (h is recomputed from h_pre rather than kept: the largest activation
  // of a block). precision: of the products.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dy, const T* x, const T* h_pre, T* h, T* dh, T* dx, int M,
                Precision precision = Precision::fp32) const {
    // h = gelu(h_pre) and dh = gelu'(h_pre), one pass sharing the erf.
    kernels::gelu_forward_grad(h, dh, h_pre, std::size_t(M) * std::size_t(fc1.out));
    fc2.backward(ps, dy, h, static_cast<T*>(nullptr), M, precision);  // y = h · W2ᵀ + b2: dW2, db2
    // h, free now, = ∂L/∂h_pre = (dy · W2) ⊙ gelu'(h_pre), one product scaled by dh.
    kernels::linear_backward_input_scaled(h, dy, ps.value(fc2.weight), dh, M, fc2.in, fc2.out, precision);
    fc1.backward(ps, h, x, dx, M, precision);  // h_pre = x · W1ᵀ + b1
  }
};

}  // namespace tjepa
