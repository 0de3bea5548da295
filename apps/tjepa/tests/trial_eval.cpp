// tjepa eval --trials (trial_eval.hpp) on the FabricSlide slice (tests/data/fabricslide, MIT): the
// labelled shares of the training trials, every row of the protocol per seed and share, the
// named Welch contrasts, the same tables from the same command, and the flags of one protocol
// refused with the other.
#include <doctest/doctest.h>

#include "../eval.hpp"

#include "../../../tests/support/files.hpp"

#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {
namespace fs = std::filesystem;
using tjepa_test::read_file;
using tjepa_test::TempDir;

const fs::path eval_data_dir = TJEPA_TEST_DATA_DIR;

// 4 trials of each of 3 classes, 3 windows each; trial t is class t % 3.
tjepa::cli::WindowLabels twelve_trials() {
  tjepa::cli::WindowLabels w;
  w.targets.classes = 3;
  for (int t = 0; t < 12; ++t)
    for (int k = 0; k < 3; ++k) {
      w.window.push_back(t * 3 + k);
      w.trial.push_back(t);
      w.targets.label.push_back(t % 3);
      w.targets.groups.group.push_back(t);
      w.targets.groups.stratum.push_back(t % 3);
    }
  return w;
}

tjepa::cli::EvalOptions parse_eval(std::vector<std::string> args) {
  CLI::App app;
  tjepa::cli::EvalCommand ev;
  add_eval_command(app, ev);
  args.insert(args.begin(), {"tjepa", "eval"});
  std::vector<const char*> argv;
  for (const std::string& a : args) argv.push_back(a.c_str());
  app.parse(static_cast<int>(argv.size()), argv.data());
  return ev.resolve(static_cast<int>(argv.size()), argv.data());
}
// The command of both tests below: the FabricSlide slice, a tiny model and budget, seeds 0 and 1.
std::vector<std::string> slice_eval_args(const std::string& out) {
  const fs::path set = eval_data_dir / "fabricslide";
  return {"--trials", (set / "trials.csv").string(), "--layout", (set / "layout.csv").string(), "--axes", "1",
          "--columns", "3:19", "--tau", "10", "--dim", "16", "--depth", "1", "--heads", "2", "--predictor-depth", "1",
          "--batch", "8", "--steps", "3", "--warmup", "1", "--seeds", "0", "1", "--head-seeds", "1",
          "--label-fractions", "1", "0.5", "--max-windows", "120", "--max-test-windows", "60", "--head-steps", "30",
          "--head-patience-steps", "10", "--end-to-end-steps", "10", "--end-to-end-patience-steps", "5",
          "--byol-image-size", "63", "--quiet", "--out", out};
}
}  // namespace

