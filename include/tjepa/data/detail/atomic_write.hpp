#pragma once
// Atomic file writes: the bytes go to `<path>.tmp.<pid>`, then one rename replaces `path`, so a
// reader never sees a half-written file and a crash leaves the old file intact.
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include "tjepa/core/error.hpp"

#if __has_include(<unistd.h>)
#include <unistd.h>
#endif

namespace tjepa::detail {

inline long process_id() {
#if __has_include(<unistd.h>)
  return static_cast<long>(::getpid());
#else
  return 0;
#endif
}

// Calls write(std::ostream&) on a temporary file next to `path`, then renames it over `path`.
template <class Writer>
void write_file_atomically(const std::filesystem::path& path, Writer&& write) {
  const std::filesystem::path tmp = path.string() + ".tmp." + std::to_string(process_id());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    require<FileError>(out.good(), path.string(), ": cannot open '", tmp.string(), "' for writing");
    write(out);
    out.flush();
    if (!out.good()) {
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      fail<FileError>(path.string(), ": write error (disk full?)");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    std::filesystem::remove(tmp, ec2);
    fail<FileError>(path.string(), ": cannot rename '", tmp.string(), "' into place: ", ec.message());
  }
}

}  // namespace tjepa::detail
