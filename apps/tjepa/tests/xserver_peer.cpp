// The xServer test peer (xserver_peer.hpp).
#include "xserver_peer.hpp"

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include <chrono>
#include <cstdio>
#include <exception>
#include <thread>

#include <nlohmann/json.hpp>

namespace tjepa_test {

namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;

struct XServerPeer::Impl {
  net::io_context ioc;
  tcp::acceptor acceptor{ioc};
  std::vector<std::vector<std::string>> connections;
  double rate = 0;
  unsigned short port = 0;  // read before the thread starts: the acceptor closes after the last connection
  std::thread thread;

  void serve() {
    for (const auto& messages : connections) {
      try {
        tcp::socket socket(ioc);
        acceptor.accept(socket);
        websocket::stream<tcp::socket> ws(std::move(socket));
        ws.accept();
        ws.text(true);
        bool dropped = false;
        for (const std::string& m : messages) {
          if (m.empty()) {  // a dropped link: the socket closed without a WebSocket close
            beast::error_code ignored;
            ws.next_layer().shutdown(tcp::socket::shutdown_both, ignored);
            ws.next_layer().close(ignored);
            dropped = true;
            break;
          }
          ws.write(net::buffer(m));
          if (rate > 0) std::this_thread::sleep_for(std::chrono::duration<double>(1.0 / rate));
        }
        if (!dropped) ws.close(websocket::close_code::normal);
      } catch (const std::exception&) {
        // The client went away first: that connection is over.
      }
    }
    beast::error_code ignored;
    acceptor.close(ignored);
  }
};

XServerPeer::XServerPeer(std::vector<std::vector<std::string>> connections, double rate) : impl_(std::make_unique<Impl>()) {
  impl_->connections = std::move(connections);
  impl_->rate = rate;
  const tcp::endpoint at(net::ip::make_address("127.0.0.1"), 0);
  impl_->acceptor.open(at.protocol());
  impl_->acceptor.set_option(net::socket_base::reuse_address(true));
  impl_->acceptor.bind(at);
  impl_->acceptor.listen();
  impl_->port = impl_->acceptor.local_endpoint().port();
  impl_->thread = std::thread([this] { impl_->serve(); });
}

XServerPeer::~XServerPeer() {
  if (impl_->thread.joinable()) {
    beast::error_code ignored;
    impl_->acceptor.cancel(ignored);
    impl_->thread.join();
  }
}

unsigned short XServerPeer::port() const { return impl_->port; }

void XServerPeer::join() {
  if (impl_->thread.joinable()) impl_->thread.join();
}

std::string xserver_frame(double time, const std::vector<float>& values, int axes, int sensors) {
  nlohmann::json j;
  j["message"] = "";
  j["time"] = time;
  j["sensors"] = sensors;
  const std::size_t taxels = values.size() / static_cast<std::size_t>(axes);
  std::size_t at = 0;
  for (int s = 0; s < sensors; ++s) {
    const std::size_t n = taxels / static_cast<std::size_t>(sensors) + (s + 1 == sensors ? taxels % static_cast<std::size_t>(sensors) : 0);
    nlohmann::json e;
    e["sensor"] = std::to_string(s + 1);
    e["model"] = "XR23AHLCPP";
    e["taxels"] = n;
    std::string hex;
    char buf[8];
    for (std::size_t k = 0; k < n * static_cast<std::size_t>(axes); ++k) {
      const float v = values[at + k];
      std::snprintf(buf, sizeof buf, "%04X", static_cast<unsigned>(static_cast<long>(v)) & 0xFFFFu);
      hex += buf;
    }
    // The readings themselves as numbers (the test recordings hold integers, as Xela counts are).
    e["integer"] = std::vector<float>(values.begin() + static_cast<std::ptrdiff_t>(at),
                                      values.begin() + static_cast<std::ptrdiff_t>(at + n * static_cast<std::size_t>(axes)));
    e["data"] = hex;
    e["temp"] = std::vector<double>(n, 28.5);
    j[std::to_string(s + 1)] = e;
    at += n * static_cast<std::size_t>(axes);
  }
  return j.dump();
}

std::string xserver_welcome() { return R"({"message": "Welcome", "data": "xServer", "version": "1.7.6"})"; }

}  // namespace tjepa_test
