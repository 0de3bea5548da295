// The `tjepa` command's subcommands, run in-process on tiny inputs: layout, pretrain, probe,
// embed, demo. Each checks what the command promises: the files it writes (and that a failing
// command leaves none behind), the numbers it reports, and one-line errors for bad input.
// The layout-CSV cases read a skin through sensors/skin_from_coordinates.hpp (edges inferred from
// the coordinates); it is named here so each module these tests cover is traceable.
#include <doctest/doctest.h>

#include "../probe.hpp"
#include "../embed.hpp"
#include "../layout.hpp"
#include "../pretrain.hpp"
#include "../eval.hpp"
#include "../options.hpp"
#include <tjepa/sensors/skin_from_coordinates.hpp>

#include "../../../tests/support/files.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include <unistd.h>

namespace fs = std::filesystem;
using namespace tjepa;
using namespace tjepa::cli;

namespace {

using tjepa_test::read_file;
using tjepa_test::TempDir;

// Files under dir, recursively (to check that nothing, not even a temporary, is left).
int count_files(const fs::path& dir) {
  if (!fs::exists(dir)) return 0;
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.is_regular_file();
  return n;
}

// The smallest model that exercises every piece.
nlohmann::json tiny_run(const std::string& layout) {
  return {{"layout", layout}, {"dim", 8}, {"depth", 1}, {"heads", 2}, {"predictor_depth", 1},
          {"steps", 3},       {"batch", 4}, {"warmup_steps", 1}, {"seed", 3}};
}

// A head's progress line in a run's log: "[time]  <head>: <task> <value> <unit> (best epoch B of E)".
// Returns {B, E}, or {0, 0} when no line starts with `head_task` after its time stamp, the value is
// not a number, or the line does not end as promised. (Parsed by hand: std::regex trips GCC 12's
// -Wmaybe-uninitialized under ASan.)
std::pair<int, int> head_stop(const std::string& log, const std::string& head_task, const std::string& unit) {
  std::istringstream in(log);
  for (std::string line; std::getline(in, line);) {
    const auto stamp = line.find("] ");
    if (line.empty() || line[0] != '[' || stamp == std::string::npos) continue;
    const auto at = line.find_first_not_of(' ', stamp + 1);
    if (at == std::string::npos || line.compare(at, head_task.size(), head_task) != 0) continue;
    const auto value = at + head_task.size();
    const std::string marker = " " + unit + " (best epoch ";
    const auto tail = line.rfind(marker);
    if (tail == std::string::npos || tail <= value || !std::isdigit(static_cast<unsigned char>(line[value])))
      return {0, 0};
    int best = 0, epochs = 0;
    char close = 0;
    std::istringstream t(line.substr(tail + marker.size()));
    std::string of;
    if (!(t >> best >> of >> epochs >> close) || of != "of" || close != ')' || t.peek() != EOF) return {0, 0};
    return {best, epochs};
  }
  return {0, 0};
}

}  // namespace

TEST_SUITE("cli") {

TEST_CASE("layout: summary of the built-in Allegro hand / as text and JSON / and an SVG") {
  TempDir t;
  std::ostringstream out;
  LayoutOptions o;
  o.json = true;
  o.svg = (t.path / "hand.svg").string();
  CHECK(run_layout(o, out) == 0);
  const auto j = nlohmann::json::parse(out.str());
  CHECK(j["taxels"] == 368);
  CHECK(j["edges"] == 638);
  CHECK(j["bridges"] == 68);  // 17 adjacent pad pairs x 4
  CHECK(j["groups"] == 18);
  CHECK(j["parts"] == 1);
  CHECK(j["components"] == 1);
  const std::string svg = read_file(o.svg);
  CHECK(svg.starts_with("<svg"));
  CHECK(svg.find("</svg>") != std::string::npos);
  // Without --force an existing SVG is not overwritten, and the command says so.
  CHECK_THROWS_AS(run_layout(o, out), FileError);

  std::ostringstream text;
  LayoutOptions plain;
  CHECK(run_layout(plain, text) == 0);
  CHECK(text.str().find("368 taxels, 638 edges") != std::string::npos);
}

TEST_CASE("layout: sampled masks follow the reference counts") {
  std::ostringstream out;
  LayoutOptions o;
  o.layout = "grid";
  o.draw = "masks";
  o.json = true;
  o.seed = 5;
  CHECK(run_layout(o, out) == 0);
  const auto j = nlohmann::json::parse(out.str());
  const int n = j["taxels"];
  REQUIRE(j.contains("masks"));
  const auto& targets = j["masks"]["targets"];
  REQUIRE(targets.size() == 4);
  CHECK(targets[0]["kind"] == "local");
  CHECK(targets[2]["kind"] == "global");
  for (const auto& tg : targets) {
    CHECK(tg["size"].get<int>() >= static_cast<int>(n * 0.10));
    CHECK(tg["size"].get<int>() < static_cast<int>(n * 0.18) + 1);
  }
  const int k = j["masks"]["context"];
  CHECK(k >= std::max(32, static_cast<int>(std::ceil(0.15 * n))));
  CHECK(k < n);
}

TEST_CASE("layout: a CSV layout gets grid edges inside groups and bridges between them") {
  TempDir t;
  const fs::path csv = t.path / "two_pads.csv";
  {
    std::ofstream f(csv);
    f << "# two 2x3 pads side by side, 4 mm pitch\nid,group,x,y\n";
    int id = 0;
    for (int g = 0; g < 2; ++g)
      for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c) f << id++ << ",pad" << g << ',' << (g * 14 + c * 4) << ',' << r * 4 << '\n';
  }
  std::ostringstream out;
  LayoutOptions o;
  o.layout = csv.string();
  o.json = true;
  CHECK(run_layout(o, out) == 0);
  const auto j = nlohmann::json::parse(out.str());
  CHECK(j["taxels"] == 12);
  CHECK(j["groups"] == 2);
  CHECK(j["bridges"] == 4);               // the 4 closest cross-pad pairs
  CHECK(j["edges"] == 2 * 7 + 4);         // a 2x3 grid has 7 four-neighbour edges
  CHECK(j["components"] == 1);

  // A malformed CSV is one clear error naming the file and line.
  {
    std::ofstream f(t.path / "bad.csv");
    f << "x,y\n1,2\n3,oops\n";
  }
  o.layout = (t.path / "bad.csv").string();
  try {
    run_layout(o, out);
    FAIL("expected an error");
  } catch (const FileError& e) {
    const std::string msg = e.what();
    CHECK(msg.find("bad.csv:3") != std::string::npos);
    CHECK(msg.find('\n') == std::string::npos);
  }
  o.layout = "no-such-layout";
  CHECK_THROWS_AS(run_layout(o, out), ConfigError);
}

