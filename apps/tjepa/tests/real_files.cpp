// The `tjepa` command on files shaped like real sensors' (a magnetometer skin of 10 taxels in a text
// file with a header and motor columns, Xela counts, NaN and Inf at known places, a recording in
// XELA's xServer order) and the traps a first real run falls into.
#include <doctest/doctest.h>

#include "../probe.hpp"
#include "../embed.hpp"
#include "../layout.hpp"
#include "../pretrain.hpp"
#include "../../../tests/support/files.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using tjepa_test::read_file;
using tjepa_test::TempDir;

// Two AnySkin-like boards of 5 magnetometers (a plus of 7 mm arms), 30 mm apart.
void write_board_layout(const fs::path& p) {
  std::ofstream f(p);
  f << "id,x,y,part,group\n";
  const double arm[5][2] = {{0, 0}, {-7, 0}, {7, 0}, {0, 7}, {0, -7}};
  for (int b = 0; b < 2; ++b)
    for (int k = 0; k < 5; ++k) f << b * 5 + k << ',' << arm[k][0] + 30 * b << ',' << arm[k][1] << ",hand,board" << b << '\n';
}

// T frames of 10 magnetometers x 3 axes at fixed offsets of a few hundred uT (each its own), a
// press on one magnetometer at a time, then 8 motor columns; whitespace text like np.savetxt.
std::vector<std::vector<double>> magnetometer_rows(int T) {
  std::vector<std::vector<double>> rows;
  for (int t = 0; t < T; ++t) {
    std::vector<double> r;
    for (int i = 0; i < 10; ++i)
      for (int a = 0; a < 3; ++a) {
        const double offset = 150.0 * std::sin(1.7 * i + 2.3 * a + 0.4);
        const double press = (t / 7) % 10 == i ? 25.0 * std::sin(0.3 * t + a) : 0.0;
        r.push_back(offset + press + 0.5 * std::sin(13.1 * t + i + a));
      }
    for (int m = 0; m < 8; ++m) r.push_back(1800 + (37 * t + 91 * m) % 2200);
    rows.push_back(r);
  }
  return rows;
}

void write_rows(const fs::path& p, const std::vector<std::vector<double>>& rows, const std::string& header = "") {
  std::ofstream f(p);
  f.precision(17);
  if (!header.empty()) f << header << '\n';
  for (const auto& r : rows) {
    for (std::size_t k = 0; k < r.size(); ++k) f << (k ? " " : "") << r[k];
    f << '\n';
  }
}

nlohmann::json small_model() {
  return {{"dim", 8}, {"depth", 1}, {"heads", 2}, {"predictor_depth", 1}, {"batch", 4}, {"seed", 5}};
}

// A small pre-training run on the board layout (write_board_layout into dir/anyskin.csv) of the
// recording dir/data into dir/run; warmup < 0 leaves the default warm-up.
tjepa::cli::PretrainOptions board_run(const fs::path& dir, const std::string& data, int steps, int warmup) {
  tjepa::cli::PretrainOptions po;
  po.overrides = small_model();
  po.overrides["layout"] = (dir / "anyskin.csv").string();
  po.overrides["steps"] = steps;
  if (warmup >= 0) po.overrides["warmup_steps"] = warmup;
  po.data = {(dir / data).string()};
  po.out = (dir / "run").string();
  po.quiet = true;
  return po;
}

}  // namespace

