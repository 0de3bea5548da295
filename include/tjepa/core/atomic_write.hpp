#pragma once
// Atomic file writes: the content goes to `<path>.tmp.<pid>`, then std::filesystem::rename puts it
// in place, so a reader never sees a half-written file and a failed write leaves the old file.
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <string_view>
#include <system_error>

#include <unistd.h>

#include "tjepa/core/error.hpp"

namespace tjepa {

// Streams the content: write(std::ostream&) fills the temporary file, which then replaces `path`.
// Large outputs (a .npy of embeddings) never need to exist in memory as one string.
template <class Writer>
void write_file_atomic_with(const std::filesystem::path& path, Writer&& write) {
  const std::filesystem::path tmp = path.string() + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    require<FileError>(static_cast<bool>(out), "write_file_atomic: cannot open '", tmp.string(), "' for writing");
    write(static_cast<std::ostream&>(out));
    out.flush();
    if (!out) {
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      fail<FileError>("write_file_atomic: writing '", tmp.string(), "' failed");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    std::filesystem::remove(tmp, ec2);
    fail<FileError>("write_file_atomic: cannot rename '", tmp.string(), "' to '", path.string(), "': ",
                    ec.message());
  }
}

inline void write_file_atomic(const std::filesystem::path& path, std::string_view content) {
  write_file_atomic_with(path, [&](std::ostream& out) {
    out.write(content.data(), static_cast<std::streamsize>(content.size()));
  });
}

}  // namespace tjepa
