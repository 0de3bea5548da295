#pragma once
// Pre-training for `tjepa pretrain` and `tjepa demo`: the library's Trainer, with a progress line
// and one log row per step. This file only prints; the Trainer does the work.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <tjepa/tjepa.hpp>

#include "options.hpp"
#include "output.hpp"
#include "setup.hpp"
#include "trials.hpp"

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

// A collapse in a pre-training log: at the last row, the target embeddings' std over windows
// (target_sample_std) is under a tenth of their std inside a window (target_std), or has fallen
// under a quarter of its value at the first row. "" when neither.
// The sizes of the run's masks in a line, and a warning when most targets are one token (a small
// skin, or parts of a few taxels with per-part targets): the predictor then fills single taxels.
inline std::string mask_size_note(const MaskCollator& c, const TrainConfig& run) {
  const MaskSizeSummary m = summarize_mask_sizes(c, streams::masks(run.seed));
  if (m.target_max == 0) return "";  // the block scheme: sizes per sample
  char buf[256];
  std::snprintf(buf, sizeof buf, "masks: contexts of %d-%d tokens, %d targets of %d-%d tokens (mean %.1f)%s\n",
                m.context_min, m.context_max, c.num_targets(), m.target_min, m.target_max, m.target_mean,
                c.per_part() ? ", per part" : "");
  std::string s = buf;
  if (m.target_mean < 2) {
    std::snprintf(buf, sizeof buf, "warning: mask targets of %d-%d tokens (mean %.1f), most of them one token", m.target_min,
                  m.target_max, m.target_mean);
    s += std::string(buf) +
         (c.per_part() ? " (per-part targets on parts of a few taxels)" : "") +
         ": the predictor mostly fills single taxels from their neighbours" +
         (c.per_part() ? "; masks.part_targets \"whole\" draws targets across the parts" : "") +
         "; on skins this small, --config examples/configs/small_skin.json (graph positions, normalized targets) "
         "kept more of each taxel's window on FabricSlide, where larger targets lost more (docs/real_data.md)\n";
  }
  return s;
}

inline std::string collapse_warning(const CsvTable& log, const std::string& preprocessing) {
  if (log.rows.empty()) return "";
  const double within = log.rows.back()[6], across = log.rows.back()[9], first = log.rows.front()[9];
  const std::string remedy = std::string(preprocessing == "baseline" || preprocessing == "xela"
                                             ? ""
                                             : "; try --preprocess baseline (with --baseline REST)") +
                             ", a lower --lr or a slower EMA (--ema-start)";
  char buf[256];
  if (std::isfinite(within) && std::isfinite(across) && across < 0.1 * within) {
    std::snprintf(buf, sizeof buf, "the target embeddings hardly differ between windows (std over windows %.3g, inside a window %.3g): a collapse",
                  across, within);
    return buf + std::string(": the inputs may be dominated by fixed per-taxel offsets") + remedy;
  }
  if (std::isfinite(first) && std::isfinite(across) && log.rows.size() > 1 && across < 0.25 * first) {
    std::snprintf(buf, sizeof buf, "the target embeddings' std over windows fell from %.3g at step %.0f to %.3g at step %.0f (below a quarter): a collapse",
                  first, log.rows.front()[0], across, log.rows.back()[0]);
    return buf + remedy;
  }
  return "";
}

struct PretrainOptions {
  std::string config;                 // JSON file with TrainConfig keys ("" = defaults)
  nlohmann::json overrides = nlohmann::json::object();  // command-line overrides of TrainConfig keys
  std::vector<std::string> data;      // recordings (.npy [T, N, m] or text); empty: simulated
  TrialOptions trials;                // --trials TABLE: its training (and validation) trials, no labels
  double test_fraction = 0.2;         // --trials without a split column: as the probe's
  std::string baseline;               // no-contact recording (preprocessing xela or baseline)
  std::string preprocess = "auto";    // auto | xela | baseline | standardize | none (setup.hpp)
  DataFormat format;                  // how recordings are read (axes, columns, header, NaN)
  int simulate_frames = 20000;        // simulated data: frames of the pre-training recording
  int simulate_contacts = 1;          // simulated data: indenters touching at once (SimulatedSkin::record)
  std::string out;                    // "": the resumed checkpoint's folder, else runs/pretrain
  bool force = false;
  bool quiet = false;
  std::string resume;                 // continue the run of this checkpoint (its config, then overrides)
  std::int64_t stop_after = -1;       // stop (and save) after this many steps of the schedule (< 0: at its end)
  bool strict = false;                // warnings about the layout's graph are errors
  DataParallel<float> parallel;       // under mpirun: this rank's share of each batch (rank 0 prints and writes)
};

