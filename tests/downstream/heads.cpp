// Evaluation building blocks of the downstream protocol: Welch's one-sided t-test (the Student-t
// CDF against closed forms and table quantiles), the ridge baseline on hand-crafted features,
// attentive-probe heads with early stopping (downstream/early_stopping.hpp: the split, patience,
// the best epoch restored), and the sequence head (gradients against central differences, which
// include downstream/causal_attention.hpp's parameters and inputs; causal attention against a
// plain-loop reference; training).
#include <doctest/doctest.h>

#include <tjepa/sim.hpp>
#include <tjepa/tjepa.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <tuple>
#include <type_traits>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <vector>

#include "../support/gradcheck.hpp"
#include "../support/files.hpp"

using namespace tjepa;

TEST_SUITE("downstream") {

// A linear head y = w·x on 40 samples of 4 features, early-stopped by the Trainer: a
// HeadObjective of the test's own (forward, backward, validate).
struct LinearHeadRun {
  std::vector<double> x, y;
  ParamSet<double> params;
  ParamId w;
  std::vector<double> residual;
  std::span<const std::int64_t> batch;
  explicit LinearHeadRun(std::uint64_t init) {
    Rng rng(4);
    for (int i = 0; i < 40; ++i) {
      double t = 0;
      for (int k = 0; k < 4; ++k) x.push_back(rng.normal()), t += (k + 1) * x.back();
      y.push_back(t + 0.3 * rng.normal());
    }
    w = params.add("weight", {4});
    params.allocate();
    Rng r(init);
    for (auto& v : params.values()) v = r.normal();
  }
  double mse(std::span<const std::int64_t> ids, bool keep) {
    double l = 0;
    if (keep) residual.assign(ids.size(), 0.0), batch = ids;
    for (std::size_t i = 0; i < ids.size(); ++i) {
      double p = 0;
      for (int k = 0; k < 4; ++k) p += params.value(w)[k] * x[static_cast<std::size_t>(ids[i]) * 4 + k];
      const double e = p - y[static_cast<std::size_t>(ids[i])];
      l += e * e / static_cast<double>(ids.size());
      if (keep) residual[i] = e;
    }
    return l;
  }
  void backward() {
    for (std::size_t i = 0; i < batch.size(); ++i)
      for (int k = 0; k < 4; ++k)
        params.grad(w)[k] += 2 * residual[i] * x[static_cast<std::size_t>(batch[i]) * 4 + k] / static_cast<double>(batch.size());
  }
  Trainer<HeadObjective<double>>* make(std::unique_ptr<Trainer<HeadObjective<double>>>& t, const HeadTrainConfig& c,
                                       const ValidationSplit& split) {
    t = std::make_unique<Trainer<HeadObjective<double>>>(
        std::vector<PrefixedParams<double>>{{"head.", &params}}, split.fit, c,
        [this](std::span<const std::int64_t> ids) { return mse(ids, true); }, [this] { backward(); },
        [this, split] { return mse(split.validation, false); });
    return t.get();
  }
};

TEST_CASE("an early-stopped head through the Trainer: save mid-epoch then resume is bitwise the whole run") {
  const HeadTrainConfig cfg{.max_epochs = 40, .patience = 3, .batch = 8, .lr = 0.05, .seed = 1};
  const ValidationSplit split = split_for_validation(40, cfg.validation_fraction, cfg.seed);
  std::unique_ptr<Trainer<HeadObjective<double>>> t1, t2, t3;
  LinearHeadRun straight(1);
  straight.make(t1, cfg, split)->run();
  const EarlyStoppingRecord& r = t1->record();
  REQUIRE(r.epochs() >= 2);
  CHECK(t1->stopped_early() == (r.epochs() < cfg.max_epochs));
  const auto best = std::min_element(r.validation_loss.begin(), r.validation_loss.end());
  CHECK(r.best_epoch == best - r.validation_loss.begin());
  CHECK(straight.mse(split.validation, false) == r.best_validation);  // the best epoch's parameters restored

  const std::filesystem::path ckpt = std::filesystem::temp_directory_path() / "tjepa_head_resume.safetensors";
  LinearHeadRun first(1);
  Trainer<HeadObjective<double>>* a = first.make(t2, cfg, split);
  a->checkpoint = ckpt;
  a->checkpoint_every = 3;  // 32 fitting samples: 4 steps per epoch, so step 6 is mid-epoch 1
  a->run(7);
  LinearHeadRun resumed(99);  // another init: everything comes from the file
  Trainer<HeadObjective<double>>* b = resumed.make(t3, cfg, split);
  b->resume(ckpt);
  CHECK(b->step() == 6);
  CHECK(b->record().epochs() == 1);
  b->run();
  CHECK(b->record().validation_loss == r.validation_loss);
  CHECK(b->record().train_loss == r.train_loss);
  CHECK(b->record().best_epoch == r.best_epoch);
  CHECK(std::ranges::equal(resumed.params.values(), straight.params.values()));
  const nlohmann::json meta = nlohmann::json::parse(load_safetensors(ckpt).metadata.at("config"));
  CHECK(meta["objective"] == "head");
  std::filesystem::remove(ckpt);
  // A head has no all_reduce: the Trainer refuses to run it data parallel.
  LinearHeadRun sharded(1);
  Trainer<HeadObjective<double>>* c = sharded.make(t1, cfg, split);
  c->parallel.ranks = 2;
  CHECK_THROWS_WITH_AS(c->run(1), doctest::Contains("cannot run data parallel"), ConfigError);
}

TEST_CASE("student_t_cdf: closed forms at df 1 2 3 4 and table quantiles") {
  const double pi = std::numbers::pi;
  for (double t : {-30.0, -3.0, -1.0, -0.2, 0.0, 0.5, 1.7, 4.0, 25.0}) {
    INFO("t = ", t);
    CHECK(student_t_cdf(t, 1) == doctest::Approx(0.5 + std::atan(t) / pi).epsilon(1e-12));  // Cauchy
    CHECK(student_t_cdf(t, 2) == doctest::Approx(0.5 + t / (2 * std::sqrt(2 + t * t))).epsilon(1e-12));
    const double u = t / std::sqrt(3.0);
    CHECK(student_t_cdf(t, 3) == doctest::Approx(0.5 + (u / (1 + u * u) + std::atan(u)) / pi).epsilon(1e-12));
    const double w = 1 + t * t / 4;
    CHECK(student_t_cdf(t, 4) ==
          doctest::Approx(0.5 + 0.375 * t / std::sqrt(w) * (1 - t * t / (12 * w))).epsilon(1e-12));
    CHECK(student_t_cdf(-t, 7.3) == doctest::Approx(1 - student_t_cdf(t, 7.3)).epsilon(1e-13));
  }
  // Upper quantiles of Student's t tables (three decimals): one-sided p at the quantile.
  CHECK(1 - student_t_cdf(2.015, 5) == doctest::Approx(0.05).epsilon(2e-3));
  CHECK(1 - student_t_cdf(1.812, 10) == doctest::Approx(0.05).epsilon(2e-3));
  CHECK(1 - student_t_cdf(2.764, 10) == doctest::Approx(0.01).epsilon(2e-3));
  CHECK(1 - student_t_cdf(12.706, 1) == doctest::Approx(0.025).epsilon(1e-4));
  CHECK(1 - student_t_cdf(63.657, 1) == doctest::Approx(0.005).epsilon(1e-4));
  CHECK(1 - student_t_cdf(2.086, 20) == doctest::Approx(0.025).epsilon(2e-3));
  // Large df: the normal distribution.
  CHECK(student_t_cdf(1.959963984540054, 1e9) == doctest::Approx(0.975).epsilon(1e-8));
  CHECK(student_t_cdf(1.959963984540054, INFINITY) == doctest::Approx(0.975).epsilon(1e-12));
  CHECK(student_t_cdf(1.959963984540054, 5e6) == doctest::Approx(0.975).epsilon(1e-7));
  CHECK(student_t_cdf(1.959963984540054, 5e6) < student_t_cdf(1.959963984540054, 2e7));
  // Tiny df and far tails stay in [0, 1] and monotone.
  CHECK(student_t_cdf(1e6, 0.3) <= 1.0);
  CHECK(student_t_cdf(1e6, 0.3) > student_t_cdf(1e3, 0.3));
  CHECK(student_t_cdf(-1e6, 0.3) >= 0.0);
  CHECK_THROWS_AS(student_t_cdf(1.0, 0.0), ConfigError);
  CHECK_THROWS_AS(student_t_cdf(NAN, 3.0), ConfigError);
}

TEST_CASE("regularized_incomplete_beta: closed forms with non-integer parameters") {
  for (double x : {0.0, 0.01, 0.3, 0.5, 0.77, 0.999, 1.0}) {
    INFO("x = ", x);
    CHECK(regularized_incomplete_beta(1.0, 2.5, x) == doctest::Approx(1 - std::pow(1 - x, 2.5)).epsilon(1e-12));
    CHECK(regularized_incomplete_beta(3.7, 1.0, x) == doctest::Approx(std::pow(x, 3.7)).epsilon(1e-12));
    CHECK(regularized_incomplete_beta(0.5, 0.5, x) ==
          doctest::Approx(2 / std::numbers::pi * std::asin(std::sqrt(x))).epsilon(1e-12));
  }
  CHECK_THROWS_AS(regularized_incomplete_beta(0.0, 1.0, 0.5), ConfigError);
  CHECK_THROWS_AS(regularized_incomplete_beta(1.0, 1.0, 1.5), ConfigError);
}

TEST_CASE("welch_t_test: statistic and df by hand and both alternatives") {
  const std::vector<double> a{1, 2, 3, 4}, b{3, 5, 7};
  // mean 2.5, s² 5/3 over 4; mean 5, s² 4 over 3
  const double va = 5.0 / 3 / 4, vb = 4.0 / 3, se2 = va + vb;
  const double t = (2.5 - 5) / std::sqrt(se2), df = se2 * se2 / (va * va / 3 + vb * vb / 2);
  const WelchResult less = welch_t_test(a, b, Alternative::less);
  CHECK(less.t == doctest::Approx(t).epsilon(1e-14));
  CHECK(less.df == doctest::Approx(df).epsilon(1e-14));
  CHECK(less.df == doctest::Approx(3.2347).epsilon(1e-4));
  CHECK(less.p == doctest::Approx(student_t_cdf(t, df)).epsilon(1e-14));
  // df lies between 3 and 4: so does the p-value between the integer-df closed forms.
  const double p3 = student_t_cdf(t, 3), p4 = student_t_cdf(t, 4);
  CHECK(less.p < p3);
  CHECK(less.p > p4);
  CHECK(less.p > 0.05);
  CHECK(less.p < 0.1);
  const WelchResult greater = welch_t_test(a, b, Alternative::greater);
  CHECK(greater.t == less.t);
  CHECK(greater.p == doctest::Approx(1 - less.p).epsilon(1e-12));
  // Swapping the samples mirrors t.
  const WelchResult swapped = welch_t_test(b, a, Alternative::greater);
  CHECK(swapped.t == doctest::Approx(-t).epsilon(1e-14));
  CHECK(swapped.p == doctest::Approx(less.p).epsilon(1e-12));
  // Equal variances and sizes: Welch's df is 2(n − 1).
  const WelchResult eq = welch_t_test(std::vector<double>{1, 2, 3}, std::vector<double>{2, 3, 4});
  CHECK(eq.df == doctest::Approx(4.0).epsilon(1e-14));
  CHECK(eq.t == doctest::Approx(-1 / std::sqrt(2.0 / 3)).epsilon(1e-14));
  const SampleSummary s = summarize(a);
  CHECK(s.mean == 2.5);
  CHECK(s.sd == doctest::Approx(std::sqrt(5.0 / 3)).epsilon(1e-15));
}

TEST_CASE("welch_t_test: equal samples and zero variance give defined results") {
  const std::vector<double> a{0.3, 0.5, 0.4};
  const WelchResult same = welch_t_test(a, a);
  CHECK(same.t == 0.0);
  CHECK(same.p == doctest::Approx(0.5).epsilon(1e-14));
  const std::vector<double> c1{1, 1, 1}, c2{2, 2, 2};
  const WelchResult lo = welch_t_test(c1, c2, Alternative::less);
  CHECK(std::isinf(lo.t));
  CHECK(lo.t < 0);
  CHECK(lo.p == 0.0);
  CHECK(lo.df == 4.0);
  CHECK(welch_t_test(c1, c2, Alternative::greater).p == 1.0);
  CHECK(welch_t_test(c2, c1, Alternative::greater).p == 0.0);
  CHECK(welch_t_test(c1, c1).p == 0.5);
  // One sample constant: df is the other's n − 1.
  const WelchResult one = welch_t_test(c1, std::vector<double>{1, 2, 3, 4});
  CHECK(one.df == doctest::Approx(3.0).epsilon(1e-14));
  CHECK_THROWS_AS(welch_t_test(std::vector<double>{1}, c2), DataError);
  CHECK_THROWS_AS(welch_t_test(c1, std::vector<double>{1, NAN}), DataError);
}

TEST_CASE("window_features: pad sums and taxel means per axis") {
  // 2 windows, 3 taxels in groups {0, 1, 0}, 2 frames, 2 axes; x[b, n, t, a] = 100b + 10n + t + 0.5a.
  WindowBatch wb;
  std::tie(wb.batch, wb.taxels, wb.length, wb.axes) = std::tuple{2, 3, 2, 2};
  wb.x.resize(24);
  for (int b = 0; b < 2; ++b)
    for (int n = 0; n < 3; ++n)
      for (int t = 0; t < 2; ++t)
        for (int a = 0; a < 2; ++a) wb.x[((b * 3 + n) * 2 + t) * 2 + a] = float(100 * b + 10 * n + t + 0.5 * a);
  const std::vector<int> group{0, 1, 0};
  const Eigen::MatrixXd f = window_features(wb, group, 2);
  REQUIRE(f.rows() == 2);
  REQUIRE(f.cols() == 2 * 2 + 3 * 2);
  for (int b = 0; b < 2; ++b)
    for (int a = 0; a < 2; ++a) {
      auto mean = [&](int n) { return 100.0 * b + 10 * n + 0.5 + 0.5 * a; };
      CHECK(f(b, 0 * 2 + a) == doctest::Approx(mean(0) + mean(2)));
      CHECK(f(b, 1 * 2 + a) == doctest::Approx(mean(1)));
      for (int n = 0; n < 3; ++n) CHECK(f(b, 4 + n * 2 + a) == doctest::Approx(mean(n)));
    }
  CHECK_THROWS_AS(window_features(wb, std::vector<int>{0, 1}, 2), ShapeError);
  CHECK_THROWS_AS(window_features(wb, std::vector<int>{0, 2, 0}, 2), DataError);
}

TEST_CASE("group_mean_embeddings: each group's mean token embedding for the rows asked for") {
  // 3 samples, 4 tokens in groups {1, 0, 1, 1}, d = 2; x[s, n, i] = 100s + 10n + i.
  const int S = 3, N = 4, d = 2;
  std::vector<float> x(static_cast<std::size_t>(S) * N * d);
  for (int s = 0; s < S; ++s)
    for (int n = 0; n < N; ++n)
      for (int i = 0; i < d; ++i) x[static_cast<std::size_t>((s * N + n) * d + i)] = float(100 * s + 10 * n + i);
  const std::vector<int> group{1, 0, 1, 1};
  const std::vector<std::int64_t> rows{2, 0};
  const Eigen::MatrixXd f = group_mean_embeddings(x, N, d, rows, group, 2);
  REQUIRE(f.rows() == 2);
  REQUIRE(f.cols() == 2 * d);
  for (int r = 0; r < 2; ++r)
    for (int i = 0; i < d; ++i) {
      const double base = 100.0 * rows[static_cast<std::size_t>(r)] + i;
      CHECK(f(r, i) == doctest::Approx(base + 10));                      // group 0: token 1
      CHECK(f(r, d + i) == doctest::Approx(base + 10.0 * (0 + 2 + 3) / 3));  // group 1: tokens 0, 2, 3
    }
  CHECK_THROWS_WITH_AS(group_mean_embeddings(x, N, d, rows, group, 3), doctest::Contains("group 2 has no token"), DataError);
  CHECK_THROWS_WITH_AS(group_mean_embeddings(x, N, d, std::vector<std::int64_t>{3}, group, 2), doctest::Contains("row 3"),
                       DataError);
  CHECK_THROWS_AS(group_mean_embeddings(x, N, d, rows, std::vector<int>{1, 0, 1}, 2), ShapeError);
  CHECK_THROWS_AS(group_mean_embeddings(x, N, 5, rows, group, 2), ShapeError);  // 24 values, not [S, 4, 5]
  CHECK_THROWS_AS(group_mean_embeddings(x, N, d, rows, std::vector<int>{1, 0, 2, 1}, 2), DataError);
}

TEST_CASE("TokenComponents: per-token residuals on the leading principal directions") {
  // Embeddings x[s, n] = μ_n + a_s,n u + b_s,n v with orthonormal u, v in R^4, var(a) > var(b):
  // the two directions span {u, v}, the first holds the larger variance, the shares sum to 1, and
  // each token's residual from its mean is rebuilt exactly from its two features.
  const int S = 40, N = 3, d = 4;
  Rng rng(11);
  const Eigen::Vector4d u = Eigen::Vector4d(1, 1, 0, 0) / std::sqrt(2.0), v = Eigen::Vector4d(0, 0, 1, -1) / std::sqrt(2.0);
  std::vector<float> x(static_cast<std::size_t>(S) * N * d);
  for (int s = 0; s < S; ++s)
    for (int n = 0; n < N; ++n) {
      const double a = 3.0 * rng.normal(0.0, 1.0), b = 0.5 * rng.normal(0.0, 1.0);
      for (int i = 0; i < d; ++i)
        x[static_cast<std::size_t>((s * N + n) * d + i)] = float(10.0 * n - i + a * u(i) + b * v(i));
    }
  std::vector<std::int64_t> rows(S);
  for (int s = 0; s < S; ++s) rows[static_cast<std::size_t>(s)] = s;
  const TokenComponents t = TokenComponents::fit(x, N, d, rows, 2);
  REQUIRE(t.components() == 2);
  for (int j = 0; j < 2; ++j) {
    const Eigen::Vector4d e = t.directions.col(j);
    CHECK(std::hypot(e.dot(u), e.dot(v)) == doctest::Approx(1).epsilon(1e-5));  // in span {u, v}
  }
  CHECK(std::abs(t.directions.col(0).dot(u)) > 0.99);  // mostly u: var(a) = 36 var(b)
  CHECK(t.variance_share.sum() == doctest::Approx(1).epsilon(1e-5));
  CHECK(t.variance_share(0) > t.variance_share(1));
  const std::vector<std::int64_t> pick{5, 17};
  const Eigen::MatrixXd f = t.features(x, pick);
  REQUIRE(f.rows() == 2);
  REQUIRE(f.cols() == N * 2);
  for (int r = 0; r < 2; ++r)
    for (int n = 0; n < N; ++n) {
      const Eigen::Vector4d rebuilt = t.directions * f.row(r).segment(n * 2, 2).transpose();
      for (int i = 0; i < d; ++i) {
        const double xi = x[static_cast<std::size_t>((pick[static_cast<std::size_t>(r)] * N + n) * d + i)];
        CHECK(rebuilt(i) == doctest::Approx(xi - t.mean(n, i)).epsilon(1e-4));
      }
    }
  CHECK_THROWS_WITH_AS(TokenComponents::fit(x, N, d, rows, 5), doctest::Contains("k = 5"), ConfigError);
  CHECK_THROWS_AS(TokenComponents::fit(x, N, d, std::vector<std::int64_t>{1}, 2), DataError);
  CHECK_THROWS_WITH_AS(t.features(x, std::vector<std::int64_t>{S}), doctest::Contains("row 40"), DataError);
  const std::vector<float> flat(x.size(), 1.0f);
  CHECK_THROWS_WITH_AS(TokenComponents::fit(flat, N, d, rows, 2), doctest::Contains("do not vary"), DataError);
}

namespace {
// n rows of p features ~ N(mean_j, scale_j²) (scales and offsets differ, to exercise the
// standardization).
Eigen::MatrixXd random_features(int n, int p, Rng& rng) {
  Eigen::MatrixXd X(n, p);
  for (int j = 0; j < p; ++j)
    for (int i = 0; i < n; ++i) X(i, j) = 3.0 * j - 2 + (0.5 + j) * rng.normal(0.0, 1.0);
  return X;
}
}  // namespace

TEST_CASE("fit_ridge: recovers a known linear map and picks the small lambda without noise") {
  Rng rng(5);
  const int n = 80, p = 6, k = 3;
  const Eigen::MatrixXd X = random_features(n, p, rng);
  Eigen::MatrixXd W(p, k);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < k; ++j) W(i, j) = rng.normal(0.0, 1.0);
  const Eigen::RowVectorXd b = Eigen::RowVectorXd::LinSpaced(k, -1.0, 2.0);
  const Eigen::MatrixXd Y = (X * W).rowwise() + b;
  const std::vector<double> lambdas{10.0, 1e-8, 1.0, 1e-3};
  const RidgeModel m = fit_ridge(X, Y, lambdas, 0.25, 1);
  CHECK(m.lambda == 1e-8);
  REQUIRE(m.validation.size() == 4);
  CHECK(m.validation[1] < m.validation[3]);
  CHECK(m.validation[3] < m.validation[2]);
  CHECK(m.validation[2] < m.validation[0]);
  const Eigen::MatrixXd Xt = random_features(20, p, rng);
  const Eigen::MatrixXd Yt = (Xt * W).rowwise() + b;
  CHECK((predict(m, Xt) - Yt).cwiseAbs().maxCoeff() < 1e-6);
  // Same seed, same model; the dual form (more features than rows) solves the same problem.
  const RidgeModel again = fit_ridge(X, Y, lambdas, 0.25, 1);
  CHECK(again.weight == m.weight);
  const Eigen::MatrixXd Xw = random_features(10, 30, rng);
  const Eigen::MatrixXd Yw = random_features(10, 2, rng);
  const RidgeModel dual = fit_ridge_at(Xw, Yw, 0.7);
  const Eigen::MatrixXd Z = (Xw.rowwise() - dual.mean).array().rowwise() / dual.scale.array();
  Eigen::MatrixXd A = Z.transpose() * Z;
  A.diagonal().array() += 0.7;
  const Eigen::MatrixXd primal = A.ldlt().solve(Z.transpose() * (Yw.rowwise() - dual.bias));
  CHECK((dual.weight - primal).cwiseAbs().maxCoeff() < 1e-9);
  // A constant feature is left unscaled and gets no weight.
  Eigen::MatrixXd Xc = X;
  Xc.col(2).setConstant(4.0);
  const RidgeModel c = fit_ridge_at(Xc, Y, 1.0);
  CHECK(c.scale(2) == 1.0);
  CHECK(c.weight.row(2).cwiseAbs().maxCoeff() == 0.0);
  CHECK_THROWS_AS(fit_ridge(X, Y, std::vector<double>{}, 0.25, 1), ConfigError);
  CHECK_THROWS_AS(fit_ridge(X, Y, lambdas, 1.0, 1), ConfigError);
  CHECK_THROWS_AS(fit_ridge(X, Y, std::vector<double>{0.0}, 0.25, 1), ConfigError);
  CHECK_THROWS_AS(fit_ridge(X, Y.topRows(10), lambdas, 0.25, 1), ShapeError);
  // With groups, λ is scored on held-out whole groups (split_by_groups), by hand here.
  SampleGroups g;
  for (int i = 0; i < n; ++i) {
    g.group.push_back(i / 8);        // 10 groups of 8 rows
    g.stratum.push_back(i / 8 % 2);  // 2 strata
  }
  const Eigen::MatrixXd Yn = Y + 0.5 * random_features(n, k, rng);
  const RidgeModel grouped = fit_ridge(X, Yn, lambdas, 0.25, 1, g);
  const ValidationSplit split = split_by_groups(g, 0.25, 1);
  auto rows = [](const Eigen::MatrixXd& M, const std::vector<std::int64_t>& ids) {
    Eigen::MatrixXd out(static_cast<Eigen::Index>(ids.size()), M.cols());
    for (std::size_t i = 0; i < ids.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = M.row(ids[i]);
    return out;
  };
  REQUIRE(grouped.validation.size() == lambdas.size());
  for (std::size_t j = 0; j < lambdas.size(); ++j) {
    const RidgeModel f = fit_ridge_at(rows(X, split.fit), rows(Yn, split.fit), lambdas[j]);
    const Eigen::MatrixXd e = predict(f, rows(X, split.validation)) - rows(Yn, split.validation);
    CHECK(grouped.validation[j] == doctest::Approx(e.squaredNorm() / static_cast<double>(e.size())).epsilon(1e-12));
  }
  CHECK_THROWS_AS(fit_ridge(X, Y, lambdas, 0.25, 1, SampleGroups{{1, 2}, {}, {}}), ShapeError);
}

TEST_CASE("fit_ridge_classifier: separable classes by argmax of one-hot ridge") {
  Rng rng(9);
  const int n = 90, p = 4, C = 3;
  Eigen::MatrixXd X(n, p);
  std::vector<int> y(n);
  for (int i = 0; i < n; ++i) {
    y[i] = i % C;
    for (int j = 0; j < p; ++j) X(i, j) = rng.normal(0.0, 0.3) + (j == y[i] ? 4.0 : 0.0);
  }
  const std::vector<double> lambdas{1e-3, 1.0, 100.0};
  const RidgeModel m = fit_ridge_classifier(X, y, C, lambdas, 0.2, 3);
  CHECK(m.outputs() == C);
  for (double v : m.validation) CHECK(v < 1.0 / 18);  // no validation error at any lambda
  const std::vector<int> c = predict_class(m, X);
  int hit = 0;
  for (int i = 0; i < n; ++i) hit += c[i] == y[i];
  CHECK(hit == n);
  y[0] = 3;
  CHECK_THROWS_AS(fit_ridge_classifier(X, y, C, lambdas, 0.2, 3), DataError);
}

namespace {
// S samples of L tokens whose direction encodes two regression targets (F, 2F − 3) and a class
// (a LayerNorm comes first in the probe: the information is in the direction, not the scale).
struct EncodedSamples {
  AlignedVector<float> x;  // [S, L, d]
  HeadTargets targets;
};
EncodedSamples encoded_samples(int S, int L, int d, std::uint64_t seed, bool random_targets = false) {
  Rng rng(seed);
  EncodedSamples e{AlignedVector<float>(static_cast<std::size_t>(S) * L * d, 0.0f), {2, 4, {}, {}, {}}};
  for (int i = 0; i < S; ++i) {
    const float F = static_cast<float>(rng.uniform(0, 10));
    const int cls = static_cast<int>(rng.below(4));
    for (int l = 0; l < L; ++l) {
      float* t = e.x.data() + (static_cast<std::size_t>(i) * L + l) * d;
      t[0] = F + static_cast<float>(rng.normal(0.0, 0.1));
      t[1] = 10.0f - F;
      t[2 + cls] = 10.0f;
      t[6 + l % (d - 6)] += 1.0f;
    }
    const float G = random_targets ? static_cast<float>(rng.normal(0.0, 3.0)) : 2 * F - 3;
    e.targets.value.insert(e.targets.value.end(), {random_targets ? static_cast<float>(rng.uniform(0, 10)) : F, G});
    e.targets.label.push_back(random_targets ? static_cast<int>(rng.below(4)) : cls);
  }
  return e;
}

HeadTrainConfig train_config(int max_epochs, int patience, int batch, double lr) {
  HeadTrainConfig c;
  c.max_epochs = max_epochs;
  c.patience = patience;
  c.batch = batch;
  c.lr = lr;
  return c;
}
}  // namespace

TEST_CASE("train_head: learns regression and classes with early stopping and restores the best epoch") {
  const int S = 160, L = 2, d = 12;
  const auto [x, targets] = encoded_samples(S, L, d, 4);
  FrozenFeatures<float> f(x, L, d);
  HeadTrainConfig cfg = train_config(60, 8, 16, 1e-2);
  ProbeHead<float> head(d, 3, 2, 4, 0);
  CHECK(head.params.contains("probe.head.fc2.weight"));
  const HeadTrainResult r = train_head(head, f, targets, cfg);
  REQUIRE(r.epochs() >= 1);
  CHECK(r.epochs() <= cfg.max_epochs);
  CHECK(r.train_loss.size() == r.validation_loss.size());
  const auto best = std::min_element(r.validation_loss.begin(), r.validation_loss.end());
  CHECK(r.best_epoch == best - r.validation_loss.begin());
  CHECK(r.best_validation == *best);
  CHECK(r.best_validation < 0.3 * r.validation_loss.front());
  // The restored parameters give the best epoch's validation loss.
  const ValidationSplit split = split_for_validation(S, cfg.validation_fraction, cfg.seed);
  CHECK(head_objective(head, f, targets, split.validation, cfg.class_weight) ==
        doctest::Approx(r.best_validation).epsilon(1e-6));
  const HeadMetrics m = evaluate_head(head, f, targets);
  REQUIRE(m.rmse.size() == 2);
  CHECK(m.rmse[0] < 0.25 * 2.9);  // 2.9: the constant predictor's RMSE on F ~ U(0, 10)
  CHECK(m.rmse[1] < 0.25 * 5.8);
  CHECK(m.accuracy > 0.9);
  CHECK(m.majority_accuracy < 0.5);
  // Same seed, same head.
  ProbeHead<float> again(d, 3, 2, 4, 0);
  const HeadTrainResult r2 = train_head(again, f, targets, cfg);
  CHECK(r2.validation_loss == r.validation_loss);
  CHECK(std::equal(head.params.values().begin(), head.params.values().end(), again.params.values().begin()));
  // Regression only and classification only.
  HeadTargets reg{2, 0, targets.value, {}, {}}, cls{0, 4, {}, targets.label, {}};
  ProbeHead<float> hr(d, 3, 2, 0, 1), hc(d, 3, 0, 4, 1);
  cfg.max_epochs = 3;
  CHECK(train_head(hr, f, reg, cfg).epochs() == 3);
  CHECK(train_head(hc, f, cls, cfg).epochs() == 3);
  CHECK(evaluate_head(hc, f, cls).rmse.empty());
  CHECK_THROWS_AS(train_head(hr, f, cls, cfg), ShapeError);
  // The demo's force + indenter labels as general targets.
  const ProbeLabels pl{{7, 8}, {1, 2, 3, 4, 5, 6}, {0, 3}};
  const HeadTargets ht = head_targets(pl, 4);
  CHECK(ht.size() == 2);
  CHECK(ht.value == pl.force);
  CHECK(ht.label == pl.indenter);
  CHECK_THROWS_AS(head_targets(pl, 3), DataError);
  CHECK_THROWS_AS(ProbeHead<float>(d, 3, 0, 1, 0), ConfigError);
  cfg.patience = 0;
  CHECK_THROWS_AS(train_head(hr, f, reg, cfg), ConfigError);
}

TEST_CASE("train_head with stop_on_error: the validation top-1 error decides and the loss breaks ties") {
  const int S = 160, L = 2, d = 12;
  const auto [x, targets] = encoded_samples(S, L, d, 4);
  FrozenFeatures<float> f(x, L, d);
  const HeadTargets cls{0, 4, {}, targets.label, {}}, reg{2, 0, targets.value, {}, {}};
  HeadTrainConfig cfg = train_config(12, 4, 16, 3e-3);
  cfg.stop_on_error = true;
  ProbeHead<float> head(d, 3, 0, 4, 1);
  const HeadTrainResult r = train_head(head, f, cls, cfg);
  REQUIRE(r.epochs() >= 2);
  const ValidationSplit split = split_for_validation(S, cfg.validation_fraction, cfg.seed);
  const auto n = static_cast<double>(split.validation.size());
  // Each epoch's criterion: k wrong of n, plus a tie-break below one sample's worth.
  std::vector<int> wrong;
  for (double v : r.validation_loss) {
    const int k = static_cast<int>(std::floor(v * n));
    CHECK(v - k / n >= 0.0);
    CHECK(v - k / n < 1.0 / (n + 1.0));
    wrong.push_back(k);
  }
  CHECK(wrong[static_cast<std::size_t>(r.best_epoch)] == *std::ranges::min_element(wrong));
  CHECK(wrong.front() > wrong[static_cast<std::size_t>(r.best_epoch)]);  // it learns
  // The restored head: its errors on the validation samples are the best epoch's.
  const std::vector<float> y = head_outputs(head, f, split.validation);
  int k = 0;
  for (std::size_t b = 0; b < split.validation.size(); ++b)
    k += argmax(y.data() + b * 4, 4) != cls.label[static_cast<std::size_t>(split.validation[b])];
  CHECK(k == wrong[static_cast<std::size_t>(r.best_epoch)]);
  CHECK(head_validation(head, f, cls, split.validation, cfg) == doctest::Approx(r.best_validation).epsilon(1e-6));
  // Without it, the criterion is the loss; a regression head ignores the flag.
  HeadTrainConfig by_loss = cfg;
  by_loss.stop_on_error = false;
  CHECK(head_validation(head, f, cls, split.validation, by_loss) ==
        doctest::Approx(head_objective(head, f, cls, split.validation, cfg.class_weight)).epsilon(1e-12));
  ProbeHead<float> r1(d, 3, 2, 0, 2), r2(d, 3, 2, 0, 2);
  CHECK(train_head(r1, f, reg, cfg).validation_loss == train_head(r2, f, reg, by_loss).validation_loss);
}

TEST_CASE("split_for_validation: random samples or contiguous blocks with gaps - disjoint and seeded") {
  const ValidationSplit r = split_for_validation(100, 0.2, 3);
  CHECK(r.validation.size() == 20u);
  CHECK(r.fit.size() == 80u);
  std::set<std::int64_t> all(r.fit.begin(), r.fit.end());
  all.insert(r.validation.begin(), r.validation.end());
  CHECK(all.size() == 100u);
  // 5 blocks of 4 in 5 segments of 20; the 2 samples on each side of a block are in neither set.
  const ValidationSplit b = split_for_validation(100, 0.2, 3, 5, 2);
  REQUIRE(b.validation.size() == 20u);
  std::set<std::int64_t> val(b.validation.begin(), b.validation.end()), fit(b.fit.begin(), b.fit.end());
  for (int seg = 0; seg < 5; ++seg) {
    std::vector<std::int64_t> in;
    for (auto v : b.validation)
      if (v / 20 == seg) in.push_back(v);
    REQUIRE(in.size() == 4u);
    CHECK(in.back() - in.front() == 3);  // contiguous
  }
  for (auto v : b.validation) {
    CHECK(fit.count(v) == 0);
    for (int g = 1; g <= 2; ++g) {  // no fitting sample within the gap of a validation sample
      CHECK(fit.count(v - g) == 0);
      CHECK(fit.count(v + g) == 0);
    }
  }
  CHECK(b.fit.size() + b.validation.size() <= 100u);
  CHECK(b.fit.size() >= 100u - 20u - 5u * 4u);
  CHECK(split_for_validation(100, 0.2, 3, 5, 2).validation == b.validation);
  CHECK(split_for_validation(100, 0.2, 4, 5, 2).validation != b.validation);
  CHECK_THROWS_WITH_AS(split_for_validation(20, 0.2, 3, 5, 2), doctest::Contains("cannot hold 5 validation blocks"),
                       DataError);
}

TEST_CASE("split_by_groups: whole groups - stratified - seeded / validation_split picks groups over blocks") {
  // 6 strata (objects) with 1, 2, 5, 10, 10, 10 groups (episodes) of 3-7 samples, interleaved.
  SampleGroups g;
  const int groups_of[6] = {1, 2, 5, 10, 10, 10};
  std::int64_t id = 100;
  std::map<std::int64_t, int> stratum_of;
  for (int round = 0; round < 10; ++round)
    for (int st = 0; st < 6; ++st)
      if (round < groups_of[st]) {
        stratum_of[id] = st;
        for (int k = 0; k < 3 + (round + st) % 5; ++k) {
          g.group.push_back(id);
          g.stratum.push_back(st);
        }
        ++id;
      }
  const int S = static_cast<int>(g.group.size());
  const ValidationSplit s = split_by_groups(g, 0.2, 7);
  REQUIRE(s.fit.size() + s.validation.size() == static_cast<std::size_t>(S));
  CHECK(std::is_sorted(s.fit.begin(), s.fit.end()));
  CHECK(std::is_sorted(s.validation.begin(), s.validation.end()));
  std::set<std::int64_t> fit_groups, val_groups;
  for (auto i : s.fit) fit_groups.insert(g.group[static_cast<std::size_t>(i)]);
  for (auto i : s.validation) val_groups.insert(g.group[static_cast<std::size_t>(i)]);
  for (auto v : val_groups) CHECK(fit_groups.count(v) == 0);  // no group on both sides
  // Held-out groups per stratum: round(0.2 n), at least 1 where n >= 2, never all.
  const int expected[6] = {0, 1, 1, 2, 2, 2};
  int held[6] = {};
  for (auto v : val_groups) ++held[stratum_of[v]];
  for (int st = 0; st < 6; ++st) CHECK(held[st] == expected[st]);
  CHECK(split_by_groups(g, 0.2, 7).validation == s.validation);
  CHECK(split_by_groups(g, 0.2, 8).validation != s.validation);
  // One group per stratum: one seeded group is held out.
  const SampleGroups lone{{5, 5, 6, 6, 7}, {0, 0, 1, 1, 2}, {}};
  const ValidationSplit l = split_by_groups(lone, 0.2, 1);
  REQUIRE(!l.validation.empty());
  std::set<std::int64_t> lv;
  for (auto i : l.validation) lv.insert(lone.group[static_cast<std::size_t>(i)]);
  CHECK(lv.size() == 1u);
  CHECK_THROWS_WITH_AS(split_by_groups(SampleGroups{{1, 1, 1}, {}, {}}, 0.2, 1), doctest::Contains("1 group(s)"), DataError);
  CHECK_THROWS_WITH_AS(split_by_groups(SampleGroups{{1, 1, 2}, {0, 1, 1}, {}}, 0.2, 1),
                       doctest::Contains("one stratum per group"), DataError);
  // validation_split: groups win when present, blocks with groups are an error, no groups: the old split.
  HeadTrainConfig cfg;
  cfg.seed = 7;
  CHECK(validation_split(S, cfg, g).validation == s.validation);
  CHECK(validation_split(100, cfg, SampleGroups{}).validation == split_for_validation(100, 0.2, 7).validation);
  cfg.validation_groups = false;
  CHECK(validation_split(S, cfg, g).validation == split_for_validation(S, 0.2, 7).validation);
  cfg.validation_groups = true;
  cfg.validation_blocks = 2;
  CHECK_THROWS_WITH_AS(validation_split(S, cfg, g), doctest::Contains("validation_blocks"), ConfigError);
  CHECK_THROWS_AS(validation_split(S + 1, HeadTrainConfig{}, g), ShapeError);
}

TEST_CASE("validation_folds: every group validates once - dealt per stratum - seeded / errors") {
  // 3 strata of 5, 4 and 1 groups of 2-4 samples each.
  SampleGroups g;
  const int groups_of[3] = {5, 4, 1};
  std::int64_t id = 10;
  for (int st = 0; st < 3; ++st)
    for (int k = 0; k < groups_of[st]; ++k, ++id)
      for (int n = 0; n < 2 + (k + st) % 3; ++n) g.group.push_back(id), g.stratum.push_back(st);
  const int S = static_cast<int>(g.group.size());
  HeadTrainConfig cfg;
  cfg.folds = 3;
  cfg.seed = 5;
  const std::vector<ValidationSplit> f = validation_folds(S, cfg, g);
  REQUIRE(f.size() == 3u);
  std::vector<int> times(static_cast<std::size_t>(S), 0);
  std::map<std::int64_t, std::set<int>> folds_of_group;
  for (int k = 0; k < 3; ++k) {
    const ValidationSplit& s = f[static_cast<std::size_t>(k)];
    CHECK(s.fit.size() + s.validation.size() == static_cast<std::size_t>(S));
    CHECK(std::is_sorted(s.fit.begin(), s.fit.end()));
    for (auto i : s.validation) ++times[static_cast<std::size_t>(i)], folds_of_group[g.group[static_cast<std::size_t>(i)]].insert(k);
  }
  for (int t : times) CHECK(t == 1);                          // every sample validates exactly once
  for (const auto& [grp, ks] : folds_of_group) CHECK(ks.size() == 1u);  // a group whole in one fold
  // Dealt in turn across strata: 10 groups give folds of 4, 3, 3 groups, and stratum 0's 5 groups
  // are 2, 2, 1 over the folds.
  std::map<int, int> groups_in_fold, stratum0_in_fold;
  for (const auto& [grp, ks] : folds_of_group) {
    ++groups_in_fold[*ks.begin()];
    if (grp < 15) ++stratum0_in_fold[*ks.begin()];
  }
  std::vector<int> sizes, s0;
  for (auto [k, n] : groups_in_fold) sizes.push_back(n);
  for (auto [k, n] : stratum0_in_fold) s0.push_back(n);
  std::sort(sizes.begin(), sizes.end());
  std::sort(s0.begin(), s0.end());
  CHECK(sizes == std::vector<int>{3, 3, 4});
  CHECK(s0 == std::vector<int>{1, 2, 2});
  CHECK(validation_folds(S, cfg, g)[1].validation == f[1].validation);  // seeded
  cfg.seed = 6;
  bool differs = false;
  for (int k = 0; k < 3; ++k) differs |= validation_folds(S, cfg, g)[static_cast<std::size_t>(k)].validation != f[static_cast<std::size_t>(k)].validation;
  CHECK(differs);
  // No groups: samples dealt, 10 samples in folds of 4, 3, 3.
  const std::vector<ValidationSplit> plain = validation_folds(10, cfg, SampleGroups{});
  std::vector<std::size_t> n;
  for (const auto& s : plain) n.push_back(s.validation.size());
  std::sort(n.begin(), n.end());
  CHECK(n == std::vector<std::size_t>{3, 3, 4});
  cfg.folds = 11;
  CHECK_THROWS_WITH_AS(validation_folds(S, cfg, g), doctest::Contains("10 group(s) for 11 folds"), DataError);
  CHECK_THROWS_WITH_AS(validation_folds(10, cfg, SampleGroups{}), doctest::Contains("10 samples for 11 folds"), DataError);
  cfg.folds = 2;
  cfg.validation_blocks = 2;
  CHECK_THROWS_WITH_AS(cfg.validate(), doctest::Contains("not blocks"), ConfigError);
}

namespace {
// train_head's last run after its folds, by hand: best_epoch + 1 epochs on every sample.
template <class Features>
void final_run(ProbeHead<float>& head, Features& f, const HeadTargets& targets, HeadTrainConfig cfg, int best_epoch) {
  cfg.max_epochs = best_epoch + 1;
  ValidationSplit every;
  for (int i = 0; i < targets.size(); ++i) every.fit.push_back(i);
  detail::train_head_split(head, f, targets, cfg, every, nullptr, 0);
}
}  // namespace

TEST_CASE("train_head with folds: side by side until the mean curve stops improving / then every sample for the best epoch count") {
  const int S = 160, L = 2, d = 12;
  auto [x, targets] = encoded_samples(S, L, d, 4);
  for (int i = 0; i < S; ++i) targets.groups.group.push_back(i / 4), targets.groups.stratum.push_back(0);  // 40 groups of 4
  FrozenFeatures<float> f(x, L, d);
  HeadTrainConfig cfg = train_config(60, 8, 16, 1e-2);
  cfg.folds = 3;
  const ProbeHead<float> start(d, 3, 2, 4, 0);
  ProbeHead<float> head = start;
  const HeadTrainResult r = train_head(head, f, targets, cfg);
  const int E = r.epochs();
  // Stopped by the Trainer's rule on the mean: patience epochs after the lowest, or at max_epochs.
  CHECK((E == cfg.max_epochs || E - 1 - r.best_epoch == cfg.patience));
  // The folds by hand: each from the same start, validating on its fold, for the same E epochs and
  // not stopped on its own (the lockstep changes no fold's bits).
  HeadTrainConfig by_hand = cfg;
  by_hand.max_epochs = E;
  by_hand.patience = E;
  std::vector<HeadTrainResult> folds;
  for (const ValidationSplit& split : validation_folds(S, cfg, targets.groups)) {
    ProbeHead<float> h = start;
    folds.push_back(detail::train_head_split(h, f, targets, by_hand, split, nullptr, 0));
  }
  const HeadTrainResult mean = mean_validation_curve(folds);
  CHECK(r.validation_loss == mean.validation_loss);
  CHECK(r.best_epoch == mean.best_epoch);
  const auto best = std::min_element(r.validation_loss.begin(), r.validation_loss.end());
  CHECK(r.best_epoch == best - r.validation_loss.begin());
  for (const auto& fr : folds) CHECK(fr.validation_loss.size() == static_cast<std::size_t>(E));
  CHECK(r.validation_loss[0] == doctest::Approx((folds[0].validation_loss[0] + folds[1].validation_loss[0] +
                                                 folds[2].validation_loss[0]) / 3));
  // Then best_epoch + 1 epochs on all 160 samples from the start again: the same parameters.
  CHECK(r.train_loss.size() == static_cast<std::size_t>(r.best_epoch + 1));
  ProbeHead<float> all = start;
  final_run(all, f, targets, cfg, r.best_epoch);
  CHECK(std::equal(head.params.values().begin(), head.params.values().end(), all.params.values().begin()));
  CHECK(r.best_validation < 0.3 * r.validation_loss.front());
  CHECK(evaluate_head(head, f, targets).accuracy > 0.9);
  // Validation trials given in the targets (a table's val split): one split, no folds.
  targets.groups.held = {0, 1, 2, 3, 4, 5, 6, 7};
  ProbeHead<float> held = start;
  const HeadTrainResult rh = train_head(held, f, targets, cfg);
  CHECK(rh.train_loss.size() == rh.validation_loss.size());
}

TEST_CASE("train_head end to end with folds: the encoder starts each fold and the final run where it began") {
  ParamSet<float> ps;
  const int N = 4, W = 3, S = 48;
  const Tokenizer tok = Tokenizer::per_taxel(ps, N, 1, W, 8);
  const Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = 8, .depth = 1, .heads = 2});
  ps.allocate();
  init_params(ps, 2);
  Rng rng(9);
  AlignedVector<float> values(static_cast<std::size_t>(S) * W * N);
  for (auto& v : values) v = static_cast<float>(rng.normal());
  Recording rec(S * W, N, 1, std::move(values));
  const WindowSource src(rec, WindowSpec{W});
  std::vector<std::int64_t> windows;
  HeadTargets targets{1, 0, {}, {}, {}};
  for (int w = 0; w < S; ++w) {
    windows.push_back(w);
    targets.value.push_back(static_cast<float>(rng.normal()));
  }
  const ParamSet<float> encoder_start = ps;
  EncoderFeatures<float> feats(ps, tok, enc, src, windows);
  HeadTrainConfig cfg = train_config(3, 5, 8, 1e-3);
  cfg.folds = 2;
  const ProbeHead<float> start(8, 2, 1, 0, 0);
  ProbeHead<float> head = start;
  const HeadTrainResult r = train_head(head, feats, targets, cfg);
  // The same final run by hand, from the encoder's start.
  ParamSet<float> ps2 = encoder_start;
  EncoderFeatures<float> feats2(ps2, tok, enc, src, windows);
  ProbeHead<float> again = start;
  final_run(again, feats2, targets, cfg, r.best_epoch);
  CHECK(std::equal(ps.values().begin(), ps.values().end(), ps2.values().begin()));
  CHECK(std::equal(head.params.values().begin(), head.params.values().end(), again.params.values().begin()));
  // Each fold by hand with an encoder of its own: the folds run side by side, sharing one encoder
  // swapped in and out, give the same curves.
  HeadTrainConfig by_hand = cfg;
  by_hand.max_epochs = by_hand.patience = r.epochs();
  std::vector<HeadTrainResult> folds;
  for (const ValidationSplit& split : validation_folds(S, cfg, targets.groups)) {
    ParamSet<float> own = encoder_start;
    EncoderFeatures<float> own_feats(own, tok, enc, src, windows);
    ProbeHead<float> h = start;
    folds.push_back(detail::train_head_split(h, own_feats, targets, by_hand, split, nullptr, 0));
  }
  CHECK(r.validation_loss == mean_validation_curve(folds).validation_loss);
}

