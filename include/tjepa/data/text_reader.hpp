#pragma once
// Text recordings: one frame per line, one column per (taxel, axis), separated by whitespace or by
// commas (CSV). Lines that are empty or start with '#' are skipped; `skip_rows` header lines are
// skipped first (-1: the first data line is skipped when one of its fields is not a number, a
// header row naming the columns). A column map says which column holds value (n, a): columns[n·m + a]; without one
// the columns are taken in order, taxel-major with the axis fastest. A frame may span several
// lines (`lines_per_frame`, as in the iCub grasp dataset's 7 lines per time slice): its columns are
// those of its lines one after the other.
//
// The file is streamed line by line straight into the recording's buffer, so it is never held
// twice. Every problem throws FileError as "<file>:<line>: <what>".
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/data/recording.hpp"

namespace tjepa {

struct TextFormat {
  int axes = 1;              // m, sensing axes per taxel
  int taxels = 0;            // N; 0: from the column map, or columns / axes
  std::vector<int> columns;  // [N·m] source column (0-based) of value (n, a); empty: in order
  char delimiter = 0;        // ',' or ' ' (any whitespace); 0: ',' if the first data line has one
  int skip_rows = 0;         // header lines to skip before the data; -1: detect one header row
  bool require_finite = false;  // NaN/Inf (and "nan"/"inf" text) are errors
  int lines_per_frame = 1;   // data lines that make one frame, their columns joined in order
};

namespace detail {

// Splits a line into fields; whitespace mode merges runs of spaces/tabs.
inline void split_fields(std::string_view line, char delim, std::vector<std::string_view>& out) {
  out.clear();
  if (delim == ',') {
    std::size_t start = 0;
    for (;;) {
      const std::size_t end = line.find(',', start);
      std::string_view f = line.substr(start, end == std::string_view::npos ? std::string_view::npos : end - start);
      while (!f.empty() && (f.front() == ' ' || f.front() == '\t')) f.remove_prefix(1);
      while (!f.empty() && (f.back() == ' ' || f.back() == '\t')) f.remove_suffix(1);
      out.push_back(f);
      if (end == std::string_view::npos) break;
      start = end + 1;
    }
    return;
  }
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i == line.size()) break;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
    out.push_back(line.substr(i, j - i));
    i = j;
  }
}

inline bool parse_float(std::string_view s, float& v) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

}  // namespace detail

