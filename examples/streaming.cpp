// Streaming inference: the library's Pipeline (downstream/pipeline.hpp) called at control-loop
// rate on the frames of the 368-taxel Allegro hand, the frozen encoder and a head on top: a trained
// one (--head, from `tjepa probe --task ... --save`, refused if it was trained on another encoder)
// or an untrained force (3) and indenter probe of the same cost.
//
// Each tick: one new frame [N, m] → Pipeline::push: drift removed → preprocessed → into the ring of
// the last τ frames → window [N, m·τ] → tokenizer → encoder (all N tokens) → head. Every buffer is
// made before the loop and the workspaces stop growing after the first window, so the steady
// state allocates nothing: every malloc of the process is counted (apps/common/allocation_counter)
// and the example checks it.
//
//   streaming [--checkpoint runs/demo/checkpoint.safetensors | --reference-size] [--head head.safetensors] [--ticks 2000] [--rate 100] [--spin]
//             [--threads 2] [--realtime] [--stages] [--controls] [--memory-kib 1024 4096] [--repack] [--precision bf16]
// Prints latency p50 / p99 / max per tick and the allocations after warm-up. --stages times each
// stage of every tick (StageClock) and says where the slowest ticks lose their time. --controls
// then times fixed loops of the median tick's length the same way: FMAs in registers (what
// the clock and the scheduler alone give) and read-modify-write sweeps over buffers of 1 MiB and
// 4 MiB (--memory-kib; the encoder's working set is about 2.5 MiB, this machine's L2 2 MiB): what
// the memory system alone gives. A p99/p50 no better than theirs is
// the machine's, not the encoder's. Ticks during which the thread was preempted (an involuntary
// context switch) are counted, and p50 / p99 are also given without them: on a shared machine the
// scheduler alone can set the p99. --realtime (SCHED_FIFO) is how a control loop avoids that;
// back to back it runs into the kernel's RT throttling (50 ms per second by default), so use it with
// --rate.
//
// --threads T runs each window on T OpenMP threads (default 1): at batch 1 the library splits the
// rows of every product and attention's heads × query chunks over them. The team is made in the
// warm-up ticks and reused (no allocation in steady state, counted with malloc interposed), and
// under --realtime its threads inherit SCHED_FIFO from the loop's thread, which sets it first.
#include <CLI/CLI.hpp>
#include <sched.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#ifdef _OPENMP
#include <omp.h>
#endif
#include <vector>

#include <allocation_counter.hpp>
#include <tjepa/downstream/pipeline.hpp>
#include <tjepa/downstream/probe_labels.hpp>
#include <tjepa/kernels/peaks.hpp>
#include <tjepa/sim.hpp>

namespace {
using Clock = std::chrono::steady_clock;

// Latency of each timed tick, and whether the thread was preempted during it (an involuntary
// context switch: the scheduler's jitter, not the tick's own).
struct Timings {
  std::vector<double> us;
  std::vector<char> preempted;
};

long involuntary_switches() {
  rusage u{};
  getrusage(RUSAGE_THREAD, &u);
  return u.ru_nivcsw;
}

// Runs tick(k) for k < warmup + ticks at `rate` Hz (0: back to back), sleeping or busy-waiting
// (spin) until each next tick. on_warm() runs once, right before the first timed tick.
template <class Tick, class OnWarm>
Timings timed_loop(int warmup, int ticks, double rate, bool spin, Tick&& tick, OnWarm&& on_warm) {
  Timings t;
  t.us.reserve(static_cast<std::size_t>(ticks));
  t.preempted.reserve(static_cast<std::size_t>(ticks));
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(rate > 0 ? 1.0 / rate : 0.0));
  auto next = Clock::now();
  for (int k = 0; k < warmup + ticks; ++k) {
    if (k == warmup) on_warm();
    const long switches = involuntary_switches();
    const auto t0 = Clock::now();
    tick(k);
    const auto t1 = Clock::now();
    if (k >= warmup) {
      t.us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      t.preempted.push_back(involuntary_switches() != switches);
    }
    if (rate > 0) {
      next += period;
      if (spin)
        while (Clock::now() < next) {
        }
      else
        std::this_thread::sleep_until(next);
    }
  }
  return t;
}

// Value at quantile p of sorted values.
double quantile(const std::vector<double>& sorted, double p) {
  return sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(p * static_cast<double>(sorted.size())))];
}

