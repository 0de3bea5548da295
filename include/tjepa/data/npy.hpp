#pragma once
// NumPy .npy files: read (versions 1, 2 and 3; float32 or float64, little-endian, C order) and
// write (float32/float64, version 1 unless the header needs 2), atomically.
//
// Format (numpy.lib.format): the magic "\x93NUMPY", a major and minor version byte, the header
// length (uint16 little-endian in version 1, uint32 in 2 and 3), then an ASCII (3: UTF-8) Python
// dict literal {'descr': '<f4', 'fortran_order': False, 'shape': (T, N, m), } padded with spaces
// and a newline so that the data start on a 64-byte boundary, then the raw values.
//
// Reading maps the file: float32 data are used in place (no copy, nothing held twice); float64 data
// are converted to float32 straight from the mapping. Every malformed file throws FileError naming
// the file and what is wrong; nothing a file holds can make the reader crash or over-read.
#include <algorithm>
#include <bit>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <ostream>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/atomic_write.hpp"
#include "tjepa/data/detail/float_storage.hpp"
#include "tjepa/data/detail/mapped_file.hpp"
#include "tjepa/data/recording.hpp"

namespace tjepa {

static_assert(std::endian::native == std::endian::little, "tjepa's .npy reader assumes a little-endian host");

// Integer arrays (label ids) are read too, as float: every value must be exactly a float
// (|v| <= 2^24), else read_npy throws naming the index.
enum class NpyDtype { float32, float64, int8, int16, int32, int64, uint8, uint16, uint32, uint64 };

inline const char* npy_dtype_name(NpyDtype d) {
  constexpr const char* names[] = {"float32", "float64", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64"};
  return names[static_cast<int>(d)];
}
inline std::size_t npy_item_size(NpyDtype d) {
  constexpr std::size_t sizes[] = {4, 8, 1, 2, 4, 8, 1, 2, 4, 8};
  return sizes[static_cast<int>(d)];
}

struct NpyHeader {
  int major_version = 1;
  int minor_version = 0;
  NpyDtype dtype = NpyDtype::float32;
  bool fortran_order = false;
  std::vector<std::int64_t> shape;
  std::size_t data_offset = 0;  // bytes before the first value

  std::size_t item_size() const { return npy_item_size(dtype); }
  std::size_t numel() const {
    std::size_t n = 1;
    for (auto s : shape) n *= static_cast<std::size_t>(s);
    return n;
  }
};

namespace detail {

inline std::string shape_string(std::span<const std::int64_t> shape) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    s += std::to_string(shape[i]);
    s += (shape.size() == 1 || i + 1 < shape.size()) ? "," : "";
    if (i + 1 < shape.size()) s += " ";
  }
  return s + ")";
}

// The subset of Python literals a .npy header uses: a dict of strings, booleans and int tuples.
class NpyHeaderParser {
 public:
  NpyHeaderParser(std::string_view text, const std::string& file) : text_(text), file_(file) {}

  NpyHeader parse() {
    NpyHeader h;
    bool have_descr = false, have_order = false, have_shape = false;
    skip_space();
    if (!eat('{'))
      error("the header is not a Python dict (it must start with '{')");
    skip_space();
    while (!eat('}')) {
      const std::string key = parse_string("a dict key");
      skip_space();
      if (!eat(':')) error("expected ':' after key '" + key + "'");
      skip_space();
      if (key == "descr") {
        if (have_descr) error("duplicate key 'descr'");
        have_descr = true;
        if (peek() != '\'' && peek() != '"')
          error("'descr' is not a string (structured dtypes are not supported)");
        h.dtype = parse_dtype(parse_string("the 'descr' value"));
      } else if (key == "fortran_order") {
        if (have_order) error("duplicate key 'fortran_order'");
        have_order = true;
        h.fortran_order = parse_bool();
      } else if (key == "shape") {
        if (have_shape) error("duplicate key 'shape'");
        have_shape = true;
        h.shape = parse_shape();
      } else {
        error("unexpected key '" + key + "' (expected only 'descr', 'fortran_order' and 'shape')");
      }
      skip_space();
      if (eat(',')) {
        skip_space();
        continue;
      }
      skip_space();
      if (peek() != '}') error("expected ',' or '}' after the value of '" + key + "'");
    }
    skip_space();
    if (pos_ != text_.size()) error("unexpected text after the closing '}'");
    if (!have_descr) error("missing key 'descr'");
    if (!have_order) error("missing key 'fortran_order'");
    if (!have_shape) error("missing key 'shape'");
    if (h.fortran_order)
      fail<FileError>(file_, ": Fortran-order arrays are not supported; save a C-order array "
                             "(numpy.ascontiguousarray) instead");
    return h;
  }

