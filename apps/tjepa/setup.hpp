#pragma once
// The `tjepa` command's setup: skins (built-in or CSV) and data (simulated or from files).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <span>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/core/files.hpp>
#include <tjepa/eval.hpp>

namespace tjepa::cli {

// ---------------------------------------------------------------------------------------------
// Skins

// The skin of a run: a built-in layout ("allegro", "grid", "two-part") or a layout CSV, its
// edges (built in, an edges CSV, or inferred from the coordinates by the bridge rule), and the
// order of the recordings' taxel columns (TaxelLayout::column). What the user should hear about
// the graph (outliers, a part in several pieces) goes to `warnings` one line each, or is an error
// when strict.
struct SkinSpec {
  std::string layout = "allegro";
  std::string edges;             // edges CSV ("": built in or inferred)
  std::string columns;           // "key=name,..." for the layout CSV's columns
  std::string bridges = "connect";
  std::string order;             // "", "xserver", "reference" (Allegro) or an id,column CSV
  bool strict = false;
  static SkinSpec of(const TrainConfig& c) {
    return {c.data.layout, c.data.layout_edges, c.data.layout_columns, c.data.bridges, c.data.taxel_order, false};
  }
};

// Fewer steps than the default warm-up: the warm-up becomes a tenth of the run, with a note (a
// warm-up the command line or config file set stays, and validate() names it).
inline void fit_default_warmup(TrainConfig& run, const nlohmann::json& overrides, std::ostream& out) {
  if (run.schedule.warmup_steps <= run.schedule.steps || overrides.contains("warmup_steps") ||
      run.schedule.warmup_steps != TrainConfig{}.schedule.warmup_steps)
    return;
  out << "note: " << run.schedule.steps << " steps are fewer than the default warm-up of " << run.schedule.warmup_steps
      << "; warming up for " << run.schedule.steps / 10 << " steps (--warmup sets it)\n";
  run.schedule.warmup_steps = run.schedule.steps / 10;
}

inline Skin load_skin(const SkinSpec& s, std::ostream* warnings = nullptr) {
  InferredSkin r;
  const bool builtin = s.layout == "allegro" || s.layout == "grid" || s.layout == "two-part";
  if (builtin) {
    require<ConfigError>(s.edges.empty(), "--edges is for a layout CSV; the built-in layout '", s.layout,
                         "' has its own edges");
    r.skin = s.layout == "allegro" ? layouts::allegro_xela() : s.layout == "grid" ? layouts::grid_skin()
                                                                                : layouts::two_part_skin();
  } else {
    require<ConfigError>(path_exists(s.layout), "layout '", s.layout,
                         "' is neither a built-in layout (allegro, grid, two-part) nor an existing CSV file");
    const LayoutCsvColumns cols = parse_csv_columns(s.columns);
    if (!s.edges.empty()) {
      require_input_file(s.edges, "edges file");
      r = read_skin_csv_checked(s.layout, s.edges, cols.nodes, cols.edges);
    } else {
      CoordinateSkinOptions o;
      o.bridges = parse_bridge_rule(s.bridges);
      r = read_skin_coordinates_csv(s.layout, cols.nodes, o);
    }
  }
  if (!s.order.empty()) {
    if (s.order == "xserver" || s.order == "reference") {
      require<ConfigError>(s.layout == "allegro", "taxel order '", s.order, "' is the Allegro hand's (layout allegro), ",
                           "not layout '", s.layout, "'s; give an order CSV (id,column) instead");
      r.skin.layout.column = s.order == "xserver" ? layouts::allegro::xserver_columns()
                                                  : layouts::allegro::reference_columns();
    } else {
      require<ConfigError>(path_exists(s.order), "taxel order '", s.order,
                           "' is neither xserver, reference nor an existing order CSV (id,column)");
      r.skin.layout.column = read_taxel_order_csv(s.order, r.skin.layout);
    }
    r.skin.layout.validate();
  }
  for (const auto& w : r.warnings) {
    require<DataError>(!s.strict, s.layout, ": ", w, " (an error under --strict)");
    if (warnings) *warnings << "warning: " << s.layout << ": " << w << '\n';
  }
  return r.skin;
}

// A recording in the layout's taxel order (TaxelLayout::column), after its taxel count is checked.
inline Recording in_layout_order(Recording rec, const Skin& skin, const std::string& what) {
  require<ShapeError>(rec.taxels() == skin.size(), what, ": ", rec.taxels(), " taxels, the layout has ", skin.size());
  if (!skin.layout.has_columns()) return rec;
  return select_taxels(rec, skin.layout.column);
}

// ---------------------------------------------------------------------------------------------
// Data

// Preprocessing by name:
//   xela         Xela uSkin counts: readings outside [20000, 60000] are drop-outs (0), each taxel's
//                no-contact mean is subtracted, then per-axis standardization. Refused, saying so,
//                when most readings lie outside that range (the data are not Xela counts).
//   baseline     each taxel's no-contact mean subtracted, then per-axis standardization: magnetometer
//                skins such as AnySkin, whose taxels sit at different offsets.
//   standardize  per-axis standardization over all taxels.
//   none         the values as they are.
//   auto         xela when at least 90 % of the readings are in Xela's range; else baseline when the
//                taxels' offsets vary more than each taxel's signal does; else standardize.
// auto decides on all training recordings together (one file or the same frames as many give the
// same choice). The no-contact mean comes from the baseline recording, or without one from the
// first training recording (baseline_contact_warning says when that one moves like the data).
struct PreprocessChoice {
  std::string mode, reason;
};

namespace data_stats {
// Fraction of finite readings inside Xela's valid range, and the range of all finite readings.
inline std::tuple<double, float, float> xela_range_share(std::span<const Recording> recs) {
  const PreprocessConfig x = PreprocessConfig::xela_counts();
  std::size_t in = 0, n = 0;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (const Recording& r : recs)
    for (float v : r.values())
      if (std::isfinite(v)) {
        ++n;
        in += v >= x.valid_min && v <= x.valid_max;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
  return {n ? static_cast<double>(in) / static_cast<double>(n) : 0.0, lo, hi};
}
// Per taxel and axis over all frames of all recordings: the count, mean and variance of the
// finite readings ([N·m] each).
struct TaxelMoments {
  std::vector<double> count, mean, var;
};
inline TaxelMoments taxel_moments(std::span<const Recording> recs) {
  const std::size_t per = static_cast<std::size_t>(recs[0].taxels()) * recs[0].axes();
  TaxelMoments t{std::vector<double>(per, 0.0), std::vector<double>(per, 0.0), std::vector<double>(per, 0.0)};
  for (const Recording& r : recs)
    for (int f = 0; f < r.frames(); ++f)
      for (std::size_t k = 0; k < per; ++k) {
        const double v = r.frame(f)[k];
        if (!std::isfinite(v)) continue;
        t.count[k] += 1;  // Welford
        const double d = v - t.mean[k];
        t.mean[k] += d / t.count[k];
        t.var[k] += d * (v - t.mean[k]);
      }
  for (std::size_t k = 0; k < per; ++k) t.var[k] = t.count[k] > 0 ? t.var[k] / t.count[k] : 0.0;
  return t;
}

// Variance of the taxels' means against the mean variance inside a taxel, per axis, summed, over
// all frames of all recordings: one file or the same frames as many give the same ratio.
inline double offset_to_signal_ratio(std::span<const Recording> recs) {
  const int N = recs[0].taxels(), m = recs[0].axes();
  const TaxelMoments t = taxel_moments(recs);
  double between = 0, within = 0;
  for (int a = 0; a < m; ++a) {
    double mm = 0, ms = 0;
    int k = 0;
    for (int i = 0; i < N; ++i) {
      const std::size_t j = static_cast<std::size_t>(i) * m + a;
      if (t.count[j] == 0) continue;
      mm += t.mean[j], ms += t.var[j], ++k;
    }
    if (!k) continue;
    mm /= k;
    for (int i = 0; i < N; ++i) {
      const std::size_t j = static_cast<std::size_t>(i) * m + a;
      if (t.count[j] > 0) between += (t.mean[j] - mm) * (t.mean[j] - mm) / k;
    }
    within += ms / k;
  }
  return within > 0 ? between / within : (between > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}
}  // namespace data_stats

// A model converted from the reference code expects baseline-subtracted readings (the reference's
// dataset subtracts each taxel's no-contact mean before its model); raw Xela counts would reach it
// unchanged. Says so, one line, when at least 90 % of the readings lie in Xela's raw range.
inline void raw_counts_warning(const TrainedModel& m, std::span<const Recording> recs, std::ostream& out) {
  if (m.converted_from.empty() || m.pre.config().subtract_baseline || recs.empty()) return;
  const auto [share, lo, hi] = data_stats::xela_range_share(recs);
  if (share < 0.9) return;
  out << "warning: " << static_cast<int>(100 * share) << " % of the readings (range " << lo << " .. " << hi
      << ") are raw Xela counts, but the model converted from " << m.converted_from
      << " expects baseline-subtracted readings (the reference's dataset subtracts each taxel's no-contact mean "
         "before its model): subtract the baselines first, or its embeddings are of data it never saw\n";
}

// The mode `asked` resolves to (auto picks from the data), and why.
inline PreprocessChoice choose_preprocessing(const std::string& asked, std::span<const Recording> train) {
  require<ConfigError>(!train.empty(), "preprocessing: no training recording");
  require<ConfigError>(asked != "magnetic", "preprocessing 'magnetic' is now called 'xela' (Xela uSkin counts, ",
                       "readings outside [20000, 60000] dropped); for a magnetometer skin such as AnySkin use 'baseline'");
  if (asked != "auto") return {asked, "asked for"};
  const double share = std::get<0>(data_stats::xela_range_share(train));
  if (share >= 0.9)
    return {"xela", std::to_string(static_cast<int>(100 * share)) + " % of the readings are in Xela's range [20000, 60000]"};
  const double ratio = data_stats::offset_to_signal_ratio(train);
  if (ratio > 1.0) return {"baseline", "the taxels' offsets vary " + std::to_string(ratio) + " x more than their signals"};
  return {"standardize", "the readings are not Xela counts and the taxels share one offset"};
}

// A no-contact mean taken from a recording that moves like the data: its readings' variance (per
// taxel, averaged) is at least a quarter of all training readings'. "" when it looks at rest.
inline std::string baseline_contact_warning(const Recording& rest, std::span<const Recording> train) {
  const data_stats::TaxelMoments r = data_stats::taxel_moments(std::span<const Recording>(&rest, 1));
  const data_stats::TaxelMoments all = data_stats::taxel_moments(train);
  double vr = 0, va = 0;
  for (std::size_t k = 0; k < r.var.size(); ++k) vr += r.var[k], va += all.var[k];
  if (!(va > 0) || vr < 0.25 * va) return "";
  return "the no-contact mean is taken from " + rest.source() + ", whose readings vary " +
         std::to_string(static_cast<int>(std::lround(100 * vr / va))) +
         " % as much as all training readings: if it holds contact (a grasp, a stroke), give --baseline a recording at rest";
}

// A preprocessor of a resolved mode (not auto), fitted on the training recordings.
inline Preprocessor fit_preprocessor(const std::string& mode, const Recording* baseline,
                                     std::span<const Recording> train) {
  require<ConfigError>(mode != "auto", "fit_preprocessor: resolve 'auto' with choose_preprocessing first");
  (void)choose_preprocessing(mode, train);  // the checks of the mode's name
  const auto [share, lo, hi] = data_stats::xela_range_share(train);
  PreprocessConfig c;
  if (mode == "xela") {
    require<DataError>(share >= 0.5, "preprocessing 'xela' expects Xela counts in [20000, 60000], but ",
                       static_cast<int>(100 * share), " % of the readings of ", train[0].source(), " are (they range over [",
                       lo, ", ", hi, "]); all others would be dropped as drop-outs. For a magnetometer skin such as ",
                       "AnySkin use --preprocess baseline; otherwise standardize or none");
    c = PreprocessConfig::xela_counts();
  } else if (mode == "baseline") {
    c = PreprocessConfig::baseline_standardization();
  } else if (mode == "standardize") {
    c.scaling = Scaling::per_axis;
  } else {
    require<ConfigError>(mode == "none", "preprocessing '", mode, "', expected auto, xela, baseline, standardize or none");
  }
  Preprocessor p(c);
  if (c.subtract_baseline) p.fit_baseline(baseline ? *baseline : train[0]);
  p.fit(train);
  return p;
}

// How recordings are read: axes per taxel (text files and [T, N·m] .npy), which columns of a
// text file hold the taxels' values ("0:60" or "0:30,60:90", end exclusive, in the file's order,
// taxel-major with the axis fastest; "": all), header rows (-1: detect one), and what a NaN/Inf
// reading means (error, hold the last finite value, interpolate, zero).
struct DataFormat {
  int axes = 3;
  std::string columns;
  int skip_rows = -1;
  std::string non_finite = "error";
  int lines_per_frame = 1;  // text: lines that make one frame (the iCub grasp dataset: 7)
};

// "a:b[,c:d...]" -> the column indices a..b-1, c..d-1, ...
inline std::vector<int> parse_column_ranges(const std::string& spec) {
  std::vector<int> cols;
  std::size_t at = 0;
  while (at < spec.size()) {
    const std::size_t end = std::min(spec.find(',', at), spec.size());
    const std::string item = spec.substr(at, end - at);
    const std::size_t colon = item.find(':');
    int a = -1, b = -1;
    try {
      if (colon == std::string::npos) {
        a = std::stoi(item), b = a + 1;
      } else {
        a = std::stoi(item.substr(0, colon)), b = std::stoi(item.substr(colon + 1));
      }
    } catch (const std::exception&) {
      a = b = -1;
    }
    require<ConfigError>(a >= 0 && b > a, "--columns '", spec, "': '", item,
                         "' is not a column range a:b (0-based, end exclusive, a < b) or a column");
    for (int c = a; c < b; ++c) cols.push_back(c);
    at = end + 1;
  }
  return cols;
}

// The windows of a run's recordings: τ frames, `stride` apart (0: τ), and with --non-finite drop
// none that holds a NaN/Inf reading.
inline WindowSpec window_spec(int tau, const DataFormat& fmt, int stride = 0) {
  return WindowSpec{tau, stride, parse_non_finite(fmt.non_finite) == NonFinite::drop};
}

// Says how many windows --non-finite drop left out of `src` (nothing when none).
inline void note_dropped(const WindowSource& src, const std::string& what, std::ostream& out) {
  if (src.dropped() > 0)
    out << "note: " << what << ": " << src.dropped() << " of " << src.dropped() + src.size()
        << " windows left out: they hold NaN/Inf readings (--non-finite drop)\n";
}

// A recording from .npy ([T, N, m] or [T, N·m] with axes given) or text/CSV. A .npy is read into
// memory, not mapped (the command runs for hours and the file may change under it), unless map is
// set: data-parallel ranks map it and read only the windows of their shards (the file must then
// not be truncated or rewritten in place during the run). NaN/Inf readings are found here, before
// any statistic sees them, and handled by the format's policy.
inline Recording read_recording(const std::filesystem::path& path, const DataFormat& fmt = {}, bool map = false) {
  require_input_file(path, "recording");
  const NonFinite policy = parse_non_finite(fmt.non_finite);
  Recording rec;
  if (path.extension() == ".npy") {
    require<ConfigError>(fmt.lines_per_frame == 1, path.string(), ": --lines-per-frame is for text recordings, not .npy");
    NpyReadOptions opt;
    opt.map = map;
    rec = read_recording_npy(path, fmt.axes > 0 ? fmt.axes : 0, opt);
    if (!fmt.columns.empty()) {
      // The columns of each frame's N·m values, regrouped as taxels of `axes` values.
      const std::vector<int> cols = parse_column_ranges(fmt.columns);
      const int m = fmt.axes > 0 ? fmt.axes : rec.axes();
      const int per = rec.taxels() * rec.axes();
      require<ConfigError>(static_cast<int>(cols.size()) % m == 0, path.string(), ": --columns picks ", cols.size(),
                           " values per frame, expected a multiple of axes = ", m);
      for (int c : cols)
        require<ConfigError>(c < per, path.string(), ": --columns names column ", c, ", but a frame holds ", per, " values");
      const Recording flat(rec.frames(), per, 1, AlignedVector<float>(rec.values().begin(), rec.values().end()),
                           rec.source());
      const Recording picked = select_taxels(flat, cols);
      rec = Recording(rec.frames(), static_cast<int>(cols.size()) / m, m,
                      AlignedVector<float>(picked.values().begin(), picked.values().end()), rec.source());
    }
  } else {
    TextFormat f;
    f.axes = fmt.axes > 0 ? fmt.axes : 3;
    f.skip_rows = fmt.skip_rows;
    f.lines_per_frame = fmt.lines_per_frame;
    f.columns = parse_column_ranges(fmt.columns);
    f.require_finite = policy == NonFinite::error;  // names the file's line
    rec = read_text_recording(path, f);
  }
  replace_non_finite(rec, policy, "reading");
  return rec;
}

// Frame labels from a [T, 4] .npy file: force (shear u, shear v, normal) in N and the indenter
// class (-1 or any negative value: no contact).
inline std::vector<FrameLabel> read_frame_labels(const std::filesystem::path& path, int frames) {
  const NpyArray a = read_npy(path);
  require<FileError>(a.shape.size() == 2 && a.shape[1] == 4 && a.shape[0] == frames, path.string(),
                     ": labels of shape ", nlohmann::json(a.shape).dump(), ", expected [", frames,
                     ", 4] (force u, v, normal in N; indenter class or -1)");
  const float* v = a.data();
  std::vector<FrameLabel> out(static_cast<std::size_t>(frames));
  for (int t = 0; t < frames; ++t) {
    const float* r = v + static_cast<std::size_t>(t) * 4;
    for (int k = 0; k < 3; ++k) {
      require<FileError>(std::isfinite(r[k]), path.string(), ": row ", t, " has force ", r[k], ", expected finite");
      out[static_cast<std::size_t>(t)].force[static_cast<std::size_t>(k)] = r[k];
    }
    out[static_cast<std::size_t>(t)].indenter = r[3] >= 0 ? static_cast<int>(r[3]) : -1;
  }
  return out;
}

// Labels as a [T, 4] array (the inverse of read_frame_labels).
inline std::vector<float> frame_label_array(std::span<const FrameLabel> labels) {
  std::vector<float> v;
  for (const auto& l : labels) v.insert(v.end(), {l.force[0], l.force[1], l.force[2], static_cast<float>(l.indenter)});
  return v;
}

// At most `limit` of ids (0: all), a seeded random subset kept in the order given.
template <class Id>
std::vector<Id> seeded_subset(std::vector<Id> ids, int limit, std::uint64_t seed) {
  if (limit > 0 && static_cast<int>(ids.size()) > limit) {
    Rng(seed, 0x6c6162656c).shuffle(std::span<Id>(ids));  // "label"
    ids.resize(static_cast<std::size_t>(limit));
    std::sort(ids.begin(), ids.end());
  }
  return ids;
}

// Windows with at least min_contact frames in contact, at most `limit` of them (a seeded random
// subset, kept in time order), for probes.
inline std::vector<std::int64_t> labelled_windows(const WindowSource& src, int min_contact, int limit,
                                                  std::uint64_t seed) {
  std::vector<std::int64_t> ids = src.windows_with_contact(min_contact);
  require<DataError>(!ids.empty(), "no window has >= ", min_contact, " frames in contact");
  return seeded_subset(std::move(ids), limit, seed);
}

// Throws unless rec has the checkpoint's taxels and axes per frame.
inline void require_fits(const Recording& rec, const TrainedModel& m) {
  const JepaModel<float>& model = *m.model;
  require<ShapeError>(rec.taxels() == model.num_tokens() && rec.axes() * m.config.data.tau == model.config.in_dim,
                      rec.source(), ": ", rec.taxels(), " taxels x ", rec.axes(), " axes; the checkpoint expects ",
                      model.num_tokens(), " taxels x ", model.config.in_dim / m.config.data.tau, " axes");
}

}  // namespace tjepa::cli
