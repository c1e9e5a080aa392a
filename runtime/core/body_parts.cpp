#include "runtime/core/body_parts.h"

#include "runtime/core/result.h"

namespace poseforest::core {
namespace {

struct PartInfo {
  std::string_view name;
  Rgb colour;
  int mirror;
};

// Colours: left parts warm/saturated, right parts their cooler counterparts, so a left/right
// confusion is visible at a glance. Order follows enum Part.
constexpr std::array<PartInfo, kNumParts> kParts{{
    {"LU_head", {255, 0, 0}, 1},
    {"RU_head", {255, 128, 128}, 0},
    {"LW_head", {200, 0, 100}, 3},
    {"RW_head", {255, 150, 220}, 2},
    {"neck", {255, 255, 0}, 4},
    {"L_shoulder", {255, 128, 0}, 6},
    {"R_shoulder", {255, 200, 120}, 5},
    {"LU_arm", {0, 160, 0}, 8},
    {"RU_arm", {140, 255, 140}, 7},
    {"LW_arm", {0, 90, 60}, 10},
    {"RW_arm", {100, 220, 180}, 9},
    {"L_elbow", {128, 64, 0}, 12},
    {"R_elbow", {200, 160, 100}, 11},
    {"L_wrist", {128, 0, 128}, 14},
    {"R_wrist", {220, 140, 255}, 13},
    {"L_hand", {0, 0, 255}, 16},
    {"R_hand", {120, 160, 255}, 15},
    {"LU_torso", {0, 128, 128}, 18},
    {"RU_torso", {0, 255, 255}, 17},
    {"LW_torso", {64, 64, 160}, 20},
    {"RW_torso", {150, 150, 255}, 19},
    {"LU_leg", {128, 128, 0}, 22},
    {"RU_leg", {220, 220, 90}, 21},
    {"LW_leg", {100, 40, 40}, 24},
    {"RW_leg", {220, 120, 120}, 23},
    {"L_knee", {160, 0, 0}, 26},
    {"R_knee", {255, 90, 60}, 25},
    {"L_ankle", {60, 60, 60}, 28},
    {"R_ankle", {170, 170, 170}, 27},
    {"L_foot", {0, 80, 200}, 30},
    {"R_foot", {90, 200, 255}, 29},
}};

struct JointInfo {
  std::string_view name;
  int mirror;
};

constexpr std::array<JointInfo, kNumJoints> kJoints{{
    {"head", 0},       {"neck", 1},      {"L_shoulder", 3}, {"R_shoulder", 2},
    {"L_elbow", 5},    {"R_elbow", 4},   {"L_wrist", 7},    {"R_wrist", 6},
    {"L_hand", 9},     {"R_hand", 8},    {"L_knee", 11},    {"R_knee", 10},
    {"L_ankle", 13},   {"R_ankle", 12},  {"L_foot", 15},    {"R_foot", 14},
}};

std::vector<std::vector<int>> BuildJointParts() {
  auto p = [](Part part) { return int(part); };
  return {
      {p(Part::kLUHead), p(Part::kRUHead), p(Part::kLWHead), p(Part::kRWHead)},
      {p(Part::kNeck)},
      {p(Part::kLShoulder)}, {p(Part::kRShoulder)},
      {p(Part::kLElbow)},    {p(Part::kRElbow)},
      {p(Part::kLWrist)},    {p(Part::kRWrist)},
      {p(Part::kLHand)},     {p(Part::kRHand)},
      {p(Part::kLKnee)},     {p(Part::kRKnee)},
      {p(Part::kLAnkle)},    {p(Part::kRAnkle)},
      {p(Part::kLFoot)},     {p(Part::kRFoot)},
  };
}

}  // namespace

std::string_view PartName(int part) {
  POSEFOREST_CHECK(part >= 0 && part < kNumParts);
  return kParts[size_t(part)].name;
}

Rgb PartColour(int part) {
  POSEFOREST_CHECK(part >= 0 && part < kNumParts);
  return kParts[size_t(part)].colour;
}

int MirrorPart(int part) {
  POSEFOREST_CHECK(part >= 0 && part < kNumParts);
  return kParts[size_t(part)].mirror;
}

std::optional<int> PartFromName(std::string_view name) {
  for (int i = 0; i < kNumParts; ++i)
    if (kParts[size_t(i)].name == name) return i;
  return std::nullopt;
}

std::string_view JointName(int joint) {
  POSEFOREST_CHECK(joint >= 0 && joint < kNumJoints);
  return kJoints[size_t(joint)].name;
}

const std::vector<int>& JointParts(int joint) {
  static const std::vector<std::vector<int>> table = BuildJointParts();
  POSEFOREST_CHECK(joint >= 0 && joint < kNumJoints);
  return table[size_t(joint)];
}

int MirrorJoint(int joint) {
  POSEFOREST_CHECK(joint >= 0 && joint < kNumJoints);
  return kJoints[size_t(joint)].mirror;
}

}  // namespace poseforest::core
