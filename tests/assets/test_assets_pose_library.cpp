// Pose libraries: furthest-neighbour subsampling guarantees, file round trip, corruption,
// clip-level split.

#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <set>

#include "renderer/assets/pose_library.h"
#include "runtime/core/rng.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;
using poseforest::core::ErrorCode;
namespace fs = std::filesystem;

namespace {

fs::path Mocap(const std::string& rel) { return poseforest::testing::DataDir() / "mocap" / rel; }

// Random poses: small random rotations of every joint (so many are within a few cm).
std::vector<Pose> RandomPoses(size_t n, double max_angle, uint64_t seed) {
  poseforest::core::RngStream rng{poseforest::core::CounterRng(seed)};
  std::vector<Pose> poses(n);
  for (auto& p : poses)
    for (auto& q : p.rotation) {
      const Eigen::Vector3d axis = Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()).normalized();
      q = Eigen::Quaterniond(Eigen::AngleAxisd(max_angle * rng.Uniform01(), axis));
    }
  return poses;
}

PoseLibrary SmallLibrary() {
  PoseLibrary lib;
  lib.clips = {"clip_a", "clip_b"};
  lib.poses = RandomPoses(5, 1.0, 7);
  for (size_t i = 0; i < lib.poses.size(); ++i) {
    lib.poses[i].root_translation = Eigen::Vector3d(0.1 * double(i), -0.2, 0.05);
    lib.sources.push_back({uint32_t(i % 2), uint32_t(10 * i)});
  }
  lib.min_distance_m = 0.05;
  return lib;
}

}  // namespace

TEST_CASE("furthest-neighbour subsampling: kept poses >= t apart, dropped ones within t of a kept one",
          "[pose_library]") {
  // Mostly-similar random poses plus a real clip's retargeted frames.
  std::vector<Pose> poses = RandomPoses(1500, 0.25, 11);
  BvhOptions bo;
  bo.max_frames = 400;
  auto clip = LoadBvh(Mocap("cmu_iclone_cc3/002_05.bvh"), bo);
  REQUIRE(clip.ok());
  auto real = RetargetClip(*clip, ReferenceRestJoints());
  REQUIRE(real.ok());
  poses.insert(poses.end(), real->begin(), real->end());

  std::vector<std::array<float, 3 * kNumSkelJoints>> sig;
  for (const auto& p : poses) sig.push_back(PoseSignature(p));
  for (double t : {0.05, 0.12}) {
    const auto kept = SubsamplePoses(sig, t);
    INFO("threshold " << t << ", kept " << kept.size() << " of " << sig.size());
    REQUIRE(kept.size() > 1);
    REQUIRE(kept.size() < sig.size());
    CHECK(std::is_sorted(kept.begin(), kept.end()));
    double closest = 1e9;
    for (size_t a = 0; a < kept.size(); ++a)
      for (size_t b = a + 1; b < kept.size(); ++b)
        closest = std::min(closest, PoseDistance(sig[kept[a]], sig[kept[b]]));
    CHECK(closest >= t - 1e-6);
    std::set<size_t> kept_set(kept.begin(), kept.end());
    double worst = 0;
    for (size_t i = 0; i < sig.size(); ++i) {
      if (kept_set.count(i)) continue;
      double nearest = 1e9;
      for (size_t k : kept) nearest = std::min(nearest, PoseDistance(sig[i], sig[k]));
      worst = std::max(worst, nearest);
    }
    CHECK(worst < t);
  }
  // Threshold 0 keeps everything.
  CHECK(SubsamplePoses(sig, 0).size() == sig.size());
}

