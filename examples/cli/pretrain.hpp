#pragma once
// Pre-training for `tjepa pretrain` and `tjepa demo`: the library's Trainer, with a progress line
// and one log row per step. This file only prints; the Trainer does the work.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <tjepa/tjepa.hpp>

#include "output.hpp"

namespace tjepa::cli {

struct PretrainOutcome {
  CsvTable log;              // one row per step
  double seconds = 0;
  double windows_per_second = 0;
};

// The rows of an earlier log.csv with step < before (the steps a resumed run keeps), or none when
// the file is missing or not a pre-training log.
inline CsvTable earlier_log_rows(const std::filesystem::path& path, std::int64_t before);

inline const std::vector<std::string>& pretrain_log_columns() {
  static const std::vector<std::string> c{"step", "loss", "lr", "weight_decay", "momentum", "grad_norm",
                                          "target_std", "windows_per_s", "seconds", "target_sample_std"};
  return c;
}

// Runs the trainer until step stop_after (< 0: the end of its schedule), printing progress unless quiet.
inline PretrainOutcome pretrain(JepaTrainer<float>& trainer, bool quiet, std::int64_t stop_after = -1) {
  const int B = trainer.objective().config().batch;
  PretrainOutcome out;
  out.log.header = pretrain_log_columns();
  ProgressLine progress("pretrain", trainer.total_steps(), quiet);
  const std::int64_t first = trainer.step();
  trainer.on_step = [&](const JepaStepStats& st) {
    const double t = progress.elapsed();
    const double rate = t > 0 ? static_cast<double>((st.step + 1 - first) * B) / t : 0.0;
    out.log.rows.push_back({static_cast<double>(st.step), st.loss, st.lr, st.weight_decay, st.momentum, st.grad_norm,
                            st.target_std, rate, t, st.target_sample_std});
    char extra[96];
    std::snprintf(extra, sizeof extra, "loss %.4f  target std %.3f (over samples %.3f)", st.loss, st.target_std,
                  st.target_sample_std);
    progress.update(st.step + 1, (st.step + 1 - first) * B, extra);
  };
  trainer.run(stop_after < 0 ? -1 : std::max<std::int64_t>(0, stop_after - first));
  trainer.on_step = nullptr;
  out.seconds = progress.elapsed();
  out.windows_per_second =
      out.seconds > 0 ? static_cast<double>(trainer.step() - first) * B / out.seconds : 0.0;
  return out;
}

// Writes checkpoint.safetensors (the trainer's), log.csv and loss.svg into dir (registered with
// files). earlier: the log of the steps before a resume, which the new rows continue.
inline void write_pretrain_outputs(const std::filesystem::path& dir, JepaTrainer<float>& trainer,
                                   const PretrainOutcome& outcome, OutputFiles& files, const CsvTable& earlier = {}) {
  trainer.save(files.add(dir / "checkpoint.safetensors"));
  CsvTable log = earlier;
  log.header = outcome.log.header;
  log.rows.insert(log.rows.end(), outcome.log.rows.begin(), outcome.log.rows.end());
  write_file_atomic(files.add(dir / "log.csv"), log.str());
  const std::vector<double> x = log.column(0);
  write_file_atomic(files.add(dir / "loss.svg"),
                    curve_svg(x,
                              {{"JEPA loss", log.column(1), "#1f77b4"},
                               {"target std", log.column(6), "#ff7f0e"}},
                              "Tactile-JEPA pre-training", "step"));
}

inline CsvTable earlier_log_rows(const std::filesystem::path& path, std::int64_t before) {
  CsvTable t;
  t.header = pretrain_log_columns();
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line)) return t;
  std::string want;
  for (const auto& c : t.header) want += (want.empty() ? "" : ",") + c;
  if (line != want) return t;
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::istringstream fields(line);
    for (std::string f; std::getline(fields, f, ',');) row.push_back(std::strtod(f.c_str(), nullptr));
    if (row.size() != t.header.size() || row[0] >= static_cast<double>(before)) continue;
    t.rows.push_back(std::move(row));
  }
  return t;
}

}  // namespace tjepa::cli
