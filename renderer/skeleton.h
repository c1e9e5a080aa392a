#pragma once
// The canonical skeleton every body and every mocap clip is mapped onto. Bodies supply rest
// joint positions (so bone lengths come from the body); poses supply bone rotations.
//
// Body frame: metres, Y up, the person faces +Z in the rest pose (T-pose: arms along +-X),
// the person's left is +X. The renderer places the body in the camera frame (x right, y down,
// z forward) with the scene transform.

#include <array>
#include <string_view>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace poseforest::renderer {

enum class SkelJoint : int {
  kPelvis = 0,  // root, between the hips
  kSpine,       // lower back / navel height
  kChest,       // upper spine, between the shoulder blades
  kNeck,        // base of the neck
  kHead,        // base of the skull (top of the neck)
  kHeadTop,     // end site: top of the head
  kLCollar, kLShoulder, kLElbow, kLWrist, kLHandTip,
  kRCollar, kRShoulder, kRElbow, kRWrist, kRHandTip,
  kLHip, kLKnee, kLAnkle, kLToe,
  kRHip, kRKnee, kRAnkle, kRToe,
};
inline constexpr int kNumSkelJoints = 24;

/// Parent of each joint (-1 for the root).
inline constexpr std::array<int, kNumSkelJoints> kSkelParent = {
    -1, 0, 1, 2, 3, 4,      // pelvis spine chest neck head headtop
    2, 6, 7, 8, 9,          // left arm from the chest
    2, 11, 12, 13, 14,      // right arm
    0, 16, 17, 18,          // left leg from the pelvis
    0, 20, 21, 22,          // right leg
};

/// Stable names ("pelvis", "L_elbow", ...), used by rig name maps and files.
std::string_view SkelJointName(int joint);

/// Joint positions in the body frame, metres.
using SkelPositions = std::array<Eigen::Vector3d, kNumSkelJoints>;

/// A pose: for each joint, the rotation (body frame) taking its rest-pose frame to its posed
/// frame; the bone from joint j to each child c is rotated by rotation[j]. Root translation is
/// the pelvis position relative to its rest position. Identity everywhere = the rest T-pose.
struct Pose {
  std::array<Eigen::Quaterniond, kNumSkelJoints> rotation;
  Eigen::Vector3d root_translation = Eigen::Vector3d::Zero();

  Pose() { rotation.fill(Eigen::Quaterniond::Identity()); }
};

/// Posed joint positions: posed[root] = rest[root] + root_translation,
/// posed[c] = posed[p] + rotation[p] * (rest[c] - rest[p]). Bone lengths are preserved.
SkelPositions PoseJoints(const SkelPositions& rest, const Pose& pose);

}  // namespace poseforest::renderer
