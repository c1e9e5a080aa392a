#pragma once
// Retargeting mocap onto the canonical skeleton (renderer/skeleton.h), and the rig name maps
// that tie mocap and mesh skeletons to the canonical joints.
//
// Method (position based, so it works for any source rest pose, including the CC3 files whose
// zero-rotation pose is not a T-pose):
//  1. forward kinematics gives the source's world joint positions (metres, Y up, bvh.h);
//  2. the name map picks the source joint for each canonical joint; head top, hand tips, toes,
//     spine and collars that a family lacks are estimated (see CanonicalTracks);
//  3. facing: the source's left = (L_hip - R_hip) + (L_shoulder - R_shoulder), made horizontal;
//     forward = left x up. A rotation about Y turns forward to +Z, either per frame
//     (FacingMode::kPerFrame, the default: the pose library is then yaw-free, the paper adds
//     rotation about the vertical axis at render time) or once per clip from its first frame
//     (kFirstFrame: turning motions stay turns);
//  4. global joint rotations: the pelvis and chest get full frames (primary axis = the bone to
//     spine / neck, secondary = the hip line / the collar line, or the shoulder line where the
//     collars sit on the spine), so their twist comes from the hips and shoulders; every other bone gets the
//     smallest rotation that turns its parent-carried rest direction onto the source direction (twist
//     inherited from the parent). So every canonical bone points exactly the way the source bone points,
//     while bone LENGTHS stay the target's (PoseJoints applies rotations to the target's rest bones);
//  5. root translation: vertical: the target's lowest ankle/toe joint is placed as high above
//     the target's floor (its rest lowest ankle/toe joint) as the source's lowest ankle/toe joint
//     is above the source's floor (the clip's lowest ankle/toe joint), scaled by target leg /
//     source leg; so feet on the ground stay on the ground and jumps scale with the body.
//     Horizontal translation is 0 unless
//     keep_horizontal_translation (then: scaled pelvis path relative to the clip's first frame,
//     in the facing-normalised frame).

#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "renderer/assets/bvh.h"
#include "renderer/skeleton.h"
#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

/// For each canonical joint, the source joint names that stand for it (first present wins).
/// An empty list means the family has no such joint (it is estimated or folded).
struct RigNameMap {
  std::string family;  ///< "cmu_cgspeed", "makehuman_default", "mixamo", ...
  std::array<std::vector<std::string>, kNumSkelJoints> names;
};

/// Name maps for BVH families: cmu_cgspeed, reallusion_cc3, bandai_namco, biovision.
const std::vector<RigNameMap>& MocapNameMaps();
/// Name maps for mesh rigs: makehuman_default, mixamo, quaternius, cesium_man (a bone maps to
/// the canonical joint at its head; see mesh_loader.h).
const std::vector<RigNameMap>& MeshRigNameMaps();

/// A name map from (canonical joint name as SkelJointName gives it, source bone name) pairs, for
/// a rig no built-in map knows (Blender's Rigify: {"L_elbow", "forearm.L"}, ...; "bone@tail"
/// names a bone's tail). Several bones for one joint: the first present wins. Errors
/// (kInvalidArgument) name an unknown joint or an empty bone name.
core::Result<RigNameMap> BoneMapFromPairs(const std::vector<std::pair<std::string, std::string>>& pairs,
                                          const std::string& family);

/// Strips a namespace prefix ("mixamorig:Hips" -> "Hips", "Armature|Hips" -> "Hips").
std::string_view StripRigPrefix(std::string_view name);

/// Canonical joints a source must provide (the rest can be estimated): pelvis, chest, neck,
/// head, shoulders, elbows, wrists, hips, knees, ankles.
bool IsRequiredJoint(int joint);

/// Resolves each canonical joint to an index into `names` (-1 where the map has none present).
/// Picks the map (of `maps`) that covers the most required joints. Fails with kInvalidArgument
/// naming `source` and listing the required canonical joints that no map finds.
core::Result<std::array<int, kNumSkelJoints>> ResolveJoints(const std::vector<std::string>& names,
                                                            const std::vector<RigNameMap>& maps,
                                                            const std::string& source,
                                                            std::string* family = nullptr);

/// Canonical joint positions of a mocap clip: metres, Y up, as captured (not facing-normalised).
struct CanonicalTracks {
  std::string source;
  std::string family;                 ///< name map used
  std::vector<SkelPositions> frames;  ///< one per clip frame
  double leg_length_m = 0;            ///< mean of L/R hip->knee->ankle, first frame
  double floor_y_m = 0;               ///< lowest ankle/toe joint height over the clip
};

/// Maps a clip onto canonical joints (FK + name map + estimates for missing optional joints).
core::Result<CanonicalTracks> ExtractCanonicalTracks(const BvhClip& clip);

enum class FacingMode { kPerFrame, kFirstFrame };

struct RetargetOptions {
  FacingMode facing = FacingMode::kPerFrame;
  bool keep_horizontal_translation = false;
};

/// Horizontal unit vector the skeleton faces (left x up), from hips and shoulders.
Eigen::Vector3d FacingDirection(const SkelPositions& joints);

/// Retargets one frame of source positions (metres, Y up) onto a target rest skeleton.
/// `yaw` rotates the source to face +Z; `root_y` is the target pelvis height change (m) and
/// `root_xz` the horizontal root translation (m).
Pose RetargetPositions(const SkelPositions& source, const SkelPositions& target_rest,
                       const Eigen::Quaterniond& yaw, double root_y, const Eigen::Vector2d& root_xz);

/// Retargets a whole clip onto `target_rest` (any rest pose; bone lengths come from it).
core::Result<std::vector<Pose>> RetargetClip(const BvhClip& clip, const SkelPositions& target_rest,
                                             const RetargetOptions& options = {});

/// Same, from already extracted tracks.
std::vector<Pose> RetargetTracks(const CanonicalTracks& tracks, const SkelPositions& target_rest,
                                 const RetargetOptions& options = {});

/// Re-expresses a pose made for `from_rest` (by default the reference T-pose, as stored in pose
/// libraries) for a body with rest joints `to_rest`: every bone of `to_rest` then points the way
/// it points in PoseJoints(from_rest, pose), whatever the two rest poses (T-pose, A-pose) are;
/// the root follows the foot-on-floor rule of RetargetTracks with the leg-length scale, and the
/// horizontal root translation is scaled by the leg-length ratio. Needed because Pose rotations
/// are relative to a rest pose: a library pose applied directly to MakeHuman's A-pose rest would
/// leave the arms 45 degrees off.
Pose AdaptPose(const Pose& pose, const SkelPositions& to_rest, const SkelPositions& from_rest);
Pose AdaptPose(const Pose& pose, const SkelPositions& to_rest);

/// A reference adult T-pose (1.75 m, feet on y = 0, faces +Z, left = +X), used to measure pose
/// distances and when no body is at hand.
const SkelPositions& ReferenceRestJoints();

/// Hip -> knee -> ankle length of a skeleton, mean of both legs (m).
double LegLength(const SkelPositions& joints);

}  // namespace poseforest::renderer::assets
