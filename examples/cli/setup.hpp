#pragma once
// The `tjepa` command's setup: skins (built-in or CSV), the run configuration (JSON), data
// (simulated or from files), and models saved to / restored from checkpoints.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/tjepa.hpp>
#include <tjepa/train/jepa_step.hpp>

namespace tjepa::cli {

// ---------------------------------------------------------------------------------------------
// Skins

// A layout CSV: a header naming the columns, then one taxel per row. Columns: x, y (mm), and
// optionally z, id, part, group (names or numbers; default one part / one group). Edges: inside a
// group, taxels closer than 1.2 x the group's nearest-neighbour spacing (4-neighbours on a grid);
// between two groups of one part whose closest taxels are within 2 x that spacing, the k = 4
// closest pairs (as the built-in layouts' bridges). Weights: distance in mm.
inline Skin read_layout_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  require<FileError>(static_cast<bool>(in), "cannot open layout file '", path.string(), "'");
  std::string line;
  std::vector<std::string_view> f;
  std::vector<std::string> cols;
  int lineno = 0;
  auto where = [&] { return path.string() + ":" + std::to_string(lineno); };
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    detail::split_fields(line, ',', f);
    for (auto s : f) {
      std::string c(s);
      c.erase(0, c.find_first_not_of(" \t\r"));
      c.erase(c.find_last_not_of(" \t\r") + 1);
      cols.push_back(c);
    }
    break;
  }
  auto col = [&](const char* name) {
    const auto it = std::find(cols.begin(), cols.end(), name);
    return it == cols.end() ? -1 : static_cast<int>(it - cols.begin());
  };
  const int cx = col("x"), cy = col("y"), cz = col("z"), cid = col("id"), cp = col("part"), cg = col("group");
  require<FileError>(cx >= 0 && cy >= 0, path.string(), ": the header must name columns x and y (got '",
                     line, "')");
  const int dim = cz >= 0 ? 3 : 2;
  LayoutBuilder b(dim);
  std::map<std::string, int> parts, groups;
  std::vector<int> group_part;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
    detail::split_fields(line, ',', f);
    require<FileError>(f.size() == cols.size(), where(), ": ", f.size(), " fields, expected ", cols.size());
    auto text = [&](int c) {
      std::string s(f[static_cast<std::size_t>(c)]);
      s.erase(0, s.find_first_not_of(" \t\r"));
      s.erase(s.find_last_not_of(" \t\r") + 1);
      return s;
    };
    auto number = [&](int c) {
      float v = 0;
      require<FileError>(detail::parse_float(text(c), v) && std::isfinite(v), where(), ": column '", cols[c],
                         "' = '", text(c), "', expected a finite number");
      return static_cast<double>(v);
    };
    const std::string pname = cp >= 0 ? text(cp) : "part0";
    if (!parts.contains(pname)) parts.emplace(pname, b.add_part(pname));
    const std::string gname = cg >= 0 ? text(cg) : "group0";
    if (!groups.contains(gname)) {
      groups.emplace(gname, b.add_group(gname, parts.at(pname)));
      group_part.push_back(parts.at(pname));
    }
    require<FileError>(group_part[static_cast<std::size_t>(groups.at(gname))] == parts.at(pname), where(),
                       ": group '", gname, "' appears in two parts");
    double xyz[3] = {number(cx), number(cy), cz >= 0 ? number(cz) : 0.0};
    const int id = cid >= 0 ? static_cast<int>(number(cid)) : -1;
    b.add_taxel(groups.at(gname), std::span<const double>(xyz, static_cast<std::size_t>(dim)), -1, -1, id);
  }
  const TaxelLayout& l = b.layout();
  require<FileError>(l.size() >= 2, path.string(), ": ", l.size(), " taxels, expected at least 2");
  const int G = l.num_groups();
  std::vector<std::vector<int>> members(static_cast<std::size_t>(G));
  for (int i = 0; i < l.size(); ++i) members[static_cast<std::size_t>(l.group[i])].push_back(i);
  std::vector<double> spacing(static_cast<std::size_t>(G), 0.0);
  for (int g = 0; g < G; ++g) {
    const auto& m = members[static_cast<std::size_t>(g)];
    double nn_max = 0;  // the group's spacing: the largest nearest-neighbour distance
    for (int i : m) {
      double nn = std::numeric_limits<double>::infinity();
      for (int j : m)
        if (j != i) nn = std::min(nn, l.distance(i, j));
      if (std::isfinite(nn)) nn_max = std::max(nn_max, nn);
    }
    spacing[static_cast<std::size_t>(g)] = nn_max;
    for (std::size_t a = 0; a < m.size(); ++a)
      for (std::size_t c = a + 1; c < m.size(); ++c)
        if (l.distance(m[a], m[c]) <= 1.2 * nn_max) b.add_edge(m[a], m[c]);
  }
  std::vector<GroupPair> pairs;
  for (int g = 0; g < G; ++g)
    for (int h = g + 1; h < G; ++h) {
      if (group_part[static_cast<std::size_t>(g)] != group_part[static_cast<std::size_t>(h)]) continue;
      double best = std::numeric_limits<double>::infinity();
      for (int i : members[static_cast<std::size_t>(g)])
        for (int j : members[static_cast<std::size_t>(h)]) best = std::min(best, l.distance(i, j));
      const double s = std::max(spacing[static_cast<std::size_t>(g)], spacing[static_cast<std::size_t>(h)]);
      if (best <= 2.0 * s) pairs.push_back({g, h});
    }
  for (const auto& p : pairs) {
    const auto k = std::min<std::size_t>(4, members[static_cast<std::size_t>(p.a)].size() *
                                                members[static_cast<std::size_t>(p.b)].size());
    b.add_bridges(std::span<const GroupPair>(&p, 1), static_cast<int>(k));
  }
  return b.build();
}

