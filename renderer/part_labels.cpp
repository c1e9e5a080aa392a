#include "renderer/part_labels.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "runtime/core/body_parts.h"
#include "runtime/core/result.h"

namespace poseforest::renderer {
namespace {

using Eigen::Vector3d;
using J = SkelJoint;
using core::Part;

const Vector3d& At(const SkelPositions& s, J j) { return s[size_t(int(j))]; }

/// Arc-length position (metres from the first point) of the nearest point on a polyline; the
/// last segment is extended beyond its end so points past it get s > total length.
double PolylinePosition(const Vector3d& p, const std::vector<Vector3d>& line) {
  double best_d = 1e30, best_s = 0, start = 0;
  for (size_t k = 0; k + 1 < line.size(); ++k) {
    const Vector3d ab = line[k + 1] - line[k];
    const double len = ab.norm();
    if (len < 1e-9) continue;
    double t = (p - line[k]).dot(ab) / (len * len);
    const bool last = k + 2 == line.size();
    t = std::max(t, 0.0);
    if (!last) t = std::min(t, 1.0);
    const double d = (line[k] + t * ab - p).norm();
    if (d < best_d) best_d = d, best_s = start + t * len;
    start += len;
  }
  return best_s;
}

enum class Region { kHead, kNeck, kTorso, kLArm, kRArm, kLLeg, kRLeg };

Region RegionOf(int joint) {
  switch (J(joint)) {
    case J::kHead:
    case J::kHeadTop:
      return Region::kHead;
    case J::kNeck:
      return Region::kNeck;
    case J::kPelvis:
    case J::kSpine:
    case J::kChest:
    case J::kLCollar:
    case J::kRCollar:
      return Region::kTorso;
    case J::kLShoulder:
    case J::kLElbow:
    case J::kLWrist:
    case J::kLHandTip:
      return Region::kLArm;
    case J::kRShoulder:
    case J::kRElbow:
    case J::kRWrist:
    case J::kRHandTip:
      return Region::kRArm;
    case J::kLHip:
    case J::kLKnee:
    case J::kLAnkle:
    case J::kLToe:
      return Region::kLLeg;
    case J::kRHip:
    case J::kRKnee:
    case J::kRAnkle:
    case J::kRToe:
      return Region::kRLeg;
  }
  return Region::kTorso;
}

uint8_t P(Part p) { return uint8_t(p); }

}  // namespace

uint8_t LabelPoint(const SkelPositions& rest, const Eigen::Vector3f& pf, int dominant, const PartBands& b) {
  const Vector3d p = pf.cast<double>();
  const double mid_x = 0.5 * (At(rest, J::kPelvis).x() + At(rest, J::kHead).x());
  const bool left_of_mid = p.x() >= mid_x;  // the person's left is +X
  const Region region = RegionOf(dominant);

  // Shoulders: a ball around each shoulder joint, taken from the torso and the upper arm.
  if (region == Region::kTorso || region == Region::kLArm || region == Region::kRArm) {
    for (int side = 0; side < 2; ++side) {
      const J sh = side == 0 ? J::kLShoulder : J::kRShoulder;
      const J el = side == 0 ? J::kLElbow : J::kRElbow;
      const double r = b.shoulder_radius * (At(rest, el) - At(rest, sh)).norm();
      const bool arm_other_side =
          (side == 0 && region == Region::kRArm) || (side == 1 && region == Region::kLArm);
      if (!arm_other_side && (p - At(rest, sh)).norm() < r) {
        return side == 0 ? P(Part::kLShoulder) : P(Part::kRShoulder);
      }
    }
  }
  switch (region) {
    case Region::kHead: {
      const double centre_y = 0.5 * (At(rest, J::kHead).y() + At(rest, J::kHeadTop).y());
      const bool upper = p.y() >= centre_y;
      if (upper) return left_of_mid ? P(Part::kLUHead) : P(Part::kRUHead);
      return left_of_mid ? P(Part::kLWHead) : P(Part::kRWHead);
    }
    case Region::kNeck:
      return P(Part::kNeck);
    case Region::kTorso: {
      const double split_y = 0.5 * (At(rest, J::kPelvis).y() + At(rest, J::kNeck).y());
      const bool upper = p.y() >= split_y;
      if (upper) return left_of_mid ? P(Part::kLUTorso) : P(Part::kRUTorso);
      return left_of_mid ? P(Part::kLWTorso) : P(Part::kRWTorso);
    }
    case Region::kLArm:
    case Region::kRArm: {
      const bool left = region == Region::kLArm;
      const Vector3d sh = At(rest, left ? J::kLShoulder : J::kRShoulder);
      const Vector3d el = At(rest, left ? J::kLElbow : J::kRElbow);
      const Vector3d wr = At(rest, left ? J::kLWrist : J::kRWrist);
      const Vector3d tip = At(rest, left ? J::kLHandTip : J::kRHandTip);
      const double l_up = (el - sh).norm(), l_fore = (wr - el).norm(), l_hand = (tip - wr).norm();
      const double s = PolylinePosition(p, {sh, el, wr, tip});
      const double s_el = l_up, s_wr = l_up + l_fore;
      if (s >= s_wr + b.wrist_after * l_hand) return left ? P(Part::kLHand) : P(Part::kRHand);
      if (s >= s_wr - b.wrist_before * l_fore) return left ? P(Part::kLWrist) : P(Part::kRWrist);
      if (std::abs(s - s_el) <= b.elbow_half * l_fore) return left ? P(Part::kLElbow) : P(Part::kRElbow);
      if (s > s_el) return left ? P(Part::kLWArm) : P(Part::kRWArm);
      return left ? P(Part::kLUArm) : P(Part::kRUArm);
    }
    case Region::kLLeg:
    case Region::kRLeg: {
      const bool left = region == Region::kLLeg;
      const Vector3d hip = At(rest, left ? J::kLHip : J::kRHip);
      const Vector3d kn = At(rest, left ? J::kLKnee : J::kRKnee);
      const Vector3d an = At(rest, left ? J::kLAnkle : J::kRAnkle);
      const double l_thigh = (kn - hip).norm(), l_shin = (an - kn).norm();
      const J dj = J(dominant);
      const bool foot_bone = dj == J::kLAnkle || dj == J::kRAnkle || dj == J::kLToe || dj == J::kRToe;
      // "Below the ankle" along the shin direction (the legs are straight in the rest pose).
      const Vector3d down = (an - kn).normalized();
      const double below = (p - an).dot(down);
      const bool forward = (p - an).z() > 0.25 * l_shin;
      if (below > b.foot_below * l_shin || (foot_bone && forward)) {
        return left ? P(Part::kLFoot) : P(Part::kRFoot);
      }
      const double s = PolylinePosition(p, {hip, kn, an});
      const double s_kn = l_thigh, s_an = l_thigh + l_shin;
      if (s >= s_an - b.ankle_above * l_shin) return left ? P(Part::kLAnkle) : P(Part::kRAnkle);
      if (std::abs(s - s_kn) <= b.knee_half * l_shin) return left ? P(Part::kLKnee) : P(Part::kRKnee);
      if (s > s_kn) return left ? P(Part::kLWLeg) : P(Part::kRWLeg);
      return left ? P(Part::kLULeg) : P(Part::kRULeg);
    }
  }
  return P(Part::kLUTorso);
}

namespace {

int DominantJoint(const SkinInfluence& s) {
  std::array<float, kNumSkelJoints> w{};
  for (int i = 0; i < 4; ++i) {
    if (s.joint[size_t(i)] < kNumSkelJoints) w[s.joint[size_t(i)]] += s.weight[size_t(i)];
  }
  return int(std::max_element(w.begin(), w.end()) - w.begin());  // ties: the lower joint index
}

/// The average of two skin influences, keeping the four largest weights.
SkinInfluence MergeSkin(const SkinInfluence& a, const SkinInfluence& b) {
  std::array<float, kNumSkelJoints> w{};
  for (int i = 0; i < 4; ++i) {
    if (a.joint[size_t(i)] < kNumSkelJoints) w[a.joint[size_t(i)]] += 0.5f * a.weight[size_t(i)];
    if (b.joint[size_t(i)] < kNumSkelJoints) w[b.joint[size_t(i)]] += 0.5f * b.weight[size_t(i)];
  }
  SkinInfluence out;
  float sum = 0;
  for (int k = 0; k < 4; ++k) {
    const int j = int(std::max_element(w.begin(), w.end()) - w.begin());
    if (w[size_t(j)] <= 0) break;
    out.joint[size_t(k)] = uint8_t(j);
    out.weight[size_t(k)] = w[size_t(j)];
    sum += w[size_t(j)];
    w[size_t(j)] = 0;
  }
  for (float& x : out.weight) x /= sum;
  return out;
}

}  // namespace

void RefinePartBoundaries(BodyMesh& mesh, int levels, const PartBands& bands) {
  POSEFOREST_CHECK(mesh.part.size() == mesh.vertices.size() && mesh.skin.size() == mesh.vertices.size());
  for (int level = 0; level < levels; ++level) {
    std::unordered_map<uint64_t, uint32_t> midpoint;
    auto key = [](uint32_t a, uint32_t b) {
      return a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a);
    };
    auto split = [&](uint32_t a, uint32_t b) -> int64_t {
      if (mesh.part[a] == mesh.part[b]) return -1;
      auto [it, inserted] = midpoint.try_emplace(key(a, b), uint32_t(mesh.vertices.size()));
      if (inserted) {
        const Eigen::Vector3f p = 0.5f * (mesh.vertices[a] + mesh.vertices[b]);
        const SkinInfluence s = MergeSkin(mesh.skin[a], mesh.skin[b]);
        mesh.vertices.push_back(p);
        mesh.skin.push_back(s);
        mesh.part.push_back(LabelPoint(mesh.rest_joints, p, DominantJoint(s), bands));
      }
      return it->second;
    };
    std::vector<std::array<uint32_t, 3>> out;
    out.reserve(mesh.triangles.size() * 5 / 4);
    for (const auto& t : mesh.triangles) {
      const int64_t m[3] = {split(t[0], t[1]), split(t[1], t[2]), split(t[2], t[0])};
      const int n = int(m[0] >= 0) + int(m[1] >= 0) + int(m[2] >= 0);
      if (n == 0) {
        out.push_back(t);
      } else if (n == 3) {
        const uint32_t m01 = uint32_t(m[0]), m12 = uint32_t(m[1]), m20 = uint32_t(m[2]);
        out.push_back({t[0], m01, m20});
        out.push_back({m01, t[1], m12});
        out.push_back({m20, m12, t[2]});
        out.push_back({m01, m12, m20});
      } else if (n == 1) {
        const int e = m[0] >= 0 ? 0 : (m[1] >= 0 ? 1 : 2);  // split edge (v_e, v_e+1)
        const uint32_t a = t[size_t(e)], b = t[size_t((e + 1) % 3)], c = t[size_t((e + 2) % 3)];
        const uint32_t mid = uint32_t(m[e]);
        out.push_back({a, mid, c});
        out.push_back({mid, b, c});
      } else {
        const int keep = m[0] < 0 ? 0 : (m[1] < 0 ? 1 : 2);  // the unsplit edge
        // Rotate so the unsplit edge is (v2, v0): split edges are (v0, v1) and (v1, v2).
        const int s0 = (keep + 1) % 3;
        const uint32_t v0 = t[size_t(s0)], v1 = t[size_t((s0 + 1) % 3)], v2 = t[size_t((s0 + 2) % 3)];
        const uint32_t m01 = uint32_t(m[s0]), m12 = uint32_t(m[(s0 + 1) % 3]);
        out.push_back({m01, v1, m12});
        out.push_back({v0, m01, m12});
        out.push_back({v0, m12, v2});
      }
    }
    mesh.triangles = std::move(out);
  }
}

void LabelBodyParts(BodyMesh& mesh, const PartBands& bands) {
  POSEFOREST_CHECK_MSG(mesh.skin.size() == mesh.vertices.size(),
                       "LabelBodyParts: one skin influence per vertex");
  mesh.part.resize(mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    mesh.part[v] = LabelPoint(mesh.rest_joints, mesh.vertices[v], DominantJoint(mesh.skin[v]), bands);
  }
}

}  // namespace poseforest::renderer
