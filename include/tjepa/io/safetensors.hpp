#pragma once
// The safetensors format (huggingface/safetensors), read and written without Python:
//
//   [8 bytes]  N, the header length, unsigned little-endian
//   [N bytes]  a JSON object: {"__metadata__": {str: str}, "<name>": {"dtype": "F32",
//              "shape": [2, 3], "data_offsets": [begin, end]}, ...}; padded with spaces
//   [rest]     the data: raw little-endian row-major tensors; offsets count from its first byte
//
// Loading is strict: every tensor entry needs exactly dtype/shape/data_offsets, a known dtype,
// a byte range that matches its shape, and the ranges must tile the data exactly (no overlap,
// no hole, nothing past the end, nothing after the last tensor). The header length is limited
// (100 MB, as in the reference Rust crate) and keys must be unique. Every failure throws
// FileError naming the file and the problem.
//
// Writing orders the tensors by element size (largest first, then insertion order) so each one
// starts aligned to its element size, and pads the header to a multiple of 8, as the reference
// writer does. Files are written atomically (core/atomic_write.hpp).
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/core/atomic_write.hpp"

namespace tjepa {

enum class Dtype : std::uint8_t { BOOL, U8, I8, U16, I16, F16, BF16, U32, I32, F32, U64, I64, F64 };

inline constexpr std::string_view dtype_name(Dtype d) {
  switch (d) {
    case Dtype::BOOL: return "BOOL";
    case Dtype::U8: return "U8";
    case Dtype::I8: return "I8";
    case Dtype::U16: return "U16";
    case Dtype::I16: return "I16";
    case Dtype::F16: return "F16";
    case Dtype::BF16: return "BF16";
    case Dtype::U32: return "U32";
    case Dtype::I32: return "I32";
    case Dtype::F32: return "F32";
    case Dtype::U64: return "U64";
    case Dtype::I64: return "I64";
    case Dtype::F64: return "F64";
  }
  return "?";
}

// Bytes per element.
inline constexpr std::size_t dtype_size(Dtype d) {
  switch (d) {
    case Dtype::BOOL:
    case Dtype::U8:
    case Dtype::I8: return 1;
    case Dtype::U16:
    case Dtype::I16:
    case Dtype::F16:
    case Dtype::BF16: return 2;
    case Dtype::U32:
    case Dtype::I32:
    case Dtype::F32: return 4;
    case Dtype::U64:
    case Dtype::I64:
    case Dtype::F64: return 8;
  }
  return 0;
}

inline std::optional<Dtype> dtype_from_name(std::string_view s) {
  for (auto d : {Dtype::BOOL, Dtype::U8, Dtype::I8, Dtype::U16, Dtype::I16, Dtype::F16, Dtype::BF16,
                 Dtype::U32, Dtype::I32, Dtype::F32, Dtype::U64, Dtype::I64, Dtype::F64})
    if (dtype_name(d) == s) return d;
  return std::nullopt;
}

// The dtype of a C++ element type (arithmetic types with a fixed width).
template <class T>
inline constexpr Dtype dtype_of = [] {
  if constexpr (std::is_same_v<T, float>) return Dtype::F32;
  else if constexpr (std::is_same_v<T, double>) return Dtype::F64;
  else if constexpr (std::is_same_v<T, std::int64_t>) return Dtype::I64;
  else if constexpr (std::is_same_v<T, std::uint64_t>) return Dtype::U64;
  else if constexpr (std::is_same_v<T, std::int32_t>) return Dtype::I32;
  else if constexpr (std::is_same_v<T, std::uint32_t>) return Dtype::U32;
  else if constexpr (std::is_same_v<T, std::int16_t>) return Dtype::I16;
  else if constexpr (std::is_same_v<T, std::uint16_t>) return Dtype::U16;
  else if constexpr (std::is_same_v<T, std::int8_t>) return Dtype::I8;
  else if constexpr (std::is_same_v<T, std::uint8_t>) return Dtype::U8;
  else static_assert(sizeof(T) == 0, "tjepa: no safetensors dtype for this element type");
}();

// Largest header accepted on load, in bytes. A tensor's entry takes about 100 bytes, so 4 MiB
// holds about 40 000 tensors (a tjepa checkpoint of the reference model with its optimizer state
// has a few hundred). The reference crate allows 100 MB. Parsing is linear in the header's length
// and its memory a small multiple of it (measured by a script of commit 5b4349d).
inline constexpr std::size_t safetensors_max_header = std::size_t{4} << 20;
// Longest array in a header (a shape or data_offsets): more dimensions than any tensor has.
inline constexpr std::size_t safetensors_max_array = 64;

namespace detail {
// Reverses each element's bytes in place (only big-endian hosts need it: the format is LE).
inline void swap_element_bytes(std::span<std::byte> bytes, std::size_t elem) {
  if (elem <= 1) return;
  for (std::size_t i = 0; i + elem <= bytes.size(); i += elem) std::reverse(bytes.begin() + i, bytes.begin() + i + elem);
}

inline std::string shape_string(const std::vector<std::int64_t>& shape) {
  std::string s = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  return s + "]";
}
}  // namespace detail

// One tensor: dtype, shape and its raw little-endian bytes.
struct Tensor {
  Dtype dtype = Dtype::F32;
  std::vector<std::int64_t> shape;  // empty: a scalar
  std::vector<std::byte> data;      // numel() * dtype_size(dtype) bytes

