#pragma once
// Linear layer on a batch of rows: out[M, N] = in[M, K] · w[N, K]ᵀ + b[N].
//
// w is stored PyTorch-style [out, in]. A [B, L, C] activation is a [B·L, C] matrix, so every
// token-wise layer is one large GEMM: float through the packed xsimd GEMM of detail/sgemm.hpp
// (bias, residual add and GELU fused into its epilogue), double (gradient checks) through Eigen's
// packed kernels (detail/gemm.hpp). Neither allocates after warm-up; rows are split over the
// OpenMP threads. Backward ADDS into its gradients (llm.c style): one zero_grad serves a whole step.
#include <algorithm>
#include <cstddef>
#include <type_traits>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/eigen.hpp"
#include "tjepa/kernels/detail/bgemm.hpp"
#include "tjepa/kernels/detail/gemm.hpp"
#include "tjepa/kernels/detail/sgemm.hpp"
#include "tjepa/kernels/gelu.hpp"

namespace tjepa::kernels {

namespace ref {
// Scalar reference, the spec for the fast path.
template <class T>
void linear_forward(T* out, const T* in, const T* w, const T* b, int M, int K, int N) {
  for (int m = 0; m < M; ++m)
    for (int n = 0; n < N; ++n) {
      T s = b ? b[n] : T(0);
      for (int k = 0; k < K; ++k) s += in[std::size_t(m) * K + k] * w[std::size_t(n) * K + k];
      out[std::size_t(m) * N + n] = s;
    }
}
template <class T>
void linear_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w, int M, int K,
                     int N) {
  for (int m = 0; m < M; ++m)
    for (int n = 0; n < N; ++n) {
      const T g = dout[std::size_t(m) * N + n];
      if (db) db[n] += g;
      for (int k = 0; k < K; ++k) {
        if (din) din[std::size_t(m) * K + k] += g * w[std::size_t(n) * K + k];
        if (dw) dw[std::size_t(n) * K + k] += g * in[std::size_t(m) * K + k];
      }
    }
}
}  // namespace ref

// How a forward product reads its weight: in which precision (Precision::bf16 where the build has
// AVX512-BF16, else fp32: bgemm::resolve), and packed beforehand for it (PackedWeights) or, with
// packed = nullptr, packed by the product itself. double ignores it (Eigen's path).
struct WeightPlan {
  Precision precision = Precision::fp32;
  const void* packed = nullptr;  // float panels (fp32) or bf16 pairs (bgemm::pack)
};

}  // namespace tjepa::kernels

