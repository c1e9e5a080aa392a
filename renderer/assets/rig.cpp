#include "renderer/assets/rig.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poseforest::renderer::assets {
namespace {

using core::ErrorCode;
using core::Status;
using J = SkelJoint;

bool IsLeafJoint(int j) { return J(j) == J::kHeadTop || J(j) == J::kLHandTip || J(j) == J::kRHandTip; }

int Dominant(const SkinInfluence& s) {
  int best = 0;
  for (int k = 1; k < 4; ++k)
    if (s.weight[size_t(k)] > s.weight[size_t(best)]) best = k;
  return s.weight[size_t(best)] > 0 ? s.joint[size_t(best)] : -1;
}

}  // namespace

core::Result<FoldedRig> FoldRig(const std::vector<RigBone>& bones, const std::string& source,
                                const std::vector<RigNameMap>& extra_maps) {
  // Candidate names: every bone's name (its head) and "name@tail" (its tail).
  std::vector<std::string> names;
  std::vector<std::pair<int, bool>> what;  // (bone, is_tail)
  for (size_t b = 0; b < bones.size(); ++b) {
    names.push_back(bones[b].name);
    what.push_back({int(b), false});
    if (bones[b].has_tail) {
      names.push_back(bones[b].name + "@tail");
      what.push_back({int(b), true});
    }
  }
  FoldedRig rig;
  std::vector<RigNameMap> maps = extra_maps;  // first: they win ties
  maps.insert(maps.end(), MeshRigNameMaps().begin(), MeshRigNameMaps().end());
  auto resolved = ResolveJoints(names, maps, source, &rig.family);
  if (!resolved.ok()) {
    std::string list;
    size_t shown = 0;
    for (const auto& b : bones) {
      if (shown++ == 40) {
        list += ", ...";
        break;
      }
      list += (list.empty() ? "" : ", ") + b.name;
    }
    return Status(resolved.status().code(), resolved.status().message() + "; bones in the file (" +
                                                std::to_string(bones.size()) + "): " + list);
  }
  rig.bone_joint.assign(bones.size(), -1);
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const int n = (*resolved)[size_t(j)];
    rig.rest_joints[size_t(j)] = Eigen::Vector3d::Zero();
    if (n < 0) continue;
    const auto [b, is_tail] = what[size_t(n)];
    rig.rest_joints[size_t(j)] = is_tail ? bones[size_t(b)].tail : bones[size_t(b)].head;
    rig.mapped[size_t(j)] = true;
    if (!is_tail && !IsLeafJoint(j) && rig.bone_joint[size_t(b)] < 0) rig.bone_joint[size_t(b)] = j;
  }
  // Unmapped bones fold onto their nearest mapped ancestor (an ancestor already folded carries
  // its own nearest mapped ancestor's joint, so stopping there gives the same answer).
  for (size_t b = 0; b < bones.size(); ++b) {
    if (rig.bone_joint[b] >= 0) continue;
    int a = bones[b].parent, guard = 0;
    while (a >= 0 && rig.bone_joint[size_t(a)] < 0 && guard++ < 1000) a = bones[size_t(a)].parent;
    // A bone whose ancestors map nowhere (a rig root above the hips) follows the pelvis.
    rig.bone_joint[b] =
        (a >= 0 && rig.bone_joint[size_t(a)] >= 0) ? rig.bone_joint[size_t(a)] : int(J::kPelvis);
  }
  return rig;
}

std::vector<SkinInfluence> FoldSkin(const FoldedRig& rig, const RigWeights& weights,
                                    const std::vector<Eigen::Vector3f>& vertices) {
  std::vector<SkinInfluence> skin(vertices.size());
  std::array<float, kNumSkelJoints> acc;
  for (size_t v = 0; v < vertices.size(); ++v) {
    acc.fill(0.f);
    if (v < weights.size())
      for (const auto& [b, w] : weights[v])
        if (b >= 0 && size_t(b) < rig.bone_joint.size() && w > 0) acc[size_t(rig.bone_joint[size_t(b)])] += w;
    std::array<int, kNumSkelJoints> order;
    for (int j = 0; j < kNumSkelJoints; ++j) order[size_t(j)] = j;
    std::partial_sort(order.begin(), order.begin() + 4, order.end(), [&](int a, int b) {
      return acc[size_t(a)] > acc[size_t(b)] || (acc[size_t(a)] == acc[size_t(b)] && a < b);
    });
    float total = 0;
    for (int k = 0; k < 4; ++k) total += acc[size_t(order[size_t(k)])];
    SkinInfluence& s = skin[v];
    if (total > 0) {
      for (int k = 0; k < 4; ++k) {
        s.joint[size_t(k)] = uint8_t(order[size_t(k)]);
        s.weight[size_t(k)] = acc[size_t(order[size_t(k)])] / total;
      }
    } else {
      int best = int(J::kPelvis);
      double best_d = std::numeric_limits<double>::infinity();
      for (int j = 0; j < kNumSkelJoints; ++j) {
        if (IsLeafJoint(j) || !rig.mapped[size_t(j)]) continue;
        const double d = (rig.rest_joints[size_t(j)] - vertices[v].cast<double>()).squaredNorm();
        if (d < best_d) best_d = d, best = j;
      }
      s.joint[0] = uint8_t(best);
      s.weight[0] = 1.f;
    }
  }
  return skin;
}

