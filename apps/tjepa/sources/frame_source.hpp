#pragma once
// Live sources of frames for `tjepa run`, each behind one interface: the xServer WebSocket client
// (Xela uSkin), the AnySkin serial reader, and a replay of a recording at its rate.
//
// A source delivers frames [N, m] in the sensor's own taxel order (the recording's column order),
// and says when frames were lost before one (`gap`): a reconnect, a malformed message, a frame of
// the wrong size, a jump in the sensor's clock. The caller then starts a new window, so that no
// window is ever built from frames on both sides of a gap. Every such event is counted by kind
// and reported at the end; none is silently passed over.
#include <cstdint>
#include <map>
#include <span>
#include <string>

namespace tjepa::cli {

struct FrameInfo {
  double time = 0;     // the sensor's clock, seconds (the replay's: frame / rate)
  bool gap = false;    // frames were lost between the previous frame and this one
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Blocks until the next frame, written into frame [N·m]; false when the stream has ended (the
  // recording is over, the peer is gone for good, or stop() was called).
  virtual bool next(std::span<float> frame, FrameInfo& info) = 0;
  // Asks a blocked next() to return false soon (from a signal handler's flag, another thread).
  virtual void stop() = 0;
  // What went wrong so far, by kind ("malformed message": 2, "reconnect": 1, ...).
  const std::map<std::string, std::int64_t>& problems() const { return problems_; }
  virtual std::string describe() const = 0;

 protected:
  void count(const std::string& kind, std::int64_t n = 1) { problems_[kind] += n; }
  std::map<std::string, std::int64_t> problems_;
};

}  // namespace tjepa::cli
