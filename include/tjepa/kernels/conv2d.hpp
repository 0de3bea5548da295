#pragma once
// 2-D convolution, ReLU, max-pooling and adaptive average pooling on NHWC activations: the pieces
// of torchvision's AlexNet trunk (baselines/alexnet.hpp).
//
// Activations are [B, H, W, C] row-major (C fastest). A convolution's weight keeps PyTorch's
// layout [O, C, kh, kw] and its bias [O], so a checkpoint maps one-to-one. With a square kernel k,
// stride s and zero padding p:
//
//   out[b, y, x, o] = bias[o] + Σ_{c, i, j} in[b, y·s − p + i, x·s − p + j, c] · w[o, c, i, j]
//   out [B, Ho, Wo, O],  Ho = ⌊(H + 2p − k)/s⌋ + 1,  Wo likewise
//
// Fast path (im2col + GEMM): each output pixel's receptive field becomes one row of k·k·C values
// in (i, j, c) order, copied as contiguous runs of C values (zeros where the window leaves the
// input); the weight is permuted to [O, kh, kw, C], so the convolution is the product
// out[rows, O] = col[rows, k·k·C] · w'ᵀ + bias of linear.hpp's linear_forward (float through the
// packed xsimd GEMM, double through Eigen's kernels). Its output rows are the pixels of
// [B, Ho, Wo, O] in order: NHWC in, NHWC out, no transpose. The B·Ho·Wo rows are processed in
// chunks of at most Conv2dScratch::max_col im2col values, so the buffer stays bounded; a 1 × 1
// kernel with stride 1 and no padding reads its input as the im2col matrix. Nothing allocates
// after warm-up (Conv2dScratch grows and is reused).
//
// Backward recomputes im2col chunk by chunk and runs linear_backward on it; the column gradient
// is scattered back into din (col2im), each sample by one thread in row order, so the result does
// not depend on the thread count or the chunk size. Like every kernel of the library, backward
// ADDS into its gradients (din, dw, db): one zero_grad serves a whole step.
//
// Max-pooling (no padding, floor mode: nn.MaxPool2d(k, s)) records per output value the position
// y·W + x of its maximum within the sample's plane (PyTorch's indices); ties keep the first in
// (i, j) scan order and a NaN wins, as PyTorch's CPU kernel. Adaptive average pooling uses
// PyTorch's bins: output i averages input rows [⌊i·H/Ho⌋, ⌈(i + 1)·H/Ho⌉), likewise columns; bins
// overlap or repeat when H is not a multiple of Ho or is smaller.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/kernels/linear.hpp"

namespace tjepa::kernels {

// The geometry of one convolution: input [B, H, W, C], weight [O, C, k, k], stride, padding.
struct Conv2dShape {
  int B = 0, H = 0, W = 0, C = 0, O = 0, k = 1, stride = 1, pad = 0;

  // Output side: ⌊(H + 2 pad − k)/stride⌋ + 1, or 0 where the padded input is smaller than k.
  int Ho() const { return out_side(H); }
  int Wo() const { return out_side(W); }
  // Values of one im2col row (k·k·C), rows (B·Ho·Wo), and the tensors' sizes.
  int patch() const { return k * k * C; }
  std::size_t rows() const { return std::size_t(B) * std::size_t(Ho()) * std::size_t(Wo()); }
  std::size_t in_size() const { return std::size_t(B) * std::size_t(H) * std::size_t(W) * std::size_t(C); }
  std::size_t out_size() const { return rows() * std::size_t(O); }
  std::size_t weight_size() const { return std::size_t(O) * std::size_t(patch()); }