TEST_CASE("train_head: stops after patience epochs without improvement on unlearnable targets") {
  const int S = 60, L = 1, d = 12;
  const auto [x, targets] = encoded_samples(S, L, d, 8, true);
  FrozenFeatures<float> f(x, L, d);
  const HeadTrainConfig cfg = train_config(200, 4, 8, 1e-2);
  ProbeHead<float> head(d, 3, 2, 4, 2);
  const HeadTrainResult r = train_head(head, f, targets, cfg);
  CHECK(r.epochs() < cfg.max_epochs);
  CHECK(r.epochs() == r.best_epoch + 1 + cfg.patience);
  for (int e = r.best_epoch + 1; e < r.epochs(); ++e) CHECK(r.validation_loss[e] >= r.best_validation);
}

TEST_CASE("train_head end to end: the encoder trains and is restored to its best epoch") {
  // A simulated 4x4 grid skin of 4 pads, preprocessed as the magnetic sensor is; the head
  // regresses the force of the windows with a contact.
  SimulatedSkin sim(SkinGeometry::from_layout(
                        layouts::grid_skin({.rows = 4, .cols = 4, .pitch = 4.0, .group_rows = 2, .group_cols = 2}).layout),
                    SimConfig{}, 3);
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(sim.record_baseline(100));
  SimRecording rec = sim.record(600);
  pre.fit(rec.recording);
  const WindowSource src(rec.recording, WindowSpec{5}, rec.labels, pre);
  const std::vector<std::int64_t> contact = src.windows_with_contact(2);
  HeadTargets targets{3, 0, {}, {}, {}};
  for (std::int64_t w : contact) {
    const auto force = src.label(w).force;
    targets.value.insert(targets.value.end(), force.begin(), force.end());
  }
  REQUIRE(targets.size() >= 16);

  ParamSet<float> ps;
  const Tokenizer tok = Tokenizer::per_taxel(ps, 16, 3, 5, 8);
  const Encoder enc(ps, EncoderConfig{.num_tokens = 16, .dim = 8, .depth = 1, .heads = 2});
  ps.allocate();
  init_params(ps, 1);
  const std::vector<float> before(ps.values().begin(), ps.values().end());
  EncoderFeatures<float> feats(ps, tok, enc, src, contact);
  ProbeHead<float> head(8, 2, 3, 0, 0);
  const HeadTrainConfig cfg = train_config(4, 2, 8, 1e-3);
  const HeadTrainResult r = train_head(head, feats, targets, cfg);
  REQUIRE(r.best_epoch >= 0);
  double moved = 0;
  for (std::size_t i = 0; i < before.size(); ++i) moved += std::abs(ps.values()[i] - before[i]);
  CHECK(moved > 0);
  const ValidationSplit split = split_for_validation(targets.size(), cfg.validation_fraction, cfg.seed);
  CHECK(head_objective(head, feats, targets, split.validation, cfg.class_weight) ==
        doctest::Approx(r.best_validation).epsilon(1e-5));
}

