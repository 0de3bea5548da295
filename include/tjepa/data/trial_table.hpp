#pragma once
// Trial tables: labelled tactile data as many short recordings (trials), one label each — an
// object grasped, a fabric stroked, a slip or not. A CSV file whose header names its columns:
//
//   file,label,split,group
//   grasps/book_1.txt,book,train,
//   grasps/book_2.txt,book,test,
//
//   file    the trial's recording (any format the readers take), relative to the table's folder
//   label   a class name (numbers are names too), a regression value, or a per-frame label file
//           (a path ending in .npy, .csv or .txt, relative to the table's folder)
//   split   optional: train, val or test (every row then has one)
//   group   optional: trials that must stay on one side of every split (one session, one
//           setpoint); empty: the trial is its own group
//
// Other columns are refused by name; fields may be double-quoted ("a,b" and "" for a quote).
// Lines that are empty or start with '#' are skipped. Every problem throws FileError as
// "<table>:<line>: <what>". Windows are cut inside each trial, never across two (WindowSource
// takes the trials as separate recordings).
#include <algorithm>
#include <charconv>
#include <cstdint>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/core/files.hpp"

namespace tjepa {

enum class TrialSplit { none, train, val, test };

inline const char* trial_split_name(TrialSplit s) {
  return s == TrialSplit::train ? "train" : s == TrialSplit::val ? "val" : s == TrialSplit::test ? "test" : "";
}

struct Trial {
  std::filesystem::path file;   // resolved against the table's folder
  std::string label;            // as written (a class name or value); a label file's path as written
  std::filesystem::path label_file;  // the per-frame label file, resolved; empty: `label` is the trial's
  TrialSplit split = TrialSplit::none;
  std::string group;            // "" : the trial is its own group
  int line = 0;                 // the table's line (messages)
};

struct TrialTable {
  std::string source;           // the table's path
  std::vector<Trial> trials;
  bool has_split = false, has_group = false;

  std::size_t size() const { return trials.size(); }
  // "<table>:<line>" of trial i, for messages.
  std::string where(std::size_t i) const { return source + ":" + std::to_string(trials.at(i).line); }
  bool labels_are_files() const { return !trials.empty() && !trials.front().label_file.empty(); }
  // The trials' group keys: the group column, or a key of the trial's own where it has none.
  std::vector<std::string> group_keys() const {
    std::vector<std::string> g;
    for (std::size_t i = 0; i < trials.size(); ++i)
      g.push_back(trials[i].group.empty() ? "\x01trial " + std::to_string(i) : trials[i].group);
    return g;
  }
  // Each trial's group as a number: the groups in order of first appearance, 0, 1, ...
  std::vector<std::int64_t> group_ids() const {
    std::vector<std::int64_t> id;
    std::map<std::string, std::int64_t> seen;
    for (const std::string& k : group_keys()) id.push_back(seen.emplace(k, static_cast<std::int64_t>(seen.size())).first->second);
    return id;
  }
};

namespace detail {
// Fields of one CSV line; a field may be double-quoted. Returns false on an unterminated quote.
inline bool split_csv_line(std::string_view line, std::vector<std::string>& out) {
  out.clear();
  std::string f;
  std::size_t i = 0;
  for (;;) {
    f.clear();
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i < line.size() && line[i] == '"') {
      ++i;
      for (;;) {
        if (i >= line.size()) return false;
        if (line[i] == '"') {
          if (i + 1 < line.size() && line[i + 1] == '"') f += '"', i += 2;
          else { ++i; break; }
        } else {
          f += line[i++];
        }
      }
      while (i < line.size() && line[i] != ',') ++i;  // spaces after the closing quote
    } else {
      const std::size_t end = std::min(line.find(',', i), line.size());
      f.assign(line.substr(i, end - i));
      while (!f.empty() && (f.back() == ' ' || f.back() == '\t')) f.pop_back();
      i = end;
    }
    out.push_back(f);
    if (i >= line.size()) return true;
    ++i;  // the comma
  }
}

inline bool is_label_file_name(const std::string& s) {
  const std::string ext = std::filesystem::path(s).extension().string();
  return ext == ".npy" || ext == ".csv" || ext == ".txt";
}
}  // namespace detail

