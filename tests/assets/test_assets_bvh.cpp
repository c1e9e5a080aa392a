// BVH loader: parsing, the quirks listed in /work/shared/data/SOURCES.md, normalisation, FK,
// and errors that name the file and line.

#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <sstream>

#include "renderer/assets/bvh.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer::assets;
using poseforest::core::ErrorCode;
namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

fs::path Mocap(const std::string& rel) { return poseforest::testing::DataDir() / "mocap" / rel; }

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteAll(const fs::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out << s;
}

// Root with 6 channels (given rotation order) and one child 10 units along +X.
std::string TwoJointBvh(const std::string& order, const std::string& frame) {
  return "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition " + order +
         "\n  JOINT Arm\n  {\n    OFFSET 10 0 0\n    CHANNELS 3 Zrotation Yrotation Xrotation\n"
         "    End Site\n    {\n      OFFSET 0 5 0\n    }\n  }\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n" +
         frame + "\n";
}

Eigen::Matrix3d R(char axis, double deg) {
  const Eigen::Vector3d a = axis == 'X'   ? Eigen::Vector3d::UnitX()
                            : axis == 'Y' ? Eigen::Vector3d::UnitY()
                                          : Eigen::Vector3d::UnitZ();
  return Eigen::AngleAxisd(deg * kPi / 180, a).toRotationMatrix();
}

std::string ErrorOf(const poseforest::core::Result<BvhClip>& r) { return r.ok() ? "" : r.status().message(); }

}  // namespace

TEST_CASE("rotation channel order is applied in file order (ZYX and ZXY)", "[bvh]") {
  BvhOptions raw;
  raw.normalize = false;
  const std::string angles = "0 0 0 30 40 50 0 0 0";
  for (const auto& [order, m] : {std::pair{std::string("Zrotation Yrotation Xrotation"),
                                           Eigen::Matrix3d(R('Z', 30) * R('Y', 40) * R('X', 50))},
                                 std::pair{std::string("Zrotation Xrotation Yrotation"),
                                           Eigen::Matrix3d(R('Z', 30) * R('X', 40) * R('Y', 50))},
                                 std::pair{std::string("Xrotation Yrotation Zrotation"),
                                           Eigen::Matrix3d(R('X', 30) * R('Y', 40) * R('Z', 50))}}) {
    auto clip = ParseBvh(TwoJointBvh(order, angles), "two.bvh", raw);
    REQUIRE(clip.ok());
    const auto p = ForwardKinematics(*clip, 0);
    REQUIRE(p.size() == 3);  // Hips, Arm, Arm_End
    const Eigen::Vector3d arm = m * Eigen::Vector3d(10, 0, 0);
    CHECK((p[1] - arm).norm() < 1e-9);
    CHECK((p[2] - (arm + m * Eigen::Vector3d(0, 5, 0))).norm() < 1e-9);
    CHECK(clip->joints[2].end_site);
    CHECK(clip->joints[2].name == "Arm_End");
  }
}

TEST_CASE("position channels replace the offset", "[bvh]") {
  BvhOptions raw;
  raw.normalize = false;
  auto clip = ParseBvh(TwoJointBvh("Zrotation Yrotation Xrotation", "1 2 3 0 0 0 0 0 0"), "t.bvh", raw);
  REQUIRE(clip.ok());
  const auto p = ForwardKinematics(*clip, 0);
  CHECK((p[0] - Eigen::Vector3d(1, 2, 3)).norm() < 1e-12);
  CHECK((p[1] - Eigen::Vector3d(11, 2, 3)).norm() < 1e-12);
}

TEST_CASE("tabs, CRLF and blank lines are tolerated", "[bvh]") {
  std::string text = TwoJointBvh("Zrotation Yrotation Xrotation", "0\t0\t0\t0\t0\t0\t0\t0\t90");
  std::string crlf;
  for (char c : text) {
    if (c == '\n')
      crlf += "\r\n";
    else
      crlf += c;
  }
  // A tab after `Frames:` as in the Bandai Namco files.
  const size_t f = crlf.find("Frames: 1");
  crlf.replace(f, 9, "Frames:\t1");
  auto clip = ParseBvh(crlf, "crlf.bvh", BvhOptions{false, -1});
  REQUIRE(clip.ok());
  CHECK(clip->num_frames == 1);
  CHECK(clip->Frame(0)[8] == 90.0);
}