namespace tjepa::detail {
inline const std::uint32_t* bf16_panels(const void* p) { return static_cast<const std::uint32_t*>(p); }
inline const float* fp32_panels(const void* p) { return static_cast<const float*>(p); }

// A weight w [out, in] packed for products in precision p (resolved): the floats it takes, and
// the packing into dst (bf16 pairs are 32-bit words, kept in float storage).
inline std::size_t packed_weight_size(Precision p, int out, int in) {
  return p == Precision::bf16 ? bgemm::packed_size(out, in) : sgemm::packed_size(out, in);
}
// The packing's unit of work is a panel of NR outputs (the same NR in both precisions), so that
// threads can share it.
inline int weight_panels(int out) { return (out + sgemm::NR - 1) / sgemm::NR; }
inline void pack_weight_panel(float* dst, Precision p, const float* w, int out, int in, int panel) {
  if (p == Precision::bf16)
    bgemm::pack_whole_panel(reinterpret_cast<std::uint32_t*>(dst), w, in, sgemm::Order::col_major, in, out, panel);
  else
    sgemm::pack_panel(dst, w, in, sgemm::Order::col_major, in, out, panel, 0, in);
}
inline void pack_weight(float* dst, Precision p, const float* w, int out, int in) {
  for (int q = 0; q < weight_panels(out); ++q) pack_weight_panel(dst, p, w, out, in, q);
}
// sgemm::gemm's product in precision p: bgemm::gemm for bf16 (the float GEMM without AVX512-BF16).
inline void gemm(Precision p, int rows, int cols, int depth, const float* A, std::ptrdiff_t lda, sgemm::Order a_order,
                 const float* B, std::ptrdiff_t ldb, sgemm::Order b_order, float* C, std::ptrdiff_t ldc,
                 const sgemm::Epilogue& e = {}) {
  if (bgemm::resolve(p) == Precision::bf16)
    bgemm::gemm(rows, cols, depth, A, lda, a_order, B, ldb, b_order, C, ldc, e);
  else
    sgemm::gemm(rows, cols, depth, A, lda, a_order, B, ldb, b_order, C, ldc, e);
}

// Rows [0, rows) of C[rows, cols] = A[rows, depth] · B per e, from B packed in precision p.
inline void compute_rows(Precision p, int rows, int cols, int depth, const float* A, const void* packed, float* C,
                         const sgemm::Epilogue& e) {
  using sgemm::Order;
#if TJEPA_BF16_NATIVE
  if (p == Precision::bf16) {
    bgemm::compute_rows(0, rows, cols, depth, A, depth, Order::row_major, bf16_panels(packed), C, cols, e);
    return;
  }
#endif
  (void)p;
  sgemm::compute_rows(0, rows, cols, depth, A, depth, Order::row_major, fp32_panels(packed), C, cols, e);
}

// out[M, N] = in[M, K] · wᵀ through the GEMM of the plan's precision with epilogue e, from w
// packed beforehand when plan.packed is not nullptr.
inline void forward_gemm(float* out, const float* in, const float* w, kernels::WeightPlan plan, int M, int K, int N,
                         const sgemm::Epilogue& e) {
  using sgemm::Order;
  if (!plan.packed)
    gemm(plan.precision, M, N, K, in, K, Order::row_major, w, K, Order::col_major, out, N, e);
  else if (bgemm::resolve(plan.precision) == Precision::bf16)
    bgemm::gemm_packed(M, N, K, in, K, Order::row_major, bf16_panels(plan.packed), out, N, e);
  else
    sgemm::gemm_packed(M, N, K, in, K, Order::row_major, fp32_panels(plan.packed), out, N, e);
}
}  // namespace tjepa::detail

namespace tjepa::kernels {

// Weights packed once for the GEMMs (detail/sgemm.hpp, detail/bgemm.hpp) and reused by later
// products. Every forward product otherwise packs its weight again (a transposing copy of the
// weight per call); inference on weights that do not change (Workspace::frozen_weights) skips
// that. Keyed by the weight's address and precision: clear() when the values change. keep = false
// packs nothing and only carries the precision (each product then packs per call). Nothing is
// packed for double.
template <class T>
class PackedWeights {
 public:
  Precision precision = Precision::fp32;
  bool keep = true;

  // w [out, in] as the products read it; packed on the first call for this w and precision.
  WeightPlan get(const T* w, int out, int in) {
    const Precision p = detail::bgemm::resolve(precision);
    if constexpr (!std::is_same_v<T, float>) {
      return {p, nullptr};
    } else {
      if (!keep) return {p, nullptr};
      for (const Entry& e : entries_)
        if (e.w == w && e.out == out && e.in == in && e.precision == p) return {p, e.packed.data()};
      Entry& e = entries_.emplace_back(Entry{w, out, in, p, {}});
      e.packed.resize(detail::packed_weight_size(p, out, in));
      detail::pack_weight(e.packed.data(), p, w, out, in);
      return {p, e.packed.data()};
    }
  }
  void clear() { entries_.clear(); }
  std::size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    const T* w;
    int out, in;
    Precision precision;
    AlignedVector<T> packed;
  };
  std::vector<Entry> entries_;
};