  // Throws ShapeError naming the values unless every size is positive, the padding is not
  // negative and the output has at least one pixel.
  void validate(const char* where = "conv2d") const {
    require<ShapeError>(B > 0 && H > 0 && W > 0 && C > 0 && O > 0, where, ": B ", B, ", H ", H, ", W ", W, ", C ",
                        C, ", O ", O, ", expected all > 0");
    require<ShapeError>(k > 0 && stride > 0 && pad >= 0, where, ": kernel ", k, ", stride ", stride, ", padding ",
                        pad, ", expected kernel > 0, stride > 0, padding >= 0");
    require<ShapeError>(std::int64_t(k) * k * C <= std::numeric_limits<int>::max() / 2, where, ": kernel ", k,
                        " with ", C, " channels, too large");
    require<ShapeError>(Ho() >= 1 && Wo() >= 1, where, ": input ", H, "x", W, " with padding ", pad,
                        " is smaller than the kernel ", k, " (output ", Ho(), "x", Wo(), ")");
  }

 private:
  int out_side(int n) const {
    const std::int64_t span = std::int64_t(n) + 2 * std::int64_t(pad) - k;
    return span < 0 || stride <= 0 ? 0 : int(span / stride + 1);
  }
};

// Buffers of conv2d_forward and conv2d_backward, grown on first use and reused: one scratch may
// serve convolutions of any shapes (the largest sets its size).
template <class T>
struct Conv2dScratch {
  std::size_t max_col = std::size_t(1) << 22;  // im2col values per chunk (at least one row)
  AlignedVector<T> col, dcol;                   // [chunk rows, k·k·C]
  AlignedVector<T> wperm, dwperm;               // [O, k, k, C]
};

namespace ref {
// Scalar references, the spec for the fast path: plain loops over PyTorch's weight layout.
template <class T>
void conv2d_forward(T* out, const T* in, const T* w, const T* b, const Conv2dShape& s) {
  s.validate("ref::conv2d_forward");
  const int Ho = s.Ho(), Wo = s.Wo();
  for (int n = 0; n < s.B; ++n)
    for (int y = 0; y < Ho; ++y)
      for (int x = 0; x < Wo; ++x)
        for (int o = 0; o < s.O; ++o) {
          T acc = b ? b[o] : T(0);
          for (int c = 0; c < s.C; ++c)
            for (int i = 0; i < s.k; ++i)
              for (int j = 0; j < s.k; ++j) {
                const int iy = y * s.stride - s.pad + i, ix = x * s.stride - s.pad + j;
                if (iy < 0 || iy >= s.H || ix < 0 || ix >= s.W) continue;
                acc += in[((std::size_t(n) * s.H + iy) * s.W + ix) * s.C + c] *
                       w[((std::size_t(o) * s.C + c) * s.k + i) * s.k + j];
              }
          out[((std::size_t(n) * Ho + y) * Wo + x) * s.O + o] = acc;
        }
}
// din += ∂/∂in, dw += ∂/∂w, db += ∂/∂b of Σ dout ⊙ out; din and db may be nullptr.
template <class T>
void conv2d_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w, const Conv2dShape& s) {
  s.validate("ref::conv2d_backward");
  const int Ho = s.Ho(), Wo = s.Wo();
  for (int n = 0; n < s.B; ++n)
    for (int y = 0; y < Ho; ++y)
      for (int x = 0; x < Wo; ++x)
        for (int o = 0; o < s.O; ++o) {
          const T g = dout[((std::size_t(n) * Ho + y) * Wo + x) * s.O + o];
          if (db) db[o] += g;
          for (int c = 0; c < s.C; ++c)
            for (int i = 0; i < s.k; ++i)
              for (int j = 0; j < s.k; ++j) {
                const int iy = y * s.stride - s.pad + i, ix = x * s.stride - s.pad + j;
                if (iy < 0 || iy >= s.H || ix < 0 || ix >= s.W) continue;
                const std::size_t xi = ((std::size_t(n) * s.H + iy) * s.W + ix) * s.C + c;
                const std::size_t wi = ((std::size_t(o) * s.C + c) * s.k + i) * s.k + j;
                if (din) din[xi] += g * w[wi];
                if (dw) dw[wi] += g * in[xi];
              }
        }
}
}  // namespace ref

}  // namespace tjepa::kernels