// Reads a trial table (see the top). Paths are resolved against the table's folder and must exist.
inline TrialTable read_trial_table(const std::filesystem::path& path) {
  TrialTable t;
  t.source = path.string();
  std::ifstream in(path);
  require<FileError>(in.good(), t.source, ": cannot open the trial table");
  const std::filesystem::path dir = path.parent_path();
  std::string line;
  std::vector<std::string> fields;
  int lineno = 0, col_file = -1, col_label = -1, col_split = -1, col_group = -1;
  std::size_t ncols = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    require<FileError>(detail::split_csv_line(line, fields), t.source, ":", lineno, ": a quoted field is not closed");
    if (ncols == 0) {  // the header
      ncols = fields.size();
      for (std::size_t c = 0; c < fields.size(); ++c) {
        int* slot = fields[c] == "file" ? &col_file : fields[c] == "label" ? &col_label
                  : fields[c] == "split" ? &col_split : fields[c] == "group" ? &col_group : nullptr;
        require<FileError>(slot != nullptr, t.source, ":", lineno, ": column '", fields[c],
                           "', expected a header of file, label and optionally split and group");
        require<FileError>(*slot < 0, t.source, ":", lineno, ": column '", fields[c], "' appears twice");
        *slot = static_cast<int>(c);
      }
      require<FileError>(col_file >= 0 && col_label >= 0, t.source, ":", lineno,
                         ": the header needs the columns file and label (and optionally split, group), it has '", line, "'");
      t.has_split = col_split >= 0, t.has_group = col_group >= 0;
      continue;
    }
    require<FileError>(fields.size() == ncols, t.source, ":", lineno, ": ", fields.size(), " fields, the header has ",
                       ncols);
    Trial r;
    r.line = lineno;
    const std::string& file = fields[static_cast<std::size_t>(col_file)];
    require<FileError>(!file.empty(), t.source, ":", lineno, ": no file");
    r.file = dir / file;
    require_input_file(r.file, "recording", t.source + ":" + std::to_string(lineno) + ": ");
    r.label = fields[static_cast<std::size_t>(col_label)];
    require<FileError>(!r.label.empty(), t.source, ":", lineno, ": no label for ", file);
    if (detail::is_label_file_name(r.label)) {
      r.label_file = dir / r.label;
      const std::string problem = input_file_problem(r.label_file);
      require<FileError>(problem.empty(), t.source, ":", lineno, ": label file '", r.label_file.string(), "': ",
                         problem, " (a label ending in .npy, .csv or .txt names a per-frame label file)");
    }
    if (!t.trials.empty())
      require<FileError>(r.label_file.empty() == t.trials.front().label_file.empty(), t.source, ":", lineno,
                         ": label '", r.label, "' ", r.label_file.empty() ? "is a value" : "is a label file",
                         ", line ", t.trials.front().line, "'s ", r.label_file.empty() ? "a label file" : "a value",
                         "; a table's labels are all per-trial values or all per-frame files");
    if (col_split >= 0) {
      const std::string& s = fields[static_cast<std::size_t>(col_split)];
      r.split = s == "train" ? TrialSplit::train : s == "val" ? TrialSplit::val : s == "test" ? TrialSplit::test
                                                                                            : TrialSplit::none;
      require<FileError>(r.split != TrialSplit::none, t.source, ":", lineno, ": split '", s,
                         "', expected train, val or test");
    }
    if (col_group >= 0) r.group = fields[static_cast<std::size_t>(col_group)];
    t.trials.push_back(std::move(r));
  }
  require<FileError>(!in.bad(), t.source, ": read error");
  require<FileError>(ncols > 0, t.source, ": empty; expected a header (file,label[,split][,group]) and one row per trial");
  require<FileError>(!t.trials.empty(), t.source, ": a header and no trial");
  return t;
}

// The class names of a table's labels and each trial's class id: names sorted, numerically when
// every name is a number (so "2" comes before "10").
struct TrialClasses {
  std::vector<std::string> names;
  std::vector<int> of_trial;  // [trials]
};

inline TrialClasses trial_classes(const TrialTable& t) {
  require<ConfigError>(!t.labels_are_files(), t.source, ": the labels are per-frame files, not class names");
  TrialClasses c;
  for (const Trial& r : t.trials) c.names.push_back(r.label);
  std::sort(c.names.begin(), c.names.end());
  c.names.erase(std::unique(c.names.begin(), c.names.end()), c.names.end());
  auto number = [](const std::string& s, double& v) {
    const auto res = std::from_chars(s.data(), s.data() + s.size(), v);
    return res.ec == std::errc() && res.ptr == s.data() + s.size();
  };
  double a = 0, b = 0;
  if (std::all_of(c.names.begin(), c.names.end(), [&](const std::string& s) { return number(s, a); }))
    std::sort(c.names.begin(), c.names.end(), [&](const std::string& x, const std::string& y) {
      number(x, a), number(y, b);
      return a < b;
    });
  for (const Trial& r : t.trials)
    c.of_trial.push_back(static_cast<int>(std::find(c.names.begin(), c.names.end(), r.label) - c.names.begin()));
  return c;
}

// Each trial's regression value; throws naming the line of a label that is not a finite number.
inline std::vector<float> trial_values(const TrialTable& t) {
  require<ConfigError>(!t.labels_are_files(), t.source, ": the labels are per-frame files, not values");
  std::vector<float> v;
  for (std::size_t i = 0; i < t.size(); ++i) {
    const std::string& s = t.trials[i].label;
    float x = 0;
    const auto res = std::from_chars(s.data(), s.data() + s.size(), x);
    require<FileError>(res.ec == std::errc() && res.ptr == s.data() + s.size() && std::isfinite(x), t.where(i),
                       ": label '", s, "' is not a number (a regression needs one value per trial)");
    v.push_back(x);
  }
  return v;
}

// Trials of one recording that concatenates them: each frame's trial id (a label column), the
// frames of a trial consecutive. A trial is a run of equal ids [begin, end); an id that comes back
// after another trial's frames, or one that is not finite, is a DataError naming the frame.
struct FrameTrial {
  int begin = 0, end = 0;  // frames [begin, end)
  double id = 0;           // as the column holds it
};

inline std::vector<FrameTrial> frame_trials(std::span<const float> id, const std::string& source) {
  std::vector<FrameTrial> t;
  std::map<double, int> first_frame;
  for (std::size_t f = 0; f < id.size(); ++f) {
    const double v = id[f];
    require<DataError>(std::isfinite(v), source, ": frame ", f, " has trial id ", v, ", expected a finite number");
    if (!t.empty() && t.back().id == v) {
      t.back().end = static_cast<int>(f) + 1;
      continue;
    }
    const auto [at, fresh] = first_frame.emplace(v, static_cast<int>(f));
    require<DataError>(fresh, source, ": frame ", f, " has trial id ", v, " again after other trials (its frames begin at ",
                       at->second, "); a trial's frames must be consecutive");
    t.push_back({static_cast<int>(f), static_cast<int>(f) + 1, v});
  }
  require<DataError>(!t.empty(), source, ": no frame, so no trial");
  return t;
}

}  // namespace tjepa
