#pragma once
// AlexNet: torchvision's alexnet().features followed by its avgpool, the image trunk of the BYOL
// (T-DEX) baseline. Images x [B, S, S, Cin] (NHWC) → features [B, w₄·R²]:
//
//   a₀ = relu(conv₀(x))     k 11, stride 4, pad 2    [B, S₁, S₁, w₀]   S₁ = ⌊(S − 7)/4⌋ + 1
//   p₀ = maxpool(a₀)        3 × 3, stride 2          [B, P₁, P₁, w₀]   P₁ = ⌊(S₁ − 3)/2⌋ + 1
//   a₁ = relu(conv₁(p₀))    k 5, pad 2               [B, P₁, P₁, w₁]
//   p₁ = maxpool(a₁)                                 [B, P₂, P₂, w₁]   P₂ = ⌊(P₁ − 3)/2⌋ + 1
//   a₂ = relu(conv₂(p₁))    k 3, pad 1               [B, P₂, P₂, w₂]
//   a₃ = relu(conv₃(a₂))    k 3, pad 1               [B, P₂, P₂, w₃]
//   a₄ = relu(conv₄(a₃))    k 3, pad 1               [B, P₂, P₂, w₄]
//   p₄ = maxpool(a₄)                                 [B, P₃, P₃, w₄]   P₃ = ⌊(P₂ − 3)/2⌋ + 1
//   q  = adaptive_avgpool(p₄)                        [B, R, R, w₄]     R = pooled
//   features[b, c·R² + y·R + x] = q[b, y, x, c]      [B, w₄·R²]
//
// At S = 224 and the default widths (64, 192, 384, 256, 256): S₁ 55, P₁ 27, P₂ 13, P₃ 6, and
// 9216 features. The smallest image is 63 (P₃ = 1); R > P₃ repeats bins, as PyTorch does.
// The features are flattened in PyTorch's order (c, y, x) (torch.flatten(avgpool(x), 1) of NCHW),
// so that a PyTorch Linear(9216, ·) weight applies to them unchanged.
//
// PyTorch names (prefix "" by default): features.{0,3,6,8,10}.weight [wᵢ, Cᵢ, k, k] and .bias
// [wᵢ], the indices of the Conv2d modules in torchvision's features Sequential. Both are drawn
// from U(−1/√fan_in, 1/√fan_in), fan_in = Cᵢ·k·k: PyTorch's default Conv2d initialization.
//
// Activations are NHWC inside: channels are contiguous, so the convolutions' im2col copies runs
// of C values and their GEMM writes the next layer's NHWC input directly (the rows are pixels, the
// columns channels, as the transformer's [tokens, channels]), and ReLU and pooling run over
// contiguous channels. The kernels are kernels/conv2d.hpp's.
//
// forward keeps every activation backward needs in an AlexNetCache (post-ReLU outputs, max-pool
// indices, pooled inputs) and a pointer to the images, which must stay valid until backward.
// backward ADDS into the parameter gradients (and into the image gradient when wanted), as every
// module of the library.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <type_traits>
#include <vector>

#include "tjepa/core/param_set.hpp"
#include "tjepa/kernels/conv2d.hpp"
#include "tjepa/model/layers.hpp"

namespace tjepa {

// The spatial sides of the stack: conv₀'s output and the three max-pools'.
struct AlexNetSides {
  int conv0 = 0, pool0 = 0, pool1 = 0, pool2 = 0;
};

struct AlexNetConfig {
  int in_channels = 3;
  int image_size = 224;                               // S: images are S × S
  std::array<int, 5> widths{64, 192, 384, 256, 256};  // output channels of the five convolutions
  int pooled = 6;                                     // R: the adaptive average pool's output side

  static constexpr int min_image_size = 63;

  AlexNetSides sides() const {
    AlexNetSides s;
    s.conv0 = kernels::Conv2dShape{1, image_size, image_size, 1, 1, 11, 4, 2}.Ho();
    s.pool0 = kernels::pool_out_side(s.conv0, 3, 2);
    s.pool1 = kernels::pool_out_side(s.pool0, 3, 2);
    s.pool2 = kernels::pool_out_side(s.pool1, 3, 2);
    return s;
  }
  int out_dim() const { return widths[4] * pooled * pooled; }