TEST_SUITE("cli") {

TEST_CASE("label_share: whole trials / at least 2 of each class / seeded / regression keeps at least 4 trials") {
  using namespace tjepa::cli;
  const WindowLabels w = twelve_trials();
  CHECK(label_share(w, 1.0, 7).size() == w.window.size());
  for (std::uint64_t seed : {0u, 1u, 2u, 3u}) {
    const std::vector<std::size_t> rows = label_share(w, 0.1, seed);
    std::map<int, int> windows_of_trial;
    std::map<int, std::set<int>> trials_of_class;
    for (std::size_t r : rows) ++windows_of_trial[w.trial[r]], trials_of_class[w.targets.label[r]].insert(w.trial[r]);
    for (const auto& [trial, n] : windows_of_trial) CHECK(n == 3);  // a trial whole or not at all
    REQUIRE(trials_of_class.size() == 3u);
    for (const auto& [c, ts] : trials_of_class) CHECK(ts.size() == 2u);  // round(0.4) raised to the floor of 2
    CHECK(std::is_sorted(rows.begin(), rows.end()));
    CHECK(label_share(w, 0.1, seed) == rows);
  }
  CHECK(label_share(w, 0.1, 0) != label_share(w, 0.1, 1));
  CHECK(label_share(w, 0.75, 0).size() == 27u);  // 3 of 4 trials per class
  // The share's validation trials: the table's, where the share holds them.
  WindowLabels held = w;
  held.targets.groups.held = {0, 1};
  const WindowLabels s = share_labels(held, label_share(held, 0.1, 0));
  for (std::int64_t g : s.targets.groups.held)
    CHECK(std::find(s.targets.groups.group.begin(), s.targets.groups.group.end(), g) != s.targets.groups.group.end());
  WindowLabels reg = w;
  reg.targets.classes = 0;
  reg.targets.label.clear();
  for (int i = 0; i < 36; ++i) reg.targets.value.push_back(static_cast<float>(i / 3));
  reg.targets.regression = 1;
  CHECK(label_share(reg, 0.1, 0).size() == 12u);  // 4 trials of 3 windows
}

TEST_CASE("tjepa eval --trials: every row per seed and label share / Welch contrasts of Tactile-JEPA") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trial_eval");
  const EvalOptions o = parse_eval(slice_eval_args((t / "a").string()));
  REQUIRE(o.on_trials);
  CHECK(o.trial.pooling == PoolingKind::taxel);
  CHECK(o.trial.seeds == std::vector<std::uint64_t>{0, 1});
  CHECK(o.eval.train.data.tau == 10);
  CHECK(o.eval.train.data.drift_time_constant == TrainConfig{}.data.drift_time_constant);  // tjepa pretrain's defaults
  std::ostringstream log;
  REQUIRE(run_eval(o, log) == 0);
  const auto j = nlohmann::json::parse(read_file(t / "a" / "results.json"));
  REQUIRE(j["tables"].size() == 2u);
  const std::vector<std::string> rows{"constant", "ridge on raw windows", "random init, linear", "random init, frozen",
                                      "end to end", "MAE, linear", "MAE, frozen", "DINO, linear", "DINO, frozen",
                                      "BYOL, frozen", "Tactile-JEPA, linear", "Tactile-JEPA, frozen"};
  for (const auto& table : j["tables"]) {
    REQUIRE(table["rows"].size() == rows.size());
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const auto& row = table["rows"][r];
      CHECK(row["name"] == rows[r]);
      REQUIRE(row["seeds"]["top1"].size() == 2u);
      REQUIRE(row["seeds"]["trial_top1"].size() == 2u);
      for (const char* m : {"top1", "trial_top1"})
        for (const auto& v : row["seeds"][m]) CHECK((v.get<double>() >= 0 && v.get<double>() <= 1));
    }
    // Tactile-JEPA against random init (probe and linear) and against end to end, per metric.
    REQUIRE(table["contrasts"].size() == 6u);
    for (const auto& c : table["contrasts"]) {
      CHECK(c["row"].get<std::string>().starts_with("Tactile-JEPA"));
      CHECK(c["tested"] == true);
      CHECK((c["p"].get<double>() >= 0 && c["p"].get<double>() <= 1));
    }
  }
  // The shares: all 12 training slides, then 2 of each fabric's 4.
  CHECK(j["tables"][0]["title"].get<std::string>().starts_with(
      "Labelled training trials: 100 % (12 of 12 trials, 120 windows); 3 classes; 60 held-out windows of 6 trials"));
  CHECK(j["tables"][1]["title"].get<std::string>().starts_with("Labelled training trials: 50 % (6 of 12 trials,"));
  CHECK(j["trials"]["test"] == 6);
  CHECK(j["windows"]["pretrain"] == 168);  // 14 windows of each training slide (tau 10, one every 10 frames)
  CHECK(j["windows"]["heads"] == 120);
  CHECK(j["windows"]["test"] == 60);
  // The three fabrics are apart in the raw readings of one window (a real-data check of the path).
  for (const auto& v : j["tables"][0]["rows"][1]["seeds"]["top1"]) CHECK(v.get<double>() >= 0.9);
  CHECK(j["pretraining"].size() == 8u);  // MAE, DINO, BYOL, Tactile-JEPA at 2 seeds
  for (const auto& p : j["pretraining"])
    if (p["row"] == "DINO") {  // whether its student ended uniform, against ln P of its prototypes
      CHECK(p["collapsed"].is_boolean());
      CHECK(p["uniform_dino"].get<double>() == doctest::Approx(std::log(16.0 * 16)));  // 16d prototypes at d 16
      CHECK(p["last_dino"].get<double>() > 0);
    }
  // Every head's training: 2 seeds x 2 shares x (random, MAE, DINO, BYOL, Tactile-JEPA frozen and end to end).
  REQUIRE(j["head_training"].size() == 24u);
  for (const auto& h : j["head_training"]) {
    CHECK(h["epochs"].get<int>() >= 1);
    CHECK((h["best_epoch"].get<int>() >= 0 && h["best_epoch"].get<int>() < h["epochs"].get<int>()));
    CHECK(h["trials"].get<int>() >= 6);
    CHECK(h["folds"] == 3);  // 12 and 6 labelled slides, fewer than 200: 3-fold cross-validation
  }
  const std::string md = read_file(t / "a" / "results.md");
  CHECK(md.find("- top-1: Tactile-JEPA, frozen against random init, frozen; one-sided Welch t = ") != std::string::npos);
}