namespace tjepa::detail {

// The valid kernel columns [j0, j1) of a window whose first input column is x0 (may be empty).
inline void conv_valid_range(int x0, int k, int W, int& j0, int& j1) {
  j0 = std::max(0, -x0);
  j1 = std::min(k, W - x0);
}

// One im2col row: the receptive field of output pixel (y, x) of sample `in` [H, W, C], in
// (i, j, c) order, zeros outside the input.
template <class T>
void im2col_row(T* dst, const T* in, int y, int x, const kernels::Conv2dShape& s) {
  const int C = s.C, k = s.k, y0 = y * s.stride - s.pad, x0 = x * s.stride - s.pad;
  int j0, j1;
  conv_valid_range(x0, k, s.W, j0, j1);
  const std::size_t run = std::size_t(k) * C;
  for (int i = 0; i < k; ++i) {
    T* d = dst + std::size_t(i) * run;
    const int iy = y0 + i;
    if (iy < 0 || iy >= s.H || j1 <= j0) {
      std::fill(d, d + run, T(0));
      continue;
    }
    std::fill(d, d + std::size_t(j0) * C, T(0));
    const T* src = in + (std::size_t(iy) * s.W + std::size_t(x0 + j0)) * C;
    std::copy(src, src + std::size_t(j1 - j0) * C, d + std::size_t(j0) * C);
    std::fill(d + std::size_t(j1) * C, d + run, T(0));
  }
}

// col2im of one row: din (sample [H, W, C]) += the row's values at their input positions.
template <class T>
void col2im_row(T* din, const T* src, int y, int x, const kernels::Conv2dShape& s) {
  const int C = s.C, k = s.k, y0 = y * s.stride - s.pad, x0 = x * s.stride - s.pad;
  int j0, j1;
  conv_valid_range(x0, k, s.W, j0, j1);
  if (j1 <= j0) return;
  const std::size_t run = std::size_t(k) * C, n = std::size_t(j1 - j0) * C;
  for (int i = 0; i < k; ++i) {
    const int iy = y0 + i;
    if (iy < 0 || iy >= s.H) continue;
    const T* g = src + std::size_t(i) * run + std::size_t(j0) * C;
    T* d = din + (std::size_t(iy) * s.W + std::size_t(x0 + j0)) * C;
    for (std::size_t e = 0; e < n; ++e) d[e] += g[e];
  }
}

// Rows [r0, r0 + M) of the im2col matrix of in [B, H, W, C] into col [M, k·k·C], rows over the
// threads.
template <class T>
void im2col_rows(T* col, const T* in, std::size_t r0, int M, const kernels::Conv2dShape& s) {
  const int Ho = s.Ho(), Wo = s.Wo(), K = s.patch();
  const std::size_t plane = std::size_t(Ho) * Wo, sample = std::size_t(s.H) * s.W * s.C;
  [[maybe_unused]] const bool par = std::size_t(M) * std::size_t(K) > parallel_grain;
  TJEPA_OMP(omp parallel for schedule(static) if (par))
  for (int m = 0; m < M; ++m) {
    const std::size_t r = r0 + std::size_t(m), n = r / plane, p = r % plane;
    im2col_row(col + std::size_t(m) * K, in + n * sample, int(p / Wo), int(p % Wo), s);
  }
}

// din [B, H, W, C] += col2im of dcol [M, k·k·C] (rows [r0, r0 + M)): the samples of the chunk over
// the threads, each sample's rows by one thread in order.
template <class T>
void col2im_rows(T* din, const T* dcol, std::size_t r0, int M, const kernels::Conv2dShape& s) {
  const int Ho = s.Ho(), Wo = s.Wo(), K = s.patch();
  const std::size_t plane = std::size_t(Ho) * Wo, sample = std::size_t(s.H) * s.W * s.C;
  const std::size_t r1 = r0 + std::size_t(M), n0 = r0 / plane, n1 = (r1 - 1) / plane + 1;
  [[maybe_unused]] const bool par = n1 - n0 > 1 && std::size_t(M) * std::size_t(K) > parallel_grain;
  TJEPA_OMP(omp parallel for schedule(dynamic, 1) if (par))
  for (std::ptrdiff_t q = std::ptrdiff_t(n0); q < std::ptrdiff_t(n1); ++q) {
    const std::size_t n = std::size_t(q);
    const std::size_t a = std::max(r0, n * plane), e = std::min(r1, (n + 1) * plane);
    for (std::size_t r = a; r < e; ++r) {
      const std::size_t p = r - n * plane;
      col2im_row(din + n * sample, dcol + (r - r0) * K, int(p / Wo), int(p % Wo), s);
    }
  }
}

// w [O, C, k, k] → wp [O, k, k, C] (the im2col row order).
template <class T>
void conv_permute_weight(T* wp, const T* w, const kernels::Conv2dShape& s) {
  const int C = s.C, kk = s.k * s.k;
  for (int o = 0; o < s.O; ++o)
    for (int c = 0; c < C; ++c)
      for (int q = 0; q < kk; ++q)
        wp[(std::size_t(o) * kk + q) * C + c] = w[(std::size_t(o) * C + c) * kk + q];
}
// dw [O, C, k, k] += dwp [O, k, k, C].
template <class T>
void conv_add_unpermuted(T* dw, const T* dwp, const kernels::Conv2dShape& s) {
  const int C = s.C, kk = s.k * s.k;
  for (int o = 0; o < s.O; ++o)
    for (int c = 0; c < C; ++c)
      for (int q = 0; q < kk; ++q)
        dw[(std::size_t(o) * C + c) * kk + q] += dwp[(std::size_t(o) * kk + q) * C + c];
}

inline bool conv_is_pointwise(const kernels::Conv2dShape& s) { return s.k == 1 && s.stride == 1 && s.pad == 0; }
// Rows per chunk: at most max_col im2col values, at least one row.
inline int conv_chunk_rows(const kernels::Conv2dShape& s, std::size_t max_col) {
  const std::size_t rows = std::max<std::size_t>(1, max_col / std::size_t(s.patch()));
  return int(std::min({rows, s.rows(), std::size_t(std::numeric_limits<int>::max() / 2)}));
}

// Throws ShapeError unless a pooling's sizes are positive and the input holds one window.
inline void pool_check(const char* where, int B, int H, int W, int C, int k, int stride) {
  require<ShapeError>(B > 0 && H > 0 && W > 0 && C > 0 && k > 0 && stride > 0, where, ": B ", B, ", H ", H, ", W ",
                      W, ", C ", C, ", kernel ", k, ", stride ", stride, ", expected all > 0");
  require<ShapeError>(H >= k && W >= k, where, ": input ", H, "x", W, " is smaller than the window ", k);
  require<ShapeError>(std::int64_t(H) * W <= std::numeric_limits<std::int32_t>::max(), where, ": input ", H, "x", W,
                      " has too many positions for int32 indices");
}

}  // namespace tjepa::detail