// out[M, N] = in[M, K] · wᵀ (+ b); b may be nullptr. plan: the precision, and w packed beforehand
// (PackedWeights::get), or {}: fp32, packed per call.
template <class T>
void linear_forward(T* out, const T* in, const T* w, const T* b, int M, int K, int N, WeightPlan plan = {}) {
  if constexpr (std::is_same_v<T, float>) {
    detail::forward_gemm(out, in, w, plan, M, K, N, {false, b, nullptr});
    return;
  }
  // The bias is the GEMM's starting value, so bias and product are one pass over out.
  MatrixMap<T> o(out, M, N);
  if (b)
    o.rowwise() = ConstRowVectorMap<T>(b, N);
  else
    o.setZero();
  detail::gemm_accumulate<Eigen::RowMajor, Eigen::ColMajor>(M, N, K, in, K, w, K, out, N);
}

// out[M, N] = residual[M, N] + in[M, K] · wᵀ (+ b): the residual add fused into the GEMM's
// epilogue. residual may equal out (out += ...).
template <class T>
void linear_forward_residual(T* out, const T* residual, const T* in, const T* w, const T* b, int M, int K, int N,
                             WeightPlan plan = {}) {
  if constexpr (std::is_same_v<T, float>) {
    detail::forward_gemm(out, in, w, plan, M, K, N, {false, b, nullptr, nullptr, residual});
    return;
  }
  MatrixMap<T> o(out, M, N);
  if (residual != out) o = ConstMatrixMap<T>(residual, M, N);
  if (b) o.rowwise() += ConstRowVectorMap<T>(b, N);
  detail::gemm_accumulate<Eigen::RowMajor, Eigen::ColMajor>(M, N, K, in, K, w, K, out, N);
}

// out[M, N] += in[M, K] · wᵀ (+ b).
template <class T>
void linear_forward_accumulate(T* out, const T* in, const T* w, const T* b, int M, int K, int N) {
  linear_forward_residual(out, static_cast<const T*>(out), in, w, b, M, K, N);
}

// Differentiates out = in · wᵀ + b:
//   din[M, K] += dout · w,   dw[N, K] += doutᵀ · in,   db[N] += Σ_m dout[m, :].
// Any of din, dw, db may be nullptr (not wanted). add_din = false: din = dout · w (overwritten,
// so the caller need not zero it first). precision: of both products (float; bf16 operands, fp32
// accumulation into fp32 gradients).
template <class T>
void linear_backward(T* din, T* dw, T* db, const T* dout, const T* in, const T* w, int M, int K,
                     int N, bool add_din = true, Precision precision = Precision::fp32) {
  if constexpr (std::is_same_v<T, float>) {
    using detail::sgemm::Order;
    if (din) detail::gemm(precision, M, K, N, dout, N, Order::row_major, w, K, Order::row_major, din, K, {add_din});
    if (dw && N < K) {
      // Few outputs (fc2: 192 × 768): the product is computed as dwᵀ [K, N] = inᵀ · dout, whose
      // packed B (dout) per depth block is N columns instead of K and stays in L2, then added
      // transposed.
      thread_local AlignedVector<float> dwt;
      float* t = detail::grow(dwt, std::size_t(K) * std::size_t(N));
      detail::gemm(precision, K, N, M, in, K, Order::col_major, dout, N, Order::row_major, t, N);
      detail::add_transposed(dw, t, K, N);
    } else if (dw) {
      detail::gemm(precision, N, K, M, dout, N, Order::col_major, in, K, Order::row_major, dw, K, {true});
    }
  } else {
    if (din && !add_din) std::fill(din, din + std::size_t(M) * std::size_t(K), T(0));
    if (din) detail::gemm_accumulate<Eigen::RowMajor, Eigen::RowMajor>(M, K, N, dout, N, w, K, din, K);
    if (dw) detail::gemm_accumulate<Eigen::ColMajor, Eigen::RowMajor>(N, K, M, dout, N, in, K, dw, K);
  }
  if (db) detail::add_column_sums(db, dout, M, N);
}

