#pragma once
// A fresh temporary directory per test, removed with everything in it at the end:
// <temp>/tjepa_<tag>_<pid>_<n>, so that runs side by side never share one.
#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace tjepa_test {

struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& tag = "test") {
    static int counter = 0;
    path = std::filesystem::temp_directory_path() /
           ("tjepa_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::filesystem::path operator/(const std::string& name) const { return path / name; }
};

}  // namespace tjepa_test
