#pragma once
// BVH (Biovision Hierarchy) motion capture: parser, normalisation and forward kinematics.
//
// The loader copes with the quirks of the staged data (see /work/shared/data/SOURCES.md):
// any rotation-channel order per joint, position channels on any joint (Bandai Namco), TAB
// separators and CRLF line ends, a declared `Frames:` count smaller than the data (exactly
// `Frames:` lines are read, the rest is ignored and counted), and it reports truncated or
// malformed files with the file name and the 1-based line number.
//
// Normalisation (on by default) makes every clip look the same to the rest of the pipeline:
//  * units -> metres: the skeleton family fixes the unit (cgspeed CMU: 1 unit ~ 0.0564 m, per
//    the CMU FAQ; Reallusion CC3, Bandai Namco: cm); otherwise the unit is guessed from the rest leg length
//    (hip->knee->ankle) among mm, cm, inch, cgspeed, m;
//  * Z-up -> Y-up: a clip whose pelvis->head direction points along +Z in the data (the iClone
//    `RL_BoneRoot` files) gets a -90 degree rotation about X applied to its world positions;
//  * the T-pose reference frame 0 of the cgspeed CMU family is dropped.
// After normalisation the world frame is metres, Y up; the facing direction is left as captured
// (retarget.h rotates each pose to face +Z).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

/// One BVH channel.
enum class BvhChannel : uint8_t { kXpos, kYpos, kZpos, kXrot, kYrot, kZrot };

/// Naming family of a mocap skeleton, detected from its joint names.
enum class SkeletonFamily : uint8_t {
  kUnknown = 0,
  kCmuCgspeed,     ///< Hips, LHipJoint, LeftUpLeg, ..., LowerBack, Spine1, Neck1 (31 joints)
  kReallusionCC3,  ///< CC_Base_Hip, CC_Base_L_Thigh, ... (iClone exports; some Z-up)
  kBandaiNamco,    ///< joint_Root, Hips, Spine, Chest, UpperArm_L, LowerLeg_R, ...
  kBiovision,      ///< Hips, Chest, LeftCollar, LeftShoulder, LeftElbow, LeftHip, LeftKnee, ...
};

/// "cmu_cgspeed", "reallusion_cc3", "bandai_namco", "biovision", "unknown".
std::string_view SkeletonFamilyName(SkeletonFamily family);

/// A joint of the BVH hierarchy. End sites are joints too (no channels, `end_site` set) and are
/// named "<parent>_End".
struct BvhJoint {
  std::string name;
  int parent = -1;                                   ///< index into BvhClip::joints, -1 for a root
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  ///< file units, in the parent's frame
  std::vector<BvhChannel> channels;                  ///< in file order
  int first_channel = 0;                             ///< index of channels[0] within a frame's values
  bool end_site = false;
};

/// A parsed (and by default normalised) clip. Joints are in file order, parents before
/// children.
struct BvhClip {
  std::string source;  ///< file path (or the name given to ParseBvh)
  std::vector<BvhJoint> joints;
  int num_channels = 0;        ///< values per frame
  int num_frames = 0;          ///< frames kept (after dropping a reference frame)
  double frame_time_s = 0.0;   ///< seconds per frame
  std::vector<double> motion;  ///< num_frames * num_channels, file units / degrees

  SkeletonFamily family = SkeletonFamily::kUnknown;
  double unit_to_m = 1.0;  ///< metres per file unit (1 when not normalised)
  /// The rest hierarchy is Z-up (the root's first child offset points along Z, as in the iClone
  /// `RL_BoneRoot` files). Those files rotate the root by -90 degrees about X in every frame, so
  /// their FK output is already Y-up and needs no fix; see z_up_input.
  bool z_up_hierarchy = false;
  bool z_up_input = false;  ///< the FK output was Z-up; `world_fix` rotates it to Y-up
  Eigen::Matrix3d world_fix = Eigen::Matrix3d::Identity();  ///< applied to FK output
  int dropped_leading_frames = 0;  ///< reference frames removed (cgspeed T-pose frame 0)
  int declared_frames = 0;         ///< the header's `Frames:` value
  int ignored_trailing_lines = 0;  ///< non-empty lines after the declared frames

  /// Index of the joint called `name`, or -1.
  int FindJoint(std::string_view name) const;
  /// The values of frame `f` (num_channels of them).
  const double* Frame(int f) const { return motion.data() + size_t(f) * size_t(num_channels); }
};

struct BvhOptions {
  bool normalize = true;  ///< metres, Y-up, drop reference frames (see file comment)
  int max_frames = -1;    ///< keep at most this many frames (after dropping), -1 = all
};

/// Parses BVH text. `source` names the file in error messages.
core::Result<BvhClip> ParseBvh(std::string_view text, const std::string& source,
                               const BvhOptions& options = {});

/// Reads and parses a BVH file. Errors: kIo / kNotFound for unreadable files, kDataLoss with
/// "file:line: ..." for truncated or malformed content.
core::Result<BvhClip> LoadBvh(const std::filesystem::path& path, const BvhOptions& options = {});

/// Detects the skeleton family from joint names.
SkeletonFamily DetectFamily(const std::vector<BvhJoint>& joints);

/// World positions of every joint (end sites included) at frame `f`: metres when the clip is
/// normalised (file units * unit_to_m otherwise), rotated by world_fix (Y-up).
std::vector<Eigen::Vector3d> ForwardKinematics(const BvhClip& clip, int f);

/// Same, but also returns each joint's world rotation (world_fix applied).
void ForwardKinematics(const BvhClip& clip, int f, std::vector<Eigen::Vector3d>* positions,
                       std::vector<Eigen::Matrix3d>* rotations);

}  // namespace poseforest::renderer::assets