TEST_CASE_TEMPLATE("CausalSelfAttention: against a plain-loop causal softmax", T, float, double) {
  const int B = 2, L = 7, d = 10, H = 2, Dh = 5;
  ParamSet<T> ps;
  const CausalSelfAttention attn = CausalSelfAttention::add(ps, "attn", d, H, true);
  ps.allocate();
  init_params(ps, 3);
  Rng rng(4);
  std::vector<T> x(std::size_t(B) * L * d), y(x.size(), T(0)), qkv(std::size_t(B) * L * 3 * d), att(x.size()),
      lse(std::size_t(B) * H * L);
  test::fill_normal(x, rng);
  for (auto& v : ps.values()) v = static_cast<T>(v * 20);  // weights of O(0.4): peaked softmax rows
  Workspace<T> ws;
  attn.forward(ps, AttentionRows{B, L}, x.data(), AttentionSaved<T>{.qkv = qkv.data(), .att = att.data(), .lse = lse.data()},
               y.data(), ws);
  // Reference on the same qkv: row l of head h attends to rows 0..l.
  const double tol = std::is_same_v<T, float> ? 2e-5 : 1e-12;
  for (int b = 0; b < B; ++b)
    for (int h = 0; h < H; ++h)
      for (int l = 0; l < L; ++l) {
        auto at = [&](int row, int part, int c) { return double(qkv[(std::size_t(b) * L + row) * 3 * d + part * d + h * Dh + c]); };
        std::vector<double> s(std::size_t(l) + 1);
        double mx = -1e300, sum = 0;
        for (int j = 0; j <= l; ++j) {
          double dot = 0;
          for (int c = 0; c < Dh; ++c) dot += at(l, 0, c) * at(j, 1, c);
          s[std::size_t(j)] = dot / std::sqrt(double(Dh));
          mx = std::max(mx, s[std::size_t(j)]);
        }
        for (auto& v : s) sum += (v = std::exp(v - mx));
        for (int c = 0; c < Dh; ++c) {
          double o = 0;
          for (int j = 0; j <= l; ++j) o += s[std::size_t(j)] / sum * at(j, 2, c);
          CHECK(double(att[(std::size_t(b) * L + l) * d + h * Dh + c]) == doctest::Approx(o).epsilon(tol).scale(1));
        }
        CHECK(double(lse[(std::size_t(b) * H + h) * L + l]) == doctest::Approx(mx + std::log(sum)).epsilon(tol).scale(1));
      }
}