namespace tjepa::kernels {

// out [B, Ho, Wo, O] = conv(in [B, H, W, C], w [O, C, k, k]) + b [O]; b may be nullptr.
template <class T>
void conv2d_forward(T* out, const T* in, const T* w, const T* b, const Conv2dShape& s, Conv2dScratch<T>& scratch) {
  s.validate("conv2d_forward");
  const int K = s.patch(), O = s.O;
  T* wp = detail::grow(scratch.wperm, s.weight_size());
  detail::conv_permute_weight(wp, w, s);
  const std::size_t rows = s.rows();
  if (detail::conv_is_pointwise(s)) {
    // A 1 × 1 kernel: the input is the im2col matrix. Chunks keep each product's rows an int.
    const std::size_t step = std::size_t(std::numeric_limits<int>::max() / 2) / std::size_t(std::max(K, O));
    for (std::size_t r0 = 0; r0 < rows; r0 += step) {
      const int M = int(std::min(step, rows - r0));
      linear_forward(out + r0 * O, in + r0 * K, wp, b, M, K, O);
    }
    return;
  }
  const int chunk = detail::conv_chunk_rows(s, scratch.max_col);
  T* col = detail::grow(scratch.col, std::size_t(chunk) * K);
  for (std::size_t r0 = 0; r0 < rows; r0 += std::size_t(chunk)) {
    const int M = int(std::min<std::size_t>(std::size_t(chunk), rows - r0));
    detail::im2col_rows(col, in, r0, M, s);
    linear_forward(out + r0 * O, static_cast<const T*>(col), static_cast<const T*>(wp), b, M, K, O);
  }
}

// Differentiates out = conv(in, w) + b given dout [B, Ho, Wo, O]:
//   din [B, H, W, C] += ∂/∂in,  dw [O, C, k, k] += ∂/∂w,  db [O] += Σ_rows dout.
// Any of din, dw, db may be nullptr (not wanted).
template <class T>
void conv2d_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w, const Conv2dShape& s,
                     Conv2dScratch<T>& scratch) {
  s.validate("conv2d_backward");
  const int K = s.patch(), O = s.O;
  const std::size_t wsize = s.weight_size();
  T* wp = nullptr;
  if (din) {
    wp = detail::grow(scratch.wperm, wsize);
    detail::conv_permute_weight(wp, w, s);
  }
  T* dwp = nullptr;
  if (dw) {
    dwp = detail::grow(scratch.dwperm, wsize);
    std::fill(dwp, dwp + wsize, T(0));
  }
  const std::size_t rows = s.rows();
  if (detail::conv_is_pointwise(s)) {
    const std::size_t step = std::size_t(std::numeric_limits<int>::max() / 2) / std::size_t(std::max(K, O));
    for (std::size_t r0 = 0; r0 < rows; r0 += step) {
      const int M = int(std::min(step, rows - r0));
      linear_backward(din ? din + r0 * K : static_cast<T*>(nullptr), dwp, db, dout + r0 * O, in + r0 * K,
                      static_cast<const T*>(wp), M, K, O, true);
    }
  } else if (din || dw) {
    const int chunk = detail::conv_chunk_rows(s, scratch.max_col);
    T* col = dw ? detail::grow(scratch.col, std::size_t(chunk) * K) : nullptr;
    T* dcol = din ? detail::grow(scratch.dcol, std::size_t(chunk) * K) : nullptr;
    for (std::size_t r0 = 0; r0 < rows; r0 += std::size_t(chunk)) {
      const int M = int(std::min<std::size_t>(std::size_t(chunk), rows - r0));
      if (dw) detail::im2col_rows(col, in, r0, M, s);
      linear_backward(dcol, dwp, db, dout + r0 * O, static_cast<const T*>(col), static_cast<const T*>(wp), M, K, O,
                      false);
      if (din) detail::col2im_rows(din, static_cast<const T*>(dcol), r0, M, s);
    }
  } else if (db) {
    const std::size_t step = std::size_t(std::numeric_limits<int>::max() / 2) / std::size_t(O);
    for (std::size_t r0 = 0; r0 < rows; r0 += step)
      detail::add_column_sums(db, dout + r0 * O, int(std::min(step, rows - r0)), O);
  }
  if (dw) detail::conv_add_unpermuted(dw, static_cast<const T*>(dwp), s);
}

