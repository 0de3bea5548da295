// Labelled trials end to end on slices of two real datasets (tests/data/fabricslide: FabricSlide,
// MIT; tests/data/icub_grasp: the iCub grasp dataset, copyright kept): pre-training on the
// training trials only, windows that never cross a trial, splits that never cut one, window- and
// trial-level results, predictions per window and per trial, the linear read-out beside the
// attentive probe, and the label checks a first real run trips over.
#include <doctest/doctest.h>

#include "../pretrain.hpp"
#include "../embed.hpp"
#include "../probe.hpp"
#include "../run.hpp"
#include "xserver_peer.hpp"

#include "../../../tests/support/files.hpp"

#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {
namespace fs = std::filesystem;
using tjepa_test::read_file;
using tjepa_test::TempDir;

const fs::path data_dir = TJEPA_TEST_DATA_DIR;

tjepa::cli::DataFormat fabric_format() {
  tjepa::cli::DataFormat f;
  f.axes = 1, f.columns = "3:19";
  return f;
}
tjepa::cli::DataFormat icub_format() {
  tjepa::cli::DataFormat f;
  f.axes = 1, f.columns = "14:74", f.skip_rows = 1, f.lines_per_frame = 7;
  return f;
}

tjepa::cli::PretrainOptions trial_run(const fs::path& set, const tjepa::cli::DataFormat& f, const fs::path& out, int tau) {
  tjepa::cli::PretrainOptions po;
  po.overrides = {{"dim", 16}, {"depth", 1}, {"heads", 2}, {"predictor_depth", 1}, {"batch", 8}, {"seed", 3},
                  {"steps", 20}, {"warmup_steps", 2}, {"tau", tau}, {"layout", (set / "layout.csv").string()}};
  po.trials.table = (set / "trials.csv").string();
  po.format = f;
  po.out = out.string();
  po.quiet = true;
  return po;
}

// Splits a CSV line; fields may be double-quoted (the row names hold commas).
std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> f(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') f.back() += '"', ++i;
    else if (c == '"') quoted = !quoted;
    else if (c == ',' && !quoted) f.emplace_back();
    else f.back() += c;
  }
  return f;
}
}  // namespace

