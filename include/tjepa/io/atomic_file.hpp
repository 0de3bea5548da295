#pragma once
// Atomic file writes: the bytes go to `<path>.tmp.<pid>` and one rename replaces `path`. A reader
// (or a crash) sees the old file or the new one, never half of one, so the last good checkpoint
// survives a failed save. The mechanism is core/atomic_write.hpp's (one implementation
// for every file tjepa writes); this is its byte-buffer form.
#include <cstddef>
#include <filesystem>
#include <ostream>
#include <span>

#include "tjepa/core/atomic_write.hpp"

namespace tjepa {

inline void write_file_atomic(const std::filesystem::path& path, std::span<const std::byte> bytes) {
  write_file_atomic_with(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  });
}

}  // namespace tjepa
