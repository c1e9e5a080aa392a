#pragma once
// Linear-blend skinning on the canonical skeleton (CPU reference; the EGL renderer does the same
// sum in its vertex shader with the same per-joint transforms).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "renderer/body.h"
#include "renderer/skeleton.h"

namespace poseforest::renderer {

/// Per-joint skinning transforms, body frame, metres: T_j = [R_j | posed_j - R_j * rest_j], so
/// a rest-pose point rigidly attached to joint j's bone goes to T_j * p.
using SkinTransforms = std::array<Eigen::Isometry3d, kNumSkelJoints>;

/// T_j from the rest joints and a pose (posed joints from PoseJoints).
SkinTransforms ComputeSkinTransforms(const SkelPositions& rest, const Pose& pose);

/// Posed vertices: v' = sum_i w_i * T_{j_i} * v (body frame, metres).
void SkinVertices(const BodyMesh& mesh, const SkinTransforms& transforms,
                  std::vector<Eigen::Vector3f>* posed);

}  // namespace poseforest::renderer