// p50 / p99 of the ticks the scheduler left alone.
void print_unpreempted(const Timings& t) {
  std::vector<double> alone;
  for (std::size_t i = 0; i < t.us.size(); ++i)
    if (!t.preempted[i]) alone.push_back(t.us[i]);
  if (alone.empty()) return;
  std::sort(alone.begin(), alone.end());
  const double p50 = quantile(alone, 0.5), p99 = quantile(alone, 0.99);
  std::printf("  %zu of %zu ticks preempted; the others: p50 %.0f us, p99 %.0f us, p99/p50 %.3f\n",
              t.us.size() - alone.size(), t.us.size(), p50, p99, p99 / p50);
}

// p50 / p99 / max of all ticks, then of the unpreempted ones.
void print_latency(const char* what, const Timings& t) {
  std::vector<double> all = t.us;
  std::sort(all.begin(), all.end());
  const double p50 = quantile(all, 0.5), p99 = quantile(all, 0.99);
  std::printf("%s: p50 %.0f us, p99 %.0f us, max %.0f us, p99/p50 %.3f\n", what, p50, p99, all.back(), p99 / p50);
  print_unpreempted(t);
}

// Per stage name (summed over the blocks of a tick): median time, p99, and how much longer the
// stage took in the slowest 1% of ticks than in the ticks around the median — where the tail lives.
void print_stages(const std::vector<double>& latency_us, const std::vector<std::vector<std::pair<const char*, double>>>& stages) {
  std::vector<std::size_t> order(latency_us.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return latency_us[a] < latency_us[b]; });
  const std::size_t n = order.size(), tail = std::max<std::size_t>(1, n / 100);
  std::vector<std::string> names;
  std::map<std::string, std::vector<double>> per_tick;  // stage → µs per tick
  for (std::size_t t = 0; t < n; ++t)
    for (const auto& [name, us] : stages[t]) {
      auto& v = per_tick[name];
      if (v.empty()) {
        v.assign(n, 0.0);
        names.emplace_back(name);
      }
      v[t] += us;
    }
  std::printf("%-10s %9s %9s %8s %22s\n", "stage", "p50 us", "p99 us", "p99/p50", "slowest 1% vs median");
  for (const auto& name : names) {
    const std::vector<double>& v = per_tick.at(name);
    double slow = 0, mid = 0;
    for (std::size_t i = 0; i < tail; ++i) {
      slow += v[order[n - 1 - i]];
      mid += v[order[std::min(n - 1, n / 2 - tail / 2 + i)]];
    }
    std::vector<double> sorted = v;
    std::sort(sorted.begin(), sorted.end());
    const double p50 = quantile(sorted, 0.5), p99 = quantile(sorted, 0.99);
    std::printf("%-10s %9.1f %9.1f %8.3f %+15.1f us/tick\n", name.c_str(), p50, p99, p99 / p50, (slow - mid) / double(tail));
  }
}

// The controls: each runs `reps` times a fixed amount of work; calibrate() finds the reps that
// take about `us` µs.
struct FmaControl {
  float operator()(int reps) const {
    using V = xsimd::batch<float>;
    V a[8];
    for (int i = 0; i < 8; ++i) a[i] = V(1.0f + 1e-3f * float(i));
    volatile float mv = 0.9999999f, cv = 1e-7f;  // opaque: else g++ folds the loop away
    const V m(mv), c(cv);
    for (int r = 0; r < reps; ++r)
      for (int i = 0; i < 8; ++i) a[i] = xsimd::fma(a[i], m, c);
    float s = 0;
    for (int i = 0; i < 8; ++i) s += xsimd::hadd(a[i]);
    return s;
  }
};
struct MemoryControl {
  explicit MemoryControl(int kib) : buffer((std::size_t(kib) << 10) / sizeof(float), 1.0f) {}
  tjepa::AlignedVector<float> buffer;
  float operator()(int reps) {
    using V = xsimd::batch<float>;
    V acc(0.0f);
    const V one(1.0f);
    for (int r = 0; r < reps; ++r)
      for (std::size_t i = 0; i < buffer.size(); i += V::size) {
        const V v = V::load_aligned(buffer.data() + i);
        acc += v;
        (v * one).store_aligned(buffer.data() + i);
      }
    return xsimd::hadd(acc);
  }
};
template <class Control>
int calibrate(Control& control, double us) {
  volatile float sink = 0;
  int reps = 1;
  for (;;) {
    const auto t0 = Clock::now();
    sink = sink + control(reps);
    const double took = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    if (took > us / 4 || reps > (1 << 28)) return std::max(1, static_cast<int>(reps * us / took));
    reps *= 2;
  }
}

}  // namespace