TEST_SUITE("cli") {

TEST_CASE("a 10-taxel magnetometer skin pre-trains with default masks from a text file with a header and motor columns") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  write_board_layout(t / "anyskin.csv");
  std::string header;
  for (int i = 0; i < 10; ++i) header += "m" + std::to_string(i) + "x m" + std::to_string(i) + "y m" + std::to_string(i) + "z ";
  for (int m = 0; m < 8; ++m) header += "motor" + std::to_string(m) + (m < 7 ? " " : "");
  write_rows(t / "session.txt", magnetometer_rows(300), header);

  PretrainOptions po = board_run(t.path, "session.txt", 6, -1);  // fewer steps than the default warm-up: clamped
  po.format.columns = "0:30";
  std::ostringstream out;
  REQUIRE(run_pretrain(po, out) == 0);
  const std::string text = out.str();
  CHECK(text.find("note: 6 steps are fewer than the default warm-up of 60; warming up for 0 steps") != std::string::npos);
  CHECK(text.find("preprocessing: baseline (the taxels' offsets vary") != std::string::npos);
  CHECK(text.find("10 taxels, tau 10") != std::string::npos);
  const TrainedModel m = load_trained_model(t / "run" / "checkpoint.safetensors");
  CHECK(m.model->num_tokens() == 10);
  CHECK(m.config.masks.min_context_tokens == -1);

  // Without --columns the motor columns are refused, with the way out named.
  po.format.columns.clear();
  po.force = true;
  CHECK_THROWS_WITH_AS(run_pretrain(po, out), doctest::Contains("38 columns, expected a multiple of axes = 3 (other columns too"),
                       FileError);
  // `layout --draw masks` works on the small skin.
  LayoutOptions lo;
  lo.layout = (t / "anyskin.csv").string();
  lo.draw = "masks";
  lo.json = true;
  std::ostringstream lj;
  REQUIRE(run_layout(lo, lj) == 0);
  const auto j = nlohmann::json::parse(lj.str());
  CHECK(j["warnings"].empty());
  CHECK(j["taxels"] == 10);
  CHECK(j["components"] == 1);
  CHECK(j["masks"]["context"].get<int>() >= 2);
}

TEST_CASE("preprocessing: xela refuses readings that are not Xela counts / auto says what it picked") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  write_rows(t / "mag.txt", magnetometer_rows(120));
  DataFormat f;
  f.columns = "0:30";
  const Recording mag = read_recording(t / "mag.txt", f);
  CHECK_THROWS_WITH_AS(fit_preprocessor("xela", nullptr, std::span<const Recording>(&mag, 1)),
                       doctest::Contains("expects Xela counts in [20000, 60000], but 0 % of the readings"), DataError);
  CHECK_THROWS_WITH_AS(choose_preprocessing("magnetic", std::span<const Recording>(&mag, 1)),
                       doctest::Contains("now called 'xela'"), ConfigError);
  CHECK(choose_preprocessing("auto", std::span<const Recording>(&mag, 1)).mode == "baseline");
  // Xela counts: auto picks xela.
  Recording xela(50, 4, 3);
  for (int tt = 0; tt < 50; ++tt)
    for (int i = 0; i < 4; ++i)
      for (int a = 0; a < 3; ++a) xela.at(tt, i, a) = static_cast<float>(30000 + 500 * i + 40 * std::sin(tt + a));
  CHECK(choose_preprocessing("auto", std::span<const Recording>(&xela, 1)).mode == "xela");
  // One shared offset: standardize.
  Recording shared(50, 4, 3);
  for (int tt = 0; tt < 50; ++tt)
    for (int i = 0; i < 4; ++i)
      for (int a = 0; a < 3; ++a) shared.at(tt, i, a) = static_cast<float>(3 + std::sin(0.7 * tt + 1.3 * i + a));
  CHECK(choose_preprocessing("auto", std::span<const Recording>(&shared, 1)).mode == "standardize");
  // baseline: each taxel's own offset removed (no baseline recording: the training data's mean).
  const Preprocessor p = fit_preprocessor("baseline", nullptr, std::span<const Recording>(&mag, 1));
  CHECK(p.baseline().size() == 30u);
  CHECK(p.baseline()[0] == doctest::Approx(150.0 * std::sin(0.4)).epsilon(0.05));
}

