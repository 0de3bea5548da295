#pragma once
// Welch's unequal-variance t-test, one-sided, for comparing two encoders' scores over seeds (the
// paper's protocol: 3 pre-training seeds × 3 heads per encoder, the best two compared).
//
//   a [na], b [nb] scores;   mean, s² the sample mean and variance (n − 1 in the denominator)
//   se² = s_a²/na + s_b²/nb
//   t   = (mean_a − mean_b) / se
//   df  = se⁴ / ((s_a²/na)²/(na − 1) + (s_b²/nb)²/(nb − 1))      (Welch–Satterthwaite)
//   p   = P(T_df ≤ t)   for Alternative::less     H1: mean_a < mean_b (lower is better: RMSE)
//   p   = P(T_df ≥ t)   for Alternative::greater  H1: mean_a > mean_b (higher is better: accuracy)
// as scipy.stats.ttest_ind(a, b, equal_var=False, alternative=...). A small p says a is better.
//
// Zero variance (se = 0, every score of a equal, every score of b equal): the t statistic does not
// exist (scipy gives NaN); tjepa returns a defined result instead, so a results table never holds
// NaN: means that differ in the direction of H1 give t = ±inf and p = 0, in the other direction
// t = ∓inf and p = 1; equal means give t = 0, p = 0.5 (the limit at t = 0). df is then
// na + nb − 2 (Welch's df is 0/0).
//
// The Student-t CDF is F(t) = 1 − ½·I_x(df/2, ½) for t ≥ 0 with x = df/(df + t²) (and the mirror
// for t < 0), I the regularized incomplete beta function, evaluated by its continued fraction
// (modified Lentz), which converges fast for x < (a + 1)/(a + b + 2); otherwise the symmetry
// I_x(a, b) = 1 − I_{1−x}(b, a) is used. Non-integer df (Welch's) are fine.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>

#include "tjepa/core/error.hpp"

namespace tjepa {

enum class Alternative {
  less,    // H1: mean(a) < mean(b)
  greater  // H1: mean(a) > mean(b)
};

// Sample mean and standard deviation (n − 1 in the denominator; 0 when n = 1).
struct SampleSummary {
  double mean = 0, sd = 0;
  int n = 0;
};

inline SampleSummary summarize(std::span<const double> x) {
  require<DataError>(!x.empty(), "summarize: no values, expected at least 1");
  SampleSummary s;
  s.n = static_cast<int>(x.size());
  for (double v : x) {
    require<DataError>(std::isfinite(v), "summarize: value ", v, ", expected finite");
    s.mean += v;
  }
  s.mean /= s.n;
  double q = 0;
  for (double v : x) q += (v - s.mean) * (v - s.mean);
  s.sd = s.n > 1 ? std::sqrt(q / (s.n - 1)) : 0.0;
  return s;
}

namespace detail {
// The continued fraction of I_x(a, b) (Numerical Recipes' betacf) by the modified Lentz method:
// I_x(a, b) = x^a (1 − x)^b / (a B(a, b)) · 1/(1+ d1/(1+ d2/(1+ ...))).
inline double beta_continued_fraction(double a, double b, double x) {
  constexpr double tiny = 1e-300, eps = 1e-15;
  constexpr int max_iter = 10000;
  const double qab = a + b, qap = a + 1, qam = a - 1;
  double c = 1, d = 1 - qab * x / qap;
  if (std::fabs(d) < tiny) d = tiny;
  d = 1 / d;
  double h = d;
  for (int m = 1; m <= max_iter; ++m) {
    const int m2 = 2 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));  // even step d_{2m}
    d = 1 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));  // odd step d_{2m+1}
    d = 1 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1) < eps) return h;
  }
  fail<NumericError>("regularized_incomplete_beta: no convergence at a = ", a, ", b = ", b, ", x = ", x);
}
}  // namespace detail

namespace detail {
// I_x(a, b) with y = 1 − x given separately (exact where x is close to 1).
inline double incomplete_beta(double a, double b, double x, double y) {
  if (x == 0) return 0;
  if (y == 0) return 1;
  // log of x^a (1 − x)^b / B(a, b)
  const double log_front = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) + b * std::log(y);
  if (x < (a + 1) / (a + b + 2)) return std::exp(log_front) * beta_continued_fraction(a, b, x) / a;
  return 1 - std::exp(log_front) * beta_continued_fraction(b, a, y) / b;
}
}  // namespace detail