  void validate() const {
    require<ConfigError>(in_channels > 0, "AlexNet: in_channels ", in_channels, ", expected > 0");
    for (std::size_t i = 0; i < widths.size(); ++i)
      require<ConfigError>(widths[i] > 0 && widths[i] <= (1 << 20), "AlexNet: widths[", i, "] = ", widths[i],
                           ", expected in [1, 2^20]");
    require<ConfigError>(in_channels <= (1 << 20), "AlexNet: in_channels ", in_channels, ", expected <= 2^20");
    require<ConfigError>(image_size >= min_image_size && image_size <= (1 << 16), "AlexNet: image_size ",
                         image_size, " (conv 11/4 then three max-pools 3/2 leave ", sides().pool2,
                         " pixels), expected in [", min_image_size, ", 65536]");
    require<ConfigError>(pooled > 0 && pooled <= 1024, "AlexNet: pooled ", pooled, ", expected in [1, 1024]");
  }
};

// What backward needs of a forward pass, and the scratch of both; grown on first use and reused.
template <class T>
struct AlexNetCache {
  int B = 0;                             // batch of the last forward (0: none)
  const T* images = nullptr;             // the last forward's input (not copied)
  AlignedVector<T> a0, a1, a2, a3, a4;   // post-ReLU conv outputs
  AlignedVector<T> p0, p1, p4;           // max-pool outputs (the next layer's inputs)
  std::vector<std::int32_t> i0, i1, i4;  // max-pool indices
  AlignedVector<T> q;                    // adaptive pool output [B, R, R, w₄] (NHWC)
  AlignedVector<T> g0, g1, dq;           // backward's gradient buffers
  kernels::Conv2dScratch<T> conv;
};

struct AlexNet {
  // One Conv2d of the stack: its parameters and geometry.
  struct Conv {
    ParamId weight, bias;
    int in = 0, out = 0, k = 1, stride = 1, pad = 0;
  };

  // Indices of the convolutions in torchvision's features Sequential.
  static constexpr std::array<int, 5> torch_index{0, 3, 6, 8, 10};

  AlexNetConfig config;
  std::array<Conv, 5> convs;

  AlexNet() = default;
  template <class T>
  AlexNet(ParamSet<T>& ps, const AlexNetConfig& c, const std::string& prefix = "") : config(c) {
    c.validate();
    constexpr std::array<int, 5> kernel{11, 5, 3, 3, 3}, stride{4, 1, 1, 1, 1}, pad{2, 2, 1, 1, 1};
    int in = c.in_channels;
    for (std::size_t i = 0; i < convs.size(); ++i) {
      Conv& v = convs[i];
      v.in = in;
      v.out = c.widths[i];
      v.k = kernel[i];
      v.stride = stride[i];
      v.pad = pad[i];
      const std::string name = prefix + "features." + std::to_string(torch_index[i]);
      const double bound = 1.0 / std::sqrt(double(v.in) * v.k * v.k);
      v.weight = ps.add(name + ".weight", {v.out, v.in, v.k, v.k}, ParamInit::uniform, bound);
      v.bias = ps.add(name + ".bias", {v.out}, ParamInit::uniform, bound);
      in = v.out;
    }
  }

  int out_dim() const { return config.out_dim(); }

  // Forward multiply-adds × 2 of the five convolutions for a batch of B (pooling and ReLU, a few
  // per mille, not counted).
  static double flops(const AlexNetConfig& c, int B) {
    const AlexNetSides s = c.sides();
    const std::array<int, 5> side{s.conv0, s.pool0, s.pool1, s.pool1, s.pool1}, kernel{11, 5, 3, 3, 3};
    double macs = 0;
    int in = c.in_channels;
    for (std::size_t i = 0; i < 5; ++i) {
      macs += double(side[i]) * side[i] * c.widths[i] * double(in) * kernel[i] * kernel[i];
      in = c.widths[i];
    }
    return 2.0 * macs * B;
  }

