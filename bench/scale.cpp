// The JEPA step phase by phase on 1, 2, ... threads (bench/scale.sh): where its time goes and
// which phases leave cores idle. Each phase is timed by the step's own StageClock marks
// (JepaWorkspace::clock) and, within a phase, each block stage by the modules' own marks
// (Workspace::clock: norm1, qkv, attention, ..., mlp backward, ...; summed over the blocks); mask
// sampling, which the trainer runs before each step on the calling thread, is timed on its own.
// Thread counts take turns repetition by repetition, so that a slow spell of the machine falls on
// all of them alike. Prints one JSON object per line:
//   {"skin", "precision", "threads", "phase", "ms" (median over repetitions), "calls"} per phase,
//   {..., "phase", "stage", "ms", "calls"} per stage of a phase,
//   {"skin", "precision", "threads", "phase": "step", "ms", "gflops", "paired_speedup" (the median
//   over repetitions of the first thread count's step over this count's in the same repetition),
//   "paired_speedup_quartiles", ...} the whole step.
//   tjepa_scale [--skin allegro|deco] [--precision fp32|bf16] [--threads 1,2] [--reps 9]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <nlohmann/json.hpp>
#include <tjepa/tjepa.hpp>

#include "jepa_setup.hpp"

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::vector<int> parse_threads(const std::string& s) {
  std::vector<int> out;
  std::size_t p = 0;
  while (p <= s.size()) {
    const std::size_t q = std::min(s.find(',', p), s.size());
    const int t = std::stoi(s.substr(p, q - p));
    tjepa::require<tjepa::ConfigError>(t >= 1, "--threads: ", t, ", expected >= 1");
    out.push_back(t);
    p = q + 1;
  }
  return out;
}

// The marks JepaStep makes at the end of each phase (JepaWorkspace::clock); every other mark is a
// stage of the phase that ends next.
bool is_phase(const std::string& name) {
  static const char* const phases[] = {"zero_grad",         "target tokenizer",   "target encoder",
                                       "target statistics", "context tokenizer",  "context encoder",
                                       "predictor forward", "loss",               "predictor backward",
                                       "context encoder backward", "tokenizer backward", "clip",
                                       "AdamW",             "EMA"};
  return std::find(std::begin(phases), std::end(phases), name) != std::end(phases);
}

int run(int argc, char** argv) {
  std::string skin = "allegro", precision = "fp32", threads_arg = "1,2";
  int reps = 9;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      tjepa::require<tjepa::ConfigError>(i + 1 < argc, a, " needs a value");
      return argv[++i];
    };
    if (a == "--skin") skin = value();
    else if (a == "--precision") precision = value();
    else if (a == "--threads") threads_arg = value();
    else if (a == "--reps") reps = std::stoi(value());
    else tjepa::fail<tjepa::ConfigError>("unknown argument ", a, " (--skin, --precision, --threads, --reps)");
  }
  tjepa::require<tjepa::ConfigError>(reps >= 1, "--reps: ", reps, ", expected >= 1");
  tjepa::require<tjepa::ConfigError>(precision == "fp32" || precision == "bf16", "--precision ", precision,
                                     ", expected fp32 or bf16");
  const tjepa::Precision p = precision == "bf16" ? tjepa::Precision::bf16 : tjepa::Precision::fp32;
  if (p == tjepa::Precision::bf16 && !tjepa::has_native_bf16())
    tjepa::fail<tjepa::ConfigError>("--precision bf16: built without AVX512-BF16 (bf16 would run fp32)");
  const std::vector<int> threads = parse_threads(threads_arg);
#ifndef _OPENMP
  for (int t : threads) tjepa::require<tjepa::ConfigError>(t == 1, "built without OpenMP: --threads 1 only");