// "allegro" (the built-in Xela/Allegro hand), "grid" (a generic grid skin), "two-part", or the
// path of a layout CSV.
inline Skin load_skin(const std::string& spec) {
  if (spec == "allegro") return layouts::allegro_xela();
  if (spec == "grid") return layouts::grid_skin();
  if (spec == "two-part") return layouts::two_part_skin();
  require<ConfigError>(std::filesystem::exists(spec), "layout '", spec,
                       "' is neither a built-in layout (allegro, grid, two-part) nor an existing CSV file");
  return read_layout_csv(spec);
}

// ---------------------------------------------------------------------------------------------
// Configuration

// A pre-training run: model size, masks (the reference's defaults), optimizer and schedules.
struct RunConfig {
  std::string layout = "allegro";
  int tau = 10;  // frames per window
  // Model (JepaConfig): encoder width / depth / heads, predictor depth (its width is the encoder's).
  int dim = 96, depth = 4, heads = 3, predictor_depth = 2;
  // Training (a short run: a peak rate above the reference's 1e-4, which is tuned for 500 epochs).
  int steps = 600, batch = 32, warmup_steps = 60;
  double lr = 1e-3, start_lr = 1e-4, final_lr = 1e-5;
  double wd_start = 0.04, wd_end = 0.4;
  // AdamW's moment decays (the reference: 0.9, 0.999; the demo uses beta2 0.99).
  double beta1 = 0.9, beta2 = 0.999;
  // A short run: the target encoder (what the probes read) must follow the context encoder within
  // a few hundred steps; the reference's 0.996 suits 500 epochs (its EMA lags ~250 steps).
  double ema_start = 0.99, ema_end = 1.0;
  double drop_path = 0.0;
  double tokenizer_bias_std = 1.0;  // JepaConfig::tokenizer_bias_std (the reference: 0)
  // The position table's start (init only): 0 = the reference's N(0, 0.02²); k > 0 = the graph's k
  // smallest Laplacian eigenvectors, RMS position_scale (graph_positions, spectral_positions.hpp).
  int position_eigenvectors = 0;
  double position_scale = 1.0;
  // Masks (MaskConfig; the reference's defaults): per-batch context and target ratios, targets per sample.
  double context_ratio_lo = 0.5, context_ratio_hi = 0.9;
  double target_ratio_lo = 0.10, target_ratio_hi = 0.18;
  int local_targets = 2, global_targets = 2;
  double activity_weight = 0.0;  // JepaStepConfig::activity_weight (the reference: 0, a plain mean)
  // Data: DriftTracker's time constant in frames (200: 2 s at 100 Hz), for recordings with a
  // no-contact baseline (the "magnetic" preprocessing); 0 = off, the reference's one fixed baseline.
  // Off by default here (the reference's preprocessing); the demo turns it on together with beta2
  // 0.99 (demo_run_config in commands.hpp says why).
  double drift_time_constant = 0.0;
  // The objective's reference options (JepaStepConfig): "mse" or I-JEPA's "smooth_l1", targets
  // re-normalized by a LayerNorm without affine, the predictor's positions from the context encoder.
  std::string loss = "mse";
  bool normalize_targets = false, predictor_pos_from_context = false;
  bool standardize_targets = false;  // JepaStepConfig::standardize_targets (not in the reference)
  std::uint64_t seed = 0;