  // images [B, S, S, Cin] → features [B, out_dim]. The cache keeps what backward needs (and the
  // images pointer); an inference pass uses the same call.
  template <class T>
  void forward(const ParamSet<T>& ps, const T* images, int B, T* features,
               std::type_identity_t<AlexNetCache<T>>& c) const {
    check_params(ps, convs[4].bias, "AlexNet::forward");
    require<ShapeError>(B > 0 && images && features, "AlexNet::forward: B = ", B,
                        ", expected > 0 images and non-null images, features");
    const AlexNetSides s = config.sides();
    const std::array<int, 5>& w = config.widths;
    const int R = config.pooled;
    c.B = 0;
    c.images = images;
    // conv₀ → ReLU → max-pool
    T* a0 = detail::grow(c.a0, size(B, s.conv0, w[0]));
    conv_forward(ps, 0, images, a0, B, config.image_size, c);
    T* p0 = detail::grow(c.p0, size(B, s.pool0, w[0]));
    std::int32_t* i0 = detail::grow(c.i0, size(B, s.pool0, w[0]));
    kernels::maxpool2d_forward(p0, i0, static_cast<const T*>(a0), B, s.conv0, s.conv0, w[0], 3, 2);
    // conv₁ → ReLU → max-pool
    T* a1 = detail::grow(c.a1, size(B, s.pool0, w[1]));
    conv_forward(ps, 1, p0, a1, B, s.pool0, c);
    T* p1 = detail::grow(c.p1, size(B, s.pool1, w[1]));
    std::int32_t* i1 = detail::grow(c.i1, size(B, s.pool1, w[1]));
    kernels::maxpool2d_forward(p1, i1, static_cast<const T*>(a1), B, s.pool0, s.pool0, w[1], 3, 2);
    // conv₂, conv₃, conv₄ (each → ReLU) → max-pool
    T* a2 = detail::grow(c.a2, size(B, s.pool1, w[2]));
    conv_forward(ps, 2, p1, a2, B, s.pool1, c);
    T* a3 = detail::grow(c.a3, size(B, s.pool1, w[3]));
    conv_forward(ps, 3, a2, a3, B, s.pool1, c);
    T* a4 = detail::grow(c.a4, size(B, s.pool1, w[4]));
    conv_forward(ps, 4, a3, a4, B, s.pool1, c);
    T* p4 = detail::grow(c.p4, size(B, s.pool2, w[4]));
    std::int32_t* i4 = detail::grow(c.i4, size(B, s.pool2, w[4]));
    kernels::maxpool2d_forward(p4, i4, static_cast<const T*>(a4), B, s.pool1, s.pool1, w[4], 3, 2);
    // adaptive average pool, then NHWC → PyTorch's (c, y, x) flattening
    T* q = detail::grow(c.q, size(B, R, w[4]));
    kernels::adaptive_avgpool2d_forward(q, static_cast<const T*>(p4), B, s.pool2, s.pool2, w[4], R, R);
    to_torch_order(features, q, B, R, w[4]);
    c.B = B;
  }

  // dfeatures [B, out_dim] → parameter gradients (added into ps.grad) and dimages [B, S, S, Cin]
  // += ∂L/∂images (nullptr: not wanted). Reads the cache of the last forward, which it leaves
  // intact (a second backward adds the same gradients again); the images of that forward must
  // still be valid.
  template <class T>
  void backward(ParamSet<T>& ps, const T* dfeatures, AlexNetCache<T>& c, T* dimages = nullptr) const {
    check_params(ps, convs[4].bias, "AlexNet::backward");
    require<ConfigError>(c.B > 0 && c.images, "AlexNet::backward: the cache holds no forward pass");
    require<ShapeError>(dfeatures != nullptr, "AlexNet::backward: dfeatures is null");
    const int B = c.B, R = config.pooled;
    const AlexNetSides s = config.sides();
    const std::array<int, 5>& w = config.widths;
    std::size_t most = 0;
    for (std::size_t n : {size(B, s.conv0, w[0]), size(B, s.pool0, w[1]), size(B, s.pool1, w[2]),
                          size(B, s.pool1, w[3]), size(B, s.pool1, w[4])})
      most = std::max(most, n);
    T* g = detail::grow(c.g0, most);
    T* h = detail::grow(c.g1, most);
    T* dq = detail::grow(c.dq, size(B, R, w[4]));
    from_torch_order(dq, dfeatures, B, R, w[4]);
    // adaptive pool → max-pool → ReLU of conv₄
    zero(g, size(B, s.pool2, w[4]));
    kernels::adaptive_avgpool2d_backward(g, static_cast<const T*>(dq), B, s.pool2, s.pool2, w[4], R, R);
    zero(h, size(B, s.pool1, w[4]));
    kernels::maxpool2d_backward(h, static_cast<const T*>(g), c.i4.data(), B, s.pool1, s.pool1, w[4], 3, 2);
    kernels::relu_backward(h, static_cast<const T*>(h), c.a4.data(), size(B, s.pool1, w[4]));
    // conv₄, conv₃, conv₂ (each after its ReLU's backward)
    zero(g, size(B, s.pool1, w[3]));
    conv_backward(ps, 4, g, h, c.a3.data(), B, s.pool1, c);
    kernels::relu_backward(g, static_cast<const T*>(g), c.a3.data(), size(B, s.pool1, w[3]));
    zero(h, size(B, s.pool1, w[2]));
    conv_backward(ps, 3, h, g, c.a2.data(), B, s.pool1, c);
    kernels::relu_backward(h, static_cast<const T*>(h), c.a2.data(), size(B, s.pool1, w[2]));
    zero(g, size(B, s.pool1, w[1]));
    conv_backward(ps, 2, g, h, c.p1.data(), B, s.pool1, c);
    // max-pool → ReLU → conv₁
    zero(h, size(B, s.pool0, w[1]));
    kernels::maxpool2d_backward(h, static_cast<const T*>(g), c.i1.data(), B, s.pool0, s.pool0, w[1], 3, 2);
    kernels::relu_backward(h, static_cast<const T*>(h), c.a1.data(), size(B, s.pool0, w[1]));
    zero(g, size(B, s.pool0, w[0]));
    conv_backward(ps, 1, g, h, c.p0.data(), B, s.pool0, c);
    // max-pool → ReLU → conv₀
    zero(h, size(B, s.conv0, w[0]));
    kernels::maxpool2d_backward(h, static_cast<const T*>(g), c.i0.data(), B, s.conv0, s.conv0, w[0], 3, 2);
    kernels::relu_backward(h, static_cast<const T*>(h), c.a0.data(), size(B, s.conv0, w[0]));
    conv_backward(ps, 0, dimages, h, c.images, B, config.image_size, c);
  }

