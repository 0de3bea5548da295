// ScoreTable (downstream/score_table.hpp): samples as head means, mean ± sd, the best two rows
// under Welch's test, rows without runs or with a non-finite score, extra columns and notes, the
// JSON with every run; and ConstantBaseline::outputs, the constant row's predictions.
#include <doctest/doctest.h>

#include <tjepa/downstream/metrics.hpp>
#include <tjepa/downstream/score_table.hpp>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

using namespace tjepa;

TEST_SUITE("downstream") {

namespace {

ScoreTable two_metric_table() {
  ScoreTable t;
  t.title = "toy";
  t.row_header = "row";
  t.sample_name = "repeats";
  t.metrics = {ScoreMetric{"top1", "top-1", "%", true, true, 100, "%.1f", "%.1f"},
               ScoreMetric{"rmse", "RMSE", "", false, true, 1, "%.4g", "%.2g"}};
  return t;
}

}  // namespace

TEST_CASE("ScoreTable: samples / mean ± sd / the best two rows / notes and extra columns") {
  ScoreTable t = two_metric_table();
  t.columns = {"best epoch"};
  t.note_column = true;
  ScoreRow& a = t.row("a");
  a.runs = {{{0.5, 2.0}, {0.7, 2.0}}, {{0.9, 1.0}}};  // sample 1: two heads, averaged to 0.6
  a.cells = {"3 of 10"};
  ScoreRow& b = t.row("b");
  b.runs = {{{0.2, 0.5}}, {{0.3, 0.6}}};
  b.note = "flagged";
  t.row("diverged");  // no runs: "-"
  t.row("nan").runs = {{{std::numeric_limits<double>::quiet_NaN(), 1.0}}};
  CHECK(&t.row("a") == &t.rows[0]);  // row() finds before it adds
  REQUIRE(t.rows.size() == 4);

  const std::vector<double> a0 = t.rows[0].samples(0);
  REQUIRE(a0.size() == 2);
  CHECK(a0[0] == doctest::Approx(0.6));
  CHECK(a0[1] == 0.9);
  const SampleSummary s = t.rows[0].summary(0);
  CHECK(s.n == 2);
  CHECK(s.mean == doctest::Approx(0.75));
  CHECK(s.sd == doctest::Approx(std::sqrt(2 * 0.15 * 0.15)));
  CHECK(t.rows[2].summary(0).n == 0);
  CHECK(std::isnan(t.rows[3].summary(0).mean));

  // The non-finite and empty rows take no part in the comparisons.
  const auto cmp = t.comparisons();
  REQUIRE(cmp.size() == 2);
  CHECK(cmp[0].best == 0);
  CHECK(cmp[0].second == 1);
  CHECK(cmp[0].tested);
  CHECK(cmp[0].test.p == doctest::Approx(welch_t_test(std::vector<double>{0.6, 0.9}, std::vector<double>{0.2, 0.3},
                                                      Alternative::greater).p));
  CHECK(cmp[1].best == 1);  // lower RMSE is better; "nan" has RMSE 1.0 but no top-1, it still counts here
  CHECK(cmp[1].second == 3);
  CHECK(!cmp[1].tested);

  const std::string md = t.markdown();
  CAPTURE(md);
  CHECK(md.find("### toy\n\n| row | top-1 (%) ↑ | RMSE ↓ | best epoch | note |\n|---|---|---|---|---|\n") == 0);
  CHECK(md.find("| a | 75.0 ± 21.2 | 1.5 ± 0.71 | 3 of 10 | |") != std::string::npos);
  CHECK(md.find("| b | 25.0 ± 7.1 | 0.55 ± 0.071 | | **flagged** |") != std::string::npos);
  CHECK(md.find("| diverged | - | - | | |") != std::string::npos);
  CHECK(md.find("| nan | nan | 1 | | |") != std::string::npos);
  CHECK(md.find("- top-1: best a, second b; one-sided Welch t = ") != std::string::npos);
  CHECK(md.find("- RMSE: best b, second nan; not tested (fewer than 2 repeats)") != std::string::npos);

  const nlohmann::json j = t.to_json();
  CHECK(j["rows"][0]["repeats"]["top1"][0].get<double>() == doctest::Approx(0.6));
  CHECK(j["rows"][0]["runs"][0][1]["top1"].get<double>() == 0.7);
  CHECK(j["rows"][1]["note"] == "flagged");
  CHECK(!j["rows"][0].contains("note"));
  CHECK(j["rows"][2]["mean"].empty());
  CHECK(j["rows"][3]["mean"]["top1"].is_null());
  CHECK(j["comparisons"].size() == 2);

  // Without a note column, notes follow the table.
  t.note_column = false;
  CHECK(t.markdown().find("\nnote: b: flagged\n") != std::string::npos);
  // Extra info goes into the row's JSON.
  t.rows[0].info = {{"lr", 1e-3}};
  CHECK(t.to_json()["rows"][0]["lr"] == 1e-3);
  CHECK_THROWS_AS(t.metric("f1"), ConfigError);
  CHECK(t.metric("rmse") == 1);
  t.rows[0].runs.push_back({{0.5}});  // a run short of a metric
  CHECK_THROWS_AS(t.markdown(), ShapeError);
}

TEST_CASE("ConstantBaseline::outputs: the training means and a one-hot majority class") {
  const std::vector<float> values{1, 10, 3, 20};
  const std::vector<int> labels{2, 0, 2};
  const ConstantBaseline c = ConstantBaseline::fit(values, 2, labels, 3);
  const std::vector<double> y = c.outputs(2);
  CHECK(y == std::vector<double>{2, 15, 0, 0, 1, 2, 15, 0, 0, 1});
  CHECK(ConstantBaseline::fit({}, 0, labels, 3).outputs(1) == std::vector<double>{0, 0, 1});
  CHECK(ConstantBaseline::fit(values, 2, {}, 0).outputs(1) == std::vector<double>{2, 15});
}

}  // TEST_SUITE
