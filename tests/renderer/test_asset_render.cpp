// The asset helper's bodies (MakeHuman kit, Assimp rigged meshes) through the SyntheticRenderer:
// labelled here by LabelBodyParts, they show all 31 parts between a front and a back view.
#include <catch2/catch.hpp>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/synthetic_source.h"
#include "runtime/core/body_parts.h"
#include "tests/support/paths.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {
SceneSample View(int body, double yaw_deg) {
  SceneSample s;
  PersonPlacement p;
  p.body = body;
  Eigen::Isometry3d world_from_body = Eigen::Isometry3d::Identity();
  world_from_body.translate(Eigen::Vector3d(0, 0, -3.0));
  world_from_body.rotate(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.rotate(Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()));
  camera_from_world.translate(Eigen::Vector3d(0, -1.0, 0));
  p.camera_from_body = camera_from_world * world_from_body;
  s.people.push_back(p);
  return s;
}
}  // namespace

TEST_CASE("asset bodies render with all 31 parts", "[egl][data]") {
  const auto data = testing::DataDir();
  SceneConfig config;
  config.use_procedural_bodies = false;
  config.noise.enabled = false;
  auto kit = assets::MakeHumanKit::Load(data / "meshes" / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  const auto& presets = assets::MakeHumanPresets();
  REQUIRE(presets.size() >= 3);
  for (size_t i : {size_t(0), presets.size() / 2, presets.size() - 1}) {
    auto body = (*kit)->Build(presets[i]);
    REQUIRE(body.ok());
    config.bodies.push_back(std::move(body).value());
  }
  for (const char* f : {"cesium_man/CesiumMan.glb", "quaternius_modular_women/Soldier.gltf"}) {
    auto body = assets::LoadRiggedMesh(data / "meshes" / f);
    REQUIRE(body.ok());
    config.bodies.push_back(std::move(body).value());
  }
  auto r = SyntheticRenderer::Create(config);
  REQUIRE(r.ok());
  for (int b = 0; b < int((*r)->bodies().size()); ++b) {
    std::vector<int> count(core::kNumParts, 0);
    for (double yaw : {0.0, 180.0}) {
      auto f = (*r)->RenderScene(View(b, yaw));
      REQUIRE(f.ok());
      for (uint8_t l : f->labels.pixels) {
        if (l != core::kBackgroundLabel) count[l]++;
      }
    }
    for (int p = 0; p < core::kNumParts; ++p) {
      INFO((*r)->bodies()[size_t(b)].name << ": " << core::PartName(p));
      CHECK(count[size_t(p)] >= 10);
    }
  }
  // Random frames with these bodies render too.
  for (uint64_t i = 0; i < 5; ++i) {
    auto f = (*r)->Render(3, i);
    REQUIRE(f.ok());
  }
}
