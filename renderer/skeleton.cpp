#include "renderer/skeleton.h"

namespace poseforest::renderer {
namespace {
constexpr std::array<std::string_view, kNumSkelJoints> kNames = {
    "pelvis",  "spine",   "chest",   "neck",     "head",       "head_top",
    "L_collar", "L_shoulder", "L_elbow", "L_wrist", "L_hand_tip",
    "R_collar", "R_shoulder", "R_elbow", "R_wrist", "R_hand_tip",
    "L_hip",   "L_knee",  "L_ankle", "L_toe",
    "R_hip",   "R_knee",  "R_ankle", "R_toe",
};
}  // namespace

std::string_view SkelJointName(int joint) { return kNames.at(size_t(joint)); }

SkelPositions PoseJoints(const SkelPositions& rest, const Pose& pose) {
  SkelPositions posed;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const int p = kSkelParent[size_t(j)];
    if (p < 0) {
      posed[size_t(j)] = rest[size_t(j)] + pose.root_translation;
    } else {
      posed[size_t(j)] = posed[size_t(p)] + pose.rotation[size_t(p)] * (rest[size_t(j)] - rest[size_t(p)]);
    }
  }
  return posed;
}

}  // namespace poseforest::renderer
