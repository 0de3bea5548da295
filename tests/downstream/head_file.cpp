// Heads as files (downstream/head_file.hpp): a probe head and a sequence head written and read
// back give the same parameters and the same predictions bit for bit with their run information;
// a head refuses another encoder by name; files of the wrong kind, with a tensor missing or extra,
// or a non-finite value are refused; the encoder fingerprint sees weights and data statistics.
#include <doctest/doctest.h>

#include <tjepa/downstream/head_file.hpp>
#include <tjepa/tjepa.hpp>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "../support/files.hpp"

using namespace tjepa;

TEST_SUITE("downstream") {

namespace {

HeadInfo head_info(const std::string& encoder) {
  HeadInfo info;
  info.task = "classification";
  info.class_names = {"cotton", "denim", "silk"};
  info.output_names = {"force", "speed"};
  info.tau = 10;
  info.stride = 5;
  info.encoder = encoder;
  info.encoder_file = "runs/x/checkpoint.safetensors";
  return info;
}

// Random embeddings [S, N, d].
FrozenFeatures<float> features(int S, int N, int d, std::uint64_t seed) {
  Rng rng(seed);
  AlignedVector<float> e(static_cast<std::size_t>(S) * N * d);
  for (float& v : e) v = static_cast<float>(rng.normal());
  return FrozenFeatures<float>(std::move(e), N, d);
}

// The file at path rewritten without tensor `drop` (and with `add` added when not empty).
void rewrite(const std::filesystem::path& path, const std::string& drop, const std::string& add = "") {
  const SafetensorsFile in = load_safetensors(path);
  SafetensorsFile out;
  out.metadata = in.metadata;
  for (const std::string& n : in.names())
    if (n != drop) out.add(n, in.at(n));
  if (!add.empty()) out.add(add, std::span<const float>(std::vector<float>{1.0f}), {1});
  save_safetensors(path, out);
}

}  // namespace

TEST_CASE("probe head file: the same head back bit for bit / its information / another encoder refused by name") {
  TempDir t("head_file");
  const int N = 6, d = 8;
  ProbeHead<float> head(d, 2, 2, 3, 7, 0, PoolingConfig{.kind = PoolingKind::taxel, .tokens = N, .components = 2});
  head.scaler.mean = {1.5, -2.0};
  head.scaler.std = {0.5, 3.0};
  HeadInfo info = head_info("0123456789abcdef");
  info.center_shift.assign(static_cast<std::size_t>(N) * d, 0.25f);
  save_head(t / "head.safetensors", head, info);

  const LoadedProbeHead<float> back = load_probe_head<float>(t / "head.safetensors", "0123456789abcdef");
  REQUIRE(back.head.params.count() == head.params.count());
  for (std::size_t i = 0; i < head.params.count(); ++i) {
    const auto a = head.params.value_span(head.params.id(i));
    const auto b = back.head.params.value_span(back.head.params.id(i));
    CHECK(back.head.params.infos()[i].name == head.params.infos()[i].name);
    CHECK(std::equal(a.begin(), a.end(), b.begin(), b.end()));
  }
  CHECK(back.head.regression == 2);
  CHECK(back.head.classes == 3);
  CHECK(back.head.scaler.mean == head.scaler.mean);
  CHECK(back.head.scaler.std == head.scaler.std);
  CHECK(back.head.probe.config.pooling.kind == PoolingKind::taxel);
  CHECK(back.info.class_names == info.class_names);
  CHECK(back.info.output_names == info.output_names);
  CHECK(back.info.tau == 10);
  CHECK(back.info.stride == 5);
  CHECK(back.info.task == "classification");
  CHECK(back.info.encoder_file == info.encoder_file);
  CHECK(back.info.center_shift == info.center_shift);
  FrozenFeatures<float> f = features(5, N, d, 3);
  CHECK(predict_head(back.head, f, 5) == predict_head(head, f, 5));

  // Loaded for another encoder: refused, naming both fingerprints and where the head's came from.
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "head.safetensors", "fedcba9876543210", "the target encoder"),
                       doctest::Contains("was trained on encoder 0123456789abcdef (runs/x/checkpoint.safetensors), not on "
                                         "the target encoder (fedcba9876543210)"),
                       ConfigError);
  // Not a sequence head.
  CHECK_THROWS_WITH_AS(load_sequence_head<float>(t / "head.safetensors"), doctest::Contains("holds a 'probe' head"),
                       FileError);
  // Information that does not fit the head is refused when writing.
  HeadInfo bad = info;
  bad.class_names.pop_back();
  CHECK_THROWS_WITH_AS(save_head(t / "bad.safetensors", head, bad), doctest::Contains("2 class names for 3 classes"),
                       ConfigError);
  bad = info;
  bad.encoder = "xyz";
  CHECK_THROWS_AS(save_head(t / "bad.safetensors", head, bad), ConfigError);
  CHECK(!std::filesystem::exists(t / "bad.safetensors"));
}

