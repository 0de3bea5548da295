// The MAE baseline end to end on a tiny model in double: the loss against central differences
// for every encoder and decoder parameter, the loss as a plain masked mean, determinism, the
// uniform masking, the encoder's layout against JepaModel's, errors, the optimizer step, the NaN
// stop, and a short run on synthetic data where the loss falls.
// g++ 12 reports a false (maybe-)uninitialized inside its AVX-512 intrinsics once Eigen's double
// kernels are inlined (GCC bug 105593); see tests/model/modules.cpp.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/masks/uniform_masking.hpp>
#include <tjepa/baselines/mae.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <vector>

#include "../support/gradcheck.hpp"

using namespace tjepa;

namespace {

// 12 tokens, d = 8, 2 heads, 1 encoder block, 1 decoder block; m·τ = 4 values per taxel.
// mask_ratio 0.75: 3 visible and 9 masked tokens per sample.
MaeConfig tiny_mae_config() {
  MaeConfig c;
  c.in_dim = 4;
  c.axes = 2;
  c.encoder = EncoderConfig{.num_tokens = 12, .dim = 8, .depth = 1, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6};
  c.decoder = PredictorConfig{8, 8, 1, 2, 2.0, false, 1e-6};
  return c;
}

// Every parameter away from its degenerate init (LayerNorm 1/0, zero biases and mask token).
MaeModel<double> random_mae_model(const MaeConfig& c, std::uint64_t seed) {
  MaeModel<double> model(c, seed);
  test::randomize(model.context, seed + 1);
  test::randomize(model.decoder_params, seed + 2);
  return model;
}

std::vector<double> tiny_mae_input(std::uint64_t seed, int B = 2, int N = 12, int W = 4) {
  Rng rng(seed);
  return test::normal_vector(static_cast<std::size_t>(B) * N * W, rng);
}

// S windows of a 6 x 6 sheet (36 taxels), m = 2 axes, τ = 2 frames, as tokenizer rows
// [S, 36, 4] axis-major: a wide Gaussian blob of random centre, width and amplitude moving by a random
// step between the two frames (first axis its pressure, second its change since the frame
// before), plus noise. Smooth in space, so visible taxels tell the masked ones.
std::vector<float> blob_windows(int S, std::uint64_t seed) {
  const int side = 6, N = side * side, W = 4;
  std::vector<float> x(static_cast<std::size_t>(S) * N * W);
  Rng rng(seed);
  for (int s = 0; s < S; ++s) {
    const double cx = rng.uniform(0, side - 1), cy = rng.uniform(0, side - 1), amp = rng.uniform(0.5, 2.0);
    const double vx = rng.uniform(-0.5, 0.5), vy = rng.uniform(-0.5, 0.5), width = rng.uniform(6.0, 12.0);
    for (int n = 0; n < N; ++n) {
      double prev = 0;
      float* row = x.data() + (static_cast<std::size_t>(s) * N + n) * W;
      for (int t = 0; t < 2; ++t) {
        const double dx = n % side - (cx + t * vx), dy = n / side - (cy + t * vy);
        const double p = amp * std::exp(-(dx * dx + dy * dy) / width);
        row[t] = static_cast<float>(p + 0.02 * rng.normal());               // axis 0, frame t
        row[2 + t] = static_cast<float>(p - prev + 0.02 * rng.normal());    // axis 1, frame t
        prev = p;
      }
    }
  }
  return x;
}

}  // namespace

