#pragma once
// Packed float GEMM with a register-blocked xsimd micro-kernel and fused epilogues, for the
// linear layers' three products (forward X·Wᵀ, dX = dY·W, dW = dYᵀ·X):
//
//   C[rows, cols] (+)= A[rows, depth] · B[depth, cols] (+ bias[cols]) (then G = gelu(C))
//
// A is read in place (row- or column-major, any stride); B is packed once per call into panels of
// NR columns, [depth][NR] each (a last panel of at most NR/2 columns [depth][NR/2]), zero-padded
// on the right, shared by the threads. The rows of C are
// split over the OpenMP threads in whole MR-row blocks. Depth runs in KC blocks: the A
// micro-panel (MR × KC) stays in L1 while the B panels of one depth block (KC × cols) stream from
// L2. xsimd's default architecture picks AVX-512, AVX2 or SSE2 at compile time.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <utility>

#include "tjepa/core/detail/vendor.hpp"

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/detail/parallel.hpp"
#include "tjepa/core/detail/simd.hpp"
#include "tjepa/core/detail/transpose.hpp"
#include "tjepa/kernels/gelu.hpp"

namespace tjepa::detail::sgemm {

using V = xsimd::batch<float>;
inline constexpr int W = static_cast<int>(V::size);
// An MR × NV·W block of C in MR·NV registers: 24 of AVX-512's 32 (+ NV B vectors + a broadcast),
// 8 of AVX2's / SSE's 16.
inline constexpr int MR = W >= 16 ? 6 : 4;
inline constexpr int NV = W >= 16 ? 4 : 2;
inline constexpr int NR = NV * W;
// Depths per block: the products of depth 768 (fc2's forward, fc1's dX) and the weight gradients'
// slabs of 512 run as one block, so that each C tile goes through the epilogue once (256 made
// two or three read-modify-write passes over C). Row-major A's 6 rows of 768 floats (18 KiB)
// stay in L1, a B panel (192 KiB) in L2; column-major A (dYᵀ) touches one line a depth, 32 KiB
// for a slab of 512. bench/RESULTS.md ("fp32's depth blocks of 768"): the fp32 JEPA step 1.02x
// faster on one Zen 5 core, 1.08x on two; the AVX2 code 1.02x; on an Intel Xeon (48 KiB L1,
// 2 MiB L2) 1.02x on one core, 1.01x on two; no Zen 4 (32 KiB L1) timing.
inline constexpr int KC = 768;
// Depths per packing task: B's panels are packed by the threads in tasks of one panel × this many
// depths, so that a product with few panels still splits its packing evenly.
inline constexpr int pack_depth = 256;

enum class Order { row_major, col_major };

// What happens to a finished tile. bias [cols] is added once; gelu [rows, ldc]: C keeps the
// pre-activation and gelu receives gelu(C) (the MLP's fc1). accumulate: C += A·B, else C = A·B.
// scale [rows, ldc] (with accumulate = false): C = (A·B) ⊙ scale, the MLP's backward through its
// GELU fused into the product that yields ∂L/∂h (scale: gelu' at the pre-activation). residual
// [rows, ldc] (with accumulate = false; may equal C): C = residual + A·B, a residual add without a
// copy of the stream.
struct Epilogue {
  bool accumulate = false;
  const float* bias = nullptr;
  float* gelu = nullptr;
  const float* scale = nullptr;
  const float* residual = nullptr;
};

inline V gelu(V x) { return detail::gelu<float>(x); }
inline float gelu(float x) {
  float y;
  kernels::ref::gelu_forward(&y, &x, 1);
  return y;
}

// acc[R][NK·W] = A · B over one depth block of kc: a(i, k) = a[i·lda + k] (AO row-major) or
// a[k·lda + i] (column-major), b packed [kc][NK·W] (NK < NV: a last panel of at most NK·W
// columns, packed that narrow). pf: the next row block's A, prefetched while
// this one computes (A is read in place, and in a training step it comes cold from memory);
// nullptr: none. Not inlined: with only the loop's own values live, g++ keeps all R·NV
// accumulators in registers (inlined into the epilogue's many arguments, it spills some).
template <Order AO, int R, int NK>
[[gnu::noinline]] void depth_loop(int kc, const float* a, std::ptrdiff_t lda, const float* b, const float* pf,
                                  float* acc_out) {
  V acc[R][NK];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int j = 0; j < NK; ++j) acc[i][j] = V(0.0f);
  constexpr int line = 64 / int(sizeof(float));
  for (int k0 = 0; k0 < kc; k0 += line) {
    const int k1 = std::min(kc, k0 + line);
    // Row-major A: one line of each of the next block's rows per line of depth.
    if (AO == Order::row_major && pf)
#pragma GCC unroll 8
      for (int i = 0; i < MR; ++i) __builtin_prefetch(pf + i * lda + k0);
    for (int k = k0; k < k1; ++k) {
      V bv[NK];
#pragma GCC unroll 4
      for (int j = 0; j < NK; ++j) bv[j] = V::load_aligned(b + std::ptrdiff_t(k) * NK * W + j * W);
      // Column-major A: the next block's MR values at this depth (one line, or two).
      if (AO == Order::col_major && pf) {
        __builtin_prefetch(pf + k * lda);
        __builtin_prefetch(pf + k * lda + MR - 1);
      }
#pragma GCC unroll 8
      for (int i = 0; i < R; ++i) {
        const V ai(AO == Order::row_major ? a[i * lda + k] : a[k * lda + i]);
#pragma GCC unroll 4
        for (int j = 0; j < NK; ++j) acc[i][j] = xsimd::fma(ai, bv[j], acc[i][j]);
      }
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int j = 0; j < NK; ++j) acc[i][j].store_aligned(acc_out + i * NR + j * W);
}

// The epilogue of an R × (cols ≤ NK·W) tile of C whose product (of one depth block) is in tile
// [R][NR]: c_in [R, ldc] is what the product is added to (C itself holding a partial sum or the
// value accumulated into, or the residual) or nullptr; bias on the first depth block, g (gelu
// output) and gg (scale) on the last. The product kernels write the tile's first NK·W
// columns of each row; the edge path reads only cols <= NK·W of them. GCC cannot see that bound
// and warns (maybe-uninitialized) in some inlining contexts: silenced here, for these functions
// only. Shared by the float kernel below and the bf16 one (bgemm.hpp).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
template <int R, int NK>
inline void prefetch_tile(const float* c, std::ptrdiff_t ldc, const float* c_in, const float* gg) {
  // The tile's C (and GELU input) lines arrive while the depth loop runs.
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < NK; ++j) {
      __builtin_prefetch(c + i * ldc + j * W, 1);
      if (c_in && c_in != c) __builtin_prefetch(c_in + i * ldc + j * W);
      if (gg) __builtin_prefetch(gg + i * ldc + j * W);
    }
}
template <int R, int NK>
TJEPA_PROFILE_INLINE void finish_tile(const float* tile, float* c, std::ptrdiff_t ldc, int cols, const float* c_in,
                                      const float* bias, float* g, const float* gg) {
  if (cols == NK * W) {
#pragma GCC unroll 8
    for (int i = 0; i < R; ++i) {
      float* ci = c + i * ldc;
#pragma GCC unroll 4
      for (int j = 0; j < NK; ++j) {
        V v = V::load_aligned(tile + i * NR + j * W);
        if (c_in) v += V::load_unaligned(c_in + i * ldc + j * W);
        if (bias) v += V::load_unaligned(bias + j * W);
        if (gg) v *= V::load_unaligned(gg + i * ldc + j * W);
        v.store_unaligned(ci + j * W);
        if (g) gelu(v).store_unaligned(g + i * ldc + j * W);
      }
    }
    return;
  }
  for (int i = 0; i < R; ++i) {
    float* ci = c + i * ldc;
    for (int j = 0; j < cols; ++j) {
      float v = tile[i * NR + j];
      if (c_in) v += c_in[i * ldc + j];
      if (bias) v += bias[j];
      if (gg) v *= gg[i * ldc + j];
      ci[j] = v;
      if (g) g[i * ldc + j] = gelu(v);
    }
  }
}

