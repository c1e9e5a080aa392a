// Retargeting: bone directions follow the source, bone lengths stay the target's, facing is
// normalised to +Z, known poses land where expected, unknown rigs error clearly.

#include <catch2/catch.hpp>
#include <cmath>
#include <map>
#include <sstream>

#include "renderer/assets/bvh.h"
#include "renderer/assets/retarget.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;
using poseforest::core::ErrorCode;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct JointSpec {
  std::string name, parent;
  Eigen::Vector3d offset;  // cm
  bool end = false;
};

// A Bandai-Namco-named T-pose figure (cm), facing +Z, left = +X.
std::vector<JointSpec> TinySkeleton() {
  std::vector<JointSpec> j = {
      {"Hips", "", {0, 0, 0}},       {"Spine", "Hips", {0, 15, 0}}, {"Chest", "Spine", {0, 20, 0}},
      {"Neck", "Chest", {0, 17, 0}}, {"Head", "Neck", {0, 11, 0}},  {"Head_End", "Head", {0, 17, 0}, true},
  };
  for (int s : {1, -1}) {
    const std::string S = s > 0 ? "_L" : "_R";
    j.push_back({"Shoulder" + S, "Chest", {3.0 * s, 13, 0}});
    j.push_back({"UpperArm" + S, "Shoulder" + S, {15.0 * s, 0, 0}});
    j.push_back({"LowerArm" + S, "UpperArm" + S, {29.0 * s, 0, 0}});
    j.push_back({"Hand" + S, "LowerArm" + S, {26.0 * s, 0, 0}});
    j.push_back({"Hand" + S + "_End", "Hand" + S, {18.0 * s, 0, 0}, true});
    j.push_back({"UpperLeg" + S, "Hips", {9.0 * s, -3, 0}});
    j.push_back({"LowerLeg" + S, "UpperLeg" + S, {0, -42, 0}});
    j.push_back({"Foot" + S, "LowerLeg" + S, {0, -42, 0}});
    j.push_back({"Toes" + S, "Foot" + S, {0, -6, 13}});
    j.push_back({"Toes" + S + "_End", "Toes" + S, {0, 0, 5}, true});
  }
  return j;
}

// BVH text for `joints`, each frame a map joint -> (Z, Y, X) degrees; the root is at (0, 95, 0)
// plus `root_offset` and turned by `root_yaw` degrees about Y.
std::string MakeBvh(const std::vector<JointSpec>& joints,
                    const std::vector<std::map<std::string, Eigen::Vector3d>>& frames, double root_yaw = 0) {
  std::ostringstream o;
  o << "HIERARCHY\n";
  std::vector<std::string> order;
  std::function<void(const std::string&, int)> emit = [&](const std::string& name, int depth) {
    const JointSpec* js = nullptr;
    for (const auto& j : joints)
      if (j.name == name) js = &j;
    const std::string ind(size_t(depth) * 2, ' ');
    if (js->end) {
      o << ind << "End Site\n"
        << ind << "{\n"
        << ind << "  OFFSET " << js->offset.transpose() << "\n"
        << ind << "}\n";
      return;
    }
    o << ind << (js->parent.empty() ? "ROOT " : "JOINT ") << name << "\n" << ind << "{\n";
    o << ind << "  OFFSET " << js->offset.transpose() << "\n";
    o << ind << "  CHANNELS " << (js->parent.empty() ? "6 Xposition Yposition Zposition " : "3 ")
      << "Zrotation Yrotation Xrotation\n";
    order.push_back(name);
    for (const auto& c : joints)
      if (c.parent == name) emit(c.name, depth + 1);
    o << ind << "}\n";
  };
  emit("Hips", 0);
  o << "MOTION\nFrames: " << frames.size() << "\nFrame Time: 0.0333333\n";
  for (const auto& f : frames) {
    for (const auto& name : order) {
      Eigen::Vector3d zyx = Eigen::Vector3d::Zero();
      if (auto it = f.find(name); it != f.end()) zyx = it->second;
      if (name == "Hips") {
        o << "0 95 0 ";
        zyx.y() += root_yaw;
      }
      o << zyx.x() << " " << zyx.y() << " " << zyx.z() << " ";
    }
    o << "\n";
  }
  return o.str();
}