TEST_CASE("pretrain / probe and embed on a tiny simulated skin") {
  TempDir t;
  std::ostringstream out;
  PretrainOptions po;
  po.overrides = tiny_run("grid");
  po.overrides["drift_time_constant"] = 200;
  po.simulate_frames = 300;
  po.out = (t.path / "run").string();
  po.quiet = true;
  REQUIRE(run_pretrain(po, out) == 0);
  const fs::path ck = t.path / "run" / "checkpoint.safetensors";
  REQUIRE(fs::exists(ck));
  const std::string log = read_file(t.path / "run" / "log.csv");
  CHECK(log.starts_with("step,loss,"));
  CHECK(std::count(log.begin(), log.end(), '\n') == 1 + 3);  // header + one row per step
  CHECK(read_file(t.path / "run" / "loss.svg").starts_with("<svg"));
  CHECK(count_files(t.path / "run") == 3);  // no temporaries left

  // The checkpoint restores the run's config, the model and the fitted preprocessing.
  const TrainedModel m = load_trained_model(ck);
  CHECK(m.config.model.dim == 8);
  CHECK(m.step == 3);
  CHECK(m.model->num_tokens() == 192);
  CHECK(m.pre.ready());
  // Simulated data come with a no-contact baseline, and the run asked for drift tracking: the
  // checkpoint carries the tracker (fitted rest readings and noise of the 192 taxels x 3 axes).
  REQUIRE(m.drift.has_value());
  CHECK(m.drift->taxels() == 192);
  CHECK(m.drift->config().time_constant == m.config.data.drift_time_constant);
  CHECK(m.drift->noise()[2] == doctest::Approx(SimConfig{}.noise_std).epsilon(0.15));

  // Running again into the same directory needs --force.
  CHECK_THROWS_AS(run_pretrain(po, out), FileError);

  SUBCASE("probe on simulated labelled data, results as JSON") {
    ProbeOptions pb;
    pb.checkpoint = ck.string();
    pb.simulate_train_frames = 600;
    pb.simulate_test_frames = 400;
    pb.probe.max_epochs = 1;
    pb.probe.batch = 8;
    pb.out = (t.path / "probe.json").string();
    pb.quiet = true;
    std::ostringstream pout;
    REQUIRE(run_probe(pb, pout) == 0);
    const auto j = nlohmann::json::parse(read_file(pb.out));
    REQUIRE(j["results"].size() == 2);
    for (const auto& r : j["results"]) {
      CHECK(r["mean"]["indenter_accuracy"].get<double>() >= 0.0);
      CHECK(r["mean"]["indenter_accuracy"].get<double>() <= 1.0);
      for (const char* k : {"force_rmse_u", "force_rmse_v", "force_rmse_n", "force_rmse"})
        CHECK(std::isfinite(r["mean"][k].get<double>()));
      CHECK(r["windows"].get<int>() > 0);
    }
    CHECK(pout.str().find("| encoder | RMSE u (N) ↓ | RMSE v (N) ↓ | RMSE n (N) ↓ | RMSE avg (N) ↓ | indenter top-1 (%) ↑ | probe lr |") !=
          std::string::npos);
    // --save: the force and indenter head as a file, for the encoder it was trained on.
    pb.save = (t.path / "force_head.safetensors").string();
    pb.out.clear();
    REQUIRE(run_probe(pb, pout) == 0);
    const TrainedModel m2 = load_trained_model(ck);
    const auto head = load_probe_head<float>(pb.save, encoder_fingerprint(m2, m2.model->target));
    CHECK(head.head.regression == 3);
    CHECK(head.head.classes == num_indenter_shapes);
    CHECK(head.info.output_names == std::vector<std::string>{"force_u", "force_v", "force_normal"});
    CHECK(head.info.class_names.front() == "sphere");
    CHECK(head.info.task == "force and indenter");
    CHECK(head.info.tau == m2.config.data.tau);
    CHECK(pout.str().find("wrote " + pb.save + ": target encoder (frozen), encoder ") != std::string::npos);
  }

  SUBCASE("probe on labelled files") {
    SimulatedSkin sim(SkinGeometry::from_layout(layouts::grid_skin().layout), SimConfig{}, 9);
    const SimRecording a = sim.record(500), b = sim.record(300);
    write_npy(t.path / "train.npy", a.recording);
    write_npy(t.path / "test.npy", b.recording);
    const auto la = frame_label_array(a.labels), lb = frame_label_array(b.labels);
    write_npy(t.path / "train_labels.npy", std::span<const float>(la), {a.recording.frames(), 4});
    write_npy(t.path / "test_labels.npy", std::span<const float>(lb), {b.recording.frames(), 4});
    ProbeOptions pb;
    pb.checkpoint = ck.string();
    pb.train_data = {(t.path / "train.npy").string()};
    pb.train_labels = {(t.path / "train_labels.npy").string()};
    pb.test_data = {(t.path / "test.npy").string()};
    pb.test_labels = {(t.path / "test_labels.npy").string()};
    pb.probe.max_epochs = 1;
    pb.probe.batch = 8;
    pb.quiet = true;
    std::ostringstream pout;
    CHECK(run_probe(pb, pout) == 0);
    // Labels of the wrong length: one clear error.
    pb.test_labels = pb.train_labels;
    CHECK_THROWS_AS(run_probe(pb, pout), FileError);
  }

  SUBCASE("embed writes [windows, N, d]") {
    SimulatedSkin sim(SkinGeometry::from_layout(layouts::grid_skin().layout), SimConfig{}, 4);
    write_npy(t.path / "rec.npy", sim.record(65).recording);
    EmbedOptions eo;
    eo.checkpoint = ck.string();
    eo.data = {(t.path / "rec.npy").string()};
    eo.out = (t.path / "emb.npy").string();
    eo.quiet = true;
    std::ostringstream eout;
    REQUIRE(run_embed(eo, eout) == 0);
    const NpyArray e = read_npy(eo.out);
    CHECK(e.shape == std::vector<std::int64_t>{6, 192, 8});  // 65 frames → 6 windows of 10
    // Finite embeddings that depend on the window.
    bool finite = true;
    for (std::size_t i = 0; i < e.numel(); ++i) finite = finite && std::isfinite(e.data()[i]);
    CHECK(finite);
    CHECK(e.data()[0] != e.data()[192 * 8]);
    // A recording of another sensor size is rejected, and no output appears.
    write_npy(t.path / "wrong.npy", Recording(20, 10, 3));
    eo.data = {(t.path / "wrong.npy").string()};
    eo.out = (t.path / "emb2.npy").string();
    CHECK_THROWS_AS(run_embed(eo, eout), ShapeError);
    CHECK_FALSE(fs::exists(eo.out));
  }
}

