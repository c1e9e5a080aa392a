// `poseforest render`, run in-process: files written, readable, identical for any thread count.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "apps/commands/commands.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using namespace poseforest;

namespace {

int Run(std::vector<std::string> args) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  return apps::commands::RenderMain(int(argv.size()), argv.data());
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

TEST_CASE("poseforest render writes depth, labels, joints and a montage, independent of threads",
          "[cli][egl]") {
  const fs::path a = testing::ScratchDir("render-a"), b = testing::ScratchDir("render-b");
  REQUIRE(Run({"render", "--out", a.string(), "--count", "5", "--seed", "42", "--people", "2", "--montage",
               (a / "montage.png").string()}) == 0);
  REQUIRE(Run({"render", "--out", b.string(), "--count", "5", "--seed", "42", "--people", "2", "--threads",
               "2"}) == 0);
  for (int i = 0; i < 5; ++i) {
    char name[32];
    for (const char* stem : {"depth", "labels", "joints"}) {
      std::snprintf(name, sizeof name, "%s_%06d.%s", stem, i, std::string(stem) == "joints" ? "json" : "png");
      INFO(name);
      REQUIRE(fs::exists(a / name));
      CHECK(Slurp(a / name) == Slurp(b / name));
    }
  }
  auto depth = runtime::ReadDepthImage((a / "depth_000003.png").string());
  REQUIRE(depth.ok());
  CHECK(depth->width == 640);
  CHECK(depth->height == 480);
  CHECK(core::CountForeground(*depth) > 100);
  const std::string labels_bytes = Slurp(a / "labels_000003.png");
  auto labels = runtime::DecodePng(
      {reinterpret_cast<const uint8_t*>(labels_bytes.data()), labels_bytes.size()}, "labels");
  REQUIRE(labels.ok());
  REQUIRE(labels->channels == 1);
  int fg = 0;
  for (size_t k = 0; k < labels->samples8.size(); ++k) {
    const uint8_t l = labels->samples8[k];
    REQUIRE((l < 31 || l == 255));
    REQUIRE((l == 255) == (depth->pixels[k] == 0));
    fg += l != 255;
  }
  CHECK(fg > 100);
  const std::string json = Slurp(a / "joints_000003.json");
  CHECK(json.find("\"L_shoulder\"") != std::string::npos);
  CHECK(json.find("\"visible\"") != std::string::npos);
  CHECK(fs::file_size(a / "montage.png") > 1000);
  // Again into `a` with fewer frames: frames 3 and 4 would stay and mix with the new ones (eval
  // reads every frame of the folder), so it is refused, the folder untouched; the same count
  // (every file replaced) is not.
  const std::string before = Slurp(a / "depth_000000.png");
  CHECK(Run({"render", "--out", a.string(), "--count", "3", "--seed", "7"}) == 2);
  CHECK(Slurp(a / "depth_000000.png") == before);
  CHECK(fs::exists(a / "depth_000004.png"));
  CHECK(Run({"render", "--out", a.string(), "--count", "5", "--seed", "42", "--people", "2"}) == 0);
  CHECK(Slurp(a / "depth_000000.png") == before);
  fs::remove_all(a);
  fs::remove_all(b);
}

TEST_CASE("poseforest render refuses bad options with exit code 2", "[cli]") {
  CHECK(Run({"render"}) == 2);
  CHECK(Run({"render", "--out", "/tmp/x", "--rotation", "90"}) == 2);
  CHECK(Run({"render", "--out", "/tmp/x", "--count", "-3"}) == 2);
  CHECK(Run({"render", "--out", "/tmp/x", "--bogus"}) == 2);
  CHECK(Run({"render", "--help"}) == 0);
}

TEST_CASE("poseforest render --sensor: the camera's size and ToF noise; effects off render as before",
          "[cli][egl]") {
  const fs::path base = testing::ScratchDir("render-sensor-base"), off = testing::ScratchDir("render-sensor-off"),
                 fly = testing::ScratchDir("render-sensor-fly"), v2 = testing::ScratchDir("render-sensor-v2");
  REQUIRE(Run({"render", "--out", base.string(), "--count", "2", "--seed", "7", "--clutter", "walls"}) == 0);
  REQUIRE(Run({"render", "--out", off.string(), "--count", "2", "--seed", "7", "--clutter", "walls", "--sensor",
               "kinect-v1", "--flying-pixels", "0", "--range-holes", "0", "--grazing-holes", "0"}) == 0);
  REQUIRE(Run({"render", "--out", fly.string(), "--count", "2", "--seed", "7", "--clutter", "walls",
               "--flying-pixels", "0.5"}) == 0);
  REQUIRE(Run({"render", "--out", v2.string(), "--count", "2", "--seed", "7", "--sensor", "kinect-v2"}) == 0);
  for (const char* name : {"depth_000001.png", "labels_000001.png", "mask_000001.png"}) {
    INFO(name);
    CHECK(Slurp(off / name) == Slurp(base / name));  // switched off: byte for byte as before
  }
  CHECK(Slurp(fly / "depth_000001.png") != Slurp(base / "depth_000001.png"));
  auto depth = runtime::ReadDepthImage((v2 / "depth_000001.png").string());
  REQUIRE(depth.ok());
  CHECK(depth->width == 512);
  CHECK(depth->height == 424);
  CHECK(core::CountForeground(*depth) > 100);
  CHECK_THAT(Slurp(v2 / "camera.txt"), Catch::Contains("kinect-v2 512 424 365.5 365.5"));
  CHECK(Run({"render", "--out", v2.string(), "--count", "1", "--sensor", "kinect-v9"}) == 2);
  CHECK(Run({"render", "--out", v2.string(), "--count", "1", "--grazing-holes", "1.5"}) == 2);
}