Eigen::Vector3d P(const SkelPositions& s, SkelJoint j) { return s[size_t(int(j))]; }

// Bones whose direction the retargeting matches exactly (all but the rigid pelvis->hip and
// chest->collar offsets).
std::vector<std::pair<int, int>> MatchedBones() {
  std::vector<std::pair<int, int>> b;
  for (int c = 1; c < kNumSkelJoints; ++c) {
    const int p = kSkelParent[size_t(c)];
    const SkelJoint pc = SkelJoint(p), cc = SkelJoint(c);
    if (pc == SkelJoint::kPelvis && cc != SkelJoint::kSpine) continue;
    if (pc == SkelJoint::kChest && cc != SkelJoint::kNeck) continue;
    b.push_back({p, c});
  }
  return b;
}

}  // namespace

TEST_CASE("raising the left arm 90 degrees puts elbow and wrist straight above the shoulder", "[retarget]") {
  const auto skel = TinySkeleton();
  const std::string text = MakeBvh(skel, {{}, {{"UpperArm_L", {90, 0, 0}}}});
  auto clip = ParseBvh(text, "tiny.bvh");
  REQUIRE(clip.ok());
  CHECK(clip->family == SkeletonFamily::kBandaiNamco);
  const SkelPositions& rest = ReferenceRestJoints();
  auto poses = RetargetClip(*clip, rest);
  REQUIRE(poses.ok());
  REQUIRE(poses->size() == 2);

  // Frame 0 is the source T-pose: joints keep their directions, so posing the reference T-pose
  // changes each bone direction only as much as the two T-poses differ.
  const auto p0 = PoseJoints(rest, (*poses)[0]);
  const auto p1 = PoseJoints(rest, (*poses)[1]);
  const double upper = (P(rest, SkelJoint::kLElbow) - P(rest, SkelJoint::kLShoulder)).norm();
  const double fore = (P(rest, SkelJoint::kLWrist) - P(rest, SkelJoint::kLElbow)).norm();
  const Eigen::Vector3d sh = P(p1, SkelJoint::kLShoulder);
  CHECK((P(p1, SkelJoint::kLElbow) - (sh + Eigen::Vector3d(0, upper, 0))).norm() < 1e-9);
  CHECK((P(p1, SkelJoint::kLWrist) - (sh + Eigen::Vector3d(0, upper + fore, 0))).norm() < 1e-9);
  // The right arm stays horizontal, pointing to -X.
  const Eigen::Vector3d rdir = (P(p1, SkelJoint::kRWrist) - P(p1, SkelJoint::kRElbow)).normalized();
  CHECK((rdir - Eigen::Vector3d(-1, 0, 0)).norm() < 1e-9);
  // Everything but the left arm is as in frame 0.
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const SkelJoint s = SkelJoint(j);
    if (s == SkelJoint::kLElbow || s == SkelJoint::kLWrist || s == SkelJoint::kLHandTip) continue;
    CHECK((p0[size_t(j)] - p1[size_t(j)]).norm() < 1e-9);
  }
  // Standing frame: the pelvis stays at its rest height (feet on the same floor).
  CHECK(std::abs((*poses)[0].root_translation.y()) < 0.03);
}

