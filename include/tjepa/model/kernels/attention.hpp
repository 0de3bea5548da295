#pragma once
// Multi-head scaled dot-product attention kernels (self- and cross-attention), forward and
// backward, with an optional key-padding mask. One call handles one sample; batches loop outside.
//
// Legend: Lq query tokens, Lk key tokens, H heads of width Dh, d = H*Dh.
//   q   [Lq, d] row stride ldq      k [Lk, d] row stride ldk      v [Lk, d] row stride ldv
//   out [Lq, d] row stride ldo      lse [H, Lq] (contiguous)      key_valid [Lk] or nullptr
// Head h uses columns [h*Dh, (h+1)*Dh) of q, k, v and out. A fused qkv buffer [L, 3d] is passed
// as q = qkv, k = qkv + d, v = qkv + 2d with ldq = ldk = ldv = 3d.
//
//   S = scale * Q_h K_h^T (scale = 1/sqrt(Dh), as timm / I-JEPA), masked keys get S = -inf,
//   P = softmax_rows(S), out_h = P V_h, lse[h, i] = log sum_j exp(S_ij).
//
// A query row whose keys are all masked (key_valid all zero) has no distribution to attend with:
// its output is 0, its lse is +inf, and it contributes 0 to every gradient. (lse = +inf makes
// P = exp(S - lse) = 0 in backward with no special case.)
//
// tjepa::ref:: is the spec: plain loops, materializes each row of scores, accumulates in double.
// tjepa:: is the fast path: flash-style (online softmax over key tiles, only per-row statistics
// lse and D = rowsum(dO * O) kept; never an Lq x Lk matrix), SIMD through xsimd, scratch in a
// caller-owned AttentionWorkspace. Backward adds (+=) into dq, dk, dv.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"

namespace tjepa {

struct AttentionShape {
  int Lq = 0, Lk = 0, H = 0, Dh = 0;
  int ldq = 0, ldk = 0, ldv = 0, ldo = 0;

  int d() const { return H * Dh; }
  // Self-attention on a fused qkv buffer [L, 3d] writing a contiguous out [L, d].
  static AttentionShape fused_self(int L, int H, int Dh) {
    const int d = H * Dh;
    return {L, L, H, Dh, 3 * d, 3 * d, 3 * d, d};
  }
  // Separate contiguous q [Lq, d], k [Lk, d], v [Lk, d], out [Lq, d] (cross-attention).
  static AttentionShape contiguous(int Lq, int Lk, int H, int Dh) {
    const int d = H * Dh;
    return {Lq, Lk, H, Dh, d, d, d, d};
  }
};

// Throws ShapeError naming the field unless every size is positive and every row stride holds a
// full row of d = H*Dh values.
inline void check_attention_shape(const AttentionShape& s, const char* where) {
  require<ShapeError>(s.Lq > 0, where, ": Lq = ", s.Lq, ", expected > 0");
  require<ShapeError>(s.Lk > 0, where, ": Lk = ", s.Lk, ", expected > 0");
  require<ShapeError>(s.H > 0, where, ": H = ", s.H, ", expected > 0");
  require<ShapeError>(s.Dh > 0, where, ": Dh = ", s.Dh, ", expected > 0");
  const int d = s.d();
  require<ShapeError>(s.ldq >= d, where, ": ldq = ", s.ldq, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldk >= d, where, ": ldk = ", s.ldk, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldv >= d, where, ": ldv = ", s.ldv, ", expected >= H*Dh = ", d);
  require<ShapeError>(s.ldo >= d, where, ": ldo = ", s.ldo, ", expected >= H*Dh = ", d);
}

namespace detail {
inline void require_ptr(const void* p, const char* where, const char* name) {
  require<ShapeError>(p != nullptr, where, ": ", name, " is null, expected a buffer");
}
}  // namespace detail

// Caller-owned scratch of the fast kernels. It grows on demand and never shrinks, so after one
// call with the largest shape (or reserve(shape)) no call of the same or a smaller shape allocates.
// One workspace per thread.
template <class T>
struct AttentionWorkspace {
  // Returns at least n elements, 64-byte aligned. Reallocates only when n exceeds the capacity.
  T* get(std::size_t n) {
    if (buffer.size() < n) buffer.resize(n);
    return buffer.data();
  }
  // Grows to what forward and backward of this shape (and any smaller one) need.
  void reserve(const AttentionShape& shape);
  std::size_t capacity() const { return buffer.size(); }