TEST_SUITE("cli") {

TEST_CASE("trials: FabricSlide slides pre-train on the training trials / the probe reads windows inside trials / per window and per trial") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trials_fabric");
  const fs::path set = data_dir / "fabricslide";
  std::ostringstream log;
  REQUIRE(run_pretrain(trial_run(set, fabric_format(), t / "run", 10), log) == 0);
  CHECK(log.str().find("trials: pre-training on the 12 training and validation trials of 12 training, 0 validation "
                       "and 6 test trials of 18 (the table's split column); the test trials are left out") != std::string::npos);

  ProbeOptions pb;
  pb.checkpoint = (t / "run" / "checkpoint.safetensors").string();
  pb.task = "classification";
  pb.trials.table = (set / "trials.csv").string();
  pb.format = fabric_format();
  pb.probe.max_epochs = 4;
  pb.probe.patience = 4;
  pb.lr_grid = {1e-3, 3e-3};
  pb.quiet = true;
  pb.out = (t / "probe.json").string();
  pb.predictions = (t / "pred.csv").string();
  pb.save = (t / "head.safetensors").string();
  std::ostringstream out;
  REQUIRE(run_probe(pb, out) == 0);
  const std::string text = out.str();
  CHECK(text.find("(12 / 6 trials)") != std::string::npos);
  {  // The checkpoint encoder's probe as a file: its classes, its windows, the encoder it reads.
    const TrainedModel m = load_trained_model(pb.checkpoint);
    const auto head = load_probe_head<float>(pb.save, encoder_fingerprint(m, m.model->target));
    CHECK(head.info.class_names == std::vector<std::string>{"BeigeCotton", "BrownCotton", "Canvas"});
    CHECK(head.info.tau == 10);
    CHECK(head.info.stride == 10);
    CHECK(head.info.task == "classification");
    CHECK(head.head.classes == 3);
    CHECK(text.find("wrote " + pb.save + ": target encoder (frozen), probe (") != std::string::npos);
    CHECK_THROWS_WITH_AS(load_probe_head<float>(pb.save, encoder_fingerprint(m, m.model->context), "the context encoder"),
                         doctest::Contains("not on the context encoder"), ConfigError);
    ProbeOptions again = pb;  // the head file exists: --force
    again.out.clear(), again.predictions.clear();
    CHECK_THROWS_WITH_AS(run_probe(again, out), doctest::Contains("head.safetensors"), FileError);
  }
  CHECK(text.find("| top-1 (%) ↑ | trial top-1 (%) ↑ |") != std::string::npos);
  const auto j = nlohmann::json::parse(read_file(t / "probe.json"));
  REQUIRE(j["results"].size() == 6u);
  CHECK(j["classes"] == std::vector<std::string>{"BeigeCotton", "BrownCotton", "Canvas"});
  CHECK(j["trials"]["test"] == 6);
  for (const auto& f : j["trials"]["test_files"]) CHECK(f.get<std::string>().find("mmps_2.csv") != std::string::npos);
  const std::vector<std::string> names{"constant (train mean / majority)", "ridge on raw windows",
                                       "random encoder (frozen), linear", "random encoder (frozen), probe (",
                                       "target encoder (frozen), linear", "target encoder (frozen), probe ("};
  for (std::size_t r = 0; r < names.size(); ++r) {
    CHECK(j["results"][r]["name"].get<std::string>().starts_with(names[r]));
    CHECK(j["results"][r]["mean"].contains("top1"));
    CHECK(j["results"][r]["mean"].contains("trial_top1"));
  }
  // The probe's pooling and rate were chosen on validation among both poolings and the grid: the
  // lowest validation loss tried, and the row's name and JSON say which.
  for (int r : {3, 5}) {
    const auto& tried = j["results"][r]["tried"];
    REQUIRE(tried.size() == 4u);
    const double lr = j["results"][r]["lr"];
    const std::string pooling = j["results"][r]["pooling"];
    CHECK((lr == 1e-3 || lr == 3e-3));
    CHECK(j["results"][r]["name"].get<std::string>().ends_with(", probe (" + pooling + ")"));
    double best = 1e300;
    std::string best_pooling;
    for (const auto& e : tried)
      if (e["validation_loss"].is_number() && e["validation_loss"].get<double>() < best)
        best = e["validation_loss"], best_pooling = e["pooling"];
    CHECK(best_pooling == pooling);
    CHECK(std::set<std::string>{tried[0]["pooling"], tried[2]["pooling"]} == std::set<std::string>{"attentive", "taxel"});
  }
  // Attentive against linear on the same embeddings: within 2 points, or the row says so.
  for (int r : {3, 5}) {
    const double gap = j["results"][r - 1]["mean"]["top1"].get<double>() - j["results"][r]["mean"]["top1"].get<double>();
    const std::string flag = j["results"][r].value("note", "");
    CAPTURE(gap);
    CHECK((gap <= 0.02 || flag.find("less than the linear read-out per window") != std::string::npos));
  }

  // Predictions: every held-out window lies inside its trial, each trial appears once per row at
  // trial level, and no held-out window comes from a training trial.
  std::map<std::string, int> frames_of;
  for (const auto& e : fs::directory_iterator(set))
    if (e.path().extension() == ".csv" && e.path().filename().string().find("mmps_") != std::string::npos) {
      std::ifstream f(e.path());
      std::string line;
      int n = -1;  // the header
      while (std::getline(f, line)) n += !line.empty();
      frames_of[e.path().filename().string()] = n;
    }
  std::ifstream pred(t / "pred.csv");
  std::string line;
  std::getline(pred, line);
  CHECK(line == "row,level,trial,window,first_frame,frames,label,prediction");
  std::map<std::string, int> trial_rows;
  int windows = 0;
  while (std::getline(pred, line)) {
    const auto f = fields(line);
    REQUIRE(f.size() == 8u);
    CHECK(f[2].find("mmps_2.csv") != std::string::npos);
    REQUIRE(frames_of.count(f[2]) == 1);
    if (f[1] == "window") {
      ++windows;
      CHECK(std::stoi(f[4]) + std::stoi(f[5]) <= frames_of[f[2]]);
    } else {
      CHECK(f[1] == "trial");
      CHECK(std::stoi(f[5]) == frames_of[f[2]]);
      ++trial_rows[f[0]];
    }
    CHECK(f[6] == f[2].substr(0, f[2].find('_')));  // the label is the trial's
  }
  CHECK(windows == 6 * j["test_windows"].get<int>());
  for (const auto& [row, n] : trial_rows) CHECK(n == 6);

  // tjepa run: the saved head on a held-out trial, replayed from its file and streamed by the
  // xServer test peer, predicts what probe predicted on the same windows.
  {
    const std::string trial = "Canvas_F120_V150mmps_2.csv";
    std::map<int, std::string> probe_says;  // the window's last frame → the class predicted
    std::ifstream again(t / "pred.csv");
    std::getline(again, line);
    while (std::getline(again, line)) {
      const auto f = fields(line);
      if (f[0].starts_with("target encoder (frozen), probe") && f[1] == "window" && f[2] == trial)
        probe_says[std::stoi(f[4]) + std::stoi(f[5]) - 1] = f[7];
    }
    REQUIRE(probe_says.size() >= 10u);
    auto run_says = [&](const fs::path& csv) {
      std::map<int, std::string> says;
      std::ifstream in(csv);
      std::string row;
      std::getline(in, row);
      CHECK(row == "window,frame,time,gap,prediction,p_BeigeCotton,p_BrownCotton,p_Canvas");
      while (std::getline(in, row)) {
        const auto f = fields(row);
        REQUIRE(f.size() == 8u);
        says[std::stoi(f[1])] = f[4];
      }
      return says;
    };
    RunOptions ro;
    ro.model = pb.checkpoint;
    ro.head = pb.save;
    ro.source = "replay:" + (set / trial).string();
    ro.format = fabric_format();
    ro.rate = 0;
    ro.out = (t / "run_replay.csv").string();
    std::ostringstream rout;
    REQUIRE(run_live(ro, rout) == 0);
    CHECK(run_says(ro.out) == probe_says);
    CHECK(rout.str().find("problems: none") != std::string::npos);
    CHECK(rout.str().find("allocations after the first window: pipeline 0,") != std::string::npos);
    CHECK(rout.str().find("latency of a window") != std::string::npos);

    const Recording rec = read_recording(set / trial, fabric_format());
    std::vector<std::string> messages{tjepa_test::xserver_welcome()};
    for (int f = 0; f < rec.frames(); ++f)
      messages.push_back(tjepa_test::xserver_frame(0.01 * f, std::vector<float>(rec.frame(f), rec.frame(f) + rec.taxels()), 1));
    tjepa_test::XServerPeer peer({messages});
    RunOptions xo = ro;
    xo.source = "ws://127.0.0.1:" + std::to_string(peer.port());
    xo.format = DataFormat{};
    xo.reconnects = 0;
    xo.out = (t / "run_xserver.csv").string();
    std::ostringstream xout;
    REQUIRE(run_live(xo, xout) == 0);
    CHECK(run_says(xo.out) == probe_says);
    CHECK(xout.str().find("problems: connection dropped 1;") != std::string::npos);  // the peer's close at the end
    xo.out.clear();
    xo.format.columns = "3:19";
    CHECK_THROWS_WITH_AS(run_live(xo, xout), doctest::Contains("--columns and --lines-per-frame are for replay:FILE"),
                         ConfigError);
    RunOptions no_head = ro;
    no_head.head.clear();
    CHECK_THROWS_WITH_AS(run_live(no_head, xout), doctest::Contains("--out writes the head's predictions: give --head"),
                         ConfigError);
  }

  // embed over the table's trials: one row per window, and a CSV saying which is which.
  EmbedOptions eo;
  eo.checkpoint = pb.checkpoint;
  eo.trials.table = pb.trials.table;
  eo.format = fabric_format();
  eo.out = (t / "emb.npy").string();
  eo.quiet = true;
  std::ostringstream eout;
  REQUIRE(run_embed(eo, eout) == 0);
  const NpyArray emb = read_npy(eo.out);
  std::ifstream wcsv(t / "emb.windows.csv");
  std::getline(wcsv, line);
  CHECK(line == "window,file,first_frame,frames,label,split");
  std::int64_t rows = 0;
  while (std::getline(wcsv, line)) {
    const auto f = fields(line);
    REQUIRE(f.size() == 6u);
    CHECK(std::stoll(f[0]) == rows++);
    const std::string file = fs::path(f[1]).filename().string();
    CHECK(std::stoi(f[2]) + std::stoi(f[3]) <= frames_of[file]);
    CHECK(f[4] == file.substr(0, file.find('_')));
  }
  CHECK(rows == emb.shape[0]);
  eo.data = {"x.csv"};
  CHECK_THROWS_WITH_AS(run_embed(eo, eout), doctest::Contains("--data FILE... or --trials TABLE"), ConfigError);

  // Flags that act or are refused by name.
  ProbeOptions sub = pb;
  sub.force = true;
  sub.max_windows = 20;
  std::ostringstream sout;
  REQUIRE(run_probe(sub, sout) == 0);
  CHECK(nlohmann::json::parse(read_file(t / "probe.json"))["train_windows"] == 20);
  ProbeOptions no_task = sub;
  no_task.task.clear();
  CHECK_THROWS_WITH_AS(run_probe(no_task, sout), doctest::Contains("give --task regression or classification"), ConfigError);
  ProbeOptions both = sub;
  both.data = (set / "BeigeCotton_F120_V150mmps_0.csv").string();
  both.labels = both.data;
  CHECK_THROWS_WITH_AS(run_probe(both, sout), doctest::Contains("--task needs one of: --trials TABLE"), ConfigError);
}

