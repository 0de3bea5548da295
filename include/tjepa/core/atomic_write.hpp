#pragma once
// Atomic, durable file writes. The content goes to a temporary file created exclusively
// (O_CREAT | O_EXCL | O_NOFOLLOW, an unpredictable name) in the target's directory; the file is
// fsync'ed, renamed over the target, and the directory is fsync'ed. A reader sees the old file or
// the new one, never a part; after a power cut the rename is either on disk or not. Every error
// path (a writer that throws, a full disk, a failed rename) removes the temporary file.
//
// Temporary names: `.<name>.tjepa-tmp.<host hash>.<pid>.<random>` beside `<name>`. A process
// killed mid-write leaves one behind; the next write of the same target on the same host removes
// those whose process no longer runs or is a zombie (stale_temporaries lists them). Hosts are
// told apart by name: containers that share a host name and a volume but not a PID namespace must
// not write the same file. Each write lists the target's directory once.
#include <array>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <random>
#include <streambuf>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tjepa/core/error.hpp"
#include "tjepa/core/hash.hpp"

namespace tjepa {

namespace detail {

// A std::streambuf writing to a POSIX file descriptor through a 64 KiB buffer. A failed write
// (ENOSPC, EFBIG, EIO) is remembered with its errno and makes the stream bad.
class FdStreambuf : public std::streambuf {
 public:
  explicit FdStreambuf(int fd) : fd_(fd) { setp(buf_.data(), buf_.data() + buf_.size()); }
  int error() const { return error_; }