TEST_CASE("non-finite readings: an error at the file's line before any statistic / hold and zero on request") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  {
    std::ofstream f(t / "gaps.csv");
    f << "time,a0,a1,a2,b0,b1,b2\n"       // line 1: a header, detected
      << "0.00,1,2,3,4,5,6\n"
      << "0.01,1.5,2.5,3.5,4.5,5.5,6.5\n"
      << "0.02,2,nan,4,5,6,7\n"           // line 4: frame 2, taxel 0, axis 1
      << "0.03,2,3,4,inf,6,7\n";          // line 5: frame 3, taxel 1, axis 0
  }
  DataFormat f;
  f.columns = "1:7";
  CHECK_THROWS_WITH_AS(read_recording(t / "gaps.csv", f), doctest::Contains("gaps.csv:4: column 3: value nan (frame 2, taxel 0, axis 1)"),
                       DataError);
  f.non_finite = "hold";
  const Recording held = read_recording(t / "gaps.csv", f);
  CHECK(held.frames() == 4);
  CHECK(held(2, 0, 1) == 2.5f);
  CHECK(held(3, 1, 0) == 5.0f);
  f.non_finite = "interpolate";
  const Recording between = read_recording(t / "gaps.csv", f);
  CHECK(between(2, 0, 1) == 2.75f);  // 2.5 and 3 around it
  CHECK(between(3, 1, 0) == 5.0f);   // the last frame: the nearest finite reading
  f.non_finite = "zero";
  const Recording zeroed = read_recording(t / "gaps.csv", f);
  CHECK(zeroed(2, 0, 1) == 0.0f);
  CHECK(zeroed(3, 1, 0) == 0.0f);
  // drop: the readings stay, the windows that hold one are left out (and only those).
  f.non_finite = "drop";
  const Recording kept = read_recording(t / "gaps.csv", f);
  CHECK(std::isnan(kept(2, 0, 1)));
  CHECK(std::isinf(kept(3, 1, 0)));
  const WindowSource every(kept, WindowSpec{2, 1, true});
  CHECK(every.size() == 1);  // frames 0-1; 1-2 and 2-3 hold a NaN/Inf
  CHECK(every.dropped() == 2);
  CHECK(every.start_of(0) == 0);
  const WindowSource strict(kept, WindowSpec{2, 1});
  WindowBatch wb;
  const std::int64_t second[1] = {1};
  CHECK_THROWS_WITH_AS(strict.gather(second, wb), doctest::Contains("at frame 2, taxel 0, axis 1"), DataError);
  CHECK_THROWS_WITH_AS(WindowSource(kept.frames_range(2, 4), WindowSpec{2, 1, true}),
                       doctest::Contains("1 windows left out for NaN/Inf readings"), DataError);
  CHECK(window_spec(10, f).skip_non_finite);
  EmbedOptions eo;
  eo.checkpoint = eo.out = "unused";
  eo.data = {"unused"};
  eo.format = f;
  CHECK_THROWS_WITH_AS(run_embed(eo, std::cout), doctest::Contains("--non-finite drop would shift them"), ConfigError);
  f.non_finite = "skip";
  CHECK_THROWS_WITH_AS(read_recording(t / "gaps.csv", f), doctest::Contains("expected error, hold, interpolate, zero or drop"), ConfigError);
  // A .npy with an Inf: named by frame, taxel and axis as the file holds it.
  Recording r(5, 2, 3, 1.0f);
  r.at(3, 1, 2) = std::numeric_limits<float>::infinity();
  write_npy(t / "gaps.npy", r);
  CHECK_THROWS_WITH_AS(read_recording(t / "gaps.npy", DataFormat{}),
                       doctest::Contains("at frame 3, taxel 1, axis 2"), DataError);
  CHECK_THROWS_WITH_AS(parse_column_ranges("0:30,x"), doctest::Contains("'x' is not a column range"), ConfigError);
  CHECK(parse_column_ranges("0:2,5,8:10") == std::vector<int>{0, 1, 5, 8, 9});
}