// fc1's forward with its epilogue fused: pre[M, N] = in · wᵀ + b, out[M, N] = gelu(pre) (out may
// alias pre: inference keeps only the activation). plan: as linear_forward's.
template <class T>
void linear_bias_gelu_forward(T* out, T* pre, const T* in, const T* w, const T* b, int M, int K, int N,
                              WeightPlan plan = {}) {
  if constexpr (std::is_same_v<T, float>) {
    detail::forward_gemm(pre, in, w, plan, M, K, N, {false, b, out});
  } else {
    linear_forward(pre, in, w, static_cast<const T*>(nullptr), M, K, N);
    bias_gelu_forward(out, pre, b, M, N);
  }
}

// Rows per tile of the row-tiled MLP: a [48, hidden] activation tile (72 KiB at hidden 384) stays
// in L2 next to both packed weights while fc2 reads it back.
inline constexpr int mlp_tile_rows = 48;

// Rows [i0, i1) of the row-tiled MLP below on the calling thread, from w1 and w2 packed in precision
// p (p1, p2), through h, one [mlp_tile_rows, H] tile.
inline void mlp_forward_rows(float* out, const float* residual, const float* in, Precision p, const void* p1,
                             const float* b1, const void* p2, const float* b2, int i0, int i1, int K, int H, int N,
                             float* h) {
  for (; i0 < i1; i0 += mlp_tile_rows) {
    const int r = std::min(mlp_tile_rows, i1 - i0);
    detail::compute_rows(p, r, H, K, in + std::size_t(i0) * K, p1, h, {false, b1, h});
    detail::compute_rows(p, r, N, H, h, p2, out + std::size_t(i0) * N,
                         {false, b2, nullptr, nullptr, residual ? residual + std::size_t(i0) * N : nullptr});
  }
}

