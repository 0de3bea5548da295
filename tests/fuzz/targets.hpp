#pragma once
// Fuzz targets, one per reader of files a user hands to tjepa. Each takes arbitrary bytes and
// must either read them or throw a tjepa::Error; any other exception, a crash or a sanitizer
// report is a finding. Built two ways (tests/fuzz/CMakeLists.txt):
//   - with clang's -fsanitize=fuzzer,address,undefined, one libFuzzer binary per target
//     (fuzz_main.cpp, TJEPA_FUZZ_TARGET names the target);
//   - as a plain program (replay.cpp) that runs every file of a target's corpus, in the tests.
// The seed corpora in tests/fuzz/corpus/<target>/ are written by tjepa's own writers
// (`tjepa_fuzz_replay --write-corpus tests/fuzz/corpus`).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <string_view>
#include <unistd.h>

#include <tjepa/core/error.hpp>
#include <tjepa/data/npy.hpp>
#include <tjepa/data/text_reader.hpp>
#include <tjepa/data/trial_table.hpp>
#include <tjepa/train/reference_checkpoint.hpp>
#include <tjepa/io/safetensors.hpp>
#include <tjepa/sensors/csv.hpp>
#include <tjepa/sensors/generic.hpp>
#include <tjepa/train/config.hpp>
#include <tjepa/train/trained_model.hpp>

namespace tjepa::fuzz {

// The readers take paths: the input goes to a per-process scratch file (in /dev/shm if there is
// one, so the fuzzer does not wait on a disk).
inline std::filesystem::path scratch_file(std::string_view suffix) {
  static const std::filesystem::path dir = [] {
    std::error_code ec;
    return std::filesystem::is_directory("/dev/shm", ec) ? std::filesystem::path("/dev/shm")
                                                        : std::filesystem::temp_directory_path();
  }();
  return dir / ("tjepa_fuzz_" + std::to_string(::getpid()) + std::string(suffix));
}

inline std::filesystem::path write_input(const std::uint8_t* data, std::size_t size, std::string_view suffix) {
  const auto p = scratch_file(suffix);
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return p;
}

// When set (tjepa_fuzz_replay -v), the errors the readers throw are printed.
inline bool verbose = false;

// Runs f(); a tjepa::Error is the expected answer to bad input.
template <class F>
int expect_tjepa_errors(F&& f) {
  try {
    f();
    if (verbose) std::fprintf(stderr, "  read\n");
  } catch (const tjepa::Error& e) {
    if (verbose) std::fprintf(stderr, "  tjepa::Error: %s\n", e.what());
  }
  return 0;
}

inline int safetensors(const std::uint8_t* data, std::size_t size) {
  return expect_tjepa_errors([&] {
    const auto file = parse_safetensors(std::span(reinterpret_cast<const std::byte*>(data), size), "input");
    for (const auto& name : file.names()) {
      const Tensor& t = file.at(name);
      if (t.dtype == Dtype::F32) (void)t.to_vector<float>();
      if (t.dtype == Dtype::F64) (void)t.to_vector<double>();
    }
  });
}

inline int checkpoint(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".safetensors");
  return expect_tjepa_errors([&] { (void)load_trained_model(p); });
}

inline int npy(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".npy");
  expect_tjepa_errors([&] { (void)read_npy(p); });
  NpyReadOptions copy;
  copy.map = false;
  copy.require_finite = true;
  expect_tjepa_errors([&] { (void)read_npy(p, copy); });
  return expect_tjepa_errors([&] { (void)read_recording_npy(p); });
}

inline int text_recording(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".csv");
  TextFormat three;
  three.axes = 3;
  TextFormat strict;
  strict.skip_rows = 1;
  strict.require_finite = true;
  TextFormat lines;  // the iCub grasp dataset's layout: a first line, then frames of 3 lines
  lines.axes = 1, lines.skip_rows = 1, lines.lines_per_frame = 3;
  expect_tjepa_errors([&] { (void)read_text_recording(p, three); });
  expect_tjepa_errors([&] { (void)read_text_recording(p, lines); });
  return expect_tjepa_errors([&] { (void)read_text_recording(p, strict); });
}

// A trial table: its rows name files that do not exist next to the scratch file (errors), unless
// the input names the scratch file itself.
inline int trial_table(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".trials.csv");
  return expect_tjepa_errors([&] {
    const TrialTable t = read_trial_table(p);
    if (!t.labels_are_files()) (void)trial_classes(t);
  });
}

inline int layout_csv(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".nodes.csv");
  return expect_tjepa_errors([&] { (void)read_layout_csv(p); });
}

// Edges against a fixed layout: a 4 x 4 grid (ids 0-15) in one group.
inline int edges_csv(const std::uint8_t* data, std::size_t size) {
  static const Skin skin = [] {
    layouts::GridSkinOptions o;
    o.rows = o.cols = 4;
    return layouts::grid_skin(o);
  }();
  const auto p = write_input(data, size, ".edges.csv");
  return expect_tjepa_errors([&] { (void)read_edges_csv(p, skin.layout); });
}

inline int run_config(const std::uint8_t* data, std::size_t size) {
  const auto p = write_input(data, size, ".json");
  return expect_tjepa_errors([&] { TrainConfig::from_file(p).validate(); });
}

struct Target {
  const char* name;
  int (*run)(const std::uint8_t*, std::size_t);
};

// A reference-code state dict through the converter: config, load, and back.
inline int reference_checkpoint(const std::uint8_t* data, std::size_t size) {
  return expect_tjepa_errors([&] {
    const auto file = parse_safetensors(std::span(reinterpret_cast<const std::byte*>(data), size), "input");
    ReferenceOptions opt;
    opt.heads = 2;
    if (file.contains("context_encoder.pos_embed")) {
      const Tensor& pos = file.at("context_encoder.pos_embed");
      if (pos.shape.size() == 3 && pos.shape[1] > 0 && pos.shape[1] < 4096)
        opt.token_types.assign(static_cast<std::size_t>(pos.shape[1]), 0);
    }
    ReferenceFacts facts;
    const JepaConfig c = reference_model_config(file, opt, &facts);
    JepaModel<float> m(c, 0);
    load_reference_state(file, m, opt);
    (void)reference_state(m, facts, opt);
  });
}

inline constexpr Target targets[] = {
    {"safetensors", safetensors}, {"checkpoint", checkpoint}, {"npy", npy},           {"text_recording", text_recording},
    {"layout_csv", layout_csv},   {"edges_csv", edges_csv},   {"run_config", run_config},
    {"reference_checkpoint", reference_checkpoint}, {"trial_table", trial_table},
};

}  // namespace tjepa::fuzz