  std::size_t numel() const {
    std::size_t n = 1;
    for (auto s : shape) n *= static_cast<std::size_t>(s);
    return n;
  }

  template <class T>
  static Tensor from(std::span<const T> values, std::vector<std::int64_t> shape) {
    Tensor t{dtype_of<T>, std::move(shape), {}};
    for (auto s : t.shape)
      require<ShapeError>(s >= 0, "Tensor::from: shape ", detail::shape_string(t.shape), " has a negative dimension");
    require<ShapeError>(t.numel() == values.size(), "Tensor::from: ", values.size(), " values for shape ",
                        detail::shape_string(t.shape), ", expected ", t.numel());
    t.data.resize(values.size_bytes());
    if (!values.empty()) std::memcpy(t.data.data(), values.data(), values.size_bytes());
    if constexpr (std::endian::native == std::endian::big) detail::swap_element_bytes(t.data, sizeof(T));
    return t;
  }
  template <class T>
  static Tensor from(const std::vector<T>& values, std::vector<std::int64_t> shape) {
    return from(std::span<const T>(values), std::move(shape));
  }

  // Copies the values into `out`; the dtype must be T's and the sizes must agree.
  template <class T>
  void copy_to(std::span<T> out) const {
    require<ShapeError>(dtype == dtype_of<T>, "Tensor::copy_to: tensor dtype ", dtype_name(dtype),
                        ", expected ", dtype_name(dtype_of<T>));
    require<ShapeError>(out.size() == numel(), "Tensor::copy_to: tensor of shape ", detail::shape_string(shape),
                        " holds ", numel(), " values, destination holds ", out.size());
    if (!out.empty()) std::memcpy(out.data(), data.data(), data.size());
    if constexpr (std::endian::native == std::endian::big)
      detail::swap_element_bytes(std::as_writable_bytes(out), sizeof(T));
  }
  template <class T>
  std::vector<T> to_vector() const {
    std::vector<T> v(numel());
    copy_to(std::span<T>(v));
    return v;
  }
};

// A safetensors file in memory: named tensors and string metadata.
class SafetensorsFile {
 public:
  std::map<std::string, std::string> metadata;

  // Adds a tensor; names are unique and non-empty, "__metadata__" is reserved.
  void add(std::string name, Tensor t) {
    require<ConfigError>(!name.empty(), "SafetensorsFile::add: empty tensor name");
    require<ConfigError>(name != "__metadata__", "SafetensorsFile::add: the name '__metadata__' is reserved");
    require<ConfigError>(!index_.contains(name), "SafetensorsFile::add: duplicate tensor name '", name, "'");
    require<ShapeError>(t.data.size() == t.numel() * dtype_size(t.dtype), "SafetensorsFile::add('", name,
                        "'): ", t.data.size(), " bytes for ", dtype_name(t.dtype), " ",
                        detail::shape_string(t.shape), ", expected ", t.numel() * dtype_size(t.dtype));
    index_.emplace(name, tensors_.size());
    names_.push_back(std::move(name));
    tensors_.push_back(std::move(t));
  }
  template <class T>
  void add(std::string name, std::span<const T> values, std::vector<std::int64_t> shape) {
    add(std::move(name), Tensor::from(values, std::move(shape)));
  }