  nlohmann::json to_json() const {
    return {{"layout", layout}, {"tau", tau}, {"dim", dim}, {"depth", depth}, {"heads", heads},
            {"predictor_depth", predictor_depth}, {"steps", steps}, {"batch", batch}, {"warmup_steps", warmup_steps},
            {"lr", lr}, {"start_lr", start_lr}, {"final_lr", final_lr}, {"wd_start", wd_start}, {"wd_end", wd_end},
            {"beta1", beta1}, {"beta2", beta2},
            {"ema_start", ema_start}, {"ema_end", ema_end}, {"drop_path", drop_path},
            {"tokenizer_bias_std", tokenizer_bias_std},
            {"position_eigenvectors", position_eigenvectors}, {"position_scale", position_scale},
            {"context_ratio", {context_ratio_lo, context_ratio_hi}},
            {"target_ratio", {target_ratio_lo, target_ratio_hi}}, {"local_targets", local_targets},
            {"global_targets", global_targets}, {"activity_weight", activity_weight},
            {"drift_time_constant", drift_time_constant}, {"loss", loss},
            {"normalize_targets", normalize_targets}, {"predictor_pos_from_context", predictor_pos_from_context},
            {"standardize_targets", standardize_targets},
            {"seed", seed}};
  }
  // Overrides the fields the JSON names; an unknown key or a wrong type is an error.
  void update(const nlohmann::json& j, const std::string& source) {
    require<ConfigError>(j.is_object(), source, ": expected a JSON object");
    const nlohmann::json known = to_json();
    for (const auto& [k, v] : j.items()) {
      require<ConfigError>(known.contains(k), source, ": unknown key '", k, "' (known: ", known.dump(), ")");
      try {
        if (k == "layout") layout = v.get<std::string>();
        else if (k == "tau") tau = v.get<int>();
        else if (k == "dim") dim = v.get<int>();
        else if (k == "depth") depth = v.get<int>();
        else if (k == "heads") heads = v.get<int>();
        else if (k == "predictor_depth") predictor_depth = v.get<int>();
        else if (k == "steps") steps = v.get<int>();
        else if (k == "batch") batch = v.get<int>();
        else if (k == "warmup_steps") warmup_steps = v.get<int>();
        else if (k == "lr") lr = v.get<double>();
        else if (k == "start_lr") start_lr = v.get<double>();
        else if (k == "final_lr") final_lr = v.get<double>();
        else if (k == "wd_start") wd_start = v.get<double>();
        else if (k == "wd_end") wd_end = v.get<double>();
        else if (k == "beta1") beta1 = v.get<double>();
        else if (k == "beta2") beta2 = v.get<double>();
        else if (k == "ema_start") ema_start = v.get<double>();
        else if (k == "ema_end") ema_end = v.get<double>();
        else if (k == "drop_path") drop_path = v.get<double>();
        else if (k == "tokenizer_bias_std") tokenizer_bias_std = v.get<double>();
        else if (k == "position_eigenvectors") position_eigenvectors = v.get<int>();
        else if (k == "position_scale") position_scale = v.get<double>();
        else if (k == "context_ratio") std::tie(context_ratio_lo, context_ratio_hi) = v.get<std::pair<double, double>>();
        else if (k == "target_ratio") std::tie(target_ratio_lo, target_ratio_hi) = v.get<std::pair<double, double>>();
        else if (k == "local_targets") local_targets = v.get<int>();
        else if (k == "global_targets") global_targets = v.get<int>();
        else if (k == "activity_weight") activity_weight = v.get<double>();
        else if (k == "drift_time_constant") drift_time_constant = v.get<double>();
        else if (k == "loss") loss = v.get<std::string>();
        else if (k == "normalize_targets") normalize_targets = v.get<bool>();
        else if (k == "standardize_targets") standardize_targets = v.get<bool>();
        else if (k == "predictor_pos_from_context") predictor_pos_from_context = v.get<bool>();
        else if (k == "seed") seed = v.get<std::uint64_t>();
      } catch (const nlohmann::json::exception&) {
        fail<ConfigError>(source, ": key '", k, "' = ", v.dump(), " has the wrong type (expected like ",
                          known.at(k).dump(), ")");
      }
    }
  }
  // Overrides the fields a JSON file names.
  void update_from_file(const std::filesystem::path& path) {
    std::ifstream in(path);
    require<FileError>(static_cast<bool>(in), "cannot open config file '", path.string(), "'");
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
      fail<ConfigError>(path.string(), ": not valid JSON: ", e.what());
    }
    update(j, path.string());
  }
  static RunConfig from_file(const std::filesystem::path& path) {
    RunConfig c;
    c.update_from_file(path);
    return c;
  }
  void validate() const {
    require<ConfigError>(tau > 0, "config: tau = ", tau, ", expected > 0");
    require<ConfigError>(dim > 0 && heads > 0 && dim % heads == 0, "config: dim = ", dim, ", heads = ", heads,
                         ", expected dim a positive multiple of heads");
    require<ConfigError>(depth > 0 && predictor_depth > 0, "config: depth = ", depth, ", predictor_depth = ",
                         predictor_depth, ", expected > 0");
    require<ConfigError>(steps > 0 && batch > 0, "config: steps = ", steps, ", batch = ", batch, ", expected > 0");
    require<ConfigError>(warmup_steps >= 0 && warmup_steps <= steps, "config: warmup_steps = ", warmup_steps,
                         ", expected in [0, steps]");
    require<ConfigError>(lr > 0 && start_lr > 0 && final_lr > 0, "config: learning rates must be > 0");
    require<ConfigError>(beta1 >= 0 && beta1 < 1 && beta2 >= 0 && beta2 < 1, "config: beta1/beta2 = ", beta1, "/",
                         beta2, ", expected in [0, 1)");
    require<ConfigError>(ema_start >= 0 && ema_start <= 1 && ema_end >= 0 && ema_end <= 1,
                         "config: ema_start/ema_end = ", ema_start, "/", ema_end, ", expected in [0, 1]");
    require<ConfigError>(tokenizer_bias_std >= 0, "config: tokenizer_bias_std = ", tokenizer_bias_std,
                         ", expected >= 0");
    require<ConfigError>(position_eigenvectors >= 0, "config: position_eigenvectors = ", position_eigenvectors,
                         ", expected >= 0 (0: the reference's random table)");
    require<ConfigError>(position_scale > 0 && std::isfinite(position_scale), "config: position_scale = ",
                         position_scale, ", expected > 0");
    require<ConfigError>(drop_path >= 0 && drop_path < 1, "config: drop_path = ", drop_path, ", expected in [0, 1)");
    require<ConfigError>(activity_weight >= 0 && std::isfinite(activity_weight), "config: activity_weight = ",
                         activity_weight, ", expected >= 0");
    require<ConfigError>(drift_time_constant == 0 || (std::isfinite(drift_time_constant) && drift_time_constant >= 1),
                         "config: drift_time_constant = ", drift_time_constant, ", expected 0 (off) or >= 1 frame");
    require<ConfigError>(loss == "mse" || loss == "smooth_l1", "config: loss = '", loss,
                         "', expected 'mse' or 'smooth_l1'");
    const MaskConfig m = masks();
    detail::check_ratio_range(m.context_ratio, "context_ratio");
    detail::check_ratio_range(m.target_ratio, "target_ratio");
    require<ConfigError>(local_targets >= 0 && global_targets >= 0 && local_targets + global_targets > 0,
                         "config: local_targets = ", local_targets, ", global_targets = ", global_targets,
                         ", expected >= 0 and at least one target");
  }

  JepaConfig model(int num_tokens, int axes) const {
    JepaConfig c = JepaConfig::reference(num_tokens, tau * axes, axes);
    c.encoder.dim = dim;
    c.encoder.depth = depth;
    c.encoder.heads = heads;
    c.predictor.in_dim = dim;
    c.predictor.dim = dim;
    c.predictor.depth = predictor_depth;
    c.predictor.heads = heads;
    c.tokenizer_bias_std = tokenizer_bias_std;
    return c;
  }
  // A new model of this run over `graph` (its tokens), initialized from `init_seed`.
  std::unique_ptr<JepaModel<float>> new_model(const TaxelGraph& graph, int axes, std::uint64_t init_seed) const {
    auto m = std::make_unique<JepaModel<float>>(model(graph.num_nodes(), axes), init_seed);
    if (position_eigenvectors > 0) {
      require<ConfigError>(position_eigenvectors <= graph.num_nodes(), "config: position_eigenvectors = ",
                           position_eigenvectors, ", expected at most the ", graph.num_nodes(), " tokens");
      m->set_positions(graph_positions(graph, dim, position_eigenvectors, position_scale, init_seed));
    }
    return m;
  }
  MaskConfig masks() const {
    MaskConfig m;
    m.context_ratio = {context_ratio_lo, context_ratio_hi};
    m.target_ratio = {target_ratio_lo, target_ratio_hi};
    m.num_local = local_targets;
    m.num_global = global_targets;
    return m;
  }
  AdamWConfig adamw() const { return AdamWConfig{beta1, beta2, 1e-8}; }
  // The step's objective options (the rest of JepaStepConfig keeps the reference's values).
  JepaStepConfig step() const {
    JepaStepConfig c;
    c.loss = loss == "smooth_l1" ? JepaLossKind::smooth_l1 : JepaLossKind::mse;
    c.normalize_targets = normalize_targets;
    c.standardize_targets = standardize_targets;
    c.predictor_pos_from_context = predictor_pos_from_context;
    c.drop_path = drop_path;
    c.activity_weight = activity_weight;
    return c;
  }
  TrainingSchedule schedule() const {
    TrainingSchedule s;
    s.lr = WarmupCosineLr{start_lr, lr, final_lr, warmup_steps, steps};
    s.wd = CosineWeightDecay{wd_start, wd_end, steps};
    s.momentum = LinearMomentum{ema_start, ema_end, steps};
    s.validate();
    return s;
  }
};

