#pragma once
// Atomic file writes: the bytes go to `<path>.tmp.<pid>`, are flushed to the disk, and the temp
// file is renamed over `path`. A reader (or a crash) sees the old file or the new one, never half
// of one, so the last good checkpoint survives a failed save.
#include <cerrno>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <span>
#include <string>
#include <system_error>

#include <fcntl.h>
#include <unistd.h>

#include "tjepa/core/error.hpp"

namespace tjepa {

inline void write_file_atomic(const std::filesystem::path& path, std::span<const std::byte> bytes) {
  const std::filesystem::path tmp = path.string() + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    fail<FileError>(path.string(), ": cannot create temporary file '", tmp.string(), "': ", std::strerror(errno));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ::ssize_t w = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      const int err = errno;
      ::close(fd);
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      fail<FileError>(path.string(), ": write failed after ", done, " of ", bytes.size(),
                      " bytes: ", std::strerror(err));
    }
    done += static_cast<std::size_t>(w);
  }
  const bool synced = ::fsync(fd) == 0;
  const int sync_err = errno;
  const bool closed = ::close(fd) == 0;
  if (!synced || !closed) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    fail<FileError>(path.string(), ": flushing the temporary file failed: ",
                    std::strerror(synced ? errno : sync_err));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    std::filesystem::remove(tmp, ec2);
    fail<FileError>(path.string(), ": cannot rename '", tmp.string(), "' into place: ", ec.message());
  }
}

}  // namespace tjepa
