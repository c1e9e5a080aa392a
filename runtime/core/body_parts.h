#pragma once
// The body-part taxonomy of Shotton et al. 2011 (section 3.1): 31 parts, their colours, the
// left<->right mirror map, and the 16 evaluated joints with the parts that feed each.

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

namespace poseforest::core {

/// The paper's 31 parts. L/R = the person's left/right, U/W = upper/lower (W for "loWer").
enum class Part : uint8_t {
  kLUHead = 0, kRUHead, kLWHead, kRWHead,
  kNeck,
  kLShoulder, kRShoulder,
  kLUArm, kRUArm, kLWArm, kRWArm,
  kLElbow, kRElbow,
  kLWrist, kRWrist,
  kLHand, kRHand,
  kLUTorso, kRUTorso, kLWTorso, kRWTorso,
  kLULeg, kRULeg, kLWLeg, kRWLeg,
  kLKnee, kRKnee,
  kLAnkle, kRAnkle,
  kLFoot, kRFoot,
};
inline constexpr int kNumParts = 31;

/// The 16 joints evaluated in section 4 (Fig. 7).
enum class Joint : uint8_t {
  kHead = 0, kNeck,
  kLShoulder, kRShoulder,
  kLElbow, kRElbow,
  kLWrist, kRWrist,
  kLHand, kRHand,
  kLKnee, kRKnee,
  kLAnkle, kRAnkle,
  kLFoot, kRFoot,
};
inline constexpr int kNumJoints = 16;

struct Rgb {
  uint8_t r, g, b;
};

/// Short stable identifier, e.g. "LU_head", "R_elbow" (used in files and JSON).
std::string_view PartName(int part);
/// Display colour of a part (distinct, left/right differ).
Rgb PartColour(int part);
/// Colour used for background pixels in label pictures.
inline constexpr Rgb kBackgroundColour{0, 0, 0};
/// The part on the other side of the body (LU_head <-> RU_head, neck -> neck).
/// Mirroring an image left<->right must swap labels through this map.
int MirrorPart(int part);
/// Part with this name, if any.
std::optional<int> PartFromName(std::string_view name);

/// Identifier of a joint, e.g. "head", "L_shoulder".
std::string_view JointName(int joint);
/// The parts whose probability is pooled to localize a joint (head: the four head parts).
const std::vector<int>& JointParts(int joint);
/// The joint on the other side of the body.
int MirrorJoint(int joint);

}  // namespace poseforest::core
