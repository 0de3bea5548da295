#pragma once
// enum_name(e): e's name in its enum's json_names(E) table (found by ADL). That table is the one
// list of names an enum keeps, for JSON (core/json.hpp) and for text alike.
namespace tjepa {

template <class E>
constexpr const char* enum_name(E e) {
  for (const auto& [name, value] : json_names(e))
    if (value == e) return name.data();  // the names are string literals
  return "?";
}

}  // namespace tjepa
