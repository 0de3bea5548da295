// The JEPA step end to end on a tiny model in double: the full loss against central differences
// for every trainable parameter, tiling against one predictor pass per target, the optimizer step
// with EMA, and the NaN stop.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/train/health.hpp>
#include <tjepa/train/jepa_model.hpp>
#include <tjepa/train/jepa_step.hpp>

#include <barrier>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <span>
#include <thread>
#include <vector>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

// 9 tokens, d = 8, 2 heads, 2 encoder blocks, 1 predictor block; m·τ = 4 values per taxel.
JepaConfig tiny_config(int depth = 2) {
  JepaConfig c;
  c.in_dim = 4;
  c.axes = 2;
  c.encoder = EncoderConfig{.num_tokens = 9, .dim = 8, .depth = depth, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6};
  c.predictor = PredictorConfig{8, 8, 1, 2, 2.0, false, 1e-6};
  return c;
}

// Every parameter of all three sets away from its degenerate init, so every gradient path counts.
JepaModel<double> random_model(std::uint64_t seed, int depth = 2) {
  JepaModel<double> model(tiny_config(depth), seed);
  test::randomize(model.context, seed + 1);
  test::randomize(model.target, seed + 2);
  test::randomize(model.predictor_params, seed + 3);
  return model;
}

// B = 2 samples, K = 4 context tokens, 3 targets: sizes 2, 3, 2 (two share a predictor pass),
// overlapping each other, disjoint from the context.
MaskBatch tiny_masks() {
  MaskBatch m;
  m.B = 2;
  m.K = 4;
  m.context = {0, 1, 4, 8, 2, 3, 6, 7};
  TargetSet a{2, TargetKind::local, -1, {2, 3, 0, 1}};
  TargetSet b{3, TargetKind::global, -1, {3, 5, 6, 4, 5, 8}};
  TargetSet c{2, TargetKind::local, -1, {5, 7, 1, 8}};
  m.targets = {a, b, c};
  return m;
}

std::vector<double> tiny_input(std::uint64_t seed, int B = 2) {
  Rng rng(seed);
  return test::normal_vector(static_cast<std::size_t>(B) * 9 * 4, rng);
}

// A 6 x 6 sheet (36 taxels, 4 pads) with m = 2 axes, windows of τ = 2 frames: Gaussian blobs
// drift across it (the first axis their pressure, the second its change), plus noise. Smooth in
// space and time, so context tokens predict target tokens.
WindowSource blob_source(int frames, std::uint64_t seed) {
  const int side = 6, N = side * side, m = 2;
  AlignedVector<float> v(static_cast<std::size_t>(frames) * N * m, 0.0f);
  Rng rng(seed);
  double cx = 2.5, cy = 2.5, vx = 0.3, vy = 0.2, amp = 1.0;
  std::vector<double> prev(N, 0.0);
  for (int t = 0; t < frames; ++t) {
    if (rng.uniform() < 0.05) {  // a new contact now and then
      cx = rng.uniform(0, side - 1);
      cy = rng.uniform(0, side - 1);
      vx = rng.uniform(-0.4, 0.4);
      vy = rng.uniform(-0.4, 0.4);
      amp = rng.uniform(0.5, 2.0);
    }
    cx += vx;
    cy += vy;
    if (cx < 0 || cx > side - 1) vx = -vx;
    if (cy < 0 || cy > side - 1) vy = -vy;
    for (int n = 0; n < N; ++n) {
      const double dx = n % side - cx, dy = n / side - cy;
      const double p = amp * std::exp(-(dx * dx + dy * dy) / 3.0);
      v[(static_cast<std::size_t>(t) * N + n) * m] = static_cast<float>(p + 0.02 * rng.normal());
      v[(static_cast<std::size_t>(t) * N + n) * m + 1] = static_cast<float>(p - prev[n] + 0.02 * rng.normal());
      prev[n] = p;
    }
  }
  return WindowSource(Recording(frames, N, m, std::move(v), "blobs"), WindowSpec{2});
}

TaxelGraph blob_graph() {
  layouts::GridSkinOptions o;
  o.rows = o.cols = 6;
  o.group_rows = o.group_cols = 3;
  return layouts::grid_skin(o).graph;
}

JepaConfig blob_config() {
  JepaConfig c;
  c.in_dim = 4;  // m·τ
  c.axes = 2;
  c.encoder = EncoderConfig{.num_tokens = 36, .dim = 16, .depth = 2, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6};
  c.predictor = PredictorConfig{16, 16, 1, 2, 2.0, false, 1e-6};
  return c;
}

// The reference's schedule shortened: batches of 16, `warmup` warm-up steps, a higher peak rate;
// the model keys match blob_config().
TrainConfig blob_trainer_config(std::int64_t steps, std::int64_t warmup, std::uint64_t seed) {
  TrainConfig tc;
  tc.data.tau = 2;
  tc.model.dim = 16, tc.model.depth = 2, tc.model.heads = 2, tc.model.predictor_depth = 1;
  tc.masks.min_context_tokens = 6;
  tc.schedule.steps = steps;
  tc.schedule.warmup_steps = warmup;
  tc.batch = 16;
  tc.schedule.lr = 1e-3, tc.schedule.start_lr = 1e-5, tc.schedule.final_lr = 1e-6;
  tc.schedule.ema_start = 0.994;
  tc.seed = seed;
  tc.step.drop_path = 0.0;
  return tc;
}

// BYOL on the blob sheet: 63 x 63 images of its 2 axes, a narrow AlexNet, projection 8.
ByolConfig blob_byol_config(const TrainConfig& tc) {
  ByolConfig bc = byol_config(tc, 2);
  bc.encoder.image_size = bc.image.image_size = 63;
  bc.encoder.widths = {4, 6, 6, 4, 4};
  bc.encoder.pooled = 2;
  bc.projection = 8, bc.hidden = 16;
  return bc;
}
// The sheet's 6 x 6 taxels as its picture, row-major.
TaxelCanvas blob_canvas() {
  TaxelCanvas canvas{6, 6, {}};
  for (int n = 0; n < 36; ++n) canvas.pixel.push_back(n);
  return canvas;
}

struct TempPath {
  std::filesystem::path path;
  explicit TempPath(const std::string& name)
      : path(std::filesystem::temp_directory_path() / ("tjepa_train_" + name + ".safetensors")) {
    std::filesystem::remove(path);
  }
  ~TempPath() {
    std::error_code ec;
    std::filesystem::remove(path, ec);
  }
};

// R ranks as R threads (rank 0 on the caller's): sums over a barrier, the ranks' values added in
// rank order (in T), as an allreduce would.
template <int R>
struct ThreadRanks {
  std::barrier<> sync{R};
  std::vector<float> slot[R];
  std::vector<double> stat_slot[R];

  template <class Slots, class V>
  void sum(Slots& slots, int rank, std::span<V> v) {
    slots[rank].assign(v.begin(), v.end());
    sync.arrive_and_wait();
    for (std::size_t i = 0; i < v.size(); ++i) {
      V acc = slots[0][i];
      for (int q = 1; q < R; ++q) acc = static_cast<V>(acc + slots[q][i]);
      v[i] = acc;
    }
    sync.arrive_and_wait();
  }
  DataParallel<float> parallel(int r) {
    DataParallel<float> dp;
    dp.rank = r;
    dp.ranks = R;
    dp.sum = [this, r](std::span<float> v) { sum(slot, r, v); };
    dp.sum_stats = [this, r](std::span<double> v) { sum(stat_slot, r, v); };
    return dp;
  }
  template <class F>
  void run(F&& rank_main) {
    std::vector<std::thread> others;
    for (int r = 1; r < R; ++r) others.emplace_back(rank_main, r);
    rank_main(0);
    for (auto& t : others) t.join();
  }
};

}  // namespace

