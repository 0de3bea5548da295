#pragma once
// replay:FILE — a recording (.npy [T, N, m] or a CSV as the other subcommands read it) played
// frame by frame at its rate (--rate Hz; 0: as fast as the pipeline takes them).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <span>
#include <string>
#include <thread>

#include <tjepa/tjepa.hpp>

#include "frame_source.hpp"

namespace tjepa::cli {

class ReplaySource : public FrameSource {
 public:
  ReplaySource(Recording rec, double rate) : rec_(std::move(rec)), rate_(rate) {
    require<ConfigError>(rate_ >= 0 && std::isfinite(rate_), "replay: rate ", rate_, ", expected >= 0");
  }
  bool next(std::span<float> frame, FrameInfo& info) override {
    if (stop_ || t_ >= rec_.frames()) return false;
    const std::size_t per = static_cast<std::size_t>(rec_.taxels()) * rec_.axes();
    require<ShapeError>(frame.size() == per, rec_.source(), ": frames of ", rec_.taxels(), " taxels x ", rec_.axes(),
                        " axes, the model reads ", frame.size(), " values a frame");
    if (rate_ > 0) {
      if (t_ == 0) start_ = Clock::now();
      std::this_thread::sleep_until(start_ + std::chrono::duration_cast<Clock::duration>(
                                                 std::chrono::duration<double>(static_cast<double>(t_) / rate_)));
    }
    std::copy_n(rec_.frame(t_), per, frame.data());
    info.time = rate_ > 0 ? static_cast<double>(t_) / rate_ : static_cast<double>(t_);
    info.gap = false;
    ++t_;
    return true;
  }
  void stop() override { stop_ = true; }
  std::string describe() const override {
    return "replay of " + rec_.source() + " (" + std::to_string(rec_.frames()) + " frames" +
           (rate_ > 0 ? " at " + std::to_string(static_cast<int>(rate_)) + " Hz)" : ", back to back)");
  }

 private:
  using Clock = std::chrono::steady_clock;
  Recording rec_;
  double rate_;
  int t_ = 0;
  Clock::time_point start_;
  std::atomic<bool> stop_{false};
};

}  // namespace tjepa::cli
