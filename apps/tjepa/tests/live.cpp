// Live sources of `tjepa run` against real peers on loopback: the xServer WebSocket client against
// a test server that speaks XELA's protocol (welcome, frames, a malformed message, a frame of the
// wrong taxel count, a jump of the clock, a dropped link and a reconnect), the AnySkin serial
// reader on a pseudo-terminal (openpty) that plays the board's binary stream (split writes, a
// stream joined mid-frame, a non-finite frame, the device gone), and the message and byte parsers
// on their own.
#include <doctest/doctest.h>

#include <pty.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "../sources/anyskin.hpp"
#include "../sources/replay.hpp"
#include "../sources/xserver.hpp"
#include "xserver_peer.hpp"

namespace {
using namespace tjepa;
using namespace tjepa::cli;

// Frame t of a test stream [N·m]: distinct integer readings.
std::vector<float> stream_frame(int t, int N, int m) {
  std::vector<float> f(static_cast<std::size_t>(N) * m);
  for (std::size_t k = 0; k < f.size(); ++k) f[k] = static_cast<float>(30000 + 100 * t + static_cast<int>(k));
  return f;
}

// The AnySkin board's bytes of one frame: per magnetometer t, x, y, z as float32, then "\r\n".
std::vector<std::uint8_t> anyskin_bytes(const std::vector<float>& xyz, float temperature = 25.0f) {
  std::vector<std::uint8_t> b;
  for (std::size_t g = 0; g < xyz.size() / 3; ++g) {
    const float v[4] = {temperature, xyz[3 * g], xyz[3 * g + 1], xyz[3 * g + 2]};
    const auto* p = reinterpret_cast<const std::uint8_t*>(v);
    b.insert(b.end(), p, p + sizeof v);
  }
  b.push_back('\r');
  b.push_back('\n');
  return b;
}
}  // namespace

