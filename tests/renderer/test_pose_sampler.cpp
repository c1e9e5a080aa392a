// Procedural pose sampler: deterministic, bone lengths kept, joints within limits.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <map>

#include "renderer/pose_sampler.h"
#include "renderer/procedural_body.h"
#include "renderer/synthetic_source.h"
#include "runtime/skeleton.h"

using namespace poseforest::renderer;

namespace {
const Eigen::Vector3d& J(const SkelPositions& s, SkelJoint j) { return s[size_t(int(j))]; }
double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / M_PI;
}
}  // namespace

TEST_CASE("procedural poses are a pure function of (seed, index)", "[pose]") {
  const Pose a = SampleProceduralPose(5, 17), b = SampleProceduralPose(5, 17),
             c = SampleProceduralPose(5, 18);
  bool same = true, differ = false;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    same = same && a.rotation[size_t(j)].coeffs() == b.rotation[size_t(j)].coeffs();
    differ = differ || !a.rotation[size_t(j)].coeffs().isApprox(c.rotation[size_t(j)].coeffs());
  }
  CHECK(same);
  CHECK(differ);
}

TEST_CASE("procedural poses keep bone lengths and respect joint limits", "[pose]") {
  const SkelPositions rest = ProceduralSkeleton(ProceduralBaseShape(11));
  int upright = 0, arms_raised = 0, knees_bent = 0;
  const int n = 2000;
  for (int i = 0; i < n; ++i) {
    const Pose pose = SampleProceduralPose(1234, uint64_t(i));
    const SkelPositions p = PoseJoints(rest, pose);
    for (int j = 1; j < kNumSkelJoints; ++j) {
      const int par = kSkelParent[size_t(j)];
      REQUIRE(std::abs(pose.rotation[size_t(j)].norm() - 1.0) < 1e-9);
      REQUIRE((p[size_t(j)] - p[size_t(par)]).norm() ==
              Approx((rest[size_t(j)] - rest[size_t(par)]).norm()).margin(1e-9));
    }
    for (int side = 0; side < 2; ++side) {
      const SkelJoint hip = side ? SkelJoint::kRHip : SkelJoint::kLHip;
      const SkelJoint knee = side ? SkelJoint::kRKnee : SkelJoint::kLKnee;
      const SkelJoint ankle = side ? SkelJoint::kRAnkle : SkelJoint::kLAnkle;
      const SkelJoint sh = side ? SkelJoint::kRShoulder : SkelJoint::kLShoulder;
      const SkelJoint el = side ? SkelJoint::kRElbow : SkelJoint::kLElbow;
      const SkelJoint wr = side ? SkelJoint::kRWrist : SkelJoint::kLWrist;
      // Knee and elbow flex within 0..150 degrees (never hyper-extend backwards a lot).
      const double knee_flex = AngleDeg(J(p, knee) - J(p, hip), J(p, ankle) - J(p, knee));
      const double elbow_flex = AngleDeg(J(p, el) - J(p, sh), J(p, wr) - J(p, el));
      REQUIRE(knee_flex <= 150.0);
      REQUIRE(elbow_flex <= 150.0);
      // The knee bends backwards: the shin turns towards -Z of the thigh's frame, i.e. the
      // ankle never moves in front of the thigh line by a large flexion.
      knees_bent += knee_flex > 30.0;
      arms_raised += J(p, el).y() > J(p, sh).y() + 0.05;
    }
    // The head stays above the pelvis in nearly all poses.
    upright += J(p, SkelJoint::kHeadTop).y() > J(p, SkelJoint::kPelvis).y() + 0.3;
  }
  CHECK(upright > n * 0.97);
  CHECK(arms_raised > n * 0.2);  // variety: arms up and down
  CHECK(arms_raised < n * 1.0);  // ... but most arms hang below the shoulder
  CHECK(knees_bent > n * 0.2);
}

TEST_CASE("FaceForward removes a pose's heading", "[pose]") {
  const SkelPositions rest = ProceduralSkeleton(ProceduralBaseShape(11));
  for (int i = 0; i < 50; ++i) {
    Pose pose = SampleProceduralPose(77, uint64_t(i));
    const Eigen::Quaterniond turn(Eigen::AngleAxisd(0.7 * i, Eigen::Vector3d::UnitY()));
    for (auto& q : pose.rotation) q = turn * q;  // a mocap clip walking off in some direction
    FaceForward(rest, &pose);
    const SkelPositions p = PoseJoints(rest, pose);
    Eigen::Vector3d left = (J(p, SkelJoint::kLHip) - J(p, SkelJoint::kRHip)) +
                           (J(p, SkelJoint::kLShoulder) - J(p, SkelJoint::kRShoulder));
    left.y() = 0;
    const Eigen::Vector3d facing = left.normalized().cross(Eigen::Vector3d::UnitY());
    CHECK(facing.z() == Approx(1.0).margin(1e-9));
    // Only a rotation about the vertical: heights are unchanged.
    const SkelPositions before = PoseJoints(rest, SampleProceduralPose(77, uint64_t(i)));
    for (int j = 0; j < kNumSkelJoints; ++j)
      CHECK(p[size_t(j)].y() == Approx(before[size_t(j)].y()).margin(1e-9));
  }
}