 private:
  [[noreturn]] void error(const std::string& what) const {
    const std::string_view shown = text_.substr(0, 200);
    fail<FileError>(file_, ": malformed .npy header: ", what, " (at character ", pos_, " of \"", shown,
                    text_.size() > shown.size() ? "..." : "", "\")");
  }
  char peek() const { return pos_ < text_.size() ? text_[pos_] : '\0'; }
  bool eat(char c) {
    if (peek() != c || pos_ >= text_.size()) return false;
    ++pos_;
    return true;
  }
  void skip_space() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t' || text_[pos_] == '\n' ||
                                   text_[pos_] == '\r'))
      ++pos_;
  }
  std::string parse_string(const char* what) {
    const char q = peek();
    if (q != '\'' && q != '"') error(std::string("expected a quoted string for ") + what);
    ++pos_;
    const std::size_t end = text_.find(q, pos_);
    if (end == std::string_view::npos) error("unterminated string");
    std::string s(text_.substr(pos_, end - pos_));
    pos_ = end + 1;
    return s;
  }
  bool parse_bool() {
    if (text_.substr(pos_, 4) == "True") {
      pos_ += 4;
      return true;
    }
    if (text_.substr(pos_, 5) == "False") {
      pos_ += 5;
      return false;
    }
    error("'fortran_order' is not True or False");
  }
  std::vector<std::int64_t> parse_shape() {
    if (!eat('(')) error("'shape' is not a tuple");
    std::vector<std::int64_t> shape;
    skip_space();
    while (!eat(')')) {
      if (!std::isdigit(static_cast<unsigned char>(peek()))) error("'shape' holds something other than a non-negative integer");
      std::int64_t v = 0;
      while (std::isdigit(static_cast<unsigned char>(peek()))) {
        if (v > (std::numeric_limits<std::int64_t>::max() - 9) / 10) error("a 'shape' entry is too large");
        v = v * 10 + (text_[pos_++] - '0');
      }
      if (eat('L')) {}  // Python 2 long suffix
      shape.push_back(v);
      skip_space();
      if (eat(',')) {
        skip_space();
        continue;
      }
      if (peek() != ')') error("expected ',' or ')' in 'shape'");
    }
    return shape;
  }
  NpyDtype parse_dtype(const std::string& d) const {
    if (d.size() == 3 && (d[0] == '<' || d[0] == '=') && d[1] == 'f') {
      if (d[2] == '4') return NpyDtype::float32;
      if (d[2] == '8') return NpyDtype::float64;
    }
    // integers: '<i8', '<u4', '|i1', '|u1' (one byte has no byte order)
    if (d.size() == 3 && (d[1] == 'i' || d[1] == 'u') &&
        (d[0] == '<' || d[0] == '=' || (d[0] == '|' && d[2] == '1'))) {
      const bool u = d[1] == 'u';
      switch (d[2]) {
        case '1': return u ? NpyDtype::uint8 : NpyDtype::int8;
        case '2': return u ? NpyDtype::uint16 : NpyDtype::int16;
        case '4': return u ? NpyDtype::uint32 : NpyDtype::int32;
        case '8': return u ? NpyDtype::uint64 : NpyDtype::int64;
        default: break;
      }
    }
    if (d.size() == 3 && d[0] == '>' && (d[1] == 'f' || d[1] == 'i' || d[1] == 'u'))
      fail<FileError>(file_, ": big-endian dtype '", d, "' is not supported; convert with arr.astype('<", d[1],
                      d[2], "')");
    fail<FileError>(file_, ": unsupported dtype '", d,
                    "': expected float32 ('<f4'), float64 ('<f8') or a little-endian integer ('<i8', '<u2', '|u1', ...)");
  }

  std::string_view text_;
  const std::string& file_;
  std::size_t pos_ = 0;
};

}  // namespace detail

