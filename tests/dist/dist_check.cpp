// The data-parallel Trainer over MPI, driven by tests/dist/check.sh under mpirun:
//   tjepa_dist_check --curve FILE [--steps N] [--checkpoint FILE] [--stop-after S] [--resume FILE]
//                    [--fail-rank R --fail-at S]
// A small Tactile-JEPA (d 32, 2 blocks, drop-path 0.3, 2L+2G masks) pre-trains on simulated
// Allegro data with a global batch of 8 split over the ranks. Rank 0 writes the loss of every step
// (17 significant digits) to FILE. At the end every rank checks that all ranks hold bitwise the
// same parameters. --fail-rank R --fail-at S makes rank R throw after step S (the abort path).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <string>

#include <tjepa/dist/mpi.hpp>
#include <tjepa/sim.hpp>

using namespace tjepa;

int main(int argc, char** argv) {
  dist::MpiSession mpi(&argc, &argv);
  return mpi.run_or_abort([&] {
    std::string curve, checkpoint, resume;
    std::int64_t steps = 20, stop_after = -1, fail_at = -1;
    int fail_rank = -1;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      require<ConfigError>(i + 1 < argc, "tjepa_dist_check: ", a, " needs a value");
      const char* v = argv[++i];
      if (a == "--curve") curve = v;
      else if (a == "--steps") steps = std::atoll(v);
      else if (a == "--checkpoint") checkpoint = v;
      else if (a == "--stop-after") stop_after = std::atoll(v);
      else if (a == "--resume") resume = v;
      else if (a == "--fail-rank") fail_rank = std::atoi(v);
      else if (a == "--fail-at") fail_at = std::atoll(v);
      else fail<ConfigError>("tjepa_dist_check: unknown option ", a);
    }
    const Skin skin = layouts::allegro_xela();
    SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 3);
    const Recording baseline = sim.record_baseline(200);
    const Recording rec = sim.record(1200).recording;
    Preprocessor pre(PreprocessConfig::xela_counts());
    pre.fit_baseline(baseline);
    pre.fit(std::span<const Recording>(&rec, 1));
    TrainConfig cfg;
    cfg.model.dim = 32, cfg.model.depth = 2, cfg.model.heads = 2, cfg.model.predictor_depth = 1, cfg.batch = 8, cfg.schedule.steps = steps;
    cfg.schedule.warmup_steps = 4, cfg.step.drop_path = 0.3, cfg.seed = 5;
    const WindowSource source(rec, WindowSpec{cfg.data.tau}, {}, pre);
    auto model = make_jepa_model(cfg, skin.graph, rec.axes(), cfg.seed);
    JepaTrainer<float> trainer(*model, source, skin.graph, cfg);
    trainer.parallel = dist::mpi_data_parallel<float>(mpi.comm());
    trainer.parallel.check_every = 5;  // the fingerprint check in the Trainer runs too
    trainer.checkpoint = checkpoint;
    trainer.checkpoint_every = 1;
    if (!resume.empty()) trainer.resume(resume);
    std::ofstream out;
    if (mpi.rank() == 0 && !curve.empty()) {
      out.open(curve, std::ios::app);
      out << std::setprecision(17);
    }
    trainer.on_step = [&](const JepaStepStats& st) {
      if (out.is_open()) out << st.step << " " << st.loss << " " << st.grad_norm << "\n";
      if (mpi.rank() == fail_rank && st.step == fail_at)
        fail<DataError>("tjepa_dist_check: the planned failure at step ", st.step);
    };
    trainer.run(stop_after < 0 ? -1 : stop_after - trainer.step());
    // Every rank applied the same update: the parameters must be bitwise equal across ranks.
    std::uint64_t h = fingerprint_seed;
    for (const auto& part : model->parts()) h = fingerprint<float>(part.params->values(), h);
    require<NumericError>(trainer.parallel.agree(h), "tjepa_dist_check: the ranks' parameters differ after step ",
                          trainer.step());
    if (mpi.rank() == 0)
      std::printf("%d rank(s): %lld steps, the ranks' parameters are equal\n", mpi.size(),
                  static_cast<long long>(trainer.step()));
    return 0;
  });
}
