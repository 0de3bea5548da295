#pragma once
// serial:DEVICE[@BAUD] — an AnySkin / ReSkin board over USB serial (termios). The board's binary
// burst stream: per frame, for each of its magnetometers, four float32 (t, x, y, z: temperature
// and the magnetic field) in the host's byte order, then "\r\n" (AnySkin's
// 5X_binary_burst_stream firmware and its Python reader). A model of m = 3 axes reads x, y, z
// (the temperature dropped, as AnySkin's reader does by default); m = 4 reads all four.
//
// Framing: a frame is 16·N + 2 bytes ending in "\r\n". A frame that does not end so (bytes lost,
// the stream joined mid-frame) is counted as "resync", its bytes are dropped through the next
// "\r\n", and the next good frame is marked as a gap. A frame with a non-finite value is counted
// and dropped (a gap too). The device gone (unplugged: read() fails) is counted as "reconnect"
// and reopened with backoff, up to `reconnects` times.
#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <tjepa/tjepa.hpp>

#include "frame_source.hpp"

namespace tjepa::cli {

// The byte framing alone (no device): feed() bytes, then take() whole frames.
class AnySkinDecoder {
 public:
  AnySkinDecoder(int magnetometers, int axes) : mags_(magnetometers), axes_(axes) {
    require<ConfigError>(magnetometers > 0 && (axes == 3 || axes == 4), "AnySkin: ", magnetometers,
                         " magnetometers of ", axes, " axes; the board sends (t, x, y, z) per magnetometer, so a "
                         "model of 3 (x, y, z) or 4 axes reads it");
    buf_.reserve(static_cast<std::size_t>(frame_bytes()) * 64);
  }
  int frame_bytes() const { return 16 * mags_ + 2; }
  // Room for n more bytes; write into it and call fed(n).
  std::uint8_t* room(std::size_t n) {
    if (buf_.size() - end_ < n) {
      std::copy(buf_.begin() + static_cast<std::ptrdiff_t>(begin_), buf_.begin() + static_cast<std::ptrdiff_t>(end_),
                buf_.begin());
      end_ -= begin_;
      begin_ = 0;
      if (buf_.size() - end_ < n) buf_.resize(end_ + n);
    }
    return buf_.data() + end_;
  }
  void fed(std::size_t n) { end_ += n; }
  void feed(std::span<const std::uint8_t> bytes) {
    std::copy(bytes.begin(), bytes.end(), room(bytes.size()));
    fed(bytes.size());
  }
  // The next whole frame into frame [N·m], or false when more bytes are needed. gap: bytes or
  // frames were dropped before it. resyncs / bad counted into the references.
  bool take(std::span<float> frame, bool& gap, std::int64_t& resyncs, std::int64_t& non_finite) {
    const std::size_t L = static_cast<std::size_t>(frame_bytes());
    while (end_ - begin_ >= L) {
      const std::uint8_t* f = buf_.data() + begin_;
      if (f[L - 2] != '\r' || f[L - 1] != '\n') {
        // Lost alignment: drop through the next "\r\n" (or all but the last byte, which may be '\r').
        ++resyncs;
        pending_gap_ = true;
        std::size_t k = begin_;
        while (k + 1 < end_ && !(buf_[k] == '\r' && buf_[k + 1] == '\n')) ++k;
        begin_ = k + 1 < end_ ? k + 2 : k;
        continue;
      }
      float v[4];
      bool finite = true;
      for (int g = 0; g < mags_; ++g) {
        std::memcpy(v, f + 16 * g, sizeof v);
        for (int a = 0; a < axes_; ++a) {
          const float x = v[a + 4 - axes_];  // m = 3: x, y, z; m = 4: t, x, y, z
          finite = finite && std::isfinite(x);
          frame[static_cast<std::size_t>(g) * axes_ + a] = x;
        }
      }
      begin_ += L;
      if (!finite) {
        ++non_finite;
        pending_gap_ = true;
        continue;
      }
      gap = pending_gap_;
      pending_gap_ = false;
      return true;
    }
    return false;
  }
  void mark_gap() { pending_gap_ = true; }
  void clear() {
    begin_ = end_ = 0;
    pending_gap_ = true;
  }