// Parses and checks the header of a whole .npy file held in bytes[0, size): magic, version,
// header dict, dtype, order, and that the data after the header are exactly numel·item_size bytes.
inline NpyHeader parse_npy_header(const char* bytes, std::size_t size, const std::string& file) {
  static constexpr char magic[6] = {'\x93', 'N', 'U', 'M', 'P', 'Y'};
  require<FileError>(size > 0, file, ": empty file, expected a NumPy .npy file");
  require<FileError>(size >= 6 && std::memcmp(bytes, magic, 6) == 0, file,
                     ": bad magic: not a NumPy .npy file (expected the bytes \\x93NUMPY at the start)");
  require<FileError>(size >= 8, file, ": truncated header: the file ends inside the version bytes");
  const int major = static_cast<unsigned char>(bytes[6]), minor = static_cast<unsigned char>(bytes[7]);
  require<FileError>(major >= 1 && major <= 3 && minor == 0, file, ": unsupported .npy format version ", major, ".",
                     minor, ", expected 1.0, 2.0 or 3.0");
  const std::size_t len_bytes = major == 1 ? 2 : 4;
  require<FileError>(size >= 8 + len_bytes, file, ": truncated header: the file ends inside the header length");
  std::size_t header_len = 0;
  for (std::size_t i = 0; i < len_bytes; ++i)
    header_len |= static_cast<std::size_t>(static_cast<unsigned char>(bytes[8 + i])) << (8 * i);
  const std::size_t prefix = 8 + len_bytes;
  require<FileError>(header_len <= size - prefix, file, ": truncated header: it claims ", header_len,
                     " bytes but the file has only ", size - prefix, " after the header length");
  NpyHeader h = detail::NpyHeaderParser(std::string_view(bytes + prefix, header_len), file).parse();
  h.major_version = major;
  h.minor_version = minor;
  h.data_offset = prefix + header_len;
  // numel·item_size without overflow.
  std::size_t need = h.item_size();
  for (auto s : h.shape) {
    const auto us = static_cast<std::size_t>(s);
    require<FileError>(us == 0 || need <= std::numeric_limits<std::size_t>::max() / us, file, ": shape ",
                       detail::shape_string(h.shape), " is too large");
    need *= us;
  }
  const std::size_t have = size - h.data_offset;
  const char* type = npy_dtype_name(h.dtype);
  require<FileError>(have >= need, file, ": truncated data: shape ", detail::shape_string(h.shape), " of ", type,
                     " needs ", need, " bytes but the file has only ", have, " after the header");
  require<FileError>(have == need, file, ": shape/data size mismatch: shape ", detail::shape_string(h.shape),
                     " of ", type, " needs ", need, " bytes but the file has ", have, " after the header");
  return h;
}

// Reads only the header of a .npy file (the file is mapped, not read).
inline NpyHeader read_npy_header(const std::filesystem::path& path) {
  detail::MappedFile f(path);
  return parse_npy_header(f.data(), f.size(), f.path());
}

// An n-dimensional float32 array read from a .npy file (row-major, C order).
struct NpyArray {
  std::vector<std::int64_t> shape;
  detail::FloatStorage values;  // numel floats, possibly a read-only view into the mapped file
  std::string source;           // the file name

  std::size_t numel() const { return values.size(); }
  const float* data() const { return values.data(); }
};

struct NpyReadOptions {
  // Throw DataError (naming the element's index) if any value is NaN or ±Inf.
  bool require_finite = false;
  // Map the file and use float32 data in place (no copy of a multi-GB recording). The file must
  // then not be truncated or rewritten in place while the array lives (SIGBUS; replacing it by
  // rename is safe). false: read the file into memory, never mapped.
  bool map = true;
};

