// The asset bodies work with the renderer: every one of the 31 parts appears under its part
// labelling, and its skinning poses them where the retargeted skeleton says.

#include <catch2/catch.hpp>
#include <set>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/assets/retarget.h"
#include "renderer/part_labels.h"
#include "renderer/skinning.h"
#include "runtime/core/body_parts.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;

namespace {

void CheckAllParts(BodyMesh& body) {
  LabelBodyParts(body);
  REQUIRE(body.part.size() == body.vertices.size());
  std::set<int> seen(body.part.begin(), body.part.end());
  std::string missing;
  for (int p = 0; p < poseforest::core::kNumParts; ++p)
    if (!seen.count(p)) missing += std::to_string(p) + " ";
  INFO(body.name << " lacks parts: " << missing);
  CHECK(missing.empty());
  CHECK(*seen.rbegin() < poseforest::core::kNumParts);
}

}  // namespace

TEST_CASE("MakeHuman bodies get all 31 body parts", "[parts][data]") {
  auto kit = MakeHumanKit::Load(poseforest::testing::DataDir() / "meshes" / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  for (const char* name : {"girl-8", "female-young-average", "male-young-heavy", "male-old"}) {
    const MakeHumanParams* params = nullptr;
    for (const auto& p : MakeHumanPresets())
      if (p.name == name) params = &p;
    REQUIRE(params);
    auto body = (*kit)->Build(*params);
    REQUIRE(body.ok());
    CheckAllParts(*body);
  }
}

TEST_CASE("staged rigged meshes get all 31 body parts", "[parts][data]") {
  const auto dir = poseforest::testing::DataDir() / "meshes";
  for (const char* f : {"makehuman_export_fbx/MakeHumanModel.fbx", "quaternius_modular_women/Soldier.gltf",
                        "cesium_man/CesiumMan.glb", "quaternius_casual_female/Casual_Female.gltf"}) {
    auto body = LoadRiggedMesh(dir / f);
    REQUIRE(body.ok());
    CheckAllParts(*body);
  }
}

TEST_CASE("a retargeted hands-up pose skins a MakeHuman body with the hands where the skeleton says",
          "[skinning][data]") {
  auto kit = MakeHumanKit::Load(poseforest::testing::DataDir() / "meshes" / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  auto body = (*kit)->Build(MakeHumanPresets()[7]);
  REQUIRE(body.ok());
  auto clip = LoadBvh(poseforest::testing::DataDir() / "mocap" / "bandai_namco_2" /
                      "dataset-2_raise-up-both-hands_normal_001.bvh");
  REQUIRE(clip.ok());
  auto poses = RetargetClip(*clip, ReferenceRestJoints());
  REQUIRE(poses.ok());
  // The frame with the highest wrists.
  size_t best = 0;
  double best_y = -1e9;
  for (size_t f = 0; f < poses->size(); ++f) {
    const auto j = PoseJoints(ReferenceRestJoints(), (*poses)[f]);
    const double y = std::min(j[size_t(SkelJoint::kLWrist)].y(), j[size_t(SkelJoint::kRWrist)].y());
    if (y > best_y) best_y = y, best = f;
  }
  const Pose pose = AdaptPose((*poses)[best], body->rest_joints);
  const auto joints = PoseJoints(body->rest_joints, pose);
  // Hands raised above the shoulders (around head height in this clip).
  REQUIRE(joints[size_t(SkelJoint::kLWrist)].y() > joints[size_t(SkelJoint::kLShoulder)].y() + 0.1);
  REQUIRE(joints[size_t(SkelJoint::kRWrist)].y() > joints[size_t(SkelJoint::kRShoulder)].y() + 0.1);
  std::vector<Eigen::Vector3f> posed;
  SkinVertices(*body, ComputeSkinTransforms(body->rest_joints, pose), &posed);
  REQUIRE(posed.size() == body->vertices.size());
  // Vertices that follow a wrist end up around the posed hand, above the shoulders; feet stay
  // on the floor.
  for (SkelJoint w : {SkelJoint::kLWrist, SkelJoint::kRWrist}) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    size_t n = 0;
    for (size_t v = 0; v < posed.size(); ++v)
      if (body->skin[v].joint[0] == int(w) && body->skin[v].weight[0] > 0.9f)
        mean += posed[v].cast<double>(), ++n;
    REQUIRE(n > 100);
    mean /= double(n);
    const Eigen::Vector3d wrist = joints[size_t(w)];
    const Eigen::Vector3d tip = joints[size_t(int(w) + 1)];
    CHECK((mean - 0.5 * (wrist + tip)).norm() < 0.08);
    CHECK(mean.y() > joints[size_t(SkelJoint::kLShoulder)].y() + 0.1);
  }
  float min_y = 1e9f;
  for (const auto& v : posed) min_y = std::min(min_y, v.y());
  CHECK(std::abs(min_y) < 0.05);
}