int main(int argc, char** argv) {
  using namespace tjepa;
  CLI::App app{"Streaming inference of a frozen Tactile-JEPA encoder over a ring buffer of frames"};
  std::string checkpoint, head_file;
  int ticks = 2000, warmup = 20, threads = 1;
  double rate = 0;
  bool spin = false, stages = false, controls = false, repack = false, realtime = false, reference_size = false;
  std::vector<int> memory_kib{1024, 4096};
  app.add_option("--checkpoint", checkpoint, "checkpoint of `tjepa pretrain`/`tjepa demo` (default: random weights, demo size)");
  app.add_option("--head", head_file, "head of `tjepa probe --task ... --save` (default: an untrained force and indenter probe)");
  app.add_option("--ticks", ticks, "control-loop ticks to time")->capture_default_str();
  app.add_option("--warmup", warmup, "ticks before timing and allocation counting")->capture_default_str();
  app.add_option("--threads", threads, "OpenMP threads that run each window (batch 1: rows of each product, heads of attention)")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  app.add_option("--rate", rate, "control-loop rate in Hz (0: back to back)")->capture_default_str();
  app.add_flag("--reference-size", reference_size,
               "random weights of the reference's size (d 192, 12 blocks) instead of the demo's (d 96, 4 blocks)");
  app.add_flag("--spin", spin, "busy-wait between ticks instead of sleeping (with --rate)");
  app.add_flag("--realtime", realtime,
               "run under SCHED_FIFO (priority 10), as a control loop would: other threads no longer preempt it");
  std::string precision = "fp32";
  app.add_option("--precision", precision, "arithmetic of the encoder's products (the probe's are fp32)")
      ->check(CLI::IsMember({"fp32", "bf16"}))
      ->capture_default_str();
  app.add_flag("--repack", repack, "pack the weights for the GEMM on every call, as training does (A/B of frozen weights)");
  app.add_flag("--stages", stages, "time each stage of every tick and show where the slowest ticks lose time");
  app.add_flag("--controls", controls, "then time an FMA loop and a memory sweep of the median tick's length the same way");
  app.add_option("--memory-kib", memory_kib,
                 "the memory controls' buffers in KiB, one sweep control each (1024 fits this machine's 2 MiB L2, 4096 does not)")
      ->check(CLI::Range(64, 1 << 20));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "streaming: error: %s\n", e.what());
    return 2;
  }
  try {
    if (realtime) {
      const sched_param param{10};
      if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) {
        std::fprintf(stderr, "streaming: error: SCHED_FIFO refused (%s): needs CAP_SYS_NICE or an rtprio limit\n",
                     std::strerror(errno));
        return 1;
      }
    }
#ifdef _OPENMP
    omp_set_num_threads(threads);
#else
    require<ConfigError>(threads == 1, "--threads ", threads, ": this build has no OpenMP, so one thread only");
