// Optimizer pieces: schedules, gradient clipping, the deterministic sum, AdamW, EMA.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "../support/params.hpp"
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/core/prefixed_params.hpp>
#include <tjepa/optim/adamw.hpp>
#include <tjepa/optim/detail/deterministic_sum.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

using tjepa_test::fill_grads;
using tjepa_test::make_params;

TEST_SUITE("optim") {
  TEST_CASE("schedules match their closed forms at chosen steps") {
    // The paper's schedule (Sec. IV-D, training details) with Sparsh-skin's epochs: 500 epochs,
    // 10 steps per epoch, 30 warm-up epochs.
    const auto s = tjepa::TrainingSchedule::reference(500, 10, 30);
    const double W = 300, T = 5000;
    CHECK(s.total_steps() == 5000);
    // Warm-up: optimizer step s uses k = s + 1.
    for (std::int64_t step : {0, 1, 17, 150, 298}) {
      const double k = static_cast<double>(step + 1);
      CHECK(s.lr_at(step) == doctest::Approx(1e-5 + k / W * (1e-4 - 1e-5)).epsilon(1e-14));
    }
    CHECK(s.lr(0) == doctest::Approx(1e-5).epsilon(1e-15));
    CHECK(s.lr_at(299) == doctest::Approx(1e-4).epsilon(1e-15));  // k = W: the peak
    // Cosine part, and the halfway point lands on the mean of peak and floor.
    for (std::int64_t step : {299, 400, 2649, 4000, 4999}) {
      const double k = static_cast<double>(step + 1);
      const double expected = 1e-6 + (1e-4 - 1e-6) * 0.5 * (1 + std::cos(std::numbers::pi * (k - W) / (T - W)));
      CHECK(s.lr_at(step) == doctest::Approx(expected).epsilon(1e-14));
    }
    CHECK(s.lr(300 + 2350) == doctest::Approx((1e-4 + 1e-6) / 2).epsilon(1e-12));
    CHECK(s.lr_at(4999) == doctest::Approx(1e-6).epsilon(1e-12));
    // Weight decay: 0.04 → 0.4, cosine-increasing, clamped at the end.
    CHECK(s.wd(0) == doctest::Approx(0.04).epsilon(1e-15));
    CHECK(s.wd(2500) == doctest::Approx(0.22).epsilon(1e-14));
    CHECK(s.wd(5000) == doctest::Approx(0.4).epsilon(1e-15));
    // The reference code's timing (the default): update s at wd(s), update 0 at wd_initial (the
    // optimizer's constructor value; unset: wd(0) = wd_start).
    CHECK(s.wd_timing == tjepa::WeightDecayTiming::reference);
    CHECK(s.wd_at(0) == doctest::Approx(0.04).epsilon(1e-15));
    CHECK(tjepa::TrainConfig{}.schedule.build().wd_at(0) == 0.05);
    auto ijepa = s;
    ijepa.wd_timing = tjepa::WeightDecayTiming::ijepa;
    for (std::int64_t step : {0, 10, 1234, 4999}) {
      const double k = static_cast<double>(step + 1);
      CHECK(ijepa.wd_at(step) ==
            doctest::Approx(0.4 + (0.04 - 0.4) * 0.5 * (1 + std::cos(std::numbers::pi * k / T))).epsilon(1e-14));
      CHECK(s.wd_at(step) == doctest::Approx(0.4 + (0.04 - 0.4) * 0.5 * (1 + std::cos(std::numbers::pi * (k - 1) / T)))
                                 .epsilon(1e-14));
    }
    // Momentum: linear 0.994 → 1 over all steps, indexed by the step just taken.
    CHECK(s.momentum_at(0) == 0.994);
    CHECK(s.momentum_at(2500) == doctest::Approx(0.997).epsilon(1e-15));
    CHECK(s.momentum(5000) == doctest::Approx(1.0).epsilon(1e-15));
    for (std::int64_t step : {1, 77, 4321})
      CHECK(s.momentum_at(step) == doctest::Approx(0.994 + step * 0.006 / T).epsilon(1e-15));
    // Monotone pieces.
    for (std::int64_t k = 1; k < 300; ++k) CHECK(s.lr(k) > s.lr(k - 1));
    for (std::int64_t k = 301; k <= 5000; k += 7) CHECK(s.lr(k) < s.lr(k - 1));
    for (std::int64_t k = 1; k <= 5000; k += 13) CHECK(s.wd(k) > s.wd(k - 1));

    CHECK_THROWS_AS(tjepa::TrainingSchedule::reference(10, 5, 11), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::TrainingSchedule::reference(0, 5, 0), tjepa::ConfigError);
  }

  TEST_CASE("the schedule equals the stateful schedulers of I-JEPA's loop and of the reference code") {
    // I-JEPA's loop: `lr = scheduler.step(); wd = wd_scheduler.step(); ...; optimizer.step()`.
    auto s = tjepa::TrainingSchedule::reference(7, 3, 2);
    s.wd_timing = tjepa::WeightDecayTiming::ijepa;
    double counter = 0;
    for (std::int64_t step = 0; step < s.total_steps(); ++step) {
      counter += 1;
      const auto k = static_cast<std::int64_t>(counter);
      CHECK(s.lr_at(step) == s.lr(k));
      CHECK(s.wd_at(step) == s.wd(k));
    }
    // The reference code: the optimizer starts at its constructor value (optim_cfg weight_decay
    // 0.05, not the schedule's 0.04) and its weight-decay scheduler is stepped after each update.
    s.wd_timing = tjepa::WeightDecayTiming::reference;
    s.wd_initial = 0.05;
    double wd = 0.05;
    std::int64_t stepped = 0;
    for (std::int64_t step = 0; step < s.total_steps(); ++step) {
      CHECK(s.wd_at(step) == doctest::Approx(wd).epsilon(1e-15));
      wd = s.wd(++stepped);
    }
  }

  TEST_CASE("gradient clipping: joint norm and PyTorch coefficient and thread independence") {
    auto a = make_params<double>(1);
    auto b = make_params<double>(2, 4);
    fill_grads(a, 3, 2.0);
    fill_grads(b, 4, 2.0);
    double ss = 0;
    for (auto* ps : {&a, &b})
      for (std::size_t i = 0; i < ps->count(); ++i)
        for (double g : ps->grad_span(ps->id(i))) ss += g * g;
    const std::vector<tjepa::PrefixedParams<double>> parts{{"context_encoder.", &a}, {"predictor.", &b}};
    const double norm = tjepa::grad_norm<double>(parts);
    CHECK(norm == doctest::Approx(std::sqrt(ss)).epsilon(1e-13));

    auto a0 = a;
    const double before = tjepa::clip_grad_norm<double>(parts, 1.0);
    CHECK(before == norm);
    const double coef = 1.0 / (norm + 1e-6);
    for (std::size_t i = 0; i < a.count(); ++i)
      for (std::size_t j = 0; j < a.id(i).size; ++j)
        CHECK(a.grad(a.id(i))[j] == doctest::Approx(a0.grad(a0.id(i))[j] * coef).epsilon(1e-14));
    CHECK(tjepa::grad_norm<double>(parts) == doctest::Approx(norm * coef).epsilon(1e-12));

    // Below the threshold nothing changes.
    auto a1 = a;
    CHECK(tjepa::clip_grad_norm(a, 10.0) < 10.0);
    CHECK(std::equal(a.grads().begin(), a.grads().end(), a1.grads().begin()));
    CHECK_THROWS_AS(tjepa::clip_grad_norm(a, 0.0), tjepa::ConfigError);

    // The norm of a large buffer is bitwise the same on one thread and on all.
    tjepa::ParamSet<float> big;
    big.add("w", {1000, 333});
    big.allocate();
    fill_grads(big, 5);
    const tjepa::PrefixedParams<float> one{"", &big};
    const int threads = tjepa::detail::max_threads();
#if defined(_OPENMP)
    omp_set_num_threads(1);
#endif
    const double n1 = tjepa::grad_norm<float>(std::span(&one, 1));
#if defined(_OPENMP)
    omp_set_num_threads(threads);
#endif
    const double n2 = tjepa::grad_norm<float>(std::span(&one, 1));
    CHECK(n1 == n2);
  }

  TEST_CASE("deterministic_sum: chunk sums left to right and the same bits on 1 and 2 threads") {
    const std::size_t n = tjepa::detail::parallel_grain + 12345;  // above the grain: parallel
    auto term = [](std::size_t i) { return std::sin(0.001 * static_cast<double>(i)) * 1e-3 + 1e-9 * i; };
    const std::size_t chunk = 1000;  // does not divide n
    double expected = 0;
    for (std::size_t c = 0; c * chunk < n; ++c) {
      double part = 0;
      for (std::size_t i = c * chunk; i < std::min(n, (c + 1) * chunk); ++i) part += term(i);
      expected += part;
    }
#if defined(_OPENMP)
    const int previous = omp_get_max_threads();
    omp_set_num_threads(1);
#endif
    const double one = tjepa::detail::deterministic_sum(n, term, chunk);
#if defined(_OPENMP)
    omp_set_num_threads(2);
#endif
    const double two = tjepa::detail::deterministic_sum(n, term, chunk);
#if defined(_OPENMP)
    omp_set_num_threads(previous);
#endif
    CHECK(one == expected);
    CHECK(two == expected);
    CHECK(tjepa::detail::deterministic_sum(0, term) == 0.0);
    CHECK(tjepa::detail::deterministic_sum(3, term, 2) == (term(0) + term(1)) + term(2));
  }

  TEST_CASE("deterministic_sum_squares: the sum of squares in double to rounding / same bits on 1 and 2 threads") {
    const std::size_t n = tjepa::detail::parallel_grain + 4321;  // parallel / a partial last chunk and lane run
    std::vector<float> x(n);
    tjepa::Rng rng(9);
    for (auto& v : x) v = static_cast<float>(rng.normal());
    long double exact = 0;
    for (float v : x) exact += static_cast<long double>(v) * static_cast<long double>(v);
#if defined(_OPENMP)
    const int previous = omp_get_max_threads();
    omp_set_num_threads(1);
#endif
    const double one = tjepa::detail::deterministic_sum_squares(x.data(), n);
#if defined(_OPENMP)
    omp_set_num_threads(2);
#endif
    const double two = tjepa::detail::deterministic_sum_squares(x.data(), n);
#if defined(_OPENMP)
    omp_set_num_threads(previous);
#endif
    CHECK(one == two);
    CHECK(one == doctest::Approx(static_cast<double>(exact)).epsilon(1e-14));
    // Fewer terms than lanes: each in its own running sum, added in order.
    const float y[3] = {1.5f, -2.0f, 0.25f};
    CHECK(tjepa::detail::deterministic_sum_squares(y, 3) == (2.25 + 4.0) + 0.0625);
    CHECK(tjepa::detail::deterministic_sum_squares(y, 0) == 0.0);
  }

  TEST_CASE("AdamW matches the textbook update and decays only 2-D weights") {
    auto ps = make_params<double>(7);
    auto ref = ps;  // the reference copy, updated by the plain formula below
    tjepa::AdamW<double> opt({{"", &ps}});
    const tjepa::AdamWConfig c;
    std::vector<double> m(ps.flat_size(), 0.0), v(ps.flat_size(), 0.0);
    for (int t = 1; t <= 4; ++t) {
      fill_grads(ps, 100 + t);
      const double lr = 1e-2 * t, wd = 0.1 * t;
      opt.step(lr, wd);
      for (const auto& info : ref.infos())
        for (std::size_t j = info.offset; j < info.offset + info.size; ++j) {
          const double g = ps.grads()[j];
          double& p = ref.values()[j];
          if (info.decay) p -= lr * wd * p;
          m[j] = c.beta1 * m[j] + (1 - c.beta1) * g;
          v[j] = c.beta2 * v[j] + (1 - c.beta2) * g * g;
          const double mhat = m[j] / (1 - std::pow(c.beta1, t));
          const double vhat = v[j] / (1 - std::pow(c.beta2, t));
          p -= lr * mhat / (std::sqrt(vhat) + c.eps);
        }
    }
    CHECK(opt.steps() == 4);
    for (std::size_t j = 0; j < ps.flat_size(); ++j) {
      CHECK(ps.values()[j] == doctest::Approx(ref.values()[j]).epsilon(1e-12));
      CHECK(opt.exp_avg(0)[j] == doctest::Approx(m[j]).epsilon(1e-12));
      CHECK(opt.exp_avg_sq(0)[j] == doctest::Approx(v[j]).epsilon(1e-12));
    }
  }

  TEST_CASE("AdamW in vectors: the formula in float / a partial last vector as if whole / same bits on 1 and 2 threads") {
    // "a" (37 values) is "b"'s first 37 (48 values): a's last 5 sit in a partial vector, b's in a
    // whole one. "big" is above the parallel grain, so two threads split it.
    const int big_rows = static_cast<int>(tjepa::detail::parallel_grain / 61) + 3;
    auto make = [&] {
      tjepa::ParamSet<float> ps;
      ps.add("a.weight", {37, 1});
      ps.add("b.weight", {48, 1});
      ps.add("big.weight", {big_rows, 61});
      ps.add("big.bias", {61});
      ps.allocate();
      tjepa::Rng rng(5);
      for (std::size_t i = 0; i < ps.count(); ++i)
        for (auto& v : ps.value_span(ps.id(i))) v = static_cast<float>(rng.normal());
      auto a = ps.value_span(ps.id(0));
      std::copy(a.begin(), a.end(), ps.value_span(ps.id(1)).begin());
      return ps;
    };
    auto grads = [](tjepa::ParamSet<float>& ps, int t) {
      fill_grads(ps, 300 + t);
      auto a = ps.grad_span(ps.id(0));
      std::copy(a.begin(), a.end(), ps.grad_span(ps.id(1)).begin());
    };
    auto run = [&](int threads) {
      auto ps = make();
#if defined(_OPENMP)
      const int previous = omp_get_max_threads();
      omp_set_num_threads(threads);
#else
      (void)threads;
#endif
      tjepa::AdamW<float> opt({{"", &ps}});
      for (int t = 1; t <= 3; ++t) {
        grads(ps, t);
        opt.step(1e-2, 0.05);
      }
#if defined(_OPENMP)
      omp_set_num_threads(previous);
#endif
      return ps;
    };
    const auto one = run(1), two = run(2);
    CHECK(std::equal(one.values().begin(), one.values().end(), two.values().begin()));
    const auto a = one.value_span(one.id(0)), b = one.value_span(one.id(1));
    CHECK(std::equal(a.begin(), a.end(), b.begin()));
    // The textbook update in double, three steps.
    auto ref = make();
    std::vector<double> m(ref.flat_size(), 0.0), v(ref.flat_size(), 0.0), p(ref.values().begin(), ref.values().end());
    const tjepa::AdamWConfig c;
    for (int t = 1; t <= 3; ++t) {
      grads(ref, t);
      for (const auto& info : ref.infos())
        for (std::size_t j = info.offset; j < info.offset + info.size; ++j) {
          const double g = ref.grads()[j];
          if (info.decay) p[j] -= 1e-2 * 0.05 * p[j];
          m[j] = c.beta1 * m[j] + (1 - c.beta1) * g;
          v[j] = c.beta2 * v[j] + (1 - c.beta2) * g * g;
          p[j] -= 1e-2 * (m[j] / (1 - std::pow(c.beta1, t))) / (std::sqrt(v[j] / (1 - std::pow(c.beta2, t))) + c.eps);
        }
    }
    double worst = 0;
    for (const auto& info : ref.infos())
      for (std::size_t j = info.offset; j < info.offset + info.size; ++j)
        worst = std::max(worst, std::abs(double(one.values()[j]) - p[j]) / (1e-3 + std::abs(p[j])));
    CHECK(worst < 1e-5);
  }

  TEST_CASE("no weight decay reaches biases or LayerNorm parameters") {
    auto ps = make_params<float>(8);
    auto before = ps;
    ps.zero_grad();  // with zero gradients AdamW moves nothing: only decay could
    tjepa::AdamW<float> opt({{"context_encoder.", &ps}});
    opt.step(0.1, 0.5);
    for (const auto& info : ps.infos()) {
      const bool one_d = info.shape.size() == 1;
      const bool bias = info.name.ends_with("bias");
      CHECK_MESSAGE(info.decay == !(one_d || bias), info.name);
      for (std::size_t j = info.offset; j < info.offset + info.size; ++j) {
        if (info.decay)
          CHECK(ps.values()[j] == doctest::Approx(before.values()[j] * 0.95f).epsilon(1e-6));
        else
          CHECK(ps.values()[j] == before.values()[j]);
      }
    }
    // The decay group holds exactly the position table, the mask vector and the 2-D weights.
    std::vector<std::string> decayed;
    for (auto i : ps.decay_group()) decayed.push_back(ps.infos()[i].name);
    CHECK(decayed == std::vector<std::string>{"pos_embed", "blocks.0.attn.qkv.weight", "mask_token"});
    CHECK_THROWS_AS(opt.step(-1.0, 0.1), tjepa::ConfigError);
    tjepa::ParamSet<float> unallocated;
    unallocated.add("w", {2, 2});
    CHECK_THROWS_AS(tjepa::AdamW<float>({{"", &unallocated}}), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::AdamW<float>({{"", &ps}, {"", &ps}}), tjepa::ConfigError);
  }

  TEST_CASE("EMA update of the target encoder") {
    auto target = make_params<double>(11);
    const auto context = make_params<double>(12);
    const auto t0 = target;
    tjepa::ema_update(target, context, 0.994);
    for (std::size_t j = 0; j < target.flat_size(); ++j)
      CHECK(target.values()[j] ==
            doctest::Approx(0.994 * t0.values()[j] + 0.006 * context.values()[j]).epsilon(1e-15));
    auto same = t0;
    tjepa::ema_update(same, context, 1.0);  // momentum 1 keeps the target
    CHECK(std::equal(same.values().begin(), same.values().end(), t0.values().begin()));
    tjepa::ema_update(same, context, 0.0);  // momentum 0 copies the context
    CHECK(std::equal(same.values().begin(), same.values().end(), context.values().begin()));
    auto other = make_params<double>(13, 4);
    CHECK_THROWS_AS(tjepa::ema_update(other, context, 0.5), tjepa::ShapeError);
    CHECK_THROWS_AS(tjepa::ema_update(same, context, 1.5), tjepa::ConfigError);
  }
}