inline int run_pretrain(const PretrainOptions& o, std::ostream& out_lead) {
  const bool lead = o.parallel.rank == 0;
  NullStream null;
  std::ostream& out = lead ? out_lead : null;
  TrainConfig run = !o.config.empty()   ? TrainConfig::from_file(o.config)
                    : !o.resume.empty() ? load_trained_model(o.resume).config
                                        : TrainConfig{};
  // --steps 0: the initialization itself, written as a checkpoint (a random encoder to compare
  // against, with the data statistics of the run); its schedule says 1 step, none taken.
  const bool init_only = o.overrides.contains("steps") && o.overrides["steps"].is_number() && o.overrides["steps"] == 0;
  require<ConfigError>(!init_only || o.resume.empty(), "--steps 0 writes an initialization; it does not resume a run");
  nlohmann::json overrides = o.overrides;
  if (init_only) overrides["steps"] = 1, overrides["warmup_steps"] = 0;
  run.update(overrides, "command line");
  fit_default_warmup(run, overrides, out);
  run.validate();
  SkinSpec spec = SkinSpec::of(run);
  spec.strict = o.strict;
  const Skin skin = load_skin(spec, &out);
  std::vector<Recording> recs;
  std::vector<std::string> data_names = o.data;  // the recordings' files
  std::optional<Recording> baseline;
  std::string mode = o.preprocess;
  if (o.data.empty() && o.trials.table.empty()) {
    require<ConfigError>(o.simulate_frames >= run.data.tau, "--simulate ", o.simulate_frames, " frames, expected >= tau");
    SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, run.seed);
    baseline = sim.record_baseline(300);
    recs.push_back(sim.record(o.simulate_frames, o.simulate_contacts).recording);
    if (mode == "auto") mode = "xela";  // the simulated skin reports Xela counts
  } else if (!o.trials.table.empty()) {
    require<ConfigError>(o.data.empty(), "--trials and --data both name the recordings; give one");
    const TrialTable table = read_trial_table(o.trials.table);
    const TrialSplits sp = split_trials(table, o.test_fraction, o.trials.seed);
    const std::vector<int> fit = sp.fit();
    out << "trials: pre-training on the " << fit.size() << " training and validation trials of " << describe_split(table, sp)
        << "; the test trials are left out\n";
    TrialRecordings tr = read_trials(table, fit, o.format, skin, run.data.tau, "training trials", out);
    recs = std::move(tr.recordings);
    for (int i : tr.trial) data_names.push_back(table.trials[static_cast<std::size_t>(i)].file.string());
    if (!o.baseline.empty()) baseline = in_layout_order(read_recording(o.baseline, o.format), skin, o.baseline);
  } else {
    // Data parallel: each rank maps the recordings, so training reads only the pages of its
    // shards' windows; fitting the preprocessing (and the drift tracker, which writes a private
    // copy) still reads every recording once on every rank.
    const bool map = o.parallel.active();
    for (const auto& p : o.data) recs.push_back(in_layout_order(read_recording(p, o.format, map), skin, p));
    if (!o.baseline.empty()) baseline = in_layout_order(read_recording(o.baseline, o.format, map), skin, o.baseline);
  }
  for (std::size_t r = 0; r < recs.size(); ++r)
    require<ShapeError>(recs[r].taxels() == skin.size(), data_names.empty() ? "simulated" : data_names[r], ": ",
                        recs[r].taxels(), " taxels, the layout '", run.data.layout, "' has ", skin.size());
  std::vector<Recording*> rec_ptrs;
  for (auto& r : recs) rec_ptrs.push_back(&r);
  const PreprocessChoice picked = choose_preprocessing(mode, recs);
  if (mode != picked.mode) out << "preprocessing: " << picked.mode << " (" << picked.reason << ")\n";
  if ((picked.mode == "xela" || picked.mode == "baseline") && !baseline && !data_names.empty()) {
    out << "note: no --baseline recording: each taxel's no-contact mean is taken over " << data_names[0] << "\n";
    const std::string w = baseline_contact_warning(recs[0], recs);
    if (!w.empty()) out << "warning: " << w << "\n";
  }
  const std::optional<DriftTracker> drift =
      picked.mode == "xela" && baseline ? track_drift(run, *baseline, rec_ptrs) : std::nullopt;
  const Preprocessor pre = fit_preprocessor(picked.mode, baseline ? &*baseline : nullptr, recs);
  const int axes = recs[0].axes();
  const WindowSource src(recs, window_spec(run.data.tau, o.format), {}, pre);
  note_dropped(src, "pre-training data", out);

  OutputFiles files;
  // A resumed run writes into its own folder unless told otherwise, and continues its log there.
  const std::filesystem::path dir =
      !o.out.empty() ? std::filesystem::path(o.out)
                     : !o.resume.empty() ? std::filesystem::path(o.resume).parent_path() : std::filesystem::path("runs/pretrain");
  std::error_code ec;  // a name the system refuses: not the run's own folder (the writes name the problem)
  const bool own_folder = !o.resume.empty() &&
                          std::filesystem::equivalent(std::filesystem::absolute(o.resume, ec).parent_path(), dir, ec);
  OutputFiles::check_new(dir / "checkpoint.safetensors", o.force || own_folder);
  if (lead) files.make_dir(dir);
  const auto owned = make_jepa_model(run, skin.graph, axes, run.seed);
  JepaModel<float>& model = *owned;
  JepaTrainer<float> trainer(model, src, skin.graph, run);
  trainer.parallel = o.parallel;
  trainer.extras = data_state(pre, drift ? &*drift : nullptr);
  if (!o.resume.empty()) trainer.resume(o.resume);
  require<ConfigError>(o.stop_after < 0 || o.stop_after > trainer.step(), "--stop-after ", o.stop_after,
                       ", expected a step after the run's current ", trainer.step());
  out << "pre-training on " << src.size() << " windows (" << skin.size() << " taxels, tau " << run.data.tau << "), "
      << model.context.numel() << " encoder + " << model.predictor_params.numel() << " predictor parameters, "
      << run.schedule.steps << " steps of " << run.batch
      << (o.parallel.active() ? " on " + std::to_string(o.parallel.ranks) + " MPI ranks" : std::string()) << "\n";
  if (run.step.precision == Precision::bf16 && lead)
    if (const std::string why = bf16_slower_reason(measure_product_peaks()); !why.empty())
      out << "note: --precision bf16: " << why << "\n";
  const std::string masks = mask_size_note(trainer.objective().collator(), run);
  if (!masks.empty() && lead) out << masks;
  if (init_only) {
    if (!lead) return 0;
    trainer.save(files.add(dir / "checkpoint.safetensors"));
    files.commit();
    out << "--steps 0: wrote the initialization (seed " << run.seed << ", no training step) to "
        << (dir / "checkpoint.safetensors").string() << "\n";
    return 0;
  }
  const PretrainOutcome r = pretrain(trainer, o.quiet || !lead, o.stop_after);
  if (!lead) return 0;
  write_pretrain_outputs(dir, trainer, r, files,
                         own_folder ? earlier_log_rows(dir / "log.csv", r.log.rows.empty() ? 0 : static_cast<std::int64_t>(r.log.rows.front()[0]))
                                    : CsvTable{});
  files.commit();
  out << "loss " << r.log.rows.front()[1] << " -> " << r.log.rows.back()[1] << ", target std "
      << r.log.rows.back()[6] << " (over samples " << r.log.rows.back()[9] << "), " << r.windows_per_second << " windows/s, " << format_duration(r.seconds)
      << "\nwrote " << (dir / "checkpoint.safetensors").string() << ", log.csv, loss.svg\n";
  const std::string collapse = collapse_warning(r.log, picked.mode);
  if (!collapse.empty()) out << "warning: " << collapse << "\n";
  return 0;
}


// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_pretrain_command(CLI::App& app, PretrainOptions& o) {
  CLI::App* sub = app.add_subcommand("pretrain", "Pre-train Tactile-JEPA: checkpoint, CSV log, loss-curve SVG");
  sub->add_option("--config", o.config, "JSON run configuration (keys as in the checkpoint's config.run)");
  add_run_overrides(sub, o.overrides);
  sub->add_option("--data", o.data, "recordings (.npy [T, N, m] or CSV); default: simulated data");
  add_trial_options(sub, o.trials);
  sub->add_option("--test-fraction", o.test_fraction, "--trials without a split column: the share of trials held out "
                  "(as the probe's, so pre-training never sees its test trials)")->capture_default_str();
  sub->add_option("--baseline", o.baseline, "no-contact recording (preprocessing xela or baseline)");
  sub->add_option("--preprocess", o.preprocess, "auto | xela | baseline | standardize | none")->capture_default_str();
  add_data_format(sub, o.format);
  sub->add_option("--simulate", o.simulate_frames, "frames of simulated data")->capture_default_str();
  sub->add_option("--simulate-contacts", o.simulate_contacts, "indenters touching at once in simulated data")
      ->capture_default_str();
  sub->add_option("--out", o.out, "output directory (default: runs/pretrain; a resumed run's own folder)");
  sub->add_flag("--force", o.force, "overwrite an existing checkpoint");
  sub->add_flag("--quiet", o.quiet, "no progress line");
  sub->add_option("--resume", o.resume, "continue the run of this checkpoint (same data and config)");
  sub->add_option("--stop-after", o.stop_after, "stop and save after this many steps of the schedule");
  sub->add_flag("--strict", o.strict, "warnings about the layout's graph are errors");
  return sub;
}

}  // namespace tjepa::cli