TEST_CASE("pretrain --precision bf16 notes why where bf16 would not be faster on this build and core") {
  TempDir t;
  std::ostringstream out;
  PretrainOptions po;
  po.overrides = tiny_run("grid");
  po.overrides["precision"] = "bf16";
  po.simulate_frames = 300;
  po.out = (t.path / "run").string();
  po.quiet = true;
  REQUIRE(run_pretrain(po, out) == 0);
  const std::string why = bf16_slower_reason(measure_product_peaks());
  CAPTURE(out.str());
  CHECK((out.str().find("note: --precision bf16: ") != std::string::npos) == !why.empty());
  if (!has_native_bf16()) CHECK(out.str().find("no AVX512-BF16, so bf16 computes in fp32") != std::string::npos);
}

TEST_CASE("resume across programs: tjepa pretrain to a user Trainer and back give the uninterrupted loss curve bitwise") {
  TempDir t;
  std::ostringstream out;
  PretrainOptions po;
  po.overrides = tiny_run("grid");
  po.overrides["steps"] = 6;
  po.overrides["drop_path"] = 0.1;  // the per-step noise seeds must match too
  po.simulate_frames = 300;
  po.quiet = true;
  auto losses = [](const fs::path& log) {  // the loss column of a log.csv, as written
    std::vector<std::string> v;
    std::istringstream in(read_file(log));
    std::string line;
    std::getline(in, line);
    while (std::getline(in, line)) v.push_back(line.substr(line.find(',') + 1, line.find(',', line.find(',') + 1) - line.find(',') - 1));
    return v;
  };
  po.out = (t.path / "straight").string();
  REQUIRE(run_pretrain(po, out) == 0);
  const auto straight = losses(t.path / "straight" / "log.csv");
  REQUIRE(straight.size() == 6);

  // The user's program: the same simulated sensor, preprocessing and config, through the library only.
  TrainConfig cfg = TrainConfig::from_json(po.overrides, "test");
  const Skin skin = layouts::grid_skin();
  SimulatedSkin sim(SkinGeometry::from_layout(skin.layout), SimConfig{}, cfg.seed);
  const Recording baseline = sim.record_baseline(300);
  const Recording rec = sim.record(300, 1).recording;
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(baseline);
  pre.fit(std::span<const Recording>(&rec, 1));
  const WindowSource src(rec, WindowSpec{cfg.data.tau}, {}, pre);
  auto to_text = [](double v) {  // as CsvTable writes a number
    CsvTable c;
    c.header = {"v"};
    c.rows = {{v}};
    const std::string s = c.str();
    return s.substr(2, s.size() - 3);
  };

  SUBCASE("pretrain --stop-after 3, then a user Trainer resumes") {
    po.out = (t.path / "half").string();
    po.stop_after = 3;
    REQUIRE(run_pretrain(po, out) == 0);
    auto model = make_jepa_model(cfg, skin.graph, 3, 12345);  // everything must come from the file
    JepaTrainer<float> trainer(*model, src, skin.graph, cfg);
    trainer.resume(t.path / "half" / "checkpoint.safetensors");
    CHECK(trainer.step() == 3);
    const auto tail = trainer.run();
    REQUIRE(tail.size() == 3);
    for (int s = 0; s < 3; ++s) CHECK(to_text(tail[s].loss) == straight[3 + s]);
    // Bitwise: the parameters equal those of the uninterrupted run's final checkpoint.
    const TrainedModel done = load_trained_model(t.path / "straight" / "checkpoint.safetensors");
    for (auto [a, b] : {std::pair{&model->context, &done.model->context}, std::pair{&model->target, &done.model->target},
                        std::pair{&model->predictor_params, &done.model->predictor_params}})
      CHECK(std::equal(a->values().begin(), a->values().end(), b->values().begin()));
  }
  SUBCASE("a user Trainer stops at 3, then pretrain --resume continues") {
    auto model = make_jepa_model(cfg, skin.graph, 3, cfg.seed);
    JepaTrainer<float> trainer(*model, src, skin.graph, cfg);
    trainer.extras = data_state(pre);
    const auto head = trainer.run(3);
    for (int s = 0; s < 3; ++s) CHECK(to_text(head[s].loss) == straight[s]);
    trainer.save(t.path / "user.safetensors");
    po.out = (t.path / "continued").string();
    po.overrides = nlohmann::json::object();
    po.resume = (t.path / "user.safetensors").string();
    REQUIRE(run_pretrain(po, out) == 0);
    const auto tail = losses(t.path / "continued" / "log.csv");
    REQUIRE(tail.size() == 3);
    for (int s = 0; s < 3; ++s) CHECK(tail[s] == straight[3 + s]);
    // Bitwise: every tensor (parameters and AdamW moments) equals the uninterrupted run's.
    const auto a = load_safetensors(t.path / "continued" / "checkpoint.safetensors");
    const auto b = load_safetensors(t.path / "straight" / "checkpoint.safetensors");
    CHECK(a.names() == b.names());
    for (const auto& name : b.names()) CHECK(a.at(name).data == b.at(name).data);
  }
}