TEST_SUITE("baselines") {
  TEST_CASE("MAE loss: analytic gradient of every encoder and decoder parameter = central differences") {
    const test::SingleThread one_thread;
    MaeConfig c = tiny_mae_config();
    SUBCASE("plain targets") {}
    SUBCASE("per-token normalized targets (norm_pix_loss)") { c.norm_targets = true; }
    SUBCASE("drop-path 0.5 in the encoder with a fixed noise seed") { c.drop_path = 0.5; }
    SUBCASE("a decoder of width 4 with 2 blocks") { c.decoder = PredictorConfig{8, 4, 2, 2, 2.0, false, 1e-6}; }
    SUBCASE("the decoder reads the encoder's position rows") { c.decoder_pos_from_encoder = true; }
    auto model = random_mae_model(c, 1);
    const auto x = tiny_mae_input(5);
    const MaskBatch masks = UniformMasking(12, c.mask_ratio).sample(2, 3, 0);
    MaeWorkspace<double> w;
    const std::uint64_t noise = 77;
    auto loss = [&] { return mae_forward(model, x.data(), 2, masks, w, noise); };
    model.context.zero_grad();
    model.decoder_params.zero_grad();
    const double l = mae_forward(model, x.data(), 2, masks, w, noise);
    mae_backward(model, w);
    CHECK(l > 0);
    CHECK(l == loss());  // forward is a pure function of its inputs
    // Every tensor: the tokenizer (patch_embed.*), the position table, the block weights, the
    // final norm, and the decoder's projections, mask token, blocks, norm and position rows.
    test::check_param_gradients(model.context, loss);
    test::check_param_gradients(model.decoder_params, loss);
    // The decoder's position rows (its own or the encoder's) get a gradient at masked tokens.
    const int masked = masks.targets[0].row(0)[0];
    const double* dpos = model.decoder_pos_grad() + masked * c.decoder.dim;
    CHECK(std::any_of(dpos, dpos + c.decoder.dim, [](double g) { return g != 0.0; }));
    CHECK(model.decoder_params.contains("pos_embed") == !c.decoder_pos_from_encoder);
  }

  TEST_CASE("the MAE loss is the mean squared error over the masked tokens only") {
    auto model = random_mae_model(tiny_mae_config(), 11);
    auto x = tiny_mae_input(12);
    const MaskBatch masks = UniformMasking(12, 0.75).sample(2, 4, 1);
    MaeWorkspace<double> w;
    const double l = mae_forward(model, x.data(), 2, masks, w, 1);
    // The decoder on its own, the way the header's formula reads.
    const int B = 2, N = 12, W = 4, d = 8, K = masks.K, M = masks.targets[0].size;
    CHECK(K == 3);
    CHECK(M == 9);
    Workspace<double> ws;
    std::vector<double> tok(B * N * d), z(B * K * d), p(B * M * W);
    model.tokenizer.forward(model.context, x.data(), B, tok.data(), ws);
    model.encoder.forward(model.context, {tok.data(), B, masks.context}, z.data(), ws);
    model.decoder.forward(model.decoder_params, {z.data(), B, K, model.decoder_pos_rows(), N, masks.targets[0].indices.data(), B, M}, p.data(), ws);
    double s = 0;
    for (int b = 0; b < B; ++b)
      for (int k = 0; k < M; ++k)
        for (int c = 0; c < W; ++c) {
          const double e = p[(b * M + k) * W + c] - x[(b * N + masks.targets[0].row(b)[k]) * W + c];
          s += e * e;
        }
    CHECK(l == doctest::Approx(s / (B * M * W)).epsilon(1e-12));
    // The visible tokens' own values do not enter the target: changing a visible token's row
    // changes the loss only through the encoder, and a masked token's row only through the target.
    const int visible = masks.context_row(0)[0];
    for (int c = 0; c < W; ++c) x[visible * W + c] = 0.0;
    const double l_visible = mae_forward(model, x.data(), 2, masks, w, 1);
    CHECK(l_visible != l);
    // With norm_targets each target row is standardized over its W values (biased, eps 1e-6).
    model.config.norm_targets = true;
    const double ln = mae_forward(model, x.data(), 2, masks, w, 1);
    std::vector<double> y(w.y.begin(), w.y.begin() + B * M * W);
    for (int r = 0; r < B * M; ++r) {
      double mu = 0, var = 0;
      for (int c = 0; c < W; ++c) mu += y[r * W + c] / W;
      for (int c = 0; c < W; ++c) var += (y[r * W + c] - mu) * (y[r * W + c] - mu) / W;
      CHECK(mu == doctest::Approx(0.0).scale(1.0).epsilon(1e-12));
      CHECK(var == doctest::Approx(1.0).epsilon(1e-4));  // eps 1e-6 against a variance ~1
    }
    CHECK(ln != l_visible);
  }

  TEST_CASE("two MAE backward passes accumulate twice the gradient") {
    auto model = random_mae_model(tiny_mae_config(), 21);
    const auto x = tiny_mae_input(22);
    const MaskBatch masks = UniformMasking(12, 0.75).sample(2, 5, 0);
    MaeWorkspace<double> w;
    model.context.zero_grad();
    model.decoder_params.zero_grad();
    (void)mae_forward(model, x.data(), 2, masks, w, 5);
    mae_backward(model, w);
    const auto context = model.context;
    const auto decoder = model.decoder_params;
    mae_backward(model, w);  // the same forward pass, differentiated again
    for (std::size_t i = 0; i < context.grads().size(); ++i)
      CHECK(model.context.grads()[i] == doctest::Approx(2 * context.grads()[i]).epsilon(1e-12));
    for (std::size_t i = 0; i < decoder.grads().size(); ++i)
      CHECK(model.decoder_params.grads()[i] == doctest::Approx(2 * decoder.grads()[i]).epsilon(1e-12));
  }

  TEST_CASE("MAE determinism: the same seeds give the same loss and gradients") {
    MaeConfig c = tiny_mae_config();
    c.drop_path = 0.5;
    const auto x = tiny_mae_input(31, 4);
    const UniformMasking masking(12, c.mask_ratio);
    auto run = [&](std::uint64_t model_seed, std::uint64_t mask_seed, std::uint64_t noise_seed) {
      MaeModel<double> model(c, model_seed);
      MaeWorkspace<double> w;
      model.context.zero_grad();
      model.decoder_params.zero_grad();
      const double l = mae_forward(model, x.data(), 4, masking.sample(4, mask_seed, 2), w, noise_seed);
      mae_backward(model, w);
      std::vector<double> g(model.context.grads().begin(), model.context.grads().end());
      g.insert(g.end(), model.decoder_params.grads().begin(), model.decoder_params.grads().end());
      return std::pair{l, g};
    };
    const auto a = run(1, 2, 3), b = run(1, 2, 3);
    CHECK(a.first == b.first);  // bitwise
    CHECK(a.second == b.second);
    CHECK(run(9, 2, 3).first != a.first);  // another init
    CHECK(run(1, 8, 3).first != a.first);  // other masks
    CHECK(run(1, 2, 4).first != a.first);  // other drop-path noise
  }

  TEST_CASE("uniform masking: visible and masked partition the tokens at the configured ratio") {
    const int N = 368;
    const UniformMasking masking(N, 0.75);
    CHECK(masking.num_masked() == 276);
    CHECK(masking.num_visible() == 92);
    std::vector<int> masked_count(N, 0);
    MaskBatch batch;
    for (std::uint64_t b = 0; b < 50; ++b) {
      masking.sample_into(batch, 8, 7, b);
      REQUIRE(batch.B == 8);
      REQUIRE(batch.K == 92);
      REQUIRE(batch.num_targets() == 1);
      REQUIRE(batch.targets[0].size == 276);
      for (int i = 0; i < 8; ++i) {
        const auto vis = batch.context_row(i);
        const auto msk = batch.targets[0].row(i);
        CHECK(std::is_sorted(vis.begin(), vis.end()));
        CHECK(std::is_sorted(msk.begin(), msk.end()));
        std::vector<int> all(vis.begin(), vis.end());
        all.insert(all.end(), msk.begin(), msk.end());
        std::sort(all.begin(), all.end());
        std::vector<int> expect(N);
        for (int v = 0; v < N; ++v) expect[v] = v;
        CHECK(all == expect);  // disjoint, and together every token
        for (int v : msk) ++masked_count[v];
      }
    }
    // Uniform: each token is masked in 400 samples with probability 0.75 (mean 300, sd 8.7).
    const auto [lo, hi] = std::minmax_element(masked_count.begin(), masked_count.end());
    MESSAGE("masked counts over 400 samples: min ", *lo, ", max ", *hi);
    CHECK(*lo > 250);
    CHECK(*hi < 350);
    // Deterministic in (seed, batch index); samples and batches differ.
    const MaskBatch a = masking.sample(8, 7, 3), b = masking.sample(8, 7, 3), c = masking.sample(8, 7, 4);
    CHECK(a.context == b.context);
    CHECK(a.targets[0].indices == b.targets[0].indices);
    CHECK(a.context != c.context);
    CHECK(!std::equal(a.context_row(0).begin(), a.context_row(0).end(), a.context_row(1).begin()));
    // The floor of N·ratio tokens are masked.
    CHECK(UniformMasking(12, 0.5).num_masked() == 6);
    CHECK(UniformMasking(10, 0.75).num_masked() == 7);
    CHECK_THROWS_WITH_AS(UniformMasking(12, 1.0), doctest::Contains("mask_ratio = 1"), ConfigError);
    CHECK_THROWS_WITH_AS(UniformMasking(12, 0.05), doctest::Contains("masks 0"), ConfigError);
    CHECK_THROWS_WITH_AS(UniformMasking(1, 0.5), doctest::Contains("num_tokens = 1"), ConfigError);
    CHECK_THROWS_WITH_AS(masking.sample(0, 1, 0), doctest::Contains("batch_size = 0"), ConfigError);
  }

  TEST_CASE("the MAE encoder has JepaModel's context names and shapes and starts from its values") {
    const auto same_encoder = [](const MaeConfig& mc) {
      JepaConfig jc;
      static_cast<ContextEncoderConfig&>(jc) = mc;
      jc.predictor = PredictorConfig{mc.encoder.dim, mc.encoder.dim, 1, 2, 2.0, false, 1e-6};
      const JepaModel<float> jepa(jc, 17);
      const MaeModel<float> mae(mc, 17);
      REQUIRE(mae.context.count() == jepa.context.count());
      for (std::size_t i = 0; i < mae.context.count(); ++i) {
        CHECK(mae.context.infos()[i].name == jepa.context.infos()[i].name);
        CHECK(mae.context.infos()[i].shape == jepa.context.infos()[i].shape);
      }
      CHECK(std::ranges::equal(mae.context.values(), jepa.context.values()));
      CHECK(mae.token_width() == jepa.token_width());
    };
    MaeConfig c = tiny_mae_config();
    c.tokenizer_bias_std = 1.0;
    SUBCASE("per-taxel tokens") { same_encoder(c); }
    SUBCASE("grouped tokens") {
      c.group_size = {4, 4, 5, 4, 5, 4, 4, 4, 5, 4, 4, 4};
      CHECK(c.token_width() == 20);
      same_encoder(c);
    }
    // The same checkpoint code reads either encoder: an MAE encoder export loads into JepaModel's
    // context, and the full names under "context_encoder." match.
    MaeModel<float> mae(tiny_mae_config(), 3);
    JepaConfig jc;
    static_cast<ContextEncoderConfig&>(jc) = tiny_mae_config();
    jc.predictor = PredictorConfig{8, 8, 1, 2, 2.0, false, 1e-6};
    JepaModel<float> jepa(jc, 4);
    const auto path = std::filesystem::temp_directory_path() / "tjepa_train_mae_encoder.safetensors";
    const std::vector<PrefixedParams<float>> mae_enc{{"", &mae.context}}, jepa_enc{{"", &jepa.context}};
    CheckpointState state;
    state.config = mae.config.to_json();
    export_encoder<float>(path, mae_enc, state);
    const CheckpointState back = load_encoder<float>(path, jepa_enc);
    std::filesystem::remove(path);
    CHECK(std::ranges::equal(jepa.context.values(), mae.context.values()));
    CHECK(back.config.at("mask_ratio") == 0.75);
    CHECK(back.config.at("decoder").at("out_dim") == 4);
    CHECK(mae.trainable().front().prefix == jepa.trainable().front().prefix);
    CHECK(mae.parts().size() == 2);
    CHECK(mae.decoder_params.contains("pos_embed"));
    CHECK(mae.decoder_params.infos().back().shape == std::vector<std::int64_t>{1, 12, 8});
    CHECK(mae.decoder_params.value_span(mae.decoder.output_projection.weight).size() == 4 * 8);
  }

  TEST_CASE("MAE shape and config errors throw with a clear message") {
    auto model = random_mae_model(tiny_mae_config(), 41);
    const auto x = tiny_mae_input(42);
    MaeWorkspace<double> w;
    const MaskBatch good = UniformMasking(12, 0.75).sample(2, 1, 0);
    CHECK_THROWS_WITH_AS(mae_backward(model, w), doctest::Contains("holds no forward pass"), ConfigError);
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 0, good, w, 1), doctest::Contains("B = 0"), ShapeError);
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 3, good, w, 1), doctest::Contains("masks for B = 2"),
                         ShapeError);
    CHECK_THROWS_WITH_AS(mae_forward(model, static_cast<const double*>(nullptr), 2, good, w, 1),
                         doctest::Contains("x is null"), ShapeError);
    MaskBatch bad = good;
    bad.context[3] = 12;
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 2, bad, w, 1), doctest::Contains("visible[3] = 12"),
                         ShapeError);
    bad = good;
    bad.targets[0].indices[5] = -1;
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 2, bad, w, 1), doctest::Contains("masked[5] = -1"),
                         ShapeError);
    bad = good;
    bad.targets.push_back(good.targets[0]);
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 2, bad, w, 1), doctest::Contains("2 target sets, expected 1"),
                         ShapeError);
    bad = good;
    bad.context.pop_back();
    CHECK_THROWS_WITH_AS(mae_forward(model, x.data(), 2, bad, w, 1), doctest::Contains("expected B·K = 2·3"),
                         ShapeError);
    // A rejected forward leaves nothing to differentiate.
    CHECK_THROWS_AS(mae_backward(model, w), ConfigError);

    MaeConfig c = tiny_mae_config();
    c.decoder.in_dim = 6;
    CHECK_THROWS_WITH_AS(MaeModel<float>(c, 1), doctest::Contains("decoder.in_dim = 6, expected encoder.dim = 8"),
                         ConfigError);
    c = tiny_mae_config();
    c.decoder.out_dim = 8;
    CHECK_THROWS_WITH_AS(MaeModel<float>(c, 1), doctest::Contains("expected 0 or the token width m·τ = 4"),
                         ConfigError);
    c = tiny_mae_config();
    c.mask_ratio = 0.05;
    CHECK_THROWS_WITH_AS(MaeModel<float>(c, 1), doctest::Contains("masks 0 of 12"), ConfigError);
    c = tiny_mae_config();
    c.axes = 3;
    CHECK_THROWS_WITH_AS(MaeModel<float>(c, 1), doctest::Contains("MaeConfig: axes = 3"), ConfigError);
    c = tiny_mae_config();
    c.drop_path = 1.0;
    CHECK_THROWS_AS(MaeModel<float>(c, 1), ConfigError);
    c = tiny_mae_config();
    c.decoder.dim = 4;
    c.decoder_pos_from_encoder = true;
    CHECK_THROWS_WITH_AS(MaeModel<float>(c, 1), doctest::Contains("with decoder_pos_from_encoder, expected encoder.dim = 8"),
                         ConfigError);
    MaeModel<float> m(tiny_mae_config(), 1);
    CHECK_THROWS_WITH_AS(m.set_positions(std::vector<double>(5, 0.0)), doctest::Contains("expected N·d = 12·8"),
                         ShapeError);
    // JEPA's predictor predicts embeddings: an output width other than d is refused there.
    JepaConfig jc;
    static_cast<ContextEncoderConfig&>(jc) = tiny_mae_config();
    jc.predictor = PredictorConfig{8, 8, 1, 2, 2.0, false, 1e-6};
    jc.predictor.out_dim = 4;
    CHECK_THROWS_WITH_AS(JepaModel<float>(jc, 1), doctest::Contains("predictor.out_dim = 4"), ConfigError);
  }

  TEST_CASE("an MAE training step: scheduled AdamW on the encoder and the decoder") {
    MaeModel<double> model(tiny_mae_config(), 51);
    const auto x = tiny_mae_input(52);
    AdamW<double> opt(model.trainable());
    const auto schedule = TrainingSchedule::reference(10, 4, 2);
    MaeWorkspace<double> w;
    const auto context0 = model.context;
    const auto decoder0 = model.decoder_params;
    const MaskBatch masks = UniformMasking(12, 0.75).sample(2, 1, 5);
    const MaeStepStats st = mae_train_step(model, opt, schedule, 5, x.data(), 2, masks, w, 9);
    CHECK(st.step == 5);
    CHECK(st.lr == doctest::Approx(schedule.lr(6)).epsilon(1e-15));
    CHECK(st.weight_decay == doctest::Approx(schedule.wd(5)).epsilon(1e-15));  // the reference timing: update s at wd(s)
    CHECK(st.grad_norm > 0);
    CHECK(st.loss > 0);
    CHECK(opt.steps() == 1);
    CHECK(!std::ranges::equal(model.context.values(), context0.values()));
    CHECK(!std::ranges::equal(model.decoder_params.values(), decoder0.values()));
  }

  TEST_CASE("a NaN stops the MAE step with NumericError before any parameter changes") {
    MaeModel<double> model(tiny_mae_config(), 61);
    auto x = tiny_mae_input(62);
    x[7] = std::numeric_limits<double>::quiet_NaN();
    AdamW<double> opt(model.trainable());
    const auto schedule = TrainingSchedule::reference(10, 4, 2);
    MaeWorkspace<double> w;
    const auto before = model;
    const MaskBatch masks = UniformMasking(12, 0.75).sample(2, 1, 0);
    CHECK_THROWS_WITH_AS(mae_train_step(model, opt, schedule, 0, x.data(), 2, masks, w, 1),
                         doctest::Contains("MAE step 0: the loss is nan"), NumericError);
    CHECK(opt.steps() == 0);
    CHECK(std::ranges::equal(model.context.values(), before.context.values()));
    CHECK(std::ranges::equal(model.decoder_params.values(), before.decoder_params.values()));
  }

  TEST_CASE("on small synthetic data the MAE loss falls below what positions alone predict") {
    const int S = 256, B = 16, N = 36, W = 4, epochs = 20, steps_per_epoch = S / B;
    const auto windows = blob_windows(S, 3);
    // The best prediction from a token's position alone: each (token, value)'s mean over the set.
    std::vector<double> mean(N * W, 0.0);
    for (int s = 0; s < S; ++s)
      for (int i = 0; i < N * W; ++i) mean[i] += windows[static_cast<std::size_t>(s) * N * W + i] / S;
    double position_only = 0;
    for (int s = 0; s < S; ++s)
      for (int i = 0; i < N * W; ++i) {
        const double e = windows[static_cast<std::size_t>(s) * N * W + i] - mean[i];
        position_only += e * e / (S * N * W);
      }
    MaeConfig c;
    c.in_dim = W;
    c.axes = 2;
    c.encoder = EncoderConfig{.num_tokens = N, .dim = 16, .depth = 2, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6};
    c.decoder = PredictorConfig{16, 16, 1, 2, 2.0, false, 1e-6};
    MaeModel<float> model(c, 13);
    AdamW<float> opt(model.trainable());
    TrainingSchedule schedule = TrainingSchedule::reference(epochs, steps_per_epoch, 1);
    schedule.lr.ref_lr = 1e-3;
    const UniformMasking masking(N, c.mask_ratio);  // 9 visible, 27 masked
    MaeWorkspace<float> w;
    MaskBatch masks;
    Rng noise(5);
    std::vector<double> losses;
    for (std::int64_t s = 0; s < schedule.total_steps(); ++s) {
      const float* x = windows.data() + static_cast<std::size_t>(s % steps_per_epoch) * B * N * W;
      masking.sample_into(masks, B, 21, static_cast<std::uint64_t>(s));
      const MaeStepStats st = mae_train_step(model, opt, schedule, s, x, B, masks, w, noise());
      CHECK(std::isfinite(st.loss));
      losses.push_back(st.loss);
    }
    const std::size_t n = losses.size(), k = steps_per_epoch;
    double first = 0, last = 0;
    for (std::size_t i = 0; i < k; ++i) first += losses[i] / k, last += losses[n - k + i] / k;
    MESSAGE("steps ", n, ": mean loss over the first epoch ", first, ", over the last ", last,
            "; from positions alone ", position_only);
    CHECK(last < 0.5 * first);
    // The encoder reads the visible windows: it beats the per-token mean it could learn blind.
    CHECK(last < 0.9 * position_only);
  }
}
