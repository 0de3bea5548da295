// `tjepa convert` and `tjepa embed` on the PyTorch fixture's model (tests/reference/fixture.hpp):
// the reference's checkpoint in a permuted recording order converts, embeds as its target encoder
// and converts back bit for bit; what tjepa cannot represent is refused by name.
#include <doctest/doctest.h>

#include "../convert.hpp"
#include "../embed.hpp"

#include "../../../tests/reference/fixture.hpp"
#include "../../../tests/support/files.hpp"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace tjepa;
namespace rf = tjepa::reference_fixture;

TEST_SUITE("cli") {
  TEST_CASE("tjepa convert: the fixture's model in a permuted recording order - embed gives its target encoder's output - back bit for bit") {
    using tjepa_test::TempDir;
    TempDir t("convert");
    const SafetensorsFile fx = load_safetensors(rf::fixture_dir() / "per_taxel-reference-f32.safetensors");
    // The skin: two 2x3 pads; the recordings (and the reference's tokens) in a permuted order.
    const auto csv = t / "pads.csv", order = t / "order.csv";
    std::vector<int> column(12);
    {
      std::ofstream f(csv), o(order);
      f << "id,group,x,y\n";
      o << "id,column\n";
      for (int j = 0; j < 12; ++j) {
        f << j << ",pad" << j / 6 << ',' << (j / 6 * 14 + j % 3 * 4) << ',' << (j % 6) / 3 * 4 << '\n';
        column[std::size_t(j)] = (5 * j + 3) % 12;
        o << j << ',' << column[std::size_t(j)] << '\n';
      }
    }
    SafetensorsFile ref = rf::fixture_part(fx, "init.");
    ref.metadata["reference.config"] = R"({"num_heads": 2, "sequence_length": 6, "time_chunk_size": 6})";
    save_safetensors(t / "ref.safetensors", ref);
    cli::ConvertOptions co;
    co.in = (t / "ref.safetensors").string();
    co.out = (t / "tjepa.safetensors").string();
    co.layout = csv.string();
    co.order = order.string();
    co.taxel_types = "2,2,0,0,0,1,1,0,2,1,0,0";
    std::ostringstream out;
    REQUIRE(cli::run_convert(co, out) == 0);
    CHECK(out.str().find("temporal padding 2") != std::string::npos);
    CHECK(out.str().find("taxel types 3") != std::string::npos);

    // The fixture's windows x [B, T, N, C] as one recording [B·T, N, C], columns in the reference's order.
    const auto x = rf::fixture_values(fx, "x");
    std::vector<float> rec(x.begin(), x.end());
    const std::int64_t shape[3] = {3 * 6, 12, 3};
    write_npy(t / "rec.npy", std::span<const float>(rec), std::span<const std::int64_t>(shape));
    cli::EmbedOptions eo;
    eo.checkpoint = co.out;
    eo.data = {(t / "rec.npy").string()};
    eo.out = (t / "emb.npy").string();
    eo.quiet = true;
    REQUIRE(cli::run_embed(eo, out) == 0);
    CHECK(out.str().find("taxel rows in the recordings' column order") != std::string::npos);
    const auto h = rf::fixture_values(fx, "step0.h");
    {  // Row c is the recording's column c: the reference's token c, its target encoder's output.
      const NpyArray emb = read_npy(t / "emb.npy");
      REQUIRE(emb.shape == std::vector<std::int64_t>{3, 12, 8});
      const double err = rf::fixture_error<float>(std::span<const float>(emb.data(), emb.numel()),
                                                  std::vector<double>(h.begin(), h.end()));
      MESSAGE("tjepa embed on the converted fixture model against its target encoder: relative error ", err);
      CHECK(err < 1e-5);
    }
    {  // --rows layout: token j of tjepa's layout is the reference's token column[j].
      eo.rows = "layout";
      eo.force = true;
      REQUIRE(cli::run_embed(eo, out) == 0);
      const NpyArray emb = read_npy(t / "emb.npy");
      std::vector<double> expected(h.size());
      for (int w = 0; w < 3; ++w)
        for (int j = 0; j < 12; ++j)
          for (int c = 0; c < 8; ++c)
            expected[(std::size_t(w) * 12 + j) * 8 + c] = h[(std::size_t(w) * 12 + column[std::size_t(j)]) * 8 + c];
      CHECK(rf::fixture_error<float>(std::span<const float>(emb.data(), emb.numel()), expected) < 1e-5);
      eo.rows = "taxels";
      CHECK_THROWS_WITH_AS(cli::run_embed(eo, out), doctest::Contains("--rows 'taxels', expected recording or layout"),
                           ConfigError);
      eo.rows = "recording";
    }
    {  // Raw Xela counts into a converted model: said, once.
      std::vector<float> raw(rec.size());
      for (std::size_t k = 0; k < raw.size(); ++k) raw[k] = 30000.0f + 50.0f * rec[k];
      write_npy(t / "raw.npy", std::span<const float>(raw), std::span<const std::int64_t>(shape));
      cli::EmbedOptions ro = eo;
      ro.data = {(t / "raw.npy").string()};
      ro.out = (t / "raw_emb.npy").string();
      std::ostringstream warned;
      REQUIRE(cli::run_embed(ro, warned) == 0);
      CHECK(warned.str().find("are raw Xela counts, but the model converted from " + (t / "ref.safetensors").string() +
                              " expects baseline-subtracted readings") != std::string::npos);
      CHECK(out.str().find("raw Xela counts") == std::string::npos);
    }
    {  // The run config's explicit temporal_patch_padding: 0 wins over the default for a file without the marker.
      SafetensorsFile zero = ref;
      zero.metadata["reference.config"] =
          R"({"num_heads": 2, "sequence_length": 6, "time_chunk_size": 6, "temporal_patch_padding": 0})";
      save_safetensors(t / "zero.safetensors", zero);
      cli::ConvertOptions zo = co;
      zo.in = (t / "zero.safetensors").string();
      zo.out = (t / "zero_tjepa.safetensors").string();
      std::ostringstream zout;
      REQUIRE(cli::run_convert(zo, zout) == 0);
      CHECK(zout.str().find("temporal padding 0 (the run config's temporal_patch_padding)") != std::string::npos);
      CHECK(load_trained_model(zo.out).model->config.temporal_padding == 0);
    }

    // Back to the reference: the same tensors, bit for bit.
    cli::ConvertOptions back;
    back.in = co.out;
    back.out = (t / "back.safetensors").string();
    REQUIRE(cli::run_convert(back, out) == 0);
    const SafetensorsFile b = load_safetensors(back.out);
    CHECK(b.size() == ref.size());
    for (const std::string& name : ref.names()) {
      REQUIRE_MESSAGE(b.contains(name), name);
      CHECK_MESSAGE(b.at(name).dtype == ref.at(name).dtype, name);
      CHECK_MESSAGE(b.at(name).shape == ref.at(name).shape, name);
      CHECK_MESSAGE(b.at(name).data == ref.at(name).data, name);
    }

    // What tjepa cannot represent is refused by name.
    SafetensorsFile reg = ref;
    reg.add("context_encoder.register_tokens", Tensor::from(std::vector<float>(16, 0.0f), {1, 2, 8}));
    save_safetensors(t / "reg.safetensors", reg);
    co.in = (t / "reg.safetensors").string();
    co.out = (t / "reg_tjepa.safetensors").string();
    CHECK_THROWS_WITH_AS(cli::run_convert(co, out), doctest::Contains("register_tokens"), FileError);
    CHECK_FALSE(std::filesystem::exists(co.out));
    co.in = (t / "last.ckpt").string();
    CHECK_THROWS_WITH_AS(cli::run_convert(co, out), doctest::Contains("torch_checkpoint.py to-safetensors"), ConfigError);
    SafetensorsFile chunks = ref;
    chunks.metadata["reference.config"] = R"({"num_heads": 2, "sequence_length": 12, "time_chunk_size": 6})";
    save_safetensors(t / "chunks.safetensors", chunks);
    co.in = (t / "chunks.safetensors").string();
    CHECK_THROWS_WITH_AS(cli::run_convert(co, out), doctest::Contains("one token per taxel"), FileError);
  }
}