TEST_CASE("probe head file: a missing or extra tensor / a non-finite value / not a head file") {
  TempDir t("head_file_bad");
  ProbeHead<float> head(8, 2, 0, 2, 1);
  HeadInfo info = head_info("0123456789abcdef");
  info.output_names.clear();
  info.class_names = {"no", "yes"};
  save_head(t / "head.safetensors", head, info);
  CHECK_NOTHROW(load_probe_head<float>(t / "head.safetensors"));

  std::filesystem::copy_file(t / "head.safetensors", t / "missing.safetensors");
  const std::string first = head.params.infos()[0].name;
  rewrite(t / "missing.safetensors", first);
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "missing.safetensors"), doctest::Contains(first.c_str()), FileError);

  std::filesystem::copy_file(t / "head.safetensors", t / "extra.safetensors");
  rewrite(t / "extra.safetensors", "", "probe.stray");
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "extra.safetensors"), doctest::Contains("probe.stray"), FileError);

  ProbeHead<float> nan_head(8, 2, 0, 2, 1);
  nan_head.params.value_span(nan_head.params.id(0))[0] = std::numeric_limits<float>::quiet_NaN();
  save_head(t / "nan.safetensors", nan_head, info);
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "nan.safetensors"), doctest::Contains("non-finite"), FileError);

  SafetensorsFile other;
  other.add("x", std::span<const float>(std::vector<float>{1.0f}), {1});
  save_safetensors(t / "other.safetensors", other);
  CHECK_THROWS_AS(load_probe_head<float>(t / "other.safetensors"), FileError);
  const std::string missing = "head file '" + (t / "none.safetensors").string() + "': no such file";
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "none.safetensors"), doctest::Contains(missing.c_str()), FileError);
}

TEST_CASE("sequence head file: the same head back bit for bit") {
  TempDir t("sequence_head_file");
  SequenceHeadConfig c;
  c.dim = 8, c.heads = 2, c.length = 3, c.outputs = 2;
  SequenceModel<float> model(c, 5);
  model.scaler.mean = {0.5, 1.0};
  model.scaler.std = {2.0, 4.0};
  HeadInfo info = head_info("00000000000000ff");
  info.task = "pose";
  info.class_names.clear();
  save_head(t / "seq.safetensors", model, info);
  const LoadedSequenceHead<float> back = load_sequence_head<float>(t / "seq.safetensors", "00000000000000ff");
  CHECK(back.head.head.config.length == 3);
  CHECK(back.head.scaler.std == model.scaler.std);
  CHECK(back.info.output_names == info.output_names);
  FrozenFeatures<float> f = features(6, 4, 8, 9);
  SequenceTargets q;
  q.length = 3, q.outputs = 2;
  q.window = {0, 1, 2, 3, 4, 5};
  q.value.assign(12, 0.0f);
  CHECK(predict_sequence_head(back.head, f, q) == predict_sequence_head(model, f, q));
  CHECK_THROWS_WITH_AS(load_probe_head<float>(t / "seq.safetensors"), doctest::Contains("holds a 'sequence' head"),
                       FileError);
}

TEST_CASE("encoder_fingerprint: the same weights and statistics give the same digits / any change another") {
  ProbeHead<float> a(8, 2, 1, 0, 3), b(8, 2, 1, 0, 3);
  const std::string fa = encoder_fingerprint(a.params);
  CHECK(fa.size() == 16);
  CHECK(encoder_fingerprint(b.params) == fa);
  b.params.value_span(b.params.id(1))[0] += 1e-6f;
  CHECK(encoder_fingerprint(b.params) != fa);
  const std::vector<NamedTensor> stats{{"preprocess.mean", {2}, {0.0f, 1.0f}}};
  const std::vector<NamedTensor> other{{"preprocess.mean", {2}, {0.0f, 2.0f}}};
  CHECK(encoder_fingerprint(a.params, stats) != fa);
  CHECK(encoder_fingerprint(a.params, stats) != encoder_fingerprint(a.params, other));
}

}  // TEST_SUITE