TEST_CASE("SequenceHead: gradients of inputs and every parameter / causal predictions") {
  const int B = 2, L = 4, N = 3, d = 6, P = 3;
  for (const PoolingKind pooling : {PoolingKind::attentive, PoolingKind::taxel}) {
    INFO("pooling ", to_string(pooling));
    ParamSet<double> ps;
    const SequenceHead sh(ps, SequenceHeadConfig{d, 2, L, P, 2.0, 1e-6, {pooling, N, 2}});
    ps.allocate();
    test::randomize(ps, 21);
    for (const char* name : {"pos_embed", "blocks.0.norm1.weight", "blocks.0.attn.qkv.weight", "blocks.0.attn.proj.bias",
                             "blocks.0.mlp.fc2.weight", "norm.bias", "head.weight", "head.bias"})
      CHECK(ps.contains(name));
    if (pooling == PoolingKind::taxel) {
      CHECK(ps.infos()[ps.id("pool.proj.weight").index].shape == std::vector<std::int64_t>{2, d});
      CHECK(ps.infos()[ps.id("pool.fc.weight").index].shape == std::vector<std::int64_t>{d, N * 2});
      CHECK(ps.contains("pool.norm.bias"));
      CHECK_FALSE(ps.contains("pool.query_tokens"));
    } else {
      CHECK(ps.contains("pool.query_tokens"));
      CHECK(ps.contains("pool.cross_attention_block.xattn.kv.weight"));
      CHECK_FALSE(ps.contains("pool.fc.weight"));
    }
    CHECK_FALSE(ps.contains("pool.head.fc1.weight"));
    Rng rng(22);
    auto x = test::normal_vector(std::size_t(B) * L * N * d, rng);
    auto w = test::normal_vector(std::size_t(B) * L * P, rng);
    std::vector<double> y(w.size());
    SequenceCache<double> cache, scratch;
    Workspace<double> ws;
    auto loss = [&] {
      sh.forward(ps, x.data(), B, N, y.data(), scratch, ws);
      return test::dot(w.data(), y.data(), y.size());
    };
    ps.zero_grad();
    sh.forward(ps, x.data(), B, N, y.data(), cache, ws);
    std::vector<double> dx(x.size(), 0.0);
    sh.backward(ps, w.data(), dx.data(), cache, ws);
    CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss, 96) < test::grad_tolerance);
    test::check_param_gradients(ps, loss);
    // A second backward adds the same gradient again.
    const std::vector<double> g1(ps.grads().begin(), ps.grads().end()), dx1 = dx;
    sh.forward(ps, x.data(), B, N, y.data(), cache, ws);
    sh.backward(ps, w.data(), dx.data(), cache, ws);
    for (std::size_t i = 0; i < g1.size(); ++i) REQUIRE(ps.grads()[i] == doctest::Approx(2 * g1[i]).epsilon(1e-12));
    for (std::size_t i = 0; i < dx.size(); ++i) REQUIRE(dx[i] == doctest::Approx(2 * dx1[i]).epsilon(1e-12));
    // The prediction after window l does not see later windows: change window 2 of sequence 1 (not
    // by a constant shift, which LayerNorm ignores).
    const std::vector<double> y0 = y;
    const std::size_t changed = std::size_t(L) + 2;
    for (int i = 0; i < N * d; ++i) x[changed * N * d + i] += rng.normal(0.0, 1.0);
    sh.forward(ps, x.data(), B, N, y.data(), scratch, ws);
    for (std::size_t r = 0; r < std::size_t(B) * L; ++r)
      for (int p = 0; p < P; ++p) {
        INFO("row ", r);
        if (r < changed)
          CHECK(y[r * P + p] == y0[r * P + p]);
        else
          CHECK(y[r * P + p] != y0[r * P + p]);
      }
  }
}