TEST_CASE("--order xserver: a recording in XELA's order reaches the taxels it measured / --export writes the order") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  const Skin plain = load_skin(SkinSpec{});
  SkinSpec spec;
  spec.order = "xserver";
  const Skin ordered = load_skin(spec);
  const std::vector<int> point_id = layouts::allegro::xserver_columns();
  CHECK(ordered.layout.column == point_id);
  // Values in xServer order: point p's reading is p.
  Recording xs(1, 368, 3);
  for (int p = 0; p < 368; ++p)
    for (int a = 0; a < 3; ++a) xs.at(0, p, a) = static_cast<float>(p);
  const Recording in_order = in_layout_order(xs, ordered, "xserver.npy");
  for (int j = 0; j < 368; ++j) CHECK(in_order(0, j, 0) == static_cast<float>(point_id[static_cast<std::size_t>(j)]));
  CHECK(in_layout_order(xs, plain, "x")(0, 5, 0) == 5.0f);
  spec.layout = "grid";
  CHECK_THROWS_WITH_AS(load_skin(spec), doctest::Contains("is the Allegro hand's"), ConfigError);

  // layout --export: the hand, its order and its graph, read back as a CSV layout.
  LayoutOptions lo;
  lo.order = "xserver";
  lo.export_csv = (t / "allegro.csv").string();
  std::ostringstream out;
  REQUIRE(run_layout(lo, out) == 0);
  CHECK(out.str().find("--edges " + (t / "allegro.edges.csv").string()) != std::string::npos);
  SkinSpec back;
  back.layout = (t / "allegro.csv").string();
  back.edges = (t / "allegro.edges.csv").string();
  const Skin copy = load_skin(back);
  CHECK(copy.layout.column == point_id);
  CHECK(copy.graph.edges() == ordered.graph.edges());
  CHECK(copy.layout.group_names == ordered.layout.group_names);
  CHECK_THROWS_AS(run_layout(lo, out), FileError);  // exists: --force
  // Without the edges file, the graph inferred from the coordinates has the same pads and one piece.
  back.edges.clear();
  std::ostringstream warnings;
  const Skin inferred = load_skin(back, &warnings);
  CHECK(warnings.str().empty());
  CHECK(inferred.graph.num_components() == 1);
}

TEST_CASE("traps: a baseline of the wrong size is named / a resumed run continues its own folder and log") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  write_board_layout(t / "anyskin.csv");
  {
    auto rows = magnetometer_rows(200);
    for (auto& r : rows) r.resize(30);  // the magnetometers only
    write_rows(t / "session.txt", rows);
    rows.resize(20);
    for (auto& r : rows) r.resize(27);  // 9 magnetometers
    write_rows(t / "rest.txt", rows);
  }
  PretrainOptions po = board_run(t.path, "session.txt", 4, 1);
  po.baseline = (t / "rest.txt").string();
  std::ostringstream out;
  CHECK_THROWS_WITH_AS(run_pretrain(po, out), doctest::Contains("rest.txt: 9 taxels, the layout has 10"), ShapeError);
  CHECK_FALSE(std::filesystem::exists(t / "run"));

  po.baseline.clear();
  po.stop_after = 2;
  REQUIRE(run_pretrain(po, out) == 0);
  const std::string first = read_file(t / "run" / "log.csv");
  // Resume into the same folder: no --force, and the log goes on from step 2.
  PretrainOptions again = po;
  again.overrides = nlohmann::json::object();
  again.resume = (t / "run" / "checkpoint.safetensors").string();
  again.out.clear();
  again.stop_after = -1;
  REQUIRE(run_pretrain(again, out) == 0);
  const std::string log = read_file(t / "run" / "log.csv");
  CHECK(log.starts_with(first));
  CHECK(std::count(log.begin(), log.end(), '\n') == 1 + 4);
  CHECK(load_trained_model(t / "run" / "checkpoint.safetensors").step == 4);
}

}

