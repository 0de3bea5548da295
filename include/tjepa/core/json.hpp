#pragma once
// Typed reads of JSON values (configs, checkpoint metadata): a missing key, a wrong type or an
// out-of-range number throws a tjepa::Error (ConfigError by default, FileError for files) that
// names where the JSON came from and the key, never a nlohmann exception.
//
//   const int d = json_get<int>(meta, "dim", "run.safetensors: config.model");
//   json_read(j, "betas", cfg.betas, "config.json");          // into an existing field
//
// Besides numbers, strings, booleans, arrays and vectors, two kinds of config types convert:
// - an enum E with a `json_names(E)` found by ADL that returns its (name, value) pairs, as its
//   name ("fp32"); a string that names no value is an error that lists the names;
// - a struct with double members lo and hi (RatioRange), as [lo, hi].
// json_value(v) is v's JSON in the same form.
#include <array>
#include <concepts>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"

namespace tjepa {

// An enum whose values have JSON names (see above).
template <class E>
concept JsonNamedEnum = std::is_enum_v<E> && requires(E e) {
  { json_names(e) };
};
// A range [lo, hi] of two doubles.
template <class R>
concept JsonRange = std::is_class_v<R> && requires(R r) {
  { r.lo } -> std::convertible_to<double>;
  { r.hi } -> std::convertible_to<double>;
};

// v as JSON: a named enum as its name, a range as [lo, hi], anything else as nlohmann converts it.
template <class T>
nlohmann::json json_value(const T& v) {
  if constexpr (JsonNamedEnum<T>) {
    for (const auto& [name, value] : json_names(v))
      if (value == v) return std::string(name);
    return static_cast<std::int64_t>(v);  // not a named value: only from a cast
  } else if constexpr (JsonRange<T>) {
    return nlohmann::json::array({v.lo, v.hi});
  } else {
    return nlohmann::json(v);
  }
}

namespace detail {

template <class T>
struct is_std_array : std::false_type {};
template <class T, std::size_t N>
struct is_std_array<std::array<T, N>> : std::true_type {};
template <class T>
struct is_std_vector : std::false_type {};
template <class T>
struct is_std_vector<std::vector<T>> : std::true_type {};

// A description of what T looks like in JSON, for error messages.
template <class T>
std::string json_kind() {
  if constexpr (std::is_same_v<T, bool>) return "a boolean";
  else if constexpr (JsonNamedEnum<T>) {
    std::string names;
    for (const auto& [name, value] : json_names(T{})) names += (names.empty() ? "'" : ", '") + std::string(name) + "'";
    return "one of " + names;
  } else if constexpr (JsonRange<T>) return "an array [lo, hi] of 2 numbers";
  else if constexpr (std::is_integral_v<T>) return std::is_unsigned_v<T> ? "a non-negative integer" : "an integer";
  else if constexpr (std::is_floating_point_v<T>) return "a number";
  else if constexpr (std::is_same_v<T, std::string>) return "a string";
  else if constexpr (std::is_same_v<T, nlohmann::json>) return "an object";
  else if constexpr (is_std_array<T>::value)
    return "an array of " + std::to_string(std::tuple_size_v<T>) + " x " + json_kind<typename T::value_type>();
  else return "an array of " + json_kind<typename T::value_type>();
}

// Converts v to T, or returns false when v is not a T (an integer out of T's range is not a T).
template <class T>
bool json_convert(const nlohmann::json& v, T& out) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) return false;
    out = v.get<bool>();
  } else if constexpr (JsonNamedEnum<T>) {
    if (!v.is_string()) return false;
    for (const auto& [name, value] : json_names(out))
      if (name == v.get<std::string>()) {
        out = value;
        return true;
      }
    return false;
  } else if constexpr (JsonRange<T>) {
    std::array<double, 2> lohi{};
    if (!json_convert(v, lohi)) return false;
    out.lo = lohi[0];
    out.hi = lohi[1];
  } else if constexpr (std::is_integral_v<T>) {
    if (v.is_number_unsigned()) {
      const auto u = v.get<std::uint64_t>();
      if (u > static_cast<std::uint64_t>(std::numeric_limits<T>::max())) return false;
      out = static_cast<T>(u);
    } else if (v.is_number_integer()) {
      const auto i = v.get<std::int64_t>();
      if constexpr (std::is_unsigned_v<T>) {
        if (i < 0) return false;
        if (static_cast<std::uint64_t>(i) > static_cast<std::uint64_t>(std::numeric_limits<T>::max())) return false;
      } else {
        if (i < static_cast<std::int64_t>(std::numeric_limits<T>::min()) ||
            i > static_cast<std::int64_t>(std::numeric_limits<T>::max()))
          return false;
      }
      out = static_cast<T>(i);
    } else {
      return false;
    }
  } else if constexpr (std::is_floating_point_v<T>) {
    if (!v.is_number()) return false;
    out = v.get<T>();
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) return false;
    out = v.get<std::string>();
  } else if constexpr (std::is_same_v<T, nlohmann::json>) {
    if (!v.is_object()) return false;
    out = v;
  } else if constexpr (is_std_array<T>::value) {
    if (!v.is_array() || v.size() != std::tuple_size_v<T>) return false;
    T tmp{};
    for (std::size_t i = 0; i < tmp.size(); ++i)
      if (!json_convert(v[i], tmp[i])) return false;
    out = tmp;
  } else {
    static_assert(is_std_vector<T>::value, "json_convert: unsupported type");
    if (!v.is_array()) return false;
    T tmp(v.size());
    for (std::size_t i = 0; i < tmp.size(); ++i)
      if (!json_convert(v[i], tmp[i])) return false;
    out = std::move(tmp);
  }
  return true;
}

}  // namespace detail

// j[key] into out. Throws E naming `where` and the key when j is not an object, the key is
// missing or its value is not a T.
template <class E = ConfigError, class T>
void json_read(const nlohmann::json& j, std::string_view key, T& out, std::string_view where) {
  require<E>(j.is_object(), where, ": expected a JSON object, got ", j.type_name());
  const auto it = j.find(std::string(key));
  require<E>(it != j.end(), where, ": missing key '", key, "'");
  if (!detail::json_convert(*it, out))
    fail<E>(where, ": key '", key, "' = ", it->dump(), ", expected ", detail::json_kind<T>());
}

template <class T, class E = ConfigError>
T json_get(const nlohmann::json& j, std::string_view key, std::string_view where) {
  T out{};
  json_read<E>(j, key, out, where);
  return out;
}

// The JSON text `text` parsed; E naming `where` when it is not valid JSON.
template <class E = ConfigError>
nlohmann::json json_parse(std::string_view text, std::string_view where) {
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    fail<E>(where, ": not valid JSON (", e.what(), ")");
  }
}

}  // namespace tjepa