TEST_SUITE("cli") {

TEST_CASE("xServer messages: the welcome / a frame of two sensors in key order / wrong taxel count / malformed") {
  std::vector<float> frame(4 * 3, -1.0f);
  double time = 0;
  std::string why;
  CHECK(parse_xserver_message(tjepa_test::xserver_welcome(), frame, 3, time, why) == XServerMessage::other);
  const std::vector<float> values = stream_frame(2, 4, 3);
  CHECK(parse_xserver_message(tjepa_test::xserver_frame(12.5, values, 3, 2), frame, 3, time, why) == XServerMessage::frame);
  CHECK(frame == values);
  CHECK(time == 12.5);
  std::vector<float> five(5 * 3);
  CHECK(parse_xserver_message(tjepa_test::xserver_frame(1, values, 3), five, 3, time, why) == XServerMessage::wrong_size);
  CHECK(why == "4 taxels, the model has 5");
  CHECK(parse_xserver_message("{\"sensors\": 1, \"time\": 1, \"1\": {\"taxels\": 4, \"integer\": [1, 2]}}", frame, 3,
                              time, why) == XServerMessage::wrong_size);
  CHECK(why == "sensor \"1\": 2 readings for 4 taxels of 3 axes");
  CHECK(parse_xserver_message("{\"sensors\": 1, \"time\": 1", frame, 3, time, why) == XServerMessage::malformed);
  CHECK(parse_xserver_message("{\"sensors\": 2, \"time\": 1, \"1\": {\"taxels\": 0, \"integer\": []}}", frame, 3, time,
                              why) == XServerMessage::malformed);
  CHECK(why == "no sensor entry \"2\"");
  CHECK(parse_xserver_message("{\"sensors\": 1, \"1\": {\"taxels\": 4, \"integer\": []}}", frame, 3, time, why) ==
        XServerMessage::malformed);
  CHECK(why == "no numeric 'time'");
  CHECK(parse_ws_url("ws://robot.local").port == "5000");
  CHECK(parse_ws_url("ws://10.0.0.2:5001/x").target == "/x");
  CHECK_THROWS_AS(parse_ws_url("http://10.0.0.2"), ConfigError);
  CHECK_THROWS_AS(parse_ws_url("ws://host:99999"), ConfigError);
}

TEST_CASE("xServer client against a loopback peer: frames in order / faults counted and marked as gaps / a dropped link reconnected / the end") {
  const int N = 4, m = 3;
  // Connection 1: welcome, frames 0-4, a malformed message, frames 5-6, a frame of 3 taxels,
  // frames 7-8, then the link drops. Connection 2: welcome, frames 9-10, frame 14 (the clock
  // jumps: 11-13 lost), 15, then a normal close; then the peer stops listening.
  std::vector<std::string> first{tjepa_test::xserver_welcome()}, second{tjepa_test::xserver_welcome()};
  auto frame_msg = [&](int t) { return tjepa_test::xserver_frame(0.01 * t, stream_frame(t, N, m), m); };
  for (int t = 0; t < 5; ++t) first.push_back(frame_msg(t));
  first.push_back("{\"message\": \"\", \"time\": ");
  for (int t = 5; t < 7; ++t) first.push_back(frame_msg(t));
  first.push_back(tjepa_test::xserver_frame(0.07, stream_frame(99, 3, m), m));
  for (int t = 7; t < 9; ++t) first.push_back(frame_msg(t));
  first.push_back("");
  for (int t : {9, 10, 14, 15}) second.push_back(frame_msg(t));
  tjepa_test::XServerPeer peer({first, second});

  XServerOptions o;
  o.port = std::to_string(peer.port());
  o.taxels = N;
  o.axes = m;
  o.reconnects = 2;
  o.backoff_s = 0.02;
  XServerSource src(o);
  std::vector<float> frame(static_cast<std::size_t>(N) * m);
  std::vector<int> got, gaps;
  FrameInfo info;
  while (src.next(frame, info)) {
    const int t = static_cast<int>(std::lround(info.time * 100));
    CHECK(frame == stream_frame(t, N, m));
    got.push_back(t);
    if (info.gap) gaps.push_back(t);
  }
  CHECK(got == std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 14, 15});
  CHECK(gaps == std::vector<int>{5, 7, 9, 14});
  const auto& p = src.problems();
  CHECK(p.at("malformed message") == 1);
  CHECK(p.at("wrong taxel count") == 1);
  CHECK(p.at("time gap (frames lost)") == 1);
  CHECK(p.at("reconnect") == 1);
  CHECK(p.at("connection dropped") == 2);  // the dropped link, then the peer's close at the end
  CHECK(p.at("failed reconnect attempt") == 2);
}

TEST_CASE("xServer client: no server is a clear error / stop() ends a wait") {
  XServerOptions o;
  {
    tjepa_test::XServerPeer peer({});  // listens, serves nobody, closes
    o.port = std::to_string(peer.port());
  }
  o.taxels = 4;
  o.reconnects = 1;
  o.backoff_s = 0.01;
  CHECK_THROWS_WITH_AS(XServerSource{o}, doctest::Contains("cannot connect to the xServer at ws://127.0.0.1:"), FileError);
  // A peer that says welcome and then nothing: stop() from another thread ends next().
  tjepa_test::XServerPeer quiet({{tjepa_test::xserver_welcome()}}, 2);
  o.port = std::to_string(quiet.port());
  o.idle_timeout_s = 30;
  XServerSource src(o);
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    src.stop();
  });
  std::vector<float> frame(12);
  FrameInfo info;
  CHECK_FALSE(src.next(frame, info));
  stopper.join();
}