 private:
  static std::size_t size(int B, int side, int channels) {
    return std::size_t(B) * std::size_t(side) * std::size_t(side) * std::size_t(channels);
  }
  template <class T>
  static void zero(T* p, std::size_t n) {
    detail::parallel_fill(p, p + n, T(0));
  }
  kernels::Conv2dShape shape(std::size_t i, int B, int side) const {
    const Conv& v = convs[i];
    return {B, side, side, v.in, v.out, v.k, v.stride, v.pad};
  }
  // y = relu(conv_i(x)) for x [B, side, side, in].
  template <class T>
  void conv_forward(const ParamSet<T>& ps, std::size_t i, const T* x, T* y, int B, int side,
                    AlexNetCache<T>& c) const {
    const kernels::Conv2dShape sh = shape(i, B, side);
    kernels::conv2d_forward(y, x, ps.value(convs[i].weight), ps.value(convs[i].bias), sh, c.conv);
    kernels::relu_forward(y, static_cast<const T*>(y), sh.out_size());
  }
  // dx += ∂/∂x (nullptr: not wanted) and the parameter gradients of conv_i, from dy (the gradient
  // of the conv's output, before its ReLU) and the conv's input x.
  template <class T>
  void conv_backward(ParamSet<T>& ps, std::size_t i, T* dx, const T* dy, const T* x, int B, int side,
                     AlexNetCache<T>& c) const {
    kernels::conv2d_backward(dx, ps.grad(convs[i].weight), ps.grad(convs[i].bias), dy, x,
                             static_cast<const T*>(ps.value(convs[i].weight)), shape(i, B, side), c.conv);
  }
  // out[b, c·R² + y·R + x] = q[b, y, x, c] and its inverse.
  template <class T>
  static void to_torch_order(T* out, const T* q, int B, int R, int C) {
    const std::size_t RR = std::size_t(R) * R;
    for (std::size_t b = 0; b < std::size_t(B); ++b)
      for (std::size_t p = 0; p < RR; ++p)
        for (std::size_t ch = 0; ch < std::size_t(C); ++ch) out[(b * C + ch) * RR + p] = q[(b * RR + p) * C + ch];
  }
  template <class T>
  static void from_torch_order(T* q, const T* in, int B, int R, int C) {
    const std::size_t RR = std::size_t(R) * R;
    for (std::size_t b = 0; b < std::size_t(B); ++b)
      for (std::size_t p = 0; p < RR; ++p)
        for (std::size_t ch = 0; ch < std::size_t(C); ++ch) q[(b * RR + p) * C + ch] = in[(b * C + ch) * RR + p];
  }
};

}  // namespace tjepa
