#pragma once
// A small CSV table reader for the layout files: comma-separated fields, optional double quotes
// (a "" inside quotes is one "), surrounding blanks trimmed, blank lines and lines starting with
// '#' skipped. Each row keeps its 1-based line number for error messages.
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "tjepa/core/error.hpp"

namespace tjepa::detail {

struct CsvRow {
  int line = 0;
  std::vector<std::string> fields;
};

inline std::string trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return std::string(s.substr(b, e - b + 1));
}

inline std::vector<CsvRow> read_csv_rows(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  require<FileError>(static_cast<bool>(in), path.string(), ": cannot open for reading");
  std::vector<CsvRow> rows;
  std::string line;
  int no = 0;
  while (std::getline(in, line)) {
    ++no;
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    CsvRow row{no, {}};
    std::string field;
    bool quoted = false, was_quoted = false;
    for (std::size_t k = 0; k < t.size(); ++k) {
      const char c = t[k];
      if (quoted) {
        if (c == '"' && k + 1 < t.size() && t[k + 1] == '"') field += '"', ++k;
        else if (c == '"') quoted = false;
        else field += c;
      } else if (c == '"') {
        quoted = was_quoted = true;
      } else if (c == ',') {
        row.fields.push_back(was_quoted ? field : trim(field));
        field.clear();
        was_quoted = false;
      } else {
        field += c;
      }
    }
    require<FileError>(!quoted, path.string(), ":", no, ": unterminated quote");
    row.fields.push_back(was_quoted ? field : trim(field));
    rows.push_back(std::move(row));
  }
  return rows;
}

inline std::string where(const std::filesystem::path& path, int line) {
  return path.string() + ":" + std::to_string(line) + ": ";
}

inline long long parse_integer(const std::filesystem::path& path, int line, const std::string& column,
                               const std::string& s) {
  long long v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  require<FileError>(ec == std::errc() && p == s.data() + s.size() && !s.empty(), where(path, line), "column '",
                     column, "': '", s, "' is not an integer");
  return v;
}

inline double parse_real(const std::filesystem::path& path, int line, const std::string& column, const std::string& s) {
  double v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  require<FileError>(ec == std::errc() && p == s.data() + s.size() && !s.empty(), where(path, line), "column '",
                     column, "': '", s, "' is not a number");
  return v;
}

// Shortest text that reads back as exactly v.
inline std::string format_real(double v) {
  char buf[64];
  const auto [p, ec] = std::to_chars(buf, buf + sizeof buf, v);
  (void)ec;
  return std::string(buf, p);
}

// Quotes a text field when it holds a comma, a quote or surrounding blanks, or starts with '#'.
inline std::string csv_field(const std::string& s) {
  const bool needs = s.find_first_of(",\"") != std::string::npos || (!s.empty() && (s[0] == '#' || s[0] == ' ' ||
                                                                                      s.back() == ' '));
  if (!needs) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

}  // namespace tjepa::detail
