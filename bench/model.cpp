// Benchmarks of the model modules (float): the ViT-Tiny encoder of the paper's Sec. IV-D (12
// blocks, d = 192, 3 heads, MLP 768), inference at the token counts of Sparsh-skin (368) and
// DECO-50 (528), a training-shaped forward+backward, the predictor at training shape, and the
// grouped tokenizer on 2124 taxels.
//
// FLOP convention: GEMMs 2·M·K·N (per block: qkv 6d², proj 2d², fc1 + fc2 16d², so 24·M·d²);
// attention 4·L²·d per sample forward, 3.5× that forward+backward (the attention suite's
// convention); backward GEMMs 2× forward. LayerNorm, GELU and adds are not counted.
// The attentive probe is timed, not counted: its cross-attention folds the shared query into the
// key weights (model/attention.hpp), so its work is a few passes over the tokens, not GEMMs.
// PyTorch's times for the same shapes: bench/compare.sh runs bench/compare_torch.py beside these
// (bench/RESULTS.md).
#include <benchmark/benchmark.h>

#include <vector>

#include <tjepa/core/random.hpp>
#include <tjepa/model/attentive_probe.hpp>
#include <tjepa/model/encoder.hpp>
#include <tjepa/model/init.hpp>
#include <tjepa/model/predictor.hpp>
#include <tjepa/model/tokenizer.hpp>

#include "bf16.hpp"