void EstimateMissingJoints(FoldedRig& rig, const std::vector<Eigen::Vector3f>& vertices,
                           const std::vector<SkinInfluence>& skin) {
  auto& r = rig.rest_joints;
  auto P = [&](J j) -> Eigen::Vector3d& { return r[size_t(int(j))]; };
  auto has = [&](J j) { return rig.mapped[size_t(int(j))]; };
  if (!has(J::kSpine)) P(J::kSpine) = 0.5 * (P(J::kPelvis) + P(J::kChest));
  for (auto [c, s] : {std::pair{J::kLCollar, J::kLShoulder}, std::pair{J::kRCollar, J::kRShoulder}})
    if (!has(c)) P(c) = P(J::kNeck) + (P(s) - P(J::kNeck)) / 3.0;
  std::vector<int> dom(vertices.size());
  for (size_t v = 0; v < vertices.size(); ++v) dom[v] = v < skin.size() ? Dominant(skin[v]) : -1;
  if (!has(J::kHeadTop)) {
    double top = -std::numeric_limits<double>::infinity();
    for (size_t v = 0; v < vertices.size(); ++v)
      if (dom[v] == int(J::kHead)) top = std::max(top, double(vertices[v].y()));
    const Eigen::Vector3d h = P(J::kHead);
    P(J::kHeadTop) = std::isfinite(top) && top > h.y() ? Eigen::Vector3d(h.x(), top, h.z())
                                                       : h + Eigen::Vector3d(0, 0.2, 0);
  }
  for (auto [tip, wrist, elbow] :
       {std::tuple{J::kLHandTip, J::kLWrist, J::kLElbow}, std::tuple{J::kRHandTip, J::kRWrist, J::kRElbow}}) {
    if (has(tip)) continue;
    const Eigen::Vector3d w = P(wrist);
    Eigen::Vector3d dir = w - P(elbow);
    dir = dir.norm() > 1e-9 ? dir.normalized() : Eigen::Vector3d::UnitX();
    double reach = 0;
    for (size_t v = 0; v < vertices.size(); ++v)
      if (dom[v] == int(wrist)) reach = std::max(reach, (vertices[v].cast<double>() - w).dot(dir));
    P(tip) = w + dir * (reach > 0.02 ? reach : 0.15);
  }
  for (auto [toe, ankle] : {std::pair{J::kLToe, J::kLAnkle}, std::pair{J::kRToe, J::kRAnkle}}) {
    if (has(toe)) continue;
    const Eigen::Vector3d a = P(ankle);
    double front = -std::numeric_limits<double>::infinity();
    for (size_t v = 0; v < vertices.size(); ++v)
      if (dom[v] == int(ankle)) front = std::max(front, double(vertices[v].z()));
    if (!std::isfinite(front) || front <= a.z() + 0.02) {
      P(toe) = a + Eigen::Vector3d(0, -0.05, 0.12);
      continue;
    }
    // Centroid of the front 4 cm of the foot, lifted halfway to the ankle's height.
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int n = 0;
    for (size_t v = 0; v < vertices.size(); ++v)
      if (dom[v] == int(ankle) && vertices[v].z() > front - 0.04) sum += vertices[v].cast<double>(), ++n;
    P(toe) = sum / n;
  }
}

Eigen::Matrix3d SnapToAxes(const Eigen::Matrix3d& m) {
  Eigen::Matrix3d best = Eigen::Matrix3d::Identity();
  double best_score = -1e30;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (const auto& p : perms) {
    for (int signs = 0; signs < 8; ++signs) {
      Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
      for (int row = 0; row < 3; ++row) c(row, p[row]) = (signs >> row) & 1 ? -1.0 : 1.0;
      if (c.determinant() < 0) continue;
      const double score = (c.array() * m.array()).sum();
      if (score > best_score) best_score = score, best = c;
    }
  }
  return best;
}

void PlaceOnFloor(BodyMesh* body) {
  float min_y = std::numeric_limits<float>::infinity();
  for (const auto& v : body->vertices) min_y = std::min(min_y, v.y());
  const Eigen::Vector3d pelvis = body->rest_joints[size_t(SkelJoint::kPelvis)];
  const Eigen::Vector3d shift(-pelvis.x(), -double(min_y), -pelvis.z());
  for (auto& v : body->vertices) v += shift.cast<float>();
  for (auto& j : body->rest_joints) j += shift;
}

}  // namespace poseforest::renderer::assets
