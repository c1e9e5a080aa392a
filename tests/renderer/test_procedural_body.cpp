// Procedural bodies, part labels and CPU skinning.
#include <catch2/catch.hpp>
#include <map>
#include <set>

#include "renderer/part_labels.h"
#include "renderer/pose_sampler.h"
#include "renderer/procedural_body.h"
#include "renderer/skinning.h"
#include "runtime/core/body_parts.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

/// Signed volume (m^3) of a closed mesh with outward (CCW) triangles.
double SignedVolume(const BodyMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    v += m.vertices[t[0]].cast<double>().dot(
        m.vertices[t[1]].cast<double>().cross(m.vertices[t[2]].cast<double>()));
  }
  return v / 6.0;
}

const Eigen::Vector3d& J(const SkelPositions& s, SkelJoint j) { return s[size_t(int(j))]; }

}  // namespace

TEST_CASE("the procedural family spans child to heavy adult with closed, skinned meshes", "[procedural]") {
  REQUIRE(kNumProceduralShapes >= 15);
  double min_h = 10, max_h = 0, min_volume_per_h3 = 1e9, max_volume_per_h3 = 0;
  for (int i = 0; i < kNumProceduralShapes; ++i) {
    const BodyShape shape = ProceduralBaseShape(i);
    const BodyMesh m = MakeProceduralBody(shape);
    INFO(m.name);
    min_h = std::min(min_h, shape.height_m);
    max_h = std::max(max_h, shape.height_m);
    CHECK(m.triangles.size() >= 5000);
    CHECK(m.triangles.size() <= 30000);
    REQUIRE(m.skin.size() == m.vertices.size());
    REQUIRE(m.part.size() == m.vertices.size());

    // Closed: every directed edge appears once and its reverse once (each primitive is a
    // closed, consistently oriented surface).
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    for (const auto& t : m.triangles) {
      for (int k = 0; k < 3; ++k) edges[{t[size_t(k)], t[size_t((k + 1) % 3)]}]++;
    }
    bool closed = true;
    for (const auto& [e, n] : edges) {
      auto it = edges.find({e.second, e.first});
      if (n != 1 || it == edges.end() || it->second != 1) closed = false;
    }
    CHECK(closed);
    const double volume = SignedVolume(m);
    CHECK(volume > 0);
    const double h3 = shape.height_m * shape.height_m * shape.height_m;
    min_volume_per_h3 = std::min(min_volume_per_h3, volume / h3);
    max_volume_per_h3 = std::max(max_volume_per_h3, volume / h3);

    // Skin weights: non-negative, sum to one, on real joints.
    for (const SkinInfluence& s : m.skin) {
      float sum = 0;
      for (int k = 0; k < 4; ++k) {
        REQUIRE(s.weight[size_t(k)] >= 0.0f);
        REQUIRE(s.joint[size_t(k)] < kNumSkelJoints);
        sum += s.weight[size_t(k)];
      }
      REQUIRE(sum == Approx(1.0f).margin(1e-5));
    }
    // Body frame: feet on y = 0, top of the head at the height, left (+X) side symmetric.
    float min_y = 1e9f, max_y = -1e9f, min_x = 1e9f, max_x = -1e9f;
    for (const auto& v : m.vertices) {
      min_y = std::min(min_y, v.y()), max_y = std::max(max_y, v.y());
      min_x = std::min(min_x, v.x()), max_x = std::max(max_x, v.x());
    }
    CHECK(min_y == Approx(0.0).margin(0.005));
    CHECK(max_y == Approx(shape.height_m).margin(0.03 * shape.height_m));
    CHECK(max_x == Approx(-min_x).margin(1e-4));
    CHECK(J(m.rest_joints, SkelJoint::kLHandTip).x() > 0.0);  // left = +X
    CHECK(J(m.rest_joints, SkelJoint::kHeadTop).y() == Approx(shape.height_m));
  }
  CHECK(min_h <= 1.1);
  CHECK(max_h >= 1.9);
  // Heavy shapes hold clearly more volume per height^3 than slim ones.
  CHECK(max_volume_per_h3 > 1.6 * min_volume_per_h3);
}

