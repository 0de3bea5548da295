// The file formats: safetensors (round trip, byte layout, every corruption named), checkpoints
// (models, optimizer moments, step, RNG, config and statistics) and the encoder-only export.
#include <doctest/doctest.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"
#include "../support/params.hpp"
// The modules this file tests (the umbrella above holds them all; named here so each is traceable).
#include <tjepa/io/checkpoint.hpp>
#include <tjepa/io/safetensors.hpp>

namespace {

namespace fs = std::filesystem;
using tjepa_test::fill_grads;
using tjepa_test::make_params;

using tjepa_test::TempDir;

std::vector<std::byte> read_bytes(const fs::path& p) {
  const std::string c = tjepa_test::read_file(p);
  std::vector<std::byte> b(c.size());
  if (!c.empty()) std::memcpy(b.data(), c.data(), c.size());
  return b;
}

void write_bytes(const fs::path& p, const std::vector<std::byte>& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

// A raw safetensors file: 8-byte length, the given header text, `data_bytes` bytes of data.
std::vector<std::byte> raw_file(const std::string& header, std::size_t data_bytes, std::uint64_t length = 0) {
  if (length == 0) length = header.size();
  std::vector<std::byte> b(8 + header.size() + data_bytes, std::byte{0});
  for (int i = 0; i < 8; ++i) b[static_cast<std::size_t>(i)] = static_cast<std::byte>((length >> (8 * i)) & 0xFF);
  std::memcpy(b.data() + 8, header.data(), header.size());
  return b;
}

std::string error_of(const fs::path& p) {
  try {
    (void)tjepa::load_safetensors(p);
  } catch (const tjepa::FileError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_SUITE("io") {
  TEST_CASE("safetensors round trip and byte layout") {
    TempDir dir("st_roundtrip");
    tjepa::SafetensorsFile f;
    const std::vector<std::uint8_t> u8{1, 2, 3};
    const std::vector<double> f64{1.5, -2.25, 1e300, 0.1};
    const std::vector<float> f32{0.5f, -1.0f, 3.25f, 7.0f, 8.0f, 9.0f};
    const std::vector<std::int64_t> i64{-5};
    f.add<std::uint8_t>("bytes", u8, {3});
    f.add<float>("w", f32, {2, 3});
    f.add<double>("x", f64, {4});
    f.add<std::int64_t>("scalar", i64, {});
    f.add<float>("empty", std::span<const float>(), {0, 4});
    f.metadata["config"] = R"({"d": 8})";
    f.metadata["note"] = "ünïcode";
    CHECK_THROWS_AS(f.add<float>("w", f32, {6}), tjepa::ConfigError);
    CHECK_THROWS_AS(f.add<float>("__metadata__", f32, {6}), tjepa::ConfigError);
    CHECK_THROWS_AS(f.add<float>("bad", f32, {4}), tjepa::ShapeError);
    const fs::path p = dir.path / "a.safetensors";
    tjepa::save_safetensors(p, f);
    CHECK_FALSE(fs::exists(p.string() + ".tmp." + std::to_string(::getpid())));

    const auto bytes = read_bytes(p);
    std::uint64_t n = 0;
    for (int i = 7; i >= 0; --i) n = (n << 8) | std::to_integer<std::uint64_t>(bytes[static_cast<std::size_t>(i)]);
    CHECK(n % 8 == 0);
    CHECK(static_cast<char>(bytes[8]) == '{');
    const auto header = nlohmann::json::parse(std::string(reinterpret_cast<const char*>(bytes.data() + 8), n));
    CHECK(header["w"]["dtype"] == "F32");
    CHECK(header["w"]["shape"] == nlohmann::json::array({2, 3}));
    CHECK(header["__metadata__"]["note"] == "ünïcode");
    // Every tensor starts aligned to its element size; together they fill the data exactly.
    std::size_t total = 0;
    for (const auto& [name, e] : header.items()) {
      if (name == "__metadata__") continue;
      const auto begin = e["data_offsets"][0].get<std::size_t>();
      CHECK(begin % tjepa::dtype_size(*tjepa::dtype_from_name(e["dtype"].get<std::string>())) == 0);
      total += e["data_offsets"][1].get<std::size_t>() - begin;
    }
    CHECK(8 + n + total == bytes.size());

    const auto g = tjepa::load_safetensors(p);
    CHECK(g.size() == 5);
    CHECK(g.metadata == f.metadata);
    CHECK(g.at("w").to_vector<float>() == f32);
    CHECK(g.at("w").shape == std::vector<std::int64_t>{2, 3});
    CHECK(g.at("x").to_vector<double>() == f64);
    CHECK(g.at("bytes").to_vector<std::uint8_t>() == u8);
    CHECK(g.at("scalar").to_vector<std::int64_t>() == i64);
    CHECK(g.at("scalar").shape.empty());
    CHECK(g.at("empty").numel() == 0);
    CHECK_THROWS_AS(g.at("x").to_vector<float>(), tjepa::ShapeError);
    CHECK_THROWS_AS(g.at("nope"), tjepa::FileError);

    // A second save over the first replaces it whole.
    tjepa::SafetensorsFile small;
    small.add<float>("w", f32, {6});
    tjepa::save_safetensors(p, small);
    CHECK(tjepa::load_safetensors(p).size() == 1);
    CHECK_THROWS_AS(tjepa::save_safetensors(dir.path / "missing_dir" / "x.safetensors", small), tjepa::FileError);
  }

  TEST_CASE("every corrupt safetensors file throws a FileError naming the file and the problem") {
    TempDir dir("st_corrupt");
    const fs::path p = dir.path / "bad.safetensors";
    auto expect = [&](const std::vector<std::byte>& bytes, const std::string& phrase) {
      write_bytes(p, bytes);
      const std::string msg = error_of(p);
      CHECK_MESSAGE(msg.find(p.string()) != std::string::npos, msg);
      CHECK_MESSAGE(msg.find(phrase) != std::string::npos, "expected '" << phrase << "' in: " << msg);
    };
    const std::string ok = R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}})";
    {
      write_bytes(p, raw_file(ok, 8));  // the well-formed base case loads
      CHECK(tjepa::load_safetensors(p).at("a").numel() == 2);
    }
    expect({}, "truncated");
    expect(std::vector<std::byte>(5), "truncated: 5 bytes");
    expect(raw_file(ok, 4), "truncated: the tensors need 8 data bytes");
    expect(raw_file(ok, 8, 1ull << 40), "exceeds the limit");
    expect(raw_file(ok, 8, ok.size() + 100), "truncated: header length");
    expect(raw_file("  ", 0), "does not start with '{'");
    expect(raw_file("{\"a\":", 0), "not valid JSON");
    expect(raw_file(R"({"a":{"dtype":"F33","shape":[2],"data_offsets":[0,8]}})", 8), "unknown dtype 'F33'");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[3],"data_offsets":[0,8]}})", 8), "hold 8 bytes, expected 12");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[-2],"data_offsets":[0,8]}})", 8), "expected an integer >= 0");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[8,0]}})", 8), "end before they begin");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0]}})", 8), "two integers");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2]}})", 8), "two integers");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8],"x":1}})", 8), "unknown field 'x'");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},
                        "b":{"dtype":"F32","shape":[2],"data_offsets":[4,12]}})", 12), "overlaps");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},
                        "b":{"dtype":"F32","shape":[2],"data_offsets":[12,20]}})", 20), "belong to no tensor");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[4,12]}})", 12), "[0, 4) belong to no tensor");
    expect(raw_file(ok, 12), "4 data bytes after the last tensor");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},
                        "a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}})", 8), "key 'a' twice");
    expect(raw_file(R"({"__metadata__":{"k":1},"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}})", 8),
           "'k' is not a string");
    expect(raw_file(R"([1,2])", 0), "does not start with '{'");
    expect(raw_file(R"({"a":[0,8]})", 0), "an array outside a tensor's entry");
    expect(raw_file(R"({"a":7})", 0), "entry is not an object");
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[4294967296,4294967296],"data_offsets":[0,8]}})", 8),
           "too large");
    // Fuzzing finding 2: numel * dtype size wrapped in 64 bits ([2^53, 512] F32 declared 0 bytes,
    // [512, 2^52 + 1] F64 declared 4096) and the file was accepted.
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[9007199254740992,512],"data_offsets":[0,0]}})", 0),
           "F32 [9007199254740992, 512] is too large");
    expect(raw_file(R"({"a":{"dtype":"F64","shape":[512,4503599627370497],"data_offsets":[0,4096]}})", 4096),
           "F64 [512, 4503599627370497] is too large");
    // Structures no header has stop the parse early (header memory bound).
    expect(raw_file(R"({"a":{"dtype":"F32","shape":[)" + std::string(64 * 2, '0').replace(1, 125, std::string(63, ',').insert(0, "")).substr(0, 0) +
                        "0" + [] { std::string z; for (int i = 0; i < 64; ++i) z += ",0"; return z; }() +
                        R"(],"data_offsets":[0,0]}})", 0),
           "an array of more than 64 entries");
    expect(raw_file(R"({"a":{"dtype":{"x":{}},"shape":[2],"data_offsets":[0,8]}})", 8), "nests objects deeper");
    expect(raw_file(R"({"a":[[0]]})", 0), "an array outside a tensor's entry");
    // A real file cut short anywhere fails cleanly.
    tjepa::SafetensorsFile f;
    const std::vector<double> x(10, 1.0);
    f.add<double>("x", x, {10});
    const fs::path good = dir.path / "good.safetensors";
    tjepa::save_safetensors(good, f);
    const auto full = read_bytes(good);
    for (std::size_t cut : {std::size_t{0}, std::size_t{3}, std::size_t{20}, full.size() - 1}) {
      expect(std::vector<std::byte>(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(cut)), "");
      CHECK_THROWS_AS(tjepa::load_safetensors(p), tjepa::FileError);
    }
    // A header over a caller's limit.
    CHECK_THROWS_WITH_AS(tjepa::load_safetensors(good, 16), doctest::Contains("exceeds the limit of 16"),
                         tjepa::FileError);
    CHECK_THROWS_WITH_AS(tjepa::load_safetensors(dir.path / "none.safetensors"), doctest::Contains("cannot read"),
                         tjepa::FileError);
  }

  TEST_CASE("a checkpoint restores models and optimizer moments and step and RNG and config and statistics") {
    TempDir dir("ckpt");
    auto enc = make_params<float>(21), tgt = make_params<float>(22), pred = make_params<float>(23, 4);
    tjepa::AdamW<float> opt({{"context_encoder.", &enc}, {"predictor.", &pred}});
    for (int t = 0; t < 3; ++t) {
      fill_grads(enc, 30 + t);
      fill_grads(pred, 40 + t);
      opt.step(1e-3, 0.05);
    }
    tjepa::Rng masks(5, 1);
    for (int i = 0; i < 7; ++i) (void)masks();
    tjepa::CheckpointState st;
    st.step = 3;
    st.rng["masks"] = masks.state();
    st.config = {{"d", 6}, {"lr", 1e-4}};
    const std::vector<float> mean{0.1f, 0.2f, 0.3f}, sd{1.f, 2.f, 3.f};
    st.normalization["mean"] = tjepa::Tensor::from(mean, {3});
    st.normalization["std"] = tjepa::Tensor::from(sd, {3});
    st.metadata["dataset"] = "synthetic";
    const std::vector<tjepa::PrefixedParams<float>> models{
        {"context_encoder.", &enc}, {"target_encoder.", &tgt}, {"predictor.", &pred}};
    const fs::path p = dir.path / "last.safetensors";
    tjepa::save_checkpoint<float>(p, models, &opt, st);

    const auto file = tjepa::load_safetensors(p);
    CHECK(file.contains("context_encoder.blocks.0.attn.qkv.weight"));
    CHECK(file.contains("target_encoder.pos_embed"));
    CHECK(file.contains("predictor.mask_token"));
    CHECK(file.contains("opt.exp_avg.predictor.blocks.0.norm1.bias"));
    CHECK(file.contains("opt.exp_avg_sq.context_encoder.pos_embed"));
    CHECK_FALSE(file.contains("opt.exp_avg.target_encoder.pos_embed"));
    CHECK(file.at("context_encoder.pos_embed").shape == std::vector<std::int64_t>{1, 5, 6});
    CHECK(file.size() == 3 * 6 + 2 * 2 * 6 + 1 + 2);

    auto enc2 = make_params<float>(91), tgt2 = make_params<float>(92), pred2 = make_params<float>(93, 4);
    tjepa::AdamW<float> opt2({{"context_encoder.", &enc2}, {"predictor.", &pred2}});
    const std::vector<tjepa::PrefixedParams<float>> models2{
        {"context_encoder.", &enc2}, {"target_encoder.", &tgt2}, {"predictor.", &pred2}};
    const auto st2 = tjepa::load_checkpoint<float>(p, models2, &opt2);
    auto same = [](std::span<const float> a, std::span<const float> b) {
      return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size_bytes()) == 0;
    };
    CHECK(same(enc2.values(), enc.values()));
    CHECK(same(tgt2.values(), tgt.values()));
    CHECK(same(pred2.values(), pred.values()));
    for (std::size_t k = 0; k < 2; ++k) {
      CHECK(same(opt2.exp_avg(k), opt.exp_avg(k)));
      CHECK(same(opt2.exp_avg_sq(k), opt.exp_avg_sq(k)));
    }
    CHECK(opt2.steps() == 3);
    CHECK(st2.step == 3);
    CHECK(st2.rng.at("masks") == masks.state());
    CHECK(st2.config == st.config);
    CHECK(st2.normalization.at("std").to_vector<float>() == sd);
    CHECK(st2.metadata.at("dataset") == "synthetic");
    // The restored optimizer continues exactly like the original.
    fill_grads(enc, 50);
    fill_grads(pred, 51);
    fill_grads(enc2, 50);
    fill_grads(pred2, 51);
    opt.step(1e-3, 0.05);
    opt2.step(1e-3, 0.05);
    CHECK(same(enc2.values(), enc.values()));
  }

  TEST_CASE("loading a checkpoint that does not match throws and changes nothing") {
    TempDir dir("ckpt_bad");
    auto enc = make_params<float>(1), pred = make_params<float>(2, 4);
    tjepa::AdamW<float> opt({{"context_encoder.", &enc}, {"predictor.", &pred}});
    const std::vector<tjepa::PrefixedParams<float>> models{{"context_encoder.", &enc}, {"predictor.", &pred}};
    const fs::path p = dir.path / "c.safetensors";
    tjepa::save_checkpoint<float>(p, models, &opt, {});

    auto check_rejected = [&](auto& e, auto& q, auto* o, const std::string& phrase) {
      using S = std::remove_reference_t<decltype(e)>;
      const S e0 = e;
      const std::vector<tjepa::PrefixedParams<typename S::Scalar>> m{{"context_encoder.", &e}, {"predictor.", &q}};
      CHECK_THROWS_WITH_AS(tjepa::load_checkpoint<typename S::Scalar>(p, m, o), doctest::Contains(phrase.c_str()),
                           tjepa::FileError);
      CHECK(std::equal(e.values().begin(), e.values().end(), e0.values().begin()));
    };
    {  // another shape
      auto e = make_params<float>(3, 8);
      auto q = make_params<float>(4, 4);
      check_rejected(e, q, static_cast<tjepa::AdamW<float>*>(nullptr), "has shape [1, 5, 6], expected [1, 5, 8]");
    }
    {  // another dtype
      auto e = make_params<double>(3);
      auto q = make_params<double>(4, 4);
      check_rejected(e, q, static_cast<tjepa::AdamW<double>*>(nullptr), "has dtype F32, expected F64");
    }
    {  // a tensor the file lacks (later in order than tensors that do match)
      tjepa::ParamSet<float> e;
      e.add("pos_embed", {1, 5, 6});
      e.add("extra.weight", {2, 2});
      e.allocate();
      auto q = make_params<float>(4, 4);
      check_rejected(e, q, static_cast<tjepa::AdamW<float>*>(nullptr), "missing tensor 'context_encoder.extra.weight'");
    }
    {  // a tensor nobody expects
      tjepa::ParamSet<float> e;
      e.add("pos_embed", {1, 5, 6});
      e.allocate();
      auto q = make_params<float>(4, 4);
      check_rejected(e, q, static_cast<tjepa::AdamW<float>*>(nullptr), "unexpected tensor 'context_encoder.blocks.0.norm1.weight'");
    }
    {  // an optimizer whose moments are not in the file
      auto e = make_params<float>(5);
      auto q = make_params<float>(6, 4);
      auto extra = make_params<float>(7, 2);
      tjepa::AdamW<float> o({{"context_encoder.", &e}, {"predictor.", &q}, {"other.", &extra}});
      check_rejected(e, q, &o, "missing tensor 'opt.exp_avg.other.pos_embed'");
    }
    // An encoder export is not a training checkpoint, and the other way round.
    const fs::path x = dir.path / "encoder.safetensors";
    tjepa::export_encoder<float>(x, std::vector<tjepa::PrefixedParams<float>>{{"", &enc}}, {});
    CHECK_THROWS_WITH_AS(tjepa::load_checkpoint<float>(x, models, nullptr),
                         doctest::Contains("expected 'tjepa.checkpoint.v1'"), tjepa::FileError);
    CHECK_THROWS_AS(tjepa::load_encoder<float>(p, std::vector<tjepa::PrefixedParams<float>>{{"", &enc}}),
                    tjepa::FileError);
  }

  TEST_CASE("the encoder-only export holds plain state-dict names and config and statistics") {
    TempDir dir("export");
    auto tgt = make_params<float>(31);
    tjepa::CheckpointState st;
    st.config = {{"model", "vit_tiny"}};
    const std::vector<float> mean{0.5f, -0.5f};
    st.normalization["mean"] = tjepa::Tensor::from(mean, {2});
    const fs::path p = dir.path / "encoder.safetensors";
    tjepa::export_encoder<float>(p, std::vector<tjepa::PrefixedParams<float>>{{"", &tgt}}, st);
    const auto file = tjepa::load_safetensors(p);
    CHECK(file.contains("blocks.0.attn.qkv.weight"));
    CHECK(file.contains("normalization.mean"));
    CHECK(file.metadata.at("format") == "tjepa.encoder.v1");
    CHECK(file.size() == tgt.count() + 1);
    auto back = make_params<float>(99);
    const auto st2 = tjepa::load_encoder<float>(p, std::vector<tjepa::PrefixedParams<float>>{{"", &back}});
    CHECK(std::equal(back.values().begin(), back.values().end(), tgt.values().begin()));
    CHECK(st2.config == st.config);
    CHECK(st2.normalization.at("mean").to_vector<float>() == mean);
  }
}
