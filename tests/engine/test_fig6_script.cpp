// docs/training/fig6.sh and docs/training/plot_fig6.py end to end, as a user runs them, at a
// tiny scale: pose library from the shared mocap, rendered MakeHuman/procedural frames (real
// EGL), training, eval on held-out clips, the three CSVs and the three PNGs.
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

const std::string kHeader =
    "images_per_tree,max_depth,max_offset,test_avg_class_acc,test_pixel_acc,train_avg_class_acc,"
    "train_wall_s,nodes";

std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::vector<std::string>> Rows(const fs::path& csv) {
  std::ifstream in(csv);
  std::string line;
  std::vector<std::vector<std::string>> rows;
  std::getline(in, line);
  CHECK(line == kHeader);
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    REQUIRE(cells.size() == 8);
    rows.push_back(cells);
  }
  return rows;
}

std::string Script(const char* name) {
  return (fs::path(POSEFOREST_SOURCE_DIR) / "docs" / "training" / name).string();
}

// A tiny sweep: (a) 4 and 8 images, (b) 8 images at depths 2 and 20 (the latter shared with
// (a)), (c) 8 images at offsets 5 and 129 (the latter shared with (a)).
std::string TinyEnv(const fs::path& csv_dir) {
  return "POSEFOREST_DATA_DIR='" + testing::DataDir().string() + "' CSV_DIR='" + csv_dir.string() +
         "' CANDIDATES=20 THRESHOLDS=10 PIXELS=300 TEST=3 TRAIN_EVAL=2 IMAGE_STEPS='4 8' "
         "DEPTH_IMAGES=8 DEPTH_STEPS_FIRST='2 20' OFFSET_IMAGES=8 OFFSET_STEPS='5 129' ";
}

}  // namespace

TEST_CASE("fig6.sh writes the three CSVs and plot_fig6.py the three plots", "[fig6][egl]") {
  const auto dir = testing::ScratchDir("fig6-script");
  const auto out = dir / "out", csv = dir / "csv";
  const std::string pf = (testing::BinDir() / "poseforest").string();
  auto run = testing::RunCommand(TinyEnv(csv) + Script("fig6.sh") + " " + pf + " " + out.string());
  INFO(run.output);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("plot_fig6: wrote"));

  auto a = Rows(csv / "fig6a_images.csv"), b = Rows(csv / "fig6b_depth.csv"),
       c = Rows(csv / "fig6c_offset.csv");
  REQUIRE(a.size() == 2);
  REQUIRE(b.size() == 2);
  REQUIRE(c.size() == 2);
  CHECK(a[0][0] == "4");
  CHECK(a[1][0] == "8");
  CHECK(b[0][1] == "2");
  CHECK(c[0][2] == "5");
  for (const auto* rows : {&a, &b, &c}) {
    for (const auto& r : *rows) {
      for (int col : {3, 4, 5}) {
        const double acc = std::atof(r[col].c_str());
        CHECK(acc > 0.0);
        CHECK(acc <= 100.0);
      }
      CHECK(std::atoi(r[7].c_str()) > 0);
    }
  }
  // A depth-2 tree has at most 7 nodes; the shared point (8 images, depth 20, offset 129) is
  // trained once and reported identically in all three tables.
  CHECK(std::atoi(b[0][7].c_str()) <= 7);
  CHECK(b[1] == a[1]);
  CHECK(c[1] == a[1]);
  // The held-out test frames come from the test clips of the library the script built.
  CHECK_THAT(Slurp(out / "i8_d20_o129.textproto"),
             Catch::Contains("clips: CLIP_SET_TEST") && Catch::Contains(out.string() + "/mocap.pfposes"));

  for (const char* name : {"fig6a_images.png", "fig6b_depth.png", "fig6c_offset.png"}) {
    auto bytes = core::ReadFileBytes((csv / name).string());
    REQUIRE(bytes.ok());
    auto png = runtime::DecodePng(*bytes, name);
    REQUIRE(png.ok());
    CHECK(png->width > 300);
  }

  // RESUME=1 reuses the forests and accuracies: the same tables, nothing retrained.
  const std::string before = Slurp(csv / "fig6b_depth.csv");
  const auto stamp = fs::last_write_time(out / "i8_d2_o129.pff");
  auto again = testing::RunCommand("RESUME=1 PLOT=0 POSELIB='" + (out / "mocap.pfposes").string() + "' " +
                                   TinyEnv(csv) + Script("fig6.sh") + " " + pf + " " + out.string());
  INFO(again.output);
  REQUIRE(again.exit_code == 0);
  CHECK(Slurp(csv / "fig6b_depth.csv") == before);
  CHECK(fs::last_write_time(out / "i8_d2_o129.pff") == stamp);
  fs::remove_all(dir);
}

TEST_CASE("fig6.sh and plot_fig6.py name what is wrong", "[fig6]") {
  const auto dir = testing::ScratchDir("fig6-bad");
  const std::string pf = (testing::BinDir() / "poseforest").string();

  auto no_data = testing::RunCommand("POSEFOREST_DATA_DIR=/nonexistent/data CSV_DIR='" + dir.string() + "' " +
                                     Script("fig6.sh") + " " + pf + " " + (dir / "out").string());
  CHECK(no_data.exit_code != 0);
  CHECK_THAT(no_data.output, Catch::Contains("no shared data at /nonexistent/data"));

  auto no_program = testing::RunCommand("POSEFOREST_DATA_DIR='" + testing::DataDir().string() +
                                        "' CSV_DIR='" + dir.string() + "' " + Script("fig6.sh") + " " +
                                        (dir / "nope").string() + " " + (dir / "out").string());
  CHECK(no_program.exit_code != 0);
  CHECK_THAT(no_program.output, Catch::Contains((dir / "nope").string() + " is not an executable"));

  // A CSV without the accuracy column: the plot script names the file and the column and
  // writes no picture.
  std::ofstream(dir / "fig6a_images.csv") << "images_per_tree,max_depth,max_offset\n25,20,129\n";
  auto plot = testing::RunCommand("/usr/bin/python3 " + Script("plot_fig6.py") + " " + dir.string());
  CHECK(plot.exit_code != 0);
  CHECK_THAT(plot.output, Catch::Contains((dir / "fig6a_images.csv").string()) &&
                              Catch::Contains("no column 'test_avg_class_acc'"));
  CHECK_FALSE(fs::exists(dir / "fig6a_images.png"));
  fs::remove_all(dir);
}
