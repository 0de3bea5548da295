// BYOL's image encoder: torchvision AlexNet's trunk (baselines/alexnet.hpp) on 224 × 224 images of 3
// channels, float, batch 8, at the thread count given as the first argument:
//   BM_AlexNetForward   features only (inference: the frozen BYOL row's embedding)
//   BM_AlexNetTrain     forward and backward without the image's gradient (the online network)
//   BM_ByolStep         one whole BYOL step at the reference's sizes (two views of each window:
//                       online forward and backward, target forward, projector 9216-4096-1024 and
//                       predictor, AdamW, EMA)
// bench/compare_torch.py --only alexnet times the same trunk in PyTorch (nn.Conv2d etc.).
//
// FLOP convention: the convolutions' multiply-adds × 2 (AlexNet::flops: 1.311 GFLOP an image);
// forward + backward = 3 × forward; the BYOL step adds the target's forward and the MLPs' GEMMs.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

#include <tjepa/baselines.hpp>

#include "threads.hpp"

namespace {

using tjepa_bench::Threads;

std::vector<float> random_images(int B, int S, int C, std::uint64_t seed) {
  tjepa::Rng rng(seed);
  std::vector<float> x(static_cast<std::size_t>(B) * S * S * C);
  for (auto& v : x) v = static_cast<float>(rng.normal());
  return x;
}

void alexnet(benchmark::State& state, bool train) {
  const Threads threads(state);
  if (threads.skipped()) return;
  const int B = 8;
  const tjepa::AlexNetConfig c;
  tjepa::ParamSet<float> ps;
  const tjepa::AlexNet net(ps, c);
  ps.allocate();
  tjepa::init_params(ps, 1);
  const auto x = random_images(B, c.image_size, c.in_channels, 2);
  std::vector<float> f(static_cast<std::size_t>(B) * c.out_dim()), df(f.size(), 1e-3f);
  tjepa::AlexNetCache<float> cache;
  net.forward(ps, x.data(), B, f.data(), cache);  // warm-up: the buffers grow once
  if (train) net.backward(ps, df.data(), cache);
  for (auto _ : state) {
    net.forward(ps, x.data(), B, f.data(), cache);
    if (train) net.backward(ps, df.data(), cache);
    benchmark::DoNotOptimize(f.data());
  }
  const double flops = (train ? 3.0 : 1.0) * tjepa::AlexNet::flops(c, B);
  state.counters["GFLOP/s"] = benchmark::Counter(flops / 1e9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["images/s"] = benchmark::Counter(B, benchmark::Counter::kIsIterationInvariantRate);
}
void BM_AlexNetForward(benchmark::State& state) { alexnet(state, false); }
void BM_AlexNetTrain(benchmark::State& state) { alexnet(state, true); }
BENCHMARK(BM_AlexNetForward)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AlexNetTrain)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ByolStep(benchmark::State& state) {
  const Threads threads(state);
  if (threads.skipped()) return;
  const int B = 8;
  tjepa::ByolConfig c;  // the reference's sizes: 224, AlexNet, projection 1024, hidden 4096
  tjepa::ByolModel<float> model(c, 1);
  tjepa::AdamW<float> opt(model.trainable());
  const auto schedule = tjepa::TrainingSchedule::reference(500, 100, 30);
  const auto images = random_images(2 * B, c.image.image_size, c.encoder.in_channels, 3);
  tjepa::ByolWorkspace<float> w;
  std::int64_t s = 0;
  auto step = [&] {
    for (const auto& part : model.trainable()) part.params->zero_grad();
    const double loss = tjepa::byol_forward(model, images.data(), B, w);
    tjepa::byol_backward(model, w);
    return tjepa::byol_update(model, opt, schedule, s++, loss).loss;
  };
  step();
  for (auto _ : state) benchmark::DoNotOptimize(step());
  const double F = c.encoder.out_dim(), H = c.hidden, P = c.projection;
  const double trunk = 2 * B * tjepa::AlexNet::flops(c.encoder, 1);  // the 2B images, forward
  const double mlps = 2.0 * 2 * B * (F * H + H * P + P * H + H * P);  // projector and predictor, forward
  const double target_mlp = 2.0 * 2 * B * (F * H + H * P);
  const double flops = 3 * trunk + trunk + 3 * mlps + target_mlp;
  state.counters["GFLOP/s"] = benchmark::Counter(flops / 1e9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["windows/s"] = benchmark::Counter(B, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ByolStep)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

}  // namespace
