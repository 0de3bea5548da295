// Second translation unit that includes the umbrella header (see tests/main.cpp).
// core/detail/vendor.hpp is tested by the build itself: no test or example file silences GCC 12's
// AVX-512 warning any more, and they all build with -Werror.
#include <doctest/doctest.h>

#include <tjepa/core/detail/vendor.hpp>
#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;

struct AtomicDir {
  fs::path path = fs::temp_directory_path() / ("tjepa_atomic_" + std::to_string(::getpid()));
  AtomicDir() {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~AtomicDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::vector<std::string> names() const {
    std::vector<std::string> v;
    for (const auto& e : fs::directory_iterator(path)) v.push_back(e.path().filename().string());
    std::sort(v.begin(), v.end());
    return v;
  }
};

}  // namespace

TEST_SUITE("core") {
  TEST_CASE("version macros match the version string") {
    CHECK(std::string(tjepa::version_string) ==
          std::to_string(TJEPA_VERSION_MAJOR) + "." + std::to_string(TJEPA_VERSION_MINOR) + "." +
              std::to_string(TJEPA_VERSION_PATCH));
  }

  TEST_CASE("Error carries its message and subclasses are Errors") {
    try {
      tjepa::fail<tjepa::ShapeError>("x: shape [", 2, ", ", 3, "], expected [2, 4]");
      FAIL("no throw");
    } catch (const tjepa::Error& e) {
      CHECK(std::string(e.what()) == "x: shape [2, 3], expected [2, 4]");
    }
    CHECK_THROWS_AS(tjepa::require<tjepa::ConfigError>(false, "bad"), tjepa::ConfigError);
    CHECK_NOTHROW(tjepa::require(true, "fine"));
    CHECK_THROWS_WITH_AS(tjepa::require<tjepa::DataError>(false, "v = ", 1.5),
                         "v = 1.5", std::runtime_error);
  }

  TEST_CASE("Rng is xoshiro256** and reproducible") {
    tjepa::Rng r;
    r.set_state({1, 2, 3, 4});
    // Reference xoshiro256** from state {1,2,3,4}: rotl(2*5, 7)*9 = 11520, then 0, then 1509978240.
    CHECK(r() == 11520u);
    CHECK(r() == 0u);
    CHECK(r() == 1509978240u);

    tjepa::Rng a(7), b(7), c(8), s1(7, 1);
    for (int i = 0; i < 100; ++i) {
      const auto x = a();
      CHECK(x == b());
    }
    CHECK(tjepa::Rng(7)() != c());
    CHECK(tjepa::Rng(7)() != s1());
    CHECK(tjepa::Rng(7, 1)() == tjepa::Rng(7, 1)());

    tjepa::Rng saved(3);
    saved();
    auto st = saved.state();
    tjepa::Rng restored;
    restored.set_state(st);
    CHECK(restored() == saved());
    CHECK_THROWS_AS(restored.set_state({0, 0, 0, 0}), tjepa::ConfigError);
  }

  TEST_CASE("uniform below normal and truncated_normal have the right moments") {
    tjepa::Rng r(123);
    const int n = 200000;
    double s = 0, s2 = 0;
    for (int i = 0; i < n; ++i) {
      const double u = r.uniform();
      REQUIRE(u >= 0.0);
      REQUIRE(u < 1.0);
      s += u;
      s2 += u * u;
    }
    CHECK(s / n == doctest::Approx(0.5).epsilon(0.01));
    CHECK(s2 / n - (s / n) * (s / n) == doctest::Approx(1.0 / 12).epsilon(0.02));

    // below(7): chi-square against uniform, 6 degrees of freedom, 99.9% quantile 22.46.
    std::vector<int> counts(7, 0);
    for (int i = 0; i < 70000; ++i) ++counts[r.below(7)];
    double chi2 = 0;
    for (int c : counts) chi2 += (c - 10000.0) * (c - 10000.0) / 10000.0;
    CHECK(chi2 < 22.46);
    CHECK_THROWS_AS(r.below(0), tjepa::ConfigError);

    s = s2 = 0;
    double s4 = 0;
    for (int i = 0; i < n; ++i) {
      const double z = r.normal();
      s += z;
      s2 += z * z;
      s4 += z * z * z * z;
    }
    CHECK(std::abs(s / n) < 0.01);
    CHECK(s2 / n == doctest::Approx(1.0).epsilon(0.02));
    CHECK(s4 / n == doctest::Approx(3.0).epsilon(0.05));  // normal kurtosis

    for (int i = 0; i < 10000; ++i) {
      const double t = r.truncated_normal(0.0, 1.0, -0.5, 1.0);
      REQUIRE(t >= -0.5);
      REQUIRE(t <= 1.0);
    }
    CHECK_THROWS_AS(r.truncated_normal(0, 1, 1, 1), tjepa::ConfigError);
  }

  TEST_CASE("shuffle is a permutation and deterministic") {
    std::vector<int> v(50), w;
    for (int i = 0; i < 50; ++i) v[i] = i;
    w = v;
    tjepa::Rng a(1), b(1);
    a.shuffle(std::span<int>(v));
    b.shuffle(std::span<int>(w));
    CHECK(v == w);
    CHECK(std::set<int>(v.begin(), v.end()).size() == 50);
  }

  TEST_CASE("AlignedVector is 64-byte aligned") {
    tjepa::AlignedVector<float> v(37);
    CHECK(reinterpret_cast<std::uintptr_t>(v.data()) % 64 == 0);
  }

  TEST_CASE("row-major Eigen aliases map PyTorch-ordered buffers") {
    std::vector<float> buf = {1, 2, 3, 4, 5, 6};
    tjepa::ConstMatrixMap<float> m(buf.data(), 2, 3);
    CHECK(m(0, 2) == 3);
    CHECK(m(1, 0) == 4);
    tjepa::ConstStridedMatrixMap<float> head(buf.data() + 1, 2, 2, Eigen::OuterStride<>(3));
    CHECK(head(1, 1) == 6);
  }

  TEST_CASE("write_file_atomic: a writer that throws leaves the old file and no temporary") {
    AtomicDir dir;
    const fs::path p = dir.path / "out.bin";
    tjepa::write_file_atomic(p, "old");
    CHECK_THROWS_WITH_AS(tjepa::write_file_atomic_with(p,
                                                       [](std::ostream& out) {
                                                         out << std::string(200000, 'x');
                                                         throw std::runtime_error("writer gave up");
                                                       }),
                         "writer gave up", std::runtime_error);
    CHECK(tjepa_test::read_file(p) == "old");
    CHECK(dir.names() == std::vector<std::string>{"out.bin"});
    CHECK_THROWS_WITH_AS(tjepa::write_file_atomic(dir.path / "no_such_dir" / "x", "y"),
                         doctest::Contains("cannot create a temporary file"), tjepa::FileError);
  }

  TEST_CASE("write_file_atomic: a write killed part-way leaves the old file and the next write removes its temporary") {
    AtomicDir dir;
    const fs::path p = dir.path / "ckpt.safetensors";
    tjepa::write_file_atomic(p, "old");
    int pipefd[2];
    REQUIRE(::pipe(pipefd) == 0);
    const ::pid_t child = ::fork();
    REQUIRE(child >= 0);
    if (child == 0) {
      ::close(pipefd[0]);
      try {
        tjepa::write_file_atomic_with(p, [&](std::ostream& out) {
          out << std::string(1 << 20, 'n');
          out.flush();
          const char c = 1;
          if (::write(pipefd[1], &c, 1) != 1) ::_exit(3);
          for (;;) ::pause();  // killed here, mid-write
        });
      } catch (...) {
      }
      ::_exit(2);
    }
    ::close(pipefd[1]);
    char c = 0;
    REQUIRE(::read(pipefd[0], &c, 1) == 1);
    ::close(pipefd[0]);
    REQUIRE(::kill(child, SIGKILL) == 0);
    // Dead but not reaped (a zombie, as a killed MPI rank can be for a while): already stale.
    siginfo_t info{};
    REQUIRE(::waitid(P_PID, static_cast<id_t>(child), &info, WEXITED | WNOWAIT) == 0);
    CHECK(tjepa::stale_temporaries(p).size() == 1u);
    int status = 0;
    REQUIRE(::waitpid(child, &status, 0) == child);
    CHECK(WIFSIGNALED(status));
    CHECK(tjepa_test::read_file(p) == "old");
    const auto stale = tjepa::stale_temporaries(p);
    REQUIRE(stale.size() == 1);
    CHECK(fs::file_size(stale[0]) == (1u << 20));
    CHECK(dir.names().size() == 2);
    // Another target's write leaves it; the next write of this target removes it.
    tjepa::write_file_atomic(dir.path / "other", "o");
    CHECK(dir.names().size() == 3);
    tjepa::write_file_atomic(p, "new");
    CHECK(tjepa_test::read_file(p) == "new");
    CHECK(dir.names() == std::vector<std::string>{"ckpt.safetensors", "other"});
    CHECK(tjepa::stale_temporaries(p).empty());
  }

  TEST_CASE("write_file_atomic: symlinks never redirect the write") {
    AtomicDir dir;
    const fs::path victim = dir.path / "victim";
    tjepa::write_file_atomic(victim, "precious");
    // The output path is a symlink: it is replaced by a regular file, its target is untouched.
    const fs::path p = dir.path / "out";
    fs::create_symlink(victim, p);
    tjepa::write_file_atomic(p, "data");
    CHECK(tjepa_test::read_file(victim) == "precious");
    CHECK_FALSE(fs::is_symlink(fs::symlink_status(p)));
    CHECK(tjepa_test::read_file(p) == "data");
    // Symlinks planted at the old predictable temporary names and at stale-looking names are not
    // followed, and a planted link is not removed as a stale temporary.
    const fs::path q = dir.path / "q";
    fs::create_symlink(victim, dir.path / ("q.tmp." + std::to_string(::getpid())));
    const std::string prefix = ".q.tjepa-tmp.";
    for (const auto& n : dir.names()) CHECK(n.find(prefix) == std::string::npos);
    tjepa::write_file_atomic(q, "q data");
    CHECK(tjepa_test::read_file(victim) == "precious");
    CHECK(tjepa_test::read_file(q) == "q data");
  }

  TEST_CASE("write_file_atomic: a full disk throws a FileError naming the file and leaves no temporary") {
    // RLIMIT_FSIZE makes write(2) fail part-way with EFBIG, as a full disk fails it with ENOSPC.
    AtomicDir dir;
    const fs::path p = dir.path / "big.npy";
    tjepa::write_file_atomic(p, "old");
    rlimit old{};
    REQUIRE(::getrlimit(RLIMIT_FSIZE, &old) == 0);
    auto* old_handler = std::signal(SIGXFSZ, SIG_IGN);
    rlimit small = old;
    small.rlim_cur = 100000;
    REQUIRE(::setrlimit(RLIMIT_FSIZE, &small) == 0);
    std::string what;
    try {
      tjepa::write_file_atomic(p, std::string(1000000, 'z'));
    } catch (const tjepa::FileError& e) {
      what = e.what();
    }
    ::setrlimit(RLIMIT_FSIZE, &old);
    std::signal(SIGXFSZ, old_handler);
    CHECK(what.find("big.npy") != std::string::npos);
    CHECK(what.find("failed") != std::string::npos);
    CHECK(tjepa_test::read_file(p) == "old");
    CHECK(dir.names() == std::vector<std::string>{"big.npy"});
  }

  TEST_CASE("write_file_atomic: a 250-byte file name still gets a temporary within NAME_MAX") {
    AtomicDir dir;
    const fs::path p = dir.path / std::string(250, 'n');
    tjepa::write_file_atomic(p, "long");
    CHECK(tjepa_test::read_file(p) == "long");
    CHECK(dir.names() == std::vector<std::string>{std::string(250, 'n')});
  }

  TEST_CASE("input paths: a FileError naming the path and the system's reason / never a filesystem_error") {
    AtomicDir dir;
    tjepa::write_file_atomic(dir.path / "a.csv", "1\n");
    const fs::path too_long = dir.path / std::string(300, 'x');  // over NAME_MAX: stat fails with ENAMETOOLONG
    CHECK(tjepa::input_file_problem(dir.path / "a.csv").empty());
    CHECK(tjepa::input_file_problem(dir.path / "none.csv") == "no such file");
    CHECK(tjepa::input_file_problem(dir.path / "a.csv" / "b") == "no such file");  // a file as a folder: ENOTDIR
    CHECK(tjepa::input_file_problem(dir.path) == "a directory, not a file");
    CHECK(tjepa::input_file_problem(too_long) == std::strerror(ENAMETOOLONG));
    const std::string refused = "t.csv:2: recording '" + too_long.string() + "': File name too long";
    CHECK_THROWS_WITH_AS(tjepa::require_input_file(too_long, "recording", "t.csv:2: "), refused.c_str(), tjepa::FileError);
    CHECK_NOTHROW(tjepa::require_input_file(dir.path / "a.csv", "recording"));
    CHECK(tjepa::path_exists(dir.path / "a.csv"));
    CHECK_FALSE(tjepa::path_exists(too_long));
    tjepa::make_directories(dir.path / "p" / "q");
    CHECK(fs::is_directory(dir.path / "p" / "q"));
    tjepa::make_directories(dir.path / "p" / "q");  // already there: nothing to do
    CHECK_THROWS_WITH_AS(tjepa::make_directories(dir.path / "a.csv", "the cache"),
                         doctest::Contains("cannot create the cache '"), tjepa::FileError);
    CHECK_THROWS_WITH_AS(tjepa::make_directories(too_long / "q"), doctest::Contains("File name too long"),
                         tjepa::FileError);
  }

  TEST_CASE("write_file_atomic: two threads writing one path never mix their files") {
    AtomicDir dir;
    const fs::path p = dir.path / "shared";
    const std::string a(300000, 'a'), b(300000, 'b');
    auto run = [&](const std::string& s) {
      for (int i = 0; i < 20; ++i) tjepa::write_file_atomic(p, s);
    };
    std::thread t1(run, std::cref(a)), t2(run, std::cref(b));
    t1.join();
    t2.join();
    const std::string got = tjepa_test::read_file(p);
    CHECK((got == a || got == b));
    CHECK(dir.names() == std::vector<std::string>{"shared"});
  }

  TEST_CASE("hash: FNV-1a's published values and continuation and hex digits") {
    using tjepa::fingerprint;
    auto of = [](std::string_view t) { return fingerprint(std::span<const char>(t.data(), t.size())); };
    // The FNV-1a 64-bit test vectors (Fowler, Noll, Vo).
    CHECK(of("") == 0xcbf29ce484222325ull);
    CHECK(of("") == tjepa::fingerprint_seed);
    CHECK(of("a") == 0xaf63dc4c8601ec8cull);
    CHECK(of("foobar") == 0x85944171f73967e8ull);
    // Continuing from a value equals hashing the concatenation; floats hash by their bytes.
    CHECK(fingerprint(std::span<const char>("bar", 3), of("foo")) == of("foobar"));
    const float f[2] = {1.0f, -0.0f};
    const float g[2] = {1.0f, 0.0f};
    CHECK(fingerprint(std::span<const float>(f)) != fingerprint(std::span<const float>(g)));
    CHECK(tjepa::hex_digits(0xaf63dc4c8601ec8cull) == "af63dc4c8601ec8c");
    CHECK(tjepa::hex_digits(0) == "0000000000000000");
    CHECK(tjepa::short_hash("a") == "af63dc4c8601ec8c");
  }

  TEST_CASE("row_begin: n threads own consecutive rows in whole blocks / every row once / as even as blocks allow") {
    using tjepa::detail::row_begin;
    for (const int rows : {0, 1, 5, 6, 7, 53, 368, 529, 768})
      for (const int n : {1, 2, 3, 4, 16})
        for (const int block : {1, 6}) {
          INFO("rows ", rows, ", threads ", n, ", block ", block);
          CHECK(row_begin(rows, 0, n, block) == 0);
          CHECK(row_begin(rows, n, n, block) == rows);
          const int blocks = (rows + block - 1) / block;
          for (int t = 0; t < n; ++t) {
            const int r0 = row_begin(rows, t, n, block), r1 = row_begin(rows, t + 1, n, block);
            CHECK(r0 <= r1);
            CHECK(r0 % block == 0);
            CHECK(r1 - r0 <= (blocks + n - 1) / n * block);  // never more than its share of whole blocks
            if (blocks >= n) CHECK(r1 - r0 > (blocks / n - 1) * block);  // its share, the last block maybe partial
          }
        }
  }
}