TEST_CASE("malformed BVH text gives DataLoss naming file and line", "[bvh]") {
  const std::string good = TwoJointBvh("Zrotation Yrotation Xrotation", "0 0 0 0 0 0 0 0 0");
  SECTION("wrong number of values on a frame line") {
    std::string t = good;
    t.replace(t.rfind("0 0 0 0 0 0 0 0 0"), 17, "0 0 0 0 0 0 0 0");
    auto r = ParseBvh(t, "short.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kDataLoss);
    CHECK_THAT(ErrorOf(r), Catch::Contains("short.bvh:19:") && Catch::Contains("8 values, expected 9"));
  }
  SECTION("too many values") {
    std::string t = good;
    t.replace(t.rfind("0 0 0 0 0 0 0 0 0"), 17, "0 0 0 0 0 0 0 0 0 0");
    auto r = ParseBvh(t, "long.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("long.bvh:19:"));
  }
  SECTION("non-numeric value") {
    std::string t = good;
    t.replace(t.rfind("0 0 0 0 0 0 0 0 0"), 17, "0 0 0 0 abc 0 0 0 0");
    auto r = ParseBvh(t, "nan.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("nan.bvh:19:") && Catch::Contains("'abc' is not a number"));
  }
  SECTION("fewer frame lines than declared") {
    std::string t = good;
    t.replace(t.find("Frames: 1"), 9, "Frames: 3");
    auto r = ParseBvh(t, "few.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("few.bvh:") && Catch::Contains("1 of the 3 frames"));
  }
  SECTION("a wrong frame count: 'Frames: 0' before frames, or more lines after the frames than frames") {
    const std::string frame = "0 0 0 0 0 0 0 0 0\n";
    std::string zero = good;
    zero.replace(zero.find("Frames: 1"), 9, "Frames: 0");
    auto r0 = ParseBvh(zero, "zero.bvh");
    REQUIRE_FALSE(r0.ok());
    CHECK_THAT(ErrorOf(r0),
               Catch::Contains("zero.bvh:19:") && Catch::Contains("'Frames: 0', but 1 frame line"));
    auto empty = ParseBvh(zero.substr(0, zero.rfind(frame)), "empty.bvh");
    REQUIRE_FALSE(empty.ok());
    CHECK_THAT(ErrorOf(empty), Catch::Contains("empty.bvh:") && Catch::Contains("the clip has no frames"));
    auto more = ParseBvh(good + frame + frame, "more.bvh");
    REQUIRE_FALSE(more.ok());
    CHECK_THAT(ErrorOf(more), Catch::Contains("more.bvh:20:") &&
                                  Catch::Contains("2 non-blank lines after the 1 frames 'Frames:' declares"));
    // One stray line, as CMU's Boxing_Toes has, is tolerated and counted.
    auto stray = ParseBvh(good + frame, "stray.bvh");
    REQUIRE(stray.ok());
    CHECK(stray->num_frames == 1);
    CHECK(stray->ignored_trailing_lines == 1);
  }
  SECTION("bad OFFSET") {
    std::string t = good;
    t.replace(t.find("OFFSET 10 0 0"), 13, "OFFSET 10 x 0");
    auto r = ParseBvh(t, "off.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("off.bvh:8:"));
  }
  SECTION("unknown channel") {
    std::string t = good;
    t.replace(t.find("Xposition"), 9, "Wposition");
    auto r = ParseBvh(t, "chan.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("chan.bvh:5:") && Catch::Contains("Wposition"));
  }
  SECTION("not a BVH") {
    auto r = ParseBvh("hello\n", "x.bvh");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(ErrorOf(r), Catch::Contains("x.bvh:1:") && Catch::Contains("HIERARCHY"));
  }
}

TEST_CASE("missing file is NotFound", "[bvh]") {
  auto r = LoadBvh("/nonexistent/dir/none.bvh");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kNotFound);
  CHECK_THAT(r.status().message(), Catch::Contains("none.bvh"));
  const auto dir = poseforest::testing::ScratchDir("bvh-folder");
  std::filesystem::create_directories(dir / "clip.bvh");
  auto folder = LoadBvh(dir / "clip.bvh");
  REQUIRE_FALSE(folder.ok());
  CHECK(folder.status().code() == ErrorCode::kInvalidArgument);
  CHECK_THAT(folder.status().message(), Catch::Contains("clip.bvh: is a folder, not a file"));
  std::filesystem::remove_all(dir);
}

TEST_CASE("a truncated copy of a real file errors with its name and the line", "[bvh][data]") {
  const std::string text = ReadAll(Mocap("cmu_cgspeed_assimp/01_01.bvh"));
  REQUIRE(text.size() > 1000);
  const fs::path dir = poseforest::testing::ScratchDir("bvh-trunc");
  // Mid-hierarchy: cut after line 40.
  size_t pos = 0;
  for (int i = 0; i < 40; ++i) pos = text.find('\n', pos) + 1;
  const fs::path mid = dir / "mid_hierarchy.bvh";
  WriteAll(mid, text.substr(0, pos));
  auto r = LoadBvh(mid);
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(r.status().message(), Catch::Contains(mid.string() + ":40:") && Catch::Contains("truncated"));

  // Mid-motion: keep the header and 10 frames (the file declares 2752).
  pos = text.find("Frame Time:");
  pos = text.find('\n', pos) + 1;
  for (int i = 0; i < 10; ++i) pos = text.find('\n', pos) + 1;
  const fs::path motion = dir / "mid_motion.bvh";
  WriteAll(motion, text.substr(0, pos + 20));  // and a partial 11th line
  r = LoadBvh(motion);
  REQUIRE_FALSE(r.ok());
  CHECK_THAT(r.status().message(),
             Catch::Contains(motion.string() + ":198:") && Catch::Contains("values, expected 96"));
  fs::remove_all(dir);
}

TEST_CASE("Boxing_Toes: reads exactly Frames: lines, ZXY channel order, cm", "[bvh][data]") {
  auto clip = LoadBvh(Mocap("cmu_cgspeed_assimp/Boxing_Toes.bvh"));
  REQUIRE(clip.ok());
  CHECK(clip->declared_frames == 3069);
  CHECK(clip->num_frames == 3069);
  CHECK(clip->ignored_trailing_lines == 1);
  CHECK(clip->family == SkeletonFamily::kBiovision);
  CHECK(clip->unit_to_m == Approx(0.01));
  const auto& hips = clip->joints[size_t(clip->FindJoint("Hips"))];
  REQUIRE(hips.channels.size() == 6);
  CHECK(hips.channels[3] == BvhChannel::kZrot);
  CHECK(hips.channels[4] == BvhChannel::kXrot);
  CHECK(hips.channels[5] == BvhChannel::kYrot);
  // Standing boxer: head above hips, height in metres.
  const auto p = ForwardKinematics(*clip, 0);
  const double head = p[size_t(clip->FindJoint("Head_End"))].y();
  const double toe =
      std::min(p[size_t(clip->FindJoint("LeftToes"))].y(), p[size_t(clip->FindJoint("RightToes"))].y());
  CHECK(head - toe > 1.5);
  CHECK(head - toe < 1.95);
}

TEST_CASE("cgspeed CMU: T-pose frame 0 dropped, units 0.0564 m, ZYX", "[bvh][data]") {
  BvhOptions raw;
  raw.normalize = false;
  auto orig = LoadBvh(Mocap("cmu_cgspeed_assimp/01_01.bvh"), raw);
  auto clip = LoadBvh(Mocap("cmu_cgspeed_assimp/01_01.bvh"));
  REQUIRE(orig.ok());
  REQUIRE(clip.ok());
  CHECK(clip->family == SkeletonFamily::kCmuCgspeed);
  CHECK(orig->num_frames == 2752);
  CHECK(clip->num_frames == 2751);
  CHECK(clip->dropped_leading_frames == 1);
  CHECK(clip->unit_to_m == Approx(0.0564).epsilon(0.01));
  // Frame 0 of the file is the T-pose: arms horizontal. The kept frame 0 is the file's frame 1.
  const auto t = ForwardKinematics(*orig, 0);
  const Eigen::Vector3d arm = t[size_t(orig->FindJoint("LeftHand"))] - t[size_t(orig->FindJoint("LeftArm"))];
  CHECK(std::abs(arm.normalized().y()) < 0.1);
  CHECK(std::equal(clip->Frame(0), clip->Frame(0) + clip->num_channels, orig->Frame(1)));
  const auto& hips = clip->joints[0];
  CHECK(hips.channels[3] == BvhChannel::kZrot);
  CHECK(hips.channels[4] == BvhChannel::kYrot);
  CHECK(hips.channels[5] == BvhChannel::kXrot);
  // Metres: hips about 1 m above the floor, thigh ~0.4 m.
  const auto p = ForwardKinematics(*clip, 0);
  CHECK(p[0].y() > 0.8);
  CHECK(p[0].y() < 1.15);
  const double thigh =
      (p[size_t(clip->FindJoint("LeftLeg"))] - p[size_t(clip->FindJoint("LeftUpLeg"))]).norm();
  CHECK(thigh == Approx(0.40).margin(0.05));
}

TEST_CASE("iClone RL_BoneRoot clips: Z-up hierarchy comes out Y-up, cm -> m", "[bvh][data]") {
  // Walking clips (upright in every frame): two RL_BoneRoot files and one CC_Base_Hip file.
  for (const char* name :
       {"cmu_iclone_cc3/002_01.bvh", "cmu_iclone_cc3/007_01.bvh", "cmu_iclone_cc3/007_12.bvh"}) {
    auto clip = LoadBvh(Mocap(name), BvhOptions{true, 60});
    REQUIRE(clip.ok());
    CHECK(clip->family == SkeletonFamily::kReallusionCC3);
    CHECK(clip->unit_to_m == Approx(0.01));
    CHECK(clip->dropped_leading_frames == 0);  // frame 0 is already motion
    const bool rl_root = clip->joints[0].name == "RL_BoneRoot";
    CHECK(clip->z_up_hierarchy == rl_root);
    for (int f = 0; f < clip->num_frames; f += 20) {
      const auto p = ForwardKinematics(*clip, f);
      const Eigen::Vector3d head = p[size_t(clip->FindJoint("CC_Base_Head"))];
      const Eigen::Vector3d hip = p[size_t(clip->FindJoint("CC_Base_Hip"))];
      const Eigen::Vector3d foot = p[size_t(clip->FindJoint("CC_Base_L_Foot"))];
      INFO(name << " frame " << f);
      CHECK(head.y() - hip.y() > 0.4);  // upright along +Y
      CHECK(std::abs(head.z() - hip.z()) < 0.25);
      CHECK(head.y() - foot.y() > 1.35);  // standing/walking adult, metres
      CHECK(head.y() - foot.y() < 1.9);
    }
  }
}

TEST_CASE("Z-up data is rotated to Y-up", "[bvh]") {
  // A little figure standing along +Z with no root rotation to fix it.
  const std::string t =
      "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation "
      "Xrotation\n"
      " JOINT Neck\n {\n  OFFSET 0 0 50\n  CHANNELS 3 Zrotation Yrotation Xrotation\n"
      "  JOINT Head\n  {\n   OFFSET 0 0 10\n   CHANNELS 3 Zrotation Yrotation Xrotation\n"
      "   End Site\n   {\n    OFFSET 0 0 10\n   }\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n"
      "0 0 90 0 0 0 0 0 0 0 0 0\n0 0 90 0 0 0 0 0 0 0 0 0\n";
  auto clip = ParseBvh(t, "zup.bvh");
  REQUIRE(clip.ok());
  CHECK(clip->z_up_input);
  const auto p = ForwardKinematics(*clip, 0);
  const Eigen::Vector3d up = p[size_t(clip->FindJoint("Head"))] - p[0];
  CHECK(up.normalized().y() > 0.99);
}

TEST_CASE("Bandai Namco: position channels on every joint, TAB header, cm", "[bvh][data]") {
  auto clip = LoadBvh(Mocap("bandai_namco_1/dataset-1_bow_normal_001.bvh"));
  REQUIRE(clip.ok());
  CHECK(clip->family == SkeletonFamily::kBandaiNamco);
  CHECK(clip->frame_time_s == Approx(1.0 / 30).epsilon(0.001));
  CHECK(clip->num_channels == 22 * 6);
  CHECK_FALSE(clip->z_up_hierarchy);
  CHECK_FALSE(clip->z_up_input);
  const auto p = ForwardKinematics(*clip, 0);
  const double height = p[size_t(clip->FindJoint("Head_End"))].y() - p[size_t(clip->FindJoint("Toes_L"))].y();
  CHECK(height > 1.35);
  CHECK(height < 1.9);
}

TEST_CASE("a BVH cut at every byte never crashes; cuts before the last frame are errors", "[bvh]") {
  const std::string good = TwoJointBvh("Zrotation Xrotation Yrotation", "1 2 3 10 20 30 40 50 60");
  const size_t last_line = good.rfind("1 2 3");
  size_t errors = 0;
  for (size_t n = 0; n < good.size(); ++n) {
    auto r = ParseBvh(good.substr(0, n), "cut.bvh");
    if (!r.ok()) {
      ++errors;
      CHECK(r.status().code() == ErrorCode::kDataLoss);
      CHECK_THAT(r.status().message(), Catch::StartsWith("cut.bvh:"));
    } else {
      // Only a cut inside the last value or its line end can still parse.
      CHECK(n >= good.size() - 4);
      CHECK(r->num_frames == 1);
    }
    if (n <= last_line) CHECK_FALSE(r.ok());
  }
  CHECK(errors >= last_line);
}
