#pragma once
// A parallel sum whose result never depends on the thread count.
#include <algorithm>
#include <cstddef>
#include <vector>

#include "tjepa/core/detail/parallel.hpp"

namespace tjepa::detail {

// Σ_{i<n} term(i) in double: chunks of `chunk` terms are summed in parallel, each left to right,
// then the chunk sums left to right, so the result is bitwise the same on any number of threads.
template <class Term>
double deterministic_sum(std::size_t n, Term term, std::size_t chunk = 4096) {
  const std::size_t chunks = (n + chunk - 1) / chunk;
  std::vector<double> partial(chunks, 0.0);
  const auto count = static_cast<std::ptrdiff_t>(chunks);
  TJEPA_OMP(omp parallel for schedule(static) if (n > parallel_grain))
  for (std::ptrdiff_t c = 0; c < count; ++c) {
    const std::size_t begin = static_cast<std::size_t>(c) * chunk;
    const std::size_t end = std::min(n, begin + chunk);
    double s = 0.0;
    for (std::size_t i = begin; i < end; ++i) s += term(i);
    partial[static_cast<std::size_t>(c)] = s;
  }
  double total = 0.0;
  for (double p : partial) total += p;
  return total;
}

}  // namespace tjepa::detail