#endif
    require<ConfigError>(ticks > 0 && warmup >= 1, "--ticks ", ticks, ", --warmup ", warmup, ", expected > 0");
    const Skin skin = layouts::allegro_xela();
    // The sensor: a simulated recording played back frame by frame.
    SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, 7);
    const int N = skin.size(), m = sim.axes();
    const Recording baseline = sim.record_baseline(300);
    const SimRecording stream = sim.record(std::max(ticks + warmup, 1000));
    // The model: a checkpoint with its data statistics, or random weights of the demo size with
    // statistics fitted here (Xela counts: drop-outs, the rest readings subtracted, per-axis scales).
    TrainedModel tm;
    if (!checkpoint.empty()) {
      tm = load_trained_model(checkpoint);
    } else {
      if (reference_size) tm.config = TrainConfig::reference(1);
      tm.model = std::make_unique<JepaModel<float>>(tm.config.model_config(N, m), 0);
      Preprocessor p(PreprocessConfig::xela_counts());
      p.fit_baseline(baseline);
      p.fit(std::span<const Recording>(&stream.recording, 1));
      tm.pre = std::move(p);
      tm.drift = DriftTracker(DriftTrackerConfig::magnetic());
      tm.drift->fit(baseline);
    }
    const int d = tm.model->dim(), tau = tm.config.data.tau;
    // The head: a trained one (`tjepa probe --task ... --save`, checked against the encoder), or
    // an untrained force (3) and indenter probe of the same cost.
    std::optional<LoadedProbeHead<float>> head;
    if (!head_file.empty()) {
      head = load_probe_head<float>(head_file);
    } else {
      HeadInfo info;
      info.task = "force and indenter (untrained)";
      for (int c = 0; c < num_indenter_shapes; ++c) info.class_names.push_back("indenter " + std::to_string(c));
      info.tau = tau;
      info.stride = 1;
      head = LoadedProbeHead<float>{ProbeHead<float>(d, tm.model->config.encoder.heads, force_axes, num_indenter_shapes, 1),
                                    std::move(info)};
    }
    StageClock clock;
    // Every buffer is made here; the pipeline's workspaces stop growing on the first window.
    Pipeline pipe(std::move(tm), std::move(head),
                  PipelineConfig{.column = {},
                                 .stride = 1,
                                 .target_encoder = true,
                                 .precision = precision == "bf16" ? Precision::bf16 : Precision::fp32,
                                 .frozen_weights = !repack,
                                 .clock = stages ? &clock : nullptr});
    require<ShapeError>(pipe.taxels() == N && pipe.axes() == m, "the checkpoint expects ", pipe.taxels(),
                        " taxels of ", pipe.axes(), " axes, the hand has ", N, " of ", m);
    std::vector<std::vector<std::pair<const char*, double>>> stage_us;  // [tick] (stage, µs), made before the loop
    if (stages) {
      stage_us.resize(static_cast<std::size_t>(ticks));
      for (auto& v : stage_us) {  // touched now: no page faults while timing
        v.resize(StageClock::capacity);
        v.clear();
      }
    }
    rusage usage_before{};  // page faults and preemptions: jitter the allocation count does not show
    double checksum = 0;
    const std::size_t per = static_cast<std::size_t>(N) * m;
    auto tick = [&](int k) {
      clock.start();
      const PipelineOutput* y = pipe.push({stream.recording.frame(k % stream.recording.frames()), per});
      if (y) checksum += y->outputs[0];
      if (stages && k >= warmup) {
        auto& v = stage_us[static_cast<std::size_t>(k - warmup)];
        for (int i = 0; i < clock.count(); ++i) v.emplace_back(clock.name(i), 1e-3 * double(clock.elapsed_ns(i)));
      }
    };
    const Timings timings = timed_loop(warmup, ticks, rate, spin, tick, [&] {
      alloc::start();
      getrusage(RUSAGE_SELF, &usage_before);
    });
    const long long steady_allocations = alloc::stop();
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    std::vector<double> sorted = timings.us;
    std::sort(sorted.begin(), sorted.end());
    auto pct = [&](double p) { return quantile(sorted, p); };
    const JepaConfig& mc = pipe.model().model->config;
    std::string bf16_note;  // where bf16 is not the faster choice on this build and core, why
    if (precision == "bf16")
      if (const std::string why = bf16_slower_reason(measure_product_peaks()); !why.empty()) bf16_note = " (" + why + ")";
    std::printf("streaming: %d taxels x %d axes, window of %d frames, encoder d=%d, %d blocks, %d heads%s, %s products%s\n",
                N, m, tau, d, mc.encoder.depth, mc.encoder.heads, checkpoint.empty() ? " (random weights)" : "",
 precision.c_str(), bf16_note.c_str());
    std::printf("head: %s\n", pipe.head()->info.task.c_str());
    std::printf("%d ticks after %d warm-up ticks, %d thread%s%s%s\n", ticks, warmup, threads, threads > 1 ? "s" : "",
                rate > 0 ? (spin ? ", busy-waiting between ticks" : ", sleeping between ticks") : ", back to back",
                realtime ? ", SCHED_FIFO" : "");
    std::printf("latency per tick: p50 %.0f us, p99 %.0f us, max %.0f us (%.0f Hz sustainable at p99), p99/p50 %.3f\n",
                pct(0.5), pct(0.99), sorted.back(), 1e6 / pct(0.99), pct(0.99) / pct(0.5));
    print_unpreempted(timings);
    std::printf("allocations in steady state: %lld (checksum %.3f)\n", steady_allocations, checksum);
    std::printf("in steady state: %ld page faults, %ld involuntary context switches\n",
                (usage.ru_minflt - usage_before.ru_minflt) + (usage.ru_majflt - usage_before.ru_majflt),
                usage.ru_nivcsw - usage_before.ru_nivcsw);
    if (stages) print_stages(timings.us, stage_us);
    if (controls) {
      volatile float sink = 0;
      FmaControl fma;
      const int fma_reps = calibrate(fma, pct(0.5));
      print_latency("control, FMAs in registers",
                    timed_loop(warmup, ticks, rate, spin, [&](int) { sink = sink + fma(fma_reps); }, [] {}));
      for (const int kib : memory_kib) {
        MemoryControl memory(kib);
        const int memory_reps = calibrate(memory, pct(0.5));
        const std::string name = "control, " + std::to_string(kib) + " KiB memory sweeps";
        print_latency(name.c_str(),
                      timed_loop(warmup, ticks, rate, spin, [&](int) { sink = sink + memory(memory_reps); }, [] {}));
      }
    }
    return steady_allocations == 0 ? 0 : 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "streaming: error: %s\n", e.what());
    return 1;
  }
}