TEST_CASE("retargeting a skeleton onto itself reproduces the source joints", "[retarget]") {
  const auto skel = TinySkeleton();
  std::vector<std::map<std::string, Eigen::Vector3d>> frames;
  for (int f = 0; f < 12; ++f) {
    const double a = 10.0 * f;
    frames.push_back({{"Hips", {5, 3.0 * f, 2}},
                      {"Spine", {a / 4, a / 3, -a / 5}},
                      {"Neck", {-a / 3, a / 2, a / 4}},
                      {"Head", {a / 2, -a / 3, a / 5}},
                      {"Shoulder_L", {a / 5, a / 6, 0}},
                      {"UpperArm_L", {a, -a / 2, a / 3}},
                      {"LowerArm_L", {0, 2 * a, 0}},
                      {"Hand_L", {a, a, a}},
                      {"UpperArm_R", {-a, a / 3, -a / 2}},
                      {"LowerArm_R", {0, -a, 0}},
                      {"UpperLeg_L", {a / 2, 0, -a}},
                      {"LowerLeg_L", {0, 0, a}},
                      {"Foot_L", {0, 0, -a / 2}},
                      {"UpperLeg_R", {-a / 3, a / 2, a / 2}},
                      {"LowerLeg_R", {0, 0, 1.5 * a}}});
  }
  auto clip = ParseBvh(MakeBvh(skel, frames), "self.bvh");
  REQUIRE(clip.ok());
  auto tracks = ExtractCanonicalTracks(*clip);
  REQUIRE(tracks.ok());
  // Target = the source's own T-pose (frame with all rotations zero).
  auto tpose_clip = ParseBvh(MakeBvh(skel, {{}}), "tpose.bvh");
  REQUIRE(tpose_clip.ok());
  auto tpose = ExtractCanonicalTracks(*tpose_clip);
  REQUIRE(tpose.ok());
  const SkelPositions rest = tpose->frames[0];
  RetargetOptions opt;
  opt.facing = FacingMode::kFirstFrame;
  const auto poses = RetargetTracks(*tracks, rest, opt);
  const Eigen::Quaterniond yaw =
      Eigen::Quaterniond::FromTwoVectors(FacingDirection(tracks->frames[0]), Eigen::Vector3d::UnitZ());
  for (size_t f = 0; f < poses.size(); ++f) {
    const auto posed = PoseJoints(rest, poses[f]);
    const auto& src = tracks->frames[f];
    for (int j = 0; j < kNumSkelJoints; ++j) {
      const Eigen::Vector3d want = yaw * (src[size_t(j)] - P(src, SkelJoint::kPelvis));
      const Eigen::Vector3d got = posed[size_t(j)] - P(posed, SkelJoint::kPelvis);
      INFO("frame " << f << " joint " << SkelJointName(j));
      CHECK((want - got).norm() < 1e-6);
    }
  }
}

TEST_CASE("retargeting real clips keeps target bone lengths and source bone directions", "[retarget][data]") {
  const auto dir = poseforest::testing::DataDir() / "mocap";
  // A shorter, child-like target: bone lengths differ from every source.
  SkelPositions target = ReferenceRestJoints();
  for (auto& j : target) j *= 0.7;
  for (const char* name : {"bandai_namco_1/dataset-1_bow_normal_001.bvh", "cmu_cgspeed_assimp/01_01.bvh",
                           "cmu_iclone_cc3/002_01.bvh", "cmu_cgspeed_assimp/Boxing_Toes.bvh",
                           "cmu_misc/10_01_soccer_kick_30fps.bvh"}) {
    BvhOptions bo;
    bo.max_frames = 150;
    auto clip = LoadBvh(dir / name, bo);
    REQUIRE(clip.ok());
    auto tracks = ExtractCanonicalTracks(*clip);
    REQUIRE(tracks.ok());
    const auto poses = RetargetTracks(*tracks, target);
    REQUIRE(poses.size() == size_t(clip->num_frames));
    double worst_len = 0, worst_dir = 0, worst_facing = 0;
    for (size_t f = 0; f < poses.size(); f += 7) {
      const auto posed = PoseJoints(target, poses[f]);
      const auto& src = tracks->frames[f];
      const Eigen::Quaterniond yaw =
          Eigen::Quaterniond::FromTwoVectors(FacingDirection(src), Eigen::Vector3d::UnitZ());
      for (int c = 1; c < kNumSkelJoints; ++c) {
        const int p = kSkelParent[size_t(c)];
        worst_len = std::max(worst_len, std::abs((posed[size_t(c)] - posed[size_t(p)]).norm() -
                                                 (target[size_t(c)] - target[size_t(p)]).norm()));
      }
      for (auto [p, c] : MatchedBones()) {
        const Eigen::Vector3d s = yaw * (src[size_t(c)] - src[size_t(p)]);
        if (s.norm() < 1e-6) continue;
        worst_dir =
            std::max(worst_dir, (s.normalized() - (posed[size_t(c)] - posed[size_t(p)]).normalized()).norm());
      }
      // Every retargeted pose faces +Z (the source exactly after the yaw; the target almost).
      CHECK((FacingDirection([&] {
               SkelPositions y;
               for (int j = 0; j < kNumSkelJoints; ++j) y[size_t(j)] = yaw * src[size_t(j)];
               return y;
             }()) -
             Eigen::Vector3d::UnitZ())
                .norm() < 1e-9);
      worst_facing = std::max(worst_facing, (FacingDirection(posed) - Eigen::Vector3d::UnitZ()).norm());
    }
    INFO(name);
    CHECK(worst_len < 1e-9);
    CHECK(worst_dir < 1e-6);
    CHECK(worst_facing < 0.01);  // the target's own hip/shoulder lines differ slightly
  }
}