TEST_CASE("AnySkin bytes: frames split anywhere / joined mid-frame: resync and a gap / a non-finite frame dropped / temperature kept with 4 axes") {
  const int N = 5;
  AnySkinDecoder dec(N, 3);
  std::vector<std::uint8_t> bytes;
  for (int t = 0; t < 3; ++t) {
    const auto b = anyskin_bytes(stream_frame(t, N, 3));
    bytes.insert(bytes.end(), b.begin(), b.end());
  }
  // Joined mid-frame: the stream starts 7 bytes into frame 0.
  const std::vector<std::uint8_t> joined(bytes.begin() + 7, bytes.end());
  std::vector<float> frame(static_cast<std::size_t>(N) * 3);
  std::int64_t resyncs = 0, bad = 0;
  bool gap = false;
  std::vector<int> got;
  for (std::size_t at = 0; at < joined.size(); at += 13) {  // split into pieces of 13 bytes
    dec.feed(std::span<const std::uint8_t>(joined.data() + at, std::min<std::size_t>(13, joined.size() - at)));
    while (dec.take(frame, gap, resyncs, bad)) {
      got.push_back(static_cast<int>(frame[0] - 30000) / 100);
      CHECK(gap == (got.size() == 1));
    }
  }
  CHECK(got == std::vector<int>{1, 2});
  CHECK(resyncs == 1);
  std::vector<float> nan_frame = stream_frame(3, N, 3);
  nan_frame[4] = std::numeric_limits<float>::quiet_NaN();
  dec.feed(anyskin_bytes(nan_frame));
  dec.feed(anyskin_bytes(stream_frame(4, N, 3)));
  REQUIRE(dec.take(frame, gap, resyncs, bad));
  CHECK(frame == stream_frame(4, N, 3));
  CHECK(gap);
  CHECK(bad == 1);
  AnySkinDecoder four(N, 4);
  four.feed(anyskin_bytes(stream_frame(0, N, 3), 31.5f));
  std::vector<float> f4(static_cast<std::size_t>(N) * 4);
  REQUIRE(four.take(f4, gap, resyncs, bad));
  CHECK(f4[0] == 31.5f);
  CHECK(f4[1] == 30000.0f);
  CHECK_THROWS_AS(AnySkinDecoder(N, 2), ConfigError);
}

TEST_CASE("AnySkin on a pseudo-terminal: the board's stream read through termios / the device gone ends it") {
  int master = -1, slave = -1;
  char name[256] = {};
  REQUIRE(::openpty(&master, &slave, name, nullptr, nullptr) == 0);
  const int N = 5;
  AnySkinSource src(name, 115200, N, 3, 0, 0.01);
  ::close(slave);  // the source holds its own descriptor
  std::thread board([&] {
    for (int t = 0; t < 50; ++t) {
      const auto b = anyskin_bytes(stream_frame(t, N, 3));
      std::size_t done = 0;
      while (done < b.size()) {
        const ssize_t n = ::write(master, b.data() + done, b.size() - done);
        if (n <= 0) return;
        done += static_cast<std::size_t>(n);
      }
      if (t % 10 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    ::close(master);  // unplugged
  });
  std::vector<float> frame(static_cast<std::size_t>(N) * 3);
  FrameInfo info;
  int t = 0;
  while (src.next(frame, info)) {
    CHECK(frame == stream_frame(t, N, 3));
    CHECK_FALSE(info.gap);
    ++t;
  }
  board.join();
  CHECK(t == 50);
  CHECK(src.problems().empty());
}

TEST_CASE("replay: a recording frame by frame at its rate / the model's frame size checked") {
  Recording rec(12, 2, 3);
  for (int k = 0; k < 12 * 6; ++k) rec.mutable_data()[k] = static_cast<float>(k);
  ReplaySource src(rec, 400);
  std::vector<float> frame(6);
  FrameInfo info;
  const auto t0 = std::chrono::steady_clock::now();
  int t = 0;
  while (src.next(frame, info)) {
    CHECK(frame[0] == static_cast<float>(6 * t));
    CHECK(info.time == doctest::Approx(t / 400.0));
    ++t;
  }
  CHECK(t == 12);
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() >= 11 / 400.0);
  ReplaySource other(rec, 0);
  std::vector<float> wrong(5);
  CHECK_THROWS_AS(other.next(wrong, info), ShapeError);
}
}
