#pragma once
// A read-only view of a whole file's bytes: memory-mapped where the platform has mmap (and copy is
// false), so a multi-GB recording is paged in by the kernel and never copied; otherwise read into
// memory once. A mapping promises nothing if the file is truncated or rewritten in place while it
// lives: reading a page past the new end kills the process with SIGBUS. Replacing the file by
// rename (as tjepa's writers do) is safe: the mapping keeps the old file.
#include <cerrno>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "tjepa/core/error.hpp"

#if __has_include(<sys/mman.h>) && __has_include(<fcntl.h>) && __has_include(<unistd.h>)
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#define TJEPA_HAS_MMAP 1
#else
#define TJEPA_HAS_MMAP 0
#endif

namespace tjepa::detail {

class MappedFile {
 public:
  explicit MappedFile(const std::filesystem::path& path, bool copy = false) : path_(path.string()) {
    std::error_code ec;
    require<FileError>(std::filesystem::is_regular_file(path, ec), path_,
                       ": no such file (or not a regular file)");
    if (copy || !TJEPA_HAS_MMAP) {
      read_copy(path);
      return;
    }
#if TJEPA_HAS_MMAP
    const int fd = ::open(path_.c_str(), O_RDONLY);
    require<FileError>(fd >= 0, path_, ": cannot open: ", std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
      ::close(fd);
      fail<FileError>(path_, ": cannot stat: ", std::strerror(errno));
    }
    size_ = static_cast<std::size_t>(st.st_size);
    if (size_ > 0) {
      void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
      if (p == MAP_FAILED) {
        ::close(fd);
        fail<FileError>(path_, ": cannot map ", size_, " bytes: ", std::strerror(errno));
      }
      map_ = p;
      data_ = static_cast<const char*>(p);
    }
    ::close(fd);
#endif
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  ~MappedFile() {
#if TJEPA_HAS_MMAP
    if (map_ != nullptr) ::munmap(map_, size_);
#endif
  }

  const char* data() const { return data_; }
  std::size_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  // Reads the whole file into buffer_; a file that changes size while it is read is an error.
  void read_copy(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    require<FileError>(in.good(), path_, ": cannot open");
    in.seekg(0, std::ios::end);
    const auto end = in.tellg();
    require<FileError>(end >= 0, path_, ": cannot find the file's size");
    size_ = static_cast<std::size_t>(end);
    in.seekg(0);
    buffer_.resize(size_);
    in.read(buffer_.data(), static_cast<std::streamsize>(size_));
    require<FileError>(static_cast<std::size_t>(in.gcount()) == size_, path_, ": read ", in.gcount(), " of ", size_,
                       " bytes (the file changed while it was read)");
    data_ = buffer_.data();
  }

  std::string path_;
  const char* data_ = nullptr;
  std::size_t size_ = 0;
#if TJEPA_HAS_MMAP
  void* map_ = nullptr;
#endif
  std::vector<char> buffer_;
};

}  // namespace tjepa::detail
