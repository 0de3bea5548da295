#pragma once
// What the `tjepa` command writes: files that appear whole or not at all, a progress line, CSV
// logs and loss-curve SVGs.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <ostream>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <unistd.h>

#include <tjepa/core/files.hpp>
#include <tjepa/eval.hpp>

namespace tjepa::cli {

// An ostream that discards everything (what ranks other than 0 would print under mpirun).
struct NullStream : std::ostream {
  NullStream() : std::ostream(nullptr) {}
};

// The files (and directories) one command creates. Unless commit() is called, the destructor
// removes them again, so a command that fails leaves nothing half-done behind. A file that existed
// before (--force, or a resumed run writing into its own folder) is never removed: it holds either
// its old or its new contents. Each file itself is written atomically (write_file_atomic or the
// library's writers).
class OutputFiles {
 public:
  OutputFiles() = default;
  OutputFiles(const OutputFiles&) = delete;
  OutputFiles& operator=(const OutputFiles&) = delete;
  ~OutputFiles() {
    if (committed_) return;
    std::error_code ec;
    for (auto it = files_.rbegin(); it != files_.rend(); ++it) std::filesystem::remove(*it, ec);
    for (auto it = dirs_.rbegin(); it != dirs_.rend(); ++it) std::filesystem::remove(*it, ec);  // only if empty
  }

  // Creates dir (and missing parents), remembering the ones it made.
  void make_dir(const std::filesystem::path& dir) {
    std::vector<std::filesystem::path> missing;
    for (auto p = dir; !p.empty() && !path_exists(p); p = p.parent_path()) {
      missing.push_back(p);
      if (p == p.parent_path()) break;
    }
    make_directories(dir);
    dirs_.insert(dirs_.end(), missing.rbegin(), missing.rend());
  }
  // Registers a file about to be written (call before writing it).
  std::filesystem::path add(const std::filesystem::path& file) {
    if (!path_exists(file)) files_.push_back(file);
    return file;
  }
  // Checks that a file does not exist yet unless overwriting is allowed.
  static void check_new(const std::filesystem::path& file, bool overwrite) {
    require<FileError>(overwrite || !path_exists(file), "'", file.string(),
                       "' exists; pass --force to overwrite it");
  }
  void commit() { committed_ = true; }

 private:
  std::vector<std::filesystem::path> files_, dirs_;
  bool committed_ = false;
};

// A CSV field: as it is, or double-quoted (quotes doubled) when it holds a comma, quote or newline.
inline std::string csv_field(const std::string& v) {
  if (v.find_first_of(",\"\n") == std::string::npos) return v;
  std::string q = "\"";
  for (char ch : v) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
  return q + "\"";
}

inline std::string format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "--:--";
  const auto s = static_cast<long long>(seconds + 0.5);
  char buf[32];
  if (s >= 3600)
    std::snprintf(buf, sizeof buf, "%lld:%02lld:%02lld", s / 3600, s / 60 % 60, s % 60);
  else
    std::snprintf(buf, sizeof buf, "%lld:%02lld", s / 60, s % 60);
  return buf;
}

// A progress line on stderr: "<label> [#####.....] 120/600 <extra> | 31.2 win/s | ETA 4:32".
// On a terminal it redraws in place; otherwise (a log file, CI) it prints a line every few
// seconds, so a long run never looks dead.
class ProgressLine {
 public:
  ProgressLine(std::string label, std::int64_t total, bool quiet = false)
      : label_(std::move(label)), total_(std::max<std::int64_t>(total, 1)), quiet_(quiet),
        tty_(::isatty(::fileno(stderr)) != 0), start_(clock::now()), last_(start_) {}

  double elapsed() const { return std::chrono::duration<double>(clock::now() - start_).count(); }

  // done of total units finished; items (windows) processed so far give the rate.
  void update(std::int64_t done, std::int64_t items, const std::string& extra) {
    if (quiet_) return;
    const auto now = clock::now();
    const bool last = done >= total_;
    if (!tty_ && !last && std::chrono::duration<double>(now - last_).count() < 5.0 && done != 1) return;
    if (tty_ && !last && std::chrono::duration<double>(now - last_).count() < 0.2) return;
    last_ = now;
    const double t = elapsed();
    const double rate = t > 0.05 ? static_cast<double>(items) / t : 0.0;  // no rate from a first instant
    const double eta = done > 0 ? t * static_cast<double>(total_ - done) / static_cast<double>(done) : NAN;
    constexpr int width = 24;
    const int fill = static_cast<int>(width * static_cast<double>(done) / static_cast<double>(total_));
    std::string bar(static_cast<std::size_t>(fill), '#');
    bar.resize(width, '.');
    std::fprintf(stderr, "%s%s [%s] %lld/%lld %s | %.1f win/s | %s %s%s", tty_ ? "\r" : "", label_.c_str(),
                 bar.c_str(), static_cast<long long>(done), static_cast<long long>(total_), extra.c_str(), rate,
                 last ? "took" : "ETA", format_duration(last ? t : eta).c_str(), tty_ ? "\033[K" : "\n");
    if (tty_ && last) std::fputc('\n', stderr);
    std::fflush(stderr);
  }