// I_x(a, b) = B(x; a, b) / B(a, b), a > 0, b > 0, x ∈ [0, 1]. The continued fraction needs about
// √max(a, b) terms near the distribution's mean: fine to a, b ~ 1e7.
inline double regularized_incomplete_beta(double a, double b, double x) {
  require<ConfigError>(a > 0 && b > 0 && std::isfinite(a) && std::isfinite(b), "regularized_incomplete_beta: a = ",
                       a, ", b = ", b, ", expected finite > 0");
  require<ConfigError>(x >= 0 && x <= 1, "regularized_incomplete_beta: x = ", x, ", expected in [0, 1]");
  return detail::incomplete_beta(a, b, x, 1 - x);
}

// Above this df, student_t_cdf is the normal CDF: the difference is below 1e-8 (it shrinks as
// 1/df) and the continued fraction would need ever more terms.
inline constexpr double student_t_normal_df = 1e7;

// P(T ≤ t) for Student's t with df > 0 degrees of freedom (df need not be an integer).
inline double student_t_cdf(double t, double df) {
  require<ConfigError>(df > 0 && !std::isnan(df), "student_t_cdf: df = ", df, ", expected > 0");
  require<ConfigError>(!std::isnan(t), "student_t_cdf: t is NaN");
  if (std::isinf(t)) return t > 0 ? 1.0 : 0.0;
  if (df > student_t_normal_df) return 0.5 * std::erfc(-t / std::sqrt(2.0));
  // One tail P(T > |t|) = ½ I_x(df/2, ½), x = df/(df + t²), 1 − x = t²/(df + t²), both written
  // without t² (which overflows for huge t).
  const double r = std::fabs(t) / std::sqrt(df);  // t² / df = r²
  const double x = r > 1 ? 1 / r / (r + 1 / r) : 1 / (1 + r * r);
  const double y = r > 1 ? 1 / (1 + 1 / (r * r)) : r * r / (1 + r * r);
  const double tail = 0.5 * detail::incomplete_beta(0.5 * df, 0.5, x, y);
  return t >= 0 ? 1 - tail : tail;
}

struct WelchResult {
  double t = 0;   // (mean_a − mean_b) / se
  double df = 0;  // Welch–Satterthwaite degrees of freedom
  double p = 0;   // one-sided p-value for the chosen alternative
};

// One-sided Welch test of H1 (see Alternative) against H0: equal means. Each sample needs at
// least 2 finite values (else DataError). Zero variance: see the top of this file.
inline WelchResult welch_t_test(std::span<const double> a, std::span<const double> b,
                                Alternative alternative = Alternative::less) {
  require<DataError>(a.size() >= 2, "welch_t_test: a has ", a.size(), " values, expected at least 2");
  require<DataError>(b.size() >= 2, "welch_t_test: b has ", b.size(), " values, expected at least 2");
  const SampleSummary sa = summarize(a), sb = summarize(b);
  const double va = sa.sd * sa.sd / sa.n, vb = sb.sd * sb.sd / sb.n;  // squared standard errors
  const double se2 = va + vb, diff = sa.mean - sb.mean;
  const double sign = alternative == Alternative::less ? 1.0 : -1.0;  // H1: sign·diff < 0
  WelchResult r;
  if (se2 == 0) {
    r.df = sa.n + sb.n - 2;
    if (diff == 0) {
      r.t = 0;
      r.p = 0.5;
    } else {
      r.t = diff > 0 ? std::numeric_limits<double>::infinity() : -std::numeric_limits<double>::infinity();
      r.p = sign * diff < 0 ? 0.0 : 1.0;
    }
    return r;
  }
  r.t = diff / std::sqrt(se2);
  r.df = se2 * se2 / (va * va / (sa.n - 1) + vb * vb / (sb.n - 1));
  r.p = alternative == Alternative::less ? student_t_cdf(r.t, r.df) : student_t_cdf(-r.t, r.df);
  return r;
}

}  // namespace tjepa
