#pragma once
// Errors. Every bad input at the API boundary throws tjepa::Error (or a subclass) whose message
// names the argument, the value seen and what was expected. Hot loops check nothing.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace tjepa {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

// A tensor or argument has the wrong shape.
class ShapeError : public Error {
 public:
  using Error::Error;
};

// A configuration value is out of its range or inconsistent with another.
class ConfigError : public Error {
 public:
  using Error::Error;
};

// A file is missing, truncated or malformed. The message names the file (and line if any).
class FileError : public Error {
 public:
  using Error::Error;
};

// Data hold NaN/Inf or values that cannot be used.
class DataError : public Error {
 public:
  using Error::Error;
};

// Training diverged (NaN or Inf in the loss or gradients).
class NumericError : public Error {
 public:
  using Error::Error;
};

namespace detail {
// A NaN is written "nan" whatever its sign bit (x86 arithmetic makes "-nan"), so messages read the
// same on every machine.
template <class A>
const A& message_part(const A& a) {
  return a;
}
inline double message_part(double a) { return a != a ? std::fabs(a) : a; }
inline float message_part(float a) { return a != a ? std::fabs(a) : a; }

template <class... Args>
std::string concat(const Args&... args) {
  std::ostringstream os;
  (os << ... << message_part(args));
  return os.str();
}
}  // namespace detail

// Throws E with the streamed arguments as message: fail<ShapeError>("x: got ", n, ", expected 3").
template <class E = Error, class... Args>
[[noreturn]] void fail(const Args&... args) {
  throw E(detail::concat(args...));
}

// Throws E unless cond holds.
template <class E = Error, class... Args>
void require(bool cond, const Args&... args) {
  if (!cond) fail<E>(args...);
}

}  // namespace tjepa