TEST_CASE("train_sequence_head: learns a running sum of the windows with early stopping") {
  // Windows i encode a value F_i in their tokens' direction; sequence q is windows q, q+1, ..., and
  // its targets after window l are (F_l, running mean of F over 0..l, 0).
  const int S = 120, L = 5, N = 2, d = 12, Q = S - L + 1;
  Rng rng(31);
  AlignedVector<float> x(std::size_t(S) * N * d, 0.0f);
  std::vector<float> F(S);
  for (int i = 0; i < S; ++i) {
    F[std::size_t(i)] = static_cast<float>(rng.uniform(0, 10));
    for (int n = 0; n < N; ++n) {
      float* t = x.data() + (std::size_t(i) * N + n) * d;
      t[0] = F[std::size_t(i)];
      t[1] = 10 - F[std::size_t(i)];
      t[2 + n] = 3;
    }
  }
  SequenceTargets targets{L, 3, {}, {}, {}};
  for (int q = 0; q < Q; ++q) {
    double run = 0;
    for (int l = 0; l < L; ++l) {
      targets.window.push_back(q + l);
      run += F[std::size_t(q + l)];
      targets.value.insert(targets.value.end(), {F[std::size_t(q + l)], static_cast<float>(run / (l + 1)), 0.0f});
    }
  }
  FrozenFeatures<float> f(x, N, d);
  const HeadTrainConfig cfg = train_config(60, 8, 8, 3e-3);
  SequenceModel<float> model(SequenceHeadConfig{d, 3, L, 3, 2.0, 1e-6, {}}, 0);
  const HeadTrainResult r = train_sequence_head(model, f, targets, cfg);
  REQUIRE(r.epochs() >= 1);
  CHECK(r.best_validation < 0.3 * r.validation_loss.front());
  const ValidationSplit split = split_for_validation(Q, cfg.validation_fraction, cfg.seed);
  CHECK(sequence_objective(model, f, targets, split.validation) == doctest::Approx(r.best_validation).epsilon(1e-6));
  const std::vector<double> rmse = evaluate_sequence_head(model, f, targets);
  REQUIRE(rmse.size() == 3);
  CHECK(rmse[0] < 0.3 * 2.9);  // 2.9: the constant predictor on F ~ U(0, 10)
  CHECK(rmse[1] < 0.5 * 1.6);  // the running mean's spread is smaller (1.6 at l = 2)
  CHECK(rmse[2] < 1e-3);       // a constant target: the scaler's mean
  SequenceModel<float> again(SequenceHeadConfig{d, 3, L, 3, 2.0, 1e-6, {}}, 0);
  CHECK(train_sequence_head(again, f, targets, cfg).validation_loss == r.validation_loss);
  targets.window[3] = S;
  CHECK_THROWS_AS(train_sequence_head(again, f, targets, cfg), DataError);
}

