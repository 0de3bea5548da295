#pragma once
// The pre-training loop of `tjepa pretrain` and `tjepa demo`: windows in shuffled epochs, the
// reference's masks over the taxel graph, one jepa_train_step per batch, a progress line and a
// log row per step. after_step(s), when given, runs after step s (a read-out, a snapshot).
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>

#include <tjepa/tjepa.hpp>
#include <tjepa/train/jepa_step.hpp>

#include "output.hpp"
#include "setup.hpp"

namespace tjepa::cli {

struct PretrainOutcome {
  CsvTable log;              // one row per step
  double seconds = 0;
  double windows_per_second = 0;
  double final_target_std = 0;
  double final_target_sample_std = 0;
};

inline const std::vector<std::string>& pretrain_log_columns() {
  static const std::vector<std::string> c{"step", "loss", "lr", "weight_decay", "momentum", "grad_norm",
                                          "target_std", "windows_per_s", "seconds", "target_sample_std"};
  return c;
}

inline PretrainOutcome pretrain(JepaModel<float>& model, AdamW<float>& opt, const RunConfig& run,
                                const WindowSource& src, const TaxelGraph& graph, bool quiet,
                                const std::function<void(std::int64_t step)>& after_step = {}) {
  run.validate();
  const int B = run.batch;
  require<DataError>(src.size() >= B, "pre-training: ", src.size(), " windows, fewer than one batch of ", B);
  require<ShapeError>(graph.num_nodes() == model.num_tokens(), "pre-training: the graph has ", graph.num_nodes(),
                      " taxels, the model ", model.num_tokens(), " tokens");
  const MaskCollator collator(graph, run.masks());  // REFERENCE §3 defaults: 2 local + 2 global targets
  const TrainingSchedule schedule = run.schedule();
  const JepaStepConfig step_cfg = run.step();
  JepaWorkspace<float> w;
  WindowBatch batch;
  AlignedVector<float> rows;  // tokenizer input [B, N, m·τ]
  MaskBatch masks;
  std::vector<std::int64_t> order;
  const std::int64_t per_epoch = src.batches_per_epoch(B);
  PretrainOutcome out;
  out.log.header = pretrain_log_columns();
  ProgressLine progress("pretrain", run.steps, quiet);
  const std::uint64_t mask_seed = run.seed ^ 0x6d61736bull, data_seed = run.seed ^ 0x64617461ull;
  for (std::int64_t s = 0; s < run.steps; ++s) {
    if (s % per_epoch == 0) order = src.epoch_order(data_seed, static_cast<std::uint64_t>(s / per_epoch));
    src.gather(std::span<const std::int64_t>(order).subspan(static_cast<std::size_t>(s % per_epoch * B),
                                                           static_cast<std::size_t>(B)),
               batch);
    windows_to_tokens(batch, rows);
    collator.sample_into(masks, B, mask_seed, static_cast<std::uint64_t>(s));
    const JepaStepStats st = jepa_train_step(model, opt, schedule, s, rows.data(), B, masks, w, step_cfg,
                                             Rng(run.seed, static_cast<std::uint64_t>(s))());
    const double t = progress.elapsed();
    const double rate = t > 0 ? static_cast<double>((s + 1) * B) / t : 0.0;
    out.log.rows.push_back({static_cast<double>(s), st.loss, st.lr, st.weight_decay, st.momentum, st.grad_norm,
                            st.target_std, rate, t, st.target_sample_std});
    char extra[96];
    std::snprintf(extra, sizeof extra, "loss %.4f  target std %.3f (over samples %.3f)", st.loss, st.target_std,
                  st.target_sample_std);
    progress.update(s + 1, (s + 1) * B, extra);
    out.final_target_std = st.target_std;
    out.final_target_sample_std = st.target_sample_std;
    if (after_step) after_step(s);
  }
  out.seconds = progress.elapsed();
  out.windows_per_second = out.seconds > 0 ? static_cast<double>(run.steps) * B / out.seconds : 0.0;
  return out;
}

// Writes checkpoint.safetensors, log.csv and loss.svg into dir (registered with files).
inline void write_pretrain_outputs(const std::filesystem::path& dir, JepaModel<float>& model, const AdamW<float>& opt,
                                   const RunConfig& run, const Preprocessor& pre, const PretrainOutcome& outcome,
                                   OutputFiles& files, const DriftTracker* drift = nullptr) {
  const auto parts = model.parts();
  save_checkpoint(files.add(dir / "checkpoint.safetensors"), std::span<const PrefixedParams<float>>(parts), &opt,
                  checkpoint_state(run, model.config, pre, run.steps, drift));
  write_file_atomic(files.add(dir / "log.csv"), outcome.log.str());
  const std::vector<double> x = outcome.log.column(0);
  write_file_atomic(files.add(dir / "loss.svg"),
                    curve_svg(x,
                              {{"JEPA loss", outcome.log.column(1), "#1f77b4"},
                               {"target std", outcome.log.column(6), "#ff7f0e"}},
                              "Tactile-JEPA pre-training", "step"));
}

}  // namespace tjepa::cli