// The MLP's inference forward, row-tiled: out[M, N] = (residual +) gelu(in · w1ᵀ + b1) · w2ᵀ + b2
// with in [M, K], w1 [H, K], w2 [N, H]. Per tile of rows the activation h [tile, H] is computed and
// consumed at once, so the [M, H] activation (the largest of a block) never goes to memory, and
// both weights are packed once per call (float; the threads share the packing, panel by panel).
// Same values as linear_bias_gelu_forward then linear_forward(_residual) on whole matrices.
// residual may equal out, or be nullptr. scratch grows to the packed weights plus one [tile, H]
// activation per thread and is reused. plan1, plan2: the precision (plan1's serves both) and w1,
// w2 packed beforehand (PackedWeights; then not packed here), or {}.
template <class T>
void mlp_forward_tiled(T* out, const T* residual, const T* in, const T* w1, const T* b1, const T* w2, const T* b2,
                       int M, int K, int H, int N, AlignedVector<T>& scratch, WeightPlan plan1 = {},
                       WeightPlan plan2 = {}) {
  if (M <= 0) return;
  const int tiles = (M + mlp_tile_rows - 1) / mlp_tile_rows;
  const double flops = 4.0 * double(M) * double(H) * (double(K) + double(N));
  const int threads = flops > detail::parallel_min_flops ? std::min(detail::max_threads(), tiles) : 1;
  const std::size_t tile_size = std::size_t(mlp_tile_rows) * std::size_t(H);
  const Precision p = detail::bgemm::resolve(plan1.precision);
  // Scratch: [packed w1][packed w2] unless given, then one activation tile per thread.
  std::size_t size1 = 0, size2 = 0;
  if constexpr (std::is_same_v<T, float>) {
    if (!plan1.packed) size1 = detail::packed_weight_size(p, H, K);
    if (!plan2.packed || detail::bgemm::resolve(plan2.precision) != p) size2 = detail::packed_weight_size(p, N, H);
  }
  T* const base = detail::grow(scratch, size1 + size2 + std::size_t(threads) * tile_size);
  T* const tile_base = base + size1 + size2;
  const void* p1 = size1 ? base : plan1.packed;
  const void* p2 = size2 ? base + size1 : plan2.packed;
  // Packing tasks: w1's panels, then w2's (those not packed beforehand), shared by the threads.
  const int panels1 = size1 ? detail::weight_panels(H) : 0, panels2 = size2 ? detail::weight_panels(N) : 0;
  auto pack_task = [&](int task) {
    if constexpr (std::is_same_v<T, float>) {
      if (task < panels1)
        detail::pack_weight_panel(base, p, w1, H, K, task);
      else
        detail::pack_weight_panel(base + size1, p, w2, N, H, task - panels1);
    }
  };
  auto run_tile = [&](int i0, int r, T* h) {
    if constexpr (std::is_same_v<T, float>) {
      mlp_forward_rows(out, residual, in, p, p1, b1, p2, b2, i0, i0 + r, K, H, N, h);
    } else {
      const T* x = in + std::size_t(i0) * K;
      T* y = out + std::size_t(i0) * N;
      const T* res = residual ? residual + std::size_t(i0) * N : nullptr;
      linear_bias_gelu_forward(h, h, x, w1, b1, r, K, H);
      if (res)
        linear_forward_residual(y, res, h, w2, b2, r, H, N);
      else
        linear_forward(y, h, w2, b2, r, H, N);
    }
  };
  // Rows [i0, i1) in tiles.
  auto run_rows = [&](int i0, int i1, T* h) {
    for (; i0 < i1; i0 += mlp_tile_rows) run_tile(i0, std::min(mlp_tile_rows, i1 - i0), h);
  };
  if (threads <= 1) {
    for (int task = 0; task < panels1 + panels2; ++task) pack_task(task);
    run_rows(0, M, tile_base);
    return;
  }
  TJEPA_OMP(omp parallel num_threads(threads)) {
    if (panels1 + panels2 > 0) {
      TJEPA_OMP(omp for schedule(static))
      for (int task = 0; task < panels1 + panels2; ++task) pack_task(task);
    }
    const int id = detail::thread_id(), n = detail::team_size();
    T* const h = tile_base + std::size_t(id) * tile_size;
    // Each thread its own rows (detail::owns_rows), or tiles to whichever thread is free
    // (sgemm::run_product's reason): a tile's values do not depend on the thread that computes it.
    if (detail::owns_rows(M, n)) {
      run_rows(detail::row_begin(M, id, n), detail::row_begin(M, id + 1, n), h);
    } else {
      TJEPA_OMP(omp for schedule(dynamic, 1))
      for (int t = 0; t < tiles; ++t) run_tile(t * mlp_tile_rows, std::min(mlp_tile_rows, M - t * mlp_tile_rows), h);
    }
  }
}

// The MLP's backward through fc2 and its GELU in one product: dpre[M, K] = (dout · w) ⊙ scale for
// out = gelu(pre) · wᵀ + b (dout [M, N], w [N, K]), scale [M, K] = gelu'(pre) (gelu_forward_grad
// gives it with the activation). dpre is overwritten, not added to; it may not alias scale.
template <class T>
void linear_backward_input_scaled(T* dpre, const T* dout, const T* w, const T* scale, int M, int K, int N,
                                  Precision precision = Precision::fp32) {
  if constexpr (std::is_same_v<T, float>) {
    using detail::sgemm::Order;
    detail::gemm(precision, M, K, N, dout, N, Order::row_major, w, K, Order::row_major, dpre, K,
                 {false, nullptr, nullptr, scale});
  } else {
    const std::size_t n = std::size_t(M) * std::size_t(K);
    std::fill(dpre, dpre + n, T(0));
    detail::gemm_accumulate<Eigen::RowMajor, Eigen::RowMajor>(M, K, N, dout, N, w, K, dpre, K);
    for (std::size_t i = 0; i < n; ++i) dpre[i] *= scale[i];
  }
}

}  // namespace tjepa::kernels
