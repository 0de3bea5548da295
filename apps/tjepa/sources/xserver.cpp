// The xServer WebSocket client (xserver.hpp) on Boost.Beast, in a translation unit of its own so
// that Beast's templates are compiled once, not with every subcommand.
#include "xserver.hpp"

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>
#include <tjepa/core/error.hpp>

namespace tjepa::cli {

namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;

XServerMessage parse_xserver_message(std::string_view text, std::span<float> frame, int axes, double& time,
                                     std::string& why) {
  const nlohmann::json j = nlohmann::json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    why = "not a JSON object";
    return XServerMessage::malformed;
  }
  const auto sensors = j.find("sensors");
  if (sensors == j.end()) return XServerMessage::other;  // the welcome, or a message without readings
  if (!sensors->is_number_integer() || sensors->get<std::int64_t>() < 1 || sensors->get<std::int64_t>() > 1024) {
    why = "'sensors' is not a count of sensors";
    return XServerMessage::malformed;
  }
  const auto t = j.find("time");
  if (t == j.end() || !t->is_number()) {
    why = "no numeric 'time'";
    return XServerMessage::malformed;
  }
  time = t->get<double>();
  const auto S = sensors->get<std::int64_t>();
  // First the sizes, then the values: a frame of the wrong size writes nothing.
  std::size_t total = 0;
  for (std::int64_t s = 1; s <= S; ++s) {
    const auto e = j.find(std::to_string(s));
    if (e == j.end() || !e->is_object()) {
      why = "no sensor entry \"" + std::to_string(s) + "\"";
      return XServerMessage::malformed;
    }
    const auto taxels = e->find("taxels");
    const auto values = e->find("integer");
    if (taxels == e->end() || !taxels->is_number_integer() || values == e->end() || !values->is_array()) {
      why = "sensor \"" + std::to_string(s) + "\" has no 'taxels' count or 'integer' array";
      return XServerMessage::malformed;
    }
    const auto n = taxels->get<std::int64_t>();
    if (n < 0 || static_cast<std::size_t>(n) * static_cast<std::size_t>(axes) != values->size()) {
      why = "sensor \"" + std::to_string(s) + "\": " + std::to_string(values->size()) + " readings for " +
            std::to_string(n) + " taxels of " + std::to_string(axes) + " axes";
      return XServerMessage::wrong_size;
    }
    total += values->size();
  }
  if (total != frame.size()) {
    why = std::to_string(total / static_cast<std::size_t>(axes)) + " taxels, the model has " +
          std::to_string(frame.size() / static_cast<std::size_t>(axes));
    return XServerMessage::wrong_size;
  }
  std::size_t k = 0;
  for (std::int64_t s = 1; s <= S; ++s)
    for (const auto& v : j.at(std::to_string(s)).at("integer")) {
      if (!v.is_number()) {
        why = "sensor \"" + std::to_string(s) + "\": a reading that is not a number";
        return XServerMessage::malformed;
      }
      frame[k++] = v.get<float>();
    }
  return XServerMessage::frame;
}

XServerOptions parse_ws_url(const std::string& url) {
  XServerOptions o;
  require<ConfigError>(url.starts_with("ws://"), "source '", url, "': expected ws://HOST[:PORT][/PATH]");
  std::string rest = url.substr(5);
  const auto slash = rest.find('/');
  if (slash != std::string::npos) {
    o.target = rest.substr(slash);
    rest = rest.substr(0, slash);
  }
  const auto colon = rest.rfind(':');
  if (colon != std::string::npos) {
    o.port = rest.substr(colon + 1);
    rest = rest.substr(0, colon);
    require<ConfigError>(!o.port.empty() && std::all_of(o.port.begin(), o.port.end(), [](char c) { return c >= '0' && c <= '9'; }) &&
                             std::stoul(o.port) > 0 && std::stoul(o.port) < 65536,
                         "source '", url, "': port '", o.port, "', expected 1..65535");
  }
  require<ConfigError>(!rest.empty(), "source '", url, "': no host");
  o.host = rest;
  return o;
}

struct XServerSource::Connection {
  net::io_context ioc;
  std::unique_ptr<websocket::stream<beast::tcp_stream>> ws;
  beast::flat_buffer buffer;
  std::atomic<bool> stop{false};
  double last_time = std::numeric_limits<double>::quiet_NaN();
  bool gap = false;
  std::string why;

  // Runs the asynchronous operation start(handler) until it completes, stop is asked, or
  // timeout_s passes (then it is cancelled: the error is operation_aborted or timed_out).
  template <class Start>
  beast::error_code run(Start&& start, double timeout_s) {
    bool done = false;
    beast::error_code result;
    ioc.restart();
    start([&](beast::error_code ec, auto&&...) {
      result = ec;
      done = true;
    });
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    bool expired = false;
    while (!done) {
      ioc.run_for(std::chrono::milliseconds(50));
      if (!done && !expired && (stop || std::chrono::steady_clock::now() > deadline)) {
        expired = true;
        beast::error_code ignored;
        if (ws) beast::get_lowest_layer(*ws).socket().close(ignored);
      }
      if (!done && ioc.stopped()) ioc.restart();
    }
    return expired && !stop ? beast::error_code(beast::error::timeout) : result;
  }

