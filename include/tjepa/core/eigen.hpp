#pragma once
// Eigen aliases. tjepa stores every tensor row-major ([rows, cols] with cols contiguous), like
// PyTorch, so a [B, L, d] buffer is a [B*L, d] matrix without copies.
#include "tjepa/core/detail/vendor.hpp"

namespace tjepa {

template <class T>
using Matrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using Vector = Eigen::Matrix<T, Eigen::Dynamic, 1>;
template <class T>
using RowVector = Eigen::Matrix<T, 1, Eigen::Dynamic>;

template <class T>
using MatrixMap = Eigen::Map<Matrix<T>, Eigen::Unaligned>;
template <class T>
using ConstMatrixMap = Eigen::Map<const Matrix<T>, Eigen::Unaligned>;
template <class T>
using VectorMap = Eigen::Map<Vector<T>, Eigen::Unaligned>;
template <class T>
using ConstVectorMap = Eigen::Map<const Vector<T>, Eigen::Unaligned>;
template <class T>
using RowVectorMap = Eigen::Map<RowVector<T>, Eigen::Unaligned>;
template <class T>
using ConstRowVectorMap = Eigen::Map<const RowVector<T>, Eigen::Unaligned>;

// A row-major matrix view with a row stride (e.g. one head's columns of a [L, 3*d] qkv buffer).
template <class T>
using StridedMatrixMap = Eigen::Map<Matrix<T>, Eigen::Unaligned, Eigen::OuterStride<>>;
template <class T>
using ConstStridedMatrixMap = Eigen::Map<const Matrix<T>, Eigen::Unaligned, Eigen::OuterStride<>>;

}  // namespace tjepa