  bool contains(std::string_view name) const { return index_.contains(std::string(name)); }
  const Tensor& at(std::string_view name) const {
    auto it = index_.find(std::string(name));
    if (it == index_.end()) fail<FileError>(source_, ": no tensor named '", name, "'");
    return tensors_[it->second];
  }
  // Tensor names in insertion order (file order for a loaded file).
  const std::vector<std::string>& names() const { return names_; }
  std::size_t size() const { return tensors_.size(); }

  // Where the file came from, for error messages ("<memory>" if built in memory).
  const std::string& source() const { return source_; }
  void set_source(std::string s) { source_ = std::move(s); }

 private:
  std::vector<std::string> names_;
  std::vector<Tensor> tensors_;
  std::unordered_map<std::string, std::size_t> index_;
  std::string source_ = "<memory>";
};

// Writes the file's bytes to `out`: the header length, the header, then the tensors in the
// header's order (nothing is copied into one buffer first).
inline void write_safetensors(std::ostream& out, const SafetensorsFile& file) {
  // Largest elements first so each tensor starts aligned to its element size.
  std::vector<std::size_t> order(file.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return dtype_size(file.at(file.names()[a]).dtype) > dtype_size(file.at(file.names()[b]).dtype);
  });
  nlohmann::ordered_json header = nlohmann::ordered_json::object();
  if (!file.metadata.empty()) {
    auto meta = nlohmann::ordered_json::object();
    for (const auto& [k, v] : file.metadata) meta[k] = v;
    header["__metadata__"] = std::move(meta);
  }
  std::size_t offset = 0;
  for (std::size_t i : order) {
    const std::string& name = file.names()[i];
    const Tensor& t = file.at(name);
    header[name] = {{"dtype", std::string(dtype_name(t.dtype))},
                    {"shape", t.shape},
                    {"data_offsets", {offset, offset + t.data.size()}}};
    offset += t.data.size();
  }
  std::string text;
  try {
    text = header.dump();
  } catch (const nlohmann::json::exception& e) {
    fail<ConfigError>(file.source(), ": cannot encode the header (names and metadata must be UTF-8): ", e.what());
  }
  text.append((8 - text.size() % 8) % 8, ' ');
  char length[8];
  const std::uint64_t n = text.size();
  for (int b = 0; b < 8; ++b) length[b] = static_cast<char>((n >> (8 * b)) & 0xFF);
  out.write(length, 8);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  for (std::size_t i : order) {
    const Tensor& t = file.at(file.names()[i]);
    out.write(reinterpret_cast<const char*>(t.data.data()), static_cast<std::streamsize>(t.data.size()));
  }
}

namespace detail {
// The SAX handler of parse_safetensors' first pass over the header.
struct SafetensorsHeaderCheck {
  using json = nlohmann::json;
  std::string source;
  std::vector<std::unordered_set<std::string>> keys;  // per open object
  std::vector<std::size_t> arrays;                    // entries so far of each open array
  std::string duplicate, syntax_error;