TEST_CASE("facing: a clip turned about Y retargets to the same poses", "[retarget]") {
  const auto skel = TinySkeleton();
  const std::vector<std::map<std::string, Eigen::Vector3d>> frames = {
      {{"UpperArm_L", {40, 20, 0}}, {"LowerLeg_R", {0, 0, 30}}},
      {{"UpperArm_R", {-60, 0, 10}}, {"Spine", {10, 0, 20}}}};
  auto a = ParseBvh(MakeBvh(skel, frames, 0), "a.bvh");
  auto b = ParseBvh(MakeBvh(skel, frames, 137), "b.bvh");
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  auto pa = RetargetClip(*a, ReferenceRestJoints());
  auto pb = RetargetClip(*b, ReferenceRestJoints());
  REQUIRE(pa.ok());
  REQUIRE(pb.ok());
  for (size_t f = 0; f < frames.size(); ++f) {
    const auto ja = PoseJoints(ReferenceRestJoints(), (*pa)[f]);
    const auto jb = PoseJoints(ReferenceRestJoints(), (*pb)[f]);
    for (int j = 0; j < kNumSkelJoints; ++j) CHECK((ja[size_t(j)] - jb[size_t(j)]).norm() < 1e-9);
  }
}

TEST_CASE("unknown bone names: the error lists the missing canonical joints and the file", "[retarget]") {
  auto skel = TinySkeleton();
  for (auto& j : skel) {
    if (j.name.find("Arm") != std::string::npos) j.name = "Limb" + j.name;
    if (j.parent.find("Arm") != std::string::npos) j.parent = "Limb" + j.parent;
  }
  auto clip = ParseBvh(MakeBvh(skel, {{}}), "/data/odd_rig.bvh");
  REQUIRE(clip.ok());
  CHECK(clip->family == SkeletonFamily::kUnknown);
  auto r = RetargetClip(*clip, ReferenceRestJoints());
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kInvalidArgument);
  const std::string m = r.status().message();
  CHECK_THAT(m, Catch::Contains("/data/odd_rig.bvh") && Catch::Contains("L_shoulder") &&
                    Catch::Contains("R_elbow") && Catch::Contains("L_elbow") &&
                    Catch::Contains("UpperArm_L"));
  CHECK_THAT(m, !Catch::Contains("L_knee") && !Catch::Contains("L_wrist"));
}

TEST_CASE("name maps resolve prefixed names and report families", "[retarget]") {
  std::vector<std::string> names;
  for (const char* n :
       {"Hips",        "Spine",        "Spine1",    "Spine2",      "Neck",        "Head",
        "HeadTop_End", "LeftShoulder", "LeftArm",   "LeftForeArm", "LeftHand",    "RightShoulder",
        "RightArm",    "RightForeArm", "RightHand", "LeftUpLeg",   "LeftLeg",     "LeftFoot",
        "LeftToeBase", "RightUpLeg",   "RightLeg",  "RightFoot",   "RightToeBase"})
    names.push_back(std::string("mixamorig:") + n);
  std::string family;
  auto r = ResolveJoints(names, MeshRigNameMaps(), "x.glb", &family);
  REQUIRE(r.ok());
  CHECK(family == "mixamo");
  CHECK(names[size_t((*r)[size_t(int(SkelJoint::kChest))])] == "mixamorig:Spine2");
  CHECK(names[size_t((*r)[size_t(int(SkelJoint::kRElbow))])] == "mixamorig:RightForeArm");
}