 private:
  int mags_, axes_;
  std::vector<std::uint8_t> buf_;
  std::size_t begin_ = 0, end_ = 0;
  bool pending_gap_ = false;
};

class AnySkinSource : public FrameSource {
 public:
  // device: a tty path; magnetometers × axes: the model's taxels × axes; reconnects: how often a
  // vanished device is reopened (−1: for ever), backoff_s: the first wait, doubled up to 5 s.
  AnySkinSource(std::string device, int baud, int magnetometers, int axes, int reconnects, double backoff_s)
      : device_(std::move(device)), baud_(baud), decoder_(magnetometers, axes), reconnects_(reconnects),
        backoff_(backoff_s) {
    speed_ = speed_of(baud_);
    open_device();
  }
  ~AnySkinSource() override { close_device(); }

  bool next(std::span<float> frame, FrameInfo& info) override {
    for (;;) {
      std::int64_t resyncs = 0, bad = 0;
      bool gap = false;
      const bool got = decoder_.take(frame, gap, resyncs, bad);
      if (resyncs) count("resync (a frame not ending in \\r\\n)", resyncs);
      if (bad) count("frame with a non-finite value", bad);
      if (got) {
        info.gap = gap;
        info.time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
        return true;
      }
      if (stop_) return false;
      if (fd_ < 0 && !reopen()) return false;
      std::uint8_t* room = decoder_.room(4096);
      const ssize_t n = ::read(fd_, room, 4096);
      if (n > 0) {
        decoder_.fed(static_cast<std::size_t>(n));
      } else if (n < 0 && (errno == EINTR || errno == EAGAIN)) {
        continue;
      } else if (n < 0 || hangup()) {
        // The device is gone (EIO on a vanished USB tty or a closed pty).
        close_device();
        decoder_.clear();
      }
    }
  }
  void stop() override { stop_ = true; }
  std::string describe() const override {
    return "AnySkin on " + device_ + " at " + std::to_string(baud_) + " baud (" +
           std::to_string(decoder_.frame_bytes()) + "-byte frames)";
  }

 private:
  static speed_t speed_of(int baud) {
    switch (baud) {
      case 9600: return B9600;
      case 19200: return B19200;
      case 38400: return B38400;
      case 57600: return B57600;
      case 115200: return B115200;
      case 230400: return B230400;
      case 460800: return B460800;
      case 921600: return B921600;
      default:
        fail<ConfigError>("serial: baud rate ", baud, ", expected 9600, 19200, 38400, 57600, 115200, 230400, 460800 or 921600");
    }
  }
  void open_device() {
    fd_ = ::open(device_.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
    require<FileError>(fd_ >= 0, "serial: cannot open '", device_, "': ", std::strerror(errno));
    termios tio{};
    if (::tcgetattr(fd_, &tio) == 0) {
      ::cfmakeraw(&tio);
      ::cfsetispeed(&tio, speed_);
      ::cfsetospeed(&tio, speed_);
      tio.c_cc[VMIN] = 0;
      tio.c_cc[VTIME] = 1;  // read() returns after 0.1 s without bytes: stop() is seen
      require<FileError>(::tcsetattr(fd_, TCSANOW, &tio) == 0, "serial: cannot configure '", device_, "': ",
                         std::strerror(errno));
    }
    start_ = std::chrono::steady_clock::now();
  }
  void close_device() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  // read() gave 0 bytes: a timeout (VTIME), or the far end hung up (a pty whose master closed).
  bool hangup() const {
    termios tio{};
    return ::tcgetattr(fd_, &tio) != 0 && errno != ENOTTY;
  }
  bool reopen() {
    double wait = backoff_;
    for (int attempt = 0; reconnects_ < 0 || attempt < reconnects_; ++attempt) {
      if (stop_) return false;
      std::this_thread::sleep_for(std::chrono::duration<double>(wait));
      wait = std::min(2 * wait, 5.0);
      try {
        open_device();
        count("reconnect");
        decoder_.mark_gap();
        return true;
      } catch (const FileError&) {
        count("failed reconnect attempt");
      }
    }
    return false;
  }

  std::string device_;
  int baud_;
  speed_t speed_{};
  AnySkinDecoder decoder_;
  int reconnects_;
  double backoff_;
  int fd_ = -1;
  std::atomic<bool> stop_{false};
  std::chrono::steady_clock::time_point start_;
};

}  // namespace tjepa::cli