TEST_CASE("PerturbArms: arms toward the camera or near the body, the rest kept, deterministic", "[pose]") {
  const SkelPositions rest = ProceduralSkeleton(ProceduralBaseShape(11));
  const double shoulder_width = (J(rest, SkelJoint::kLShoulder) - J(rest, SkelJoint::kRShoulder)).norm();
  int changed_arms = 0, hands_forward = 0, hands_near_body = 0, arms = 0;
  const int n = 1000;
  for (int i = 0; i < n; ++i) {
    const Pose base = SampleProceduralPose(99, uint64_t(i));
    Pose pose = base, again = base;
    PerturbArms(3, uint64_t(i), &pose);
    PerturbArms(3, uint64_t(i), &again);
    for (int j = 0; j < kNumSkelJoints; ++j) REQUIRE(pose.rotation[size_t(j)].coeffs() == again.rotation[size_t(j)].coeffs());
    const SkelPositions b = PoseJoints(rest, base), p = PoseJoints(rest, pose);
    // Bone lengths kept; trunk, head, legs and collars untouched.
    for (int j = 1; j < kNumSkelJoints; ++j) {
      const int par = kSkelParent[size_t(j)];
      REQUIRE((p[size_t(j)] - p[size_t(par)]).norm() ==
              Approx((rest[size_t(j)] - rest[size_t(par)]).norm()).margin(1e-9));
    }
    for (SkelJoint j : {SkelJoint::kPelvis, SkelJoint::kChest, SkelJoint::kHeadTop, SkelJoint::kLShoulder,
                        SkelJoint::kRShoulder, SkelJoint::kLAnkle, SkelJoint::kRToe})
      REQUIRE((J(p, j) - J(b, j)).norm() < 1e-9);
    for (int side = 0; side < 2; ++side) {
      const SkelJoint sh = side ? SkelJoint::kRShoulder : SkelJoint::kLShoulder;
      const SkelJoint el = side ? SkelJoint::kRElbow : SkelJoint::kLElbow;
      const SkelJoint wr = side ? SkelJoint::kRWrist : SkelJoint::kLWrist;
      const SkelJoint tip = side ? SkelJoint::kRHandTip : SkelJoint::kLHandTip;
      if ((J(p, wr) - J(b, wr)).norm() < 1e-9) continue;  // this arm was left alone
      ++changed_arms;
      ++arms;
      REQUIRE(AngleDeg(J(p, el) - J(p, sh), J(p, wr) - J(p, el)) <= 150.0);
      // The hand ends in front of the shoulder (the person faces +Z) ...
      hands_forward += J(p, tip).z() > J(p, sh).z() + 0.15;
      // ... or near the face / chest: within a shoulder width of the chest-head line.
      const Eigen::Vector3d chest = J(p, SkelJoint::kChest), head = J(p, SkelJoint::kHead);
      const Eigen::Vector3d axis = (head - chest).normalized(), hand = J(p, tip) - chest;
      hands_near_body += (hand - hand.dot(axis) * axis).norm() < shoulder_width;
    }
  }
  INFO(changed_arms << " arms changed; hands forward " << hands_forward << ", near the body " << hands_near_body);
  CHECK(changed_arms > n * 1.2);  // both arms in 40 % of the poses, one in the others
  CHECK(changed_arms < n * 2);
  CHECK(hands_forward > arms * 0.6);
  CHECK(hands_near_body > arms * 0.3);
}

