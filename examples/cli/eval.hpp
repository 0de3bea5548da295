#pragma once
// tjepa eval and tjepa demo: the downstream protocol on the simulated grasping hand
// (eval/grasp_eval.hpp), printed and written as results.md, results.json, results.svg.
#include <chrono>
#include <filesystem>
#include <iostream>
#include <string>

#include <tjepa/eval.hpp>

#include "output.hpp"

namespace tjepa::cli {

struct EvalOptions {
  GraspEvalConfig eval;
  std::string out = "runs/eval";
  std::string command = "tjepa eval";  // the command line, written into results.md
  bool force = false;
  bool quiet = false;
};

// The demo: one pre-training seed, one head per task, rows constant / ridge / random / end to
// end / Tactile-JEPA, sized to run in minutes rather than hours (docs/evaluation.md, "The demo"):
// the end-to-end heads stop after 2 epochs, which the row's name says (the protocol's limits
// allow up to 200 epochs), and the linear read-out table is left to `tjepa eval`.
inline EvalOptions demo_eval_options(std::uint64_t seed) {
  EvalOptions o;
  GraspEvalConfig& c = o.eval;
  c.data_seed = seed;
  c.seeds = {seed};
  c.head_seeds = 1;
  c.mae = false;
  c.dino = false;
  c.byol = false;
  c.ablation = false;
  c.linear_readout = false;
  c.heads.end_to_end_max_epochs = 2;
  c.heads.end_to_end_patience = 2;
  o.out = "runs/demo";
  o.command = "tjepa demo";
  o.force = true;
  return o;
}

inline int run_eval(const EvalOptions& o, std::ostream& out) {
  o.eval.validate();
  const std::filesystem::path dir = o.out;
  out << "tjepa " << version_string << " " << o.command << ": " << o.eval.seeds.size() << " pre-training seed(s) x "
      << o.eval.head_seeds << " head(s) per task; " << max_threads() << " thread(s)\n" << std::flush;
  const auto t0 = std::chrono::steady_clock::now();
  OutputFiles::check_new(dir / "results.json", o.force);
  std::filesystem::create_directories(dir);
  // The tables so far, rewritten (atomically) after every pre-training seed.
  auto write = [&](const GraspEvalResult& r) {
    std::string md = "# " + o.command + "\n\n" + r.main.markdown();
    if (!r.ablation.rows.empty()) md += "\n" + r.ablation.markdown();
    if (!r.linear.rows.empty()) md += "\n" + r.linear.markdown();
    if (!r.ablation_linear.rows.empty()) md += "\n" + r.ablation_linear.markdown();
    write_file_atomic(dir / "results.md", md);
    nlohmann::json j = r.info;
    j["command"] = o.command;
    j["main"] = r.main.to_json();
    if (!r.ablation.rows.empty()) j["ablation"] = r.ablation.to_json();
    if (!r.linear.rows.empty()) j["linear"] = r.linear.to_json();
    if (!r.ablation_linear.rows.empty()) j["ablation_linear"] = r.ablation_linear.to_json();
    write_file_atomic(dir / "results.json", j.dump(2));
    write_file_atomic(dir / "results.svg", r.main.svg());
    if (!r.ablation.rows.empty()) write_file_atomic(dir / "ablation.svg", r.ablation.svg());
    return md;
  };
  const GraspEvalResult r = run_grasp_eval(
      o.eval,
      [&](const std::string& line) {
        if (!o.quiet) {
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          out << "[" << format_duration(s) << "] " << line << "\n" << std::flush;
        }
      },
      write);
  out << "\n" << write(r);
  out << "total " << format_duration(r.info["total_seconds"].get<double>()) << "; wrote " << dir.string()
      << "/{results.md, results.json, results.svg" << (r.ablation.rows.empty() ? "" : ", ablation.svg") << "}\n";
  return 0;
}

}  // namespace tjepa::cli
