// nn suite, modules: gradient checks of every module and of a 2-block encoder and predictor end
// to end, accumulation, and the allocation-free inference path.
// g++ 12 reports a false (maybe-)uninitialized inside its own AVX-512 intrinsics once Eigen's
// double kernels are inlined (GCC bug 105593). The state that counts is the one in force where
// the intrinsics header is first read, so the pragma comes before every include.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "gradcheck.hpp"

using namespace tjepa;
using test::gradient_error;
using test::grad_tolerance;

TEST_SUITE("nn") {
  TEST_CASE("Encoder on a context subset: gradients of tokens and parameters (2 blocks, drop-path)") {
    ParamSet<double> ps;
    EncoderConfig cfg{7, 12, 2, 3, 4.0, true, 1e-6};
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
      enc.forward(ps, tokens.data(), B, ctx.data(), K, out.data(), nullptr, ws, opt);
      return test::dot(w.data(), out.data(), out.size());
    };
    EncoderCache<double> cache;
    std::vector<double> dtokens(tokens.size(), 0.0);
    ps.zero_grad();
    enc.forward(ps, tokens.data(), B, ctx.data(), K, out.data(), &cache, ws, opt);
    CHECK(test::dot(w.data(), out.data(), out.size()) == doctest::Approx(loss()).epsilon(1e-12));
    enc.backward(ps, w.data(), dtokens.data(), cache, ws);
    CHECK(gradient_error(tokens.data(), dtokens.data(), tokens.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
  }

  TEST_CASE("Predictor, tiled targets: gradients of context, position rows and parameters (2 blocks)") {
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
      pred.forward(ps, ctx.data(), Bc, K, pos.data(), N, tg.data(), B, t, out.data(), nullptr, ws);
      return test::dot(w.data(), out.data(), out.size());
    };
    PredictorCache<double> cache;
    std::vector<double> dctx(ctx.size(), 0.0), dpos(pos.size(), 0.0);
    ps.zero_grad();
    pred.forward(ps, ctx.data(), Bc, K, pos.data(), N, tg.data(), B, t, out.data(), &cache, ws);
    pred.backward(ps, w.data(), dctx.data(), dpos.data(), cache, ws);
    CHECK(gradient_error(ctx.data(), dctx.data(), ctx.size(), loss) < grad_tolerance);
    CHECK(gradient_error(pos.data(), dpos.data(), pos.size(), loss) < grad_tolerance);
    test::check_param_gradients(ps, loss);
  }
}