TEST_CASE("trials: the small-skin config (examples/configs/small_skin.json) is a valid run config / the one-taxel-target warning names it") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trials_small_skin");
  const fs::path set = data_dir / "fabricslide";
  PretrainOptions po = trial_run(set, fabric_format(), t / "run", 10);
  po.config = (fs::path(TJEPA_SOURCE_DIR) / "examples" / "configs" / "small_skin.json").string();
  std::ostringstream log;
  REQUIRE(run_pretrain(po, log) == 0);
  CHECK(log.str().find("most of them one token") != std::string::npos);  // 16 taxels: targets of 1-2
  CHECK(log.str().find("--config examples/configs/small_skin.json") != std::string::npos);
  const TrainedModel m = load_trained_model((t / "run" / "checkpoint.safetensors").string());
  CHECK(m.config.model.position_eigenvectors == 8);
  CHECK(m.config.step.normalize_targets);
  CHECK(m.config.model.dim == 16);  // the command line's keys still apply over the file's
}

TEST_CASE("trials: iCub grasps / a seeded split by trial stratified by object / the same split in pretrain and probe") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trials_icub");
  const fs::path set = data_dir / "icub_grasp";
  PretrainOptions po = trial_run(set, icub_format(), t / "run", 5);
  po.test_fraction = 0.34;
  std::ostringstream log;
  REQUIRE(run_pretrain(po, log) == 0);
  CHECK(log.str().find("12 training, 0 validation and 6 test trials of 18 (a seeded split by trial, stratified by label") !=
        std::string::npos);
  CHECK(log.str().find("masks: contexts of ") != std::string::npos);
  CHECK(log.str().find("most of them one token") == std::string::npos);
  // The fingertips as five parts of 12 taxels: per-part targets of 10-18 % are mostly one taxel.
  {
    std::ifstream in(set / "layout.csv");
    std::ofstream parts(t / "parts.csv");
    for (std::string line; std::getline(in, line);) {
      const auto at = line.find(",hand,");
      if (at != std::string::npos) {
        const auto group_end = line.find(',', at + 6);
        line = line.substr(0, at + 1) + line.substr(at + 6, group_end - at - 6) + line.substr(at + 5);
      }
      parts << line << "\n";
    }
  }
  PretrainOptions five = po;
  five.overrides["layout"] = (t / "parts.csv").string();
  five.overrides["steps"] = 0;
  five.out = (t / "five").string();
  std::ostringstream flog;
  REQUIRE(run_pretrain(five, flog) == 0);
  CHECK(flog.str().find("10 targets of 1-2 tokens (mean 1.") != std::string::npos);
  CHECK(flog.str().find("), per part\n") != std::string::npos);
  CHECK(flog.str().find("warning: mask targets of 1-2 tokens (mean 1.") != std::string::npos);
  CHECK(flog.str().find("most of them one token (per-part targets on parts of a few taxels)") != std::string::npos);
  ProbeOptions pb;
  pb.checkpoint = (t / "run" / "checkpoint.safetensors").string();
  pb.task = "classification";
  pb.trials.table = (set / "trials.csv").string();
  pb.test_fraction = 0.34;
  pb.format = icub_format();
  pb.probe.max_epochs = 3;
  pb.lr_grid = {1e-3};
  pb.quiet = true;
  pb.out = (t / "probe.json").string();
  std::ostringstream out;
  REQUIRE(run_probe(pb, out) == 0);
  const auto j = nlohmann::json::parse(read_file(t / "probe.json"));
  // Two grasps of each object held out, the same ones pre-training left out.
  std::map<std::string, int> per_object;
  for (const auto& f : j["trials"]["test_files"]) {
    const std::string s = f;
    ++per_object[s.substr(0, s.rfind('_'))];
    CHECK(log.str().find(s) == std::string::npos);
  }
  CHECK(per_object == std::map<std::string, int>{{"blue_bear", 2}, {"book", 2}, {"lotion", 2}});
  CHECK(j["results"][1]["mean"].contains("trial_top1"));
  // embed writes the same split in its windows CSV (the table has no split column).
  EmbedOptions eo;
  eo.checkpoint = pb.checkpoint;
  eo.trials.table = pb.trials.table;
  eo.trials.test_fraction = 0.34;
  eo.format = icub_format();
  eo.out = (t / "emb.npy").string();
  eo.quiet = true;
  std::ostringstream eout;
  REQUIRE(run_embed(eo, eout) == 0);
  std::set<std::string> test_files, embedded_test;
  for (const auto& f : j["trials"]["test_files"]) test_files.insert(fs::path(std::string(f)).filename().string());
  std::ifstream wcsv(t / "emb.windows.csv");
  std::string line;
  std::getline(wcsv, line);
  int train_rows = 0;
  while (std::getline(wcsv, line)) {
    const auto f = fields(line);
    REQUIRE(f.size() == 6u);
    const std::string file = fs::path(f[1]).filename().string();
    CHECK_MESSAGE((f[5] == (test_files.count(file) ? "test" : "train")), file, " split ", f[5]);
    if (f[5] == "test") embedded_test.insert(file);
    train_rows += f[5] == "train";
  }
  CHECK(train_rows > 0);
  CHECK(embedded_test == test_files);

  // --center-tokens acts: the probe reads other embeddings.
  ProbeOptions centred = pb;
  centred.center_tokens = true;
  centred.force = true;
  centred.out = (t / "centred.json").string();
  REQUIRE(run_probe(centred, out) == 0);
  const auto c = nlohmann::json::parse(read_file(t / "centred.json"));
  CHECK(c["probe"]["center_tokens"] == true);
  CHECK(c["results"][5]["validation_loss"] != j["results"][5]["validation_loss"]);

  // --steps 0 writes the initialization, which the probe reads like any checkpoint.
  PretrainOptions init = po;
  init.overrides["steps"] = 0;
  init.out = (t / "init").string();
  std::ostringstream ilog;
  REQUIRE(run_pretrain(init, ilog) == 0);
  CHECK(ilog.str().find("--steps 0: wrote the initialization (seed 3, no training step)") != std::string::npos);
  const TrainedModel m = load_trained_model(t / "init" / "checkpoint.safetensors");
  CHECK(m.config.seed == 3);
}

