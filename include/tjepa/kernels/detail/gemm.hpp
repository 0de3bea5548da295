#pragma once
// Row-major GEMM on Eigen's packed kernels (gebp) without Eigen's allocations: C += A · B.
//
// Eigen's product expression allocates its packing buffers on every call once they exceed
// EIGEN_STACK_ALLOCATION_LIMIT, and its OpenMP path always does. Here the blocking object hands
// Eigen per-thread buffers that grow once and are reused, and the rows of C are split over the
// OpenMP threads by us, so a steady-state forward allocates nothing. This uses
// Eigen::internal::general_matrix_matrix_product and level3_blocking (Eigen 3.4).
#include <algorithm>
#include <cstddef>

#include "tjepa/core/detail/vendor.hpp"

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/detail/parallel.hpp"

namespace tjepa::detail {

template <class T>
class GemmBlocking : public Eigen::internal::level3_blocking<T, T> {
 public:
  // Blocking for a row-major C [rows, cols] with inner dimension depth (Eigen computes the
  // transposed, column-major product, hence mc ↔ cols and nc ↔ rows).
  GemmBlocking(Eigen::Index rows, Eigen::Index cols, Eigen::Index depth) {
    this->m_mc = cols;
    this->m_nc = rows;
    this->m_kc = depth;
    Eigen::internal::computeProductBlockingSizes<T, T, 1, Eigen::Index>(this->m_kc, this->m_mc, this->m_nc, 1);
    thread_local AlignedVector<T> a, b;
    this->m_blockA = grow(a, std::size_t(this->m_mc * this->m_kc));
    this->m_blockB = grow(b, std::size_t(this->m_kc * this->m_nc));
  }
};

// C[rows, cols] (row stride ldc) += A[rows, depth] · B[depth, cols]. LhsOrder / RhsOrder say how
// A and B are stored (Eigen::RowMajor or Eigen::ColMajor) with strides lda / ldb. Rows of C are
// split over the threads when the product is large enough to pay for it.
template <int LhsOrder, int RhsOrder, class T>
void gemm_accumulate(Eigen::Index rows, Eigen::Index cols, Eigen::Index depth, const T* A, Eigen::Index lda,
                     const T* B, Eigen::Index ldb, T* C, Eigen::Index ldc) {
  if (rows <= 0 || cols <= 0 || depth <= 0) return;
  using Product = Eigen::internal::general_matrix_matrix_product<Eigen::Index, T, LhsOrder, false, T, RhsOrder, false,
                                                                  Eigen::RowMajor, 1>;
  const double flops = 2.0 * double(rows) * double(cols) * double(depth);
  const int threads = flops > parallel_min_flops ? std::min<int>(max_threads(), int((rows + 15) / 16)) : 1;
  auto run = [&](Eigen::Index r0, Eigen::Index r1) {
    if (r1 <= r0) return;
    GemmBlocking<T> blocking(r1 - r0, cols, depth);
    const T* a = LhsOrder == Eigen::RowMajor ? A + r0 * lda : A + r0;
    Product::run(r1 - r0, cols, depth, a, lda, B, ldb, C + r0 * ldc, 1, ldc, T(1), blocking, nullptr);
  };
  if (threads <= 1) {
    run(0, rows);
    return;
  }
  // Chunks of whole 8-row panels, as even as possible.
  TJEPA_OMP(omp parallel for schedule(static) num_threads(threads))
  for (int t = 0; t < threads; ++t) {
    const Eigen::Index per = ((rows + threads - 1) / threads + 7) / 8 * 8;
    run(std::min<Eigen::Index>(rows, t * per), std::min<Eigen::Index>(rows, (t + 1) * per));
  }
}

}  // namespace tjepa::detail
