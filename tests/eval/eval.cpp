// The paper's evaluation protocol on the simulated grasping hand: the tasks
// (eval/grasp_tasks.hpp), the protocol's score table (grasp_score_table), the whole protocol
// at toy size (eval/grasp_eval.hpp) and its pre-training cache (eval/pretrain_cache.hpp).
#include <doctest/doctest.h>

#include <tjepa/eval.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "../support/files.hpp"

using namespace tjepa;

TEST_SUITE("eval") {

namespace {
struct GraspSplit {
  WindowSource src;
  std::vector<GraspLabel> labels;
};
GraspSplit grasp_split(int frames, std::uint64_t seed) {
  const Skin hand = layouts::allegro_xela();
  SimulatedHand sim(hand.layout, GraspSimConfig{}, seed);
  Preprocessor pre(PreprocessConfig::xela_counts());
  pre.fit_baseline(sim.record_baseline(200));
  GraspRecording r = sim.record(frames);
  pre.fit(r.recording);
  return {WindowSource(std::move(r.recording), WindowSpec{10}, {}, pre), std::move(r.labels)};
}
}  // namespace

TEST_CASE("grasp_tasks: every sample carries the label of its window's last frame") {
  const GraspSplit d = grasp_split(6000, 5);
  GraspTaskConfig c;
  c.sequence_length = 4;
  const GraspTasks t = grasp_tasks(d.src, d.labels, c);
  REQUIRE(std::is_sorted(t.windows.begin(), t.windows.end()));
  REQUIRE(std::adjacent_find(t.windows.begin(), t.windows.end()) == t.windows.end());
  auto last = [&](std::int64_t row) { return d.labels[d.src.start_of(t.windows[row]) + 9]; };
  REQUIRE(t.object.size() > 0);
  CHECK(t.object.classes == num_grasp_objects());
  for (std::size_t i = 0; i < t.object_rows.size(); ++i) {
    const GraspLabel l = last(t.object_rows[i]);
    CHECK(l.object == t.object.label[i]);
    CHECK(l.contact_mask != 0u);
    CHECK(t.object.groups.group[i] == l.episode);  // validation groups: the episode, by object
    CHECK(t.object.groups.stratum[i] == l.episode_object);
  }
  REQUIRE(t.force.size() > 0);
  for (std::size_t i = 0; i < t.force_rows.size(); ++i) {
    const GraspLabel l = last(t.force_rows[i]);
    CHECK(((l.contact_mask >> c.label_pad) & 1u) == 1u);
    for (int a = 0; a < 3; ++a) CHECK(t.force.value[i * 3 + a] == l.force[a]);
    CHECK(t.force.groups.group[i] == l.episode);
  }
  REQUIRE(t.pose.size() > 0);
  std::vector<bool> used(t.windows.size(), false);
  for (std::int64_t r : t.object_rows) used[r] = true;
  for (std::int64_t r : t.force_rows) used[r] = true;
  for (int q = 0; q < t.pose.size(); ++q)
    for (int l = 0; l < 4; ++l) {
      const std::int64_t row = t.pose.window[q * 4 + l];
      used[row] = true;
      const int start = d.src.start_of(t.windows[row]);
      if (l > 0) CHECK(start == d.src.start_of(t.windows[t.pose.window[q * 4 + l - 1]]) + 10);
      for (int f = 0; f < 10; ++f) CHECK(d.labels[start + f].held);
      const GraspLabel g = last(row);
      CHECK(t.pose.groups.group[static_cast<std::size_t>(q)] == g.episode);  // a sequence stays in its episode
      CHECK(t.pose.value[(q * 4 + l) * 3 + 0] == g.x_cm);
      CHECK(t.pose.value[(q * 4 + l) * 3 + 2] == g.theta_deg);
    }
  CHECK(std::all_of(used.begin(), used.end(), [](bool b) { return b; }));  // the table holds only used windows
  // Limits pick evenly spaced samples.
  c.max_object_windows = 7;
  c.max_force_windows = 5;
  c.max_pose_sequences = 3;
  const GraspTasks small = grasp_tasks(d.src, d.labels, c);
  CHECK(small.object.size() == 7);
  CHECK(small.force.size() == 5);
  CHECK(small.pose.size() == 3);
  CHECK_THROWS_AS(grasp_tasks(d.src, std::span(d.labels).first(100), c), ShapeError);
}

TEST_CASE("grasp scores: accuracy and force and pose errors by hand and the constant baseline") {
  GraspTasks te;
  te.object.classes = 3;
  te.object.label = {0, 1, 2, 2};
  te.force.regression = 3;
  te.force.value = {1, 0, 2, -1, 0, 2};
  te.pose.length = 1;
  te.pose.outputs = 3;
  te.pose.window = {0, 1};
  te.pose.value = {0, 0, 0, 1, 1, 10};
  GraspScores s{};
  score_object(s, std::vector<int>{0, 1, 1, 2}, te);
  CHECK(s[kObjectAccuracy] == doctest::Approx(75.0));
  const double fp[6] = {1, 0, 2, 1, 0, 2};  // error (2, 0, 0) on the second row
  score_force(s, fp, 3, te);
  CHECK(s[kForceRmseU] == doctest::Approx(std::sqrt(2.0)));
  CHECK(s[kForceRmseV] == 0.0);
  CHECK(s[kForceRmse] == doctest::Approx(std::sqrt(2.0)));
  const double pp[6] = {0, 0, 4, 3, 1, 10};  // position errors 0 and 2 cm; θ errors 4 and 0
  score_pose(s, pp, 3, te);
  CHECK(s[kPoseX] == doctest::Approx(std::sqrt(2.0)));
  CHECK(s[kPoseTheta] == doctest::Approx(std::sqrt(8.0)));
  CHECK(s[kPoseWithin2cm] == doctest::Approx(100.0));
  CHECK(s[kPoseWithin5deg] == doctest::Approx(100.0));
  // The constant predicts the training majority and means.
  GraspTasks tr = te;
  tr.object.label = {2, 2, 1, 0};
  const GraspScores c = score_constant(tr, te);
  CHECK(c[kObjectAccuracy] == doctest::Approx(50.0));
  CHECK(c[kForceRmseU] == doctest::Approx(1.0));  // mean 0 against ±1
  CHECK(c[kPoseTheta] == doctest::Approx(5.0));
}

TEST_CASE("grasp_score_table: head means per seed then mean ± sd over seeds and the best two with Welch test") {
  auto scores = [](double acc, double force) {
    GraspScores s{};
    s[kObjectAccuracy] = acc;
    s[kForceRmse] = force;
    return s;
  };
  ScoreTable t = grasp_score_table("toy");
  for (const auto& seed : std::vector<std::vector<GraspScores>>{{scores(50, 1.0), scores(52, 1.2)}, {scores(54, 1.1), scores(54, 1.1)}, {scores(60, 0.9), scores(58, 0.9)}})
    t.row("a").add_sample(seed);
  for (const GraspScores& k : {scores(40, 0.5), scores(41, 0.6), scores(42, 0.7)}) t.row("b").add_sample(std::vector<GraspScores>{k});
  for (int k = 0; k < 3; ++k) t.row("c <&>").add_sample(std::vector<GraspScores>{scores(10, 2.0)});
  CHECK(t.markdown().find("| method | object top-1 (%) ↑ | force RMSE (N) ↓ |") != std::string::npos);
  CHECK(t.rows[0].samples(kObjectAccuracy) == std::vector<double>{51, 54, 59});
  CHECK(t.rows[0].summary(kObjectAccuracy).mean == doctest::Approx(54.6666667));
  CHECK(t.rows[0].summary(kObjectAccuracy).sd == doctest::Approx(std::sqrt(((51 - 54.6666667) * (51 - 54.6666667) + (54 - 54.6666667) * (54 - 54.6666667) + (59 - 54.6666667) * (59 - 54.6666667)) / 2)));
  const auto cmp = t.comparisons();
  REQUIRE(cmp.size() == 5);  // the primary metrics
  CHECK(cmp[0].metric == kObjectAccuracy);
  CHECK(cmp[0].best == 0);
  CHECK(cmp[0].second == 1);
  const std::vector<double> a{51, 54, 59}, b{40, 41, 42};
  CHECK(cmp[0].test.p == doctest::Approx(welch_t_test(a, b, Alternative::greater).p));
  CHECK(cmp[0].test.p < 0.05);
  CHECK(cmp[1].metric == kForceRmse);
  CHECK(cmp[1].best == 1);  // lower is better
  CHECK(cmp[1].second == 0);
  const std::string md = t.markdown();
  CHECK(md.find("| a | 54.7 ± 4") != std::string::npos);
  CHECK(md.find("best a, second b") != std::string::npos);
  const nlohmann::json j = t.to_json();
  CHECK(j["rows"][1]["mean"]["object_accuracy"].get<double>() == doctest::Approx(41));
  CHECK(j["rows"][0]["runs"][2][1]["object_accuracy"].get<double>() == 58);
  const std::string svg = t.svg();
  CHECK(svg.rfind("<svg", 0) == 0);
  CHECK(svg.find("c &lt;&amp;&gt;") != std::string::npos);
  CHECK(svg.find("</svg>") != std::string::npos);
}

namespace {

// The protocol at toy size: seconds, not hours.
GraspEvalConfig toy_grasp_eval_config() {
  GraspEvalConfig c;
  c.seeds = {0, 1};
  c.head_seeds = 1;
  c.baseline_frames = 100;
  c.pretrain_frames = 2000;
  c.train_frames = 3000;
  c.test_frames = 2000;
  c.train.model.dim = 12;
  c.train.model.heads = 2;
  c.train.model.depth = 1;
  c.train.model.predictor_depth = 1;
  c.train.schedule.steps = 2;
  c.train.schedule.warmup_steps = 1;
  c.train.batch = 4;
  c.tasks.sequence_length = 3;
  c.tasks.max_object_windows = 40;
  c.tasks.max_force_windows = 40;
  c.tasks.max_pose_sequences = 10;
  c.heads.probe_heads = 2;
  c.heads.probe.max_epochs = 2;
  c.heads.sequence.max_epochs = 2;
  c.heads.end_to_end_max_epochs = 1;
  c.byol_image_size = 63;
  c.byol_widths = {4, 6, 6, 4, 3};  // 3 channels: its probes take 1 attention head, not 2
  c.byol_projection = 8, c.byol_hidden = 16;
  return c;
}

}  // namespace

TEST_CASE("run_grasp_eval at toy size: every row and the ablation - seed 1 alone gives the same seed-1 tables") {
  GraspEvalConfig c = toy_grasp_eval_config();
  int lines = 0;
  const GraspEvalResult r = run_grasp_eval(c, [&](const std::string&) { ++lines; });
  CHECK(lines > 10);
  REQUIRE(r.main.rows.size() == 8);
  REQUIRE(r.ablation.rows.size() == 5);
  CHECK(r.main.rows[5].name == "DINO, frozen");
  CHECK(r.main.rows[6].name == "BYOL, frozen (random-init AlexNet)");
  // The linear read-outs: the ridge row (the same runs as the main table's) and two rows per frozen
  // encoder of the main table (pad means, token components), one read-out per pre-training seed;
  // none for BYOL, whose tokens are image cells, not taxels.
  REQUIRE(r.linear.rows.size() == 9);
  CHECK(r.linear.rows[0].name == r.main.rows[1].name);
  CHECK(r.linear.rows[0].runs == r.main.rows[1].runs);
  CHECK(r.linear.rows[1].name == "random init: pad means");
  CHECK(r.linear.rows[6].name == "DINO: token components");
  CHECK(r.linear.rows[8].name == "Tactile-JEPA: token components");
  for (std::size_t i = 1; i < 9; ++i) CHECK(r.linear.rows[i].runs.front().size() == 1);
  // The ablation's linear read-outs: two rows per mask variant, the default's the same runs as the
  // Tactile-JEPA rows of the linear table.
  REQUIRE(r.ablation_linear.rows.size() == 10);
  CHECK(r.ablation_linear.rows[0].name == "2L+2G (default): pad means");
  CHECK(r.ablation_linear.rows[0].runs == r.linear.rows[7].runs);
  CHECK(r.ablation_linear.rows[1].runs == r.linear.rows[8].runs);
  CHECK(r.ablation_linear.rows[3].name == "4L: token components");
  CHECK(r.ablation_linear.rows[9].name == "2L+2G, local context: token components");
  for (const ScoreTable* t : {&r.main, &r.ablation, &r.linear, &r.ablation_linear})
    for (const ScoreRow& row : t->rows) {
      REQUIRE(row.runs.size() == 2);
      for (const auto& heads : row.runs)
        for (const auto& s : heads)
          for (double v : s) CHECK(std::isfinite(v));
    }
  CHECK(r.info["pretraining"].size() == 2 * 8);  // JEPA, MAE, DINO, BYOL and 4 mask variants per seed
  {
    // Seed 1 alone gives seed 1's scores of the two-seed run, row by row: the same seed, the same
    // numbers, and nothing of seed 0 leaks into seed 1.
    GraspEvalConfig one = c;
    one.seeds = {1};
    const GraspEvalResult again = run_grasp_eval(one);
    for (const auto& [a, b] : {std::pair{&again.main, &r.main}, std::pair{&again.ablation, &r.ablation},
                               std::pair{&again.linear, &r.linear}, std::pair{&again.ablation_linear, &r.ablation_linear}}) {
      REQUIRE(a->rows.size() == b->rows.size());
      for (std::size_t i = 0; i < a->rows.size(); ++i) {
        CAPTURE(a->rows[i].name);
        CHECK(a->rows[i].name == b->rows[i].name);
        REQUIRE(a->rows[i].runs.size() == 1);
        CHECK(a->rows[i].runs[0] == b->rows[i].runs[1]);
      }
    }
  }
  c.tasks.label_pad = 5;
  CHECK_THROWS_AS(run_grasp_eval(c), ConfigError);
  c.tasks.label_pad = c.sim.label_pad;
  c.heads.sequence.validation_blocks = c.heads.sequence.validation_gap = 1;  // and by episodes: which?
  CHECK_THROWS_WITH_AS(c.validate(), doctest::Contains("at once"), ConfigError);
  c.heads.sequence.validation_groups = false;
  CHECK_NOTHROW(c.validate());
  c.jepa = false;  // the ablation's 2L+2G row is the Tactile-JEPA row
  CHECK_THROWS_WITH_AS(c.validate(), doctest::Contains("needs the Tactile-JEPA row"), ConfigError);
  c.ablation = false;
  CHECK_NOTHROW(c.validate());
  c.readout_components = c.train.model.dim + 1;
  CHECK_THROWS_WITH_AS(c.validate(), doctest::Contains("readout_components"), ConfigError);
}

TEST_CASE("run_grasp_eval at toy size: standardized features and the other poolings read the same encoders") {
  // Standardized features for the frozen rows' heads, the taxel pooling for the probes and the
  // attentive one for the sequence head (the defaults the other way round): the same encoders,
  // so the same linear read-outs (they read the raw embeddings); the frozen rows' heads read
  // other inputs.
  GraspEvalConfig c = toy_grasp_eval_config();
  c.seeds = {0};
  c.end_to_end = c.mae = c.dino = c.byol = c.ablation = false;
  const GraspEvalResult r = run_grasp_eval(c);
  GraspEvalConfig cs = c;
  cs.heads.standardize_features = true;
  cs.heads.probe_pooling.kind = PoolingKind::taxel;
  cs.heads.sequence_pooling.kind = PoolingKind::attentive;
  const GraspEvalResult s = run_grasp_eval(cs);
  REQUIRE(r.main.rows.size() == 4);
  REQUIRE(s.main.rows.size() == 4);
  REQUIRE(s.linear.rows.size() == 5);
  CHECK(s.main.rows[2].name == "random init, frozen");
  CHECK(s.main.rows[3].name == "Tactile-JEPA, frozen");
  CHECK(s.linear.rows[3].name == "Tactile-JEPA: pad means");
  CHECK(s.linear.to_json() == r.linear.to_json());
  for (std::size_t i : {2, 3}) CHECK(s.main.rows[i].runs.front() != r.main.rows[i].runs.front());
  for (const ScoreRow& row : s.main.rows)
    for (const auto& sc : row.runs.front())
      for (double v : sc) CHECK(std::isfinite(v));
  CHECK(cs.to_json()["heads"]["standardize_features"] == true);
  CHECK(cs.to_json()["heads"]["sequence_pooling"] == "attentive");
  CHECK(cs.to_json()["heads"]["probe_pooling"] == "taxel");
  CHECK(c.to_json()["heads"]["sequence_pooling"] == "taxel");
  CHECK(c.to_json()["heads"]["probe_pooling"] == "attentive");
}

TEST_CASE("run_grasp_eval with a pre-training cache: the tables and pre-training read back and bad files named") {
  GraspEvalConfig c = toy_grasp_eval_config();
  c.seeds = {0};
  c.random = c.end_to_end = false;  // no pre-training in these rows
  const tjepa_test::TempDir dir("pretrain_cache");
  c.pretrain_cache = (dir / "cache").string();
  auto files = [&] {
    std::vector<std::filesystem::path> f;
    for (const auto& e : std::filesystem::directory_iterator(dir / "cache")) f.push_back(e.path());
    std::sort(f.begin(), f.end());
    return f;
  };
  const GraspEvalResult first = run_grasp_eval(c);  // pre-trains and writes
  const auto written = files();
  REQUIRE(written.size() == 8);  // Tactile-JEPA, MAE, DINO, BYOL and the 4 mask variants at seed 0
  auto written_as = [&](const std::string& prefix) {
    const auto it = std::find_if(written.begin(), written.end(),
                                 [&](const auto& p) { return p.filename().string().starts_with(prefix); });
    REQUIRE(it != written.end());
    return *it;
  };
  for (const char* prefix : {"tactile-jepa-seed0-", "mae-seed0-", "dino-seed0-", "byol-seed0-", "4l-seed0-", "4g-seed0-", "4-i-jepa-blocks-seed0-",
                             "2l-2g-local-context-seed0-"})
    CHECK(written_as(prefix).extension() == ".safetensors");
  for (const auto& p : first.info["pretraining"]) CHECK_FALSE(p.contains("cached"));
  CHECK(first.info["pretrain_cache"] == c.pretrain_cache);
  CHECK(c.to_json().dump().find("cache") == std::string::npos);  // not a setting of the results

  std::vector<std::string> lines;
  const GraspEvalResult second = run_grasp_eval(c, [&](const std::string& l) { lines.push_back(l); });
  CHECK(second.main.to_json() == first.main.to_json());
  CHECK(second.ablation.to_json() == first.ablation.to_json());
  CHECK(second.linear.to_json() == first.linear.to_json());
  CHECK(second.ablation_linear.to_json() == first.ablation_linear.to_json());
  CHECK(files() == written);
  REQUIRE(second.info["pretraining"].size() == 8);
  for (std::size_t i = 0; i < 8; ++i) {
    const auto& p = second.info["pretraining"][i];
    CHECK(p.contains("cached"));
    CHECK(p["last_loss"] == first.info["pretraining"][i]["last_loss"]);
    CHECK(p["row"] == first.info["pretraining"][i]["row"]);
  }
  CHECK(std::count_if(lines.begin(), lines.end(), [](const std::string& l) {
          return l.find("pre-trained encoder read from") != std::string::npos;
        }) == 8);

  // Another pre-training config is another key: pre-trained again, beside the old files.
  GraspEvalConfig other = c;
  other.train.schedule.steps = 3;
  other.mae = other.dino = other.byol = other.ablation = false;
  const GraspEvalResult third = run_grasp_eval(other);
  CHECK_FALSE(third.info["pretraining"][0].contains("cached"));
  CHECK(files().size() == 9);

  // A truncated file, and a file under another key's name: errors that name the file. The
  // Tactile-JEPA row alone reads the same file (the rows left out are not in its key) and fails
  // before any head is trained.
  GraspEvalConfig jepa_only = c;
  jepa_only.ridge = jepa_only.mae = jepa_only.dino = jepa_only.byol = jepa_only.ablation = jepa_only.linear_readout = false;
  const std::filesystem::path jepa = written_as("tactile-jepa-seed0-"), four_l = written_as("4l-seed0-");
  const auto size = std::filesystem::file_size(jepa);
  std::filesystem::copy_file(jepa, dir / "jepa.bak");
  std::filesystem::resize_file(jepa, size / 2);
  CHECK_THROWS_WITH_AS(run_grasp_eval(jepa_only), doctest::Contains(jepa.filename().string().c_str()), FileError);
  std::filesystem::copy_file(four_l, jepa, std::filesystem::copy_options::overwrite_existing);
  CHECK_THROWS_WITH_AS(run_grasp_eval(jepa_only), doctest::Contains("key is not the one asked for"), FileError);
  std::filesystem::copy_file(dir / "jepa.bak", jepa, std::filesystem::copy_options::overwrite_existing);
  const GraspEvalResult restored = run_grasp_eval(jepa_only);
  CHECK(restored.info["pretraining"][0].contains("cached"));
  REQUIRE(restored.main.rows.size() == 2);  // constant, Tactile-JEPA
  CHECK(restored.main.rows[1].name == "Tactile-JEPA, frozen");
  const auto first_jepa = std::find_if(first.main.rows.begin(), first.main.rows.end(),
                                       [](const ScoreRow& row) { return row.name == "Tactile-JEPA, frozen"; });
  REQUIRE(first_jepa != first.main.rows.end());
  CHECK(restored.main.rows[1].runs == first_jepa->runs);

  // The fingerprint sees the data: another data seed, another fingerprint.
  const GraspEvalData d0 = simulate_grasp_eval_data(c);
  GraspEvalConfig c1 = c;
  c1.data_seed = 1;
  const GraspEvalData d1 = simulate_grasp_eval_data(c1);
  CHECK(fingerprint(*d0.pretrain) == fingerprint(*simulate_grasp_eval_data(c).pretrain));
  CHECK(fingerprint(*d0.pretrain) != fingerprint(*d1.pretrain));
  CHECK(fingerprint(*d0.pretrain) != fingerprint(*d0.train));
}

TEST_CASE("PretrainCache: round trip and keys and errors that leave the parameters as they were") {
  const tjepa_test::TempDir dir("pretrain_cache_unit");
  auto params = [](float value) {
    ParamSet<float> p;
    p.add("pos_embed", {1, 4, 3});
    p.add("blocks.0.norm1.weight", {3});
    p.allocate();
    for (float& v : p.values()) v = value;
    return p;
  };
  const PretrainCache off;
  ParamSet<float> a = params(1.5f);
  CHECK_FALSE(off.load(off.key("Tactile-JEPA", 0, {}), a));
  off.save(off.key("Tactile-JEPA", 0, {}), a, {{"row", "x"}});  // nothing written
  const PretrainCache cache(dir / "c", {{"fingerprint", 7}});
  CHECK(std::filesystem::is_directory(dir / "c"));
  const nlohmann::json key = cache.key("Tactile-JEPA", 3, {{"train", {{"steps", 10}}}});
  CHECK(key["seed"] == 3);
  CHECK(key["data"]["fingerprint"] == 7);
  CHECK(key["build"]["compiler"] == __VERSION__);
  CHECK(key["threads"] == max_threads());
  CHECK(cache.path(key).filename().string().starts_with("tactile-jepa-seed3-"));
  CHECK(cache.path(key) != cache.path(cache.key("Tactile-JEPA", 3, {{"train", {{"steps", 11}}}})));
  ParamSet<float> b = params(0.0f);
  CHECK_FALSE(cache.load(key, b));  // not written yet
  cache.save(key, a, {{"row", "Tactile-JEPA"}, {"last_loss", 0.25}});
  const auto entry = cache.load(key, b);
  REQUIRE(entry);
  CHECK((*entry)["last_loss"] == 0.25);
  for (std::size_t i = 0; i < a.count(); ++i)  // (values() spans the padding between tensors too)
    CHECK(std::ranges::equal(a.value_span(a.id(i)), b.value_span(b.id(i))));

  // Another key's file under this key's name; a file without the log entry; a truncated file;
  // other shapes: each a FileError naming the file, the parameters untouched.
  const nlohmann::json other = cache.key("MAE", 3, {});
  std::filesystem::copy_file(cache.path(key), cache.path(other));
  ParamSet<float> c = params(-2.0f);
  CHECK_THROWS_WITH_AS(cache.load(other, c), doctest::Contains("key is not the one asked for"), FileError);
  CheckpointState bare;
  bare.config = other;
  save_checkpoint<float>(cache.path(other), {PrefixedParams<float>{"encoder.", &a}}, nullptr, bare);
  CHECK_THROWS_WITH_AS(cache.load(other, c), doctest::Contains("no 'pretraining'"), FileError);
  std::filesystem::resize_file(cache.path(other), std::filesystem::file_size(cache.path(other)) - 9);
  CHECK_THROWS_WITH_AS(cache.load(other, c), doctest::Contains(cache.path(other).filename().string().c_str()),
                       FileError);
  ParamSet<float> wider;
  wider.add("pos_embed", {1, 5, 3});
  wider.add("blocks.0.norm1.weight", {3});
  wider.allocate();
  CHECK_THROWS_AS(cache.load(key, wider), FileError);
  for (std::size_t i = 0; i < c.count(); ++i)
    for (float v : c.value_span(c.id(i))) CHECK(v == -2.0f);

  // The mask ablation's variants: each its own masks in the run config and so in the key, so that
  // a variant changed under its old name does not read the old encoder.
  const std::vector<MaskVariant> variants = grasp_mask_ablation(TrainConfig{});
  auto run_of = [](const MaskVariant& v) {
    TrainConfig t;
    t.masks = v.masks;
    return t.to_json();
  };
  for (std::size_t i = 0; i < variants.size(); ++i) {
    CHECK(run_of(variants[i]) != TrainConfig{}.to_json());
    for (std::size_t j = i + 1; j < variants.size(); ++j) CHECK(run_of(variants[i]) != run_of(variants[j]));
  }
  MaskVariant changed = variants.front();
  changed.masks.num_local += 1;
  CHECK(cache.path(cache.key("4L", 0, {{"train", run_of(changed)}})) !=
        cache.path(cache.key("4L", 0, {{"train", run_of(variants.front())}})));

  // A directory that cannot be one.
  std::ofstream(dir / "plain_file") << "x";
  CHECK_THROWS_WITH_AS(PretrainCache(dir / "plain_file", {}), doctest::Contains("plain_file"), FileError);
}

}  // TEST_SUITE