TEST_CASE("label checks: [T] and int64 .npy labels / a stray id listed as its own class / a held-out class training never shows") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trials_labels");
  const fs::path set = data_dir / "fabricslide";
  std::ostringstream log;
  REQUIRE(run_pretrain(trial_run(set, fabric_format(), t / "run", 10), log) == 0);
  const Recording a = read_recording(set / "BeigeCotton_F120_V150mmps_0.csv", fabric_format());
  const Recording b = read_recording(set / "Canvas_F120_V150mmps_0.csv", fabric_format());
  auto ids = [](int frames, int first, int stray) {
    std::vector<std::int64_t> v(static_cast<std::size_t>(frames));
    for (int f = 0; f < frames; ++f) v[static_cast<std::size_t>(f)] = (f / 40) % 2 + first;
    if (stray >= 0) v.back() = stray;
    return v;
  };
  // Training labels as NumPy writes np.int64 ids of shape [T].
  {
    const std::vector<std::int64_t> v = ids(a.frames(), 0, 1000);
    std::string h = "{'descr': '<i8', 'fortran_order': False, 'shape': (" + std::to_string(v.size()) + ",), }";
    h.append((10 + h.size() + 1 + 63) / 64 * 64 - 10 - h.size() - 1, ' ');
    h.push_back('\n');
    std::ofstream f(t / "a.npy", std::ios::binary);
    f.write("\x93NUMPY\x01\x00", 8);
    const char len[2] = {static_cast<char>(h.size()), 0};
    f.write(len, 2);
    f << h;
    f.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * 8));
  }
  std::ofstream(t / "b.csv") << [&] {
    std::string s = "id\n";
    for (auto v : ids(b.frames(), 1, -1)) s += std::to_string(v) + "\n";
    return s;
  }();
  ProbeOptions pb;
  pb.checkpoint = (t / "run" / "checkpoint.safetensors").string();
  pb.task = "classification";
  pb.train_data = {(set / "BeigeCotton_F120_V150mmps_0.csv").string()};
  pb.test_data = {(set / "Canvas_F120_V150mmps_0.csv").string()};
  pb.train_labels = {(t / "a.npy").string()};
  pb.test_labels = {(t / "b.csv").string()};
  pb.format = fabric_format();
  pb.probe.max_epochs = 2;
  pb.lr_grid = {1e-3};
  pb.quiet = true;
  std::ostringstream out;
  REQUIRE(run_probe(pb, out) == 0);
  // The classes are the ids present: 0, 1, 2 and the stray 1000, not 1001 classes.
  CHECK(out.str().find("classes (training / held-out windows): 0 ") != std::string::npos);
  CHECK(out.str().find(", 1000 ") != std::string::npos);
  CHECK(out.str().find("4 classes") != std::string::npos);
  CHECK(out.str().find("warning: class 2 has ") != std::string::npos);
  CHECK(out.str().find("no training window: no head can predict it, they count as wrong") != std::string::npos);
  // A two-column label file is named as the one at fault; a [T, N, 2] recording names --axes.
  {
    std::ofstream f(t / "two.csv");
    f << "id,other\n";
    for (int i = 0; i < b.frames(); ++i) f << i % 2 << ",0\n";
  }
  pb.test_labels = {(t / "two.csv").string()};
  CHECK_THROWS_WITH_AS(run_probe(pb, out), doctest::Contains("two.csv: 2 label columns"),
                       ShapeError);
  write_npy(t / "r2.npy", Recording(20, 4, 2));
  CHECK_THROWS_WITH_AS(read_recording(t / "r2.npy", DataFormat{}), doctest::Contains("on the command line --axes 2"),
                       ShapeError);
}

}

