#pragma once
// Test helpers of the nn suite: the one central-difference gradient check every kernel and module
// test uses, random fills, and a one-thread scope for tiny models. Not a translation unit
// (tests/CMakeLists globs *.cpp only).
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include <tjepa/core/random.hpp>
#include <tjepa/core/param_set.hpp>
#include <tjepa/kernels/precision.hpp>

namespace tjepa::test {

inline constexpr double grad_tolerance = 1e-6;

template <class Vec>
void fill_normal(Vec& v, Rng& rng, double std = 1.0) {
  for (auto& x : v) x = static_cast<typename Vec::value_type>(rng.normal(0.0, std));
}
template <class T>
std::vector<T> random_vector(std::size_t n, Rng& rng, double std = 1.0) {
  std::vector<T> v(n);
  fill_normal(v, rng, std);
  return v;
}
// max |a − b| / max(1, max |b|): a fast kernel's output against its reference's.
template <class T>
double max_scaled_diff(const std::vector<T>& a, const std::vector<T>& b) {
  double d = 0, s = 1;
  for (std::size_t i = 0; i < a.size(); ++i) {
    d = std::max(d, std::abs(double(a[i]) - double(b[i])));
    s = std::max(s, std::abs(double(b[i])));
  }
  return d / s;
}
inline std::vector<double> normal_vector(std::size_t n, Rng& rng, double std = 1.0) {
  std::vector<double> v(n);
  fill_normal(v, rng, std);
  return v;
}
inline double dot(const double* a, const double* b, std::size_t n) {
  double s = 0;
  for (std::size_t i = 0; i < n; ++i) s += a[i] * b[i];
  return s;
}

// Relative error ‖a − n‖₂ / max(‖a‖₂, ‖n‖₂) between the analytic gradient `grad` of
// loss() = Σ w ⊙ out with respect to the `count` values at x, and central differences
// (loss(x + h) − loss(x − h)) / 2h. At most max_checks entries, spread over the tensor, are
// perturbed (each costs two forward passes). Returns 0 when both gradients vanish.
inline double gradient_error(double* x, const double* grad, std::size_t count, const std::function<double()>& loss,
                             std::size_t max_checks = 48, double h = 1e-5) {
  const std::size_t step = std::max<std::size_t>(1, count / max_checks);
  double diff = 0, na = 0, nn = 0;
  for (std::size_t i = (count / 2) % step; i < count; i += step) {
    const double x0 = x[i];
    x[i] = x0 + h;
    const double lp = loss();
    x[i] = x0 - h;
    const double lm = loss();
    x[i] = x0;
    const double num = (lp - lm) / (2 * h);
    diff += (num - grad[i]) * (num - grad[i]);
    na += grad[i] * grad[i];
    nn += num * num;
  }
  const double den = std::sqrt(std::max(na, nn));
  return den == 0 ? 0.0 : std::sqrt(diff) / den;
}

// gradient_error for every tensor of a ParamSet (its grads must hold the analytic gradient).
inline void check_param_gradients(ParamSet<double>& ps, const std::function<double()>& loss) {
  for (std::size_t i = 0; i < ps.count(); ++i) {
    const ParamId id = ps.id(i);
    const double err = gradient_error(ps.value(id), ps.grad(id), id.size, loss);
    INFO("parameter ", ps.infos()[i].name);
    CHECK(err < grad_tolerance);
  }
}

// Values of every tensor ~ N(0, std²): away from the degenerate init (LayerNorm 1/0, zero biases)
// so that every path of the gradient is exercised.
template <class T>
void randomize(ParamSet<T>& ps, std::uint64_t seed, double std = 0.3) {
  Rng rng(seed);
  for (std::size_t i = 0; i < ps.count(); ++i) {
    const double shift = ps.infos()[i].init == ParamInit::ones ? 1.0 : 0.0;
    for (auto& v : ps.value_span(ps.id(i))) v = T(shift + rng.normal(0.0, std));
  }
}

// Runs a scope on `threads` OpenMP threads (without OpenMP: on the one there is), then restores
// the count: tests that results do not depend on it run a computation under Threads(1), Threads(2).
struct Threads {
#if defined(_OPENMP)
  int previous = omp_get_max_threads();
  explicit Threads(int threads) { omp_set_num_threads(threads); }
  ~Threads() { omp_set_num_threads(previous); }
#else
  explicit Threads(int) {}
#endif
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;
};

// The bf16 product engines this machine can run: vdpbf16ps (AMX off), then AMX tiles where
// amx_available(). Amx(on) runs a scope with AMX switched on or off, then restores the switch.
inline std::vector<bool> amx_modes() { return amx_available() ? std::vector<bool>{false, true} : std::vector<bool>{false}; }
struct Amx {
  bool previous = amx_enabled();
  explicit Amx(bool on) { set_amx(on); }
  ~Amx() { set_amx(previous); }
  Amx(const Amx&) = delete;
  Amx& operator=(const Amx&) = delete;
};

// Runs a scope on one OpenMP thread: the tiny model's thousands of forward passes would spend
// their time in thread barriers (results do not depend on the thread count).
struct SingleThread : Threads {
  SingleThread() : Threads(1) {}
};

}  // namespace tjepa::test