  void value() {
    if (!arrays.empty() && ++arrays.back() > safetensors_max_array)
      fail<FileError>(source, ": the header holds an array of more than ", safetensors_max_array, " entries");
  }
  bool null() { return value(), true; }
  bool boolean(bool) { return value(), true; }
  bool number_integer(json::number_integer_t) { return value(), true; }
  bool number_unsigned(json::number_unsigned_t) { return value(), true; }
  bool number_float(json::number_float_t, const json::string_t&) { return value(), true; }
  bool string(json::string_t&) { return value(), true; }
  bool binary(json::binary_t&) { return value(), true; }
  bool start_object(std::size_t) {
    value();
    if (keys.size() >= 2 || !arrays.empty())
      fail<FileError>(source, ": the header nests objects deeper than a tensor's entry");
    keys.emplace_back();
    return true;
  }
  bool key(json::string_t& k) {
    if (!keys.back().insert(k).second && duplicate.empty()) duplicate = k;
    return true;
  }
  bool end_object() { return keys.pop_back(), true; }
  bool start_array(std::size_t) {
    value();
    if (keys.size() != 2 || !arrays.empty())
      fail<FileError>(source, ": the header holds an array outside a tensor's entry");
    arrays.push_back(0);
    return true;
  }
  bool end_array() { return arrays.pop_back(), true; }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception& e) {
    syntax_error = e.what();
    return false;
  }
};
}  // namespace detail