TEST_CASE("shape variation is deterministic and small", "[procedural]") {
  const BodyShape base = ProceduralBaseShape(11);
  const BodyShape a = VaryShape(base, 7, 3), b = VaryShape(base, 7, 3), c = VaryShape(base, 7, 4);
  CHECK(a.height_m == b.height_m);
  CHECK(a.girth == b.girth);
  CHECK(a.height_m != c.height_m);
  CHECK(std::abs(a.height_m / base.height_m - 1.0) <= 0.03);
  CHECK(std::abs(a.girth / base.girth - 1.0) <= 0.08);
  CHECK(VaryShape(base, 7, 0).height_m == base.height_m);
}

TEST_CASE("labelling a procedural body gives all 31 parts, mirror-symmetric", "[labels]") {
  for (int i : {0, 6, 13}) {
    BodyMesh m = MakeProceduralBody(ProceduralBaseShape(i));
    std::vector<int> count(core::kNumParts, 0);
    for (uint8_t p : m.part) {
      REQUIRE(p < core::kNumParts);
      count[p]++;
    }
    for (int p = 0; p < core::kNumParts; ++p) {
      INFO(m.name << " part " << core::PartName(p));
      CHECK(count[size_t(p)] >= 10);
    }
    // The labelling is mirror-symmetric: a vertex mirrored through x = 0, with the mirrored
    // dominant joint, gets the mirrored part (vertices on the midline itself go to the left).
    auto mirror_joint = [](int j) {
      if (j >= 6 && j <= 10) return j + 5;
      if (j >= 11 && j <= 15) return j - 5;
      if (j >= 16 && j <= 19) return j + 4;
      if (j >= 20 && j <= 23) return j - 4;
      return j;
    };
    int asymmetric = 0, tested = 0;
    for (size_t v = 0; v < m.vertices.size(); ++v) {
      if (std::abs(m.vertices[v].x()) < 2e-3f) continue;
      std::array<float, kNumSkelJoints> w{};
      for (int k = 0; k < 4; ++k) w[m.skin[v].joint[size_t(k)]] += m.skin[v].weight[size_t(k)];
      const int dominant = int(std::max_element(w.begin(), w.end()) - w.begin());
      Eigen::Vector3f q = m.vertices[v];
      q.x() = -q.x();
      ++tested;
      asymmetric += LabelPoint(m.rest_joints, q, mirror_joint(dominant)) != core::MirrorPart(m.part[v]);
    }
    CHECK(tested > 1000);
    CHECK(asymmetric == 0);
    // Sides: left parts on +X, right parts on -X (with a small tolerance at the midline).
    for (size_t v = 0; v < m.vertices.size(); ++v) {
      const std::string_view name = core::PartName(m.part[v]);
      if (name[0] == 'L') REQUIRE(m.vertices[v].x() > -1e-4f);
      if (name[0] == 'R') REQUIRE(m.vertices[v].x() < 1e-4f);
    }
  }
}