TEST_CASE("tjepa eval --trials: the same command gives the same tables") {
  using namespace tjepa;
  using namespace tjepa::cli;
  TempDir t("trial_eval_again");
  nlohmann::json tables[2];
  for (int run = 0; run < 2; ++run) {
    std::vector<std::string> a = slice_eval_args((t / std::to_string(run)).string());
    for (const char* skip : {"--no-mae", "--no-dino", "--no-byol"}) a.push_back(skip);
    std::ostringstream log;
    REQUIRE(run_eval(parse_eval(a), log) == 0);
    tables[run] = nlohmann::json::parse(read_file(t / std::to_string(run) / "results.json"))["tables"];
  }
  REQUIRE(tables[0].size() == 2u);
  CHECK(tables[0][0]["rows"].size() == 7u);
  CHECK(tables[1] == tables[0]);
}

TEST_CASE("tjepa eval: the flags of one protocol are refused with the other") {
  using namespace tjepa;
  using namespace tjepa::cli;
  const std::string table = (eval_data_dir / "fabricslide" / "trials.csv").string();
  CHECK_THROWS_WITH_AS(parse_eval({"--trials", table, "--data-seed", "3"}),
                       doctest::Contains("--data-seed is for the simulated grasping hand's protocol, not --trials"),
                       ConfigError);
  CHECK_THROWS_WITH_AS(parse_eval({"--label-fractions", "1", "0.1"}),
                       doctest::Contains("--label-fractions is for the protocol on labelled trials: give --trials TABLE"),
                       ConfigError);
  CHECK_THROWS_WITH_AS(parse_eval({"--layout", "grid"}), doctest::Contains("the layout override is for --trials"),
                       ConfigError);
  CHECK_THROWS_WITH_AS(parse_eval({"--seed", "2"}), doctest::Contains("--seed does not apply"), ConfigError);
  // The shared flags reach the trial protocol.
  const EvalOptions o = parse_eval({"--trials", table, "--no-mae", "--no-byol", "--probe-pooling", "attentive",
                                    "--head-seeds", "2", "--head-stop", "loss"});
  CHECK_FALSE(o.trial.mae);
  CHECK_FALSE(o.trial.byol);
  CHECK(o.trial.dino);
  CHECK(o.trial.pooling == PoolingKind::attentive);
  CHECK(o.trial.head_seeds == 2);
  CHECK_FALSE(o.trial.head.stop_on_error);
  CHECK(parse_eval({"--trials", table}).trial.head.stop_on_error);  // the default: the validation error
  CHECK_THROWS(parse_eval({"--trials", table, "--head-stop", "accuracy"}));
  CHECK_THROWS_WITH_AS(parse_eval({"--trials", table, "--stop-on-error"}),
                       doctest::Contains("--stop-on-error is for the simulated grasping hand's protocol"), ConfigError);
  CHECK(parse_eval({"--trials", table}).trial.head_folds == 3);
  CHECK(parse_eval({"--trials", table, "--head-folds", "1", "--head-folds-below", "50"}).trial.head_folds == 1);
  CHECK(parse_eval({"--trials", table, "--head-folds-below", "50"}).trial.head_folds_below == 50);
  CHECK_THROWS(parse_eval({"--trials", table, "--head-folds", "0"}));
  CHECK_THROWS_WITH_AS(parse_eval({"--head-folds", "2"}), doctest::Contains("--head-folds is for the protocol on labelled trials"),
                       ConfigError);
}
}