// C[R, cols ≤ NK·W] from one depth block (depth_loop, then finish_tile).
template <Order AO, int R, int NK>
void micro_kernel(int kc, const float* a, std::ptrdiff_t lda, const float* b, float* c, std::ptrdiff_t ldc, int cols,
                  const float* c_in, const float* bias, float* g, const float* gg, const float* pf) {
  prefetch_tile<R, NK>(c, ldc, c_in, gg);
  alignas(64) float tile[R * NR];
  depth_loop<AO, R, NK>(kc, a, lda, b, pf, tile);
  finish_tile<R, NK>(tile, c, ldc, cols, c_in, bias, g, gg);
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

using Kernel = void (*)(int, const float*, std::ptrdiff_t, const float*, float*, std::ptrdiff_t, int, const float*,
                        const float*, float*, const float*, const float*);
template <Order AO, int NK, int... R>
constexpr auto kernel_table(std::integer_sequence<int, R...>) {
  return std::array<Kernel, sizeof...(R)>{&micro_kernel<AO, R + 1, NK>...};
}
// kernels[order][R - 1] handles R rows: the last row block of a split may be short.
inline constexpr std::array<std::array<Kernel, MR>, 2> kernels = {
    kernel_table<Order::row_major, NV>(std::make_integer_sequence<int, MR>{}),
    kernel_table<Order::col_major, NV>(std::make_integer_sequence<int, MR>{})};
// The same for a last panel of at most NR/2 columns (d = 96 is one panel and a half): half the
// FMAs of a full panel, none on its zero padding.
inline constexpr int NH = NV / 2;
inline constexpr std::array<std::array<Kernel, MR>, 2> half_kernels = {
    kernel_table<Order::row_major, NH>(std::make_integer_sequence<int, MR>{}),
    kernel_table<Order::col_major, NH>(std::make_integer_sequence<int, MR>{})};

// B(k, n) = b[k·ldb + n] (row-major) or b[n·ldb + k] (column-major, a PyTorch weight [cols, depth]
// read as its transpose) → depths [k0, k1) of panel p of dst: [depth][panel_width], columns
// p·NR + j, at dst + p·depth·NR. k0 is a multiple of 16.
// Values per depth of a panel of nc columns: NR, or NR/2 for a narrow last panel (no padding to
// fetch from memory for the half-width kernel).
inline int panel_width(int nc) { return nc <= NH * W ? NH * W : NR; }

inline void pack_panel(float* dst, const float* b, std::ptrdiff_t ldb, Order order, int depth, int cols, int p, int k0,
                       int k1) {
  const int n0 = p * NR, nc = std::min(NR, cols - n0), pw = panel_width(nc);
  float* d = dst + std::ptrdiff_t(p) * depth * NR;
  if (order == Order::row_major) {
    for (int k = k0; k < k1; ++k) {
      const float* s = b + std::ptrdiff_t(k) * ldb + n0;
      float* o = d + std::ptrdiff_t(k) * pw;
      if (nc == NR) {  // a whole row in registers: no memmove call per 256 bytes
#pragma GCC unroll 4
        for (int j = 0; j < NV; ++j) V::load_unaligned(s + j * W).store_aligned(o + j * W);
      } else {
        std::copy(s, s + nc, o);
        std::fill(o + nc, o + pw, 0.0f);
      }
    }
    return;
  }
  // A transpose in 16 × nc tiles: each source row's cache line is read once, each packed row
  // written whole; whole 16 × 16 blocks in registers (transpose16).
  constexpr int T = 16;
  for (int t0 = k0; t0 < k1; t0 += T) {
    const int kt = std::min(T, k1 - t0);
    int j = 0;
    if (kt == T)
      for (; j + T <= nc; j += T)
        transpose16([&](int i) { return b + std::ptrdiff_t(n0 + j + i) * ldb + t0; }, d + std::ptrdiff_t(t0) * pw + j,
                    pw);
    for (; j < nc; ++j) {
      const float* s = b + std::ptrdiff_t(n0 + j) * ldb + t0;
      for (int k = 0; k < kt; ++k) d[std::ptrdiff_t(t0 + k) * pw + j] = s[k];
    }
    for (int k = 0; k < kt; ++k) {
      float* o = d + std::ptrdiff_t(t0 + k) * pw;
      std::fill(o + nc, o + pw, 0.0f);
    }
  }
}

// The whole of B packed for compute_rows: [panels][depth][NR]. gemm packs per call; a caller that
// runs several products against one B (the row-tiled MLP) packs it once.
inline std::size_t packed_size(int cols, int depth) {
  return std::size_t((cols + NR - 1) / NR) * std::size_t(depth) * NR;
}
inline void pack(float* packed, const float* B, std::ptrdiff_t ldb, Order b_order, int depth, int cols) {
  for (int p = 0; p < (cols + NR - 1) / NR; ++p) pack_panel(packed, B, ldb, b_order, depth, cols, p, 0, depth);
}

// Rows [r0, r1) of C from the packed B.
inline void compute_rows(int r0, int r1, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order,
                         const float* packed, float* C, std::ptrdiff_t ldc, const Epilogue& e) {
  const std::ptrdiff_t ars = a_order == Order::row_major ? lda : 1, acs = a_order == Order::row_major ? 1 : lda;
  const std::size_t o = a_order == Order::row_major ? 0 : 1;
  const int panels = (cols + NR - 1) / NR;
  for (int k0 = 0; k0 < depth; k0 += KC) {
    const int kc = std::min(KC, depth - k0);
    const bool first = k0 == 0, last = k0 + kc == depth;
    const float* c_in = !first || e.accumulate ? C : e.residual;
    for (int i0 = r0; i0 < r1; i0 += MR) {
      const int R = std::min(MR, r1 - i0);
      const Kernel kern = kernels[o][std::size_t(R - 1)], half = half_kernels[o][std::size_t(R - 1)];
      const float* a = A + i0 * ars + k0 * acs;
      // A is read in place: its next row block is prefetched during this one's first panel (a
      // whole block when the next one is short, harmlessly).
      const float* next = i0 + MR < r1 ? a + MR * ars : nullptr;
      for (int p = 0; p < panels; ++p) {
        const int n0 = p * NR;
        const int nc = std::min(NR, cols - n0);
        const float* b = packed + std::ptrdiff_t(p) * depth * NR + std::ptrdiff_t(k0) * panel_width(nc);
        (nc <= NH * W ? half : kern)(kc, a, lda, b, C + i0 * ldc + n0, ldc, nc, c_in ? c_in + i0 * ldc + n0 : nullptr,
                                     first && e.bias ? e.bias + n0 : nullptr,
                                     last && e.gelu ? e.gelu + i0 * ldc + n0 : nullptr,
                                     last && e.scale ? e.scale + i0 * ldc + n0 : nullptr, p == 0 ? next : nullptr);
      }
    }
  }
}

// Runs one product over the rows of C: pack(task) for tasks [0, tasks) (B's panels; none when B
// was packed beforehand), then compute(r0, r1) for rows [r0, r1), on this thread below
// parallel_min_flops, else over the threads (the packing shared among them first) in chunks of
// whole MR-row blocks, up to 8 per thread, each taken by the next free thread. An even static
// split leaves every thread waiting for the slowest: on a 2-core VM twelve MLPs' worth of these
// products ran 1.75x faster on 2 threads than on 1 split in halves, 2.0x in chunks (an in-process
// A/B; bench/RESULTS.md's notes).
// Serves the float and the bf16 GEMM.
template <class Pack, class Compute>
void run_product(int rows, int cols, int depth, int tasks, Pack&& pack, Compute&& compute) {
  const double flops = 2.0 * double(rows) * double(cols) * double(depth);
  const int threads = flops > parallel_min_flops ? std::min(max_threads(), (rows + MR - 1) / MR) : 1;
  if (threads <= 1) {
    for (int task = 0; task < tasks; ++task) pack(task);
    compute(0, rows);
    return;
  }
  TJEPA_OMP(omp parallel num_threads(threads)) {
    if (tasks > 0) {  // weights packed beforehand: no barrier to wait at
      TJEPA_OMP(omp for schedule(static))
      for (int task = 0; task < tasks; ++task) pack(task);
    }
    if (owns_rows(rows, team_size())) {
      const int t = thread_id(), n = team_size();
      compute(row_begin(rows, t, n), row_begin(rows, t + 1, n));
    } else {
      const int blocks = (rows + MR - 1) / MR, chunks = std::min(blocks, 8 * team_size());
      TJEPA_OMP(omp for schedule(dynamic, 1) nowait)
      for (int c = 0; c < chunks; ++c) {
        const int b0 = blocks * c / chunks, b1 = blocks * (c + 1) / chunks;
        compute(std::min(rows, b0 * MR), std::min(rows, b1 * MR));
      }
    }
  }
}

// Products with a long depth and a small C, the weight gradients (depth: the batch's rows, C: a
// weight), split over the depth too: split over C's rows alone, every thread streams all of B
// (on 2 cores the predictor's proj gradient ran no faster on 2 threads than on 1, fc1's 1.4x).
// The depth runs in slabs of depth_slab, fixed, so that the sums, and the bits, do not depend on
// the thread count: slab s's product goes to a partial P_s [rows, cols], then C (+)= P_0 + P_1 + ...
// in that order. First every slab's B is packed (pack(slab, task) for tasks_per_slab tasks each),
// then compute(slab, r0, r1, P_s) runs the slabs, in row chunks when there are too few slabs to
// keep the threads busy (the chunks do not change any value).
inline constexpr int depth_slab = 512;
inline bool split_depth(int rows, int cols, int depth, const Epilogue& e) {
  return depth >= 2 * depth_slab && depth > rows && std::size_t(rows) * std::size_t(cols) <= (std::size_t(1) << 20) &&
         !e.bias && !e.gelu && !e.scale && !e.residual;
}
template <class Pack, class Compute>
void run_split_depth(int rows, int cols, int depth, int tasks_per_slab, Pack&& pack, Compute&& compute, float* C,
                     std::ptrdiff_t ldc, bool accumulate) {
  const int slabs = (depth + depth_slab - 1) / depth_slab, blocks = (rows + MR - 1) / MR;
  const std::size_t part = std::size_t(rows) * std::size_t(cols);
  thread_local AlignedVector<float> partial_buffer;
  float* P = grow(partial_buffer, std::size_t(slabs) * part);
  const double flops = 2.0 * double(rows) * double(cols) * double(depth);
  [[maybe_unused]] const int threads = flops > parallel_min_flops ? max_threads() : 1;
  TJEPA_OMP(omp parallel num_threads(threads) if (threads > 1)) {
    TJEPA_OMP(omp for schedule(dynamic, 1))
    for (int task = 0; task < slabs * tasks_per_slab; ++task) pack(task / tasks_per_slab, task % tasks_per_slab);
    // About 16 tasks a thread, taken as threads free up: with 4 the context encoder's weight
    // gradients at batch 8 (depth 1312: 3 slabs) made 3 chunks a slab, 9 tasks, 5 for one of 2
    // threads and 4 for the other (at most 1.8x); with 16, 33 tasks (at most 1.94x, and a slow
    // spell of one core costs one small task). bench/gemm.cpp's BM_WeightGradient times them.
    const int chunks = std::clamp((16 * team_size() + slabs - 1) / slabs, 1, std::max(1, blocks / 4));
    TJEPA_OMP(omp for schedule(dynamic, 1))
    for (int task = 0; task < slabs * chunks; ++task) {
      const int slab = task / chunks, c = task % chunks;
      const int b0 = blocks * c / chunks, b1 = blocks * (c + 1) / chunks;
      compute(slab, std::min(rows, b0 * MR), std::min(rows, b1 * MR), P + std::size_t(slab) * part);
    }
    TJEPA_OMP(omp for schedule(static))
    for (int i = 0; i < rows; ++i) {
      float* c = C + std::ptrdiff_t(i) * ldc;
      const float* p0 = P + std::size_t(i) * std::size_t(cols);
      if (accumulate)
        simd_add(p0, c, std::size_t(cols));
      else
        std::copy(p0, p0 + cols, c);
      for (int slab = 1; slab < slabs; ++slab) simd_add(p0 + std::size_t(slab) * part, c, std::size_t(cols));
    }
  }
}

// C (+)= A · B per the epilogue with B packed beforehand (pack(), packed_size(cols, depth)):
// products with weights that were packed once. depth ≥ 1.
inline void gemm_packed(int rows, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order,
                        const float* packed, float* C, std::ptrdiff_t ldc, const Epilogue& e = {}) {
  if (rows <= 0 || cols <= 0) return;
  run_product(rows, cols, depth, 0, [](int) {}, [&](int r0, int r1) {
    compute_rows(r0, r1, cols, depth, A, lda, a_order, packed, C, ldc, e);
  });
}

// The epilogue alone, for depth 0: C = (C or residual or 0) + bias (then 0 under scale, and
// gelu(C) into gelu).
inline void empty_product(int rows, int cols, float* C, std::ptrdiff_t ldc, const Epilogue& e) {
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) {
      float& c = C[std::ptrdiff_t(i) * ldc + j];
      c = (e.accumulate ? c : e.residual ? e.residual[std::ptrdiff_t(i) * ldc + j] : 0.0f) + (e.bias ? e.bias[j] : 0.0f);
      if (e.scale) c = 0.0f;
      if (e.gelu) e.gelu[std::ptrdiff_t(i) * ldc + j] = gelu(c);
    }
}

