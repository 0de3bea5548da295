#pragma once
// StageClock: timestamps of the stages of one inference call or training step, to see where its
// time goes and where its variance from call to call lives (examples/streaming.cpp --stages,
// bench/scale.cpp). Off by default:
// a Workspace's clock is nullptr, and a stage then costs one test of that pointer. On, a mark is
// one steady_clock read into a fixed array, so a timed call still allocates nothing.
//
//   ws.clock = &clock;  clock.start();  encoder.forward(..., ws);
//   clock.count() marks; stage i took clock.elapsed_ns(i) and ends with clock.name(i)
// Per block the forward's marks are norm1, qkv, attention, proj, norm2, mlp (batch-1 inference on
// several threads, BlockStack::forward_owned: norm1, qkv, barrier, attention, ...); the backward's mlp
// backward, norm2 backward, proj backward, attention backward, qkv backward, norm1 backward.
#include <array>
#include <chrono>
#include <cstdint>

namespace tjepa {

class StageClock {
 public:
  static constexpr int capacity = 512;  // marks per call; more are dropped

  void start() {
    n_ = 0;
    mark("start");
  }
  void mark(const char* stage) {
    if (n_ == capacity) return;
    t_[n_] = std::chrono::steady_clock::now().time_since_epoch().count();
    name_[n_++] = stage;
  }
  // Stages since start(): stage i runs from mark i to mark i + 1.
  int count() const { return n_ > 0 ? n_ - 1 : 0; }
  const char* name(int i) const { return name_[i + 1]; }
  std::int64_t elapsed_ns(int i) const {
    using namespace std::chrono;
    return duration_cast<nanoseconds>(steady_clock::duration(t_[i + 1] - t_[i])).count();
  }

 private:
  std::array<std::chrono::steady_clock::rep, capacity> t_{};
  std::array<const char*, capacity> name_{};
  int n_ = 0;
};

}  // namespace tjepa