TEST_CASE("pose distance is the max joint distance, pelvis-centred", "[pose_library]") {
  Pose a, b;
  b.root_translation = Eigen::Vector3d(1, 2, 3);  // translation does not count
  CHECK(PoseDistance(PoseSignature(a), PoseSignature(b)) < 1e-6);
  b.rotation[size_t(int(SkelJoint::kLElbow))] =
      Eigen::Quaterniond(Eigen::AngleAxisd(3.14159265358979 / 2, Eigen::Vector3d::UnitZ()));
  const auto& r = ReferenceRestJoints();
  const double fore = (r[size_t(int(SkelJoint::kLWrist))] - r[size_t(int(SkelJoint::kLElbow))]).norm();
  // Only the elbow's bone turns (the wrist's own rotation stays identity), so wrist and hand tip
  // both move by the wrist's displacement: sqrt(2) * forearm for a quarter turn.
  CHECK(PoseDistance(PoseSignature(a), PoseSignature(b)) == Approx(std::sqrt(2.0) * fore).epsilon(1e-5));
}

TEST_CASE("pose library round trip through memory and file", "[pose_library]") {
  const PoseLibrary lib = SmallLibrary();
  const auto bytes = SerializePoseLibrary(lib);
  auto back = ParsePoseLibrary(bytes, "mem");
  REQUIRE(back.ok());
  CHECK(back->clips == lib.clips);
  CHECK(back->min_distance_m == lib.min_distance_m);
  REQUIRE(back->poses.size() == lib.poses.size());
  for (size_t i = 0; i < lib.poses.size(); ++i) {
    CHECK(back->sources[i].clip == lib.sources[i].clip);
    CHECK(back->sources[i].frame == lib.sources[i].frame);
    CHECK((back->poses[i].root_translation - lib.poses[i].root_translation).norm() < 1e-6);
    for (int j = 0; j < kNumSkelJoints; ++j)
      CHECK(back->poses[i].rotation[size_t(j)].angularDistance(lib.poses[i].rotation[size_t(j)]) < 1e-5);
  }
  CHECK(SerializePoseLibrary(*back) == bytes);  // float storage is stable

  const fs::path dir = poseforest::testing::ScratchDir("poselib");
  REQUIRE(SavePoseLibrary(lib, dir / "lib.pfposes").ok());
  auto loaded = LoadPoseLibrary(dir / "lib.pfposes");
  REQUIRE(loaded.ok());
  CHECK(SerializePoseLibrary(*loaded) == bytes);
  auto missing = LoadPoseLibrary(dir / "none.pfposes");
  REQUIRE_FALSE(missing.ok());
  CHECK(missing.status().code() == ErrorCode::kNotFound);
  fs::create_directories(dir / "folder.pfposes");
  auto folder = LoadPoseLibrary(dir / "folder.pfposes");
  REQUIRE_FALSE(folder.ok());
  CHECK(folder.status().code() == ErrorCode::kInvalidArgument);
  CHECK_THAT(folder.status().message(), Catch::Contains("folder.pfposes: is a folder, not a file"));
  fs::remove_all(dir);
}

TEST_CASE("corrupt or truncated pose libraries are rejected at every byte", "[pose_library]") {
  const auto bytes = SerializePoseLibrary(SmallLibrary());
  for (size_t n = 0; n < bytes.size(); ++n) {
    std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(n));
    auto r = ParsePoseLibrary(cut, "cut.pfposes");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(), Catch::Contains("cut.pfposes"));
  }
  for (size_t i = 0; i < bytes.size(); ++i) {
    std::vector<uint8_t> bad = bytes;
    bad[i] ^= 0x5A;
    auto r = ParsePoseLibrary(bad, "flip.pfposes");
    REQUIRE_FALSE(r.ok());
    CHECK((r.status().code() == ErrorCode::kDataLoss || r.status().code() == ErrorCode::kVersionMismatch));
  }
  // Another major version is named as such.
  std::vector<uint8_t> v2 = bytes;
  v2[8] = 2;
  auto r = ParsePoseLibrary(v2, "v2.pfposes");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kVersionMismatch);
  CHECK_THAT(r.status().message(), Catch::Contains("2.0") && Catch::Contains("1.x"));
}

