// A trainer of your own: the library's building blocks in your loop, with a loss of your own
// (here a cosine-distance loss). Usage: tjepa_custom_trainer [steps]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <span>

#include <tjepa/sim.hpp>

using namespace tjepa;

// 1 − cos(pred_r, target_r), averaged over the rows, and its gradient.
double cosine_loss(std::span<const float> p, std::span<const float> y, std::size_t rows, int d, std::span<float> dp) {
  double total = 0;
  for (std::size_t r = 0; r < rows; ++r) {
    const float *a = &p[r * d], *b = &y[r * d];
    double ab = 0, aa = 1e-12, bb = 1e-12;
    for (int k = 0; k < d; ++k) ab += a[k] * b[k], aa += a[k] * a[k], bb += b[k] * b[k];
    const double na = std::sqrt(aa), nb = std::sqrt(bb), c = ab / (na * nb);
    total += 1 - c;
    for (int k = 0; k < d; ++k)  // ∂(1 − c)/∂a = −(b / (|a||b|) − c·a / |a|²), over the rows' mean
      dp[r * d + k] = static_cast<float>(-(b[k] / (na * nb) - c * a[k] / aa) / static_cast<double>(rows));
  }
  return total / static_cast<double>(rows);
}

int main(int argc, char** argv) {
  const int steps = argc > 1 ? std::atoi(argv[1]) : 20;
  const Skin skin = layouts::grid_skin();  // a 16 x 12 skin in 4 x 4 pads
  SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 1);
  const Recording baseline = sim.record_baseline(200);
  const Recording rec = sim.record(2000).recording;
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(baseline);
  pre.fit(std::span<const Recording>(&rec, 1));
  TrainConfig cfg;
  cfg.model.dim = 32, cfg.model.depth = 2, cfg.model.heads = 2, cfg.model.predictor_depth = 1, cfg.batch = 8, cfg.schedule.steps = steps;
  cfg.schedule.warmup_steps = steps / 10;
  const WindowSource source(rec, WindowSpec{cfg.data.tau}, {}, pre);
  auto model = make_jepa_model(cfg, skin.graph, rec.axes(), cfg.seed);
  const MaskCollator collator(skin.graph, cfg.masks);
  JepaStep<float> step(*model, cfg.step, cosine_loss);
  AdamW<float> opt(model->trainable(), cfg.adamw);
  const TrainingSchedule schedule = cfg.schedule.build();
  WindowBatch batch;
  AlignedVector<float> x;
  for (std::int64_t s = 0; s < cfg.schedule.steps; ++s) {
    const auto order = source.epoch_order(cfg.seed, static_cast<std::uint64_t>(s));  // one batch per "epoch"
    source.gather(std::span<const std::int64_t>(order).first(static_cast<std::size_t>(cfg.batch)), batch);
    windows_to_tokens(batch, x);
    const MaskBatch masks = collator.sample(cfg.batch, cfg.seed, static_cast<std::uint64_t>(s));
    step.zero_grad();
    const double loss = step.forward(x.data(), cfg.batch, masks, static_cast<std::uint64_t>(s)).loss;
    step.backward();
    const JepaStepStats st = step.update(opt, schedule, s);
    std::printf("step %lld loss %.5f grad_norm %.4f\n", static_cast<long long>(s), loss, st.grad_norm);
  }
  return 0;
}
