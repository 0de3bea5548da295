#pragma once
// tjepa embed: the frozen encoder over the windows of recordings (one, several, or a trial
// table's trials; windows never cross two), written as embeddings .npy [W, N, d], and beside it a
// CSV of which window is which: window, file, first frame, frames (and the trial's label and split).
// Row n of a window is the recordings' column n (--rows layout: the layout's taxel n, which reads
// the column the model's taxel order gives it).
#include <CLI/CLI.hpp>

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/tjepa.hpp>

#include "options.hpp"
#include "output.hpp"
#include "setup.hpp"
#include "trials.hpp"

namespace tjepa::cli {

struct EmbedOptions {
  std::string checkpoint, out;
  std::vector<std::string> data;      // recordings, windows cut inside each
  TrialOptions trials;                // or a trial table: every trial, in table order
  std::string windows;                // the windows CSV ("": out with .windows.csv)
  std::string encoder = "target";
  std::string rows = "recording";     // the embeddings' taxel rows: the recording's column order, or the layout's
  DataFormat format;                  // how recordings are read (axes, columns, header, NaN)
  int stride = 0;  // frames between windows (0 = tau)
  bool force = false;
  bool quiet = false;
};

inline int run_embed(const EmbedOptions& o, std::ostream& out) {
  require<ConfigError>(!o.checkpoint.empty() && !o.out.empty(), "--checkpoint and --out are required");
  require<ConfigError>(o.data.empty() != o.trials.table.empty(), "give the recordings as --data FILE... or --trials TABLE");
  require<ConfigError>(o.encoder == "target" || o.encoder == "context", "--encoder '", o.encoder,
                       "', expected target or context");
  require<ConfigError>(o.rows == "recording" || o.rows == "layout", "--rows '", o.rows,
                       "', expected recording or layout");
  require<ConfigError>(parse_non_finite(o.format.non_finite) != NonFinite::drop,
                       "embed writes one row per window of the recording; --non-finite drop would shift them: use "
                       "hold, interpolate or zero");
  const std::filesystem::path windows_csv =
      !o.windows.empty() ? std::filesystem::path(o.windows) : std::filesystem::path(o.out).replace_extension(".windows.csv");
  OutputFiles::check_new(o.out, o.force);
  OutputFiles::check_new(windows_csv, o.force);
  TrainedModel m = load_trained_model(o.checkpoint);
  JepaModel<float>& model = *m.model;
  const Skin skin = load_skin(SkinSpec::of(m.config));
  std::vector<Recording> recs;
  std::vector<std::string> label, split;  // per recording (trials)
  if (!o.trials.table.empty()) {
    const TrialTable t = read_trial_table(o.trials.table);
    std::vector<int> all(t.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
    // The split of pretrain, probe and eval (the table's column, or the seeded split by trial).
    const TrialSplits sp = split_trials(t, o.trials.test_fraction, o.trials.seed);
    std::vector<TrialSplit> split_of(t.size(), TrialSplit::train);
    for (int i : sp.val) split_of[static_cast<std::size_t>(i)] = TrialSplit::val;
    for (int i : sp.test) split_of[static_cast<std::size_t>(i)] = TrialSplit::test;
    TrialRecordings tr = read_trials(t, all, o.format, skin, m.config.data.tau, "trials", out);
    recs = std::move(tr.recordings);
    for (int i : tr.trial) {
      label.push_back(t.trials[static_cast<std::size_t>(i)].label);
      split.push_back(trial_split_name(split_of[static_cast<std::size_t>(i)]));
    }
  } else {
    for (const std::string& p : o.data) recs.push_back(in_layout_order(read_recording(p, o.format), skin, p));
  }
  raw_counts_warning(m, recs, out);
  for (Recording& rec : recs) {
    require_fits(rec, m);
    m.track(rec);
  }
  const WindowSource src(recs, window_spec(m.config.data.tau, o.format, o.stride), {}, m.pre);
  std::vector<std::int64_t> ids(static_cast<std::size_t>(src.size()));
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<std::int64_t>(i);
  ProgressLine bar("embed", src.size(), o.quiet);
  auto emb = embed_windows(o.encoder == "target" ? model.target : model.context, model.tokenizer,
                                 model.encoder, src, ids, 32, [&](std::int64_t d, std::int64_t) { bar.update(d, d, ""); });
  // Rows in the recording's column order: the recording's column column[i] is the layout's taxel i.
  const std::vector<int>& column = skin.layout.column;
  const bool reorder = o.rows == "recording" && skin.layout.has_columns();
  if (reorder) {
    const int N = model.num_tokens(), d = model.dim();
    std::vector<float> w(static_cast<std::size_t>(N) * d);
    for (std::int64_t s = 0; s < src.size(); ++s) {
      float* e = emb.data() + static_cast<std::size_t>(s) * w.size();
      for (int i = 0; i < N; ++i)
        std::copy_n(e + static_cast<std::size_t>(i) * d, d, w.data() + static_cast<std::size_t>(column[static_cast<std::size_t>(i)]) * d);
      std::copy(w.begin(), w.end(), e);
    }
  }
  OutputFiles files;
  write_npy(files.add(o.out), std::span<const float>(emb.data(), emb.size()),
            {src.size(), model.num_tokens(), model.dim()});
  std::string csv = label.empty() ? "window,file,first_frame,frames\n" : "window,file,first_frame,frames,label,split\n";

  for (std::int64_t w = 0; w < src.size(); ++w) {
    const auto r = static_cast<std::size_t>(src.recording_of(w));
    csv += std::to_string(w) + "," + csv_field(recs[r].source()) + "," + std::to_string(src.start_of(w)) + "," +
           std::to_string(src.length());
    if (!label.empty()) csv += "," + csv_field(label[r]) + "," + split[r];
    csv += "\n";
  }
  write_file_atomic(files.add(windows_csv), csv);
  files.commit();
  out << "wrote " << o.out << ": [" << src.size() << ", " << model.num_tokens() << ", " << model.dim()
      << "] embeddings of windows of " << m.config.data.tau << " frames from " << recs.size() << " recording(s), taxel rows "
      << (!skin.layout.has_columns() ? std::string("in the recordings' (= the layout's) order")
          : reorder                  ? "in the recordings' column order (--rows layout: the layout's)"
                                     : "in the layout's order (taxel i reads the recordings' column " +
                                           std::string("given by the model's taxel order)"))
      << ", and " << windows_csv.string() << " (which window is which)\n";
  return 0;
}

// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_embed_command(CLI::App& app, EmbedOptions& o) {
  CLI::App* sub = app.add_subcommand("embed", "Frozen encoder over a recording's windows -> embeddings .npy [W, N, d]");
  sub->add_option("--checkpoint", o.checkpoint, "checkpoint of `tjepa pretrain`")->required();
  sub->add_option("--data", o.data, "recordings (.npy [T, N, m] or CSV), windows cut inside each");
  add_trial_options(sub, o.trials);
  sub->add_option("--test-fraction", o.trials.test_fraction,
                  "--trials without a split column: the share of trials held out (the split column of --windows)")
      ->capture_default_str();
  sub->add_option("--windows", o.windows, "the CSV of which window is which (default: --out with .windows.csv)");
  sub->add_option("--out", o.out, "output .npy")->required();
  sub->add_option("--encoder", o.encoder, "target | context")->capture_default_str();
  sub->add_option("--stride", o.stride, "frames between windows (0: tau)")->capture_default_str();
  sub->add_option("--rows", o.rows, "the taxel rows' order: recording (the recordings' columns) | layout")
      ->capture_default_str();
  add_data_format(sub, o.format);
  sub->add_flag("--force", o.force, "overwrite --out");
  sub->add_flag("--quiet", o.quiet, "no progress line");
  return sub;
}

}  // namespace tjepa::cli