TEST_SUITE("cli") {

TEST_CASE("collapse_warning fires on a constructed collapse and on the spreads the real runs showed / auto preprocessing ignores how files are split") {
  using namespace tjepa;
  using namespace tjepa::cli;
  auto log = [](std::vector<std::pair<double, double>> within_across) {
    CsvTable t;
    t.header = pretrain_log_columns();
    double step = 0;
    for (const auto& [w, a] : within_across) t.rows.push_back({step += 100, 1, 1e-4, 0.04, 0.996, 1, w, 1000, 1, a});
    return t;
  };
  CHECK(collapse_warning(log({{0.5, 0.45}, {0.5, 0.4}}), "standardize").empty());
  // 0.45 -> 0.066 over windows (the 36-object set): fallen under a quarter, though not under a tenth of 0.5.
  const std::string fell = collapse_warning(log({{0.5, 0.45}, {0.5, 0.2}, {0.5, 0.066}}), "standardize");
  CHECK(fell.find("fell from 0.45 at step 100 to 0.066 at step 300") != std::string::npos);
  CHECK(fell.find("--preprocess baseline") != std::string::npos);
  // 0.013 over windows against 0.7 inside one (iCub): under a tenth.
  const std::string flat = collapse_warning(log({{0.7, 0.013}}), "baseline");
  CHECK(flat.find("hardly differ between windows") != std::string::npos);
  CHECK(flat.find("--preprocess baseline") == std::string::npos);

  // The same FabricSlide frames as one file or as slides give the same preprocessing choice.
  const fs::path set = data_dir / "fabricslide";
  std::vector<Recording> slides;
  AlignedVector<float> all;
  int frames = 0;
  for (const char* f : {"BeigeCotton_F120_V150mmps_0.csv", "Canvas_F120_V-150mmps_1.csv", "BrownCotton_F120_V150mmps_2.csv"}) {
    slides.push_back(read_recording(set / f, fabric_format()));
    all.insert(all.end(), slides.back().values().begin(), slides.back().values().end());
    frames += slides.back().frames();
  }
  const Recording one(frames, 16, 1, std::move(all), "one.csv");
  const PreprocessChoice a = choose_preprocessing("auto", slides);
  const PreprocessChoice b = choose_preprocessing("auto", std::span<const Recording>(&one, 1));
  CHECK(a.mode == b.mode);
  CHECK(a.reason == b.reason);

  // A no-contact mean from a recording that moves like the data is warned about; one at rest is not.
  Recording rest(200, 4, 1), data(400, 4, 1);
  for (int t = 0; t < 200; ++t)
    for (int n = 0; n < 4; ++n) rest.at(t, n, 0) = 100.0f * n + 0.1f * static_cast<float>((t * 7 + n) % 5);
  for (int t = 0; t < 400; ++t)
    for (int n = 0; n < 4; ++n) data.at(t, n, 0) = 100.0f * n + ((t / 20) % 4 == n ? 30.0f : 0.0f);
  CHECK(baseline_contact_warning(rest, std::span<const Recording>(&data, 1)).empty());
  data.set_source("grasp_1.txt");
  CHECK(baseline_contact_warning(data, std::span<const Recording>(&data, 1)).find("taken from grasp_1.txt") !=
        std::string::npos);
}

TEST_CASE("one file of concatenated trials: --trial-column splits by trial / several training recordings / a trial id that comes back is refused") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trials_column");
  const fs::path set = data_dir / "fabricslide";
  std::ostringstream log;
  REQUIRE(run_pretrain(trial_run(set, fabric_format(), t / "run", 10), log) == 0);
  // The 18 slides as one recording, and a label file with each frame's class and trial id.
  const TrialTable table = read_trial_table(set / "trials.csv");
  const TrialClasses classes = trial_classes(table);
  AlignedVector<float> values;
  std::string labels = "class,trial\n";
  std::map<std::string, int> frames_of;  // trial name -> frames
  int frames = 0;
  for (std::size_t i = 0; i < table.size(); ++i) {
    const Recording r = read_recording(table.trials[i].file, fabric_format());
    values.insert(values.end(), r.values().begin(), r.values().end());
    for (int f = 0; f < r.frames(); ++f) labels += std::to_string(classes.of_trial[i]) + "," + std::to_string(100 + i) + "\n";
    frames_of["all.npy trial " + std::to_string(100 + i)] = r.frames();
    frames += r.frames();
  }
  write_npy(t / "all.npy", Recording(frames, 16, 1, std::move(values), "all"));
  std::ofstream(t / "labels.csv") << labels;
  ProbeOptions pb;
  pb.checkpoint = (t / "run" / "checkpoint.safetensors").string();
  pb.task = "classification";
  pb.data = (t / "all.npy").string();
  pb.labels = (t / "labels.csv").string();
  pb.label_columns = "0";
  pb.trial_column = 1;
  pb.test_fraction = 0.34;
  pb.format.axes = 1;
  pb.probe.max_epochs = 2;
  pb.lr_grid = {1e-3};
  pb.quiet = true;
  pb.out = (t / "probe.json").string();
  pb.predictions = (t / "predictions.csv").string();
  std::ostringstream out;
  REQUIRE(run_probe(pb, out) == 0);
  CHECK(out.str().find("by --trial-column 1: 12 training, 0 validation and 6 test trials of 18 (a seeded split by trial, "
                       "stratified by label") != std::string::npos);
  const auto j = nlohmann::json::parse(read_file(t / "probe.json"));
  CHECK(j["trials"]["test"] == 6);
  // Every held-out window lies inside its trial; every row scores the 6 held-out trials.
  std::ifstream p(t / "predictions.csv");
  std::string line;
  std::getline(p, line);
  std::map<std::string, int> trial_rows;
  int windows = 0;
  while (std::getline(p, line)) {
    const auto f = fields(line);
    REQUIRE(f.size() == 8u);
    REQUIRE(frames_of.count(f[2]) == 1);
    if (f[1] == "window") {
      ++windows;
      CHECK(std::stoi(f[4]) + std::stoi(f[5]) <= frames_of[f[2]]);
    } else {
      ++trial_rows[f[0]];
      CHECK(std::stoi(f[5]) == frames_of[f[2]]);
    }
  }
  CHECK(windows == 6 * j["test_windows"].get<int>());
  CHECK(trial_rows.size() == 6u);
  for (const auto& [row, n] : trial_rows) CHECK(n == 6);

  // A trial id that comes back after another trial's frames; the flag's misuses, named.
  std::ofstream(t / "back.csv") << labels << "0,100\n";
  write_npy(t / "back.npy", Recording(frames + 1, 16, 1));
  ProbeOptions back = pb;
  back.data = (t / "back.npy").string(), back.labels = (t / "back.csv").string(), back.force = true;
  CHECK_THROWS_WITH_AS(run_probe(back, out), doctest::Contains("trial id 100 again after other trials (its frames begin at 0)"),
                       DataError);
  ProbeOptions no_columns = pb;
  no_columns.label_columns.clear(), no_columns.force = true;
  CHECK_THROWS_WITH_AS(run_probe(no_columns, out), doctest::Contains("--trial-column 1 needs --label-columns"), ConfigError);
  ProbeOptions with_table = pb;
  with_table.data.clear(), with_table.labels.clear(), with_table.force = true;
  with_table.trials.table = (set / "trials.csv").string();
  CHECK_THROWS_WITH_AS(run_probe(with_table, out), doctest::Contains("--trial-column is for one recording"), ConfigError);

  // Several training recordings, each its own: no window crosses from one to the next.
  const fs::path a = set / "BeigeCotton_F120_V150mmps_0.csv", b = set / "Canvas_F120_V150mmps_0.csv",
                 c = set / "BrownCotton_F120_V150mmps_0.csv";
  auto constant_labels = [&](const fs::path& data, int cls, const fs::path& file) {
    std::ofstream f(file);
    f << "class\n";
    for (int k = 0; k < read_recording(data, fabric_format()).frames(); ++k) f << (cls < 0 ? (k / 40) % 2 : cls) << "\n";
  };
  constant_labels(a, 0, t / "a.csv"), constant_labels(b, 1, t / "b.csv"), constant_labels(c, -1, t / "c.csv");
  ProbeOptions many;
  many.checkpoint = pb.checkpoint, many.task = "classification", many.format = fabric_format();
  many.probe.max_epochs = 2, many.lr_grid = {1e-3}, many.quiet = true, many.out = (t / "many.json").string();
  many.train_data = {a.string(), b.string()}, many.train_labels = {(t / "a.csv").string(), (t / "b.csv").string()};
  many.test_data = {c.string()}, many.test_labels = {(t / "c.csv").string()};
  REQUIRE(run_probe(many, out) == 0);
  const int tau = 10;
  const int expect = (read_recording(a, fabric_format()).frames() - tau) / tau + 1 +
                     (read_recording(b, fabric_format()).frames() - tau) / tau + 1;
  CHECK(nlohmann::json::parse(read_file(t / "many.json"))["train_windows"] == expect);
  many.train_labels.pop_back(), many.force = true;
  CHECK_THROWS_WITH_AS(run_probe(many, out), doctest::Contains("--train-data has 2 file(s) and --train-labels 1"), ConfigError);
}

}