namespace {

using namespace tjepa;

constexpr int dim = 192, depth = 12, heads = 3;

double encoder_forward_flops(double B, double L, double D = depth) {
  return D * (24.0 * B * L * dim * dim + B * 4.0 * L * L * dim);
}
double encoder_train_flops(double B, double L, double D = depth) {
  return D * (3 * 24.0 * B * L * dim * dim + 3.5 * B * 4.0 * L * L * dim);
}

std::vector<float> random_floats(std::size_t n, std::uint64_t seed) {
  Rng rng(seed);
  std::vector<float> v(n);
  for (auto& x : v) x = float(rng.normal());
  return v;
}

// A ViT-Tiny encoder on L tokens with initialized parameters, and a batch of B token rows.
struct EncoderSetup {
  ParamSet<float> ps;
  Encoder enc;
  std::vector<float> tokens, out;
  Workspace<float> ws;
  EncoderSetup(int B, int L) : enc(ps, EncoderConfig{.num_tokens = L, .dim = dim, .depth = depth, .heads = heads, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6}) {
    ps.allocate();
    init_params(ps, 1);
    tokens = random_floats(std::size_t(B) * L * dim, 2);
    out.resize(tokens.size());
  }
};

// Encoder inference (target-encoder path: all tokens, no cache), batch B, products in the given
// precision (Workspace::precision). The FLOP count is the same for both. frozen: the weights are
// packed for the GEMM once, on the first call, and reused (Workspace::frozen_weights, the
// inference path of a deployed encoder); else every product packs its weight per call, as
// training's target encoder must (its weights change every step).
void encoder_forward(benchmark::State& state, Precision precision, bool frozen = false) {
  const int L = int(state.range(0)), B = int(state.range(1));
  EncoderSetup e(B, L);
  e.ws.precision = precision;
  e.ws.frozen_weights = frozen;
  if (frozen) e.enc.forward(e.ps, {e.tokens.data(), B}, e.out.data(), e.ws);  // packs
  for (auto _ : state) {
    e.enc.forward(e.ps, {e.tokens.data(), B}, e.out.data(), e.ws);
    benchmark::DoNotOptimize(e.out.data());
  }
  state.counters["GFLOP/s"] =
      benchmark::Counter(encoder_forward_flops(B, L) * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}
void BM_EncoderForward(benchmark::State& state) { encoder_forward(state, Precision::fp32); }
BENCHMARK(BM_EncoderForward)->Args({368, 1})->Args({528, 1})->Args({2124, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// The same on frozen weights (packed once): what inference at control-loop rate runs.
void BM_EncoderForwardFrozen(benchmark::State& state) { encoder_forward(state, Precision::fp32, true); }
BENCHMARK(BM_EncoderForwardFrozen)->Args({368, 1})->Args({528, 1})->Args({2124, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// The same with bf16 products (AVX512-BF16, fp32 accumulation): qkv, proj, attention's two
// products and the MLP in bf16; softmax, GELU and norms fp32. The Frozen one is bf16 inference.
void BM_EncoderForwardBf16(benchmark::State& state) {
  if (tjepa_bench::skipped_without_bf16(state, Precision::bf16)) return;
  encoder_forward(state, Precision::bf16);
}
BENCHMARK(BM_EncoderForwardBf16)->Args({368, 1})->Args({528, 1})->Args({2124, 1})->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_EncoderForwardFrozenBf16(benchmark::State& state) {
  if (tjepa_bench::skipped_without_bf16(state, Precision::bf16)) return;
  encoder_forward(state, Precision::bf16, true);
}
BENCHMARK(BM_EncoderForwardFrozenBf16)->Args({368, 1})->Args({528, 1})->Args({2124, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

// Training-shaped encoder: forward with cache and backward to parameters and tokens, batch 8, at
// drop-path rate arg 2 / 10: 0 is PyTorch's comparison model (bench/compare.sh), 3 the reference's
// 0.3 (dropped branches are skipped, so the FLOP count overstates that work by ~30%).
void encoder_forward_backward(benchmark::State& state, Precision precision) {
  const int L = int(state.range(0)), B = int(state.range(1));
  const double rate = double(state.range(2)) / 10.0;
  EncoderSetup e(B, L);
  e.ws.precision = precision;
  auto dout = random_floats(e.tokens.size(), 3);
  std::vector<float> dtokens(e.tokens.size());
  EncoderCache<float> cache;
  std::uint64_t step = 0;
  auto train_step = [&] {
    e.ps.zero_grad();
    e.enc.forward(e.ps, {e.tokens.data(), B}, e.out.data(), cache, e.ws, {DropPath{rate, ++step}, nullptr});
    e.enc.backward(e.ps, dout.data(), dtokens.data(), cache, e.ws);
  };
  train_step();  // warm-up: the cache and workspace grow (and fault in their pages) once
  for (auto _ : state) {
    train_step();
    benchmark::DoNotOptimize(dtokens.data());
  }
  state.counters["GFLOP/s"] =
      benchmark::Counter(encoder_train_flops(B, L) * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}
void BM_EncoderForwardBackward(benchmark::State& state) { encoder_forward_backward(state, Precision::fp32); }
// The same with bf16 products (forward and backward; fp32 master weights and gradients).
void BM_EncoderForwardBackwardBf16(benchmark::State& state) {
  if (tjepa_bench::skipped_without_bf16(state, Precision::bf16)) return;
  encoder_forward_backward(state, Precision::bf16);
}
BENCHMARK(BM_EncoderForwardBackwardBf16)->Args({368, 8, 0})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_EncoderForwardBackward)->Args({368, 8, 0})->Args({368, 8, 3})->Unit(benchmark::kMillisecond)->UseRealTime();

// Predictor at training shape: batch 8, 4 targets tiled (32 rows), context 258 of 368 tokens
// (0.7 N), targets 51 tokens (0.14 N), 4 blocks; forward with cache and backward.
void BM_PredictorForwardBackward(benchmark::State& state) {
  const int N = 368, Bc = 8, R = 4, K = 258, t = 51, B = Bc * R;
  ParamSet<float> ps;
  Predictor pred(ps, PredictorConfig{dim, dim, 4, heads, 4.0, false, 1e-6});
  ps.allocate();
  init_params(ps, 1);
  auto ctx = random_floats(std::size_t(Bc) * K * dim, 2), pos = random_floats(std::size_t(N) * dim, 3);
  auto dout = random_floats(std::size_t(B) * t * dim, 4);
  std::vector<int> tg(std::size_t(B) * t);
  for (std::size_t i = 0; i < tg.size(); ++i) tg[i] = int((i * 37) % N);
  std::vector<float> out(dout.size()), dctx(ctx.size());
  Workspace<float> ws;
  PredictorCache<float> cache;
  auto train_step = [&] {
    ps.zero_grad();
    pred.forward(ps, {ctx.data(), Bc, K, pos.data(), N, tg.data(), B, t}, out.data(), cache, ws);
    pred.backward(ps, dout.data(), dctx.data(), nullptr, cache, ws);
  };
  train_step();  // warm-up, as above
  for (auto _ : state) {
    train_step();
    benchmark::DoNotOptimize(dctx.data());
  }
  state.counters["GFLOP/s"] =
      benchmark::Counter(encoder_train_flops(B, K + t, 4) * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_PredictorForwardBackward)->Unit(benchmark::kMillisecond)->UseRealTime();

// The model work of one JEPA training step on Sparsh-skin shapes, batch 8 (no loss, optimizer
// or masks: those are the training stage's): tokenizer (368 taxels, m·τ = 30) forward+backward,
// target encoder forward on all 368 tokens (drop-path 0.3, no cache), context encoder
// forward+backward on 258 tokens, predictor forward+backward on 4 tiled targets of 51 tokens.
// Compare with PyTorch's train_step/B8/L368 (bench/compare_torch.py, bench/RESULTS.md).
void BM_JepaStepModel(benchmark::State& state) {
  const int N = 368, B = 8, K = 258, t = 51, R = 4, in = 30;
  ParamSet<float> ps, target, pps;
  Tokenizer tok = Tokenizer::per_taxel(ps, N, 3, in / 3, dim);
  Encoder enc(ps, EncoderConfig{.num_tokens = N, .dim = dim, .depth = depth, .heads = heads, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
  Tokenizer::per_taxel(target, N, 3, in / 3, dim);
  Encoder(target, EncoderConfig{.num_tokens = N, .dim = dim, .depth = depth, .heads = heads, .mlp_ratio = 4.0, .bias = true, .eps = 1e-6});
  Predictor pred(pps, PredictorConfig{dim, dim, 4, heads, 4.0, false, 1e-6});
  for (auto* p : {&ps, &target, &pps}) {
    p->allocate();
    init_params(*p, 1);
  }
  auto x = random_floats(std::size_t(B) * N * in, 2), dout = random_floats(std::size_t(B) * R * t * dim, 3);
  std::vector<int> ctx(std::size_t(B) * K), tg(std::size_t(B) * R * t);
  for (std::size_t i = 0; i < ctx.size(); ++i) ctx[i] = int((i * 7) % N);
  for (std::size_t i = 0; i < tg.size(); ++i) tg[i] = int((i * 37) % N);
  std::vector<float> tokens(std::size_t(B) * N * dim), ttokens(tokens.size()), z(tokens.size());
  std::vector<float> zc(std::size_t(B) * K * dim), dzc(zc.size()), dtokens(tokens.size()), out(dout.size());
  Workspace<float> ws;
  TokenizerCache<float> tc;
  EncoderCache<float> ec;
  PredictorCache<float> pc;
  std::uint64_t step = 0;
  auto train_step = [&] {
    ps.zero_grad();
    pps.zero_grad();
    ++step;
    tok.forward(target, x.data(), B, ttokens.data(), ws);
    enc.forward(target, {ttokens.data(), B}, z.data(), ws, {DropPath{0.3, step}, nullptr});
    tok.forward(ps, x.data(), B, tokens.data(), tc, ws);
    enc.forward(ps, {tokens.data(), B, ctx}, zc.data(), ec, ws, {DropPath{0.3, step + (1u << 30)}, nullptr});
    pred.forward(pps, {zc.data(), B, K, target.value(enc.pos_embed()), N, tg.data(), B * R, t}, out.data(), pc, ws);
    std::fill(dzc.begin(), dzc.end(), 0.0f);
    pred.backward(pps, dout.data(), dzc.data(), nullptr, pc, ws);
    std::fill(dtokens.begin(), dtokens.end(), 0.0f);
    enc.backward(ps, dzc.data(), dtokens.data(), ec, ws);
    tok.backward(ps, dtokens.data(), nullptr, tc, ws);
  };
  train_step();  // warm-up, as above
  for (auto _ : state) {
    train_step();
    benchmark::DoNotOptimize(ps.grads().data());
  }
  const double flops = encoder_forward_flops(B, N) + encoder_train_flops(B, K) + encoder_train_flops(B * R, K + t, 4);
  state.counters["GFLOP/s"] = benchmark::Counter(flops * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_JepaStepModel)->Unit(benchmark::kMillisecond)->UseRealTime();

// Grouped tokenizer of DECO-50: 2124 taxels in 528 groups per window (per hand: 252 2×2 groups
// of 4, and the six 3×3 regions split into 4 + 5), τ = 3 frames, m = 1; forward only (arg 0) or
// forward with cache and backward (arg 1), batch B.
void BM_TokenizerGrouped(benchmark::State& state) {
  const bool train = state.range(0) != 0;
  const int B = int(state.range(1)), tau = 3;
  std::vector<int> sizes;
  for (int hand = 0; hand < 2; ++hand) {
    for (int g = 0; g < 252; ++g) sizes.push_back(4);
    for (int r = 0; r < 6; ++r) {
      sizes.push_back(4);
      sizes.push_back(5);
    }
  }
  int taxels = 0;
  for (int s : sizes) taxels += s;
  ParamSet<float> ps;
  Tokenizer tok = Tokenizer::grouped(ps, sizes, tau, dim);
  ps.allocate();
  init_params(ps, 1);
  const int G = tok.num_tokens;
  auto x = random_floats(std::size_t(B) * G * tok.width, 2);
  auto dout = random_floats(std::size_t(B) * G * dim, 3);
  std::vector<float> out(dout.size()), dx(x.size());
  Workspace<float> ws;
  TokenizerCache<float> cache;
  for (auto _ : state) {
    if (train) {
      ps.zero_grad();
      tok.forward(ps, x.data(), B, out.data(), cache, ws);
      tok.backward(ps, dout.data(), dx.data(), cache, ws);
    } else {
      tok.forward(ps, x.data(), B, out.data(), ws);
    }
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["taxels"] = taxels;
  state.counters["GFLOP/s"] = benchmark::Counter((train ? 3.0 : 1.0) * 2.0 * B * taxels * tau * dim * 1e-9,
                                                 benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_TokenizerGrouped)->Args({0, 1})->Args({0, 8})->Args({1, 8})->Unit(benchmark::kMicrosecond)->UseRealTime();

// One training step of the attentive probe (paper, Sec. IV-B: 3 heads; MLP ratio 4, head hidden d)
// on a batch of B windows of L frozen token embeddings, out = 16 classes: forward with cache, then
// backward, to the parameters only (arg 2 = 0: a frozen encoder's probe) or to the tokens too
// (arg 2 = 1: end to end). Counter: windows per second.
void BM_ProbeTrainStep(benchmark::State& state) {
  const int L = int(state.range(0)), B = int(state.range(1));
  const bool to_tokens = state.range(2) != 0;
  ParamSet<float> ps;
  AttentiveProbe probe(ps, ProbeConfig{dim, heads, 4.0, dim, 16, 1e-6, {}});
  ps.allocate();
  init_params(ps, 1);
  const auto x = random_floats(std::size_t(B) * L * dim, 2);
  const auto dy = random_floats(std::size_t(B) * 16, 3);
  std::vector<float> y(dy.size()), dx(x.size());
  Workspace<float> ws;
  ProbeCache<float> cache;
  for (auto _ : state) {
    ps.zero_grad();
    probe.forward(ps, {x.data(), B, L}, y.data(), cache, ws);
    probe.backward(ps, dy.data(), to_tokens ? dx.data() : nullptr, cache, ws);
    benchmark::DoNotOptimize(ps.grad(probe.query));
  }
  state.counters["windows/s"] = benchmark::Counter(double(B), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ProbeTrainStep)->Args({368, 32, 0})->Args({368, 32, 1})->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
