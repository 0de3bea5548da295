#pragma once
// 64-bit FNV-1a: a cheap, stable fingerprint of bytes (not a cryptographic hash): the data-parallel
// check that ranks hold the same parameters, the pre-training cache's keys, temporary file names.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

namespace tjepa {

inline constexpr std::uint64_t fingerprint_seed = 14695981039346656037ull;

// FNV-1a over the bytes of values, continuing from h (start: fingerprint_seed).
template <class T>
std::uint64_t fingerprint(std::span<const T> values, std::uint64_t h = fingerprint_seed) {
  for (std::byte b : std::as_bytes(values)) h = (h ^ static_cast<std::uint64_t>(b)) * 1099511628211ull;
  return h;
}

// h as 16 lower-case hex digits.
inline std::string hex_digits(std::uint64_t h) {
  static constexpr char hex[] = "0123456789abcdef";
  std::string out(16, '0');
  for (int i = 15; i >= 0; --i, h >>= 4) out[static_cast<std::size_t>(i)] = hex[h & 15];
  return out;
}

// The fingerprint of a string's bytes as 16 hex digits.
inline std::string short_hash(std::string_view s) {
  return hex_digits(fingerprint(std::span<const char>(s.data(), s.size())));
}

}  // namespace tjepa
