#pragma once
// OpenMP helpers: the library builds and runs the same without OpenMP (pragmas vanish, one thread).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#define TJEPA_OMP(directive) _Pragma(#directive)
#else
#define TJEPA_OMP(directive)
#endif

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/detail/simd.hpp"

namespace tjepa::detail {

// Below these sizes a loop runs on one thread: a parallel region costs microseconds when the
// cores are free and a scheduler time slice when they are not. The GEMM's: batch-1 inference has
// products of a few MFLOP (the demo encoder's proj, 368 × 96 × 96, 6.8 MFLOP), which two threads
// ran 1.75x faster on a Zen 4 pair, a 2.4 MFLOP one 1.4x; 1.8 MFLOP gained nothing.
inline constexpr std::size_t parallel_grain = std::size_t(1) << 17;  // elements of a row-wise kernel
inline constexpr double parallel_min_flops = 2e6;                     // of a GEMM

// Rows that stay with one thread from kernel to kernel. In a small product (batch-1 inference: a
// few hundred rows) any thread could take any rows, and then the next kernel's thread reads rows
// that the other core wrote: half of every activation crosses between the cores at every stage.
// Up to affinity_rows rows a thread, the GEMMs, LayerNorm, the row-tiled MLP and the attention's
// query rows give thread t of n the same rows, [row_begin(rows, t, n), row_begin(rows, t + 1, n)),
// in whole blocks of `block` rows (the GEMM's MR). Above it, the products hand out chunks to
// whichever thread is free (sgemm::run_product), which pays where a core is slowed for a while.
inline constexpr int affinity_rows = 384;
// Rows come in blocks of the AVX-512 GEMMs' MR (sgemm.hpp, bgemm.hpp); any split is correct, whole blocks are faster.
inline constexpr int row_block = 6;
inline bool owns_rows(int rows, int threads) { return threads > 1 && rows <= affinity_rows * threads; }
inline int row_begin(int rows, int t, int n, int block = row_block) {
  const int blocks = (rows + block - 1) / block;
  return std::min(rows, int(std::int64_t(blocks) * t / n) * block);
}

inline int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}
// Threads of the enclosing parallel region (1 outside one).
inline int team_size() {
#ifdef _OPENMP
  return omp_get_num_threads();
#else
  return 1;
#endif
}
inline int thread_id() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

// Grows a caller-owned buffer to at least n elements and returns its data. A buffer never shrinks,
// so a second call with the same shape does not allocate.
template <class T, class A>
T* grow(std::vector<T, A>& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
  return v.data();
}

// Calls f(begin, end) on [0, n) split evenly over the threads, or once within the grain.
template <class F>
void parallel_split(std::size_t n, F&& f) {
  if (n <= parallel_grain) {
    f(std::size_t(0), n);
    return;
  }
  TJEPA_OMP(omp parallel)
  {
    const std::size_t t = std::size_t(thread_id()), k = std::size_t(team_size());
    f(n * t / k, n * (t + 1) / k);
  }
}

// std::fill and std::copy over the threads: the zeroed gradient buffers and residual-stream copies
// of a training step are tens of MB, too much to leave to one thread.
template <class T>
void parallel_fill(T* first, T* last, T value) {
  parallel_split(std::size_t(last - first), [&](std::size_t b, std::size_t e) { simd_fill(first + b, e - b, value); });
}
template <class T>
void parallel_copy(const T* first, const T* last, T* out) {
  parallel_split(std::size_t(last - first),
                 [&](std::size_t b, std::size_t e) { std::copy(first + b, first + e, out + b); });
}

// db[n0, n0 + NV·W) += Σ_m x[m, n0 + ...], NV vectors of columns summed row by row in registers.
template <int NV, class T>
void column_sums_chunk(T* db, const T* x, int M, int N, int n0) {
  constexpr int W = int(simd_width<T>);
  simd<T> acc[NV];
#pragma GCC unroll 8
  for (int v = 0; v < NV; ++v) acc[v] = simd<T>(T(0));
  for (int m = 0; m < M; ++m) {
    const T* r = x + std::size_t(m) * std::size_t(N) + n0;
#pragma GCC unroll 8
    for (int v = 0; v < NV; ++v) acc[v] += xsimd::load_unaligned(r + v * W);
  }
#pragma GCC unroll 8
  for (int v = 0; v < NV; ++v) (xsimd::load_unaligned(db + n0 + v * W) + acc[v]).store_unaligned(db + n0 + v * W);
}

// db[N] += Σ_m x[m, :] for x [M, N]: columns split over the threads above the grain, each column
// summed on its own first so that adding twice gives exactly twice. A thread walks its columns in
// chunks of 8, 4, 2 and 1 vectors, each summed row by row in registers (contiguous, vectorized
// reads of x), then single columns.
template <class T>
void add_column_sums(T* db, const T* x, int M, int N) {
  constexpr int G = 16, W = int(simd_width<T>);
  const int groups = (N + G - 1) / G;
  [[maybe_unused]] const int threads =
      std::size_t(M) * std::size_t(N) > parallel_grain ? std::min(max_threads(), groups) : 1;
  TJEPA_OMP(omp parallel num_threads(threads) if (threads > 1))
  {
    const int t = thread_id(), n = team_size();
    const int c1 = std::min(N, groups * (t + 1) / n * G);
    int n0 = std::min(N, groups * t / n * G);
    for (; n0 + 8 * W <= c1; n0 += 8 * W) column_sums_chunk<8>(db, x, M, N, n0);
    if (n0 + 4 * W <= c1) column_sums_chunk<4>(db, x, M, N, n0), n0 += 4 * W;
    if (n0 + 2 * W <= c1) column_sums_chunk<2>(db, x, M, N, n0), n0 += 2 * W;
    if (n0 + W <= c1) column_sums_chunk<1>(db, x, M, N, n0), n0 += W;
    for (; n0 < c1; ++n0) {
      T acc = T(0);
      for (int m = 0; m < M; ++m) acc += x[std::size_t(m) * std::size_t(N) + n0];
      db[n0] += acc;
    }
  }
}

// dst[C, R] += srcᵀ for src [R, C], in 16 × 16 tiles (each line of src and dst read once); rows
// of dst split over the threads above the grain.
template <class T>
void add_transposed(T* dst, const T* src, int R, int C) {
  constexpr int B = 16;
  const int blocks = (C + B - 1) / B;
  [[maybe_unused]] const int threads =
      std::size_t(R) * std::size_t(C) > parallel_grain ? std::min(max_threads(), blocks) : 1;
  TJEPA_OMP(omp parallel for schedule(static) num_threads(threads) if (threads > 1))
  for (int cb = 0; cb < blocks; ++cb) {
    const int c0 = cb * B, c1 = std::min(C, c0 + B);
    for (int r0 = 0; r0 < R; r0 += B) {
      const int r1 = std::min(R, r0 + B);
      for (int c = c0; c < c1; ++c)
        for (int r = r0; r < r1; ++r) dst[std::size_t(c) * R + r] += src[std::size_t(r) * C + c];
    }
  }
}

}  // namespace tjepa::detail