TEST_CASE("clip-level split is deterministic, disjoint and order independent", "[pose_library]") {
  std::vector<fs::path> files;
  for (int i = 0; i < 400; ++i) files.push_back("/mocap/clip_" + std::to_string(i) + ".bvh");
  const ClipSplit a = SplitClips(files, 0.2, 5);
  std::vector<fs::path> reversed(files.rbegin(), files.rend());
  const ClipSplit b = SplitClips(reversed, 0.2, 5);
  CHECK(a.train.size() + a.test.size() == files.size());
  CHECK(a.test.size() > 50);
  CHECK(a.test.size() < 110);
  std::set<fs::path> test_a(a.test.begin(), a.test.end()), test_b(b.test.begin(), b.test.end());
  CHECK(test_a == test_b);
  for (const auto& f : a.train) CHECK(test_a.count(f) == 0);
  // The split depends on the clip name, not its folder; another seed gives another split.
  CHECK(IsTestClip("clip_3", 0.2, 5) == (test_a.count("/mocap/clip_3.bvh") == 1));
  CHECK(IsTestClip("clip_3", 0.2, 5) == IsTestClip("clip_3", 0.2, 5));
  const ClipSplit c = SplitClips(files, 0.2, 6);
  CHECK(std::set<fs::path>(c.test.begin(), c.test.end()) != test_a);
  CHECK(SplitClips(files, 0.0).test.empty());
}

TEST_CASE("collecting BVH files from folders is sorted; missing inputs error", "[pose_library][data]") {
  auto files = CollectBvhFiles({Mocap("cmu_cgspeed_assimp")});
  REQUIRE(files.ok());
  REQUIRE(files->size() == 3);
  CHECK(std::is_sorted(files->begin(), files->end()));
  auto bad = CollectBvhFiles({Mocap("nope")});
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.status().code() == ErrorCode::kNotFound);
}

TEST_CASE("collecting BVH files follows linked folders once; a folder without clips errors",
          "[pose_library][data]") {
  const fs::path dir = poseforest::testing::ScratchDir("bvh-links");
  fs::create_directories(dir / "set");
  // A data set made of links: a linked clip folder, the same folder linked twice, and a link
  // back up the tree (a loop unless each real folder is listed once).
  fs::create_directory_symlink(fs::absolute(Mocap("cmu_cgspeed_assimp")), dir / "set" / "cmu");
  fs::create_directory_symlink(fs::absolute(Mocap("cmu_cgspeed_assimp")), dir / "set" / "cmu_again");
  fs::create_directory_symlink(dir, dir / "set" / "up");
  auto files = CollectBvhFiles({dir / "set"});
  REQUIRE(files.ok());
  CHECK(files->size() == 3);  // the folder's three clips, once, under the first path
  for (const auto& f : *files) CHECK(f.parent_path().filename() == "cmu");
  CHECK(std::is_sorted(files->begin(), files->end()));
  for (const auto& f : *files) CHECK(f.extension() == ".bvh");
  fs::create_directories(dir / "empty" / "sub");
  auto none = CollectBvhFiles({dir / "empty"});
  REQUIRE_FALSE(none.ok());
  CHECK(none.status().code() == ErrorCode::kNotFound);
  CHECK_THAT(none.status().message(), Catch::Contains("no .bvh clips"));
}

TEST_CASE("building a library from clips records sources and thins frames", "[pose_library][data]") {
  BuildOptions opt;
  opt.max_frames_per_clip = 200;
  size_t calls = 0;
  opt.progress = [&](size_t, size_t, const fs::path&, size_t, size_t) { ++calls; };
  auto lib = BuildPoseLibrary(
      {Mocap("bandai_namco_1/dataset-1_bow_normal_001.bvh"), Mocap("cmu_iclone_cc3/002_01.bvh")}, opt);
  REQUIRE(lib.ok());
  CHECK(calls == 2);
  CHECK(lib->clips == std::vector<std::string>{"dataset-1_bow_normal_001", "002_01"});
  CHECK(lib->poses.size() > 20);
  CHECK(lib->poses.size() < 138 + 171);
  std::set<uint32_t> clips;
  for (const auto& s : lib->sources) clips.insert(s.clip);
  CHECK(clips.size() == 2);
  // A clip that does not load fails the build with that clip's name.
  auto bad = BuildPoseLibrary({Mocap("does_not_exist.bvh")}, opt);
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("does_not_exist.bvh"));
}