TEST_CASE("checkpoint metadata that no run could have throws FileError naming the key") {
  TempDir t;
  JepaConfig mc = TrainConfig{}.model_config(4, 1);
  mc.encoder.dim = 8, mc.encoder.heads = 2, mc.encoder.depth = 1;
  mc.predictor.in_dim = mc.predictor.dim = 8, mc.predictor.heads = 2, mc.predictor.depth = 1;
  JepaModel<float> model(mc, 0);
  const auto parts = model.parts();
  auto write = [&](const nlohmann::json& config) {
    CheckpointState st;
    st.config = config;
    const fs::path p = t.path / "bad.safetensors";
    save_checkpoint(p, std::span<const PrefixedParams<float>>(parts), static_cast<const AdamW<float>*>(nullptr), st);
    return p;
  };
  TrainConfig tc;
  tc.model.dim = 8, tc.model.heads = 2, tc.model.depth = 1, tc.model.predictor_depth = 1;
  auto error_of = [&](const nlohmann::json& config) {
    try {
      load_trained_model(write(config));
    } catch (const FileError& e) {
      return std::string(e.what());
    }
    return std::string("no FileError");
  };
  const nlohmann::json good = run_metadata(tc, mc);
  CHECK_NOTHROW(load_trained_model(write(good)));
  nlohmann::json j = good;
  j["train"]["tau"] = 0;  // once a SIGFPE in in_dim % tau
  CHECK(error_of(j).find("tau") != std::string::npos);
  j = good;
  j["model"]["encoder"]["dim"] = 1 << 20;  // a small file must not allocate terabytes
  j["model"]["encoder"]["heads"] = 1;
  j["model"]["predictor"]["in_dim"] = j["model"]["predictor"]["dim"] = 1 << 20;
  CHECK_MESSAGE(error_of(j).find("describes a model of about") != std::string::npos, error_of(j));
  j = good;  // the tokenizer's map alone: in_dim 2^30 (review finding)
  j["model"]["in_dim"] = 1 << 30;
  j["model"]["axes"] = 1;
  CHECK_MESSAGE(error_of(j).find("describes a model of about") != std::string::npos, error_of(j));
  j = good;
  j["model"].erase("encoder");
  CHECK(error_of(j).find("missing key 'encoder'") != std::string::npos);
  j = good;
  j["model"]["encoder"]["dim"] = "eight";
  CHECK(error_of(j).find("'dim'") != std::string::npos);
  j = good;
  j["model"]["encoder"] = nlohmann::json::array();
  CHECK(error_of(j).find("encoder") != std::string::npos);
  j = good;
  j["model"]["encoder"]["heads"] = 0;
  CHECK(error_of(j).find("heads") != std::string::npos);
  CHECK(error_of(nlohmann::json::array()).find("metadata 'config'") != std::string::npos);
}

