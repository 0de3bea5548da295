// Readers and writer: .npy (good files of every supported kind, and a corpus of malformed ones
// generated into a temporary directory) and text/CSV recordings.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <csignal>

#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using tjepa_test::TempDir;

void write_bytes(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A .npy file as NumPy writes it: magic, version, header length, dict padded to 64 bytes.
std::string npy_bytes(const std::string& dict, const std::string& data, int major = 1, bool pad = true) {
  std::string h = dict;
  const std::size_t prefix = major == 1 ? 10 : 12;
  if (pad) {
    const std::size_t total = (prefix + h.size() + 1 + 63) / 64 * 64;
    h.append(total - prefix - h.size() - 1, ' ');
    h.push_back('\n');
  }
  std::string s = "\x93NUMPY";
  s.push_back(static_cast<char>(major));
  s.push_back(0);
  const std::size_t len = h.size();
  s.push_back(static_cast<char>(len & 0xff));
  s.push_back(static_cast<char>((len >> 8) & 0xff));
  if (major != 1) {
    s.push_back(static_cast<char>((len >> 16) & 0xff));
    s.push_back(static_cast<char>((len >> 24) & 0xff));
  }
  return s + h + data;
}

template <class T>
std::string raw(const std::vector<T>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

std::vector<float> ramp(std::size_t n) {
  std::vector<float> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = 0.5f * static_cast<float>(i) - 3.0f;
  return v;
}

tjepa::TextFormat text_format(int axes, int taxels = 0, int skip_rows = 0, std::vector<int> columns = {},
                              bool require_finite = false) {
  tjepa::TextFormat f;
  f.axes = axes;
  f.taxels = taxels;
  f.skip_rows = skip_rows;
  f.columns = std::move(columns);
  f.require_finite = require_finite;
  return f;
}

std::string dict(const std::string& descr, const std::string& shape, const std::string& order = "False") {
  return "{'descr': '" + descr + "', 'fortran_order': " + order + ", 'shape': " + shape + ", }";
}

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("npy: float32 and float64 in versions 1 2 and 3 read back exactly") {
    TempDir dir;
    const auto v = ramp(24);
    std::vector<double> vd(v.begin(), v.end());
    write_bytes(dir / "f4v1.npy", npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v)));
    write_bytes(dir / "f8v1.npy", npy_bytes(dict("<f8", "(2, 4, 3)"), raw(vd)));
    write_bytes(dir / "f4v2.npy", npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v), 2));
    write_bytes(dir / "f4v3.npy", npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v), 3));
    // Keys in another order, double quotes, no trailing comma, '=' byte order, no padding.
    write_bytes(dir / "odd.npy",
                npy_bytes("{\"shape\": (2,4,3), \"fortran_order\": False, \"descr\": \"=f4\"}", raw(v), 1, false));
    for (const char* name : {"f4v1.npy", "f8v1.npy", "f4v2.npy", "f4v3.npy", "odd.npy"}) {
      CAPTURE(name);
      const tjepa::NpyArray a = tjepa::read_npy(dir / name);
      CHECK(a.shape == std::vector<std::int64_t>{2, 4, 3});
      REQUIRE(a.numel() == 24);
      for (std::size_t i = 0; i < 24; ++i) CHECK(a.data()[i] == v[i]);
      const tjepa::Recording r = tjepa::read_recording_npy(dir / name);
      CHECK(r.frames() == 2);
      CHECK(r.taxels() == 4);
      CHECK(r.axes() == 3);
      CHECK(r(1, 2, 1) == v[(1 * 4 + 2) * 3 + 1]);
    }
    // float32 files stay mapped (shared, read-only) until written to; then they are copied.
    tjepa::Recording r = tjepa::read_recording_npy(dir / "f4v1.npy");
    CHECK(r.shares_values());
    r.at(0, 0, 0) = 42.0f;
    CHECK_FALSE(r.shares_values());
    CHECK(tjepa::read_recording_npy(dir / "f4v1.npy")(0, 0, 0) == v[0]);
    // 2-D arrays: [T, N] (one axis), or [T, N*m] with the axes given.
    write_bytes(dir / "2d.npy", npy_bytes(dict("<f4", "(4, 6)"), raw(ramp(24))));
    CHECK(tjepa::read_recording_npy(dir / "2d.npy").taxels() == 6);
    const auto r3 = tjepa::read_recording_npy(dir / "2d.npy", 3);
    CHECK(r3.taxels() == 2);
    CHECK(r3.axes() == 3);
    CHECK_THROWS_WITH_AS(tjepa::read_recording_npy(dir / "2d.npy", 4), doctest::Contains("multiple of 4"),
                         tjepa::ShapeError);
    // Zero frames and a 1-D shape.
    write_bytes(dir / "empty.npy", npy_bytes(dict("<f4", "(0, 5, 3)"), ""));
    CHECK(tjepa::read_recording_npy(dir / "empty.npy").frames() == 0);
    write_bytes(dir / "1d.npy", npy_bytes(dict("<f4", "(3,)"), raw(ramp(3))));
    CHECK(tjepa::read_npy(dir / "1d.npy").shape == std::vector<std::int64_t>{3});
    CHECK_THROWS_WITH_AS(tjepa::read_recording_npy(dir / "1d.npy"), doctest::Contains("not a recording"),
                         tjepa::ShapeError);
  }

  TEST_CASE("npy: write_npy round-trips atomically and pads the header to 64 bytes") {
    TempDir dir;
    const auto v = ramp(2 * 5 * 3);
    tjepa::Recording rec(2, 5, 3, tjepa::AlignedVector<float>(v.begin(), v.end()));
    tjepa::write_npy(dir / "rec.npy", rec);
    const tjepa::NpyHeader h = tjepa::read_npy_header(dir / "rec.npy");
    CHECK(h.major_version == 1);
    CHECK(h.data_offset % 64 == 0);
    CHECK(h.shape == std::vector<std::int64_t>{2, 5, 3});
    const auto back = tjepa::read_recording_npy(dir / "rec.npy");
    for (std::size_t i = 0; i < v.size(); ++i) CHECK(back.values()[i] == v[i]);
    // Doubles and a 1-D shape; overwriting replaces the file and leaves no temporary behind.
    std::vector<double> d = {1.0, -2.5, 1e-300};
    tjepa::write_npy<double>(dir / "d.npy", d, {3});
    tjepa::write_npy<double>(dir / "d.npy", d, {3, 1});
    const auto a = tjepa::read_npy(dir / "d.npy");
    CHECK(a.shape == std::vector<std::int64_t>{3, 1});
    CHECK(a.data()[1] == -2.5f);
    int files = 0;
    for (const auto& e : fs::directory_iterator(dir.path)) {
      ++files;
      CHECK(e.path().string().find("tjepa-tmp") == std::string::npos);
    }
    CHECK(files == 2);
    CHECK_THROWS_WITH_AS(tjepa::write_npy<float>(dir / "x.npy", std::vector<float>(5), {2, 3}),
                         doctest::Contains("holds 6 values, got 5"), tjepa::ShapeError);
    CHECK_THROWS_AS(tjepa::write_npy(dir / "no_such_dir" / "x.npy", rec), tjepa::FileError);
  }

  TEST_CASE("npy: a mapped array dies with SIGBUS when its file is truncated in place - a copying read does not") {
    TempDir dir;
    const auto v = ramp(64 * 1024);  // 256 KiB of data: many pages
    tjepa::write_npy<float>(dir / "rec.npy", v, {64, 1024});
    tjepa::NpyReadOptions copy;
    copy.map = false;
    const tjepa::NpyArray copied = tjepa::read_npy(dir / "rec.npy", copy);
    // The mapping's promise, in a child: truncate in place, touch the last page.
    const ::pid_t child = ::fork();
    REQUIRE(child >= 0);
    if (child == 0) {
      std::signal(SIGBUS, SIG_DFL);  // sanitizers catch SIGBUS and exit; let the kernel's default act
      const tjepa::NpyArray mapped = tjepa::read_npy(dir / "rec.npy");
      if (::truncate((dir / "rec.npy").c_str(), 128) != 0) ::_exit(3);
      volatile float sink = mapped.data()[mapped.numel() - 1];
      (void)sink;
      ::_exit(0);
    }
    int status = 0;
    REQUIRE(::waitpid(child, &status, 0) == child);
    // Killed by SIGBUS (or, under a sanitizer that keeps its own handler, its report and exit).
    if (WIFSIGNALED(status)) CHECK(WTERMSIG(status) == SIGBUS);
    else CHECK((WIFEXITED(status) && WEXITSTATUS(status) != 0 && WEXITSTATUS(status) != 3));
    // The copy is unaffected (the file is truncated now).
    CHECK(fs::file_size(dir / "rec.npy") == 128u);
    REQUIRE(copied.numel() == v.size());
    CHECK(copied.data()[v.size() - 1] == v.back());
    CHECK_THROWS_AS(tjepa::read_npy(dir / "rec.npy", copy), tjepa::FileError);
    // Replacing the file by rename (tjepa's writers) keeps a mapped array intact.
    tjepa::write_npy<float>(dir / "rec.npy", v, {64, 1024});
    const tjepa::NpyArray mapped = tjepa::read_npy(dir / "rec.npy");
    tjepa::write_npy<float>(dir / "rec.npy", std::vector<float>(16, 0.f), {16});
    CHECK(mapped.data()[v.size() - 1] == v.back());
  }

  TEST_CASE("npy: every malformed file gives a FileError that names the file and the problem") {
    TempDir dir;
    const auto v = ramp(24);
    const std::string good = npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v));
    struct Bad {
      const char* name;
      std::string bytes;
      const char* message;
    };
    std::string bad_version = good;
    bad_version[6] = 9;
    std::string huge_len = good;
    huge_len[8] = '\xff';
    huge_len[9] = '\x7f';
    const std::vector<Bad> corpus = {
        {"empty.npy", "", "empty file"},
        {"magic.npy", "\x93NUMPX" + good.substr(6), "bad magic"},
        {"short_magic.npy", "\x93NU", "bad magic"},
        {"text.npy", "hello, world\n1 2 3\n", "bad magic"},
        {"version.npy", bad_version, "unsupported .npy format version 9.0"},
        {"no_length.npy", good.substr(0, 9), "truncated header"},
        {"truncated_header.npy", good.substr(0, 30), "truncated header"},
        {"huge_header_len.npy", huge_len, "truncated header"},
        {"not_dict.npy", npy_bytes("['descr', '<f4']", raw(v)), "not a Python dict"},
        {"not_dict2.npy", npy_bytes("descr: <f4", raw(v)), "not a Python dict"},
        {"unterminated.npy", npy_bytes("{'descr': '<f4", raw(v)), "unterminated string"},
        {"no_shape.npy", npy_bytes("{'descr': '<f4', 'fortran_order': False}", raw(v)), "missing key 'shape'"},
        {"extra_key.npy", npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': (24,), 'x': 1}", raw(v)),
         "unexpected key 'x'"},
        {"dup_key.npy", npy_bytes("{'descr': '<f4', 'descr': '<f4', 'fortran_order': False, 'shape': (24,)}", raw(v)),
         "duplicate key 'descr'"},
        {"shape_not_tuple.npy", npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': [24]}", raw(v)),
         "not a tuple"},
        {"shape_negative.npy", npy_bytes(dict("<f4", "(-24,)"), raw(v)), "non-negative integer"},
        {"shape_huge.npy", npy_bytes(dict("<f4", "(99999999999999999999,)"), raw(v)), "too large"},
        {"shape_overflow.npy", npy_bytes(dict("<f4", "(4294967296, 4294967296, 4294967296)"), raw(v)), "too large"},
        {"order_not_bool.npy", npy_bytes(dict("<f4", "(24,)", "0"), raw(v)), "not True or False"},
        {"structured.npy", npy_bytes("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (24,)}", raw(v)),
         "structured dtypes"},
        {"complex.npy", npy_bytes(dict("<c8", "(24,)"), std::string(192, '\0')), "unsupported dtype '<c8'"},
        {"int64_big.npy", npy_bytes(dict("<i8", "(3,)"), std::string("\0\0\0\0\0\0\0\0\1\0\0\0\0\0\0\0\0\0\0\x02\0\0\0\0", 24)),
         "value 33554432 at flat index 2 of int64 data is not exactly a float32"},
        {"float16.npy", npy_bytes(dict("<f2", "(24,)"), std::string(48, '\0')), "unsupported dtype '<f2'"},
        {"big_endian.npy", npy_bytes(dict(">f4", "(2, 4, 3)"), raw(v)), "big-endian"},
        {"fortran.npy", npy_bytes(dict("<f4", "(2, 4, 3)", "True"), raw(v)), "Fortran-order"},
        {"truncated_data.npy", good.substr(0, good.size() - 5), "truncated data"},
        {"too_much_data.npy", good + std::string(8, '\0'), "shape/data size mismatch"},
        {"shape_mismatch.npy", npy_bytes(dict("<f4", "(2, 4, 4)"), raw(v)), "truncated data"},
        {"trailing.npy", npy_bytes(dict("<f4", "(2, 4, 3)") + " junk", raw(v)), "after the closing"},
    };
    for (const Bad& b : corpus) {
      CAPTURE(b.name);
      write_bytes(dir / b.name, b.bytes);
      const std::string file = (dir / b.name).string();
      CHECK_THROWS_WITH_AS(tjepa::read_npy(dir / b.name), doctest::Contains(b.message), tjepa::FileError);
      CHECK_THROWS_WITH_AS(tjepa::read_npy(dir / b.name), doctest::Contains(file.c_str()), tjepa::FileError);
    }
    CHECK_THROWS_WITH_AS(tjepa::read_npy(dir / "does_not_exist.npy"), doctest::Contains("no such file"),
                         tjepa::FileError);
    CHECK_THROWS_AS(tjepa::read_npy(dir.path), tjepa::FileError);  // a directory
  }

  TEST_CASE("npy: random corruptions and truncations either read or throw tjepa::Error") {
    TempDir dir;
    const auto v = ramp(24);
    const std::string good = npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v));
    tjepa::Rng rng(17);
    int read = 0, rejected = 0;
    for (int trial = 0; trial < 600; ++trial) {
      std::string bytes = good;
      if (trial % 3 == 0) {
        bytes.resize(rng.below(bytes.size() + 1));
      } else {
        const int flips = 1 + static_cast<int>(rng.below(4));
        for (int k = 0; k < flips; ++k) bytes[rng.below(64)] = static_cast<char>(rng.below(256));
      }
      const fs::path p = dir / ("fuzz" + std::to_string(trial) + ".npy");
      write_bytes(p, bytes);
      try {
        const tjepa::NpyArray a = tjepa::read_npy(p);
        CHECK(a.numel() * sizeof(float) <= bytes.size());
        ++read;
      } catch (const tjepa::Error&) {
        ++rejected;
      }
    }
    CHECK(read + rejected == 600);
    CHECK(rejected > 300);
  }

  TEST_CASE("npy: NaN or Inf is a DataError naming its index when the caller asks for finite data") {
    TempDir dir;
    auto v = ramp(24);
    v[(1 * 4 + 2) * 3 + 0] = std::numeric_limits<float>::quiet_NaN();
    write_bytes(dir / "nan.npy", npy_bytes(dict("<f4", "(2, 4, 3)"), raw(v)));
    CHECK_NOTHROW(tjepa::read_npy(dir / "nan.npy"));  // not asked
    tjepa::NpyReadOptions opt;
    opt.require_finite = true;
    CHECK_THROWS_WITH_AS(tjepa::read_npy(dir / "nan.npy", opt), doctest::Contains("index [1, 2, 0] (frame, taxel, axis)"),
                         tjepa::DataError);
    std::vector<double> d(24, 1.0);
    d[23] = std::numeric_limits<double>::infinity();
    write_bytes(dir / "inf.npy", npy_bytes(dict("<f8", "(2, 4, 3)"), raw(d)));
    CHECK_THROWS_WITH_AS(tjepa::read_recording_npy(dir / "inf.npy", 0, opt), doctest::Contains("[1, 3, 2]"),
                         tjepa::DataError);
  }

  TEST_CASE("text: whitespace and CSV recordings with comments and header rows and a column map") {
    TempDir dir;
    write_bytes(dir / "ws.txt", "# two taxels, two axes\n1 2 3 4\n\n  5\t6 7 8  \n");
    const auto a = tjepa::read_text_recording(dir / "ws.txt", text_format(2));
    CHECK(a.frames() == 2);
    CHECK(a.taxels() == 2);
    CHECK(a(1, 0, 1) == 6.0f);
    CHECK(a(1, 1, 1) == 8.0f);
    write_bytes(dir / "c.csv", "t0x,t0y,t1x,t1y\r\n1.5, -2e3 ,+3,4\r\n5,6,7,nan\r\n");
    const auto b = tjepa::read_text_recording(dir / "c.csv", text_format(2, 0, 1));
    CHECK(b(0, 0, 1) == -2000.0f);
    CHECK(b(0, 1, 0) == 3.0f);
    CHECK(std::isnan(b(1, 1, 1)));
    // Column map: taxel 0 = columns (3, 1), taxel 1 = columns (0, 2); column 4 ignored.
    write_bytes(dir / "map.csv", "10,11,12,13,99\n20,21,22,23,99\n");
    const auto c = tjepa::read_text_recording(dir / "map.csv", text_format(2, 0, 0, {3, 1, 0, 2}));
    CHECK(c.taxels() == 2);
    CHECK(c(0, 0, 0) == 13.0f);
    CHECK(c(0, 0, 1) == 11.0f);
    CHECK(c(1, 1, 0) == 20.0f);
    CHECK(c(1, 1, 1) == 22.0f);
  }

  TEST_CASE("text: malformed files give file:line and what is wrong") {
    TempDir dir;
    auto bad = [&](const std::string& name, const std::string& text, const tjepa::TextFormat& fmt, const char* msg) {
      CAPTURE(name);
      write_bytes(dir / name, text);
      CHECK_THROWS_WITH_AS(tjepa::read_text_recording(dir / name, fmt), doctest::Contains(msg), tjepa::Error);
    };
    const std::string f = (dir / "cols.txt").string();
    bad("cols.txt", "1 2 3\n4 5\n", {}, ":2: 2 columns, expected 3");
    CHECK_THROWS_WITH(tjepa::read_text_recording(dir / "cols.txt"), doctest::Contains((f + ":2:").c_str()));
    bad("cols2.csv", "# header comment\n1,2,3\n4,5,6,7\n", {}, ":3: 4 columns, expected 3");
    bad("word.txt", "1 2\n3 abc\n", {}, ":2: column 2: 'abc' is not a number");
    bad("partial.txt", "1 2\n3 4x\n", {}, "'4x' is not a number");
    bad("emptyfield.csv", "1,2\n3,\n", {}, ":2: column 2: '' is not a number");
    bad("axes.txt", "1 2 3\n", text_format(2), ":1: 3 columns, expected a multiple of axes = 2");
    bad("taxels.txt", "1 2 3 4\n", text_format(2, 3), "expected taxels*axes = 3*2 = 6");
    bad("map_range.csv", "1,2,3\n", text_format(1, 0, 0, {0, 5}), "column map refers to column 5");
    bad("nodata.txt", "# nothing\n\n", {}, "no data rows");
    bad("nan.txt", "1 2\n3 nan\n", text_format(1, 0, 0, {}, true), ":2: column 2: value nan (frame 1, taxel 1, axis 0)");
    CHECK_THROWS_AS(tjepa::read_text_recording(dir / "nan.txt", text_format(1, 0, 0, {}, true)), tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::read_text_recording(dir / "missing.txt"), doctest::Contains("cannot open"),
                         tjepa::FileError);
    CHECK_THROWS_AS(tjepa::read_text_recording(dir / "cols.txt", text_format(0)), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::read_text_recording(dir / "cols.txt", text_format(2, 0, 0, {0, 1, 2})), tjepa::ConfigError);
  }
}