TEST_CASE("LabelPoint bands follow the skeleton of any body", "[labels]") {
  const SkelPositions rest = ProceduralSkeleton(ProceduralBaseShape(11));
  auto label = [&](const Eigen::Vector3d& p, SkelJoint dominant) {
    return core::Part(LabelPoint(rest, p.cast<float>(), int(dominant)));
  };
  const Eigen::Vector3d sh = J(rest, SkelJoint::kLShoulder), el = J(rest, SkelJoint::kLElbow);
  const Eigen::Vector3d wr = J(rest, SkelJoint::kLWrist), tip = J(rest, SkelJoint::kLHandTip);
  CHECK(label(el + Eigen::Vector3d(0, 0.03, 0), SkelJoint::kLElbow) == core::Part::kLElbow);
  CHECK(label(0.5 * (sh + el) + Eigen::Vector3d(0, 0.04, 0), SkelJoint::kLShoulder) == core::Part::kLUArm);
  CHECK(label(0.5 * (el + wr), SkelJoint::kLElbow) == core::Part::kLWArm);
  CHECK(label(wr, SkelJoint::kLWrist) == core::Part::kLWrist);
  CHECK(label(0.3 * wr + 0.7 * tip, SkelJoint::kLWrist) == core::Part::kLHand);
  CHECK(label(sh + Eigen::Vector3d(0, 0.03, 0), SkelJoint::kLShoulder) == core::Part::kLShoulder);
  CHECK(label(J(rest, SkelJoint::kRKnee) + Eigen::Vector3d(0, 0, 0.05), SkelJoint::kRKnee) ==
        core::Part::kRKnee);
  CHECK(label(J(rest, SkelJoint::kRToe), SkelJoint::kRAnkle) == core::Part::kRFoot);
  const Eigen::Vector3d head_c = 0.5 * (J(rest, SkelJoint::kHead) + J(rest, SkelJoint::kHeadTop));
  CHECK(label(head_c + Eigen::Vector3d(0.03, 0.05, 0.05), SkelJoint::kHead) == core::Part::kLUHead);
  CHECK(label(head_c + Eigen::Vector3d(-0.03, -0.05, 0.05), SkelJoint::kHead) == core::Part::kRWHead);
  CHECK(label(J(rest, SkelJoint::kChest) + Eigen::Vector3d(-0.05, 0.0, 0.1), SkelJoint::kChest) ==
        core::Part::kRUTorso);
  CHECK(label(J(rest, SkelJoint::kPelvis) + Eigen::Vector3d(0.05, 0.0, 0.1), SkelJoint::kPelvis) ==
        core::Part::kLWTorso);
}

TEST_CASE("skinning with the identity pose returns the rest mesh", "[skinning]") {
  const BodyMesh m = MakeProceduralBody(ProceduralBaseShape(7));
  std::vector<Eigen::Vector3f> posed;
  SkinVertices(m, ComputeSkinTransforms(m.rest_joints, Pose()), &posed);
  REQUIRE(posed.size() == m.vertices.size());
  float max_err = 0;
  for (size_t v = 0; v < posed.size(); ++v) max_err = std::max(max_err, (posed[v] - m.vertices[v]).norm());
  CHECK(max_err < 1e-6f);
}

TEST_CASE("skinning moves rigid parts with their bones", "[skinning]") {
  const BodyMesh m = MakeProceduralBody(ProceduralBaseShape(11));
  const Pose pose = SampleProceduralPose(99, 5);
  const SkinTransforms t = ComputeSkinTransforms(m.rest_joints, pose);
  const SkelPositions posed_joints = PoseJoints(m.rest_joints, pose);
  // T_j maps the rest joint j to the posed joint j exactly.
  for (int j = 0; j < kNumSkelJoints; ++j) {
    CHECK((t[size_t(j)] * m.rest_joints[size_t(j)] - posed_joints[size_t(j)]).norm() < 1e-9);
  }
  // A vertex skinned 100% to one joint keeps its distance to that joint.
  std::vector<Eigen::Vector3f> posed;
  SkinVertices(m, t, &posed);
  int rigid = 0;
  for (size_t v = 0; v < posed.size(); ++v) {
    if (m.skin[v].weight[0] != 1.0f) continue;
    const int j = m.skin[v].joint[0];
    const double d_rest = (m.vertices[v].cast<double>() - m.rest_joints[size_t(j)]).norm();
    const double d_posed = (posed[v].cast<double>() - posed_joints[size_t(j)]).norm();
    REQUIRE(d_posed == Approx(d_rest).margin(1e-5));
    ++rigid;
  }
  CHECK(rigid > 1000);
}
