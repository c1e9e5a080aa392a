#pragma once
// A skinned body ready to pose and render: rest-pose mesh in the body frame (metres, Y up,
// facing +Z, see skeleton.h), linear-blend skin weights on the canonical skeleton's joints,
// rest joint positions (which fix the bone lengths), and a body-part label per vertex.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "renderer/skeleton.h"

namespace poseforest::renderer {

/// Up to four joint influences of one vertex; weights are >= 0 and sum to 1; unused slots have
/// weight 0. A weight on joint j means the vertex follows joint j's transform (the bone from j
/// to its children).
struct SkinInfluence {
  std::array<uint8_t, 4> joint{};
  std::array<float, 4> weight{};
};

struct BodyMesh {
  std::string name;                          ///< e.g. "procedural", "makehuman:female-young-heavy"
  std::vector<Eigen::Vector3f> vertices;     ///< rest pose, body frame, metres
  std::vector<std::array<uint32_t, 3>> triangles;  ///< indices into vertices, CCW seen from outside
  std::vector<SkinInfluence> skin;           ///< one per vertex
  SkelPositions rest_joints;                 ///< canonical joints in the rest pose, metres
  std::vector<uint8_t> part;                 ///< one per vertex: a core::Part value (0..30)
};

}  // namespace poseforest::renderer