namespace detail {
// n integers of dtype d at src into out, each exactly (|v| <= 2^24), else FileError naming the index.
inline void integers_to_float(NpyDtype d, const char* src, std::size_t n, float* out, const std::string& file) {
  auto convert = [&](auto tag) {
    using I = decltype(tag);
    for (std::size_t i = 0; i < n; ++i) {
      I x;
      std::memcpy(&x, src + i * sizeof(I), sizeof(I));
      if constexpr (sizeof(I) >= 4) {
        constexpr I limit = I(1) << 24;
        bool exact = x <= limit;
        if constexpr (std::is_signed_v<I>) exact = exact && x >= -limit;
        require<FileError>(exact, file, ": value ", static_cast<long long>(x), " at flat index ", i, " of ",
                           npy_dtype_name(d), " data is not exactly a float32 (|v| > 2^24)");
      }
      out[i] = static_cast<float>(x);
    }
  };
  switch (d) {
    case NpyDtype::int8: convert(std::int8_t{}); break;
    case NpyDtype::int16: convert(std::int16_t{}); break;
    case NpyDtype::int32: convert(std::int32_t{}); break;
    case NpyDtype::int64: convert(std::int64_t{}); break;
    case NpyDtype::uint8: convert(std::uint8_t{}); break;
    case NpyDtype::uint16: convert(std::uint16_t{}); break;
    case NpyDtype::uint32: convert(std::uint32_t{}); break;
    case NpyDtype::uint64: convert(std::uint64_t{}); break;
    default: fail<FileError>(file, ": not an integer dtype");
  }
}
}  // namespace detail

inline NpyArray read_npy(const std::filesystem::path& path, const NpyReadOptions& opt = {}) {
  auto file = std::make_shared<detail::MappedFile>(path, !opt.map);
  const NpyHeader h = parse_npy_header(file->data(), file->size(), file->path());
  NpyArray out;
  out.shape = h.shape;
  out.source = file->path();
  const std::size_t n = h.numel();
  const char* src = file->data() + h.data_offset;
  // float32 data are used in place (mapped, or in the buffer the file was read into).
  if (h.dtype == NpyDtype::float32 && reinterpret_cast<std::uintptr_t>(src) % alignof(float) == 0) {
    const float* p = reinterpret_cast<const float*>(static_cast<const void*>(src));
    out.values = detail::FloatStorage(p, n, file);
  } else {
    AlignedVector<float> v(n);
    if (h.dtype == NpyDtype::float32) {
      if (n > 0) std::memcpy(v.data(), src, n * sizeof(float));
    } else if (h.dtype == NpyDtype::float64) {
      for (std::size_t i = 0; i < n; ++i) {
        double d;
        std::memcpy(&d, src + i * sizeof(double), sizeof(double));
        v[i] = static_cast<float>(d);
      }
    } else {
      detail::integers_to_float(h.dtype, src, n, v.data(), out.source);
    }
    out.values = detail::FloatStorage(std::move(v));
  }
  if (opt.require_finite) {
    const std::size_t i = find_non_finite(out.values.values());
    if (i != n) {
      std::string idx = "[";
      std::size_t rest = i;
      std::vector<std::int64_t> multi(h.shape.size());
      for (std::size_t d = h.shape.size(); d-- > 0;) {
        multi[d] = static_cast<std::int64_t>(rest % static_cast<std::size_t>(h.shape[d]));
        rest /= static_cast<std::size_t>(h.shape[d]);
      }
      for (std::size_t d = 0; d < multi.size(); ++d) idx += (d ? ", " : "") + std::to_string(multi[d]);
      idx += "]";
      fail<DataError>(out.source, ": value ", out.values.data()[i], " at index ", idx,
                      (h.shape.size() == 3 ? " (frame, taxel, axis)" : ""), ", expected finite data");
    }
  }
  return out;
}