TEST_CASE("train_sequence_head: the taxel pooling reads where the contact is - the attentive pooling cannot") {
  // Window i presses around a place c_i in [0, N - 1] of a row of N taxels: token n is a shared
  // vector plus a_n = exp(-(n - c_i)²) along channel 0, with no position code. The target after
  // window l is c of that window. The attentive pooling is invariant to the order of the tokens,
  // so it sees the pressure values but not where they are; the taxel pooling keeps each taxel's
  // place.
  const int S = 240, L = 4, N = 6, d = 8, Q = S - L + 1;
  Rng rng(41);
  AlignedVector<float> x(std::size_t(S) * N * d, 0.0f);
  std::vector<float> c(S);
  for (int i = 0; i < S; ++i) {
    c[std::size_t(i)] = static_cast<float>(rng.uniform(0, N - 1));
    for (int n = 0; n < N; ++n) {
      float* t = x.data() + (std::size_t(i) * N + n) * d;
      for (int k = 1; k < d; ++k) t[k] = static_cast<float>(k % 3);
      t[0] = static_cast<float>(3 * std::exp(-(n - c[std::size_t(i)]) * (n - c[std::size_t(i)])));
    }
  }
  SequenceTargets targets{L, 3, {}, {}, {}};
  for (int q = 0; q < Q; ++q)
    for (int l = 0; l < L; ++l) {
      targets.window.push_back(q + l);
      targets.value.insert(targets.value.end(), {c[std::size_t(q + l)], 0.0f, 0.0f});
    }
  FrozenFeatures<float> f(x, N, d);
  const HeadTrainConfig cfg = train_config(60, 8, 8, 3e-3);
  const double spread = (N - 1) / std::sqrt(12.0);  // sd of U(0, N - 1)
  auto rmse_of = [&](PoolingKind pooling) {
    SequenceModel<float> model(SequenceHeadConfig{d, 2, L, 3, 2.0, 1e-6, {pooling, N, 2}}, 0);
    train_sequence_head(model, f, targets, cfg);
    return evaluate_sequence_head(model, f, targets)[0];
  };
  const double taxel = rmse_of(PoolingKind::taxel), attentive = rmse_of(PoolingKind::attentive);
  INFO("taxel ", taxel, ", attentive ", attentive, ", constant ", spread);
  CHECK(taxel < 0.25 * spread);
  CHECK(attentive > 0.5 * spread);
  SequenceModel<float> wrong(SequenceHeadConfig{d, 2, L, 3, 2.0, 1e-6, {PoolingKind::taxel, N + 1, 2}}, 0);
  CHECK_THROWS_WITH_AS(train_sequence_head(wrong, f, targets, cfg), doctest::Contains("built for 7"), ShapeError);
  CHECK_THROWS_AS(SequenceModel<float>(SequenceHeadConfig{d, 2, L, 3, 2.0, 1e-6, {PoolingKind::taxel, 0, 2}}, 0),
                  ConfigError);
  CHECK(parse_pooling("taxel") == PoolingKind::taxel);
  CHECK_THROWS_WITH_AS(parse_pooling("mean"), doctest::Contains("mean"), ConfigError);
}

}  // TEST_SUITE
