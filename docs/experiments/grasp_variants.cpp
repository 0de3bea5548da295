// Diagnostics of docs/history/evaluation-log.md ("After the first run"): one pre-training seed (0), the
// grasp protocol's data. Build from the repository root and run one mode at a time:
//   g++ -std=c++20 -O2 -march=native -fopenmp -Iinclude -I/usr/include/eigen3 \
//       docs/experiments/grasp_variants.cpp -o /tmp/grasp_variants
//   OMP_NUM_THREADS=1 /tmp/grasp_variants heads               validation curves, random encoder
//   OMP_NUM_THREADS=1 /tmp/grasp_variants jepa standardize    Tactile-JEPA with standardized targets
//   OMP_NUM_THREADS=1 /tmp/grasp_variants pose                sequence head up to 100 epochs, patience 20
#include <tjepa/eval.hpp>
#include <cstdio>
#include <iostream>
using namespace tjepa;
// mode "heads": validation curves of the object probe and the sequence head on a random encoder.
// mode "jepa <variant>": seed 0, 3 heads, Tactile-JEPA row only.
int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "heads";
  GraspEvalConfig c;
  if (mode == "heads") {
    const GraspEvalData d = simulate_grasp_eval_data(c);
    const int N = d.skin.size();
    TrainConfig cfg = c.train;
    auto model = make_jepa_model<float>(cfg, d.skin.graph, 3, 0);
    FrozenFeatures<float> ftr(embed_windows(model->target, model->tokenizer, model->encoder, *d.train, d.train_tasks.windows), N, cfg.dim);
    for (double lr : {1e-3, 3e-3}) {
      SequenceHeadConfig hc; hc.dim = cfg.dim; hc.heads = 3; hc.length = 10; hc.outputs = 3;
      SequenceModel<float> sm(hc, 1);
      HeadTrainConfig h = c.heads.sequence; h.max_epochs = 100; h.patience = 100; h.lr = lr;
      const HeadTrainResult r = train_sequence_head(sm, ftr, d.train_tasks.pose, h);
      std::printf("sequence lr %g best epoch %d\n", lr, r.best_epoch);
      for (std::size_t e = 0; e < r.train_loss.size(); e += 1) std::printf("  seq lr %g epoch %zu train %.4f val %.4f\n", lr, e, r.train_loss[e], r.validation_loss[e]);
      std::fflush(stdout);
    }
    for (int task = 0; task < 2; ++task) {
      const auto& rows = task == 0 ? d.train_tasks.object_rows : d.train_tasks.force_rows;
      const auto& tg = task == 0 ? d.train_tasks.object : d.train_tasks.force;
      RowFeatures f(ftr, rows);
      ProbeHead<float> head(cfg.dim, 3, 0, tg.classes, 7);
      HeadTrainConfig h = c.heads.probe; h.max_epochs = 60; h.patience = 60;
      const HeadTrainResult r = train_head(head, f, tg, h);
      std::printf("probe task %d best epoch %d\n", task, r.best_epoch);
      for (std::size_t e = 0; e < r.train_loss.size(); ++e) std::printf("  probe %d epoch %zu train %.4f val %.4f\n", task, e, r.train_loss[e], r.validation_loss[e]);
      std::fflush(stdout);
    }
    return 0;
  }
  if (mode == "pose") {
    c.seeds = {0};
    c.head_seeds = 1;
    c.end_to_end = c.ablation = false;
    c.heads.sequence.max_epochs = 100;
    c.heads.sequence.patience = 20;
    const GraspEvalResult r = run_grasp_eval(c, [](const std::string& s) { std::cout << s << "\n" << std::flush; });
    std::cout << r.main.markdown() << "\n";
    return 0;
  }
  c.seeds = {0};
  c.ridge = c.random = c.end_to_end = c.mae = c.ablation = false;
  const std::string v = argc > 2 ? argv[2] : "default";
  if (v == "standardize") c.train.standardize_targets = true;
  else if (v == "reference") { c.train.lr = 1e-4; c.train.start_lr = 1e-5; c.train.final_lr = 1e-6; c.train.beta2 = 0.999; c.train.ema_start = 0.994; }
  else if (v != "default") { std::fprintf(stderr, "unknown variant\n"); return 2; }
  const GraspEvalResult r = run_grasp_eval(c, [](const std::string& s) { std::cout << s << "\n" << std::flush; });
  std::cout << r.main.markdown() << "\n" << r.info["pretraining"].dump() << "\n";
}