 protected:
  int_type overflow(int_type ch) override {
    if (!flush_buffer()) return traits_type::eof();
    if (!traits_type::eq_int_type(ch, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(ch);
      pbump(1);
    }
    return traits_type::not_eof(ch);
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    if (n >= static_cast<std::streamsize>(buf_.size())) {  // large blocks go straight to the file
      if (!flush_buffer() || !write_all(s, static_cast<std::size_t>(n))) return 0;
      return n;
    }
    return std::streambuf::xsputn(s, n);
  }
  int sync() override { return flush_buffer() ? 0 : -1; }

 private:
  bool flush_buffer() {
    const std::size_t n = static_cast<std::size_t>(pptr() - pbase());
    const bool ok = write_all(pbase(), n);
    setp(buf_.data(), buf_.data() + buf_.size());
    return ok;
  }
  bool write_all(const char* p, std::size_t n) {
    if (error_ != 0) return false;
    while (n > 0) {
      const ::ssize_t w = ::write(fd_, p, n);
      if (w < 0) {
        if (errno == EINTR) continue;
        error_ = errno;
        return false;
      }
      p += w;
      n -= static_cast<std::size_t>(w);
    }
    return true;
  }

  int fd_;
  int error_ = 0;
  std::array<char, 1 << 16> buf_{};
};

// `.<name>.tjepa-tmp.<host>.`; a name over 64 bytes is cut to 40 plus a hash, the host is
// hashed, so the temporary name stays within NAME_MAX whenever the target's name does.
inline std::string temporary_prefix(const std::filesystem::path& path) {
  std::array<char, 256> host{};
  if (::gethostname(host.data(), host.size() - 1) != 0) host[0] = '\0';
  std::string name = path.filename().string();
  if (name.size() > 64) name = name.substr(0, 40) + "~" + short_hash(name);
  return "." + name + ".tjepa-tmp." + short_hash(host.data()).substr(0, 8) + ".";
}

inline std::uint64_t temporary_nonce() {
  static thread_local std::mt19937_64 gen([] {
    std::random_device rd;
    const auto t = static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
    return (static_cast<std::uint64_t>(rd()) << 32) ^ rd() ^ t ^ static_cast<std::uint64_t>(::getpid());
  }());
  return gen();
}

// fsync of a directory, so that a rename inside it is on disk. Best effort: it runs after the
// rename, when the new file is already in place, so a directory that cannot be opened for reading
// (mode 0300) or a file system that cannot sync directories does not turn a done write into an
// error.
inline void sync_directory(const std::filesystem::path& dir) noexcept {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

// Whether process pid may still write: it exists (kill(pid, 0); EPERM: not ours, but it exists)
// and, where /proc tells, is not a zombie, a process that has ended and waits to be reaped (as
// a killed MPI rank can for a while after mpirun returns).
inline bool process_runs(long long pid) {
  if (::kill(static_cast<::pid_t>(pid), 0) != 0 && errno == ESRCH) return false;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return true;  // no /proc: trust kill
  const std::size_t close = line.rfind(')');     // "pid (comm) state ...", comm may hold spaces
  if (close == std::string::npos || close + 2 >= line.size()) return true;
  const char state = line[close + 2];
  return state != 'Z' && state != 'X';
}

}  // namespace detail

// The temporary files of earlier writes of `path` on this host whose process no longer runs
// (killed mid-write). write_file_atomic removes them; exposed for tests and tools.
inline std::vector<std::filesystem::path> stale_temporaries(const std::filesystem::path& path) {
  std::vector<std::filesystem::path> stale;
  const std::filesystem::path dir = path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path();
  const std::string prefix = detail::temporary_prefix(path);
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    // <pid>.<random>
    const std::string rest = name.substr(prefix.size());
    const std::size_t dot = rest.find('.');
    if (dot == 0 || dot == std::string::npos || dot > 10) continue;
    long long pid = 0;
    bool digits = true;
    for (std::size_t i = 0; i < dot; ++i) {
      if (rest[i] < '0' || rest[i] > '9') digits = false;
      else pid = pid * 10 + (rest[i] - '0');
    }
    if (!digits || pid <= 0 || pid == static_cast<long long>(::getpid())) continue;
    if (detail::process_runs(pid)) continue;
    std::error_code lec;
    if (std::filesystem::is_symlink(it->symlink_status(lec)) || !std::filesystem::is_regular_file(it->symlink_status(lec)))
      continue;
    stale.push_back(it->path());
  }
  return stale;
}

// Streams the content: write(std::ostream&) fills the temporary file, which then replaces `path`.
// Large outputs (a .npy of embeddings) never need to exist in memory as one string. If `write`
// throws, the exception propagates and the temporary file is removed; `path` is untouched.
template <class Writer>
void write_file_atomic_with(const std::filesystem::path& path, Writer&& write) {
  namespace fs = std::filesystem;
  require<FileError>(!path.filename().empty(), "write_file_atomic: '", path.string(), "' names no file");
  const fs::path dir = path.parent_path();
  for (const fs::path& s : stale_temporaries(path)) {
    std::error_code ec;
    fs::remove(s, ec);
  }
  const std::string prefix = detail::temporary_prefix(path) + std::to_string(::getpid()) + ".";
  fs::path tmp;
  int fd = -1;
  for (int attempt = 0; attempt < 16 && fd < 0; ++attempt) {
    tmp = dir / (prefix + std::to_string(detail::temporary_nonce() % 1000000000000ull));
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) break;
  }
  const int open_err = errno;
  require<FileError>(fd >= 0, "write_file_atomic: cannot create a temporary file for '", path.string(), "' in '",
                     (dir.empty() ? fs::path(".") : dir).string(), "': ", std::strerror(open_err));
  auto discard = [&] {
    if (fd >= 0) ::close(fd);
    fd = -1;
    std::error_code ec;
    fs::remove(tmp, ec);
  };
  try {
    detail::FdStreambuf buf(fd);
    std::ostream out(&buf);
    out.exceptions(std::ios::goodbit);
    write(out);
    out.flush();
    if (!out || buf.error() != 0)
      fail<FileError>("write_file_atomic: writing '", path.string(), "' failed: ",
                      buf.error() != 0 ? std::strerror(buf.error()) : "the writer's stream went bad");
    int rc = ::fsync(fd);
    int err = errno;
    require<FileError>(rc == 0, "write_file_atomic: cannot sync '", path.string(), "': ", std::strerror(err));
    rc = ::close(fd);
    err = errno;
    fd = -1;
    require<FileError>(rc == 0, "write_file_atomic: closing '", path.string(), "' failed: ", std::strerror(err));
    // rename(2) replaces a symlink at `path` itself (never its target) and is atomic.
    rc = ::rename(tmp.c_str(), path.c_str());
    err = errno;
    require<FileError>(rc == 0, "write_file_atomic: cannot rename '", tmp.string(), "' to '", path.string(), "': ",
                       std::strerror(err));
  } catch (...) {
    discard();
    throw;
  }
  detail::sync_directory(dir);
}

inline void write_file_atomic(const std::filesystem::path& path, std::string_view content) {
  write_file_atomic_with(path, [&](std::ostream& out) {
    out.write(content.data(), static_cast<std::streamsize>(content.size()));
  });
}

}  // namespace tjepa
