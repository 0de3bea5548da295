#pragma once
// A test peer that speaks XELA's xServer protocol on loopback (Boost.Beast, a thread of its own):
// for each connection in turn it accepts, sends that connection's messages, and then closes it
// (an empty message closes it abruptly there, without a WebSocket close: a dropped link). After
// the last connection it stops listening, so a client's reconnect attempts fail from then on.
#include <memory>
#include <string>
#include <vector>

namespace tjepa_test {

class XServerPeer {
 public:
  explicit XServerPeer(std::vector<std::vector<std::string>> connections, double rate = 0);
  ~XServerPeer();
  XServerPeer(const XServerPeer&) = delete;
  XServerPeer& operator=(const XServerPeer&) = delete;
  unsigned short port() const;
  void join();  // waits until every connection is served

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// One xServer frame message: `sensors` entries splitting the taxels evenly, "integer" readings of
// taxels × axes values (the Allegro hand's xServer: one entry), as XELA's server writes them.
std::string xserver_frame(double time, const std::vector<float>& values, int axes, int sensors = 1);
std::string xserver_welcome();

}  // namespace tjepa_test
