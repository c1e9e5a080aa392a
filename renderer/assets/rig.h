#pragma once
// Folding an arbitrary rig (MakeHuman's 163 bones, a glTF skin, ...) onto the canonical
// skeleton: rest joint positions from the mapped bones, and skin weights of every rig bone
// moved to the canonical joint it belongs to. Shared by makehuman.h and mesh_loader.h.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "renderer/assets/retarget.h"
#include "renderer/body.h"
#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

/// A bone of a source rig, in the body frame (metres, Y up, facing +Z) or any consistent frame.
struct RigBone {
  std::string name;
  int parent = -1;  ///< index into the bone list, -1 for a root
  Eigen::Vector3d head = Eigen::Vector3d::Zero();
  bool has_tail = false;
  Eigen::Vector3d tail = Eigen::Vector3d::Zero();
};

/// Result of mapping a rig: canonical rest joints and, per rig bone, the canonical joint its
/// weights fold onto.
struct FoldedRig {
  std::string family;                         ///< name map used
  SkelPositions rest_joints;                  ///< estimated joints filled by EstimateMissingJoints
  std::array<bool, kNumSkelJoints> mapped{};  ///< joint position came from a bone
  std::vector<int> bone_joint;                ///< canonical joint per rig bone
};

/// Maps bones through MeshRigNameMaps() (a name "X@tail" in a map means the tail of bone X).
/// A bone folds onto the canonical joint of itself or of its nearest mapped ancestor (pelvis if
/// none); leaf joints (head top, hand tips) are never fold targets. Errors list the missing
/// canonical joints and the rig's bone names, naming `source`.
/// `extra_maps` (e.g. a job's bone map for a rig no built-in map knows) are tried with the built-in
/// ones and win ties.
core::Result<FoldedRig> FoldRig(const std::vector<RigBone>& bones, const std::string& source,
                                const std::vector<RigNameMap>& extra_maps = {});

/// Per-vertex rig weights: (bone index, weight) pairs.
using RigWeights = std::vector<std::vector<std::pair<int, float>>>;

/// Folds rig weights onto canonical joints: keeps the 4 largest, renormalises; a vertex with no
/// weight follows its nearest canonical joint.
std::vector<SkinInfluence> FoldSkin(const FoldedRig& rig, const RigWeights& weights,
                                    const std::vector<Eigen::Vector3f>& vertices);

/// Fills joints the rig did not map: spine (between pelvis and chest), collars (a third of the
/// way from neck to shoulder), head top (highest head vertex), hand tips (farthest hand vertex
/// along the forearm), toes (front of the foot vertices).
void EstimateMissingJoints(FoldedRig& rig, const std::vector<Eigen::Vector3f>& vertices,
                           const std::vector<SkinInfluence>& skin);

/// Moves `body` (vertices and rest joints, metres) so that its lowest vertex is on y = 0 and its
/// pelvis above the origin.
void PlaceOnFloor(BodyMesh* body);

/// The signed axis permutation (a proper rotation) nearest to the rotation `m`.
Eigen::Matrix3d SnapToAxes(const Eigen::Matrix3d& m);

}  // namespace poseforest::renderer::assets