// C[rows, cols] (ldc) (+)= A · B per the epilogue; A(i, k) = A[i·lda + k] (row-major) or
// A[k·lda + i] (column-major), B likewise with ldb. rows, cols ≥ 0; depth 0 leaves the epilogue
// applied to an empty product.
inline void gemm(int rows, int cols, int depth, const float* A, std::ptrdiff_t lda, Order a_order, const float* B,
                 std::ptrdiff_t ldb, Order b_order, float* C, std::ptrdiff_t ldc, const Epilogue& e = {}) {
  if (rows <= 0 || cols <= 0) return;
  if (depth <= 0) return empty_product(rows, cols, C, ldc, e);
  thread_local AlignedVector<float> pack_buffer;
  const int panels = (cols + NR - 1) / NR;
  if (split_depth(rows, cols, depth, e)) {
    // Slab s: depths [s·depth_slab, +kd) of A and B, packed on its own at s·slab_size.
    const std::size_t slab_size = packed_size(cols, depth_slab);
    const int slabs = (depth + depth_slab - 1) / depth_slab, kblocks = (depth_slab + pack_depth - 1) / pack_depth;
    float* packed = grow(pack_buffer, std::size_t(slabs) * slab_size);
    const auto kd = [&](int slab) { return std::min(depth_slab, depth - slab * depth_slab); };
    const std::ptrdiff_t a_step = a_order == Order::row_major ? 1 : lda, b_step = b_order == Order::row_major ? ldb : 1;
    run_split_depth(
        rows, cols, depth, panels * kblocks,
        [&](int slab, int task) {
          const int kb = task % kblocks, k1 = std::min(kd(slab), (kb + 1) * pack_depth);
          if (kb * pack_depth < k1)
            pack_panel(packed + std::size_t(slab) * slab_size, B + slab * depth_slab * b_step, ldb, b_order, kd(slab),
                       cols, task / kblocks, kb * pack_depth, k1);
        },
        [&](int slab, int r0, int r1, float* P) {
          compute_rows(r0, r1, cols, kd(slab), A + slab * depth_slab * a_step, lda, a_order,
                       packed + std::size_t(slab) * slab_size, P, cols, {});
        },
        C, ldc, e.accumulate);
    return;
  }
  float* packed = grow(pack_buffer, packed_size(cols, depth));
  // Packing tasks of one panel × pack_depth depths: a long depth (dW) with few panels still splits
  // evenly.
  const int kblocks = (depth + pack_depth - 1) / pack_depth;
  run_product(
      rows, cols, depth, panels * kblocks,
      [&](int task) {
        const int kb = task % kblocks;
        pack_panel(packed, B, ldb, b_order, depth, cols, task / kblocks, kb * pack_depth,
                   std::min(depth, (kb + 1) * pack_depth));
      },
      [&](int r0, int r1) { compute_rows(r0, r1, cols, depth, A, lda, a_order, packed, C, ldc, e); });
}

}  // namespace tjepa::detail::sgemm
