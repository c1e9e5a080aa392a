// Bodies: clothed and sampled MakeHuman bodies through the SyntheticRenderer.
#include <catch2/catch.hpp>

#include <chrono>
#include <cstdio>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mhclo.h"
#include "renderer/scene_assets.h"
#include "renderer/synthetic_source.h"
#include "tests/support/paths.h"

using namespace poseforest;
using namespace poseforest::renderer;
namespace fs = std::filesystem;

namespace {

fs::path KitDir() { return testing::DataDir() / "meshes" / "makehuman_hm08_kit"; }
fs::path ClothesDir() { return testing::DataDir() / "meshes" / "makehuman_clothes"; }

/// Body `body` 2.6 m in front of the camera, turned by yaw_deg, raised by lift_m.
SceneSample View(int body, double yaw_deg, double lift_m = 0) {
  SceneSample s;
  PersonPlacement p;
  p.body = body;
  Eigen::Isometry3d world_from_body = Eigen::Isometry3d::Identity();
  world_from_body.translate(Eigen::Vector3d(0, lift_m, -2.6));
  world_from_body.rotate(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.rotate(Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()));
  camera_from_world.translate(Eigen::Vector3d(0, -0.95, 0));
  p.camera_from_body = camera_from_world * world_from_body;
  s.people.push_back(p);
  return s;
}

}  // namespace

TEST_CASE("clothes cover the body without holes: every outfit, front and back", "[egl][data]") {
  auto kit = assets::MakeHumanKit::Load(KitDir());
  REQUIRE(kit.ok());
  auto wardrobe = assets::LoadMakeHumanWardrobe(ClothesDir(), (*kit)->base_vertex_count());
  REQUIRE(wardrobe.ok());
  // Body 0 naked, body k > 0 the same preset in outfit k-1 with hair and shoes.
  SceneConfig config;
  config.use_procedural_bodies = false;
  config.noise.enabled = false;
  const auto& presets = assets::MakeHumanPresets();
  const assets::MakeHumanParams& woman = presets[7], &man = presets[11];
  auto naked_w = (*kit)->BuildDressed(woman, {});
  auto naked_m = (*kit)->BuildDressed(man, {});
  REQUIRE(naked_w.ok());
  REQUIRE(naked_m.ok());
  config.bodies.push_back(AssembleDressedBody(std::move(naked_w).value()));
  config.bodies.push_back(AssembleDressedBody(std::move(naked_m).value()));
  std::vector<int> naked_of;
  for (size_t o = 0; o < wardrobe->outfits.size(); ++o) {
    const bool female = wardrobe->outfits[o]->name.rfind("female", 0) == 0;
    const std::vector<const assets::MhcloProxy*> outfit = {
        wardrobe->outfits[o].get(), wardrobe->hair[o % wardrobe->hair.size()].get(),
        wardrobe->shoes[o % wardrobe->shoes.size()].get()};
    auto dressed = (*kit)->BuildDressed(female ? woman : man, outfit);
    REQUIRE(dressed.ok());
    config.bodies.push_back(AssembleDressedBody(std::move(dressed).value()));
    naked_of.push_back(female ? 0 : 1);
  }
  auto r = SyntheticRenderer::Create(config);
  if (!r.ok()) WARN("no EGL: " << r.status().ToString());
  REQUIRE(r.ok());
  for (double yaw : {0.0, 180.0}) {
    for (size_t o = 0; o < naked_of.size(); ++o) {
      const BodyMesh& body = (*r)->bodies()[o + 2];
      // Shoes lift the dressed body onto their soles: raise the naked one as much.
      const double lift = body.rest_joints[0].y() - (*r)->bodies()[size_t(naked_of[o])].rest_joints[0].y();
      auto naked = (*r)->RenderScene(View(naked_of[o], yaw, lift));
      auto clothed = (*r)->RenderScene(View(int(o) + 2, yaw));
      REQUIRE(naked.ok());
      REQUIRE(clothed.ok());
      INFO(body.name << " yaw " << yaw);
      // Every skin pixel must still be covered by something (a hole where covered skin was
      // hidden would read 0), nothing may lie behind the skin it covers, and the clothes must
      // be there, in front of the skin.
      size_t holes = 0, behind = 0, covered = 0, skin = 0;
      for (int y = 0; y < naked->depth.height; ++y)
        for (int x = 0; x < naked->depth.width; ++x) {
          const uint16_t n = naked->depth.at(x, y), c = clothed->depth.at(x, y);
          if (n == 0) continue;
          ++skin;
          if (c == 0) ++holes;
          else if (c > n + 5) ++behind;
          else if (c + 3 < n) ++covered;
        }
      CHECK(holes <= skin / 1000);
      CHECK(behind <= skin / 200);
      CHECK(covered > skin / 20);  // the clothes are really there, in front of the skin
    }
  }
}

TEST_CASE("renders of sampled clothed bodies are deterministic in (seed, index)", "[egl][data]") {
  MakeHumanBodyOptions options;
  options.sampled_bodies = 8;
  options.seed = 5;
  options.clothed_share = 0.75;
  options.clothes_dir = ClothesDir();
  auto t0 = std::chrono::steady_clock::now();
  auto bodies = MakeHumanBodies(KitDir(), options);
  REQUIRE(bodies.ok());
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  SceneConfig config;
  config.use_procedural_bodies = false;
  config.bodies = *bodies;
  t0 = std::chrono::steady_clock::now();
  auto a = SyntheticRenderer::Create(config);
  if (!a.ok()) WARN("no EGL: " << a.status().ToString());
  REQUIRE(a.ok());
  const double create_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("26 MakeHuman bodies (75%% clothed): built in %.2f s, renderer created (upload) in %.2f s\n",
              build_s, create_s);
  auto again = MakeHumanBodies(KitDir(), options);  // a second worker builds the same set
  REQUIRE(again.ok());
  config.bodies = *again;
  auto b = SyntheticRenderer::Create(config);
  REQUIRE(b.ok());
  size_t clothed_frames = 0;
  for (uint64_t i = 0; i < 6; ++i) {
    auto fa = (*a)->Render(9, i);
    auto fb = (*b)->Render(9, i);
    REQUIRE(fa.ok());
    REQUIRE(fb.ok());
    CHECK(fa->depth.pixels == fb->depth.pixels);
    CHECK(fa->labels.pixels == fb->labels.pixels);
    size_t fg = 0;
    for (uint16_t d : fa->depth.pixels) fg += d != 0;
    CHECK(fg > 1000);
    const auto scene = (*a)->Sample(9, i);
    clothed_frames += (*a)->bodies()[size_t(scene.people[0].body)].name.find('+') != std::string::npos;
  }
  CHECK(clothed_frames > 0);
}
