// End to end: a handful of real clips (one per skeleton family) retargeted onto MakeHuman and
// Assimp bodies, and the poseforest-poselib tool.

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/assets/pose_library.h"
#include "renderer/assets/retarget.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;
namespace fs = std::filesystem;

namespace {

fs::path Mocap(const std::string& rel) { return poseforest::testing::DataDir() / "mocap" / rel; }
double Y(const SkelPositions& s, SkelJoint j) { return s[size_t(int(j))].y(); }

}  // namespace

TEST_CASE("walking clips keep the target's feet on its floor", "[integration][data]") {
  auto kit = MakeHumanKit::Load(poseforest::testing::DataDir() / "meshes" / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  std::vector<BodyMesh> bodies;
  for (const char* name : {"girl-8", "male-young-heavy"})
    for (const auto& p : MakeHumanPresets())
      if (p.name == name) bodies.push_back(std::move((*kit)->Build(p)).value());
  auto cesium = LoadRiggedMesh(poseforest::testing::DataDir() / "meshes" / "cesium_man" / "CesiumMan.glb");
  REQUIRE(cesium.ok());
  bodies.push_back(std::move(*cesium));
  REQUIRE(bodies.size() == 3);

  for (const char* clip_name : {"bandai_namco_2/dataset-2_walk_normal_001.bvh", "cmu_iclone_cc3/007_12.bvh",
                                "cmu_iclone_cc3/002_01.bvh", "cmu_cgspeed_assimp/01_01.bvh"}) {
    BvhOptions bo;
    bo.max_frames = 300;
    auto clip = LoadBvh(Mocap(clip_name), bo);
    REQUIRE(clip.ok());
    auto tracks = ExtractCanonicalTracks(*clip);
    REQUIRE(tracks.ok());
    for (const auto& body : bodies) {
      const auto& rest = body.rest_joints;
      const double floor = std::min({Y(rest, SkelJoint::kLAnkle), Y(rest, SkelJoint::kRAnkle),
                                     Y(rest, SkelJoint::kLToe), Y(rest, SkelJoint::kRToe)});
      const auto poses = RetargetTracks(*tracks, rest);
      size_t grounded = 0;
      for (const auto& p : poses) {
        const auto posed = PoseJoints(rest, p);
        const double low = std::min({Y(posed, SkelJoint::kLAnkle), Y(posed, SkelJoint::kRAnkle),
                                     Y(posed, SkelJoint::kLToe), Y(posed, SkelJoint::kRToe)});
        CHECK(low > floor - 0.03);  // never through the floor
        // 8 cm: some CMU captures' floors drift by several cm over a walk (007_12).
        if (std::abs(low - floor) < 0.08) ++grounded;
      }
      INFO(clip_name << " on " << body.name << ": " << grounded << " of " << poses.size()
                     << " frames grounded");
      // 01_01 is jumping: only require most frames of the walks.
      CHECK(double(grounded) >
            (std::string(clip_name).find("01_01") != std::string::npos ? 0.3 : 0.8) * double(poses.size()));
    }
  }
}

TEST_CASE("poseforest-poselib builds and describes a library", "[integration][data]") {
  const fs::path tool = poseforest::testing::BinDir() / "poseforest-poselib";
  REQUIRE(fs::exists(tool));
  const fs::path dir = poseforest::testing::ScratchDir("poselib-cli");
  const fs::path lib = dir / "lib.pfposes";
  const std::string build = tool.string() + " build --out " + lib.string() +
                            " --min-distance 0.08 --max-frames 300 " + Mocap("cmu_misc").string() + " " +
                            Mocap("cmu_iclone_cc3/002_01.bvh").string() + " > " +
                            (dir / "build.txt").string() + " 2>&1";
  REQUIRE(std::system(build.c_str()) == 0);
  auto loaded = LoadPoseLibrary(lib);
  REQUIRE(loaded.ok());
  CHECK(loaded->clips.size() == 2);
  CHECK(loaded->min_distance_m == Approx(0.08));
  CHECK(loaded->poses.size() > 10);
  CHECK(loaded->poses.size() < 201 + 171);
  std::ifstream log(dir / "build.txt");
  std::stringstream ss;
  ss << log.rdbuf();
  CHECK_THAT(ss.str(),
             Catch::Contains("[  2/2]") && Catch::Contains("kept " + std::to_string(loaded->poses.size())));

  const std::string info = tool.string() + " info " + lib.string() + " > " + (dir / "info.txt").string();
  REQUIRE(std::system(info.c_str()) == 0);
  std::ifstream in(dir / "info.txt");
  std::stringstream is;
  is << in.rdbuf();
  CHECK_THAT(is.str(), Catch::Contains(std::to_string(loaded->poses.size()) + " poses from 2 clips"));

  // Errors exit non-zero.
  CHECK(std::system(
            (tool.string() + " info " + (dir / "missing.pfposes").string() + " 2> /dev/null").c_str()) != 0);
  CHECK(std::system((tool.string() + " build --out " + (dir / "x.pfposes").string() + " " +
                     (dir / "none").string() + " > /dev/null 2>&1")
                        .c_str()) != 0);
  // A folder without clips, and a split that leaves no training clip: an error that says so,
  // and no library written.
  auto run_build = [&](const std::string& args, const fs::path& log_file) {
    const std::string cmd = tool.string() + " build --out " + (dir / "y.pfposes").string() + " " + args +
                            " > " + log_file.string() + " 2>&1";
    const int rc = std::system(cmd.c_str());
    std::ifstream f(log_file);
    std::stringstream text;
    text << f.rdbuf();
    return std::make_pair(rc, text.str());
  };
  fs::create_directories(dir / "empty");
  const auto [empty_rc, empty_log] = run_build((dir / "empty").string(), dir / "empty.txt");
  CHECK(empty_rc != 0);
  CHECK_THAT(empty_log, Catch::Contains("no .bvh clips in this folder or below"));
  const auto [split_rc, split_log] =
      run_build("--test-fraction 1 " + Mocap("cmu_iclone_cc3/002_01.bvh").string(), dir / "split.txt");
  CHECK(split_rc != 0);
  CHECK_THAT(split_log, Catch::Contains("no clips left to build from: all 1 are test clips"));
  CHECK_FALSE(fs::exists(dir / "y.pfposes"));
  // --help on the tool and a subcommand; values out of range: exit 2, naming the option.
  for (const char* help : {"--help", "build --help", "info --help", "bvh --help"}) {
    INFO(help);
    CHECK(std::system((tool.string() + " " + help + " > /dev/null").c_str()) == 0);
  }
  for (const auto& [args, says] : std::vector<std::pair<std::string, std::string>>{
           {"--min-distance -1", "--min-distance: Value -1 not in range"},
           {"--max-frames 0", "--max-frames: Value 0 not in range"},
           {"--test-fraction 2", "--test-fraction: Value 2 not in range"},
           {"--bogus 3", "--bogus"}}) {
    const auto [rc, log] =
        run_build(args + " " + Mocap("cmu_iclone_cc3/002_01.bvh").string(), dir / "bad.txt");
    INFO(args << ": " << log);
    CHECK(WEXITSTATUS(rc) == 2);
    CHECK_THAT(log, Catch::StartsWith("poseforest-poselib: ") && Catch::Contains(says));
  }
  CHECK_FALSE(fs::exists(dir / "y.pfposes"));
  // "--out=" is an empty --out (refused), not --out taking the next argument (the clip) as the file.
  const std::string empty_out = tool.string() +
                                " build --out= " + Mocap("cmu_iclone_cc3/002_01.bvh").string() + " > " +
                                (dir / "empty_out.txt").string() + " 2>&1";
  const int empty_out_rc = std::system(empty_out.c_str());
  std::ifstream empty_out_log(dir / "empty_out.txt");
  const std::string empty_out_text((std::istreambuf_iterator<char>(empty_out_log)),
                                   std::istreambuf_iterator<char>());
  INFO(empty_out_text);
  CHECK(WEXITSTATUS(empty_out_rc) == 2);
  CHECK_THAT(empty_out_text, Catch::StartsWith("poseforest-poselib: --out: must be a file name"));
  fs::remove_all(dir);
}