// ---------------------------------------------------------------------------------------------
// Data

// Simulated recordings of one sensor (one SimulatedSkin: same offsets and gains throughout):
// a contact-free baseline, an unlabelled pre-training recording, a labelled probe-training
// recording and a labelled held-out test recording, each with its own contact events.
struct SimulatedData {
  Recording baseline;
  Recording pretrain;
  SimRecording probe_train, test;
};

inline SimulatedData simulate(const Skin& skin, std::uint64_t seed, int pretrain_frames, int probe_frames,
                              int test_frames, int pretrain_contacts = 1, int baseline_frames = 300) {
  SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, seed);
  SimulatedData d;
  d.baseline = sim.record_baseline(baseline_frames);
  d.pretrain = sim.record(pretrain_frames, pretrain_contacts).recording;
  d.probe_train = sim.record(probe_frames);
  d.test = sim.record(test_frames);
  return d;
}

// The run's DriftTracker (none when drift_time_constant is 0 or there is no baseline), fitted on the
// no-contact baseline, then run over recs in order: one continuous session of one sensor (the
// tracker carries its state from one recording to the next).
inline std::optional<DriftTracker> track_drift(const RunConfig& run, const Recording* baseline,
                                               std::span<Recording* const> recs) {
  if (run.drift_time_constant <= 0 || baseline == nullptr) return std::nullopt;
  DriftTrackerConfig c = DriftTrackerConfig::magnetic();
  c.time_constant = run.drift_time_constant;
  DriftTracker tracker(c);
  tracker.fit(*baseline);
  for (Recording* r : recs) tracker.apply(*r);
  return tracker;
}