 private:
  using clock = std::chrono::steady_clock;
  std::string label_;
  std::int64_t total_;
  bool quiet_, tty_;
  clock::time_point start_, last_;
};

// A CSV table: a header and rows of numbers, written atomically.
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<double>> rows;

  std::string str() const {
    std::ostringstream o;
    o.precision(8);
    for (std::size_t j = 0; j < header.size(); ++j) o << (j ? "," : "") << header[j];
    o << '\n';
    for (const auto& r : rows) {
      for (std::size_t j = 0; j < r.size(); ++j) o << (j ? "," : "") << r[j];
      o << '\n';
    }
    return o.str();
  }
  // Column j of every row.
  std::vector<double> column(std::size_t j) const {
    std::vector<double> c;
    for (const auto& r : rows) c.push_back(r.at(j));
    return c;
  }
};

struct CurveSeries {
  std::string name;
  std::vector<double> y;  // one value per x
  std::string color;
};

// A line plot of series over x, y on a log scale when every value is positive (losses span
// decades), as a standalone SVG document.
inline std::string curve_svg(const std::vector<double>& x, const std::vector<CurveSeries>& series,
                             const std::string& title, const std::string& x_label) {
  constexpr double W = 720, H = 400, ml = 70, mr = 150, mt = 40, mb = 50;
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  bool positive = true;
  for (double v : x) x0 = std::min(x0, v), x1 = std::max(x1, v);
  for (const auto& s : series)
    for (double v : s.y)
      if (std::isfinite(v)) y0 = std::min(y0, v), y1 = std::max(y1, v), positive = positive && v > 0;
  if (!(x1 > x0)) x1 = x0 + 1;
  if (!std::isfinite(y0)) y0 = 0, y1 = 1;
  const bool logy = positive && y1 / y0 > 20;
  auto ty = [&](double v) { return logy ? std::log10(v) : v; };
  double ly0 = ty(y0), ly1 = ty(y1);
  if (!(ly1 > ly0)) ly1 = ly0 + 1;
  auto px = [&](double v) { return ml + (v - x0) / (x1 - x0) * (W - ml - mr); };
  auto py = [&](double v) { return H - mb - (ty(v) - ly0) / (ly1 - ly0) * (H - mt - mb); };
  std::ostringstream o;
  o.precision(5);
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H << "\" viewBox=\"0 0 " << W
    << ' ' << H << "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<text x=\"" << W / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">" << xml_escape(title)
    << "</text>\n";
  o << "<rect x=\"" << ml << "\" y=\"" << mt << "\" width=\"" << W - ml - mr << "\" height=\"" << H - mt - mb
    << "\" fill=\"none\" stroke=\"#444\"/>\n";
  for (int k = 0; k <= 4; ++k) {  // y ticks
    const double lv = ly0 + (ly1 - ly0) * k / 4.0, v = logy ? std::pow(10.0, lv) : lv;
    const double y = py(v);
    o << "<line x1=\"" << ml << "\" x2=\"" << W - mr << "\" y1=\"" << y << "\" y2=\"" << y
      << "\" stroke=\"#ddd\"/><text x=\"" << ml - 6 << "\" y=\"" << y + 4 << "\" text-anchor=\"end\">" << v
      << "</text>\n";
  }
  for (int k = 0; k <= 4; ++k) {  // x ticks
    const double v = x0 + (x1 - x0) * k / 4.0;
    o << "<text x=\"" << px(v) << "\" y=\"" << H - mb + 18 << "\" text-anchor=\"middle\">" << std::llround(v)
      << "</text>\n";
  }
  o << "<text x=\"" << ml + (W - ml - mr) / 2 << "\" y=\"" << H - 10 << "\" text-anchor=\"middle\">"
    << xml_escape(x_label) << (logy ? " (log y)" : "") << "</text>\n";
  for (std::size_t s = 0; s < series.size(); ++s) {
    const auto& c = series[s];
    o << "<polyline fill=\"none\" stroke=\"" << c.color << "\" stroke-width=\"1.5\" points=\"";
    for (std::size_t i = 0; i < c.y.size() && i < x.size(); ++i)
      if (std::isfinite(c.y[i]) && (!logy || c.y[i] > 0)) o << px(x[i]) << ',' << py(c.y[i]) << ' ';
    o << "\"/>\n";
    const double ly = mt + 16 + 18.0 * static_cast<double>(s);
    o << "<line x1=\"" << W - mr + 10 << "\" x2=\"" << W - mr + 30 << "\" y1=\"" << ly - 4 << "\" y2=\"" << ly - 4
      << "\" stroke=\"" << c.color << "\" stroke-width=\"2\"/><text x=\"" << W - mr + 36 << "\" y=\"" << ly << "\">"
      << xml_escape(c.name) << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

}  // namespace tjepa::cli