// y[n] = max(x, 0) (PyTorch's relu: a NaN stays NaN); y may alias x.
template <class T>
void relu_forward(T* y, const T* x, std::size_t n) {
  TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(n); ++i) y[i] = x[i] < T(0) ? T(0) : x[i];
}

// dx[n] = dy where y > 0, else 0 (overwritten, not added); dx may alias dy.
template <class T>
void relu_backward(T* dx, const T* dy, const T* y, std::size_t n) {
  TJEPA_OMP(omp parallel for schedule(static) if (n > detail::parallel_grain))
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(n); ++i) dx[i] = y[i] > T(0) ? dy[i] : T(0);
}

// Output side of a k-window pooling with the stride, no padding, floor mode (0 when n < k).
inline int pool_out_side(int n, int k, int stride) { return n < k || stride <= 0 ? 0 : (n - k) / stride + 1; }

// out [B, Ho, Wo, C] = max over each k × k window (stride, no padding, floor mode) of in
// [B, H, W, C]; argmax [B, Ho, Wo, C] (may be nullptr: inference) gets each maximum's position
// y·W + x within its sample's plane. Ties keep the first in scan order; a NaN wins.
template <class T>
void maxpool2d_forward(T* out, std::int32_t* argmax, const T* in, int B, int H, int W, int C, int k, int stride) {
  detail::pool_check("maxpool2d_forward", B, H, W, C, k, stride);
  const int Ho = pool_out_side(H, k, stride), Wo = pool_out_side(W, k, stride);
  const std::size_t lines = std::size_t(B) * Ho;
  [[maybe_unused]] const bool par = lines * Wo * C * std::size_t(k) * k > detail::parallel_grain;
  TJEPA_OMP(omp parallel for schedule(static) if (par))
  for (std::ptrdiff_t l = 0; l < std::ptrdiff_t(lines); ++l) {
    const int n = int(l / Ho), y = int(l % Ho);
    const T* src = in + std::size_t(n) * H * W * C;
    for (int x = 0; x < Wo; ++x) {
      const std::size_t o = (std::size_t(l) * Wo + x) * C;
      T* best = out + o;
      const int y0 = y * stride, x0 = x * stride;
      const T* first = src + (std::size_t(y0) * W + x0) * C;
      std::copy(first, first + C, best);
      if (argmax) {
        std::int32_t* arg = argmax + o;
        std::fill(arg, arg + C, std::int32_t(y0 * W + x0));
        for (int i = 0; i < k; ++i)
          for (int j = (i == 0 ? 1 : 0); j < k; ++j) {
            const std::int32_t pos = std::int32_t((y0 + i) * W + x0 + j);
            const T* v = src + std::size_t(pos) * C;
            for (int c = 0; c < C; ++c)
              if (v[c] > best[c] || std::isnan(v[c])) {
                best[c] = v[c];
                arg[c] = pos;
              }
          }
      } else {
        for (int i = 0; i < k; ++i)
          for (int j = (i == 0 ? 1 : 0); j < k; ++j) {
            const T* v = src + (std::size_t(y0 + i) * W + x0 + j) * C;
            for (int c = 0; c < C; ++c)
              if (v[c] > best[c] || std::isnan(v[c])) best[c] = v[c];
          }
      }
    }
  }
}