// Preprocessing by name: "magnetic" (Xela: drop-outs, baseline, per-axis standardization; needs a
// baseline recording), "standardize" (per-axis), "none".
inline Preprocessor fit_preprocessor(const std::string& mode, const Recording* baseline,
                                     std::span<const Recording> train) {
  PreprocessConfig c;
  if (mode == "magnetic") {
    require<ConfigError>(baseline != nullptr, "preprocessing 'magnetic' needs a no-contact baseline recording (--baseline)");
    c = PreprocessConfig::magnetic();
  } else if (mode == "standardize") {
    c.scaling = Scaling::per_axis;
  } else {
    require<ConfigError>(mode == "none", "preprocessing '", mode, "', expected magnetic, standardize or none");
  }
  Preprocessor p(c);
  if (c.subtract_baseline) p.fit_baseline(*baseline);
  p.fit(train);
  return p;
}

// A recording from .npy ([T, N, m] or [T, N·m] with axes given) or text/CSV (axes given).
inline Recording read_recording(const std::filesystem::path& path, int axes) {
  require<FileError>(std::filesystem::exists(path), "no such file '", path.string(), "'");
  if (path.extension() == ".npy") return read_recording_npy(path, axes > 0 ? axes : 0);
  TextFormat f;
  f.axes = axes > 0 ? axes : 3;
  return read_text_recording(path, f);
}