TEST_SUITE("eval") {

TEST_CASE("score_linear_readouts: fits on the training embeddings and scores the test ones") {
  // 4 tokens in pads {0, 0, 1, 1}, d = 3. Sample s of a split: x[s, n] = base_n + a_s e0 on pad 0's
  // tokens + b_s e1 on token 3 only. Force is linear in a (pad 0's mean), the object is sign(a), the
  // pose is linear in b (token 3's residual along its direction). Both read-outs must find what is
  // linear in their features on held-out samples; fitted on the test split (or scored on the
  // training one) they could not, since a and b are drawn independently per split.
  const int N = 4, d = 3, Str = 70, Ste = 70, L = 2;  // equal sizes: the swapped call below is valid
  const std::vector<int> group{0, 0, 1, 1};
  auto split = [&](int S, std::uint64_t seed, std::vector<float>& x, GraspTasks& t) {
    Rng rng(seed);
    x.assign(static_cast<std::size_t>(S) * N * d, 0.0f);
    t = GraspTasks{};
    t.object.classes = 2;
    t.force.regression = 3;
    t.pose.length = L;
    t.pose.outputs = 3;
    for (int s = 0; s < S; ++s) {
      const double a = rng.normal(0.0, 1.0), b = rng.normal(0.0, 1.0);
      for (int n = 0; n < N; ++n)
        for (int i = 0; i < d; ++i) {
          double v = 0.3 * n - 0.1 * i;
          if (n < 2 && i == 0) v += a;
          if (n == 3 && i == 1) v += b;
          x[static_cast<std::size_t>((s * N + n) * d + i)] = float(v);
        }
      t.windows.push_back(s);
      t.object_rows.push_back(s);
      t.object.label.push_back(a > 0 ? 1 : 0);
      t.force_rows.push_back(s);
      for (double f : {a, 2 * a, -a}) t.force.value.push_back(float(f));
      t.pose.window.push_back(s);  // sequences of L = 2 windows: s and s again (only rows matter here)
      t.pose.window.push_back(s);
      for (int l = 0; l < L; ++l)
        for (double y : {b, 0.5 * b, 3 * b}) t.pose.value.push_back(float(y));
    }
  };
  std::vector<float> xtr, xte;
  GraspTasks tr, te;
  split(Str, 1, xtr, tr);
  split(Ste, 2, xte, te);
  const LinearReadoutScores r = score_linear_readouts(xtr, tr, xte, te, N, d, LinearReadoutConfig{group, 2, 2, 7});
  CHECK(r.group_means[kForceRmse] < 0.05);      // |force| ~ 2.4 N RMS
  CHECK(r.group_means[kObjectAccuracy] > 90.0);
  CHECK(r.token_components[kForceRmse] < 0.05);
  CHECK(r.token_components[kPoseTheta] < 0.1);  // θ ~ 3 RMS
  CHECK(r.token_components[kObjectAccuracy] > 90.0);
  // The same call with the splits' embeddings exchanged fits on samples whose a and b do not go
  // with the training labels: no read-out can then be accurate.
  const LinearReadoutScores swapped = score_linear_readouts(xte, tr, xtr, te, N, d, LinearReadoutConfig{group, 2, 2, 7});
  CHECK(swapped.group_means[kForceRmse] > 1.0);
  CHECK(swapped.token_components[kPoseTheta] > 1.0);
}

}