#endif

  const auto setup = tjepa_bench::jepa_setup(skin);
  const int B = setup.B;
  tjepa_bench::JepaRun run(setup, p);  // the step's masks: bench/train.cpp's
  const int N = run.N;
  const tjepa::MaskBatch& masks = run.masks;
  tjepa::MaskBatch drawn;  // what the timed sampling draws into
  tjepa::StageClock clock;
  const double flops = tjepa_bench::jepa_step_flops(setup.config, masks, N);

  // per thread count: phase → one total per repetition (a phase marked twice in a step, as the
  // predictor's per target group, is summed); calls per step.
  std::map<int, std::map<std::string, std::vector<double>>> ms;
  std::map<std::string, int> calls;
  std::vector<std::string> order;  // phases in the order the step reaches them
  std::int64_t s = 0;
  for (int rep = -1; rep < reps; ++rep) {  // rep -1: warm-up, the workspace grows
    for (int t : threads) {
#ifdef _OPENMP
      omp_set_num_threads(t);
      // Wake the team before the clock starts (the barrier: an empty region does not wait for it).
      // A trainer's threads come to each step warm from the last one; here the other thread
      // counts' turn leaves them asleep for a whole step, and on a VM waking them costs the first
      // parallel region milliseconds (5-20 ms on the first region, mask sampling's, on a 2-vCPU
      // Zen 5 VM: a hypervisor's wake-up, not the step's work).
#pragma omp parallel
      {
#pragma omp barrier
      }
#endif
      using clk = std::chrono::steady_clock;
      const auto t0 = clk::now();
      run.collator.sample_into(drawn, B, 3, static_cast<std::uint64_t>(s));
      const double sampling = std::chrono::duration<double, std::milli>(clk::now() - t0).count();
      tjepa::JepaStep<float>& step = run.step;
      step.workspace().clock = &clock;
      step.workspace().ws.clock = &clock;
      clock.start();
      const auto t1 = clk::now();
      const auto st = step.train(run.opt, run.schedule, s, setup.x.data(), B, masks, static_cast<std::uint64_t>(s));
      const double total = std::chrono::duration<double, std::milli>(clk::now() - t1).count();
      step.workspace().clock = nullptr;
      step.workspace().ws.clock = nullptr;
      ++s;
      if (rep < 0) continue;
      tjepa::require<tjepa::NumericError>(std::isfinite(st.loss), "step ", s, ": loss ", st.loss);
      tjepa::require<tjepa::ConfigError>(clock.count() < tjepa::StageClock::capacity - 1, "a step made more than ",
                                         tjepa::StageClock::capacity, " marks: the clock dropped some");
      // A phase's time is the sum of its stages and its own mark's; keys "phase" and "phase/stage".
      std::map<std::string, double> sum;
      std::map<std::string, int> count;
      std::vector<std::pair<std::string, double>> pending;  // stages of the phase not yet ended
      for (int i = 0; i < clock.count(); ++i) {
        const std::string name = clock.name(i);
        const double stage_ms = static_cast<double>(clock.elapsed_ns(i)) * 1e-6;
        if (!is_phase(name)) {
          pending.emplace_back(name, stage_ms);
          continue;
        }
        double phase_ms = stage_ms;
        for (const auto& [stage, ms_of_stage] : pending) {
          const std::string key = name + "/" + stage;
          if (!sum.count(key) && std::find(order.begin(), order.end(), key) == order.end()) order.push_back(key);
          sum[key] += ms_of_stage;
          ++count[key];
          phase_ms += ms_of_stage;
        }
        pending.clear();
        if (!sum.count(name) && std::find(order.begin(), order.end(), name) == order.end()) order.push_back(name);
        sum[name] += phase_ms;
        ++count[name];
      }
      for (auto& [name, v] : sum) ms[t][name].push_back(v);
      for (auto& [name, c] : count) calls[name] = c;
      ms[t]["mask sampling"].push_back(sampling);
      ms[t]["step"].push_back(total);
    }
  }
  order.insert(order.begin(), "mask sampling");
  const std::string label = tjepa_bench::masks_label(masks, N);
  for (int t : threads) {
    for (const auto& key : order) {
      const std::size_t slash = key.find('/');
      nlohmann::json line{{"skin", skin}, {"precision", precision}, {"threads", t}, {"phase", key.substr(0, slash)},
                          {"ms", median(ms[t][key])}, {"calls", key == "mask sampling" ? 1 : calls[key]}};
      if (slash != std::string::npos) line["stage"] = key.substr(slash + 1);
      std::cout << line.dump() << '\n';
    }
    const double step_ms = median(ms[t]["step"]);
    // The speed-up over the first count, repetition by repetition: the two steps of one repetition
    // run a second apart, so a slow spell of the VM longer than that falls on both and cancels
    // (the 1-thread step's median moved by 20 % between back-to-back runs on a 2-vCPU Zen 5).
    const std::vector<double>& first = ms[threads.front()]["step"];
    std::vector<double> paired;
    for (std::size_t i = 0; i < first.size(); ++i) paired.push_back(first[i] / ms[t]["step"][i]);
    std::sort(paired.begin(), paired.end());
    const auto quartile = [&](double q) { return paired[std::size_t(q * double(paired.size() - 1) + 0.5)]; };
    std::cout << nlohmann::json{{"skin", skin},
                                {"precision", precision},
                                {"threads", t},
                                {"phase", "step"},
                                {"ms", step_ms},
                                {"gflops", flops / (step_ms * 1e6)},
                                {"paired_speedup", median(paired)},
                                {"paired_speedup_quartiles", {quartile(0.25), quartile(0.75)}},
                                {"masks", label},
                                {"reps", reps}}
                     .dump()
              << std::endl;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "tjepa_scale: " << e.what() << '\n';
    return 2;
  }
}
