// split_trials (downstream/trial_split.hpp): a trial, and a group, lies whole on one side; the
// split is stratified by class where the labels allow it; the same seed gives the same split; a
// table's split column is taken as written and a group across it is an error naming the lines.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>

namespace fs = std::filesystem;
using tjepa_test::TempDir;

TEST_SUITE("downstream") {

TEST_CASE("split_trials: whole trials and groups / stratified / seeded / the table's split column as written") {
  using namespace tjepa;
  TempDir t("split");
  std::ofstream(t / "r.csv") << "1\n";
  {
    std::ofstream f(t / "t.csv");
    f << "file,label\n";
    for (int i = 0; i < 40; ++i) f << "r.csv," << (i % 4 == 0 ? "rare" : i % 2 ? "odd" : "even") << "\n";
  }
  const TrialTable tab = read_trial_table(t / "t.csv");
  const TrialSplits a = split_trials(tab, 0.25, 3), b = split_trials(tab, 0.25, 3), c = split_trials(tab, 0.25, 4);
  CHECK(a.train == b.train);
  CHECK(a.test == b.test);
  CHECK(a.test != c.test);
  CHECK(a.train.size() + a.test.size() == 40);
  CHECK(a.test.size() == 11);
  std::set<int> all(a.train.begin(), a.train.end());
  for (int i : a.test) CHECK(all.insert(i).second);  // no trial on both sides
  // Stratified: each label keeps its share on the test side.
  std::map<std::string, int> test_count;
  for (int i : a.test) ++test_count[tab.trials[static_cast<std::size_t>(i)].label];
  CHECK(test_count["rare"] == 3);   // 10 trials · 0.25 = 2.5, rounded half away from zero
  CHECK(test_count["odd"] == 5);    // 20 · 0.25
  CHECK(test_count["even"] == 3);
  CHECK(a.how.find("stratified by label") != std::string::npos);

  // Groups: every trial of a group on one side; groups holding two labels are not stratified.
  {
    std::ofstream f(t / "g.csv");
    f << "file,label,group\n";
    for (int i = 0; i < 30; ++i) f << "r.csv," << i % 3 << ",session" << i / 5 << "\n";
  }
  const TrialTable g = read_trial_table(t / "g.csv");
  const TrialSplits gs = split_trials(g, 0.34, 1);
  std::set<std::string> train_groups, test_groups;
  for (int i : gs.train) train_groups.insert(g.trials[static_cast<std::size_t>(i)].group);
  for (int i : gs.test) test_groups.insert(g.trials[static_cast<std::size_t>(i)].group);
  for (const auto& s : test_groups) CHECK(train_groups.count(s) == 0);
  CHECK(test_groups.size() == 2);
  CHECK(gs.how.find("stratified") == std::string::npos);

  // The split column as written; a group on both sides is an error naming both lines.
  std::ofstream(t / "s.csv") << "file,label,split,group\nr.csv,a,train,x\nr.csv,b,val,y\nr.csv,a,test,z\nr.csv,b,train,y\n";
  CHECK_THROWS_WITH_AS(split_trials(read_trial_table(t / "s.csv"), 0.2, 0),
                       doctest::Contains("s.csv:5: group 'y' is in split train here and in val at line 3"), DataError);
  std::ofstream(t / "s.csv") << "file,label,split\nr.csv,a,train\nr.csv,b,val\nr.csv,a,test\n";
  const TrialSplits col = split_trials(read_trial_table(t / "s.csv"), 0.2, 0);
  CHECK(col.train == std::vector<int>{0});
  CHECK(col.val == std::vector<int>{1});
  CHECK(col.test == std::vector<int>{2});
  std::ofstream(t / "s.csv") << "file,label,split\nr.csv,a,test\n";
  CHECK_THROWS_WITH_AS(split_trials(read_trial_table(t / "s.csv"), 0.2, 0), doctest::Contains("no training trial"), DataError);
  CHECK_THROWS_AS(split_trials(tab, 1.0, 0), ConfigError);
}

TEST_CASE("split_by_groups: held groups are the validation split as given") {
  using namespace tjepa;
  SampleGroups g{{0, 0, 1, 1, 2, 2}, {}, {2}};
  const ValidationSplit s = split_by_groups(g, 0.5, 9);
  CHECK(s.validation == std::vector<std::int64_t>{4, 5});
  CHECK(s.fit == std::vector<std::int64_t>{0, 1, 2, 3});
}

}