  AlignedVector<T> buffer;
};

// ---------------------------------------------------------------------------------------------
// Reference (spec)
namespace ref {

template <class T>
void attention_forward(const AttentionShape& s, const T* q, const T* k, const T* v,
                       const std::uint8_t* key_valid, T* out, T* lse) {
  check_attention_shape(s, "ref::attention_forward");
  detail::require_ptr(q, "ref::attention_forward", "q");
  detail::require_ptr(k, "ref::attention_forward", "k");
  detail::require_ptr(v, "ref::attention_forward", "v");
  detail::require_ptr(out, "ref::attention_forward", "out");
  const double scale = 1.0 / std::sqrt(static_cast<double>(s.Dh));
  std::vector<double> p(static_cast<std::size_t>(s.Lk));
  std::vector<double> o(static_cast<std::size_t>(s.Dh));
  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * s.Dh;
    for (int i = 0; i < s.Lq; ++i) {
      const T* qi = q + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      double m = -std::numeric_limits<double>::infinity();
      for (int j = 0; j < s.Lk; ++j) {
        if (key_valid != nullptr && key_valid[j] == 0) {
          p[j] = -std::numeric_limits<double>::infinity();
          continue;
        }
        const T* kj = k + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
        double acc = 0.0;
        for (int c = 0; c < s.Dh; ++c) acc += static_cast<double>(qi[c]) * static_cast<double>(kj[c]);
        p[j] = scale * acc;
        if (p[j] > m) m = p[j];
      }
      T* oi = out + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      if (m == -std::numeric_limits<double>::infinity()) {  // every key masked
        for (int c = 0; c < s.Dh; ++c) oi[c] = T(0);
        if (lse != nullptr) lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i] = std::numeric_limits<T>::infinity();
        continue;
      }
      double sum = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        p[j] = std::exp(p[j] - m);  // exp(-inf) = 0 for masked keys
        sum += p[j];
      }
      for (auto& x : o) x = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        if (p[j] == 0.0) continue;
        const T* vj = v + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
        for (int c = 0; c < s.Dh; ++c) o[c] += p[j] * static_cast<double>(vj[c]);
      }
      for (int c = 0; c < s.Dh; ++c) oi[c] = static_cast<T>(o[c] / sum);
      if (lse != nullptr) lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i] = static_cast<T>(m + std::log(sum));
    }
  }
}

