// nn suite, modules: gradient checks of every module and of a 2-block encoder and predictor end
// to end, accumulation, and the allocation-free inference path.
#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <string>
#include <vector>

#include <tjepa/tjepa.hpp>
#include <tjepa/model/stage_clock.hpp>  // tested directly below (StageClock)

#include <allocation_counter.hpp>

#include "../support/gradcheck.hpp"

using namespace tjepa;
using tjepa::alloc::count_allocations;
using test::gradient_error;
using test::grad_tolerance;

TEST_SUITE("model") {
  TEST_CASE("Encoder on a context subset: gradients of tokens and parameters (2 blocks - drop-path)") {
    ParamSet<double> ps;
    EncoderConfig cfg{.num_tokens = 7, .dim = 12, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6};
    Encoder enc(ps, cfg);
    ps.allocate();
    test::randomize(ps, 1);
    CHECK(ps.contains("pos_embed"));
    CHECK(ps.contains("blocks.1.attn.qkv.weight"));
    CHECK(ps.infos()[ps.id("blocks.1.mlp.fc1.weight").index].shape == std::vector<std::int64_t>{48, 12});
    CHECK(ps.contains("norm.bias"));
    const int B = 2, N = 7, K = 5, d = 12;
    Rng rng(2);
    auto tokens = test::normal_vector(std::size_t(B) * N * d, rng);
    const std::vector<int> ctx{0, 2, 3, 5, 6, 6, 1, 4, 0, 3};  // a repeated index is allowed
    auto w = test::normal_vector(std::size_t(B) * K * d, rng);
    std::vector<double> out(w.size());
    Workspace<double> ws;
    EncoderOptions opt;
    SUBCASE("no drop-path") {}
    SUBCASE("drop-path 0.5") { opt.drop_path = {0.5, 99}; }
    auto loss = [&] {
      enc.forward(ps, {tokens.data(), B, ctx}, out.data(), ws, opt);
      return test::dot(w.data(), out.data(), out.size());
    };
    EncoderCache<double> cache;
    std::vector<double> dtokens(tokens.size(), 0.0);
    ps.zero_grad();
    enc.forward(ps, {tokens.data(), B, ctx}, out.data(), cache, ws, opt);
    CHECK(test::dot(w.data(), out.data(), out.size()) == doctest::Approx(loss()).epsilon(1e-12));
    enc.backward(ps, w.data(), dtokens.data(), cache, ws);
    CHECK(gradient_error(tokens.data(), dtokens.data(), tokens.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
  }

  TEST_CASE("Encoder with register rows and a mask token (DINO's student): shapes / masked rows / gradients") {
    ParamSet<double> ps;
    EncoderConfig cfg{.num_tokens = 6, .dim = 8, .depth = 2, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6, .register_tokens = 2, .mask_token = true};
    Encoder enc(ps, cfg);
    ps.allocate();
    test::randomize(ps, 7);
    CHECK(ps.infos()[ps.id("register_tokens").index].shape == std::vector<std::int64_t>{1, 2, 8});
    CHECK(ps.infos()[ps.id("mask_token").index].shape == std::vector<std::int64_t>{1, 1, 8});
    const int B = 2, N = 6, K = 3, d = 8, R = 2;
    Rng rng(8);
    auto tokens = test::normal_vector(std::size_t(B) * N * d, rng);
    const std::vector<int> ctx{0, 2, 5, 3, 1, 4};
    const std::vector<std::uint8_t> masked{0, 1, 0, 1, 0, 0};
    auto w = test::normal_vector(std::size_t(B) * (R + K) * d, rng);
    std::vector<double> out(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      enc.forward(ps, {tokens.data(), B, ctx, masked}, out.data(), ws, {DropPath{0.5, 3}, nullptr});
      return test::dot(w.data(), out.data(), out.size());
    };
    EncoderCache<double> cache;
    std::vector<double> dtokens(tokens.size(), 0.0);
    ps.zero_grad();
    enc.forward(ps, {tokens.data(), B, ctx, masked}, out.data(), cache, ws, {DropPath{0.5, 3}, nullptr});
    CHECK(test::dot(w.data(), out.data(), out.size()) == doctest::Approx(loss()).epsilon(1e-12));
    enc.backward(ps, w.data(), dtokens.data(), cache, ws);
    CHECK(gradient_error(tokens.data(), dtokens.data(), tokens.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
    // A masked token's input reaches nothing: its rows of dtokens are zero (token 2 of sample 0 and
    // token 3 of sample 1 are seen nowhere else).
    for (int c = 0; c < d; ++c) {
      CHECK(dtokens[std::size_t(0 * N + 2) * d + c] == 0.0);
      CHECK(dtokens[std::size_t(1 * N + 3) * d + c] == 0.0);
    }
    // Without the register rows in the output: the token rows of the full output, and their gradients.
    const EncoderOptions tokens_only{.drop_path = DropPath{0.5, 3}, .register_rows = false};
    std::vector<double> part(std::size_t(B) * K * d), full(out.size());
    enc.forward(ps, {tokens.data(), B, ctx, masked}, full.data(), ws, {DropPath{0.5, 3}, nullptr});
    enc.forward(ps, {tokens.data(), B, ctx, masked}, part.data(), ws, tokens_only);
    for (int b = 0; b < B; ++b)
      for (std::size_t i = 0; i < std::size_t(K) * d; ++i)
        CHECK(part[std::size_t(b) * K * d + i] == full[(std::size_t(b) * (R + K) + R) * d + i]);
    auto wk = test::normal_vector(part.size(), rng);
    auto part_loss = [&] {
      enc.forward(ps, {tokens.data(), B, ctx, masked}, part.data(), ws, tokens_only);
      return test::dot(wk.data(), part.data(), part.size());
    };
    ps.zero_grad();
    enc.forward(ps, {tokens.data(), B, ctx, masked}, part.data(), cache, ws, tokens_only);
    enc.backward(ps, wk.data(), cache, ws);
    test::check_param_gradients(ps, part_loss);
    // Masked flags must cover every context token.
    CHECK_THROWS_WITH_AS(enc.forward(ps, {tokens.data(), B, ctx, std::span<const std::uint8_t>(masked.data(), 4)},
                                     out.data(), ws),
                         "Encoder::forward: 4 masked flags, expected none or batch·K", ShapeError);
  }

  TEST_CASE("Encoder with token types: taxeltype_embed rows added per token type - gradients") {
    ParamSet<double> ps;
    EncoderConfig cfg{.num_tokens = 6, .dim = 8, .depth = 1, .heads = 2, .mlp_ratio = 2.0, .bias = true, .eps = 1e-6, .token_type = {2, 0, 1, 1, 0, 2}, .token_types = 3};
    Encoder enc(ps, cfg);
    ps.allocate();
    test::randomize(ps, 5);
    CHECK(ps.infos()[ps.id("taxeltype_embed").index].shape == std::vector<std::int64_t>{3, 8});
    const int B = 2, N = 6, K = 4, d = 8;
    Rng rng(6);
    auto tokens = test::normal_vector(std::size_t(B) * N * d, rng);
    const std::vector<int> ctx{0, 2, 5, 3, 1, 1, 4, 2};
    auto w = test::normal_vector(std::size_t(B) * K * d, rng);
    std::vector<double> out(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      enc.forward(ps, {tokens.data(), B, ctx}, out.data(), ws);
      return test::dot(w.data(), out.data(), out.size());
    };
    EncoderCache<double> cache;
    std::vector<double> dtokens(tokens.size(), 0.0);
    ps.zero_grad();
    enc.forward(ps, {tokens.data(), B, ctx}, out.data(), cache, ws);
    enc.backward(ps, w.data(), dtokens.data(), cache, ws);
    CHECK(gradient_error(tokens.data(), dtokens.data(), tokens.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
    // The type row is a per-token offset: moving it into the tokens of that type gives the same output.
    const double before = loss();
    double* table = ps.value(enc.type_embed);
    for (int b = 0; b < B; ++b)
      for (int n = 0; n < N; ++n)
        for (int c = 0; c < d; ++c) tokens[(std::size_t(b) * N + n) * d + c] += table[cfg.token_type[std::size_t(n)] * d + c];
    std::fill(table, table + 3 * d, 0.0);
    CHECK(loss() == doctest::Approx(before).epsilon(1e-12));
    EncoderConfig bad = cfg;
    bad.token_type[1] = 3;
    ParamSet<double> ps2;
    CHECK_THROWS_WITH_AS(Encoder(ps2, bad), doctest::Contains("token_type[1] = 3"), ConfigError);
  }

  TEST_CASE("Predictor - tiled targets: gradients of context - position rows and parameters (2 blocks)") {
    ParamSet<double> ps;
    PredictorConfig cfg{10, 12, 2, 3, 4.0, false, 1e-6};
    Predictor pred(ps, cfg);
    ps.allocate();
    test::randomize(ps, 3);
    CHECK(ps.contains("predictor.mask_token"));
    CHECK(ps.contains("predictor.input_projection.weight"));
    CHECK_FALSE(ps.contains("predictor.blocks.0.attn.qkv.bias"));
    const int Bc = 2, K = 4, N = 9, t = 3, R = 2, B = Bc * R, din = 10, pd = 12;
    Rng rng(4);
    auto ctx = test::normal_vector(std::size_t(Bc) * K * din, rng);
    auto pos = test::normal_vector(std::size_t(N) * pd, rng);
    const std::vector<int> tg{1, 2, 3, 0, 8, 8, 5, 6, 7, 2, 4, 1};
    auto w = test::normal_vector(std::size_t(B) * t * din, rng);
    std::vector<double> out(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      pred.forward(ps, {ctx.data(), Bc, K, pos.data(), N, tg.data(), B, t}, out.data(), ws);
      return test::dot(w.data(), out.data(), out.size());
    };
    PredictorCache<double> cache;
    std::vector<double> dctx(ctx.size(), 0.0), dpos(pos.size(), 0.0);
    ps.zero_grad();
    pred.forward(ps, {ctx.data(), Bc, K, pos.data(), N, tg.data(), B, t}, out.data(), cache, ws);
    pred.backward(ps, w.data(), dctx.data(), dpos.data(), cache, ws);
    CHECK(gradient_error(ctx.data(), dctx.data(), ctx.size(), loss) < grad_tolerance);
    CHECK(gradient_error(pos.data(), dpos.data(), pos.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
  }

  TEST_CASE("BlockStack keeping only the last rows: same outputs as the full stack - gradients") {
    ParamSet<double> ps;
    const BlockConfig bc{12, 3, 2.0, true, false, true, 1e-6};
    auto stack = BlockStack::add(ps, "blocks.", 2, bc);
    ps.allocate();
    test::randomize(ps, 15);
    const int B = 3, L = 6, kf = 2, d = 12, Lk = L - kf;
    Rng rng(16);
    auto x = test::normal_vector(std::size_t(B) * L * d, rng);
    std::vector<std::uint8_t> valid(std::size_t(B) * L, 1);
    valid[1] = valid[L + 4] = 0;
    DropPath dp;
    SUBCASE("no drop-path") {}
    SUBCASE("drop-path 0.5") { dp = {0.5, 17}; }
    Workspace<double> ws;
    std::vector<double> full(x.size()), kept(std::size_t(B) * Lk * d);
    stack.forward(ps, {x.data(), B, L, valid.data()}, full.data(), dp, ws);
    stack.forward(ps, {x.data(), B, L, valid.data(), kf}, kept.data(), dp, ws);
    double diff = 0;
    for (int b = 0; b < B; ++b)
      for (std::size_t i = 0; i < std::size_t(Lk) * d; ++i)
        diff = std::max(diff, std::abs(kept[std::size_t(b) * Lk * d + i] - full[(std::size_t(b) * L + kf) * d + i]));
    CHECK(diff < 1e-12);
    auto w = test::normal_vector(kept.size(), rng);
    auto loss = [&] {
      stack.forward(ps, {x.data(), B, L, valid.data(), kf}, kept.data(), dp, ws);
      return test::dot(w.data(), kept.data(), kept.size());
    };
    BlockStackCache<double> cache;
    ps.zero_grad();
    stack.forward(ps, {x.data(), B, L, valid.data(), kf}, kept.data(), dp, cache, ws);
    CHECK(test::dot(w.data(), kept.data(), kept.size()) == doctest::Approx(loss()).epsilon(1e-13));
    std::vector<double> dx(x.size(), 0.0);
    std::copy(w.begin(), w.end(), dx.begin());
    stack.backward(ps, dx.data(), cache, ws);
    CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
  }

  TEST_CASE("Encoder and Predictor backward accumulate: two passes give twice the gradient") {
    ParamSet<double> ps;
    Encoder enc(ps, EncoderConfig{.num_tokens = 6, .dim = 12, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    Predictor pred(ps, PredictorConfig{12, 12, 1, 3, 4.0, false, 1e-6});
    ps.allocate();
    test::randomize(ps, 5);
    const int B = 2, N = 6, K = 4, t = 2, d = 12;
    Rng rng(6);
    auto tokens = test::normal_vector(std::size_t(B) * N * d, rng);
    auto w = test::normal_vector(std::size_t(B) * t * d, rng);
    const std::vector<int> ctx{0, 1, 3, 5, 2, 3, 4, 5}, tg{2, 4, 0, 1};
    std::vector<double> z(std::size_t(B) * K * d), out(w.size());
    Workspace<double> ws;
    EncoderCache<double> ec;
    PredictorCache<double> pc;
    auto step = [&](std::vector<double>& dtokens) {
      std::vector<double> dz(z.size(), 0.0);
      enc.forward(ps, {tokens.data(), B, ctx}, z.data(), ec, ws, {DropPath{0.3, 7}, nullptr});
      pred.forward(ps, {z.data(), B, K, ps.value(enc.pos_embed()), N, tg.data(), B, t}, out.data(), pc, ws);
      pred.backward(ps, w.data(), dz.data(), ps.grad(enc.pos_embed()), pc, ws);
      enc.backward(ps, dz.data(), dtokens.data(), ec, ws);
    };
    std::vector<double> d1(tokens.size(), 0.0), d2(tokens.size(), 0.0);
    ps.zero_grad();
    step(d1);
    const std::vector<double> g1(ps.grads().begin(), ps.grads().end());
    ps.zero_grad();
    step(d2);
    step(d2);
    double worst = 0, scale = 0;
    for (std::size_t i = 0; i < g1.size(); ++i) {
      worst = std::max(worst, std::abs(ps.grads()[i] - 2 * g1[i]));
      scale = std::max(scale, std::abs(g1[i]));
    }
    for (std::size_t i = 0; i < d1.size(); ++i) worst = std::max(worst, std::abs(d2[i] - 2 * d1[i]));
    CHECK(scale > 0);
    CHECK(worst <= 1e-13 * scale);
  }

  TEST_CASE("SelfAttention with a key padding mask - Mlp: gradients of inputs and parameters") {
    ParamSet<double> ps;
    const int B = 2, L = 5, d = 12;
    auto attn = SelfAttention::add(ps, "attn", d, 3, true, true);
    auto mlp = Mlp::add(ps, "mlp", d, 20, true, 7);
    ps.allocate();
    test::randomize(ps, 8);
    Rng rng(9);
    auto x = test::normal_vector(std::size_t(B) * L * d, rng);
    const std::vector<std::uint8_t> valid{1, 0, 1, 1, 0, 1, 1, 1, 1, 0};
    Workspace<double> ws;
    std::vector<double> qkv(std::size_t(B) * L * 3 * d), att(std::size_t(B) * L * d), lse(std::size_t(B) * 3 * L);
    SUBCASE("attention") {
      auto w = test::normal_vector(std::size_t(B) * L * d, rng);
      std::vector<double> y(w.size());
      auto loss = [&] {
        attn.forward(ps, AttentionRows{B, L, valid.data()}, x.data(),
                     AttentionSaved<double>{.qkv = qkv.data(), .att = att.data()}, y.data(), ws);
        return test::dot(w.data(), y.data(), y.size());
      };
      ps.zero_grad();
      const AttentionRows rows{B, L, valid.data()};
      const AttentionSaved<double> saved{.qkv = qkv.data(), .att = att.data(), .lse = lse.data()};
      attn.forward(ps, rows, x.data(), saved, y.data(), ws);
      std::vector<double> dx(x.size(), 0.0), dqkv(qkv.size()), datt(att.size());
      attn.backward(ps, rows, w.data(), x.data(), saved, AttentionScratch<double>{.dqkv = dqkv.data(), .datt = datt.data()},
                    dx.data(), ws);
      CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
      // A padded token is never attended to: changing it changes only its own output row.
      loss();
      const std::vector<double> before = y;
      x[std::size_t(1) * d + 2] += 1.0;
      loss();
      x[std::size_t(1) * d + 2] -= 1.0;
      double other = 0, own = 0;
      for (std::size_t i = 0; i < y.size(); ++i)
        (i / d == 1 ? own : other) = std::max(i / d == 1 ? own : other, std::abs(y[i] - before[i]));
      CHECK(other < 1e-14);
      CHECK(own > 1e-6);
      test::check_param_gradients(ps, loss);
    }
    SUBCASE("batch 1, long sequence: query blocks over threads equal the reference kernel") {
      const int L1 = 100;
      auto x1 = test::normal_vector(std::size_t(L1) * d, rng);
      std::vector<double> qkv1(std::size_t(L1) * 3 * d), att1(std::size_t(L1) * d), y1(att1.size());
      std::vector<double> ref_att(att1.size()), ref_lse(std::size_t(3) * L1), lse1(ref_lse.size());
      attn.forward(ps, AttentionRows{1, L1}, x1.data(),
                   AttentionSaved<double>{.qkv = qkv1.data(), .att = att1.data(), .lse = lse1.data()}, y1.data(), ws);
      kernels::ref::attention_forward(kernels::AttentionShape::fused_self(L1, 3, d / 3), qkv1.data(), qkv1.data() + d,
                             qkv1.data() + 2 * d, nullptr, ref_att.data(), ref_lse.data());
      double diff = 0;
      for (std::size_t i = 0; i < att1.size(); ++i) diff = std::max(diff, std::abs(att1[i] - ref_att[i]));
      for (std::size_t i = 0; i < lse1.size(); ++i) diff = std::max(diff, std::abs(lse1[i] - ref_lse[i]));
      CHECK(diff < 1e-12);
    }
    SUBCASE("mlp") {
      const int M = B * L;
      auto w = test::normal_vector(std::size_t(M) * 7, rng);
      std::vector<double> y(w.size()), hp(std::size_t(M) * 20), h(hp.size()), dh(hp.size());
      auto loss = [&] {
        mlp.forward(ps, x.data(), hp.data(), h.data(), y.data(), M);
        return test::dot(w.data(), y.data(), y.size());
      };
      ps.zero_grad();
      loss();
      std::vector<double> dx(x.size(), 0.0);
      mlp.backward(ps, w.data(), x.data(), hp.data(), h.data(), dh.data(), dx.data(), M);
      CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
      test::check_param_gradients(ps, loss);
    }
  }

  TEST_CASE("Tokenizer - per taxel and grouped with padding: gradients of inputs and parameters") {
    ParamSet<double> ps;
    const int B = 2, d = 12;
    Tokenizer tok;
    int in_used = 0;
    SUBCASE("per taxel") {
      tok = Tokenizer::per_taxel(ps, 5, 2, 3, d);
      CHECK(tok.width == 6);
      // The reference's Conv1d weight [d, m, τ], so a strict PyTorch load_state_dict accepts it.
      CHECK(ps.infos()[ps.id("patch_embed.proj.weight").index].shape == std::vector<std::int64_t>{12, 2, 3});
      CHECK(ps.contains("patch_embed.norm.bias"));
    }
    SUBCASE("per taxel - temporal padding 2 of 5 frames") {
      tok = Tokenizer::per_taxel(ps, 4, 2, 5, d, kernels::layer_norm_eps, "patch_embed.", 2);
      CHECK(tok.padding == 2);
      CHECK_THROWS_AS(Tokenizer::per_taxel(ps, 4, 2, 5, d, kernels::layer_norm_eps, "x.", 3), ConfigError);
    }
    SUBCASE("grouped") {
      tok = Tokenizer::grouped(ps, {4, 5, 4, 4, 5}, 3, d);
      CHECK(ps.infos()[ps.id("tokenizer.direct4.0.weight").index].shape == std::vector<std::int64_t>{12, 12});
      CHECK(ps.infos()[ps.id("tokenizer.direct5.0.weight").index].shape == std::vector<std::int64_t>{12, 15});
      CHECK(ps.contains("tokenizer.direct5.1.weight"));
      CHECK(tok.width == 15);
      in_used = 12;  // token 0 has 4 members: columns 12..14 are padding
    }
    ps.allocate();
    test::randomize(ps, 10);
    Rng rng(11);
    const int G = tok.num_tokens;
    auto x = test::normal_vector(std::size_t(B) * G * tok.width, rng);
    auto w = test::normal_vector(std::size_t(B) * G * d, rng);
    std::vector<double> y(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      tok.forward(ps, x.data(), B, y.data(), ws);
      return test::dot(w.data(), y.data(), y.size());
    };
    TokenizerCache<double> cache;
    ps.zero_grad();
    tok.forward(ps, x.data(), B, y.data(), cache, ws);
    std::vector<double> dx(x.size(), 0.0);
    tok.backward(ps, w.data(), dx.data(), cache, ws);
    CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
    if (in_used > 0) {
      const double before = loss();
      x[std::size_t(in_used) + 1] += 5.0;  // a padding value of token 0
      CHECK(loss() == before);
      CHECK(dx[std::size_t(in_used) + 1] == 0.0);
    }
    if (tok.padding > 0) {
      // The Conv1d's view: p zeros, then frames 0..τ−p−1; the last p frames are never read.
      const double before = loss();
      x[4] += 5.0;  // token 0, axis 0, frame 4
      x[std::size_t(tok.width) + 8] -= 3.0;  // token 1, axis 1, frame 3
      CHECK(loss() == before);
      CHECK(dx[4] == 0.0);
      // Against the shifted input through an unpadded map with the same weights.
      ParamSet<double> ps0;
      const Tokenizer tok0 = Tokenizer::per_taxel(ps0, 4, 2, 5, d);
      ps0.allocate();
      std::copy(ps.values().begin(), ps.values().end(), ps0.values().begin());
      std::vector<double> shifted(x.size(), 0.0), y0(y.size());
      for (std::size_t r = 0; r < x.size() / 10; ++r)
        for (int a = 0; a < 2; ++a)
          for (int f = 2; f < 5; ++f) shifted[r * 10 + a * 5 + f] = x[r * 10 + a * 5 + f - 2];
      tok0.forward(ps0, shifted.data(), B, y0.data(), ws);
      tok.forward(ps, x.data(), B, y.data(), ws);
      CHECK(y0 == y);
    }
    test::check_param_gradients(ps, loss);
  }

  // CrossAttention's reference: q, k and v projected for every token, softmax(q_h k_hᵀ/√Dh) v_h per
  // head over the valid keys (output 0 when there are none), then proj.
  template <class T>
  std::vector<double> cross_attention_reference(const tjepa::ParamSet<T>& ps, const tjepa::CrossAttention& a,
                                                const T* query, const T* x, const std::uint8_t* valid, int B, int L) {
    const int d = a.dim(), H = a.heads, Dh = d / H;
    auto linear = [&](const tjepa::LinearParams& lp, int row0, int rows, const T* in) {
      std::vector<double> out(static_cast<std::size_t>(rows));
      for (int o = 0; o < rows; ++o) {
        double s = lp.has_bias ? double(ps.value(lp.bias)[row0 + o]) : 0.0;
        for (int i = 0; i < lp.in; ++i) s += double(ps.value(lp.weight)[std::size_t(row0 + o) * lp.in + i]) * double(in[i]);
        out[std::size_t(o)] = s;
      }
      return out;
    };
    const std::vector<double> q = linear(a.q, 0, d, query);
    std::vector<double> y(std::size_t(B) * d);
    for (int b = 0; b < B; ++b) {
      std::vector<std::vector<double>> k, v;
      for (int n = 0; n < L; ++n) {
        k.push_back(linear(a.kv, 0, d, x + (std::size_t(b) * L + n) * d));
        v.push_back(linear(a.kv, d, d, x + (std::size_t(b) * L + n) * d));
      }
      std::vector<T> att(std::size_t(d), T(0));
      for (int h = 0; h < H; ++h) {
        std::vector<double> s(std::size_t(L), -std::numeric_limits<double>::infinity());
        double mx = -std::numeric_limits<double>::infinity();
        for (int n = 0; n < L; ++n) {
          if (valid && !valid[std::size_t(b) * L + n]) continue;
          double dot = 0;
          for (int j = 0; j < Dh; ++j) dot += q[std::size_t(h * Dh + j)] * k[std::size_t(n)][std::size_t(h * Dh + j)];
          s[std::size_t(n)] = dot / std::sqrt(double(Dh));
          mx = std::max(mx, s[std::size_t(n)]);
        }
        if (mx == -std::numeric_limits<double>::infinity()) continue;  // every key masked
        double z = 0;
        for (int n = 0; n < L; ++n) z += std::exp(s[std::size_t(n)] - mx);
        for (int j = 0; j < Dh; ++j) {
          double o = 0;
          for (int n = 0; n < L; ++n)
            if (!valid || valid[std::size_t(b) * L + n]) o += std::exp(s[std::size_t(n)] - mx) / z * v[std::size_t(n)][std::size_t(h * Dh + j)];
          att[std::size_t(h * Dh + j)] = T(o);
        }
      }
      const std::vector<double> yb = linear(a.proj, 0, d, att.data());
      std::copy(yb.begin(), yb.end(), y.begin() + std::ptrdiff_t(b) * d);
    }
    return y;
  }

  // A CrossAttention (3 heads) on B samples of L tokens of width d with random parameters, query
  // and tokens; key 2 of sample 0 and every key of sample 1 are masked.
  template <class T>
  struct CrossAttentionCase {
    int B, L, d, H = 3;
    ParamSet<T> ps;
    CrossAttention a;
    std::vector<T> query, x, q, u, p, pooled, att, y;
    std::vector<std::uint8_t> valid;
    CrossAttentionCase(int B_, int L_, int d_) : B(B_), L(L_), d(d_), a(CrossAttention::add(ps, "xattn", d_, 3, true)) {
      ps.allocate();
      test::randomize(ps, 21);
      Rng rng(22);
      query.resize(std::size_t(d));
      x.resize(std::size_t(B) * L * d);
      test::fill_normal(query, rng);
      test::fill_normal(x, rng);
      valid.assign(std::size_t(B) * L, 1);
      valid[2] = 0;
      std::fill(valid.begin() + L, valid.begin() + 2 * L, std::uint8_t(0));
      q.resize(std::size_t(d));
      u.resize(std::size_t(H) * d);
      p.resize(std::size_t(B) * H * L);
      pooled.resize(std::size_t(B) * H * d);
      att.resize(std::size_t(B) * d);
      y.resize(std::size_t(B) * d);
    }
    AttentionRows rows() const { return {B, L, valid.data()}; }
    CrossAttentionSaved<T> saved() { return {q.data(), u.data(), p.data(), pooled.data(), att.data()}; }
    void forward() { a.forward(ps, rows(), query.data(), x.data(), saved(), y.data()); }
  };

  TEST_CASE_TEMPLATE("CrossAttention (the shared query folded into the key weights) equals the reference that projects k and v for every token (masks / a sample with every key masked / NaN in masked tokens)", T, float, double) {
    // Small, and large enough for whole vectors of every width and the parallel weight gradient.
    for (const auto [B, L, d] : {std::array{3, 5, 12}, std::array{64, 37, 48}}) {
      CAPTURE(L);
      CrossAttentionCase<T> c(B, L, d);
      for (int i = 0; i < d; ++i) c.x[std::size_t(2) * d + i] = std::numeric_limits<T>::quiet_NaN();  // masked
      c.forward();
      const std::vector<double> ref = cross_attention_reference(c.ps, c.a, c.query.data(), c.x.data(), c.valid.data(), B, L);
      double err = 0, scale = 0;
      for (std::size_t i = 0; i < c.y.size(); ++i) {
        err = std::max(err, std::abs(double(c.y[i]) - ref[i]));
        scale = std::max(scale, std::abs(ref[i]));
      }
      CHECK(err <= (std::is_same_v<T, float> ? 1e-5 : 1e-13) * scale);  // NaN fails it
      for (int i = 0; i < d; ++i) CHECK(c.att[std::size_t(d) + i] == T(0));  // sample 1: every key masked
      // The backward stays finite too, and the masked tokens get no gradient.
      std::vector<T> dy(c.y.size(), T(1)), dq(static_cast<std::size_t>(d)), datt(c.att.size()), dpooled(c.pooled.size()),
          du(c.pooled.size()), dp(c.p.size()), ds(c.p.size()), dquery(static_cast<std::size_t>(d), T(0)), dx(c.x.size(), T(0));
      c.ps.zero_grad();
      c.a.backward(c.ps, c.rows(), dy.data(), c.query.data(), c.x.data(), c.saved(),
                   CrossAttentionScratch<T>{dq.data(), datt.data(), dpooled.data(), du.data(), dp.data(), ds.data()},
                   dquery.data(), dx.data());
      CHECK(std::all_of(dx.begin(), dx.end(), [](T v) { return std::isfinite(v); }));
      CHECK(std::all_of(dquery.begin(), dquery.end(), [](T v) { return std::isfinite(v); }));
      for (std::size_t i = 0; i < c.ps.count(); ++i)
        for (T v : c.ps.grad_span(c.ps.id(i))) CHECK(std::isfinite(v));
      for (int i = 0; i < d; ++i) CHECK(dx[std::size_t(2) * d + i] == T(0));
    }
  }

  TEST_CASE("CrossAttention with a shared query: gradients of the query / tokens / parameters (masks / every key masked)") {
    CrossAttentionCase<double> c(3, 5, 12);
    const int B = c.B, L = c.L, d = c.d, H = c.H;
    Rng rng(24);
    auto w = test::normal_vector(std::size_t(B) * d, rng);
    auto loss = [&] {
      c.forward();
      return test::dot(w.data(), c.y.data(), c.y.size());
    };
    c.ps.zero_grad();
    loss();
    std::vector<double> dq(static_cast<std::size_t>(d)), datt(std::size_t(B) * d), dpooled(std::size_t(B) * H * d),
        du(dpooled.size()), dp(c.p.size()), ds(c.p.size()), dquery(static_cast<std::size_t>(d), 0.0), dx(c.x.size(), 0.0);
    c.a.backward(c.ps, c.rows(), w.data(), c.query.data(), c.x.data(), c.saved(),
                 CrossAttentionScratch<double>{dq.data(), datt.data(), dpooled.data(), du.data(), dp.data(), ds.data()},
                 dquery.data(), dx.data());
    CHECK(gradient_error(c.query.data(), dquery.data(), c.query.size(), loss) < grad_tolerance);
    CHECK(gradient_error(c.x.data(), dx.data(), c.x.size(), loss) < grad_tolerance);
    for (int i = 0; i < d; ++i) CHECK(dx[std::size_t(2) * d + i] == 0.0);  // a masked key
    for (std::size_t i = std::size_t(L) * d; i < std::size_t(2 * L) * d; ++i) CHECK(dx[i] == 0.0);
    test::check_param_gradients(c.ps, loss);
  }

  TEST_CASE("AttentiveProbe with padded tokens: gradients of inputs and parameters") {
    ParamSet<double> ps;
    AttentiveProbe probe(ps, ProbeConfig{12, 3, 2.0, 10, 4, 1e-6, {}});
    ps.allocate();
    test::randomize(ps, 12);
    CHECK(ps.contains("probe.query_tokens"));
    CHECK(ps.contains("probe.cross_attention_block.xattn.kv.weight"));
    CHECK(ps.contains("probe.head.fc2.bias"));
    const int B = 3, L = 6, d = 12;
    Rng rng(13);
    auto x = test::normal_vector(std::size_t(B) * L * d, rng);
    std::vector<std::uint8_t> valid(std::size_t(B) * L, 1);
    valid[2] = valid[L + 5] = 0;
    auto w = test::normal_vector(std::size_t(B) * 4, rng);
    std::vector<double> y(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      probe.forward(ps, {x.data(), B, L, valid}, y.data(), ws);
      return test::dot(w.data(), y.data(), y.size());
    };
    ProbeCache<double> cache;
    ps.zero_grad();
    probe.forward(ps, {x.data(), B, L, valid}, y.data(), cache, ws);
    CHECK(test::dot(w.data(), y.data(), y.size()) == doctest::Approx(loss()).epsilon(1e-13));
    std::vector<double> dx(x.size(), 0.0);
    probe.backward(ps, w.data(), dx.data(), cache, ws);
    CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
    for (int c = 0; c < d; ++c) CHECK(dx[std::size_t(2) * d + c] == 0.0);  // a padded token
    test::check_param_gradients(ps, loss);
    // The pooling alone: inference equals the cached pass; a key_valid of the wrong size is named.
    std::vector<double> q_inference(std::size_t(B) * d), q_cached(q_inference.size());
    ProbeCache<double> pool_cache;
    probe.pool(ps, {x.data(), B, L, valid}, q_inference.data(), ws);
    probe.pool(ps, {x.data(), B, L, valid}, q_cached.data(), pool_cache, ws);
    CHECK(q_inference == q_cached);
    CHECK_THROWS_WITH_AS(probe.pool(ps, {x.data(), B, L, std::span(valid).first(3)}, q_inference.data(), ws),
                         doctest::Contains("AttentiveProbe::pool: 3 key_valid entries"), ShapeError);
    // NaN in the padded tokens changes nothing: the same outputs and the same gradients.
    auto run = [&] {
      std::vector<double> out(y.size()), grads;
      probe.forward(ps, {x.data(), B, L, valid}, out.data(), ws);  // inference
      ps.zero_grad();
      probe.forward(ps, {x.data(), B, L, valid}, y.data(), cache, ws);
      CHECK(y == out);
      std::fill(dx.begin(), dx.end(), 0.0);
      probe.backward(ps, w.data(), dx.data(), cache, ws);
      for (std::size_t i = 0; i < ps.count(); ++i)
        for (double g : ps.grad_span(ps.id(i))) grads.push_back(g);
      out.insert(out.end(), grads.begin(), grads.end());
      out.insert(out.end(), dx.begin(), dx.end());
      return out;
    };
    const std::vector<double> clean = run();
    for (const std::size_t r : {std::size_t(2), std::size_t(L + 5)})
      std::fill_n(x.begin() + std::ptrdiff_t(r * d), d, std::numeric_limits<double>::quiet_NaN());
    CHECK(run() == clean);
  }

  TEST_CASE("TaxelPooling (model/taxel_pooling.hpp) alone: gradients of inputs and parameters - inference equals the cached forward") {
    const int M = 3, N = 4, d = 6;
    ParamSet<double> ps;
    const TaxelPooling tp = TaxelPooling::add(ps, "pool.", d, PoolingConfig{PoolingKind::taxel, N, 2}, 1e-6);
    ps.allocate();
    test::randomize(ps, 16);
    Rng rng(17);
    auto x = test::normal_vector(std::size_t(M) * N * d, rng);
    auto w = test::normal_vector(std::size_t(M) * d, rng);
    std::vector<double> p(w.size()), q(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      tp.forward(ps, x.data(), M, N, q.data(), ws);
      return test::dot(w.data(), q.data(), q.size());
    };
    TaxelPoolCache<double> cache;
    ps.zero_grad();
    tp.forward(ps, x.data(), M, N, p.data(), cache, ws);
    loss();
    CHECK(p == q);
    std::vector<double> dx(x.size(), 0.0);
    tp.backward(ps, w.data(), dx.data(), M, cache, ws);
    CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
    CHECK(parse_pooling("attentive") == PoolingKind::attentive);
    CHECK(std::string(to_string(PoolingKind::taxel)) == "taxel");
  }

  TEST_CASE("AttentiveProbe with the taxel pooling: gradients of inputs and parameters - its own errors") {
    const int B = 3, L = 5, d = 8, k = 2;
    ParamSet<double> ps;
    ProbeConfig c{d, 2, 2.0, 6, 3, 1e-6, {PoolingKind::taxel, L, k}};
    AttentiveProbe probe(ps, c);
    ps.allocate();
    test::randomize(ps, 14);
    CHECK(ps.infos()[ps.id("probe.proj.weight").index].shape == std::vector<std::int64_t>{k, d});
    CHECK(ps.infos()[ps.id("probe.fc.weight").index].shape == std::vector<std::int64_t>{d, L * k});
    CHECK(ps.contains("probe.norm.weight"));
    CHECK(ps.contains("probe.head.fc2.bias"));
    CHECK_FALSE(ps.contains("probe.query_tokens"));
    Rng rng(15);
    auto x = test::normal_vector(std::size_t(B) * L * d, rng);
    auto w = test::normal_vector(std::size_t(B) * 3, rng);
    std::vector<double> y(w.size());
    Workspace<double> ws;
    auto loss = [&] {
      probe.forward(ps, {x.data(), B, L}, y.data(), ws);
      return test::dot(w.data(), y.data(), y.size());
    };
    ProbeCache<double> cache;
    ps.zero_grad();
    probe.forward(ps, {x.data(), B, L}, y.data(), cache, ws);
    CHECK(test::dot(w.data(), y.data(), y.size()) == doctest::Approx(loss()).epsilon(1e-13));
    std::vector<double> dx(x.size(), 0.0);
    probe.backward(ps, w.data(), dx.data(), cache, ws);
    CHECK(gradient_error(x.data(), dx.data(), x.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
    // Where a token sits matters: swapping two tokens of a sample changes its output.
    const std::vector<double> y0 = y;
    for (int i = 0; i < d; ++i) std::swap(x[std::size_t(i)], x[std::size_t(d + i)]);
    loss();
    CHECK(y[0] != y0[0]);
    CHECK(y[3] == y0[3]);  // sample 1 unchanged
    std::vector<std::uint8_t> valid(std::size_t(B) * L, 1);
    CHECK_THROWS_WITH_AS(probe.forward(ps, {x.data(), B, L, valid}, y.data(), ws),
                         doctest::Contains("no padded tokens"), ShapeError);
    CHECK_THROWS_WITH_AS(probe.forward(ps, {x.data(), B * L, 1}, y.data(), ws),
                         doctest::Contains("built for 5"), ShapeError);
    ParamSet<double> bad;
    c.pooling.components = 0;
    CHECK_THROWS_AS(AttentiveProbe(bad, c), ConfigError);
  }

  TEST_CASE("bad input at the module boundary throws - naming the argument") {
    ParamSet<float> ps, other;
    Encoder enc(ps, EncoderConfig{.num_tokens = 10, .dim = 12, .depth = 1, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    Predictor(other, PredictorConfig{12, 12, 1, 3, 4.0, false, 1e-6});
    Workspace<float> ws;
    std::vector<float> tokens(2 * 10 * 12), out(tokens.size());
    std::vector<int> ctx{0, 1, 2, 10};
    CHECK_THROWS_WITH_AS(enc.forward(ps, {tokens.data(), 2}, out.data(), ws),
                         "Encoder::forward: the ParamSet is not allocated", ConfigError);
    ps.allocate();
    other.allocate();
    CHECK_THROWS_AS(enc.forward(other, {tokens.data(), 2}, out.data(), ws), ConfigError);
    CHECK_THROWS_WITH_AS(enc.forward(ps, {tokens.data(), 2, ctx}, out.data(), ws),
                         "Encoder::forward: context[3] = 10, expected [0, 10)", ShapeError);
    CHECK_THROWS_WITH_AS(enc.forward(ps, {tokens.data(), 2, std::span<const int>(ctx.data(), 3)}, out.data(), ws),
                         "Encoder::forward: 3 context indices for batch 2, expected a multiple of it", ShapeError);
    CHECK_THROWS_WITH_AS(enc.forward(ps, {nullptr, 2}, out.data(), ws), "Encoder::forward: null tokens or out",
                         ShapeError);
    EncoderCache<float> empty;
    CHECK_THROWS_AS(enc.backward(ps, out.data(), nullptr, empty, ws), ConfigError);
    CHECK_THROWS_AS(Encoder(ps, EncoderConfig{.num_tokens = 10, .dim = 10, .depth = 1, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6}), ConfigError);
  }

  TEST_CASE("init_params: the reference implementation's values - deterministic from the seed") {
    ParamSet<float> a, b;
    Encoder ea(a, EncoderConfig{.num_tokens = 20, .dim = 24, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    Encoder eb(b, EncoderConfig{.num_tokens = 20, .dim = 24, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    Predictor pa(a, PredictorConfig{24, 24, 1, 3, 4.0, false, 1e-6});
    Predictor pb(b, PredictorConfig{24, 24, 1, 3, 4.0, false, 1e-6});
    a.allocate();
    b.allocate();
    CHECK(a.same_layout(b));
    init_params(a, 42);
    init_params(b, 42);
    CHECK(std::equal(a.values().begin(), a.values().end(), b.values().begin()));
    init_params(b, 43);
    CHECK_FALSE(std::equal(a.values().begin(), a.values().end(), b.values().begin()));
    auto v = [&](const char* name) { return a.value_span(a.id(name)); };
    for (float x : v("blocks.0.norm1.weight")) CHECK(x == 1.0f);
    for (float x : v("blocks.0.attn.qkv.bias")) CHECK(x == 0.0f);
    for (float x : v("predictor.mask_token")) CHECK(x == 0.0f);
    double s = 0, s2 = 0, mx = 0;
    for (float x : v("blocks.1.mlp.fc1.weight")) {
      s += x;
      s2 += double(x) * x;
      mx = std::max(mx, double(std::abs(x)));
    }
    const double n = double(v("blocks.1.mlp.fc1.weight").size());
    CHECK(std::abs(s / n) < 0.003);
    CHECK(std::sqrt(s2 / n) == doctest::Approx(0.02).epsilon(0.05));
    CHECK(mx <= 2.0);
    // Weight decay groups: 2-D weights, position table and mask token; not biases or norms.
    CHECK(a.infos()[a.id("pos_embed").index].decay);
    CHECK(a.infos()[a.id("predictor.mask_token").index].decay);
    CHECK_FALSE(a.infos()[a.id("norm.weight").index].decay);
  }

  TEST_CASE("Inference (row-tiled MLP) - frozen packed weights: the training forward's outputs / bit for bit") {
    ParamSet<float> ps;
    const int N = 53, d = 48, B = 2;
    Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = d, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    ps.allocate();
    init_params(ps, 3);
    Rng rng(15);
    std::vector<float> tokens(std::size_t(B) * N * d), train(tokens.size()), infer(tokens.size()), frozen(tokens.size());
    test::fill_normal(tokens, rng);
    EncoderCache<float> cache;
    Workspace<float> ws, fws;
    fws.frozen_weights = true;
    enc.forward(ps, {tokens.data(), B}, train.data(), cache, ws);  // untiled MLP, per-call packing
    enc.forward(ps, {tokens.data(), B}, infer.data(), ws);
    CHECK(infer == train);
    enc.forward(ps, {tokens.data(), B}, frozen.data(), fws);
    CHECK(frozen == train);
    CHECK(fws.packed.size() == 8);  // qkv, proj, fc1, fc2 of 2 blocks, packed once
    const long n = count_allocations([&] { enc.forward(ps, {tokens.data(), B}, frozen.data(), fws); });
    CHECK(n == 0);
    CHECK(frozen == train);
    CHECK(fws.packed.size() == 8);
    // The packed copies are keyed by address: new values need clear(), then they are used.
    for (float& v : ps.values()) v *= 1.5f;
    enc.forward(ps, {tokens.data(), B}, infer.data(), ws);
    fws.packed.clear();
    enc.forward(ps, {tokens.data(), B}, frozen.data(), fws);
    CHECK(frozen == infer);
    CHECK(infer != train);
  }

  TEST_CASE("Inference at batch 1 on 2 threads: each thread keeps its rows (detail::owns_rows) - the bits of 1 thread") {
    // 368 tokens at batch 1 (the Allegro hand): the products, LayerNorm, the row-tiled MLP and the
    // attention's query blocks give each of 2 threads the same rows, in blocks that differ from the
    // one-thread split, and with frozen weights the whole stack runs in one parallel region
    // (BlockStack::forward_owned); no value may depend on that, in fp32 or bf16, nor may the
    // training forward's (cache kept) at batch 1.
    ParamSet<float> ps;
    const int N = 368, d = 48;
    Encoder enc(ps, EncoderConfig{
                        .num_tokens = N, .dim = d, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    ps.allocate();
    init_params(ps, 6);
    Rng rng(17);
    std::vector<float> tokens(std::size_t(N) * d);
    test::fill_normal(tokens, rng);
    CHECK(detail::owns_rows(N, 2));
    for (const Precision p : {Precision::fp32, Precision::bf16}) {
      INFO(precision_name(p));
      std::vector<std::vector<float>> outs;
      for (const int threads : {1, 2}) {
        const test::Threads scope(threads);
        Workspace<float> ws, fws;
        ws.precision = fws.precision = p;
        fws.frozen_weights = true;
        EncoderCache<float> cache;
        std::vector<float> y(tokens.size()), yf(tokens.size()), yt(tokens.size());
        enc.forward(ps, {tokens.data(), 1}, y.data(), ws);
        enc.forward(ps, {tokens.data(), 1}, yf.data(), fws);
        enc.forward(ps, {tokens.data(), 1}, yt.data(), cache, ws);
        CHECK(yf == y);
        if (p == Precision::fp32) CHECK(yt == y);
        outs.push_back(y);
      }
      CHECK(outs[0] == outs[1]);
    }
  }

  TEST_CASE("Inference of a few samples with padded keys on 2 threads: a thread's rows cross a sample - the bits of 1 thread") {
    // 3 samples of 37 tokens (111 rows: thread 1's rows start inside sample 1), the last tokens of
    // samples 0 and 2 padding; frozen weights run BlockStack::forward_owned, whose attention
    // splits each sample's queries between the threads and reads that sample's keys only.
    ParamSet<float> ps;
    const int N = 37, d = 24, B = 3;
    Encoder enc(ps, EncoderConfig{
                        .num_tokens = N, .dim = d, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    ps.allocate();
    init_params(ps, 7);
    Rng rng(18);
    std::vector<float> tokens(std::size_t(B) * N * d);
    test::fill_normal(tokens, rng);
    std::vector<std::uint8_t> valid(std::size_t(B) * N, 1);
    for (int n = 30; n < N; ++n) valid[std::size_t(n)] = valid[std::size_t(2 * N + n)] = 0;
    CHECK(detail::row_begin(B * N, 1, 2) % N != 0);
    std::vector<std::vector<float>> outs;
    for (const int threads : {1, 2}) {
      const test::Threads scope(threads);
      Workspace<float> ws, fws;
      fws.frozen_weights = true;
      std::vector<float> y(tokens.size()), yf(tokens.size());
      enc.forward(ps, {tokens.data(), B}, y.data(), ws, {.key_valid = valid.data()});
      enc.forward(ps, {tokens.data(), B}, yf.data(), fws, {.key_valid = valid.data()});
      CHECK(yf == y);
      outs.push_back(yf);
    }
    CHECK(outs[0] == outs[1]);
    // The padding is really read as such: the same tokens without the mask give other outputs.
    Workspace<float> ws;
    std::vector<float> unmasked(tokens.size());
    enc.forward(ps, {tokens.data(), B}, unmasked.data(), ws);
    CHECK(unmasked != outs[0]);
  }

  TEST_CASE("bf16 inference: the encoder against fp32 (per-token cosine and relative error) / frozen and per-call bit for bit / no allocations") {
    // Bounds, at weights twice the initial scale (std 0.04, LayerNorm gains 2, so the blocks'
    // branches weigh in the output): every token's cosine to the fp32 output >= 0.9999 and its
    // relative error |y16 - y32| / |y32| <= 1 % (measured: 0.99999 and 0.46 %, attention in bf16 too), and no worse
    // than twice what rounding only the weights to bf16 does in fp32 (measured: 1.3×; at 4× the
    // initial scale this encoder is so sensitive that the rounding of the weights alone moves
    // tokens by 30 %). Without AVX512-BF16 bf16 is fp32, bit for bit.
    ParamSet<float> ps;
    const int N = 120, d = 192, B = 2;
    Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = d, .depth = 4, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    ps.allocate();
    init_params(ps, 4);
    for (float& v : ps.values()) v *= 2.0f;
    ParamSet<float> rounded = ps;
    for (float& v : rounded.values()) v = detail::bgemm::round_bf16(v);
    Rng rng(16);
    std::vector<float> tokens(std::size_t(B) * N * d), y32(tokens.size()), y16(tokens.size()), f16(tokens.size()),
        yr(tokens.size());
    test::fill_normal(tokens, rng);
    Workspace<float> ws, bws, fws;
    bws.precision = Precision::bf16;
    fws.precision = Precision::bf16;
    fws.frozen_weights = true;
    enc.forward(ps, {tokens.data(), B}, y32.data(), ws);
    enc.forward(rounded, {tokens.data(), B}, yr.data(), ws);
    enc.forward(ps, {tokens.data(), B}, y16.data(), bws);
    enc.forward(ps, {tokens.data(), B}, f16.data(), fws);
    CHECK(f16 == y16);
    CHECK(fws.packed.size() == 16);  // 4 weights × 4 blocks, packed once in bf16
    if (!detail::bgemm::native) {
      CHECK(y16 == y32);
      return;
    }
    // worst per-token cosine and relative error of y against y32
    auto compare = [&](const std::vector<float>& y) {
      double worst_cos = 1, worst_rel = 0;
      for (int t = 0; t < B * N; ++t) {
        double dot = 0, n32 = 0, n = 0, diff = 0;
        for (int c = 0; c < d; ++c) {
          const double a = y32[std::size_t(t) * d + c], b = y[std::size_t(t) * d + c];
          dot += a * b, n32 += a * a, n += b * b, diff += (a - b) * (a - b);
        }
        worst_cos = std::min(worst_cos, dot / std::sqrt(n32 * n));
        worst_rel = std::max(worst_rel, std::sqrt(diff / n32));
      }
      return std::pair{worst_cos, worst_rel};
    };
    const auto [cos16, rel16] = compare(y16);
    const auto [cos_r, rel_r] = compare(yr);
    MESSAGE("bf16 encoder: worst per-token cosine ", cos16, ", worst relative error ", rel16,
            "; bf16-rounded weights in fp32: ", rel_r);
    CHECK(cos16 >= 0.9999);
    CHECK(rel16 <= 0.01);
    CHECK(rel16 <= 2 * rel_r);
    CHECK(rel16 > 0);  // the bf16 path ran
    const long n = count_allocations([&] { enc.forward(ps, {tokens.data(), B}, f16.data(), fws); });
    CHECK(n == 0);
    CHECK(f16 == y16);
  }

  TEST_CASE("StageClock: an inference call marks its stages in order / changes no output / allocates nothing") {
    ParamSet<float> ps;
    const int N = 21, d = 24, B = 1;
    Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = d, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    ps.allocate();
    init_params(ps, 5);
    Rng rng(9);
    std::vector<float> tokens(std::size_t(B) * N * d), off(tokens.size()), on(tokens.size());
    test::fill_normal(tokens, rng);
    Workspace<float> ws;
    enc.forward(ps, {tokens.data(), B}, off.data(), ws);
    StageClock clock;
    ws.clock = &clock;
    clock.start();
    const long n = count_allocations([&] { enc.forward(ps, {tokens.data(), B}, on.data(), ws); });
    CHECK(n == 0);
    CHECK(on == off);
    std::vector<std::string> names;
    for (int i = 0; i < clock.count(); ++i) {
      names.emplace_back(clock.name(i));
      CHECK(clock.elapsed_ns(i) >= 0);
    }
    const std::vector<std::string> block{"norm1", "qkv", "attention", "proj", "norm2", "mlp"};
    std::vector<std::string> expected{"embed"};
    for (int b = 0; b < 2; ++b) expected.insert(expected.end(), block.begin(), block.end());
    expected.push_back("norm");
    CHECK(names == expected);
    // Past its capacity the clock drops marks instead of writing out of bounds.
    clock.start();
    for (int i = 0; i < 2 * StageClock::capacity; ++i) clock.mark("x");
    CHECK(clock.count() == StageClock::capacity - 1);
  }

  TEST_CASE("Inference after warm-up makes no heap allocation (counting allocator)") {
    ParamSet<float> ps;
    const int N = 40, d = 48, B = 2, K = 23, t = 7;
    Tokenizer tok = Tokenizer::per_taxel(ps, N, 3, 10, d);
    Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = d, .depth = 2, .heads = 3, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
    Predictor pred(ps, PredictorConfig{d, d, 2, 3, 4.0, false, 1e-6});
    AttentiveProbe probe(ps, ProbeConfig{d, 3, 4.0, 32, 3, 1e-6, {}});
    ps.allocate();
    init_params(ps, 1);
    Rng rng(14);
    std::vector<float> x(std::size_t(B) * N * 30), tokens(std::size_t(B) * N * d), z(std::size_t(B) * N * d);
    test::fill_normal(x, rng);
    std::vector<int> ctx(std::size_t(B) * K), tg(std::size_t(2 * B) * t);
    for (std::size_t i = 0; i < ctx.size(); ++i) ctx[i] = int((i * 7) % N);
    for (std::size_t i = 0; i < tg.size(); ++i) tg[i] = int((i * 5 + 3) % N);
    std::vector<float> zc(std::size_t(B) * K * d), out(std::size_t(2 * B) * t * d), y(std::size_t(B) * 3);
    Workspace<float> ws;
    auto run = [&] {
      tok.forward(ps, x.data(), B, tokens.data(), ws);
      // The target encoder, with the reference's drop-path 0.3 (it runs in training mode there).
      enc.forward(ps, {tokens.data(), B}, z.data(), ws, {DropPath{0.3, 5}, nullptr});
      enc.forward(ps, {tokens.data(), B, ctx}, zc.data(), ws);        // context
      pred.forward(ps, {zc.data(), B, K, ps.value(enc.pos_embed()), N, tg.data(), 2 * B, t}, out.data(), ws);
      probe.forward(ps, {z.data(), B, N}, y.data(), ws);
    };
    run();
    const std::vector<float> first = out;
    const long n = count_allocations(run);
#ifdef TJEPA_COUNTS_MALLOC
    MESSAGE("counted operator new and malloc");
#else
    MESSAGE("counted operator new only (malloc belongs to the sanitizer)");
#endif
    CHECK(n == 0);
    CHECK(out == first);
    // The counter is live: a fresh workspace allocates.
    Workspace<float> fresh;
    CHECK(count_allocations([&] { enc.forward(ps, {tokens.data(), B}, z.data(), fresh); }) > 0);
  }
}

