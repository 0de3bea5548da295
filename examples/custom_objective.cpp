// An objective of your own through the Trainer (checkpoints, resume, logging, NaN stop): JEPA's
// loss plus a variance term over the batch (VICReg's hinge on each prediction column's std over
// the samples). It needs the whole batch, so it has no all_reduce and is never sharded. Trains,
// stops halfway, resumes from the checkpoint, and checks the curve against an uninterrupted run.
// Usage: tjepa_custom_objective [steps] [checkpoint]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <tjepa/sim.hpp>
using namespace tjepa;

// JEPA + weight · Σ over targets of the mean over their columns of max(0, gamma − std over the batch).
struct VarianceJepa : JepaObjective<float> {
  using JepaObjective::JepaObjective;
  double weight = 0.1, gamma = 1.0, term = 0;
  template <class DP> void all_reduce(const DP&, int, int) = delete;  // needs the whole batch
  double forward(const StepBatch& b) {
    const double loss = JepaObjective::forward(b);
    JepaWorkspace<float>& w = step().workspace();
    const int B = b.size(), d = model().dim();
    term = 0;
    for (std::size_t k = 0; k < w.num_groups; ++k) {  // pred [R·B, t, d]: row r·B + b is target r of sample b
      auto& g = w.groups[k];
      const std::size_t per = static_cast<std::size_t>(g.t) * d;
      for (std::size_t r = 0; r < g.targets.size(); ++r)
        for (std::size_t c = 0; c < per; ++c) {
          const auto at = [&](int s) { return (r * B + s) * per + c; };
          double mean = 0, var = 0;
          for (int s = 0; s < B; ++s) mean += g.pred[at(s)] / B;
          for (int s = 0; s < B; ++s) var += (g.pred[at(s)] - mean) * (g.pred[at(s)] - mean) / B;
          const double sd = std::sqrt(var + 1e-4), hinge = gamma - sd;
          if (hinge <= 0) continue;
          term += hinge / per;
          for (int s = 0; s < B; ++s)  // ∂(−sd)/∂p_s = −(p_s − mean) / (B·sd), into what backward reads
            g.dpred[at(s)] -= static_cast<float>(weight * (g.pred[at(s)] - mean) / (B * sd * per));
        }
    }
    return loss + weight * term;
  }
  JepaStepStats update(std::int64_t s) {
    JepaStepStats st = JepaObjective::update(s);
    st.loss += weight * term;
    return st;
  }
  nlohmann::json metadata() const {  // what a resume must agree with
    nlohmann::json m = JepaObjective::metadata();
    m.update({{"objective", "jepa+variance"}, {"weight", weight}, {"gamma", gamma}});
    return m;
  }
};

int main(int argc, char** argv) {
  const int steps = argc > 1 ? std::atoi(argv[1]) : 12;
  const std::string path = argc > 2 ? argv[2] : "custom_objective.safetensors";
  const Skin skin = layouts::grid_skin();  // a 16 x 12 skin in 4 x 4 pads
  SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 1);
  const Recording rec = sim.record(1000).recording;  // unlabelled windows of 10 frames
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(sim.record_baseline(200));
  pre.fit(std::span<const Recording>(&rec, 1));
  const WindowSource source(rec, WindowSpec{10}, {}, pre);
  TrainConfig cfg;
  cfg.model.dim = 32, cfg.model.depth = 2, cfg.model.heads = 2, cfg.model.predictor_depth = 1, cfg.batch = 8, cfg.schedule.steps = steps;
  cfg.schedule.warmup_steps = steps / 4, cfg.step.drop_path = 0.1;
  auto run = [&](std::uint64_t init, bool resume, std::int64_t max_steps) {
    auto model = make_jepa_model(cfg, skin.graph, rec.axes(), init);
    Trainer<VarianceJepa> trainer(*model, source, skin.graph, cfg);
    trainer.checkpoint = path, trainer.checkpoint_every = steps / 2;
    if (resume) trainer.resume(path);  // everything comes from the file: the init does not matter
    std::vector<double> losses;
    for (const auto& st : trainer.run(max_steps)) losses.push_back(st.loss);
    return losses;
  };
  std::vector<double> straight = run(0, false, -1), head = run(0, false, steps / 2), tail = run(99, true, -1);
  head.insert(head.end(), tail.begin(), tail.end());
  const bool same = head == straight && straight.size() == static_cast<std::size_t>(steps);
  std::printf("loss %.5f -> %.5f; resumed at step %d: %s\n", straight.front(), straight.back(), steps / 2,
              same ? "bitwise the uninterrupted curve" : "DIFFERENT");
  return same ? 0 : 1;
}