  void close() {
    if (!ws) return;
    beast::error_code ignored;
    beast::get_lowest_layer(*ws).socket().close(ignored);
    ws.reset();
    ioc.restart();
    ioc.poll();  // let cancelled handlers finish
  }

  // One attempt to connect and handshake; "" or what failed.
  std::string connect(const XServerOptions& o) {
    close();
    tcp::resolver resolver(ioc);
    beast::error_code ec;
    const auto endpoints = resolver.resolve(o.host, o.port, ec);
    if (ec) return "cannot resolve " + o.host + ": " + ec.message();
    ws = std::make_unique<websocket::stream<beast::tcp_stream>>(ioc);
    ec = run([&](auto h) { beast::get_lowest_layer(*ws).async_connect(endpoints, std::move(h)); }, 2.0);
    if (ec) return ec.message();
    websocket::stream_base::timeout t{};
    t.handshake_timeout = std::chrono::seconds(5);
    t.idle_timeout = websocket::stream_base::none();
    t.keep_alive_pings = false;
    ws->set_option(t);
    ec = run([&](auto h) { ws->async_handshake(o.host + ":" + o.port, o.target, std::move(h)); }, 5.0);
    if (ec) return "WebSocket handshake: " + ec.message();
    buffer.consume(buffer.size());
    return "";
  }
};

XServerSource::XServerSource(XServerOptions o) : o_(std::move(o)), c_(std::make_unique<Connection>()) {
  require<ConfigError>(o_.taxels > 0 && o_.axes > 0, "xServer: the model's taxels and axes are needed");
  require<ConfigError>(o_.rate > 0 && o_.idle_timeout_s > 0 && o_.backoff_s > 0, "xServer: rate ", o_.rate,
                       ", idle timeout ", o_.idle_timeout_s, " s, backoff ", o_.backoff_s, " s, expected > 0");
  std::string failed = c_->connect(o_);
  double wait = o_.backoff_s;
  for (int attempt = 0; !failed.empty() && (o_.reconnects < 0 || attempt < o_.reconnects); ++attempt) {
    std::this_thread::sleep_for(std::chrono::duration<double>(wait));
    wait = std::min(2 * wait, 5.0);
    failed = c_->connect(o_);
  }
  require<FileError>(failed.empty(), "cannot connect to the xServer at ws://", o_.host, ":", o_.port, o_.target, ": ",
                     failed);
}

XServerSource::~XServerSource() { c_->close(); }

void XServerSource::stop() { c_->stop = true; }

std::string XServerSource::describe() const {
  return "xServer at ws://" + o_.host + ":" + o_.port + o_.target + " (" + std::to_string(o_.taxels) + " taxels)";
}

bool XServerSource::next(std::span<float> frame, FrameInfo& info) {
  Connection& c = *c_;
  for (;;) {
    if (c.stop) return false;
    if (!c.ws) {  // reconnect with backoff
      double wait = o_.backoff_s;
      for (int attempt = 0; !c.ws && (o_.reconnects < 0 || attempt < o_.reconnects); ++attempt) {
        if (c.stop) return false;
        std::this_thread::sleep_for(std::chrono::duration<double>(wait));
        wait = std::min(2 * wait, 5.0);
        if (c.connect(o_).empty()) {
          count("reconnect");
        } else {
          c.close();
          count("failed reconnect attempt");
        }
      }
      if (!c.ws) return false;
      c.gap = true;
      c.last_time = std::numeric_limits<double>::quiet_NaN();
    }
    const beast::error_code ec = c.run([&](auto h) { c.ws->async_read(c.buffer, std::move(h)); }, o_.idle_timeout_s);
    if (c.stop) return false;
    if (ec) {
      count(ec == beast::error::timeout ? "connection silent for the idle timeout" : "connection dropped");
      c.close();
      continue;
    }
    const auto data = c.buffer.data();
    const std::string_view text(static_cast<const char*>(data.data()), data.size());
    double time = 0;
    const XServerMessage kind = parse_xserver_message(text, frame, o_.axes, time, c.why);
    c.buffer.consume(c.buffer.size());
    if (kind == XServerMessage::other) continue;
    if (kind != XServerMessage::frame) {
      count(kind == XServerMessage::malformed ? "malformed message" : "wrong taxel count");
      c.gap = true;
      continue;
    }
    const double period = 1.0 / o_.rate;
    if (!std::isnan(c.last_time) && (time - c.last_time > 2.5 * period || time <= c.last_time)) {
      count(time <= c.last_time ? "time ran backwards" : "time gap (frames lost)");
      c.gap = true;
    }
    c.last_time = time;
    info.time = time;
    info.gap = c.gap;
    c.gap = false;
    return true;
  }
}

}  // namespace tjepa::cli
