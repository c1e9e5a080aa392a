#include "renderer/skinning.h"

namespace poseforest::renderer {

SkinTransforms ComputeSkinTransforms(const SkelPositions& rest, const Pose& pose) {
  const SkelPositions posed = PoseJoints(rest, pose);
  SkinTransforms t;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const Eigen::Matrix3d r = pose.rotation[size_t(j)].normalized().toRotationMatrix();
    t[size_t(j)].linear() = r;
    t[size_t(j)].translation() = posed[size_t(j)] - r * rest[size_t(j)];
  }
  return t;
}

void SkinVertices(const BodyMesh& mesh, const SkinTransforms& transforms,
                  std::vector<Eigen::Vector3f>* posed) {
  std::array<Eigen::Matrix<float, 3, 4>, kNumSkelJoints> m;
  for (int j = 0; j < kNumSkelJoints; ++j)
    m[size_t(j)] = transforms[size_t(j)].matrix().topRows<3>().cast<float>();
  posed->resize(mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const Eigen::Vector4f p = mesh.vertices[v].homogeneous();
    Eigen::Vector3f q = Eigen::Vector3f::Zero();
    const SkinInfluence& s = mesh.skin[v];
    for (int i = 0; i < 4; ++i) {
      const float w = s.weight[size_t(i)];
      if (w != 0.0f) q += w * (m[s.joint[size_t(i)]] * p);
    }
    (*posed)[v] = q;
  }
}

}  // namespace poseforest::renderer