// Frame labels from a [T, 4] .npy file: force (shear u, shear v, normal) in N and the indenter
// class (-1 or any negative value: no contact).
inline std::vector<FrameLabel> read_frame_labels(const std::filesystem::path& path, int frames) {
  const NpyArray a = read_npy(path);
  require<FileError>(a.shape.size() == 2 && a.shape[1] == 4 && a.shape[0] == frames, path.string(),
                     ": labels of shape ", detail::shape_string(std::span<const std::int64_t>(a.shape)), ", expected [", frames,
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

// Windows with at least min_contact frames in contact, at most `limit` of them (a seeded random
// subset, kept in time order), for probes.
inline std::vector<std::int64_t> labelled_windows(const WindowSource& src, int min_contact, int limit,
                                                  std::uint64_t seed) {
  std::vector<std::int64_t> ids = src.windows_with_contact(min_contact);
  require<DataError>(!ids.empty(), "no window has >= ", min_contact, " frames in contact");
  if (limit > 0 && static_cast<int>(ids.size()) > limit) {
    Rng(seed, 0x6c6162656c).shuffle(std::span<std::int64_t>(ids));  // "label"
    ids.resize(static_cast<std::size_t>(limit));
    std::sort(ids.begin(), ids.end());
  }
  return ids;
}

// ---------------------------------------------------------------------------------------------
// Models and checkpoints

// Everything a checkpoint's metadata holds besides the tensors.
inline CheckpointState checkpoint_state(const RunConfig& run, const JepaConfig& model, const Preprocessor& pre,
                                        std::int64_t step, const DriftTracker* drift = nullptr) {
  CheckpointState s;
  s.step = step;
  s.config = {{"run", run.to_json()}, {"model", model.to_json()}};
  for (const NamedTensor& t : pre.state()) s.normalization.emplace(t.name, Tensor::from(t.values, t.shape));
  if (drift)
    for (const NamedTensor& t : drift->state()) s.normalization.emplace(t.name, Tensor::from(t.values, t.shape));
  return s;
}

// A model and preprocessor restored from a checkpoint written by `tjepa pretrain` / `tjepa demo`.
struct LoadedModel {
  RunConfig run;
  std::unique_ptr<JepaModel<float>> model;
  Preprocessor pre;
  std::optional<DriftTracker> drift;  // when the run tracked drift: apply it to new recordings first
  std::int64_t step = 0;

  // The checkpoint's drift tracking over a new recording (from the fitted rest reading).
  void track(Recording& rec) {
    if (!drift) return;
    drift->reset();
    drift->apply(rec);
  }
};

inline LoadedModel load_model(const std::filesystem::path& path) {
  require<FileError>(std::filesystem::exists(path), "no such checkpoint '", path.string(), "'");
  const SafetensorsFile file = load_safetensors(path);
  const auto it = file.metadata.find("config");
  require<FileError>(it != file.metadata.end(), path.string(), ": no 'config' metadata; not a tjepa checkpoint");
  nlohmann::json cfg;
  try {
    cfg = nlohmann::json::parse(it->second);
  } catch (const nlohmann::json::exception& e) {
    fail<FileError>(path.string(), ": metadata 'config' is not valid JSON: ", e.what());
  }
  require<FileError>(cfg.contains("run") && cfg.contains("model"), path.string(),
                     ": the config has no 'run'/'model' entries; not written by the tjepa command");
  LoadedModel m;
  m.run.update(cfg.at("run"), path.string());
  const auto& mc = cfg.at("model");
  const int tokens = mc.at("encoder").at("num_tokens").get<int>(), in_dim = mc.at("in_dim").get<int>();
  require<FileError>(in_dim % m.run.tau == 0, path.string(), ": in_dim ", in_dim, " is not a multiple of tau ",
                     m.run.tau);
  m.model = std::make_unique<JepaModel<float>>(m.run.model(tokens, in_dim / m.run.tau), 0);
  const auto parts = m.model->parts();
  const CheckpointState st =
      load_checkpoint(path, std::span<const PrefixedParams<float>>(parts), static_cast<AdamW<float>*>(nullptr));
  std::vector<NamedTensor> pre_state;
  for (const auto& [name, t] : st.normalization) {
    NamedTensor nt{name, t.shape, std::vector<float>(t.numel())};
    t.copy_to(std::span<float>(nt.values));
    pre_state.push_back(std::move(nt));
  }
  m.pre = Preprocessor::from_state(pre_state);
  if (DriftTracker::in_state(pre_state)) m.drift = DriftTracker::from_state(pre_state);
  m.step = st.step;
  return m;
}

}  // namespace tjepa::cli