TEST_SUITE("data") {
  TEST_CASE("npy: integer arrays (label ids) read as exact floats / one-byte ones without a byte order") {
    using namespace tjepa;
    TempDir t("npy_int");
    std::string i8;
    for (std::int64_t v : {std::int64_t{0}, std::int64_t{-1}, std::int64_t{1000}, std::int64_t{1} << 24}) {
      char b[8];
      std::memcpy(b, &v, 8);
      i8.append(b, 8);
    }
    write_bytes(t / "ids.npy", npy_bytes(dict("<i8", "(4,)"), i8));
    const NpyArray a = read_npy(t / "ids.npy");
    REQUIRE(a.numel() == 4);
    CHECK(a.data()[1] == -1.0f);
    CHECK(a.data()[2] == 1000.0f);
    CHECK(a.data()[3] == 16777216.0f);
    write_bytes(t / "u1.npy", npy_bytes(dict("|u1", "(2, 2)"), std::string("\x01\x02\x03\xff", 4)));
    const Recording r = read_recording_npy(t / "u1.npy");
    CHECK(r(1, 1, 0) == 255.0f);
    write_bytes(t / "be.npy", npy_bytes(dict(">i4", "(1,)"), std::string(4, '\0')));
    CHECK_THROWS_WITH_AS(read_npy(t / "be.npy"), doctest::Contains("convert with arr.astype('<i4')"), FileError);
  }
}