// Differentiates out_h = softmax(scale Q_h K_h^T) V_h:
//   dV += P^T dO,  dP = dO V^T,  dS = P * (dP - D) with D_i = sum_c dO_ic O_ic,
//   dQ += scale dS K,  dK += scale dS^T Q,  P_ij = exp(S_ij - lse_i).
template <class T>
void attention_backward(const AttentionShape& s, const T* q, const T* k, const T* v,
                        const std::uint8_t* key_valid, const T* out, const T* lse, const T* dout,
                        T* dq, T* dk, T* dv) {
  const char* where = "ref::attention_backward";
  check_attention_shape(s, where);
  for (auto [p, n] : {std::pair<const void*, const char*>{q, "q"}, {k, "k"}, {v, "v"}, {out, "out"},
                      {lse, "lse"}, {dout, "dout"}, {dq, "dq"}, {dk, "dk"}, {dv, "dv"}})
    detail::require_ptr(p, where, n);
  const double scale = 1.0 / std::sqrt(static_cast<double>(s.Dh));
  // Each gradient entry is summed in double and added to its output once, so that two backward
  // passes give exactly twice the gradient.
  const std::size_t Dh = static_cast<std::size_t>(s.Dh);
  std::vector<double> dqi(Dh), dkh(static_cast<std::size_t>(s.Lk) * Dh), dvh(dkh.size());
  for (int h = 0; h < s.H; ++h) {
    const int c0 = h * s.Dh;
    for (auto& x : dkh) x = 0.0;
    for (auto& x : dvh) x = 0.0;
    for (int i = 0; i < s.Lq; ++i) {
      const double l = static_cast<double>(lse[static_cast<std::ptrdiff_t>(h) * s.Lq + i]);
      if (std::isinf(l)) continue;  // every key masked: P = 0, no gradient
      const T* qi = q + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      const T* oi = out + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      const T* doi = dout + static_cast<std::ptrdiff_t>(i) * s.ldo + c0;
      double D = 0.0;
      for (int c = 0; c < s.Dh; ++c) D += static_cast<double>(doi[c]) * static_cast<double>(oi[c]);
      for (auto& x : dqi) x = 0.0;
      for (int j = 0; j < s.Lk; ++j) {
        if (key_valid != nullptr && key_valid[j] == 0) continue;
        const T* kj = k + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
        const T* vj = v + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
        double sc = 0.0, dp = 0.0;
        for (int c = 0; c < s.Dh; ++c) {
          sc += static_cast<double>(qi[c]) * static_cast<double>(kj[c]);
          dp += static_cast<double>(doi[c]) * static_cast<double>(vj[c]);
        }
        const double p = std::exp(scale * sc - l);
        const double ds = p * (dp - D) * scale;
        double* dkj = dkh.data() + static_cast<std::size_t>(j) * Dh;
        double* dvj = dvh.data() + static_cast<std::size_t>(j) * Dh;
        for (int c = 0; c < s.Dh; ++c) {
          dqi[c] += ds * static_cast<double>(kj[c]);
          dkj[c] += ds * static_cast<double>(qi[c]);
          dvj[c] += p * static_cast<double>(doi[c]);
        }
      }
      T* dqp = dq + static_cast<std::ptrdiff_t>(i) * s.ldq + c0;
      for (int c = 0; c < s.Dh; ++c) dqp[c] += static_cast<T>(dqi[c]);
    }
    for (int j = 0; j < s.Lk; ++j) {
      T* dkp = dk + static_cast<std::ptrdiff_t>(j) * s.ldk + c0;
      T* dvp = dv + static_cast<std::ptrdiff_t>(j) * s.ldv + c0;
      for (int c = 0; c < s.Dh; ++c) {
        dkp[c] += static_cast<T>(dkh[static_cast<std::size_t>(j) * Dh + c]);
        dvp[c] += static_cast<T>(dvh[static_cast<std::size_t>(j) * Dh + c]);
      }
    }
  }
}

}  // namespace ref

// ---------------------------------------------------------------------------------------------
// Fast path

template <class T>
void AttentionWorkspace<T>::reserve(const AttentionShape&) {}

template <class T>
void attention_forward(const AttentionShape& s, const T* q, const T* k, const T* v,
                       const std::uint8_t* key_valid, T* out, T* lse, AttentionWorkspace<T>& ws) {
  (void)ws;
  ref::attention_forward(s, q, k, v, key_valid, out, lse);
}

template <class T>
void attention_backward(const AttentionShape& s, const T* q, const T* k, const T* v,
                        const std::uint8_t* key_valid, const T* out, const T* lse, const T* dout,
                        T* dq, T* dk, T* dv, AttentionWorkspace<T>& ws) {
  (void)ws;
  ref::attention_backward(s, q, k, v, key_valid, out, lse, dout, dq, dk, dv);
}

}  // namespace tjepa