TEST_SUITE("cli") {

TEST_CASE("docs/formats.md lists every run configuration key with its default") {
  // TJEPA_UPDATE_DOCS=1 rewrites the table between the markers; otherwise it must match.
  const fs::path doc = fs::path(TJEPA_SOURCE_DIR) / "docs" / "formats.md";
  const std::string text = read_file(doc);
  const std::string begin = "<!-- config keys: TJEPA_UPDATE_DOCS=1 regenerates this table -->\n";
  const std::string end = "<!-- end of config keys -->";
  const auto b = text.find(begin), e = text.find(end);
  REQUIRE(b != std::string::npos);
  REQUIRE(e != std::string::npos);
  std::string table = "| key | default |\n|---|---|\n";
  const tjepa::TrainConfig defaults;
  tjepa::TrainConfig::for_each_field(defaults, [&](const char* key, const auto& v) {
    table += std::string("| `") + key + "` | `" + tjepa::json_value(v).dump() + "` |\n";
  });
  const std::string want = text.substr(0, b + begin.size()) + table + text.substr(e);
  if (std::getenv("TJEPA_UPDATE_DOCS")) std::ofstream(doc, std::ios::binary) << want;
  CHECK(read_file(doc) == want);
}

}

TEST_SUITE("cli") {

TEST_CASE("probe --task: the user's own labels / constant / ridge / random and checkpoint rows / flags") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("real_files");
  write_board_layout(t / "anyskin.csv");
  auto rows = magnetometer_rows(400);
  for (auto& r : rows) r.resize(30);
  write_rows(t / "train.txt", std::vector<std::vector<double>>(rows.begin(), rows.begin() + 300));
  write_rows(t / "test.txt", std::vector<std::vector<double>>(rows.begin() + 300, rows.end()));
  // Labels per frame: a time column, then the press on magnetometer 0 (x axis) and on 5 (y axis).
  auto labels = [&](int from, int to, const fs::path& p, bool one_class) {
    std::ofstream f(p);
    f << "time,press0,press5,board\n";
    for (int i = from; i < to; ++i) {
      const auto& r = rows[static_cast<std::size_t>(i)];
      const double p0 = r[0] - 150.0 * std::sin(0.4), p5 = r[16] - 150.0 * std::sin(1.7 * 5 + 2.3 + 0.4);
      const int pressed = (i / 7) % 10;
      f << 0.01 * i << ',' << p0 << ',' << p5 << ',' << (one_class ? 0 : pressed / 5) << '\n';
    }
  };
  labels(0, 300, t / "train_labels.csv", false);
  labels(300, 400, t / "test_labels.csv", false);
  labels(0, 300, t / "one_class.csv", true);
  const PretrainOptions po = board_run(t.path, "train.txt", 3, 1);
  std::ostringstream log;
  REQUIRE(run_pretrain(po, log) == 0);

  ProbeOptions pb;
  pb.checkpoint = (t / "run" / "checkpoint.safetensors").string();
  pb.train_data = {(t / "train.txt").string()};
  pb.test_data = {(t / "test.txt").string()};
  pb.train_labels = {(t / "train_labels.csv").string()};
  pb.test_labels = {(t / "test_labels.csv").string()};
  pb.task = "regression";
  pb.label_columns = "1:3";
  pb.probe.max_epochs = 3;
  pb.quiet = true;
  pb.out = (t / "probe.json").string();
  std::ostringstream out;
  REQUIRE(run_probe(pb, out) == 0);
  CHECK(out.str().find("| constant (train mean / majority) |") != std::string::npos);
  CHECK(out.str().find("| ridge on raw windows |") != std::string::npos);
  const auto j = nlohmann::json::parse(read_file(t / "probe.json"));
  REQUIRE(j["results"].size() == 6u);
  CHECK(j["results"][2]["name"] == "random encoder (frozen), linear");
  CHECK(j["results"][3]["name"].get<std::string>().starts_with("random encoder (frozen), probe ("));
  CHECK(j["results"][4]["name"] == "target encoder (frozen), linear");
  CHECK(j["results"][5]["name"].get<std::string>().starts_with("target encoder (frozen), probe ("));
  CHECK(j["train_windows"] == 30);
  CHECK(j["test_windows"] == 10);
  for (const auto& r : j["results"])
    for (const char* k : {"rmse_0", "rmse_1", "mean_rmse"}) CHECK(std::isfinite(r["mean"][k].get<double>()));
  for (int r : {3, 5}) CHECK(j["results"][r].contains("validation_loss"));
  for (int r : {2, 4}) CHECK(j["results"][r].contains("lambda"));

  // Repeats: each head row is the mean over seeds, with its standard deviation; the contact filter
  // (off by default for user labels) keeps the windows in which a taxel's reading stands out.
  {
    ProbeOptions rep = pb;
    rep.repeats = 2;
    rep.force = true;
    rep.min_contact = 3;
    rep.contact_threshold = 2.0;
    std::ostringstream rout;
    REQUIRE(run_probe(rep, rout) == 0);
    CHECK(rout.str().find("contact filter: windows with at least 3 frames") != std::string::npos);
    const auto r = nlohmann::json::parse(read_file(t / "probe.json"));
    CHECK(r["repeats"] == 2);
    CHECK(r["train_windows"].get<int>() <= 30);
    for (int k : {3, 5}) {
      CHECK(std::isfinite(r["results"][k]["sd"]["mean_rmse"].get<double>()));
      CHECK(r["results"][k]["runs"].size() == 2);
    }
    CHECK(rout.str().find(" ± ") != std::string::npos);
    rep.contact_threshold = 1e6;
    CHECK_THROWS_WITH_AS(run_probe(rep, rout), doctest::Contains("lower --min-contact or --contact-threshold"), DataError);
  }

  // Classification by board, and a training split that holds one class: flagged.
  pb.task = "classification";
  pb.label_columns = "3";
  pb.force = true;
  REQUIRE(run_probe(pb, out) == 0);
  const auto c = nlohmann::json::parse(read_file(t / "probe.json"));
  CHECK(c["results"][0]["mean"].contains("top1"));
  CHECK(!c["results"][0].contains("note"));
  pb.train_labels = {(t / "one_class.csv").string()};
  REQUIRE(run_probe(pb, out) == 0);
  const auto one = nlohmann::json::parse(read_file(t / "probe.json"));
  for (const auto& r : one["results"]) CHECK(r["note"].get<std::string>().find("the training windows hold one class") != std::string::npos);

  // One session and its labels, split in time: the first 80 % train, the last 20 % are held out.
  {
    std::ofstream all(t / "all_labels.csv");
    all << read_file(t / "train_labels.csv");
    const std::string test_rows = read_file(t / "test_labels.csv");
    all << test_rows.substr(test_rows.find('\n') + 1);
  }
  write_rows(t / "all.txt", rows);
  ProbeOptions session = pb;
  session.train_data.clear(), session.test_data.clear(), session.train_labels.clear(), session.test_labels.clear();
  session.data = (t / "all.txt").string();
  session.labels = (t / "all_labels.csv").string();
  session.task = "regression";
  session.label_columns = "1:3";
  REQUIRE(run_probe(session, out) == 0);
  const auto split = nlohmann::json::parse(read_file(t / "probe.json"));
  CHECK(split["train_windows"] == 32);
  CHECK(split["test_windows"] == 8);
  session.test_fraction = 0.99;
  CHECK_THROWS_WITH_AS(run_probe(session, out), doctest::Contains("leave fewer than two windows"), DataError);
  // Labels that do not fit the recording, and a class id that is not one.
  pb.train_labels = {(t / "test_labels.csv").string()};
  CHECK_THROWS_WITH_AS(run_probe(pb, out), doctest::Contains("test_labels.csv: labels for 100 frames, the recording has 300"),
                       ShapeError);
  pb.train_labels = {(t / "train_labels.csv").string()};
  pb.label_columns = "1";
  CHECK_THROWS_WITH_AS(run_probe(pb, out), doctest::Contains("expected an integer id"), DataError);
  pb.task = "ranking";
  CHECK_THROWS_WITH_AS(run_probe(pb, out), doctest::Contains("expected regression or classification"), ConfigError);
  // The flag of a head against the constant on its validation split.
  CHECK(head_flag(1.2, 1.0).starts_with("no better than the constant"));
  CHECK(head_flag(0.99, 1.0).starts_with("no better than the constant"));  // the uniform guess's margin
  CHECK(head_flag(0.4, 1.0).empty());
  CHECK(head_flag(std::nan(""), 1.0).starts_with("diverged"));
}

}
