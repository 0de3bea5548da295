// Downstream probes: softmax cross-entropy (values and gradient against central differences),
// metrics against hand-computed values, the probe loss gradient through the AttentiveProbe, and
// probe training that learns a task whose answer is in the features (frozen and end to end).
// GCC 12 flags Eigen's AVX-512 GEMM kernels (avx512fintrin.h, -W[maybe-]uninitialized), a known
// false positive in a system header that -Werror would otherwise turn into an error.
#include <doctest/doctest.h>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/downstream/probe_labels.hpp>
#include <tjepa/eval.hpp>

#include <cmath>
#include <numeric>
#include <vector>

using namespace tjepa;

TEST_SUITE("downstream") {

TEST_CASE("softmax cross-entropy: value and gradient") {
  // Two rows of 3 logits in a buffer with row stride 5.
  const std::vector<double> z{1.0, 2.0, 0.5, 9, 9, -1.0, 0.0, 3.0, 9, 9};
  const std::vector<int> y{1, 0};
  std::vector<double> g(10, 7.0);
  const double loss = softmax_cross_entropy(z.data(), 5, y.data(), 2, 3, g.data(), 5, 2.0);
  auto lse = [](double a, double b, double c) { return std::log(std::exp(a) + std::exp(b) + std::exp(c)); };
  const double expect = ((lse(1, 2, 0.5) - 2.0) + (lse(-1, 0, 3) + 1.0)) / 2;
  CHECK(loss == doctest::Approx(expect).epsilon(1e-12));
  CHECK(g[3] == 7.0);  // outside the rows: untouched
  for (int b = 0; b < 2; ++b)
    for (int c = 0; c < 3; ++c) {
      std::vector<double> zp = z, zm = z;
      const double h = 1e-6;
      zp[b * 5 + c] += h;
      zm[b * 5 + c] -= h;
      const double num = (softmax_cross_entropy(zp.data(), 5, y.data(), 2, 3, static_cast<double*>(nullptr), 5) -
                          softmax_cross_entropy(zm.data(), 5, y.data(), 2, 3, static_cast<double*>(nullptr), 5)) /
                         (2 * h);
      CHECK(g[b * 5 + c] == doctest::Approx(2.0 * num).epsilon(1e-6));
    }
  // Large logits do not overflow.
  const std::vector<float> big{1000.0f, 0.0f};
  const int label = 0;
  CHECK(softmax_cross_entropy(big.data(), 2, &label, 1, 2, static_cast<float*>(nullptr), 2) ==
        doctest::Approx(0.0).epsilon(1e-6));
  CHECK_THROWS_AS(softmax_cross_entropy(big.data(), 2, std::vector<int>{2}.data(), 1, 2, static_cast<float*>(nullptr), 2),
                  DataError);
}

TEST_CASE("metrics: RMSE per column / accuracy / majority") {
  const std::vector<float> pred{1, 2, 9, 3, 4, 9};  // [2, 2] with row stride 3
  const std::vector<float> target{0, 2, 3, 0};
  const auto r = rmse_per_column(pred.data(), 3, target.data(), 2, 2);
  CHECK(r[0] == doctest::Approx(std::sqrt((1.0 + 0.0) / 2)));
  CHECK(r[1] == doctest::Approx(std::sqrt((0.0 + 16.0) / 2)));
  const std::vector<float> logits{0.1f, 0.9f, 0.0f, 0.8f, 0.1f, 0.1f, 0.2f, 0.2f, 0.6f};
  const std::vector<int> labels{1, 1, 2};
  CHECK(accuracy(logits.data(), 3, labels.data(), 3, 3) == doctest::Approx(2.0 / 3));
  CHECK(majority_accuracy(labels.data(), 3, 3) == doctest::Approx(2.0 / 3));
}

TEST_CASE("probe loss: gradient through the AttentiveProbe matches central differences") {
  const int B = 3, L = 5, d = 12, C = 4;
  ProbeHead<double> p(d, 3, force_axes, C, 1);
  Rng rng(2);
  for (auto& v : p.params.values()) v += 0.3 * rng.normal();
  std::vector<double> x(static_cast<std::size_t>(B) * L * d);
  for (auto& v : x) v = rng.normal();
  std::vector<float> f(B * 3);
  for (auto& v : f) v = static_cast<float>(rng.normal());
  const std::vector<int> c{0, 3, 2};
  Workspace<double> ws;
  ProbeCache<double> cache;
  std::vector<double> y(static_cast<std::size_t>(B) * (3 + C)), dy(y.size());
  auto loss = [&](bool grad) {
    if (grad)
      p.probe.forward(p.params, {x.data(), B, L}, y.data(), cache, ws);
    else
      p.probe.forward(p.params, {x.data(), B, L}, y.data(), ws);
    const auto l = detail::head_loss(y.data(), static_cast<std::size_t>(force_axes + C), f.data(), c.data(), B,
                                     force_axes, C, 0.7, grad ? dy.data() : nullptr);
    return l[0] + 0.7 * l[1];
  };
  p.params.zero_grad();
  loss(true);
  p.probe.backward(p.params, dy.data(), static_cast<double*>(nullptr), cache, ws);
  int checked = 0;
  for (std::size_t k = 0; k < p.params.count(); ++k) {
    const ParamId id = p.params.id(k);
    for (std::size_t i = 0; i < std::min<std::size_t>(id.size, 4); ++i) {
      double* v = p.params.value(id) + i;
      const double o = *v, h = 1e-6;
      *v = o + h;
      const double lp = loss(false);
      *v = o - h;
      const double lm = loss(false);
      *v = o;
      const double num = (lp - lm) / (2 * h), an = p.params.grad(id)[i];
      CHECK(std::abs(an - num) <= 1e-7 + 1e-5 * std::abs(num));
      ++checked;
    }
  }
  CHECK(checked > 40);
}

// S windows of tokens whose direction encodes the force and the class (a LayerNorm comes first in
// the probe, so the information must be in the direction, not the scale): a probe must get far
// below the constant predictor on its own training data.
struct EncodedFeatures {
  AlignedVector<float> v;  // [S, 1, d]
  ProbeLabels labels;      // windows first_window + i, force (shear_u·F, 0, F)
};
EncodedFeatures encoded_features(int S, int d, std::uint64_t seed, float shear_u, std::int64_t first_window) {
  Rng rng(seed);
  EncodedFeatures e{AlignedVector<float>(static_cast<std::size_t>(S) * d, 0.0f), {}};
  for (int i = 0; i < S; ++i) {
    const float F = static_cast<float>(rng.uniform(0, 10));
    const int cls = static_cast<int>(rng.below(4));
    e.labels.window.push_back(first_window + i);
    e.labels.force.insert(e.labels.force.end(), {shear_u * F, 0.0f, F});
    e.labels.indenter.push_back(cls);
    float* t = e.v.data() + static_cast<std::size_t>(i) * d;
    t[0] = F;
    t[1] = 10.0f - F;
    t[2 + cls] = 5.0f;
  }
  return e;
}

TEST_CASE("train_head: learns an encoded force and class (frozen features) through the Trainer") {
  const int S = 128, L = 1, d = 12;
  const auto [v, lab] = encoded_features(S, d, 5, 0.0f, 0);
  FrozenFeatures<float> f(v, L, d);
  const HeadTargets targets = head_targets(lab, 4);
  ProbeHead<float> p(d, 3, force_axes, 4, 0);
  HeadTrainConfig cfg{.max_epochs = 100, .patience = 100, .batch = 16, .lr = 3e-3};
  const HeadTrainResult r = train_head(p, f, targets, cfg);
  CHECK(r.epochs() == 100);  // patience as long as the run: no early stop
  CHECK(r.train_loss.back() < 0.2 * r.train_loss.front());
  const HeadMetrics m = evaluate_head(p, f, targets);
  double sd = 0;
  for (int i = 0; i < S; ++i) sd += std::pow(lab.force[3 * i + 2] - 5.0, 2);
  sd = std::sqrt(sd / S);  // ≈ 2.9: the constant predictor's RMSE
  CHECK(m.rmse[2] < 0.7 * sd);
  CHECK(m.rmse[0] < 1e-3);  // u, v are always 0: the scaler's mean
  CHECK(m.accuracy > 0.9);
  CHECK(m.majority_accuracy < 0.5);
  CHECK(m.samples == S);
  // Same seed, same head.
  ProbeHead<float> q(d, 3, force_axes, 4, 0);
  train_head(q, f, targets, cfg);
  CHECK(std::equal(p.params.values().begin(), p.params.values().end(), q.params.values().begin()));
}

TEST_CASE("center_token_embeddings: one shared resting embedding / differences between windows kept") {
  Rng rng(12);
  const int S = 5, T2 = 3, L = 4, d = 6;
  const std::size_t per = std::size_t(L) * d;
  std::vector<float> train(S * per), test(T2 * per);
  // Token n's embedding: a large per-token offset (its position) plus a window-dependent part.
  std::vector<float> offset(per);
  for (auto& v : offset) v = static_cast<float>(5 * rng.normal());
  for (std::size_t i = 0; i < train.size(); ++i) train[i] = offset[i % per] + static_cast<float>(rng.normal());
  for (std::size_t i = 0; i < test.size(); ++i) test[i] = offset[i % per] + static_cast<float>(rng.normal());
  const std::vector<float> train0 = train, test0 = test;
  const std::span<float> test_span(test);
  center_token_embeddings<float>(train, std::span<const std::span<float>>(&test_span, 1), L, d);
  // Every token's training mean is now the same vector: the mean over tokens of the old means.
  std::vector<double> shared(d, 0.0);
  for (int s = 0; s < S; ++s)
    for (std::size_t i = 0; i < per; ++i) shared[i % d] += double(train0[s * per + i]) / (S * L);
  for (int n = 0; n < L; ++n)
    for (int c = 0; c < d; ++c) {
      double m = 0;
      for (int s = 0; s < S; ++s) m += train[s * per + n * d + c];
      CHECK(m / S == doctest::Approx(shared[c]).epsilon(1e-5));
    }
  // Each value moved by its token's shift, the same in the training and the held-out windows.
  for (std::size_t i = 0; i < per; ++i) {
    const float shift = train[i] - train0[i];
    for (int s = 1; s < S; ++s) CHECK(train[s * per + i] - train0[s * per + i] == doctest::Approx(shift).epsilon(1e-5));
    for (int s = 0; s < T2; ++s) CHECK(test[s * per + i] - test0[s * per + i] == doctest::Approx(shift).epsilon(1e-5));
  }
  std::vector<float> bad(per + 1);
  CHECK_THROWS_WITH_AS(center_token_embeddings<float>(bad, {}, L, d), doctest::Contains("tokens*dim = 4*6"), ShapeError);
  std::vector<float> none;
  CHECK_THROWS_AS(center_token_embeddings<float>(none, {}, L, d), ShapeError);
}

TEST_CASE("standardize_channels: training channels at mean 0 and sd 1 / held-out windows by the training statistics") {
  Rng rng(13);
  const int S = 40, T2 = 7, L = 5, d = 4;
  const std::size_t per = std::size_t(L) * d;
  // One large shared vector (what every token of every window holds), a per-token offset and a
  // window-dependent part of a different scale in each channel.
  std::vector<double> shared(d), scale(d);
  for (int c = 0; c < d; ++c) shared[c] = 20 * rng.normal(), scale[c] = 0.01 * (c + 1);
  std::vector<float> offset(per);
  for (auto& v : offset) v = static_cast<float>(0.05 * rng.normal());
  auto make = [&](int windows) {
    std::vector<float> x(windows * per);
    for (std::size_t i = 0; i < x.size(); ++i)
      x[i] = static_cast<float>(shared[i % d] + offset[i % per] + scale[i % d] * rng.normal());
    return x;
  };
  std::vector<float> train = make(S), test = make(T2);
  const std::vector<float> train0 = train, test0 = test;
  const std::span<float> test_span(test);
  const auto [mean, sd] = standardize_channels<float>(train, std::span<const std::span<float>>(&test_span, 1), d);
  REQUIRE(mean.size() == std::size_t(d));
  for (int c = 0; c < d; ++c) {
    double m = 0, m0 = 0, v = 0;
    for (int r = 0; r < S * L; ++r) m += train[r * d + c], m0 += train0[r * d + c];
    m /= S * L;
    for (int r = 0; r < S * L; ++r) v += (train[r * d + c] - m) * (train[r * d + c] - m);
    CHECK(std::abs(m) < 1e-3);
    CHECK(std::sqrt(v / (S * L)) == doctest::Approx(sd[c] / std::sqrt(sd[c] * sd[c] + 1e-6)).epsilon(1e-3));
    CHECK(mean[c] == doctest::Approx(m0 / (S * L)).epsilon(1e-9));
    // Held-out values: the same affine map, with the training statistics.
    for (int r = 0; r < T2 * L; ++r)
      CHECK(test[r * d + c] == doctest::Approx((test0[r * d + c] - mean[c]) / std::sqrt(sd[c] * sd[c] + 1e-6)).epsilon(1e-3));
  }
  // What differs between tokens is kept, only rescaled: unlike center_token_embeddings, the map is
  // the same for every token.
  for (int s = 0; s < S; ++s)
    for (int c = 0; c < d; ++c)
      CHECK(train[s * per + c] - train[s * per + d + c] ==
            doctest::Approx((train0[s * per + c] - train0[s * per + d + c]) / std::sqrt(sd[c] * sd[c] + 1e-6)).epsilon(1e-3).scale(1e-2));
  std::vector<float> bad(7);
  CHECK_THROWS_WITH_AS(standardize_channels<float>(bad, {}, d), doctest::Contains("multiple of dim = 4"), ShapeError);
  std::vector<float> none;
  CHECK_THROWS_AS(standardize_channels<float>(none, {}, d), ShapeError);
  std::vector<float> nan_values(per, std::nanf(""));
  CHECK_THROWS_WITH_AS(standardize_channels<float>(nan_values, {}, d), doctest::Contains("expected finite"), NumericError);
}

TEST_CASE("end to end: the encoder trains with the probe / embeddings match the inference path") {
  const Skin skin = layouts::grid_skin({.rows = 4, .cols = 4, .pitch = 4.0, .group_rows = 2, .group_cols = 2});
  SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 3);
  const Recording base = sim.record_baseline(100);
  SimRecording rec = sim.record(600);
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(base);
  pre.fit(rec.recording);
  const WindowSource src(rec.recording, WindowSpec{5}, rec.labels, pre);
  const ProbeLabels lab = ProbeLabels::from_source(src, src.windows_with_contact(2));
  REQUIRE(lab.size() >= 16);

  ParamSet<float> ps;
  const Tokenizer tok = Tokenizer::per_taxel(ps, 16, 3, 5, 8);  // 3 axes x 5 frames
  const Encoder enc(ps, EncoderConfig{.num_tokens = 16, .dim = 8, .depth = 1, .heads = 2});
  ps.allocate();
  init_params(ps, 1);
  const std::vector<float> before(ps.values().begin(), ps.values().end());

  // The inference path of EncoderFeatures equals embed_windows.
  EncoderFeatures<float> feats(ps, tok, enc, src, lab.window);
  const auto emb = embed_windows(ps, tok, enc, src, lab.window, 7);
  std::vector<std::int64_t> all(static_cast<std::size_t>(lab.size()));
  std::iota(all.begin(), all.end(), 0);
  const float* x = feats.forward(all, false);
  for (std::size_t i = 0; i < emb.size(); ++i) REQUIRE(x[i] == doctest::Approx(emb[i]).epsilon(1e-5));
  {
    // Both feed the tokenizer each taxel's window axis-major (windows_to_tokens), as training
    // does; the raw [N, τ, m] order would give other embeddings.
    WindowBatch wb;
    src.gather(std::span<const std::int64_t>(lab.window.data(), 1), wb);
    AlignedVector<float> rows, tk(16 * 8), e(16 * 8), raw(16 * 8);
    windows_to_tokens(wb, rows);
    Workspace<float> ws;
    tok.forward(ps, rows.data(), 1, tk.data(), ws);
    enc.forward(ps, {tk.data(), 1}, e.data(), ws);
    for (std::size_t i = 0; i < e.size(); ++i) REQUIRE(e[i] == doctest::Approx(emb[i]).epsilon(1e-5));
    tok.forward(ps, wb.x.data(), 1, tk.data(), ws);
    enc.forward(ps, {tk.data(), 1}, raw.data(), ws);
    double diff = 0;
    for (std::size_t i = 0; i < raw.size(); ++i) diff += std::abs(raw[i] - emb[i]);
    CHECK(diff > 1e-2);
  }

  ProbeHead<float> p(8, 2, force_axes, 4, 0);
  const HeadTrainConfig cfg{.max_epochs = 2, .batch = 8};
  train_head(p, feats, head_targets(lab, 4), cfg);
  double moved = 0;
  for (std::size_t i = 0; i < before.size(); ++i) moved += std::abs(ps.values()[i] - before[i]);
  CHECK(moved > 0);  // end to end: the encoder's parameters changed

  FrozenFeatures<float> frozen(emb, 16, 8);
  CHECK(frozen.size() == lab.size());
  CHECK_THROWS_AS(FrozenFeatures<float>(AlignedVector<float>(10), 16, 8), ShapeError);
  // Labels must be windows with a contact.
  CHECK_THROWS_AS(ProbeLabels::from_source(src, std::vector<std::int64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11}),
                  DataError);
}

}  // TEST_SUITE
