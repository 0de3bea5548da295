#pragma once
// The `tjepa` command's setup: skins (built-in or CSV) and data (simulated or from files).
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

#include <tjepa/eval.hpp>

namespace tjepa::cli {

// ---------------------------------------------------------------------------------------------
// Skins

// "allegro" (the built-in Xela/Allegro hand), "grid" (a generic grid skin), "two-part", or the
// path of a layout CSV.
inline Skin load_skin(const std::string& spec) {
  if (spec == "allegro") return layouts::allegro_xela();
  if (spec == "grid") return layouts::grid_skin();
  if (spec == "two-part") return layouts::two_part_skin();
  require<ConfigError>(std::filesystem::exists(spec), "layout '", spec,
                       "' is neither a built-in layout (allegro, grid, two-part) nor an existing CSV file");
  return read_skin_coordinates_csv(spec);
}

// ---------------------------------------------------------------------------------------------
// Data

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

// A recording from .npy ([T, N, m] or [T, N·m] with axes given) or text/CSV (axes given). A .npy
// is read into memory, not mapped (the command runs for hours and the file may change under it),
// unless map is set: data-parallel ranks map it and read only the windows of their shards (the
// file must then not be truncated or rewritten in place during the run).
inline Recording read_recording(const std::filesystem::path& path, int axes, bool map = false) {
  require<FileError>(std::filesystem::exists(path), "no such file '", path.string(), "'");
  NpyReadOptions opt;
  opt.map = map;
  if (path.extension() == ".npy") return read_recording_npy(path, axes > 0 ? axes : 0, opt);
  TextFormat f;
  f.axes = axes > 0 ? axes : 3;
  return read_text_recording(path, f);
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

}  // namespace tjepa::cli