// Parses and validates a whole file held in memory; `source` names it in error messages.
inline SafetensorsFile parse_safetensors(std::span<const std::byte> bytes, const std::string& source,
                                         std::size_t max_header = safetensors_max_header) {
  auto bad = [&](const auto&... what) { fail<FileError>(source, ": ", what...); };
  if (bytes.size() < 8) bad("truncated: ", bytes.size(), " bytes, expected at least the 8-byte header length");
  std::uint64_t n = 0;
  for (int b = 7; b >= 0; --b) n = (n << 8) | std::to_integer<std::uint64_t>(bytes[static_cast<std::size_t>(b)]);
  if (n > max_header) bad("header length ", n, " bytes exceeds the limit of ", max_header, " bytes");
  if (n > bytes.size() - 8)
    bad("truncated: header length ", n, " bytes but only ", bytes.size() - 8, " bytes follow");
  const auto* text = reinterpret_cast<const char*>(bytes.data() + 8);
  if (n == 0 || text[0] != '{') bad("the header does not start with '{', expected a JSON object");

  // A first pass (SAX, no DOM) checks what the DOM would hide or what would make it costly:
  // duplicate keys, objects nested deeper than a tensor's entry, arrays outside an entry or longer
  // than safetensors_max_array. The DOM of a header that passes costs a small multiple of its
  // length, and both passes are linear in it.
  detail::SafetensorsHeaderCheck check;
  check.source = source;
  bool valid = false;
  try {
    valid = nlohmann::json::sax_parse(text, text + n, &check);
  } catch (const nlohmann::json::exception& e) {
    bad("the header is not valid JSON: ", e.what());
  }
  if (!valid) bad("the header is not valid JSON: ", check.syntax_error);
  if (!check.duplicate.empty()) bad("the header holds the key '", check.duplicate, "' twice");
  nlohmann::json header;
  try {
    header = nlohmann::json::parse(text, text + n);
  } catch (const nlohmann::json::exception& e) {
    bad("the header is not valid JSON: ", e.what());
  }
  if (!header.is_object()) bad("the header is not a JSON object");

  const std::size_t data_size = bytes.size() - 8 - n;
  struct Entry {
    std::string name;
    Tensor tensor;
    std::uint64_t begin, end;
  };
  std::vector<Entry> entries;
  SafetensorsFile file;
  file.set_source(source);
  for (const auto& [name, value] : header.items()) {
    if (name == "__metadata__") {
      if (!value.is_object()) bad("__metadata__ is not an object of strings");
      for (const auto& [k, v] : value.items()) {
        if (!v.is_string()) bad("__metadata__ entry '", k, "' is not a string");
        file.metadata.emplace(k, v.get<std::string>());
      }
      continue;
    }
    if (name.empty()) bad("a tensor has an empty name");
    if (!value.is_object()) bad("tensor '", name, "': entry is not an object");
    for (const auto& [k, v] : value.items()) {
      (void)v;
      if (k != "dtype" && k != "shape" && k != "data_offsets")
        bad("tensor '", name, "': unknown field '", k, "', expected only dtype, shape, data_offsets");
    }
    if (!value.contains("dtype") || !value["dtype"].is_string()) bad("tensor '", name, "': missing string 'dtype'");
    const auto dtype = dtype_from_name(value["dtype"].get<std::string>());
    if (!dtype) bad("tensor '", name, "': unknown dtype '", value["dtype"].get<std::string>(), "'");
    if (!value.contains("shape") || !value["shape"].is_array()) bad("tensor '", name, "': missing array 'shape'");
    Tensor t;
    t.dtype = *dtype;
    std::uint64_t numel = 1;
    for (const auto& s : value["shape"]) {
      if (!s.is_number_unsigned()) bad("tensor '", name, "': shape entry ", s.dump(), ", expected an integer >= 0");
      const auto dim = s.get<std::uint64_t>();
      if (dim > (std::uint64_t{1} << 53) || (dim != 0 && numel > (std::uint64_t{1} << 62) / dim))
        bad("tensor '", name, "': shape ", value["shape"].dump(), " is too large");
      numel *= dim;
      t.shape.push_back(static_cast<std::int64_t>(dim));
    }
    const auto& off = value.contains("data_offsets") ? value["data_offsets"] : nlohmann::json();
    if (!off.is_array() || off.size() != 2 || !off[0].is_number_unsigned() || !off[1].is_number_unsigned())
      bad("tensor '", name, "': data_offsets must be two integers >= 0");
    const auto begin = off[0].get<std::uint64_t>();
    const auto end = off[1].get<std::uint64_t>();
    if (begin > end) bad("tensor '", name, "': data_offsets [", begin, ", ", end, "] end before they begin");
    // numel * size can wrap in 64 bits: check before multiplying.
    if (numel > std::numeric_limits<std::uint64_t>::max() / dtype_size(t.dtype))
      bad("tensor '", name, "': ", dtype_name(t.dtype), " ", detail::shape_string(t.shape),
          " is too large (2^64 bytes or more)");
    const std::uint64_t expected = numel * dtype_size(t.dtype);
    if (end - begin != expected)
      bad("tensor '", name, "': data_offsets [", begin, ", ", end, "] hold ", end - begin, " bytes, expected ",
          expected, " for ", dtype_name(t.dtype), " ", detail::shape_string(t.shape));
    entries.push_back({name, std::move(t), begin, end});
  }

  // The byte ranges must tile [0, data_size) exactly.
  std::sort(entries.begin(), entries.end(),
            [](const Entry& a, const Entry& b) { return std::tie(a.begin, a.end) < std::tie(b.begin, b.end); });
  std::uint64_t pos = 0;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    if (e.begin < pos)
      bad("tensor '", e.name, "' (bytes [", e.begin, ", ", e.end, ")) overlaps tensor '", entries[i - 1].name,
          "' (bytes [", entries[i - 1].begin, ", ", entries[i - 1].end, "))");
    if (e.begin > pos) bad("data bytes [", pos, ", ", e.begin, ") belong to no tensor");
    pos = e.end;
  }
  if (pos > data_size)
    bad("truncated: the tensors need ", pos, " data bytes, the file holds ", data_size);
  if (pos < data_size) bad(data_size - pos, " data bytes after the last tensor belong to no tensor");

  const std::byte* data = bytes.data() + 8 + n;
  for (Entry& e : entries) {
    e.tensor.data.assign(data + e.begin, data + e.end);
    file.add(std::move(e.name), std::move(e.tensor));
  }
  return file;
}

inline void save_safetensors(const std::filesystem::path& path, const SafetensorsFile& file) {
  write_file_atomic_with(path, [&](std::ostream& out) { write_safetensors(out, file); });
}

inline SafetensorsFile load_safetensors(const std::filesystem::path& path,
                                        std::size_t max_header = safetensors_max_header) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) fail<FileError>(path.string(), ": cannot read: ", ec.message());
  std::ifstream in(path, std::ios::binary);
  if (!in) fail<FileError>(path.string(), ": cannot open for reading");
  std::vector<std::byte> bytes(static_cast<std::size_t>(size));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
  if (in.gcount() != static_cast<std::streamsize>(size))
    fail<FileError>(path.string(), ": read ", in.gcount(), " of ", size, " bytes");
  return parse_safetensors(bytes, path.string(), max_header);
}

}  // namespace tjepa