inline Recording read_text_recording(const std::filesystem::path& path, const TextFormat& fmt = {}) {
  const std::string file = path.string();
  require<ConfigError>(fmt.axes > 0, "read_text_recording(", file, "): axes = ", fmt.axes, ", expected > 0");
  require<ConfigError>(fmt.skip_rows >= -1, "read_text_recording(", file, "): skip_rows = ", fmt.skip_rows,
                       ", expected >= 0 (or -1: detect a header row)");
  require<ConfigError>(fmt.lines_per_frame >= 1, "read_text_recording(", file, "): lines_per_frame = ",
                       fmt.lines_per_frame, ", expected >= 1");
  bool detect_header = fmt.skip_rows < 0 && fmt.lines_per_frame == 1;
  require<ConfigError>(fmt.delimiter == 0 || fmt.delimiter == ',' || fmt.delimiter == ' ',
                       "read_text_recording(", file, "): delimiter '", fmt.delimiter, "', expected ',', ' ' or 0 (auto)");
  int taxels = fmt.taxels;
  int max_col = -1;
  if (!fmt.columns.empty()) {
    require<ConfigError>(fmt.columns.size() % static_cast<std::size_t>(fmt.axes) == 0, "read_text_recording(", file,
                         "): column map has ", fmt.columns.size(), " entries, expected a multiple of axes = ", fmt.axes);
    const int n_map = static_cast<int>(fmt.columns.size()) / fmt.axes;
    require<ConfigError>(taxels == 0 || taxels == n_map, "read_text_recording(", file, "): column map covers ", n_map,
                         " taxels, expected taxels = ", taxels);
    taxels = n_map;
    for (std::size_t k = 0; k < fmt.columns.size(); ++k) {
      require<ConfigError>(fmt.columns[k] >= 0, "read_text_recording(", file, "): column map entry ", k, " is ",
                           fmt.columns[k], ", expected a column index >= 0");
      max_col = std::max(max_col, fmt.columns[k]);
    }
  }
  require<ConfigError>(taxels >= 0, "read_text_recording(", file, "): taxels = ", taxels, ", expected >= 0");

  std::ifstream in(path);
  require<FileError>(in.good(), file, ": cannot open");
  std::string line;
  std::vector<std::string_view> fields;
  AlignedVector<float> values;
  char delim = fmt.delimiter;
  std::size_t ncols = 0;  // columns per row, fixed by the first data row
  long lineno = 0;
  int frames = 0;
  std::string joined;       // lines_per_frame > 1: the frame's lines so far, joined by the delimiter
  int lines_in_frame = 0;
  long frame_line = 0;      // the line a frame starts on: errors name it (and the column in the frame)
  while (std::getline(in, line)) {
    ++lineno;
    if (lineno <= fmt.skip_rows) continue;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::string_view sv(line);
    const auto first = sv.find_first_not_of(" \t");
    if (first == std::string_view::npos || sv[first] == '#') continue;
    if (delim == 0) delim = sv.find(',') != std::string_view::npos ? ',' : ' ';
    if (fmt.lines_per_frame > 1) {
      if (lines_in_frame == 0) joined.clear(), frame_line = lineno;
      else joined += delim;
      joined += sv;
      if (++lines_in_frame < fmt.lines_per_frame) continue;
      lines_in_frame = 0;
      sv = joined;
    } else {
      frame_line = lineno;
    }
    detail::split_fields(sv, delim, fields);
    if (detect_header) {
      detect_header = false;
      float v;
      const bool numeric = std::all_of(fields.begin(), fields.end(), [&](std::string_view f) {
        return detail::parse_float(f, v) || f == "nan" || f == "NaN" || f == "inf" || f == "-inf";
      });
      if (!numeric) continue;  // a header row
    }
    if (ncols == 0) {
      ncols = fields.size();
      if (fmt.columns.empty()) {
        require<FileError>(ncols % static_cast<std::size_t>(fmt.axes) == 0, file, ":", frame_line, ": ", ncols,
                           " columns, expected a multiple of axes = ", fmt.axes,
                           " (other columns too, such as time or motors? give the taxels' columns)");
        if (taxels == 0) taxels = static_cast<int>(ncols) / fmt.axes;
        require<FileError>(ncols == static_cast<std::size_t>(taxels) * fmt.axes, file, ":", frame_line, ": ", ncols,
                           " columns, expected taxels*axes = ", taxels, "*", fmt.axes, " = ",
                           static_cast<std::size_t>(taxels) * fmt.axes);
      } else {
        require<FileError>(static_cast<std::size_t>(max_col) < ncols, file, ":", frame_line, ": ", ncols,
                           " columns, but the column map refers to column ", max_col);
      }
    }
    require<FileError>(fields.size() == ncols, file, ":", frame_line, ": ", fields.size(), " columns, expected ", ncols,
                       " (as in the first data row)");
    const std::size_t base = values.size();
    const std::size_t per = static_cast<std::size_t>(taxels) * fmt.axes;
    values.resize(base + per);
    for (std::size_t k = 0; k < per; ++k) {
      const std::size_t c = fmt.columns.empty() ? k : static_cast<std::size_t>(fmt.columns[k]);
      float v;
      if (!detail::parse_float(fields[c], v))
        fail<FileError>(file, ":", frame_line, ": column ", c + 1, ": '", fields[c], "' is not a number");
      if (fmt.require_finite && !std::isfinite(v))
        fail<DataError>(file, ":", frame_line, ": column ", c + 1, ": value ", fields[c], " (frame ", frames, ", taxel ",
                        k / fmt.axes, ", axis ", k % fmt.axes, "), expected finite data");
      values[base + k] = v;
    }
    ++frames;
  }
  require<FileError>(!in.bad(), file, ": read error");
  require<FileError>(lines_in_frame == 0, file, ":", frame_line, ": the last frame has ", lines_in_frame, " of its ",
                     fmt.lines_per_frame, " lines (lines_per_frame = ", fmt.lines_per_frame, ")");
  require<FileError>(frames > 0, file, ": no data rows");
  return Recording(frames, taxels, fmt.axes, std::move(values), file);
}

}  // namespace tjepa
