#pragma once
// Checks on the paths a user names, through std::filesystem's non-throwing overloads only: a name
// the system refuses (too long, a loop of links, no permission) becomes a FileError that names the
// path and the system's reason, never a std::filesystem::filesystem_error.
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>

#include "tjepa/core/error.hpp"

namespace tjepa {

// What keeps `path` from being read as an input file: empty when it can be opened for reading as
// far as its type tells (a regular file, a pipe, a device; links followed), else "no such file",
// "a directory, not a file" or the system's reason ("File name too long", "Permission denied").
inline std::string input_file_problem(const std::filesystem::path& path) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (st.type() == std::filesystem::file_type::not_found) return "no such file";
  if (ec) return ec.message();
  if (std::filesystem::is_directory(st)) return "a directory, not a file";
  return {};
}

// Throws FileError "<where><what> '<path>': <problem>" unless `path` is an input file.
inline void require_input_file(const std::filesystem::path& path, std::string_view what, std::string_view where = {}) {
  const std::string problem = input_file_problem(path);
  require<FileError>(problem.empty(), where, what, " '", path.string(), "': ", problem);
}

// Creates the directory `dir` and its missing parents; FileError "cannot create <what> '<dir>':
// <reason>" if it cannot, or if something other than a directory is there.
inline void make_directories(const std::filesystem::path& dir, std::string_view what = "the output directory") {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  const bool made = !ec && std::filesystem::is_directory(dir, ec);
  require<FileError>(made, "cannot create ", what, " '", dir.string(), "': ",
                     ec ? ec.message() : std::string("something other than a directory is there"));
}

// Whether anything is at `path`; a name the system refuses counts as nothing there.
inline bool path_exists(const std::filesystem::path& path) noexcept {
  std::error_code ec;
  return std::filesystem::exists(path, ec);
}

}  // namespace tjepa