TEST_SUITE("train") {
  TEST_CASE("full JEPA loss: analytic gradient of every trainable parameter = central differences") {
    const test::SingleThread one_thread;
    auto model = random_model(1);
    const auto x = tiny_input(5);
    const MaskBatch masks = tiny_masks();
    JepaStepConfig cfg;
    cfg.drop_path = 0.0;
    SUBCASE("MSE, target encoder's position rows (the reference)") {}
    SUBCASE("drop-path 0.5 in both encoders, fixed noise seed") { cfg.drop_path = 0.5; }
    SUBCASE("smooth-L1 against re-normalized targets, context encoder's position rows") {
      cfg.loss = JepaLossKind::smooth_l1;
      cfg.normalize_targets = true;
      cfg.predictor_pos_from_context = true;
    }
    SUBCASE("MSE against targets standardized per token over the batch") { cfg.standardize_targets = true; }
    JepaStep<double> step(model, cfg);
    const std::uint64_t noise = 77;
    auto loss = [&] { return step.forward(x.data(), 2, masks, noise).loss; };
    const auto target_before = model.target;
    step.zero_grad();
    const double l = step.forward(x.data(), 2, masks, noise).loss;
    step.backward();
    CHECK(l == doctest::Approx(loss()).epsilon(1e-13));
    CHECK(l > 0);
    test::check_param_gradients(model.context, loss);
    test::check_param_gradients(model.predictor_params, loss);
    // The target encoder gets no gradient and is not changed by the loss.
    for (double g : model.target.grads()) CHECK(g == 0.0);
    CHECK(std::equal(model.target.values().begin(), model.target.values().end(), target_before.values().begin()));
    // Position rows get a gradient through the predictor only when it reads the context's table.
    const auto pos = model.context.grad_span(model.encoder.pos_embed());
    const bool pos_grad = std::any_of(pos.begin(), pos.end(), [](double g) { return g != 0.0; });
    CHECK(pos_grad);  // the context encoder's own use of its rows always gives one
  }

  TEST_CASE("row-weighted regression loss: the weighted mean and its gradient") {
    Rng rng(3);
    const int rows = 5, d = 3;
    std::vector<double> pred(rows * d), target(rows * d), weight(rows);
    for (auto& v : pred) v = rng.normal();
    for (auto& v : target) v = rng.normal();
    for (auto& v : weight) v = rng.uniform(0.5, 4.0);
    for (JepaLossKind kind : {JepaLossKind::mse, JepaLossKind::smooth_l1}) {
      CAPTURE(to_string(kind));
      auto ell = [&](double e) { return kind == JepaLossKind::mse ? e * e : (std::abs(e) < 1 ? 0.5 * e * e : std::abs(e) - 0.5); };
      double num = 0, den = 0;
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < d; ++c) num += weight[r] * ell(pred[r * d + c] - target[r * d + c]);
        den += weight[r] * d;
      }
      std::vector<double> g(rows * d);
      const double l = regression_loss(pred.data(), target.data(), g.data(), pred.size(), kind, 0.5, weight.data(), d);
      CHECK(l == doctest::Approx(num / den).epsilon(1e-14));
      for (std::size_t i = 0; i < pred.size(); ++i) {
        const double h = 1e-6, keep = pred[i];
        pred[i] = keep + h;
        const double up = regression_loss(pred.data(), target.data(), static_cast<double*>(nullptr), pred.size(), kind, 1.0, weight.data(), d);
        pred[i] = keep - h;
        const double down = regression_loss(pred.data(), target.data(), static_cast<double*>(nullptr), pred.size(), kind, 1.0, weight.data(), d);
        pred[i] = keep;
        CHECK(g[i] == doctest::Approx(0.5 * (up - down) / (2 * h)).epsilon(1e-7));
      }
      // Equal weights give the plain mean and its gradient, bit for bit up to rounding.
      std::vector<double> ones(rows, 3.0), g1(rows * d), g0(rows * d);
      const double l1 = regression_loss(pred.data(), target.data(), g1.data(), pred.size(), kind, 1.0, ones.data(), d);
      const double l0 = regression_loss(pred.data(), target.data(), g0.data(), pred.size(), kind);
      CHECK(l1 == doctest::Approx(l0).epsilon(1e-14));
      for (std::size_t i = 0; i < g0.size(); ++i) CHECK(g1[i] == doctest::Approx(g0[i]).epsilon(1e-14));
    }
  }

  TEST_CASE("standardize_columns: zero mean and unit variance per column / blind to a column's offset and scale") {
    Rng rng(8);
    const std::size_t M = 7, D = 1100;  // D spans three of the kernel's column chunks
    std::vector<double> x(M * D);
    for (auto& v : x) v = rng.normal();
    std::vector<double> shifted = x;
    for (std::size_t j = 0; j < D; ++j) {
      const double offset = rng.uniform(-50.0, 50.0), scale = rng.uniform(0.5, 3.0);
      for (std::size_t m = 0; m < M; ++m) shifted[m * D + j] = offset + scale * x[m * D + j];
    }
    standardize_columns(x.data(), M, D, 0.0);
    standardize_columns(shifted.data(), M, D, 0.0);
    for (std::size_t j = 0; j < D; ++j) {
      double s1 = 0, s2 = 0;
      for (std::size_t m = 0; m < M; ++m) s1 += x[m * D + j], s2 += x[m * D + j] * x[m * D + j];
      CHECK(s1 / M == doctest::Approx(0.0).scale(1.0).epsilon(1e-12));
      CHECK(s2 / M == doctest::Approx(1.0).epsilon(1e-12));
      for (std::size_t m = 0; m < M; ++m) CHECK(shifted[m * D + j] == doctest::Approx(x[m * D + j]).epsilon(1e-9));
    }
    // In the loss: a position-only encoder (the same target embedding at a token for every
    // sample) leaves nothing to predict but eps-scaled zeros, and B = 1 is refused.
    auto model = random_model(4);
    JepaStepConfig cfg;
    cfg.drop_path = 0.0;
    cfg.standardize_targets = true;
    JepaStep<double> step(model, cfg);
    const auto& w = step.workspace();
    const auto x2 = tiny_input(5);
    std::vector<double> same(x2.begin(), x2.begin() + static_cast<std::ptrdiff_t>(x2.size() / 2));
    same.insert(same.end(), same.begin(), same.end());
    step.forward(same.data(), 2, tiny_masks(), 1);
    for (std::size_t i = 0; i < 2 * std::size_t(model.num_tokens()) * model.dim(); ++i) CHECK(std::abs(w.h[i]) < 1e-6);
    MaskBatch one = tiny_masks();  // sample 0's context and targets alone
    one.B = 1;
    one.context.resize(static_cast<std::size_t>(one.K));
    for (TargetSet& t : one.targets) t.indices.resize(static_cast<std::size_t>(t.size));
    CHECK_THROWS_WITH_AS(step.forward(x2.data(), 1, one, 1), doctest::Contains("at least 2 samples"),
                         ConfigError);
  }

  TEST_CASE("two backward passes accumulate twice the gradient") {
    auto model = random_model(11, 1);
    const auto x = tiny_input(14);
    JepaStep<double> step(model, JepaStepConfig{.drop_path = 0.3});
    step.zero_grad();
    step.forward(x.data(), 2, tiny_masks(), 5);
    step.backward();
    const auto once = model.context;
    step.forward(x.data(), 2, tiny_masks(), 5);
    step.backward();
    for (std::size_t i = 0; i < once.grads().size(); ++i)
      CHECK(model.context.grads()[i] == doctest::Approx(2 * once.grads()[i]).epsilon(1e-12));
  }

  TEST_CASE("tiling targets gives the loss of one predictor pass per target averaged over targets") {
    auto model = random_model(21);
    const auto x = tiny_input(25);
    const MaskBatch masks = tiny_masks();
    JepaStepConfig cfg;
    cfg.drop_path = 0.0;
    JepaStep<double> step(model, cfg);
    const auto r = step.forward(x.data(), 2, masks, 1);
    // Each target on its own, the way the reference's formula reads.
    const int B = 2, N = 9, d = 8;
    Workspace<double> ws;
    std::vector<double> tok(B * N * d), h(B * N * d), z(B * masks.K * d);
    model.tokenizer.forward(model.target, x.data(), B, tok.data(), ws);
    model.encoder.forward(model.target, {tok.data(), B}, h.data(), ws);
    model.tokenizer.forward(model.context, x.data(), B, tok.data(), ws);
    model.encoder.forward(model.context, {tok.data(), B, masks.context}, z.data(), ws);
    double mean = 0;
    for (int j = 0; j < masks.num_targets(); ++j) {
      const TargetSet& ts = masks.targets[j];
      std::vector<double> p(B * ts.size * d);
      model.predictor.forward(model.predictor_params, {z.data(), B, masks.K, model.target.value(model.encoder.pos_embed()), N,
                               ts.indices.data(), B, ts.size}, p.data(), ws);
      double s = 0;
      for (int b = 0; b < B; ++b)
        for (int k = 0; k < ts.size; ++k)
          for (int c = 0; c < d; ++c) {
            const double e = p[(b * ts.size + k) * d + c] - h[(b * N + ts.row(b)[k]) * d + c];
            s += e * e;
          }
      const double lj = s / (B * ts.size * d);
      CHECK(r.target_losses[j] == doctest::Approx(lj).epsilon(1e-12));
      mean += lj / masks.num_targets();
    }
    CHECK(r.loss == doctest::Approx(mean).epsilon(1e-12));
    // The target-embedding std is the per-dimension std over all B·N embeddings, averaged.
    double stdsum = 0;
    for (int c = 0; c < d; ++c) {
      double mu = 0, v = 0;
      for (int i = 0; i < B * N; ++i) mu += h[i * d + c];
      mu /= B * N;
      for (int i = 0; i < B * N; ++i) v += (h[i * d + c] - mu) * (h[i * d + c] - mu);
      stdsum += std::sqrt(v / (B * N - 1));
    }
    CHECK(r.target_std == doctest::Approx(stdsum / d).epsilon(1e-12));
    // The sample std is the std over the B samples at each token and dimension, averaged.
    double sample = 0;
    for (int i = 0; i < N * d; ++i) {
      double mu = 0, v = 0;
      for (int b = 0; b < B; ++b) mu += h[b * N * d + i];
      mu /= B;
      for (int b = 0; b < B; ++b) v += (h[b * N * d + i] - mu) * (h[b * N * d + i] - mu);
      sample += std::sqrt(v / (B - 1));
    }
    CHECK(r.target_sample_std == doctest::Approx(sample / (N * d)).epsilon(1e-12));
    CHECK(r.target_sample_std > 0);
    // Embeddings that ignore the input (position only) have no sample spread but a token spread.
    std::vector<double> positional(static_cast<std::size_t>(B) * N * d);
    for (int b = 0; b < B; ++b)
      for (int i = 0; i < N * d; ++i) positional[static_cast<std::size_t>(b) * N * d + i] = std::sin(0.7 * i);
    CHECK(embedding_std(positional.data(), static_cast<std::size_t>(B), N * d) == doctest::Approx(0.0));
    CHECK(embedding_std(positional.data(), static_cast<std::size_t>(B) * N, d) > 0.1);
  }

  TEST_CASE("a training step: scheduled AdamW on the trainable sets then the EMA of the target encoder") {
    JepaModel<double> model(tiny_config(1), 31);
    test::randomize(model.predictor_params, 32);
    const auto x = tiny_input(33);
    AdamW<double> opt(model.trainable());
    const auto schedule = TrainingSchedule::reference(10, 4, 2);
    JepaStep<double> step(model, JepaStepConfig{.drop_path = 0.3});
    const auto context0 = model.context;
    const auto target0 = model.target;
    const auto st = step.train(opt, schedule, 5, x.data(), 2, tiny_masks(), 9);
    CHECK(st.step == 5);
    CHECK(st.lr == doctest::Approx(schedule.lr(6)).epsilon(1e-15));
    CHECK(st.weight_decay == doctest::Approx(schedule.wd(5)).epsilon(1e-15));  // the reference timing: update s at wd(s)
    CHECK(st.momentum == doctest::Approx(schedule.momentum(5)).epsilon(1e-15));
    CHECK(st.grad_norm > 0);
    CHECK(st.target_std > 0);
    CHECK(st.target_losses.size() == 3);
    CHECK(opt.steps() == 1);
    bool moved = false;
    for (std::size_t i = 0; i < model.context.flat_size(); ++i) {
      moved |= model.context.values()[i] != context0.values()[i];
      CHECK(model.target.values()[i] == doctest::Approx(st.momentum * target0.values()[i] +
                                                        (1 - st.momentum) * model.context.values()[i])
                                            .epsilon(1e-14));
    }
    CHECK(moved);
  }

  TEST_CASE("a NaN stops the step with NumericError before any parameter changes") {
    JepaModel<double> model(tiny_config(1), 41);
    auto x = tiny_input(42);
    x[7] = std::numeric_limits<double>::quiet_NaN();
    AdamW<double> opt(model.trainable());
    const auto schedule = TrainingSchedule::reference(10, 4, 2);
    JepaStep<double> step(model, JepaStepConfig{.drop_path = 0.3});
    const auto before = model;
    CHECK_THROWS_WITH_AS(step.train(opt, schedule, 0, x.data(), 2, tiny_masks(), 1),
                         doctest::Contains("JEPA step 0: the loss is nan"), NumericError);
    CHECK(opt.steps() == 0);
    for (auto [a, b] : {std::pair{&model.context, &before.context}, std::pair{&model.target, &before.target},
                        std::pair{&model.predictor_params, &before.predictor_params}})
      CHECK(std::equal(a->values().begin(), a->values().end(), b->values().begin()));
    // Masks that do not fit the model are rejected.
    MaskBatch bad = tiny_masks();
    bad.context[3] = 9;
    CHECK_THROWS_AS(step.forward(x.data(), 2, bad, 1), ShapeError);
    // backward needs a forward pass to differentiate.
    JepaStep<double> fresh(model, JepaStepConfig{.drop_path = 0.3});
    CHECK_THROWS_WITH_AS(fresh.backward(), doctest::Contains("no forward pass"), ConfigError);
  }

  TEST_CASE("windows reach the tokenizer axis-major as the reference's patch embedding reads them") {
    WindowBatch b;
    b.batch = 1;
    b.taxels = 2;
    b.length = 3;
    b.axes = 2;
    b.x = {0, 1, 2, 3, 4, 5, 10, 11, 12, 13, 14, 15};  // [1, 2, τ = 3, m = 2]: value = 10·taxel + 2·frame + axis
    AlignedVector<double> out;
    windows_to_tokens(b, out);
    CHECK(std::vector<double>(out.begin(), out.end()) == std::vector<double>{0, 2, 4, 1, 3, 5, 10, 12, 14, 11, 13, 15});
  }

  TEST_CASE("the tokenizer's initial bias: zero as the reference or drawn with the configured std") {
    JepaConfig c = tiny_config();
    const JepaModel<float> reference(c, 5);
    const auto bias = [](const JepaModel<float>& m, const ParamSet<float>& ps) {
      const auto& p = m.tokenizer.maps.front().proj;
      return std::vector<float>(ps.value(p.bias), ps.value(p.bias) + p.out);
    };
    for (float v : bias(reference, reference.context)) CHECK(v == 0.0f);
    c.tokenizer_bias_std = 2.0;
    const JepaModel<float> a(c, 5), b(c, 5), other(c, 6);
    const std::vector<float> ba = bias(a, a.context);
    CHECK(ba == bias(b, b.context));            // same seed, same bias
    CHECK(ba != bias(other, other.context));    // another seed, another bias
    CHECK(ba == bias(a, a.target));             // the target encoder starts as a copy
    double s2 = 0;
    for (float v : ba) s2 += double(v) * v;
    const double rms = std::sqrt(s2 / ba.size());
    CHECK(rms > 1.0);                           // std 2 over d values
    CHECK(rms < 3.0);
    // Nothing else moved: the weights are those of the reference init.
    const auto& w = a.tokenizer.maps.front().proj.weight;
    CHECK(std::ranges::equal(a.context.value_span(w), reference.context.value_span(w)));
    c.tokenizer_bias_std = -1.0;
    CHECK_THROWS_AS(JepaModel<float>(c, 5), ConfigError);
  }

  TEST_CASE("set_positions writes the context and target position tables and nothing else") {
    const JepaConfig c = tiny_config();
    JepaModel<float> m(c, 5);
    const JepaModel<float> reference(c, 5);
    const int N = m.num_tokens(), d = m.dim();
    // A path graph over the tokens: graph_positions' rows, as the demo starts its table.
    std::vector<Edge> edges;
    for (int i = 0; i + 1 < N; ++i) edges.push_back({i, i + 1, 1.0});
    const std::vector<double> rows = graph_positions(TaxelGraph(N, edges), d, std::min(N, 4), 0.7, 1);
    m.set_positions(rows);
    for (const ParamSet<float>* ps : {&m.context, &m.target}) {
      const auto e = ps->value_span(m.encoder.pos_embed());
      REQUIRE(e.size() == rows.size());
      for (std::size_t i = 0; i < rows.size(); ++i) CHECK(e[i] == static_cast<float>(rows[i]));
    }
    const auto& w = m.tokenizer.maps.front().proj.weight;
    CHECK(std::ranges::equal(m.context.value_span(w), reference.context.value_span(w)));
    CHECK_THROWS_WITH_AS(m.set_positions(std::vector<double>(3, 0.0)), doctest::Contains("expected N·d"), ShapeError);
    std::vector<double> bad = rows;
    bad[5] = NAN;
    CHECK_THROWS_WITH_AS(m.set_positions(bad), doctest::Contains("value 5"), DataError);
    // Nothing was written by the rejected calls.
    CHECK(m.context.value_span(m.encoder.pos_embed())[5] == static_cast<float>(rows[5]));
  }

  TEST_CASE("save then load then continue: the loss curve is bitwise that of an uninterrupted run") {
    const auto source = blob_source(200, 1);  // 100 windows: 6 batches of 16 per epoch
    const auto graph = blob_graph();
    TrainConfig tc = blob_trainer_config(18, 6, 5);
    tc.step.drop_path = 0.1;  // exercises the per-step noise seeds
    TempPath ckpt("resume");
    auto arm = [&](JepaTrainer<float>& t) {
      t.checkpoint = ckpt.path;
      t.checkpoint_every = 4;  // steps 4 and 8 land mid-epoch
    };

    JepaModel<float> straight_model(blob_config(), 7);
    JepaTrainer<float> straight(straight_model, source, graph, tc);
    CHECK(straight.total_steps() == 18);
    std::vector<double> straight_loss;
    for (const auto& st : straight.run()) straight_loss.push_back(st.loss);

    JepaModel<float> first_model(blob_config(), 7);
    JepaTrainer<float> first(first_model, source, graph, tc);
    arm(first);
    const auto head = first.run(10);  // checkpoints after steps 4 and 8
    REQUIRE(head.size() == 10);
    for (int s = 0; s < 10; ++s) CHECK(head[s].loss == straight_loss[s]);

    JepaModel<float> resumed_model(blob_config(), 12345);  // a different init: everything must come from the file
    JepaTrainer<float> resumed(resumed_model, source, graph, tc);
    arm(resumed);
    resumed.resume(ckpt.path);
    CHECK(resumed.step() == 8);
    // The per-taxel tokenizer weight is stored as the reference's Conv1d weight [d, m, τ].
    CHECK(load_safetensors(ckpt.path).at("context_encoder.patch_embed.proj.weight").shape ==
          std::vector<std::int64_t>{16, 2, 2});
    const auto tail = resumed.run();
    REQUIRE(tail.size() == 10);
    for (int s = 0; s < 10; ++s) {
      CHECK(tail[s].step == 8 + s);
      CHECK(tail[s].loss == straight_loss[8 + s]);  // bitwise
    }
    for (auto [a, b] : {std::pair{&resumed_model.context, &straight_model.context},
                        std::pair{&resumed_model.target, &straight_model.target},
                        std::pair{&resumed_model.predictor_params, &straight_model.predictor_params}})
      CHECK(std::memcmp(a->values().data(), b->values().data(), a->values().size_bytes()) == 0);

    // A run with another shape or schedule refuses the checkpoint.
    TrainConfig other = tc;
    other.schedule.steps = 24;
    JepaModel<float> m2(blob_config(), 1);
    JepaTrainer<float> t2(m2, source, graph, other);
    CHECK_THROWS_WITH_AS(t2.resume(ckpt.path), doctest::Contains("was written with train.steps = 18"), ConfigError);
  }

  TEST_CASE("MAE through the Trainer: the verbs' loop step for step / save then resume is bitwise / no JEPA file") {
    const auto source = blob_source(200, 1);  // 100 windows: 6 batches of 16 per epoch
    TrainConfig tc = blob_trainer_config(14, 4, 3);
    tc.step.drop_path = 0.1;  // exercises the per-step noise seeds
    const MaeConfig mc = mae_config(tc, 36, 2);
    CHECK(mc.drop_path == 0.1);

    // The loop by hand from the verbs: the shared data order, uniform masks and noise streams.
    MaeModel<float> by_hand(mc, 7);
    {
      AdamW<float> opt(by_hand.trainable(), tc.adamw);
      const TrainingSchedule schedule = tc.schedule.build();
      const UniformMasking masking(36, mc.mask_ratio);
      MaeWorkspace<float> w;
      MaskBatch masks;
      WindowBatch batch;
      AlignedVector<float> x;
      std::vector<double> losses;
      for (std::int64_t s = 0; s < tc.schedule.steps; ++s) {
        const auto order = source.epoch_order(streams::data(tc.seed), static_cast<std::uint64_t>(s / 6));
        source.gather(std::span<const std::int64_t>(order).subspan(static_cast<std::size_t>(s % 6) * 16, 16), batch);
        windows_to_tokens(batch, x);
        masking.sample_into(masks, 16, streams::masks(tc.seed), static_cast<std::uint64_t>(s));
        losses.push_back(mae_train_step(by_hand, opt, schedule, s, x.data(), 16, masks, w, streams::noise(tc.seed, s)).loss);
      }
      MaeModel<float> model(mc, 7);
      MaeTrainer<float> trainer(model, source, tc);
      CHECK(trainer.total_steps() == 14);
      const auto stats = trainer.run();
      REQUIRE(stats.size() == losses.size());
      for (std::size_t s = 0; s < losses.size(); ++s) CHECK(stats[s].loss == losses[s]);  // bitwise
      CHECK(std::ranges::equal(model.context.values(), by_hand.context.values()));
      CHECK(std::ranges::equal(model.decoder_params.values(), by_hand.decoder_params.values()));
    }

    TempPath ckpt("mae_resume");
    MaeModel<float> first_model(mc, 7);
    MaeTrainer<float> first(first_model, source, tc);
    first.checkpoint = ckpt.path;
    first.checkpoint_every = 4;
    REQUIRE(first.run(10).size() == 10);  // checkpoints after steps 4 and 8
    MaeModel<float> resumed_model(mc, 999);  // another init: everything must come from the file
    MaeTrainer<float> resumed(resumed_model, source, tc);
    resumed.resume(ckpt.path);
    CHECK(resumed.step() == 8);
    const auto tail = resumed.run();
    REQUIRE(tail.size() == 6);
    for (std::size_t k = 0; k < tail.size(); ++k) CHECK(tail[k].step == static_cast<std::int64_t>(8 + k));
    CHECK(std::ranges::equal(resumed_model.context.values(), by_hand.context.values()));
    CHECK(std::ranges::equal(resumed_model.decoder_params.values(), by_hand.decoder_params.values()));
    const nlohmann::json meta = nlohmann::json::parse(load_safetensors(ckpt.path).metadata.at("config"));
    CHECK(meta["objective"] == "mae");
    CHECK(meta["version"] == checkpoint_metadata_version);

    // A JEPA checkpoint is not an MAE run's, and the other way round.
    TempPath jepa_ckpt("mae_vs_jepa");
    JepaModel<float> jm(blob_config(), 7);
    JepaTrainer<float> jt(jm, source, blob_graph(), tc);
    jt.save(jepa_ckpt.path);
    CHECK_THROWS_WITH_AS(resumed.resume(jepa_ckpt.path), doctest::Contains("a checkpoint of a 'jepa' run"), ConfigError);
    CHECK_THROWS_WITH_AS(jt.resume(ckpt.path), doctest::Contains("a checkpoint of a 'mae' run"), ConfigError);
  }

  TEST_CASE("DINO through the Trainer: the loss falls / save then resume is bitwise / a JEPA file is refused") {
    const auto source = blob_source(200, 1);  // 100 windows: 6 batches of 16 per epoch
    TrainConfig tc = blob_trainer_config(12, 2, 3);
    tc.step.drop_path = 0.1;
    DinoConfig dc = dino_config(tc, 36, 2);
    dc.local_views = 2;
    CHECK(dc.head.prototypes == 16 * tc.model.dim);
    DinoModel<float> straight_model(dc, 7);
    DinoTrainer<float> straight(straight_model, source, tc);
    const auto stats = straight.run();
    REQUIRE(stats.size() == 12);
    for (const auto& st : stats) {
      CHECK(std::isfinite(st.loss));
      CHECK(st.loss == doctest::Approx(st.dino + st.ibot + st.koleo).epsilon(1e-6));
    }
    CHECK(stats.front().teacher_temp == doctest::Approx(dc.teacher_temp[0]));

    TempPath ckpt("dino_resume");
    DinoModel<float> first_model(dc, 7);
    DinoTrainer<float> first(first_model, source, tc);
    first.checkpoint = ckpt.path;
    first.checkpoint_every = 4;
    REQUIRE(first.run(10).size() == 10);  // checkpoints after steps 4 and 8
    DinoModel<float> resumed_model(dc, 999);  // another init: everything must come from the file
    DinoTrainer<float> resumed(resumed_model, source, tc);
    resumed.resume(ckpt.path);
    CHECK(resumed.step() == 8);
    const auto tail = resumed.run();
    REQUIRE(tail.size() == 4);
    for (std::size_t k = 0; k < tail.size(); ++k) CHECK(tail[k].loss == stats[8 + k].loss);  // bitwise
    for (auto [a, b] : {std::pair{&resumed_model.student, &straight_model.student},
                        {&resumed_model.teacher_head, &straight_model.teacher_head},
                        {&resumed_model.centers, &straight_model.centers}})
      CHECK(std::ranges::equal(a->values(), b->values()));
    const nlohmann::json meta = nlohmann::json::parse(load_safetensors(ckpt.path).metadata.at("config"));
    CHECK(meta["objective"] == "dino");
    CHECK(meta["dino"]["views"] == nlohmann::json{2, 2});

    TempPath jepa_ckpt("dino_vs_jepa");
    JepaModel<float> jm(blob_config(), 7);
    JepaTrainer<float> jt(jm, source, blob_graph(), tc);
    jt.save(jepa_ckpt.path);
    CHECK_THROWS_WITH_AS(resumed.resume(jepa_ckpt.path), doctest::Contains("a checkpoint of a 'jepa' run"), ConfigError);
  }

  TEST_CASE("BYOL through the Trainer: save then resume is bitwise / images of the middle frame / a DINO file is refused") {
    const auto source = blob_source(200, 1);
    const TrainConfig tc = blob_trainer_config(6, 1, 3);
    CHECK(byol_config(tc, 2).projection == 1024);
    CHECK(byol_config(tc, 2).hidden == 4096);
    CHECK(byol_config(tc, 2).momentum == 0.99);
    const ByolConfig bc = blob_byol_config(tc);
    const TaxelCanvas canvas = blob_canvas();
    ByolModel<float> straight_model(bc, 7);
    ByolTrainer<float> straight(straight_model, source, canvas, tc);
    const auto stats = straight.run();
    REQUIRE(stats.size() == 6);
    for (const auto& st : stats) {
      CHECK(std::isfinite(st.loss));
      CHECK(st.loss >= 0);
      CHECK(st.loss <= 8);
    }
    TempPath ckpt("byol_resume");
    ByolModel<float> first_model(bc, 7);
    ByolTrainer<float> first(first_model, source, canvas, tc);
    first.checkpoint = ckpt.path;
    first.checkpoint_every = 4;
    REQUIRE(first.run(5).size() == 5);
    ByolModel<float> resumed_model(bc, 999);
    ByolTrainer<float> resumed(resumed_model, source, canvas, tc);
    resumed.resume(ckpt.path);
    CHECK(resumed.step() == 4);
    const auto tail = resumed.run();
    REQUIRE(tail.size() == 2);
    for (std::size_t k = 0; k < tail.size(); ++k) CHECK(tail[k].loss == stats[4 + k].loss);  // bitwise
    for (auto [a, b] : {std::pair{&resumed_model.online, &straight_model.online},
                        {&resumed_model.target_projector, &straight_model.target_projector},
                        {&resumed_model.predictor_params, &straight_model.predictor_params}})
      CHECK(std::ranges::equal(a->values(), b->values()));
    const nlohmann::json meta = nlohmann::json::parse(load_safetensors(ckpt.path).metadata.at("config"));
    CHECK(meta["objective"] == "byol");
    // The frozen features: one token per cell of the pooled map, the last conv's channels.
    const std::vector<std::int64_t> ids{0, 5, 9};
    const AlignedVector<float> f = byol_embed(straight_model, straight_model.online, canvas, source, ids, 2);
    CHECK(f.size() == 3u * 4 * 4);
    CHECK(std::all_of(f.begin(), f.end(), [](float v) { return std::isfinite(v); }));
    TempPath dino_ckpt("byol_vs_dino");
    DinoModel<float> dm(dino_config(tc, 36, 2), 7);
    DinoTrainer<float> dt(dm, source, tc);
    dt.save(dino_ckpt.path);
    CHECK_THROWS_WITH_AS(resumed.resume(dino_ckpt.path), doctest::Contains("a checkpoint of a 'dino' run"), ConfigError);
    TaxelCanvas small{5, 5, {}};
    for (int n = 0; n < 25; ++n) small.pixel.push_back(n);
    CHECK_THROWS_WITH_AS(ByolTrainer<float>(resumed_model, source, small, tc), doctest::Contains("places 25 taxels"),
                         ShapeError);
  }

  TEST_CASE("TrainConfig is the modules' configs with one flat JSON key per setting") {
    // One default per setting: the members are the modules' own configs.
    const TrainConfig tc;
    const MaskConfig m0;
    CHECK(tc.to_json()["context_ratio"] == nlohmann::json::array({m0.context_ratio.lo, m0.context_ratio.hi}));
    CHECK(tc.to_json()["block_targets"] == m0.blocks.num_targets);
    CHECK(tc.step.to_json() == JepaStepConfig{}.to_json());
    CHECK(TrainConfig::reference(10).step.drop_path == 0.3);  // the reference's values: TrainConfig::reference
    // Every kind of setting through the flat view: enums by name, ranges as [lo, hi].
    TrainConfig c;
    c.update({{"precision", "bf16"}, {"mask_scheme", "ijepa_blocks"}, {"weight_decay_timing", "ijepa"},
              {"loss", "smooth_l1"}, {"block_target_scale", {0.1, 0.3}}, {"local_targets", 3}, {"beta2", 0.95},
              {"steps", 7}, {"warmup_steps", 2}, {"tau", 5}, {"dim", 12}, {"part_targets", "whole"}},
             "test");
    CHECK(c.step.precision == Precision::bf16);
    CHECK(c.masks.scheme == TargetScheme::ijepa_blocks);
    CHECK(c.schedule.wd_timing == WeightDecayTiming::ijepa);
    CHECK(c.step.loss == JepaLossKind::smooth_l1);
    CHECK(c.masks.blocks.target_scale == RatioRange{0.1, 0.3});
    CHECK(c.masks.part_targets == PartTargets::whole);
    CHECK(c.masks.num_local == 3);
    CHECK(c.adamw.beta2 == 0.95);
    CHECK(c.schedule.steps == 7);
    CHECK(c.data.tau == 5);
    CHECK(c.model.dim == 12);
    const nlohmann::json j = c.to_json();
    CHECK(j["precision"] == "bf16");
    CHECK(j["mask_scheme"] == "ijepa_blocks");
    CHECK(j["block_target_scale"] == nlohmann::json::array({0.1, 0.3}));
    CHECK(TrainConfig::from_json(j, "round trip").to_json() == j);
    CHECK(c.schedule.build().wd_timing == WeightDecayTiming::ijepa);
    // A name or shape that is no setting's is refused by key, and nothing changes.
    CHECK_THROWS_WITH_AS(c.update({{"precision", "fp16"}, {"steps", 9}}, "run.json"),
                         doctest::Contains("run.json: key 'precision' = \"fp16\", expected one of 'fp32', 'bf16'"),
                         ConfigError);
    CHECK_THROWS_WITH_AS(c.update({{"context_ratio", {0.5}}}, "run.json"),
                         doctest::Contains("key 'context_ratio' = [0.5], expected an array [lo, hi]"), ConfigError);
    CHECK(c.step.precision == Precision::bf16);
    CHECK(c.schedule.steps == 7);
    // validate() checks the masks without a graph.
    TrainConfig bad;
    bad.masks.max_tries = 0;
    CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("max_tries = 0"), ConfigError);
    bad = TrainConfig{};
    bad.masks.scheme = TargetScheme::ijepa_blocks;
    bad.masks.blocks.target_scale = {0.5, 0.2};
    CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("blocks.target_scale"), ConfigError);
    // The checkpoints that predate the mask keys ran at today's mask defaults.
    const nlohmann::json now = TrainConfig{}.to_json();
    for (const char* key : {"local_targets_per_part", "global_targets_per_part", "part_targets", "global_sampling",
                            "context_sampling", "mask_scheme", "block_target_scale", "block_target_aspect",
                            "block_context_scale", "block_context_aspect", "block_targets", "min_context_ratio",
                            "mask_max_tries"}) {
      CAPTURE(key);
      CHECK(checkpoint_legacy_defaults().at(key) == now.at(key));
    }
    // A trainer given a sampler of its own records that sampler's masks in its checkpoints.
    const auto source = blob_source(100, 2);
    const TrainConfig run = blob_trainer_config(6, 2, 4);
    MaskConfig four = run.masks;
    four.num_local = 4;
    four.num_global = 0;
    JepaModel<float> model(blob_config(), 3);
    JepaTrainer<float> trainer(model, source, MaskCollator(blob_graph(), four), run);
    CHECK(trainer.metadata()["train"]["local_targets"] == 4);
    CHECK(trainer.metadata()["train"]["global_targets"] == 0);
    CHECK(trainer.objective().config().masks.num_local == 4);
  }


  TEST_CASE("a checkpoint without a metadata version (version 1) is a JEPA run's and resumes") {
    const auto source = blob_source(100, 2);
    const TrainConfig tc = blob_trainer_config(6, 2, 4);
    TempPath ckpt("v1");
    JepaModel<float> m(blob_config(), 3);
    JepaTrainer<float> t(m, source, blob_graph(), tc);
    t.run(3);
    t.save(ckpt.path);
    // Today's files before the version: config = {"train", "model"} only.
    SafetensorsFile f = load_safetensors(ckpt.path);
    nlohmann::json meta = nlohmann::json::parse(f.metadata.at("config"));
    meta.erase("version");
    meta.erase("objective");
    // ... and before the run keys added later (checkpoint_legacy_defaults).
    for (const auto& [key, value] : checkpoint_legacy_defaults().items()) meta["train"].erase(key);
    f.metadata["config"] = meta.dump();
    save_safetensors(ckpt.path, f);
    // Read back, the file gives the behaviour it was written with: I-JEPA's weight-decay timing.
    const TrainedModel loaded = load_trained_model(ckpt.path);
    CHECK(loaded.step == 3);
    CHECK(loaded.config.schedule.wd_timing == WeightDecayTiming::ijepa);
    CHECK(loaded.config.data.taxel_order.empty());
    // A run with today's default timing is refused, by name; the file's own config resumes.
    JepaModel<float> m2(blob_config(), 3);
    JepaTrainer<float> fresh(m2, source, blob_graph(), tc);
    CHECK_THROWS_WITH_AS(fresh.resume(ckpt.path), doctest::Contains("train.wd_initial = -1.0"), ConfigError);
    TrainConfig old = tc;
    old.schedule.wd_timing = WeightDecayTiming::ijepa;
    old.schedule.wd_initial = -1;
    JepaModel<float> m3(blob_config(), 3);
    JepaTrainer<float> t2(m3, source, blob_graph(), old);
    t2.resume(ckpt.path);
    CHECK(t2.step() == 3);
  }

  TEST_CASE("data parallel: 3 ranks (threads) gather only their shards and follow the 1-process curve") {
    // The MPI-free core of the data-parallel design: three Trainers in three threads, their sums
    // over a barrier (ranks' values added in rank order, in T). A batch of 16 on 3 ranks gives
    // uneven shards of 5, 5 and 6 samples, so the count / B scaling is exercised.
    constexpr int R = 3;
    const auto source = blob_source(200, 1);  // 100 windows: 6 batches of 16 per epoch
    const auto graph = blob_graph();
    TrainConfig tc = blob_trainer_config(8, 2, 5);
    tc.step.drop_path = 0.2;  // per-sample noise must not depend on the shard
    JepaModel<float> single_model(blob_config(), 7);
    JepaTrainer<float> single(single_model, source, graph, tc);
    std::vector<double> single_loss, single_spread;
    for (const auto& st : single.run()) {
      single_loss.push_back(st.loss);
      single_spread.push_back(st.target_sample_std);
    }

    struct GatherLog {  // a Source that remembers which windows it served
      const WindowSource& src;
      mutable std::vector<std::int64_t> ids;
      std::int64_t size() const { return src.size(); }
      std::int64_t batches_per_epoch(int b) const { return src.batches_per_epoch(b); }
      std::vector<std::int64_t> epoch_order(std::uint64_t s, std::uint64_t e) const { return src.epoch_order(s, e); }
      void gather(std::span<const std::int64_t> w, WindowBatch& out) const {
        ids.insert(ids.end(), w.begin(), w.end());
        src.gather(w, out);
      }
    };
    ThreadRanks<R> ranks;
    std::vector<std::unique_ptr<JepaModel<float>>> models;
    std::vector<GatherLog> logs;
    for (int r = 0; r < R; ++r) {
      models.push_back(std::make_unique<JepaModel<float>>(blob_config(), 7));
      logs.push_back(GatherLog{source, {}});
    }
    std::vector<double> loss[R], spread;
    auto rank_main = [&](int r) {
      JepaTrainer<float, GatherLog> t(*models[static_cast<std::size_t>(r)], logs[static_cast<std::size_t>(r)], graph, tc);
      t.parallel = ranks.parallel(r);
      for (const auto& st : t.run()) {
        loss[r].push_back(st.loss);
        if (r == 0) spread.push_back(st.target_sample_std);
      }
    };
    ranks.run(rank_main);
    REQUIRE(loss[0].size() == single_loss.size());
    for (std::size_t s = 0; s < single_loss.size(); ++s) {
      for (int r = 1; r < R; ++r) CHECK(loss[r][s] == loss[0][s]);
      CHECK(loss[0][s] == doctest::Approx(single_loss[s]).epsilon(1e-6));
      // The spread over the batch's samples, from the ranks' summed moments, is the batch's.
      CHECK(spread[s] == doctest::Approx(single_spread[s]).epsilon(1e-6));
    }
    // Every rank applied the same updates: all three parameter sets bitwise equal across ranks.
    for (int r = 1; r < R; ++r)
      for (const auto& [a, b] : {std::pair{&models[0]->context, &models[r]->context},
                                 std::pair{&models[0]->target, &models[r]->target},
                                 std::pair{&models[0]->predictor_params, &models[r]->predictor_params}})
        CHECK(std::memcmp(a->values().data(), b->values().data(), a->values().size_bytes()) == 0);
    // Rank r gathered samples [⌊16r/3⌋, ⌊16(r+1)/3⌋) of each global batch, and nothing else.
    for (int r = 0; r < R; ++r) {
      std::vector<std::int64_t> expect;
      const int first = 16 * r / R, last = 16 * (r + 1) / R;
      for (std::int64_t s = 0; s < tc.schedule.steps; ++s) {
        const auto order = source.epoch_order(tc.seed ^ streams::data_salt, static_cast<std::uint64_t>(s / 6));
        const auto b = static_cast<std::ptrdiff_t>((s % 6) * 16);
        expect.insert(expect.end(), order.begin() + b + first, order.begin() + b + last);
      }
      CHECK(logs[static_cast<std::size_t>(r)].ids == expect);
    }
    // Shards of a batch: ⌊r·B/R⌋ boundaries; a batch smaller than the rank count is refused.
    DataParallel<float> dp;
    dp.ranks = 3;
    dp.rank = 2;
    CHECK(dp.shard(16).first == 10);
    CHECK(dp.shard(16).count == 6);
    CHECK_THROWS_AS(dp.shard(2), ConfigError);
  }

  TEST_CASE("BYOL data parallel: 2 ranks (threads) average their shards' losses and gradients as DDP does") {
    // Each rank's BatchNorm reads its own shard (no SyncBatchNorm): the global loss of a step is
    // the mean of the shards' losses, which one process gets by running each shard as a batch.
    constexpr int R = 2;
    const auto source = blob_source(200, 1);
    const TrainConfig tc = blob_trainer_config(3, 1, 5);
    const ByolConfig bc = blob_byol_config(tc);
    const TaxelCanvas canvas = blob_canvas();
    double expect = 0;
    {
      ByolModel<float> m(bc, 7);
      ByolObjective<float> o(m, source, canvas, tc);
      const auto order = o.epoch_order(0);
      for (int r = 0; r < R; ++r) {
        const int first = 16 * r / R, last = 16 * (r + 1) / R;
        const std::span<const std::int64_t> ids(order.data() + first, std::size_t(last - first));
        expect += o.forward(StepBatch{ids, 16, first, 0}) * (last - first) / 16.0;
      }
    }
    ThreadRanks<R> ranks;
    std::vector<std::unique_ptr<ByolModel<float>>> models;
    for (int r = 0; r < R; ++r) models.push_back(std::make_unique<ByolModel<float>>(bc, 7));
    std::vector<double> loss[R];
    ranks.run([&](int r) {
      ByolTrainer<float> t(*models[std::size_t(r)], source, canvas, tc);
      t.parallel = ranks.parallel(r);
      for (const auto& st : t.run()) loss[r].push_back(st.loss);
    });
    REQUIRE(loss[0].size() == 3);
    CHECK(loss[1] == loss[0]);
    CHECK(loss[0][0] == doctest::Approx(expect).epsilon(1e-6));
    for (const auto& [a, b] : {std::pair{&models[0]->online, &models[1]->online},
                               std::pair{&models[0]->target_projector, &models[1]->target_projector},
                               std::pair{&models[0]->predictor_params, &models[1]->predictor_params}})
      CHECK(std::memcmp(a->values().data(), b->values().data(), a->values().size_bytes()) == 0);
  }

  TEST_CASE("DINO data parallel: 2 ranks (threads) average their shards' losses / centers move toward the global mean") {
    // Each rank keeps its shard of the global batch's views; KoLeo reads its shard (as DINOv2 under
    // DDP), so the global loss of a step is the mean of the shards' losses. The centers' sums and
    // counts are summed over the ranks: after step 0 the centers are the one-process run's.
    constexpr int R = 2;
    const auto source = blob_source(200, 1);
    const TrainConfig tc = blob_trainer_config(3, 1, 5);
    DinoConfig dc = dino_config(tc, 36, 2);
    dc.local_views = 2;
    double expect = 0;
    std::vector<double> shard_sums;
    {
      DinoModel<float> m(dc, 7);
      DinoObjective<float> o(m, source, tc);
      const auto order = o.epoch_order(0);
      for (int r = 0; r < R; ++r) {
        const int first = 16 * r / R, last = 16 * (r + 1) / R;
        const std::span<const std::int64_t> ids(order.data() + first, std::size_t(last - first));
        expect += o.forward(StepBatch{ids, 16, first, 0}) * (last - first) / 16.0;
        const std::vector<double>& cs = o.workspace().center_sums;
        shard_sums.resize(cs.size(), 0.0);
        for (std::size_t i = 0; i < cs.size(); ++i) shard_sums[i] += cs[i];
      }
      // The whole batch at once: the shards' views are its views, so the sums agree.
      o.forward(StepBatch{std::span<const std::int64_t>(order.data(), 16), 16, 0, 0});
      const std::vector<double>& whole = o.workspace().center_sums;
      REQUIRE(whole.size() == shard_sums.size());
      for (std::size_t i = 0; i < whole.size(); ++i) CHECK(shard_sums[i] == doctest::Approx(whole[i]).epsilon(1e-9));
      const std::size_t P = whole.size() / 2 - 1;
      CHECK(whole[P] == 2 * 16);  // the class rows: 2 global views of 16 samples
      CHECK(whole[2 * P + 1] > 0);  // masked patches
    }
    DinoModel<float> single_model(dc, 7);
    DinoTrainer<float> single(single_model, source, tc);
    single.run(1);
    ThreadRanks<R> ranks;
    std::vector<std::unique_ptr<DinoModel<float>>> models;
    for (int r = 0; r < R; ++r) models.push_back(std::make_unique<DinoModel<float>>(dc, 7));
    std::vector<double> loss[R];
    std::vector<float> centers_after_0[R];
    ranks.run([&](int r) {
      DinoTrainer<float> t(*models[std::size_t(r)], source, tc);
      t.parallel = ranks.parallel(r);
      for (const auto& st : t.run(1)) loss[r].push_back(st.loss);
      const auto c = models[std::size_t(r)]->centers.values();
      centers_after_0[r].assign(c.begin(), c.end());
      for (const auto& st : t.run()) loss[r].push_back(st.loss);
    });
    REQUIRE(loss[0].size() == 3);
    CHECK(loss[1] == loss[0]);
    CHECK(loss[0][0] == doctest::Approx(expect).epsilon(1e-6));
    const auto c1 = single_model.centers.values();
    REQUIRE(centers_after_0[0].size() == c1.size());
    double worst = 0;
    for (std::size_t i = 0; i < c1.size(); ++i)
      worst = std::max(worst, std::abs(double(centers_after_0[0][i]) - double(c1[i])) / (std::abs(double(c1[i])) + 1e-6));
    CHECK(worst < 1e-5);
    for (const auto& [a, b] : {std::pair{&models[0]->student, &models[1]->student},
                               std::pair{&models[0]->teacher_head, &models[1]->teacher_head},
                               std::pair{&models[0]->centers, &models[1]->centers}})
      CHECK(std::memcmp(a->values().data(), b->values().data(), a->values().size_bytes()) == 0);
  }

  TEST_CASE("a NaN stops the trainer with NumericError and leaves the last checkpoint intact") {
    const auto source = blob_source(100, 2);
    JepaModel<float> model(blob_config(), 3);
    JepaTrainer<float> trainer(model, source, blob_graph(), blob_trainer_config(6, 3, 0));
    TempPath ckpt("nan");
    trainer.checkpoint = ckpt.path;
    trainer.checkpoint_every = 2;
    (void)trainer.run(2);
    REQUIRE(std::filesystem::exists(ckpt.path));
    const auto good = load_safetensors(ckpt.path);
    model.context.values()[model.context.id(3).offset] = std::numeric_limits<float>::infinity();
    CHECK_THROWS_WITH_AS(trainer.run(), doctest::Contains("jepa step 2: the loss is"), NumericError);
    CHECK(trainer.step() == 2);
    const auto after = load_safetensors(ckpt.path);
    CHECK(after.metadata.at("step") == "2");
    for (const auto& name : good.names()) CHECK(after.at(name).data == good.at(name).data);
  }

  TEST_CASE("on a small synthetic set the loss falls and the target embeddings do not collapse") {
    const auto source = blob_source(1200, 3);  // 600 windows: 37 batches of 16 per epoch
    JepaModel<float> model(blob_config(), 13);
    JepaTrainer<float> trainer(model, source, blob_graph(), blob_trainer_config(8 * 37, 37, 11));
    trainer.log_every = 100;
    std::ostringstream log;
    trainer.log = &log;
    const auto stats = trainer.run();
    CHECK(log.str().find("step 1/296 epoch 0 loss ") == 0);
    CHECK(log.str().find("step 296/296 epoch 7 loss ") != std::string::npos);
    const std::size_t n = stats.size(), k = 20;
    auto mean = [&](std::size_t from, double JepaStepStats::*f) {
      double s = 0;
      for (std::size_t i = from; i < from + k; ++i) s += stats[i].*f;
      return s / k;
    };
    const double loss0 = mean(0, &JepaStepStats::loss), loss1 = mean(n - k, &JepaStepStats::loss);
    const double std0 = mean(0, &JepaStepStats::target_std), std1 = mean(n - k, &JepaStepStats::target_std);
    double min_std = 1e9;
    for (const auto& st : stats) {
      CHECK(std::isfinite(st.loss));
      min_std = std::min(min_std, st.target_std);
    }
    MESSAGE("steps ", n, ": loss ", loss0, " -> ", loss1, ", target std ", std0, " -> ", std1, " (min ", min_std, ")");
    CHECK(loss1 < 0.5 * loss0);
    CHECK(min_std > 0.1);
  }

  TEST_CASE("a 300-step pre-training in bf16 tracks the fp32 loss curve") {
    // Band: every 20-step mean of the bf16 loss within 2 % of the fp32 run's (measured: at most
    // 0.06 %; the loss falls from 1.01 to 0.17 in both). Without AVX512-BF16 bf16 is fp32: the
    // curves are equal.
    const auto source = blob_source(1200, 3);
    auto run = [&](Precision precision) {
      JepaModel<float> model(blob_config(), 13);
      TrainConfig tc = blob_trainer_config(300, 37, 11);
      tc.step.precision = precision;
      JepaTrainer<float> trainer(model, source, blob_graph(), tc);
      std::vector<double> loss;
      for (const auto& st : trainer.run()) loss.push_back(st.loss);
      return loss;
    };
    const std::vector<double> fp32 = run(Precision::fp32), bf16 = run(Precision::bf16);
    REQUIRE(fp32.size() == 300);
    REQUIRE(bf16.size() == 300);
    if (!detail::bgemm::native) {
      CHECK(bf16 == fp32);
      return;
    }
    CHECK(bf16 != fp32);  // the bf16 products ran
    double worst = 0;
    for (std::size_t w = 0; w < 300; w += 20) {
      double a = 0, b = 0;
      for (std::size_t i = w; i < w + 20; ++i) a += fp32[i], b += bf16[i];
      worst = std::max(worst, std::abs(b - a) / a);
    }
    MESSAGE("bf16 against fp32: largest relative gap of a 20-step mean loss ", worst, "; loss ", fp32.front(), " -> ",
            fp32.back(), " (fp32), ", bf16.front(), " -> ", bf16.back(), " (bf16)");
    CHECK(worst <= 0.02);
    CHECK(bf16.back() < 0.5 * bf16.front());
  }

  TEST_CASE("column_moments: a double reference / the same bits on 1 and 2 threads for few long rows and many short ones") {
    // [8, 70656] is the targets as [B, N·d] (the sample spread), [3000, 61] many rows; both above
    // the grain, so split over the threads, the first over its columns.
    Rng rng(77);
    for (const auto& [M, D] : {std::pair<std::size_t, int>{8, 70656}, std::pair<std::size_t, int>{3000, 61}}) {
      INFO("M ", M, ", D ", D);
      std::vector<float> x(M * std::size_t(D));
      for (auto& v : x) v = static_cast<float>(rng.normal() + 100.0);  // a large shared offset
      const int previous = detail::max_threads();
#if defined(_OPENMP)
      omp_set_num_threads(1);
#endif
      const ColumnMoments one = column_moments(x.data(), M, D);
#if defined(_OPENMP)
      omp_set_num_threads(2);
#endif
      const ColumnMoments two = column_moments(x.data(), M, D);
#if defined(_OPENMP)
      omp_set_num_threads(previous);
#endif
      CHECK(one.mean == two.mean);
      CHECK(one.m2 == two.m2);
      double worst_mean = 0, worst_m2 = 0;
      for (int j = 0; j < D; ++j) {
        long double mu = 0, m2 = 0;
        for (std::size_t m = 0; m < M; ++m) mu += x[m * D + j];
        mu /= M;
        for (std::size_t m = 0; m < M; ++m) m2 += (x[m * D + j] - mu) * (x[m * D + j] - mu);
        worst_mean = std::max(worst_mean, double(std::abs(one.mean[j] - mu) / (std::abs(mu) + 1)));
        worst_m2 = std::max(worst_m2, double(std::abs(one.m2[j] - m2) / (m2 + 1e-30)));
      }
      CHECK(worst_mean < 1e-13);
      CHECK(worst_m2 < 1e-10);
    }
  }
}