TEST_CASE("AdaptPose carries a reference-pose to an A-pose body with the same bone directions",
          "[retarget]") {
  // An A-pose target: arms 45 degrees down, legs apart, different proportions.
  SkelPositions a = ReferenceRestJoints();
  for (auto& j : a) j *= 0.8;
  for (int side : {1, -1}) {
    const bool l = side > 0;
    const Eigen::Vector3d sh = a[size_t(int(l ? SkelJoint::kLShoulder : SkelJoint::kRShoulder))];
    const Eigen::Vector3d d = Eigen::Vector3d(side * std::sqrt(0.5), -std::sqrt(0.5), 0);
    a[size_t(int(l ? SkelJoint::kLElbow : SkelJoint::kRElbow))] = sh + 0.23 * d;
    a[size_t(int(l ? SkelJoint::kLWrist : SkelJoint::kRWrist))] = sh + 0.44 * d;
    a[size_t(int(l ? SkelJoint::kLHandTip : SkelJoint::kRHandTip))] = sh + 0.58 * d;
  }
  auto clip = LoadBvh(poseforest::testing::DataDir() / "mocap" / "cmu_iclone_cc3" / "005_02.bvh",
                      BvhOptions{true, 200});
  REQUIRE(clip.ok());
  auto poses = RetargetClip(*clip, ReferenceRestJoints());
  REQUIRE(poses.ok());
  double worst = 0, worst_floor = 0;
  for (size_t f = 0; f < poses->size(); f += 5) {
    const auto ref = PoseJoints(ReferenceRestJoints(), (*poses)[f]);
    const Pose adapted = AdaptPose((*poses)[f], a);
    const auto got = PoseJoints(a, adapted);
    for (auto [p, c] : MatchedBones()) {
      const Eigen::Vector3d want = ref[size_t(c)] - ref[size_t(p)];
      if (want.norm() < 1e-6) continue;
      worst = std::max(worst, (want.normalized() - (got[size_t(c)] - got[size_t(p)]).normalized()).norm());
    }
    // Feet: the adapted pose's lowest foot joint is as far above the A-body's floor as the
    // reference pose's is above the reference floor, times the leg-length ratio (0.8).
    auto low = [](const SkelPositions& s) {
      return std::min({s[size_t(int(SkelJoint::kLAnkle))].y(), s[size_t(int(SkelJoint::kRAnkle))].y(),
                       s[size_t(int(SkelJoint::kLToe))].y(), s[size_t(int(SkelJoint::kRToe))].y()});
    };
    worst_floor =
        std::max(worst_floor, std::abs((low(got) - low(a)) - 0.8 * (low(ref) - low(ReferenceRestJoints()))));
  }
  CHECK(worst < 1e-6);
  CHECK(worst_floor < 1e-9);
  // Identity on the reference body itself.
  const Pose same = AdaptPose((*poses)[10], ReferenceRestJoints());
  const auto j0 = PoseJoints(ReferenceRestJoints(), (*poses)[10]);
  const auto j1 = PoseJoints(ReferenceRestJoints(), same);
  for (int j = 0; j < kNumSkelJoints; ++j) CHECK((j0[size_t(j)] - j1[size_t(j)]).norm() < 1e-6);
}

TEST_CASE("canonical tracks of cm clips have adult standing heights in metres", "[retarget][data]") {
  const auto dir = poseforest::testing::DataDir() / "mocap";
  for (const char* name :
       {"cmu_iclone_cc3/002_01.bvh", "cmu_iclone_cc3/007_12.bvh", "cmu_cgspeed_assimp/Boxing_Toes.bvh"}) {
    auto clip = LoadBvh(dir / name, BvhOptions{true, 30});
    REQUIRE(clip.ok());
    auto tracks = ExtractCanonicalTracks(*clip);
    REQUIRE(tracks.ok());
    const auto& s = tracks->frames[0];
    const double height = P(s, SkelJoint::kHeadTop).y() - tracks->floor_y_m;
    INFO(name << " height " << height);
    CHECK(height > 1.6);
    CHECK(height < 1.9);
    CHECK(tracks->leg_length_m > 0.75);
    CHECK(tracks->leg_length_m < 1.0);
  }
}
