// Trial tables (data/trial_table.hpp) and multi-line text frames: what a table says, every bad
// table an error naming its line, and the real slices in tests/data read as their sources say.
#include <doctest/doctest.h>

#include <tjepa/tjepa.hpp>

#include "../support/files.hpp"

#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using tjepa_test::TempDir;

namespace {
void write(const fs::path& p, const std::string& s) { std::ofstream(p, std::ios::binary) << s; }
}  // namespace

TEST_SUITE("data") {

TEST_CASE("read_trial_table: columns in any order / quoted fields / paths from the table's folder / splits and groups") {
  using namespace tjepa;
  TempDir t("trials");
  fs::create_directories(t / "rec");
  for (const char* f : {"rec/a 1.csv", "rec/b,2.csv", "rec/c.csv"}) write(t / f, "1,2\n");
  write(t / "table.csv", "# grasps\nlabel,group,file,split\nbook,s1,rec/a 1.csv,train\n\n"
                         "\"bear\",s2,\"rec/b,2.csv\",test\n10,s2,rec/c.csv,test\n");
  const TrialTable tab = read_trial_table(t / "table.csv");
  REQUIRE(tab.size() == 3);
  CHECK(tab.has_split);
  CHECK(tab.has_group);
  CHECK(tab.trials[1].file == t / "rec/b,2.csv");
  CHECK(tab.trials[1].label == "bear");
  CHECK(tab.trials[2].split == TrialSplit::test);
  CHECK(tab.trials[2].line == 6);
  CHECK(tab.where(2) == (t / "table.csv").string() + ":6");
  CHECK_FALSE(tab.labels_are_files());
  // Class names sorted (numerically only when every name is a number).
  const TrialClasses c = trial_classes(tab);
  CHECK(c.names == std::vector<std::string>{"10", "bear", "book"});
  CHECK(c.of_trial == std::vector<int>{2, 1, 0});
  write(t / "num.csv", "file,label\nrec/c.csv,10\nrec/c.csv,2\nrec/c.csv,2.5\n");
  CHECK(trial_classes(read_trial_table(t / "num.csv")).names == std::vector<std::string>{"2", "2.5", "10"});
  CHECK(trial_values(read_trial_table(t / "num.csv")) == std::vector<float>{10.0f, 2.0f, 2.5f});
  CHECK_THROWS_WITH_AS(trial_values(tab), doctest::Contains("table.csv:3: label 'book' is not a number"), FileError);
  // Per-frame label files.
  write(t / "rec/c_labels.csv", "0\n");
  write(t / "files.csv", "file,label\nrec/c.csv,rec/c_labels.csv\n");
  const TrialTable lf = read_trial_table(t / "files.csv");
  CHECK(lf.labels_are_files());
  CHECK(lf.trials[0].label_file == t / "rec/c_labels.csv");
}

TEST_CASE("read_trial_table: every bad table is a FileError naming the table / the line and the problem") {
  using namespace tjepa;
  TempDir t("trials_bad");
  write(t / "a.csv", "1\n");
  write(t / "a_lab.csv", "1\n");
  auto bad = [&](const std::string& text, const std::string& what) {
    write(t / "t.csv", text);
    CAPTURE(text);
    CHECK_THROWS_WITH_AS(read_trial_table(t / "t.csv"), doctest::Contains(what.c_str()), FileError);
  };
  bad("", "t.csv: empty");
  bad("file,label\n", "a header and no trial");
  bad("file,label,speed\na.csv,x,1\n", "t.csv:1: column 'speed', expected a header of file, label");
  bad("file,file\n", "t.csv:1: column 'file' appears twice");
  bad("file,split\na.csv,train\n", "t.csv:1: the header needs the columns file and label");
  bad("file,label\na.csv\n", "t.csv:2: 1 fields, the header has 2");
  bad("file,label\nmissing.csv,x\n", "t.csv:2: recording '" + (t / "missing.csv").string() + "': no such file");
  bad("file,label\n" + std::string(300, 'x') + ",x\n", "': File name too long");  // the fuzzer's find
  bad("file,label\n.,x\n", "': a directory, not a file");
  bad("file,label\na.csv,\n", "t.csv:2: no label for a.csv");
  bad("file,label,split\na.csv,x,training\n", "t.csv:2: split 'training', expected train, val or test");
  bad("file,label\na.csv,\"x\n", "t.csv:2: a quoted field is not closed");
  bad("file,label\na.csv,nolabels.npy\n", "t.csv:2: label file '" + (t / "nolabels.npy").string() + "': no such file");
  bad("file,label\na.csv,x\na.csv,a_lab.csv\n", "t.csv:3: label 'a_lab.csv' is a label file, line 2's a value");
  CHECK_THROWS_WITH_AS(read_trial_table(t / "none.csv"), doctest::Contains("none.csv: cannot open the trial table"), FileError);
}

TEST_CASE("frame_trials: runs of equal ids in order / an id that comes back or is not finite is named by frame") {
  using namespace tjepa;
  const std::vector<float> ids{7, 7, 7, 3, 3, 9};
  const std::vector<FrameTrial> t = frame_trials(ids, "labels.csv");
  REQUIRE(t.size() == 3u);
  CHECK((t[0].begin == 0 && t[0].end == 3 && t[0].id == 7));
  CHECK((t[1].begin == 3 && t[1].end == 5 && t[1].id == 3));
  CHECK((t[2].begin == 5 && t[2].end == 6 && t[2].id == 9));
  const std::vector<float> back{1, 1, 2, 1};
  CHECK_THROWS_WITH_AS(frame_trials(back, "labels.csv"),
                       "labels.csv: frame 3 has trial id 1 again after other trials (its frames begin at 0); a trial's "
                       "frames must be consecutive",
                       DataError);
  const std::vector<float> nan{1, std::numeric_limits<float>::quiet_NaN()};
  CHECK_THROWS_WITH_AS(frame_trials(nan, "labels.csv"), doctest::Contains("labels.csv: frame 1 has trial id nan"), DataError);
  CHECK_THROWS_AS(frame_trials(std::vector<float>{}, "labels.csv"), DataError);
}

TEST_CASE("text recordings: a frame over several lines (the iCub grasp format) / and a cut last frame named") {
  using namespace tjepa;
  TempDir t("lines_per_frame");
  write(t / "g.txt", "-10000\n1 2 3 \n4 5\n6 7 8\n10 20 30 \n40 50\n60 70 80\n");
  TextFormat f;
  f.axes = 1, f.skip_rows = 1, f.lines_per_frame = 3, f.columns = {5, 6, 7};
  const Recording r = read_text_recording(t / "g.txt", f);
  CHECK(r.frames() == 2);
  CHECK(r.taxels() == 3);
  CHECK(r(0, 0, 0) == 6.0f);
  CHECK(r(1, 2, 0) == 80.0f);
  write(t / "cut.txt", "-10000\n1 2 3\n4 5\n6 7 8\n1 2 3\n");
  CHECK_THROWS_WITH_AS(read_text_recording(t / "cut.txt", f), doctest::Contains("cut.txt:5: the last frame has 1 of its 3 lines"),
                       FileError);
  write(t / "short.txt", "-10000\n1 2 3\n4 5\n6 7 8\n1 2 3\n4\n6 7 8\n");
  CHECK_THROWS_WITH_AS(read_text_recording(t / "short.txt", f), doctest::Contains("short.txt:5: 7 columns, expected 8"),
                       FileError);
  f.lines_per_frame = 0;
  CHECK_THROWS_AS(read_text_recording(t / "g.txt", f), ConfigError);
}

TEST_CASE("the real slices: FabricSlide's 16 channels and iCub's 5 x 12 taxels read as their sources describe") {
  using namespace tjepa;
  const fs::path data = TJEPA_TEST_DATA_DIR;
  TextFormat fab;
  fab.axes = 1, fab.skip_rows = -1;
  for (int c = 3; c < 19; ++c) fab.columns.push_back(c);
  const Recording s = read_text_recording(data / "fabricslide" / "BeigeCotton_F120_V150mmps_0.csv", fab);
  CHECK(s.taxels() == 16);
  CHECK(s.frames() > 100);
  TextFormat icub;
  icub.axes = 1, icub.skip_rows = 1, icub.lines_per_frame = 7;
  for (int c = 14; c < 74; ++c) icub.columns.push_back(c);
  const Recording g = read_text_recording(data / "icub_grasp" / "book_1.txt", icub);
  CHECK(g.taxels() == 60);
  // Capacitive readings 0..255, lower = more pressure (README.txt).
  for (float v : g.values()) CHECK((v >= 0.0f && v <= 255.0f));
  const TrialTable t = read_trial_table(data / "icub_grasp" / "trials.csv");
  CHECK(t.size() == 18);
  CHECK(trial_classes(t).names == std::vector<std::string>{"blue_bear", "book", "lotion"});
  const TrialTable f = read_trial_table(data / "fabricslide" / "trials.csv");
  CHECK(f.has_split);
}

}
