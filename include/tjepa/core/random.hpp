#pragma once
// Deterministic random numbers, the same on every compiler and standard library.
//
// Engine: xoshiro256** 1.0 (Blackman & Vigna, 2018), state seeded by splitmix64 of the seed.
// The standard library's distributions are implementation-defined, so every draw here is our own:
//   uniform()           53 high bits / 2^53, in [0, 1)
//   below(n)            Lemire's nearly-divisionless unbiased integer in [0, n)
//   normal()            Box–Muller from two uniforms (one value per call, no cached spare)
//   truncated_normal()  normal() rejected outside [a, b] (PyTorch's trunc_normal_ bounds are
//                       absolute, like ours; at ±2 with std 0.02 a rejection never happens)
// Independent streams: Rng(seed, stream) mixes the stream index into the seed, so sample i of a
// batch draws from Rng(seed, i) and results do not depend on the thread count.
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <span>
#include <utility>

#include "tjepa/core/error.hpp"

namespace tjepa {

namespace detail {
constexpr std::uint64_t splitmix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
constexpr std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
}  // namespace detail

class Rng {
 public:
  using result_type = std::uint64_t;
  using State = std::array<std::uint64_t, 4>;

  explicit constexpr Rng(std::uint64_t seed = 0, std::uint64_t stream = 0) { reseed(seed, stream); }

  constexpr void reseed(std::uint64_t seed, std::uint64_t stream = 0) {
    std::uint64_t x = seed;
    // Mix the stream so that (seed, 0), (seed, 1), ... are unrelated sequences.
    std::uint64_t y = stream ^ 0xD1B54A32D192ED03ull;
    const std::uint64_t salt = detail::splitmix64(y);
    x ^= salt;
    for (auto& s : s_) s = detail::splitmix64(x);
  }

  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return ~result_type{0}; }

  // The next 64 raw bits (xoshiro256**).
  constexpr result_type operator()() {
    const std::uint64_t result = detail::rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = detail::rotl(s_[3], 45);
    return result;
  }

  // A uniform double in [0, 1).
  constexpr double uniform() { return static_cast<double>((*this)() >> 11) * 0x1.0p-53; }
  // A uniform double in [lo, hi).
  constexpr double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

  // An unbiased integer in [0, n), n > 0 (Lemire 2019).
  constexpr std::uint64_t below(std::uint64_t n) {
    if (n == 0) fail<ConfigError>("Rng::below: argument n = 0, expected n > 0");
    __uint128_t m = static_cast<__uint128_t>((*this)()) * n;
    auto low = static_cast<std::uint64_t>(m);
    if (low < n) {
      const std::uint64_t threshold = (0 - n) % n;
      while (low < threshold) {
        m = static_cast<__uint128_t>((*this)()) * n;
        low = static_cast<std::uint64_t>(m);
      }
    }
    return static_cast<std::uint64_t>(m >> 64);
  }

  // A standard normal draw (Box–Muller, cosine branch).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]: log is finite
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }
  double normal(double mean, double std) { return mean + std * normal(); }

  // N(mean, std^2) restricted to [a, b] (absolute bounds) by rejection.
  double truncated_normal(double mean, double std, double a, double b) {
    if (!(a < b)) fail<ConfigError>("Rng::truncated_normal: bounds [", a, ", ", b, "], expected a < b");
    for (int i = 0; i < 1000; ++i) {
      const double x = normal(mean, std);
      if (x >= a && x <= b) return x;
    }
    // The interval holds almost no mass: fall back to a uniform draw inside it.
    return uniform(a, b);
  }

  // Fisher–Yates shuffle of a span.
  template <class V>
  void shuffle(std::span<V> v) {
    for (std::size_t i = v.size(); i > 1; --i) std::swap(v[i - 1], v[below(i)]);
  }

  constexpr const State& state() const { return s_; }
  constexpr void set_state(const State& s) {
    if (s[0] == 0 && s[1] == 0 && s[2] == 0 && s[3] == 0)
      fail<ConfigError>("Rng::set_state: all-zero state, expected at least one non-zero word");
    s_ = s;
  }

  friend constexpr bool operator==(const Rng&, const Rng&) = default;

 private:
  State s_{};
};

}  // namespace tjepa
