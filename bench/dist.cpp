// Data-parallel JEPA step at the reference scale over MPI (not a Google Benchmark: it runs under
// mpirun). ViT-Tiny (d 192, 12 blocks, 3 heads), predictor 4 blocks, N 368 taxels, m·τ 30, 2L+2G
// masks, drop-path 0.3; a global batch of B windows (default 8) split over the ranks.
//   OMP_NUM_THREADS=2 mpirun -np 1 build/release/bench/tjepa_bench_dist [B] [steps]
//   OMP_NUM_THREADS=1 mpirun -np 2 --bind-to core build/release/bench/tjepa_bench_dist [B] [steps]
// Prints windows/s of the whole step (forward, backward, allreduce, clip, AdamW, EMA), the
// allreduce's time and share of the step, and the gradient bytes summed per step.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <tjepa/dist/mpi.hpp>
#include <tjepa/tjepa.hpp>

int main(int argc, char** argv) {
  using namespace tjepa;
  dist::MpiSession mpi(&argc, &argv);
  return mpi.run_or_abort([&] {
    const int B = argc > 1 ? std::atoi(argv[1]) : 8;
    const int steps = argc > 2 ? std::atoi(argv[2]) : 5;
    const auto skin = layouts::allegro_xela();
    const MaskCollator collator(skin.graph);
    const int N = collator.num_tokens();
    JepaModel<float> model(JepaConfig::reference(N, 30, 3), 1);
    AdamW<float> opt(model.trainable());
    const auto schedule = TrainingSchedule::reference(500, 100, 30);
    JepaStep<float> step(model, JepaStepConfig{.drop_path = 0.3});  // drop-path 0.3, as the reference
    const DataParallel<float> dp = dist::mpi_data_parallel<float>(mpi.comm());
    const Shard shard = dp.shard(B);
    Rng rng(2);
    std::vector<float> x(static_cast<std::size_t>(shard.count) * N * 30);
    for (auto& v : x) v = static_cast<float>(rng.normal());
    MaskBatch masks, mine;
    using clock = std::chrono::steady_clock;
    double total = 0, reduce = 0;
    std::size_t grad_values = 0;
    for (const auto& p : model.trainable()) grad_values += p.params->grads().size();
    for (int s = -1; s < steps; ++s) {  // s = -1: warm-up, not timed
      collator.sample_into(masks, B, 3, static_cast<std::uint64_t>(s + 1));
      masks.slice_into(mine, shard.first, shard.count);
      MPI_Barrier(mpi.comm());
      const auto t0 = clock::now();
      step.zero_grad();
      step.forward(x.data(), shard.count, mine, static_cast<std::uint64_t>(s + 1), static_cast<std::uint64_t>(shard.first));
      step.backward();
      const auto t1 = clock::now();
      if (dp.active()) step.all_reduce(dp, shard.count, B);
      const auto t2 = clock::now();
      step.update(opt, schedule, s + 1);
      MPI_Barrier(mpi.comm());
      const auto t3 = clock::now();
      if (s >= 0) {
        total += std::chrono::duration<double>(t3 - t0).count();
        reduce += std::chrono::duration<double>(t2 - t1).count();
      }
    }
    double times[2] = {total, reduce};
    MPI_Allreduce(MPI_IN_PLACE, times, 2, MPI_DOUBLE, MPI_MAX, mpi.comm());
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    if (mpi.rank() == 0)
      std::printf("%d rank(s) x %d thread(s), global batch %d: %.1f ms per step, %.2f windows/s; allreduce %.2f ms "
                  "(%.2f %% of the step) of %zu gradient values (%.1f MB)\n",
                  mpi.size(), threads, B, 1e3 * times[0] / steps, B * steps / times[0], 1e3 * times[1] / steps,
                  100 * times[1] / times[0], grad_values, grad_values * 4 / 1e6);
    return 0;
  });
}
