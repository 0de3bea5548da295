#pragma once
// OpenMP without the dependency: TJEPA_OMP(parallel for) expands to `#pragma omp parallel for`
// when the compiler runs with OpenMP, and to nothing otherwise (so -Wunknown-pragmas stays quiet).
//
// Results never depend on the thread count: element-wise loops are split however OpenMP likes,
// and reductions go through deterministic_sum, which adds fixed-size chunks in a fixed order.
#include <algorithm>
#include <cstddef>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#define TJEPA_DETAIL_PRAGMA(x) _Pragma(#x)
#define TJEPA_OMP(directive) TJEPA_DETAIL_PRAGMA(omp directive)
#else
#define TJEPA_OMP(directive)
#endif

namespace tjepa {

// Threads a parallel region would use (1 without OpenMP).
inline int max_threads() {
#if defined(_OPENMP)
  return omp_get_max_threads();
#else
  return 1;
#endif
}

// Σ_{i<n} term(i) in double, bitwise the same for any thread count: chunks of `chunk` terms are
// summed in parallel, each left to right, then the chunk sums left to right.
template <class Term>
double deterministic_sum(std::size_t n, Term term, std::size_t chunk = 4096) {
  const std::size_t chunks = (n + chunk - 1) / chunk;
  std::vector<double> partial(chunks, 0.0);
  const auto count = static_cast<std::ptrdiff_t>(chunks);
  TJEPA_OMP(parallel for schedule(static))
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

}  // namespace tjepa
