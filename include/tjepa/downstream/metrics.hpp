#pragma once
// Evaluation metrics of downstream heads on held-out windows: RMSE per output column (force per
// axis, in the label's units) and classification accuracy; and the constant baseline every table
// scores first.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa {

// sqrt(mean_b (pred[b, j] − target[b, j])²) for each column j of pred [B, k] (row stride ld) and
// target [B, k] (dense). Summed in double.
template <class T, class U>
std::vector<double> rmse_per_column(const T* pred, std::size_t ld, const U* target, int B, int k) {
  require<ShapeError>(B > 0 && k > 0, "rmse_per_column: B = ", B, ", k = ", k, ", expected > 0");
  std::vector<double> s(static_cast<std::size_t>(k), 0.0);
  for (int b = 0; b < B; ++b)
    for (int j = 0; j < k; ++j) {
      const double e = static_cast<double>(pred[static_cast<std::size_t>(b) * ld + j]) -
                       static_cast<double>(target[static_cast<std::size_t>(b) * k + j]);
      s[static_cast<std::size_t>(j)] += e * e;
    }
  for (double& v : s) v = std::sqrt(v / B);
  return s;
}

// Index of the largest of z[0..C) (the first on ties).
template <class T>
int argmax(const T* z, int C) {
  int best = 0;
  for (int c = 1; c < C; ++c)
    if (z[c] > z[best]) best = c;
  return best;
}

// Fraction of rows of logits [B, C] (row stride ld) whose argmax is the label.
template <class T>
double accuracy(const T* logits, std::size_t ld, const int* labels, int B, int C) {
  require<ShapeError>(B > 0 && C > 0, "accuracy: B = ", B, ", C = ", C, ", expected > 0");
  int hit = 0;
  for (int b = 0; b < B; ++b) hit += argmax(logits + static_cast<std::size_t>(b) * ld, C) == labels[b];
  return static_cast<double>(hit) / B;
}

// Accuracy of always answering the most frequent label (the chance level to report beside it).
inline double majority_accuracy(const int* labels, int B, int C) {
  require<ShapeError>(B > 0 && C > 0, "majority_accuracy: B = ", B, ", C = ", C, ", expected > 0");
  std::vector<int> count(static_cast<std::size_t>(C), 0);
  for (int b = 0; b < B; ++b)
    if (labels[b] >= 0 && labels[b] < C) ++count[static_cast<std::size_t>(labels[b])];
  int best = 0;
  for (int c : count) best = std::max(best, c);
  return static_cast<double>(best) / B;
}

// The constant baseline: what predicts best while ignoring the input, fitted on the training
// samples: each regression column's mean and the most frequent class (the lowest id among ties).
// The protocol's "constant" row, `tjepa probe`'s and the label probe's all score these.
struct ConstantBaseline {
  std::vector<double> mean;  // [columns]: the training values' mean per column (summed in double)
  int majority = -1;         // the most frequent training class; -1 without classes
  int num_classes = 0;

  // values [S, columns] (columns 0: none); labels [S'] in [0, classes) (classes 0: none).
  static ConstantBaseline fit(std::span<const float> values, int columns, std::span<const int> labels, int classes) {
    require<ShapeError>(columns >= 0 && classes >= 0 && (columns == 0 || values.size() % std::size_t(columns) == 0),
                        "ConstantBaseline::fit: ", values.size(), " values in ", columns, " columns, ", classes,
                        " classes");
    ConstantBaseline c;
    if (columns > 0) {
      const std::size_t rows = values.size() / std::size_t(columns);
      require<DataError>(rows > 0, "ConstantBaseline::fit: no training values");
      c.mean.assign(std::size_t(columns), 0.0);
      for (std::size_t r = 0; r < rows; ++r)
        for (int j = 0; j < columns; ++j) c.mean[std::size_t(j)] += values[r * std::size_t(columns) + std::size_t(j)];
      for (double& m : c.mean) m /= static_cast<double>(rows);
    }
    if (classes > 0) {
      require<DataError>(!labels.empty(), "ConstantBaseline::fit: no training labels");
      std::vector<int> count(std::size_t(classes), 0);
      for (int l : labels) {
        require<DataError>(l >= 0 && l < classes, "ConstantBaseline::fit: class ", l, ", expected in [0, ", classes, ")");
        ++count[std::size_t(l)];
      }
      c.majority = static_cast<int>(std::max_element(count.begin(), count.end()) - count.begin());
      c.num_classes = classes;
    }
    return c;
  }

  // The predictions for `rows` samples: [rows, columns] values and [rows] classes.
  std::vector<double> values(std::size_t rows) const {
    std::vector<double> out;
    out.reserve(rows * mean.size());
    for (std::size_t r = 0; r < rows; ++r) out.insert(out.end(), mean.begin(), mean.end());
    return out;
  }
  std::vector<int> classes(std::size_t rows) const { return std::vector<int>(majority >= 0 ? rows : 0, majority); }
  // A head's outputs for `rows` samples: [rows, columns + classes], the values, then class scores
  // with 1 for the majority class and 0 for the others.
  std::vector<double> outputs(std::size_t rows) const {
    const std::size_t out = mean.size() + static_cast<std::size_t>(num_classes);
    std::vector<double> y(rows * out, 0.0);
    for (std::size_t r = 0; r < rows; ++r) {
      std::copy(mean.begin(), mean.end(), y.begin() + static_cast<std::ptrdiff_t>(r * out));
      if (majority >= 0) y[r * out + mean.size() + static_cast<std::size_t>(majority)] = 1.0;
    }
    return y;
  }
};

}  // namespace tjepa
