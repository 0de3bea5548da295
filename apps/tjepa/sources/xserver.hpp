#pragma once
// ws://HOST:PORT — XELA's xServer, which streams Xela uSkin readings as JSON over a WebSocket
// (port 5000 by default): a first message {"message": "Welcome", ...}, then one message per frame
// with "message", "time" (seconds), "sensors" (their count) and one entry per sensor keyed "1",
// "2", ...: "sensor", "model", "taxels", "data" (hex), "integer" (taxels × 3 readings), optionally
// "calibrated", and "temp". The Allegro hand's curved skin (model XR23AHLCPP) arrives as one entry
// of 368 taxels in point_id order (tjepa's taxel order "xserver").
//
// A frame is the sensors' "integer" readings in key order ("1", "2", ...), which must add up to the
// model's N taxels × m axes. What is not such a frame is counted and never reaches a window:
//   malformed message   not JSON, or a frame message without its fields of the right types
//   wrong taxel count   the sensors' taxels do not add up to the model's
//   time gap            the sensor's clock jumped by more than 2.5 periods (frames lost), or ran
//                       backwards
//   reconnect           the connection dropped (or was silent for `idle_timeout_s`) and was made again,
//                       with backoff from `backoff_s` doubling up to 5 s, `reconnects` times (−1: ever)
// and the next good frame is marked as a gap, so the pipeline starts a new window.
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "frame_source.hpp"

namespace tjepa::cli {

// One xServer message: a frame (written into frame [N·m]), the welcome or another message without
// readings, malformed, or a frame of the wrong size. why: what was wrong.
enum class XServerMessage { frame, other, malformed, wrong_size };
XServerMessage parse_xserver_message(std::string_view text, std::span<float> frame, int axes, double& time,
                                     std::string& why);

struct XServerOptions {
  std::string host = "127.0.0.1";
  std::string port = "5000";
  std::string target = "/";
  int taxels = 0, axes = 3;     // the model's
  double rate = 100;            // the sensor's frame rate (Hz), for the time-gap check
  int reconnects = -1;          // −1: for ever
  double backoff_s = 0.1;       // first wait before reconnecting
  double idle_timeout_s = 2.0;  // no message for this long: the connection is taken as dropped
};

// "ws://HOST[:PORT][/PATH]" → host, port, target (port 5000 when none is given).
XServerOptions parse_ws_url(const std::string& url);

class XServerSource : public FrameSource {
 public:
  explicit XServerSource(XServerOptions o);
  ~XServerSource() override;
  bool next(std::span<float> frame, FrameInfo& info) override;
  void stop() override;
  std::string describe() const override;

 private:
  struct Connection;
  XServerOptions o_;
  std::unique_ptr<Connection> c_;
};

}  // namespace tjepa::cli