TEST_CASE("SitDown and LeanTrunk: thighs forward and knees bent; the trunk tilted; the rest kept", "[pose]") {
  const SkelPositions rest = ProceduralSkeleton(ProceduralBaseShape(5));
  const Eigen::Vector3d up(0, 1, 0), forward(0, 0, 1);
  int leaned_forward = 0;
  const int n = 500;
  for (int i = 0; i < n; ++i) {
    Pose base = SampleProceduralPose(7, uint64_t(i));
    base.rotation[0] = Eigen::Quaterniond::Identity();  // an upright pelvis: angles read off the axes
    Pose sat = base, sat2 = base, leaned = base, leaned2 = base;
    SitDown(11, uint64_t(i), &sat);
    SitDown(11, uint64_t(i), &sat2);
    LeanTrunk(11, uint64_t(i), &leaned);
    LeanTrunk(11, uint64_t(i), &leaned2);
    for (int j = 0; j < kNumSkelJoints; ++j) {
      REQUIRE(sat.rotation[size_t(j)].coeffs() == sat2.rotation[size_t(j)].coeffs());
      REQUIRE(leaned.rotation[size_t(j)].coeffs() == leaned2.rotation[size_t(j)].coeffs());
    }
    const SkelPositions b = PoseJoints(rest, base), s = PoseJoints(rest, sat), l = PoseJoints(rest, leaned);
    for (int j = 1; j < kNumSkelJoints; ++j) {  // bone lengths kept
      const int par = kSkelParent[size_t(j)];
      const double len = (rest[size_t(j)] - rest[size_t(par)]).norm();
      REQUIRE((s[size_t(j)] - s[size_t(par)]).norm() == Approx(len).margin(1e-9));
      REQUIRE((l[size_t(j)] - l[size_t(par)]).norm() == Approx(len).margin(1e-9));
    }
    // Sitting: trunk, head and arms untouched; each thigh 60-105 degrees from hanging straight
    // down, forward (+Z); each knee bent 55-110 degrees; the feet no higher than the knees.
    for (SkelJoint j : {SkelJoint::kPelvis, SkelJoint::kChest, SkelJoint::kHeadTop, SkelJoint::kLHandTip,
                        SkelJoint::kRWrist, SkelJoint::kLHip, SkelJoint::kRHip})
      REQUIRE((J(s, j) - J(b, j)).norm() < 1e-9);
    for (int side = 0; side < 2; ++side) {
      const SkelJoint hip = side ? SkelJoint::kRHip : SkelJoint::kLHip;
      const SkelJoint kn = side ? SkelJoint::kRKnee : SkelJoint::kLKnee;
      const SkelJoint an = side ? SkelJoint::kRAnkle : SkelJoint::kLAnkle;
      const Eigen::Vector3d thigh = J(s, kn) - J(s, hip), shin = J(s, an) - J(s, kn);
      CHECK(AngleDeg(thigh, -up) > 55.0);
      CHECK(AngleDeg(thigh, -up) < 110.0);
      CHECK(thigh.z() > 0);
      CHECK(AngleDeg(thigh, shin) > 50.0);
      CHECK(AngleDeg(thigh, shin) < 115.0);
      CHECK(J(s, an).y() < J(s, kn).y());
    }
    // Leaning: pelvis, hips and legs untouched; the spine-to-head direction turned 5-37 degrees
    // (15 back or 35 forward, 15 to the side at most); the spine joint itself is the pivot.
    for (SkelJoint j : {SkelJoint::kPelvis, SkelJoint::kSpine, SkelJoint::kLHip, SkelJoint::kRKnee,
                        SkelJoint::kLToe})
      REQUIRE((J(l, j) - J(b, j)).norm() < 1e-9);
    const Eigen::Vector3d before = J(b, SkelJoint::kHead) - J(b, SkelJoint::kSpine);
    const Eigen::Vector3d after = J(l, SkelJoint::kHead) - J(l, SkelJoint::kSpine);
    CHECK(AngleDeg(before, after) > 4.9);
    CHECK(AngleDeg(before, after) < 38.0);
    leaned_forward += after.normalized().dot(forward) > before.normalized().dot(forward);
    // The arms keep their pose relative to the chest.
    const Eigen::Quaterniond rel_b = base.rotation[size_t(int(SkelJoint::kChest))].conjugate() *
                                     base.rotation[size_t(int(SkelJoint::kLElbow))];
    const Eigen::Quaterniond rel_l = leaned.rotation[size_t(int(SkelJoint::kChest))].conjugate() *
                                     leaned.rotation[size_t(int(SkelJoint::kLElbow))];
    REQUIRE(rel_b.angularDistance(rel_l) < 1e-9);
  }
  CHECK(leaned_forward > n * 0.7);  // 80 % forward
  CHECK(leaned_forward < n * 0.9);
}

TEST_CASE("the skeleton fit's typical bone lengths match the body family's", "[pose]") {
  // runtime::TypicalBoneLength centres the kinematic fit's bone preference; here against the
  // evaluation joints of every procedural base shape (children to tall adults) in the rest pose.
  std::map<std::pair<int, int>, std::vector<double>> lengths;
  for (int s = 0; s < kNumProceduralShapes; ++s) {
    const auto joints = EvalJoints(ProceduralSkeleton(ProceduralBaseShape(s)));
    for (const auto& [a, b] : poseforest::runtime::SkeletonBones())
      lengths[{a, b}].push_back((joints[size_t(a)] - joints[size_t(b)]).norm());
  }
  for (const auto& [bone, v] : lengths) {
    std::vector<double> sorted = v;
    std::sort(sorted.begin(), sorted.end());
    const double median = sorted[sorted.size() / 2];
    const double typical = poseforest::runtime::TypicalBoneLength(bone.first, bone.second);
    INFO(poseforest::core::JointName(bone.first) << " - " << poseforest::core::JointName(bone.second) << ": family median "
                                                 << median << " m, typical " << typical << " m");
    CHECK(typical == Approx(median).epsilon(0.3));
    const auto [lo, hi] = poseforest::runtime::BoneLengthRange(bone.first, bone.second);
    CHECK(sorted.front() >= lo);  // every body of the family is possible
    CHECK(sorted.back() <= hi);
  }
}