TEST_CASE("pretrain: drift tracking off (drift_time_constant 0 / the default) leaves no tracker in the checkpoint") {
  TempDir t;
  std::ostringstream out;
  PretrainOptions po;
  po.overrides = tiny_run("grid");
  po.simulate_frames = 100;
  po.out = (t.path / "run").string();
  po.quiet = true;
  REQUIRE(run_pretrain(po, out) == 0);
  const TrainedModel m = load_trained_model(t.path / "run" / "checkpoint.safetensors");
  CHECK_FALSE(m.drift.has_value());
  CHECK(m.config.data.drift_time_constant == 0);
  TrainConfig bad;
  bad.update({{"drift_time_constant", 0.5}}, "test");
  CHECK_THROWS_WITH_AS(bad.validate(), doctest::Contains("drift_time_constant"), ConfigError);
}

TEST_CASE("pretrain: a failing run leaves no files behind") {
  TempDir t;
  std::ostringstream out;
  PretrainOptions po;
  po.overrides = tiny_run("grid");
  po.overrides["batch"] = 64;  // more than the 20 windows of 200 frames
  po.simulate_frames = 200;
  po.out = (t.path / "a" / "b").string();
  po.quiet = true;
  CHECK_THROWS_AS(run_pretrain(po, out), DataError);
  CHECK_FALSE(fs::exists(t.path / "a"));
  // Config errors name the key.
  po.overrides = {{"dimm", 8}};
  try {
    run_pretrain(po, out);
    FAIL("expected an error");
  } catch (const ConfigError& e) {
    CHECK(std::string(e.what()).find("unknown key 'dimm'") != std::string::npos);
  }
}

