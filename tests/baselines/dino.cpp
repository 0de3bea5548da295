// The DINO baseline on a tiny model in double: the head, the cross-entropy and KoLeo against
// central differences, the whole loss against central differences for every student parameter,
// the views' properties, the update (EMA teacher, centers one step late), errors.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/baselines/dino_head.hpp>
#include <tjepa/baselines/dino.hpp>
#include <tjepa/baselines/dino_loss.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

// 12 tokens, d = 8, 2 heads, 1 block, m·τ = 4 values per taxel; a head 8 → 12 → 6 → 10
// prototypes; 2 global and 2 local views.
DinoConfig tiny_dino_config() {
  DinoConfig c;
  c.in_dim = 4;
  c.axes = 2;
  c.encoder = EncoderConfig{.num_tokens = 12, .dim = 8, .depth = 1, .heads = 2, .mlp_ratio = 2.0, .bias = true,
                            .eps = 1e-6, .register_tokens = 1, .mask_token = true};
  c.head = DinoHeadConfig{8, 12, 6, 10};
  c.local_views = 2;
  return c;
}

}  // namespace

TEST_SUITE("baselines") {
  TEST_CASE("DinoHead: output rows are cosines with unit prototypes / gradients of input and parameters") {
    const test::SingleThread one_thread;
    ParamSet<double> ps;
    DinoHead head(ps, DinoHeadConfig{5, 7, 4, 9});
    ps.allocate();
    test::randomize(ps, 3);
    CHECK(ps.contains("mlp.0.weight"));
    CHECK(ps.contains("mlp.4.bias"));
    CHECK(ps.infos()[ps.id("last_layer.weight_v").index].shape == std::vector<std::int64_t>{9, 4});
    const int M = 3;
    Rng rng(4);
    auto x = test::normal_vector(std::size_t(M) * 5, rng);
    auto w = test::normal_vector(std::size_t(M) * 9, rng);
    std::vector<double> out(w.size());
    DinoHeadCache<double> cache;
    head.forward(ps, x.data(), M, out.data(), cache);
    for (double o : out) CHECK(std::abs(o) <= 1.0 + 1e-12);  // unit bottleneck · unit prototype
    auto loss = [&] {
      DinoHeadCache<double> c;
      head.forward(ps, x.data(), M, out.data(), c);
      return test::dot(w.data(), out.data(), out.size());
    };
    const double l = loss();
    ps.zero_grad();
    head.forward(ps, x.data(), M, out.data(), cache);
    CHECK(test::dot(w.data(), out.data(), out.size()) == l);
    std::vector<double> dx(x.size(), 0.0);
    head.backward(ps, w.data(), x.data(), dx.data(), cache);
    CHECK(test::gradient_error(x.data(), dx.data(), x.size(), loss) < test::grad_tolerance);
    test::check_param_gradients(ps, loss);
    // Scaling a prototype's raw row changes nothing (weight norm with g = 1).
    double* v = ps.value(head.weight_v);
    for (int j = 0; j < 4; ++j) v[j] *= 3.0;
    CHECK(loss() == doctest::Approx(l).epsilon(1e-12));
    CHECK_THROWS_WITH_AS(head.backward(ps, w.data(), x.data(), dx.data(), cache), doctest::Contains("holds no forward pass"),
                         ConfigError);
  }

  TEST_CASE("DINO cross-entropy / teacher softmax and KoLeo: values and central differences") {
    const int M = 3, P = 5;
    Rng rng(9);
    auto s = test::normal_vector(std::size_t(M) * P, rng);
    auto t = test::normal_vector(std::size_t(M) * P, rng);
    const std::vector<double> center{0.1, -0.2, 0.3, 0.0, 0.5};
    std::vector<double> probs(t.size());
    dino_teacher_probs(probs.data(), t.data(), center.data(), M, P, 0.04);
    for (int m = 0; m < M; ++m) {
      double sum = 0;
      for (int k = 0; k < P; ++k) sum += probs[std::size_t(m) * P + k];
      CHECK(sum == doctest::Approx(1.0).epsilon(1e-14));
    }
    // ℓ = −Σ p log softmax(s/τ) by hand for row 0.
    double z = 0;
    for (int k = 0; k < P; ++k) z += std::exp(s[std::size_t(k)] / 0.1);
    double by_hand = 0;
    for (int k = 0; k < P; ++k) by_hand -= probs[std::size_t(k)] * (s[std::size_t(k)] / 0.1 - std::log(z));
    CHECK(dino_cross_entropy(s.data(), probs.data(), 1, P, 0.1, static_cast<double*>(nullptr), 1.0) ==
          doctest::Approx(by_hand).epsilon(1e-12));
    std::vector<double> ds(s.size(), 0.0);
    dino_cross_entropy(s.data(), probs.data(), M, P, 0.1, ds.data(), 0.7);
    auto ce = [&] { return 0.7 * dino_cross_entropy(s.data(), probs.data(), M, P, 0.1, static_cast<double*>(nullptr), 1.0); };
    CHECK(test::gradient_error(s.data(), ds.data(), s.size(), ce) < test::grad_tolerance);

    const int D = 4, R = 5;
    auto x = test::normal_vector(std::size_t(R) * D, rng);
    std::vector<double> dx(x.size(), 0.0);
    const double k = koleo_loss(x.data(), R, D, dx.data(), 0.3);
    auto kl = [&] { return 0.3 * koleo_loss(x.data(), R, D, static_cast<double*>(nullptr), 1.0); };
    CHECK(0.3 * k == doctest::Approx(kl()).epsilon(1e-14));
    CHECK(test::gradient_error(x.data(), dx.data(), x.size(), kl) < test::grad_tolerance);
    // Spreading the rows apart lowers it: identical directions are its worst case.
    std::vector<double> same(std::size_t(R) * D, 1.0);
    CHECK(koleo_loss(same.data(), R, D, static_cast<double*>(nullptr), 1.0) > k);
    CHECK_THROWS_WITH_AS(koleo_loss(x.data(), 1, D, static_cast<double*>(nullptr), 1.0),
                         doctest::Contains("expected M >= 2"), ShapeError);
  }

  TEST_CASE("DINO views: contiguous runs of the drawn sizes / masked tokens inside the global views only") {
    DinoConfig c = tiny_dino_config();
    c.encoder.num_tokens = 40;
    for (std::uint64_t s = 0; s < 20; ++s) {
      const DinoViews v = sample_dino_views(c, 3, 5, s);
      CHECK(v.Kg >= static_cast<int>(40 * 0.4));
      CHECK(v.Kg <= 40);
      CHECK(v.Kl >= 4);
      CHECK(v.Kl <= static_cast<int>(40 * 0.4));
      REQUIRE(v.global.size() == std::size_t(2 * 3 * v.Kg));
      REQUIRE(v.local.size() == std::size_t(2 * 3 * v.Kl));
      for (std::size_t i = 0; i < v.global.size(); ++i) {
        CHECK(v.global[i] >= 0);
        CHECK(v.global[i] < 40);
        if (i % std::size_t(v.Kg) != 0) CHECK(v.global[i] == v.global[i - 1] + 1);
      }
      for (std::size_t i = 0; i < v.local.size(); ++i)
        if (i % std::size_t(v.Kl) != 0) CHECK(v.local[i] == v.local[i - 1] + 1);
      for (int r = 0; r < 2 * 3; ++r) {  // each view row: a share in ibot_ratio masked, never all
        const int m = static_cast<int>(std::count(v.ibot.begin() + r * v.Kg, v.ibot.begin() + (r + 1) * v.Kg, 1));
        CHECK(m <= static_cast<int>(v.Kg * 0.5));
        CHECK(m >= std::min(v.Kg - 1, static_cast<int>(v.Kg * 0.1)));
        CHECK(m < v.Kg);
      }
      CHECK(v.ibot_rows.size() == static_cast<std::size_t>(std::count(v.ibot.begin(), v.ibot.end(), 1)));
      const DinoViews again = sample_dino_views(c, 3, 5, s);  // deterministic in (seed, step)
      CHECK(again.global == v.global);
      CHECK(again.ibot == v.ibot);
      // A shard (data parallel): samples [1, 3) of each view, in view-major order.
      const DinoViews part = dino_views_shard(v, 1, 2);
      REQUIRE(part.B == 2);
      REQUIRE(part.global.size() == std::size_t(2 * 2 * v.Kg));
      for (int g = 0; g < 2; ++g)
        for (int b = 0; b < 2; ++b)
          for (int k = 0; k < v.Kg; ++k) {
            const std::size_t at = std::size_t((g * 2 + b) * v.Kg + k), from = std::size_t((g * 3 + 1 + b) * v.Kg + k);
            CHECK(part.global[at] == v.global[from]);
            CHECK(part.ibot[at] == v.ibot[from]);
          }
      for (int l = 0; l < 2; ++l)
        for (int b = 0; b < 2; ++b)
          CHECK(part.local[std::size_t((l * 2 + b) * v.Kl)] == v.local[std::size_t((l * 3 + 1 + b) * v.Kl)]);
      CHECK(part.ibot_rows.size() == static_cast<std::size_t>(std::count(part.ibot.begin(), part.ibot.end(), 1)));
    }
    CHECK(sample_dino_views(c, 3, 5, 0).global != sample_dino_views(c, 3, 6, 0).global);
    CHECK_THROWS_WITH_AS(dino_views_shard(sample_dino_views(c, 3, 5, 0), 2, 2), doctest::Contains("samples [2, 4) of 3"),
                         ShapeError);
  }

  TEST_CASE("DINO loss: analytic gradient of every student parameter = central differences") {
    const test::SingleThread one_thread;
    DinoConfig c = tiny_dino_config();
    SUBCASE("plain") {}
    SUBCASE("drop-path 0.5 with a fixed noise seed, no local views") {
      c.drop_path = 0.5;
      c.local_views = 0;
    }
    SUBCASE("no KoLeo, three global views") {
      c.koleo_weight = 0;
      c.global_views = 3;
    }
    DinoModel<double> model(c, 1);
    test::randomize(model.student, 2);
    test::randomize(model.student_head, 3);
    test::randomize(model.teacher, 4);
    test::randomize(model.teacher_head, 5);
    test::randomize(model.centers, 6);
    Rng rng(7);
    const int B = 3;
    const auto x = test::normal_vector(std::size_t(B) * 12 * 4, rng);
    const DinoViews v = sample_dino_views(c, B, 11, 2);
    REQUIRE(!v.ibot_rows.empty());
    DinoWorkspace<double> w;
    auto loss = [&] {
      DinoWorkspace<double> scratch;
      return dino_forward(model, x.data(), B, v, 0.05, scratch, 77);
    };
    model.student.zero_grad();
    model.student_head.zero_grad();
    const double l = dino_forward(model, x.data(), B, v, 0.05, w, 77);
    CHECK(l == loss());
    CHECK(w.dino > 0);
    CHECK(w.ibot > 0);
    CHECK(l == doctest::Approx(w.dino + w.ibot + w.koleo).epsilon(1e-14));
    dino_backward(model, w);
    // The tokenizer, positions, blocks, norm, the class row and the mask token, and the head.
    test::check_param_gradients(model.student, loss);
    test::check_param_gradients(model.student_head, loss);
    const double* dmask = model.student.grad(model.encoder.mask);
    CHECK(std::any_of(dmask, dmask + 8, [](double g) { return g != 0.0; }));
    CHECK_THROWS_WITH_AS(dino_backward(model, w), doctest::Contains("holds no forward pass"), ConfigError);
  }

  TEST_CASE("a DINO update: AdamW on the student / EMA teacher / centers toward the teacher's rows") {
    const DinoConfig c = tiny_dino_config();
    DinoModel<double> model(c, 1);
    CHECK(std::ranges::equal(model.teacher.values(), model.student.values()));
    CHECK(std::ranges::equal(model.teacher_head.values(), model.student_head.values()));
    AdamW<double> opt(model.trainable(), AdamWConfig{});
    TrainingSchedule schedule;
    schedule.lr = WarmupCosineLr{1e-4, 1e-3, 1e-5, 2, 10};
    schedule.wd = CosineWeightDecay{0.04, 0.4, 10};
    schedule.momentum = LinearMomentum{0.9, 1.0, 10};
    Rng rng(3);
    const int B = 4;
    const auto x = test::normal_vector(std::size_t(B) * 12 * 4, rng);
    DinoWorkspace<double> w;
    const ParamSet<double> student_before = model.student;
    const DinoViews v = sample_dino_views(c, B, 1, 0);
    model.student.zero_grad();
    model.student_head.zero_grad();
    const double l = dino_forward(model, x.data(), B, v, 0.04, w, 5);
    dino_backward(model, w);
    const std::vector<double> teacher_logits(w.teacher_logits.begin(), w.teacher_logits.begin() + 2 * B * 10);
    const DinoStepStats st = dino_update(model, opt, schedule, 0, l, w);
    CHECK(st.momentum == doctest::Approx(0.9));
    CHECK(!std::ranges::equal(model.student.values(), student_before.values()));
    for (std::size_t i = 0; i < model.teacher.values().size(); ++i)
      CHECK(model.teacher.values()[i] ==
            doctest::Approx(0.9 * student_before.values()[i] + 0.1 * model.student.values()[i]).epsilon(1e-12));
    // The center moved a tenth of the way toward the mean of this step's teacher class rows.
    for (int k = 0; k < 10; ++k) {
      double mean = 0;
      for (int i = 0; i < 2 * B; ++i) mean += teacher_logits[std::size_t(i) * 10 + k];
      CHECK(model.centers.value(model.center)[k] == doctest::Approx(0.1 * mean / (2 * B)).epsilon(1e-12));
    }
    CHECK(dino_teacher_temp(c, 0, 100) == doctest::Approx(0.04));
    CHECK(dino_teacher_temp(c, 1, 100) == doctest::Approx(0.055));
    CHECK(dino_teacher_temp(c, 2, 100) == doctest::Approx(0.07));
    CHECK(dino_teacher_temp(c, 99, 100) == doctest::Approx(0.07));
  }

  TEST_CASE("dino_collapsed: a uniform student scores ln P against any teacher / one that follows the teacher does not") {
    const int M = 6, P = 50;
    Rng rng(11);
    const auto t = test::normal_vector(std::size_t(M) * P, rng);
    std::vector<double> teacher(t.size()), center(P, 0.0);
    dino_teacher_probs(teacher.data(), t.data(), center.data(), M, P, 0.04);
    const std::vector<double> uniform(std::size_t(M) * P, 0.37);  // the same logit for every prototype
    const double flat = dino_cross_entropy(uniform.data(), teacher.data(), M, P, 0.1, static_cast<double*>(nullptr), 1.0) / M;
    CHECK(flat == doctest::Approx(std::log(double(P))).epsilon(1e-12));
    CHECK(dino_collapsed(flat, P));
    // A student with the teacher's logits (sharper at τₛ 0.1 than uniform by far).
    const double follows = dino_cross_entropy(t.data(), teacher.data(), M, P, 0.1, static_cast<double*>(nullptr), 1.0) / M;
    CHECK(follows < 0.9 * std::log(double(P)));
    CHECK(!dino_collapsed(follows, P));
    CHECK(!dino_collapsed(0.99 * std::log(double(P)), P));
    CHECK(dino_collapsed(0.9995 * std::log(double(P)), P));
    CHECK_THROWS_WITH_AS(dino_collapsed(1.0, 1), doctest::Contains("expected > 1"), ConfigError);
  }

  TEST_CASE("DINO config and shape errors throw with a clear message") {
    DinoConfig c = tiny_dino_config();
    c.encoder.register_tokens = 0;
    CHECK_THROWS_WITH_AS(DinoModel<float>(c, 1), doctest::Contains("expected at least 1 (the class token)"), ConfigError);
    c = tiny_dino_config();
    c.head.in_dim = 6;
    CHECK_THROWS_WITH_AS(DinoModel<float>(c, 1), doctest::Contains("head.in_dim = 6, expected encoder.dim = 8"),
                         ConfigError);
    c = tiny_dino_config();
    c.global_scale = {0.5, 0.2};
    CHECK_THROWS_WITH_AS(DinoModel<float>(c, 1), doctest::Contains("global_scale = [0.5, 0.2]"), ConfigError);
    c = tiny_dino_config();
    DinoModel<float> m(c, 1);
    DinoWorkspace<float> w;
    std::vector<float> x(2 * 12 * 4, 0.0f);
    const DinoViews v = sample_dino_views(c, 2, 1, 0);
    CHECK_THROWS_WITH_AS(dino_forward(m, x.data(), 3, v, 0.04, w, 1), doctest::Contains("views for 2 samples"),
                         ShapeError);
    const DinoViews one = sample_dino_views(c, 1, 1, 0);
    CHECK_THROWS_WITH_AS(dino_forward(m, x.data(), 1, one, 0.04, w, 1), doctest::Contains("KoLeo needs at least 2"),
                         ShapeError);
  }
}