// din [B, H, W, C] += dout [B, Ho, Wo, C] at the positions argmax recorded; samples over the
// threads.
template <class T>
void maxpool2d_backward(T* din, const T* dout, const std::int32_t* argmax, int B, int H, int W, int C, int k,
                        int stride) {
  detail::pool_check("maxpool2d_backward", B, H, W, C, k, stride);
  const int Ho = pool_out_side(H, k, stride), Wo = pool_out_side(W, k, stride);
  const std::size_t per = std::size_t(Ho) * Wo * C, sample = std::size_t(H) * W * C;
  [[maybe_unused]] const bool par = B > 1 && per * B > detail::parallel_grain / 4;
  TJEPA_OMP(omp parallel for schedule(static) if (par))
  for (int n = 0; n < B; ++n) {
    T* d = din + std::size_t(n) * sample;
    const T* g = dout + std::size_t(n) * per;
    const std::int32_t* a = argmax + std::size_t(n) * per;
    for (std::size_t p = 0; p < per; p += std::size_t(C))
      for (int c = 0; c < C; ++c) d[std::size_t(a[p + c]) * C + c] += g[p + c];
  }
}

// The input rows (or columns) [start, end) of adaptive pooling's output i: PyTorch's
// start = ⌊i·n/out⌋, end = ⌈(i + 1)·n/out⌉.
inline int adaptive_start(int i, int n, int out) { return int(std::int64_t(i) * n / out); }
inline int adaptive_end(int i, int n, int out) { return int((std::int64_t(i + 1) * n + out - 1) / out); }

