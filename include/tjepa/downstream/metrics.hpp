#pragma once
// Evaluation metrics of downstream heads on held-out windows: RMSE per output column (force per
// axis, in the label's units) and classification accuracy.
#include <cmath>
#include <cstddef>
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

}  // namespace tjepa