TEST_CASE("run config: masks from JSON / round trip and bad values named") {
  TrainConfig r;
  r.update({{"local_targets", 0}, {"global_targets", 4}, {"target_ratio", {0.05, 0.08}},
            {"context_ratio", {0.6, 0.7}}},
           "test");
  const MaskConfig m = r.masks;
  CHECK(m.num_local == 0);
  CHECK(m.num_global == 4);
  CHECK(m.target_ratio == RatioRange{0.05, 0.08});
  CHECK(m.context_ratio == RatioRange{0.6, 0.7});
  TrainConfig back;
  back.update(r.to_json(), "round trip");
  CHECK(back.to_json() == r.to_json());
  // The collator samples what the config says: 4 global targets of 5-8% of the 368 taxels.
  const MaskBatch b = MaskCollator(layouts::allegro_xela().graph, m).sample(2, 1, 0);
  REQUIRE(b.num_targets() == 4);
  for (const TargetSet& ts : b.targets) {
    CHECK(ts.kind == TargetKind::global);
    CHECK(ts.size >= 18);
    CHECK(ts.size <= 29);
  }
  auto error_of = [](const nlohmann::json& j) {
    TrainConfig c;
    try {
      c.update(j, "cfg");
      c.validate();
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK(error_of({{"target_ratio", {0.3, 0.2}}}).find("target_ratio") != std::string::npos);
  CHECK(error_of({{"local_targets", 0}, {"global_targets", 0}}).find("at least one target") != std::string::npos);
  CHECK(error_of({{"target_ratio", "wide"}}).find("'target_ratio'") != std::string::npos);
  CHECK(error_of({{"loss", "l1"}}).find("loss") != std::string::npos);
  CHECK(error_of({{"normalize_targets", 1.5}}).find("'normalize_targets'") != std::string::npos);
  CHECK(error_of({{"beta2", 1.0}}).find("beta2") != std::string::npos);
  CHECK(error_of({{"tau", 0}}).find("tau") != std::string::npos);
  CHECK(error_of({{"heads", 0}}).find("heads") != std::string::npos);
  CHECK(error_of({{"position_eigenvectors", -1}}).find("position_eigenvectors") != std::string::npos);
  CHECK(error_of({{"position_scale", 0.0}}).find("position_scale") != std::string::npos);
}

TEST_CASE("run config: graph positions / AdamW betas / standardized targets reach the model and the step") {
  const Skin skin = layouts::allegro_xela();
  TrainConfig r;
  r.model.dim = 12;
  r.model.heads = 2;
  r.model.depth = 1;
  r.model.predictor_depth = 1;
  // The defaults are the reference's: a random table, β = (0.9, 0.999), plain targets.
  const auto plain = make_jepa_model(r, skin.graph, 3, 4);
  CHECK(r.adamw.beta1 == 0.9);
  CHECK(r.adamw.beta2 == 0.999);
  CHECK_FALSE(r.step.standardize_targets);
  const auto same = make_jepa_model(r, skin.graph, 3, 4);
  CHECK(std::ranges::equal(plain->context.values(), same->context.values()));
  r.update({{"position_eigenvectors", 16}, {"position_scale", 0.5}, {"beta2", 0.99}, {"standardize_targets", true}},
           "test");
  r.validate();
  CHECK(r.adamw.beta2 == 0.99);
  CHECK(r.step.standardize_targets);
  const auto graph = make_jepa_model(r, skin.graph, 3, 4);
  const std::vector<double> rows = graph_positions(skin.graph, 12, 16, 0.5, 4);
  const auto e = graph->target.value_span(graph->encoder.pos_embed());
  REQUIRE(e.size() == rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) CHECK(e[i] == static_cast<float>(rows[i]));
  r.model.position_eigenvectors = 400;
  CHECK_THROWS_WITH_AS(make_jepa_model(r, skin.graph, 3, 4), doctest::Contains("368 tokens"), ConfigError);
}

TEST_CASE("run config: the objective's reference options reach the training step") {
  TrainConfig r;
  const JepaStepConfig d = r.step;
  CHECK(d.loss == JepaLossKind::mse);  // the reference's defaults
  CHECK_FALSE(d.normalize_targets);
  CHECK_FALSE(d.predictor_pos_from_context);
  r.update({{"loss", "smooth_l1"}, {"normalize_targets", true}, {"predictor_pos_from_context", true},
            {"drop_path", 0.1}},
           "test");
  r.validate();
  const JepaStepConfig c = r.step;
  CHECK(c.loss == JepaLossKind::smooth_l1);
  CHECK(c.normalize_targets);
  CHECK(c.predictor_pos_from_context);
  CHECK(c.drop_path == 0.1);
  TrainConfig back;
  back.update(r.to_json(), "round trip");
  CHECK(back.to_json() == r.to_json());
}

TEST_CASE("probe rows: repeats as samples of one row / mean ± sd in the score table / diverged repeats left out") {
  std::vector<ProbeRow> runs(3);
  const double u[3] = {1.0, 2.0, 4.0}, acc[3] = {0.5, 0.25, 0.75};
  for (int i = 0; i < 3; ++i) {
    ProbeMetrics m;
    m.force_rmse = {u[i], 2 * u[i], 0.5};
    m.indenter_accuracy = acc[i];
    m.windows = 10;
    runs[static_cast<std::size_t>(i)] = ProbeRow{"#" + std::to_string(i), {m}, {1e-3 * (i + 1)}, 1.5, {}, nullptr, {}};
  }
  const ProbeRow r = average_rows("avg", runs);
  CHECK(r.runs.size() == 3);
  CHECK(r.seconds == doctest::Approx(4.5));
  const ScoreTable t = probe_score_table({r});
  const ScoreRow& row = t.rows.front();
  CHECK(row.summary(0).mean == doctest::Approx(7.0 / 3));
  CHECK(row.summary(1).mean == doctest::Approx(14.0 / 3));
  CHECK(row.summary(2).mean == doctest::Approx(0.5));
  // sample sd of {1, 2, 4}: sqrt(((4/3)^2 + (1/3)^2 + (5/3)^2) / 2) = sqrt(7/3)
  CHECK(row.summary(0).sd == doctest::Approx(std::sqrt(7.0 / 3)));
  CHECK(row.summary(1).sd == doctest::Approx(2 * std::sqrt(7.0 / 3)));
  CHECK(row.summary(2).sd == doctest::Approx(0.0));
  CHECK(row.summary(3).mean == doctest::Approx((7.0 / 3 + 14.0 / 3 + 0.5) / 3));  // the axes' mean
  CHECK(row.summary(4).mean == doctest::Approx(0.5));
  CHECK(row.summary(4).sd == doctest::Approx(0.25));
  const std::string md = t.markdown();
  CAPTURE(md);
  CHECK(md.find("| avg | 2.333 ± 1.528 | 4.667 ± 3.055 | 0.500 ± 0.000 |") != std::string::npos);
  CHECK(md.find("| 50.0 ± 25.0 | 1e-03,2e-03,3e-03 |") != std::string::npos);
  const auto j = t.to_json();
  CHECK(j["rows"][0]["runs"].size() == 3);
  CHECK(!j["rows"][0].contains("note"));
  CHECK(j["rows"][0]["windows"] == 10);
  CHECK(j["rows"][0]["sd"]["force_rmse_u"].get<double>() == doctest::Approx(std::sqrt(7.0 / 3)));
  // A diverged repeat is left out of the mean and named, not averaged into "66.7 % ± 57.7".
  runs[1].flag = "diverged (validation loss not finite)";
  const ProbeRow d = average_rows("avg", runs);
  const ScoreTable td = probe_score_table({d});
  CHECK(td.rows[0].summary(0).mean == doctest::Approx(2.5));
  CHECK(td.rows[0].summary(4).mean == doctest::Approx(0.625));
  CHECK(d.flag == "1 of 3 repeats diverged, left out of the mean");
  CHECK(td.markdown().find("note: avg: 1 of 3 repeats diverged") != std::string::npos);
  CHECK_THROWS_WITH_AS(average_rows("none", {}), doctest::Contains("no probes"), ConfigError);
}

TEST_CASE("demo and eval: the grasp protocol at toy size prints the tables and writes its outputs") {
  TempDir t;
  EvalOptions o = demo_eval_options(3);
  CHECK(o.eval.seeds == std::vector<std::uint64_t>{3});
  CHECK(o.eval.data_seed == 3);
  CHECK_FALSE(o.eval.mae);
  CHECK_FALSE(o.eval.dino);
  CHECK_FALSE(o.eval.byol);
  CHECK_FALSE(o.eval.ablation);
  CHECK(o.eval.heads.probe.max_epochs == GraspHeadConfig{}.probe.max_epochs);  // the protocol's probe limits
  CHECK(o.eval.heads.probe.patience == GraspHeadConfig{}.probe.patience);
  CHECK(o.eval.heads.sequence.max_epochs == GraspHeadConfig{}.sequence.max_epochs);
  CHECK(o.eval.heads.sequence.patience == GraspHeadConfig{}.sequence.patience);
  CHECK(o.eval.heads.sequence_pooling.kind == PoolingKind::taxel);
  // End to end: the protocol trains it with the heads' limits; the demo caps it at 2 epochs (its
  // budget) and the row's name says so.
  CHECK(GraspHeadConfig{}.end_to_end_max_epochs == GraspHeadConfig{}.probe.max_epochs);
  CHECK(GraspHeadConfig{}.end_to_end_patience == GraspHeadConfig{}.probe.patience);
  CHECK(end_to_end_name(GraspHeadConfig{}) == "end to end");
  CHECK(o.eval.heads.end_to_end_max_epochs == 2);
  CHECK(o.eval.heads.end_to_end_patience == 2);
  CHECK(end_to_end_name(o.eval.heads) == "end to end (at most 2 epochs, patience 2)");
  CHECK_FALSE(o.eval.linear_readout);  // the demo leaves the linear read-outs to tjepa eval
  o.eval.linear_readout = true;        // which writes them: checked here at toy size
  GraspHeadConfig impatient;
  impatient.end_to_end_patience = 2;  // the heads' epochs, a shorter patience: named too
  CHECK(end_to_end_name(impatient) == "end to end (at most 200 epochs, patience 2)");
  o.out = (t.path / "demo").string();
  o.eval.train.update(tiny_run("allegro"), "test");
  o.eval.train.data.drift_time_constant = 200;
  o.eval.pretrain_frames = 1000;
  o.eval.train_frames = 3000;
  o.eval.test_frames = 2000;
  o.eval.tasks.sequence_length = 3;
  o.eval.tasks.max_object_windows = o.eval.tasks.max_force_windows = 30;
  o.eval.tasks.max_pose_sequences = 8;
  o.eval.heads.probe.max_epochs = o.eval.heads.sequence.max_epochs = 2;
  o.eval.heads.end_to_end_max_epochs = 1;
  o.eval.heads.probe_heads = 1;
  std::ostringstream out;
  REQUIRE(run_eval(o, out) == 0);
  const std::string s = out.str();
  // A progress line per head says where it stopped: best epoch and epochs run, within the limits.
  for (const auto& [head_task, unit] : {std::pair{"Tactile-JEPA, frozen: object top-1 ", "%"},
                                        std::pair{"random init, frozen: force RMSE ", "N"}}) {
    const auto [best, epochs] = head_stop(s, head_task, unit);
    CAPTURE(head_task);
    CHECK(best >= 1);
    CHECK(best <= epochs);
    CHECK(epochs <= 2);
  }
  CHECK(head_stop(s, "end to end: pose x/y/θ RMSE ", "deg") == std::pair{1, 1});
  CHECK(head_stop(s, "end to end: pose x/y/θ RMSE ", "N") == std::pair{0, 0});  // the parser can say no
  for (const char* row : {"| constant |", "| ridge (pad sums + taxel means) |", "| random init, frozen |",
                          "| end to end (at most 1 epoch, patience 2) |", "| Tactile-JEPA, frozen |"})
    CHECK(s.find(row) != std::string::npos);
  CHECK(s.find("MAE") == std::string::npos);
  const auto j = nlohmann::json::parse(read_file(t.path / "demo" / "results.json"));
  CHECK(j["main"]["rows"].size() == 5);
  CHECK(s.find("Linear read-out") != std::string::npos);
  CHECK(j["linear"]["rows"].size() == 5);  // ridge; random init and Tactile-JEPA, each on pad means and token components
  CHECK(j["config"]["seeds"] == nlohmann::json::array({3}));
  CHECK(j["command"] == "tjepa demo");
  for (const char* f : {"results.md", "results.json", "results.svg"}) CHECK(fs::exists(t.path / "demo" / f));
  CHECK(count_files(t.path / "demo") == 3);
  // The same command again refuses to overwrite without --force, and the files stay.
  o.force = false;
  CHECK_THROWS_AS(run_eval(o, out), FileError);
  CHECK(count_files(t.path / "demo") == 3);
}

TEST_CASE("tjepa eval's command line: flags land in the options and the pre-training overrides") {
  CLI::App app;
  EvalCommand ev;
  CLI::App* eval = add_eval_command(app, ev);
  const char* argv[] = {"tjepa", "eval", "--seeds", "4", "5", "--head-seeds", "2", "--end-to-end-epochs", "30",
                        "--end-to-end-patience", "7", "--pretrain-cache", "cache/dir", "--steps", "11",
                        "--precision", "bf16", "--no-mae", "--no-dino", "--no-byol", "--byol-image-size", "96", "--no-ablation",
                        "--sequence-pooling", "attentive",
                        "--stop-on-error", "--out", "runs/x", "--force"};
  const int argc = static_cast<int>(std::size(argv));
  app.parse(argc, argv);
  REQUIRE(eval->parsed());
  const EvalOptions o = ev.resolve(argc, argv);
  CHECK(o.eval.seeds == std::vector<std::uint64_t>{4, 5});
  CHECK(o.eval.head_seeds == 2);
  CHECK(o.eval.heads.end_to_end_max_epochs == 30);
  CHECK(o.eval.heads.end_to_end_patience == 7);
  CHECK(o.eval.pretrain_cache == "cache/dir");
  CHECK(o.eval.train.schedule.steps == 11);
  CHECK(o.eval.train.schedule.warmup_steps == 1);  // the default warm-up of 60 cut to a tenth of the run
  CHECK(o.eval.train.step.precision == Precision::bf16);
  CHECK_FALSE(o.eval.mae);
  CHECK_FALSE(o.eval.dino);
  CHECK_FALSE(o.eval.byol);
  CHECK(o.eval.byol_image_size == 96);
  CHECK_FALSE(o.eval.ablation);
  CHECK(o.eval.end_to_end);
  CHECK(o.eval.heads.sequence_pooling.kind == PoolingKind::attentive);
  CHECK(o.eval.heads.probe.stop_on_error);
  CHECK_FALSE(o.eval.heads.sequence.stop_on_error);
  CHECK(o.out == "runs/x");
  CHECK(o.force);
  CHECK(o.command.starts_with("tjepa eval --seeds 4 5 "));
  CHECK(o.command.ends_with(" --out runs/x --force"));
  // Nothing given: the protocol's defaults.
  CLI::App app2;
  EvalCommand plain;
  add_eval_command(app2, plain);
  const char* none[] = {"tjepa", "eval"};
  app2.parse(2, none);
  const EvalOptions d = plain.resolve(2, none);
  CHECK(d.eval.to_json() == GraspEvalConfig{}.to_json());
  CHECK(d.eval.pretrain_cache.empty());
  CHECK_FALSE(d.eval.heads.probe.stop_on_error);
  const char* bad[] = {"tjepa", "eval", "--sequence-pooling", "mean"};
  CLI::App app3;
  EvalCommand b;
  add_eval_command(app3, b);
  CHECK_THROWS_AS(app3.parse(4, bad), CLI::ValidationError);
}

TEST_CASE("tjepa probe's command line: --probe-pooling auto tries both poolings / one fixes it / --lr-grid takes commas") {
  using namespace tjepa;
  using namespace tjepa::cli;
  auto parse = [](std::vector<const char*> argv) {
    CLI::App app;
    auto o = std::make_unique<ProbeOptions>();
    add_probe_command(app, *o);
    app.parse(static_cast<int>(argv.size()), argv.data());
    return o;
  };
  const auto d = parse({"tjepa", "probe", "--checkpoint", "c"});
  CHECK(d->poolings == std::vector<PoolingKind>{PoolingKind::attentive, PoolingKind::taxel});
  CHECK(d->lr_grid == std::vector<double>{3e-4, 1e-3, 3e-3});
  CHECK(parse({"tjepa", "probe", "--checkpoint", "c", "--probe-pooling", "taxel"})->poolings ==
        std::vector<PoolingKind>{PoolingKind::taxel});
  CHECK(parse({"tjepa", "probe", "--checkpoint", "c", "--probe-pooling", "auto"})->poolings.size() == 2u);
  CHECK(parse({"tjepa", "probe", "--checkpoint", "c", "--lr-grid", "1e-3,3e-3"})->lr_grid == std::vector<double>{1e-3, 3e-3});
  CHECK(parse({"tjepa", "probe", "--checkpoint", "c", "--lr-grid", "1e-3", "3e-3"})->lr_grid == std::vector<double>{1e-3, 3e-3});
  CHECK_THROWS_AS(parse({"tjepa", "probe", "--checkpoint", "c", "--probe-pooling", "mean"}), CLI::ValidationError);
  // Without --task the force and indenter probe has no pooling choice: the flag is refused by name.
  ProbeOptions o;
  o.checkpoint = "none.safetensors";
  o.poolings = {PoolingKind::taxel};
  std::ostringstream out;
  CHECK_THROWS_WITH_AS(run_probe(o, out), doctest::Contains("--probe-pooling are for your own labels"), ConfigError);
  CHECK(parse({"tjepa", "probe", "--checkpoint", "c", "--save", "h.safetensors"})->save == "h.safetensors");
}

}  // TEST_SUITE