// Reads a recording: a [T, N, m] array, or [T, N] (then m = 1). With `axes` > 0 a 2-D array
// [T, N·axes] is also accepted (columns taxel-major, axis fastest).
inline Recording read_recording_npy(const std::filesystem::path& path, int axes = 0, const NpyReadOptions& opt = {}) {
  NpyArray a = read_npy(path, opt);
  const auto& s = a.shape;
  auto fits_int = [](std::int64_t v) { return v <= std::numeric_limits<int>::max(); };
  if (s.size() == 3) {
    require<ShapeError>(axes <= 0 || s[2] == axes, a.source, ": shape ", detail::shape_string(s), " has ", s[2],
                        " axes, expected ", axes, " (read it with axes = ", s[2], "; on the command line --axes ", s[2], ")");
    require<ShapeError>(s[1] > 0 && s[2] > 0 && fits_int(s[0]) && fits_int(s[1]) && fits_int(s[2]), a.source,
                        ": shape ", detail::shape_string(s), ", expected [frames, taxels > 0, axes > 0]");
    return Recording(static_cast<int>(s[0]), static_cast<int>(s[1]), static_cast<int>(s[2]), std::move(a.values),
                     a.source);
  }
  if (s.size() == 2) {
    const std::int64_t m = axes > 0 ? axes : 1;
    require<ShapeError>(s[1] > 0 && s[1] % m == 0 && fits_int(s[0]) && fits_int(s[1]), a.source, ": shape ",
                        detail::shape_string(s), " has ", s[1], " columns, expected a positive multiple of ", m,
                        " axes");
    return Recording(static_cast<int>(s[0]), static_cast<int>(s[1] / m), static_cast<int>(m), std::move(a.values),
                     a.source);
  }
  fail<ShapeError>(a.source, ": shape ", detail::shape_string(s),
                   " is not a recording, expected [frames, taxels, axes] or [frames, taxels]");
}

// Writes values (row-major, shape `shape`) as a .npy file, atomically. T is float or double.
template <class T>
void write_npy(const std::filesystem::path& path, std::span<const T> values, std::span<const std::int64_t> shape) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "write_npy: float or double only");
  std::size_t n = 1;
  for (auto s : shape) {
    require<ShapeError>(s >= 0, "write_npy(", path.string(), "): negative dimension ", s, " in shape ",
                        detail::shape_string(shape));
    n *= static_cast<std::size_t>(s);
  }
  require<ShapeError>(n == values.size(), "write_npy(", path.string(), "): shape ", detail::shape_string(shape),
                      " holds ", n, " values, got ", values.size());
  std::string dict = std::string("{'descr': '<f") + (sizeof(T) == 4 ? "4" : "8") +
                     "', 'fortran_order': False, 'shape': " + detail::shape_string(shape) + ", }";
  // Pad with spaces and a final newline so the data start on a 64-byte boundary.
  const bool v2 = dict.size() + 1 + 10 > 65535;
  const std::size_t prefix = v2 ? 12 : 10;
  const std::size_t total = (prefix + dict.size() + 1 + 63) / 64 * 64;
  dict.append(total - prefix - dict.size() - 1, ' ');
  dict.push_back('\n');
  write_file_atomic_with(path, [&](std::ostream& out) {
    const char magic[8] = {'\x93', 'N', 'U', 'M', 'P', 'Y', static_cast<char>(v2 ? 2 : 1), 0};
    out.write(magic, 8);
    const std::size_t len = dict.size();
    char lb[4] = {static_cast<char>(len & 0xff), static_cast<char>((len >> 8) & 0xff),
                  static_cast<char>((len >> 16) & 0xff), static_cast<char>((len >> 24) & 0xff)};
    out.write(lb, v2 ? 4 : 2);
    out.write(dict.data(), static_cast<std::streamsize>(dict.size()));
    out.write(reinterpret_cast<const char*>(values.data()), static_cast<std::streamsize>(n * sizeof(T)));
  });
}

template <class T>
void write_npy(const std::filesystem::path& path, std::span<const T> values, std::initializer_list<std::int64_t> shape) {
  const std::vector<std::int64_t> s(shape);
  write_npy<T>(path, values, std::span<const std::int64_t>(s));
}

// Writes a recording as a [T, N, m] float32 array.
inline void write_npy(const std::filesystem::path& path, const Recording& rec) {
  const std::int64_t shape[3] = {rec.frames(), rec.taxels(), rec.axes()};
  write_npy<float>(path, rec.values(), std::span<const std::int64_t>(shape));
}

}  // namespace tjepa