// out [B, Ho, Wo, C] = the mean of each adaptive bin of in [B, H, W, C] (nn.AdaptiveAvgPool2d).
template <class T>
void adaptive_avgpool2d_forward(T* out, const T* in, int B, int H, int W, int C, int Ho, int Wo) {
  require<ShapeError>(B > 0 && H > 0 && W > 0 && C > 0 && Ho > 0 && Wo > 0, "adaptive_avgpool2d_forward: B ", B,
                      ", H ", H, ", W ", W, ", C ", C, ", output ", Ho, "x", Wo, ", expected all > 0");
  const std::size_t lines = std::size_t(B) * Ho;
  TJEPA_OMP(omp parallel for schedule(static) if (lines * Wo * C > detail::parallel_grain))
  for (std::ptrdiff_t l = 0; l < std::ptrdiff_t(lines); ++l) {
    const int n = int(l / Ho), y = int(l % Ho);
    const int y0 = adaptive_start(y, H, Ho), y1 = adaptive_end(y, H, Ho);
    const T* src = in + std::size_t(n) * H * W * C;
    for (int x = 0; x < Wo; ++x) {
      const int x0 = adaptive_start(x, W, Wo), x1 = adaptive_end(x, W, Wo);
      T* o = out + (std::size_t(l) * Wo + x) * C;
      std::fill(o, o + C, T(0));
      for (int i = y0; i < y1; ++i)
        for (int j = x0; j < x1; ++j) {
          const T* v = src + (std::size_t(i) * W + j) * C;
          for (int c = 0; c < C; ++c) o[c] += v[c];
        }
      const T count = T((y1 - y0) * (x1 - x0));
      for (int c = 0; c < C; ++c) o[c] /= count;
    }
  }
}

// din [B, H, W, C] += dout / |bin| spread over each bin; samples over the threads.
template <class T>
void adaptive_avgpool2d_backward(T* din, const T* dout, int B, int H, int W, int C, int Ho, int Wo) {
  require<ShapeError>(B > 0 && H > 0 && W > 0 && C > 0 && Ho > 0 && Wo > 0, "adaptive_avgpool2d_backward: B ", B,
                      ", H ", H, ", W ", W, ", C ", C, ", output ", Ho, "x", Wo, ", expected all > 0");
  const std::size_t per = std::size_t(Ho) * Wo * C, sample = std::size_t(H) * W * C;
  TJEPA_OMP(omp parallel for schedule(static) if (B > 1 && per * B > detail::parallel_grain / 4))
  for (int n = 0; n < B; ++n) {
    T* d = din + std::size_t(n) * sample;
    for (int y = 0; y < Ho; ++y) {
      const int y0 = adaptive_start(y, H, Ho), y1 = adaptive_end(y, H, Ho);
      for (int x = 0; x < Wo; ++x) {
        const int x0 = adaptive_start(x, W, Wo), x1 = adaptive_end(x, W, Wo);
        const T count = T((y1 - y0) * (x1 - x0));
        const T* g = dout + std::size_t(n) * per + (std::size_t(y) * Wo + x) * C;
        for (int i = y0; i < y1; ++i)
          for (int j = x0; j < x1; ++j) {
            T* v = d + (std::size_t(i) * W + j) * C;
            for (int c = 0; c < C; ++c) v[c] += g[c] / count;
          }
      }
    }
  }
}

}  // namespace tjepa::kernels
