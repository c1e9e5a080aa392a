// The renderer's camera model and clutter: frames rendered with another camera's
// intrinsics, and a floor, walls, boxes and occluders with ground-truth person masks, through
// SyntheticRenderer (real EGL rendering) and `poseforest render`, run in-process.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "apps/commands/commands.h"
#include "renderer/synthetic_source.h"
#include "runtime/camera_model.h"
#include "runtime/image_io.h"
#include "runtime/segmentation.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using namespace poseforest;

namespace {

int Run(std::vector<std::string> args) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  return apps::commands::RenderMain(int(argv.size()), argv.data());
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::unique_ptr<renderer::SyntheticRenderer> Make(const renderer::SceneConfig& c) {
  auto r = renderer::SyntheticRenderer::Create(c);
  INFO(r.status().ToString());
  REQUIRE(r.ok());
  return std::move(r).value();
}

// Rows spanned by pixels with a label other than background.
int LabelledRows(const core::LabelImage& labels) {
  int lo = labels.height, hi = -1;
  for (int y = 0; y < labels.height; ++y)
    for (int x = 0; x < labels.width; ++x)
      if (labels.at(x, y) != core::kBackgroundLabel) lo = std::min(lo, y), hi = std::max(hi, y);
  return hi < 0 ? 0 : hi - lo + 1;
}

// Whether any labelled pixel lies on the frame's border (the person is cropped).
bool TouchesEdge(const core::LabelImage& labels) {
  for (int y = 0; y < labels.height; ++y)
    for (int x = 0; x < labels.width; ++x)
      if ((x == 0 || y == 0 || x == labels.width - 1 || y == labels.height - 1) &&
          labels.at(x, y) != core::kBackgroundLabel)
        return true;
  return false;
}

int Count(const core::LabelImage& img, int value) {
  return int(std::count(img.pixels.begin(), img.pixels.end(), uint8_t(value)));
}

renderer::SceneConfig ClutterConfig() {
  renderer::SceneConfig c;
  c.noise.enabled = false;
  c.min_people = c.max_people = 2;
  c.clutter.floor = c.clutter.walls = c.clutter.boxes = true;
  c.clutter.occluders = 1;
  return c;
}

}  // namespace

TEST_CASE("the renderer takes a camera model: the same scene through another focal length",
          "[renderer][egl][camera]") {
  renderer::SceneConfig kinect;
  kinect.noise.enabled = false;
  auto azure_model = runtime::CameraPreset("azure-nfov");
  REQUIRE(azure_model.ok());
  renderer::SceneConfig azure = kinect;
  azure.camera = azure_model->intrinsics;
  auto a = Make(kinect);
  auto b = Make(azure);
  for (uint64_t i = 0; i < 3; ++i) {
    const renderer::SceneSample scene = a->Sample(7, i);
    auto fa = a->RenderScene(scene);
    auto fb = b->RenderScene(scene);
    REQUIRE(fa.ok());
    REQUIRE(fb.ok());
    CHECK(fb->depth.width == 640);
    CHECK(fb->depth.height == 576);
    // The person's extent in pixels follows fy (the frame edge may crop: skip cropped frames).
    const int ha = LabelledRows(fa->labels), hb = LabelledRows(fb->labels);
    INFO("frame " << i << ": " << ha << " rows at fy 575.8, " << hb << " at fy " << azure.camera.fy);
    REQUIRE(ha > 50);
    if (!TouchesEdge(fa->labels) && !TouchesEdge(fb->labels))
      CHECK(std::abs(double(hb) / ha - azure.camera.fy / kinect.camera.fy) < 0.04);
    // Joints project through the camera model: the pelvis-ish joints' pixels lie on the body.
    int on_body = 0, visible = 0;
    for (int j = 0; j < core::kNumJoints; ++j) {
      if (!fb->visible[0][size_t(j)]) continue;
      ++visible;
      const Eigen::Vector2d uv = azure.camera.Project(fb->joints[0][size_t(j)].cast<double>());
      const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
      bool hit = false;
      for (int dy = -3; dy <= 3; ++dy)
        for (int dx = -3; dx <= 3; ++dx)
          hit |= fb->depth.InBounds(u + dx, v + dy) && fb->people.at(u + dx, v + dy) == 1;
      on_body += hit;
    }
    CHECK(on_body >= visible * 3 / 4);
  }
}

TEST_CASE("clutter: floor, walls, boxes and occluders with per-person ground-truth masks",
          "[renderer][egl][clutter]") {
  const renderer::SceneConfig cfg = ClutterConfig();
  renderer::SceneConfig clean_cfg = cfg;
  clean_cfg.clutter = renderer::ClutterConfig();
  auto r = Make(cfg);
  auto again = Make(cfg);
  auto clean = Make(clean_cfg);
  int occluded_frames = 0, frames = 6, floor_pixels = 0;
  for (uint64_t i = 0; i < uint64_t(frames); ++i) {
    INFO("frame " << i);
    const renderer::SceneSample scene = r->Sample(11, i);
    // Clutter draws come from their own stream: the people, camera and noise are unchanged.
    const renderer::SceneSample plain = clean->Sample(11, i);
    REQUIRE(scene.people.size() == 2);
    CHECK(scene.people[0].camera_from_body.matrix() == plain.people[0].camera_from_body.matrix());
    CHECK(scene.noise_key == plain.noise_key);
    CHECK(scene.clutter.floor);
    CHECK(scene.clutter.back_wall_z < 0);
    CHECK(scene.clutter.side_wall_x != 0);
    REQUIRE(std::count_if(scene.clutter.boxes.begin(), scene.clutter.boxes.end(),
                          [](const renderer::ClutterBox& b) { return b.occluder; }) == 1);
    CHECK(plain.clutter.boxes.empty());
    CHECK_FALSE(plain.clutter.floor);

    auto f = r->Render(11, i);
    auto g = again->Render(11, i);
    auto c = clean->Render(11, i);
    REQUIRE(f.ok());
    REQUIRE(g.ok());
    REQUIRE(c.ok());
    // Deterministic: the same (seed, index) gives the same bytes on another renderer.
    CHECK(f->depth.pixels == g->depth.pixels);
    CHECK(f->labels.pixels == g->labels.pixels);
    CHECK(f->people.pixels == g->people.pixels);
    // Clutter fills the frame (floor and walls everywhere but where the walls are beyond range).
    CHECK(core::CountForeground(f->depth) > int(f->depth.pixels.size()) * 9 / 10);
    // Masks, labels and depth agree: a person pixel carries a part, a non-person pixel none.
    int mismatch = 0, person_pixels = 0;
    for (size_t p = 0; p < f->depth.pixels.size(); ++p) {
      const bool person = f->people.pixels[p] != 0;
      person_pixels += person;
      mismatch += person != (f->labels.pixels[p] != core::kBackgroundLabel);
      mismatch += person && f->people.pixels[p] > 2;
      // Where the person is visible in the cluttered frame, it is exactly the clean render.
      if (person) {
        mismatch += f->people.pixels[p] != c->people.pixels[p];
        mismatch += f->depth.pixels[p] != c->depth.pixels[p];
      } else if (c->people.pixels[p] != 0) {
        mismatch += f->depth.pixels[p] == 0 || f->depth.pixels[p] > c->depth.pixels[p];  // hidden by clutter
      }
    }
    CHECK(mismatch == 0);
    CHECK(person_pixels > 500);
    occluded_frames += Count(f->people, 0) > Count(c->people, 0);
    // Every clutter pixel lies on a surface of the sampled clutter: the floor (world y = 0), a
    // wall's plane or a box's face (within the depth rounding), on a grid over the frame.
    const Eigen::Isometry3d world_from_camera = scene.camera_from_world.inverse();
    const core::CameraIntrinsics& k = cfg.camera;
    int off_surface = 0;
    for (int y = 0; y < k.height; y += 8)
      for (int x = 0; x < k.width; x += 8) {
        const uint16_t d = f->depth.at(x, y);
        if (!d || f->people.at(x, y)) continue;
        double X = (x - k.cx) / k.fx * d * 1e-3, Y = (y - k.cy) / k.fy * d * 1e-3;
        if (scene.mirrored) X = -X;
        const Eigen::Vector3d w = world_from_camera * Eigen::Vector3d(X, Y, d * 1e-3);
        const double tol = 0.005 + 0.002 * d * 1e-3;
        bool on = std::abs(w.y()) < tol, on_floor = on;
        on |= std::abs(w.x() - scene.clutter.side_wall_x) < tol ||
              std::abs(w.z() - scene.clutter.back_wall_z) < tol;
        for (const auto& b : scene.clutter.boxes)
          on |= (w.array() >= b.min.array() - tol).all() && (w.array() <= b.max.array() + tol).all();
        off_surface += !on;
        floor_pixels += on_floor;
      }
    CHECK(off_surface == 0);
  }
  CHECK(floor_pixels > 200);
  CHECK(occluded_frames >= frames / 2);  // the occluders do hide people
}

TEST_CASE("runtime segmentation finds the rendered people in cluttered frames", "[renderer][egl][clutter]") {
  renderer::SceneConfig cfg = ClutterConfig();
  cfg.noise.enabled = true;
  auto r = Make(cfg);
  runtime::SegmentationResult seg;
  double iou_sum = 0;
  int people = 0, good = 0, floors = 0;
  for (uint64_t i = 0; i < 6; ++i) {
    auto f = r->Render(3, i);
    REQUIRE(f.ok());
    runtime::SegmentPeople(f->depth, cfg.camera, runtime::SegmentationOptions{}, &seg);
    floors += seg.floor.has_value();
    for (int k = 1; k <= 2; ++k) {
      if (Count(f->people, k) < 800) continue;  // mostly hidden or out of view
      double best = 0;
      for (int j = 1; j <= int(seg.people.size()); ++j)
        best = std::max(best, runtime::MaskIoU(f->people, k, seg.labels, j));
      iou_sum += best;
      good += best > 0.7;
      ++people;
    }
  }
  INFO(people << " people, mean IoU " << iou_sum / std::max(1, people) << ", floor found in " << floors
              << "/6");
  CHECK(floors >= 3);
  REQUIRE(people >= 6);
  CHECK(iou_sum / people > 0.7);
  CHECK(good >= people * 2 / 3);
}

TEST_CASE("poseforest render: --camera, --clutter, --occluders, --masks; deterministic; clear errors",
          "[cli][egl][clutter]") {
  const fs::path a = testing::ScratchDir("render-clutter-a"), b = testing::ScratchDir("render-clutter-b");
  for (const fs::path& dir : {a, b})
    REQUIRE(Run({"render", "--out", dir.string(), "--count", "3", "--seed", "5", "--people", "2", "--clutter",
                 "floor,walls,boxes", "--occluders", "2", "--camera", "kinect-v2", "--threads",
                 dir == a ? "1" : "2"}) == 0);
  for (int i = 0; i < 3; ++i) {
    for (const char* stem : {"depth", "labels", "mask", "joints"}) {
      char name[32];
      std::snprintf(name, sizeof name, "%s_%06d.%s", stem, i, std::string(stem) == "joints" ? "json" : "png");
      INFO(name);
      REQUIRE(fs::exists(a / name));
      CHECK(Slurp(a / name) == Slurp(b / name));
    }
  }
  auto cam = runtime::ReadCameraModelFile((a / "camera.txt").string());
  REQUIRE(cam.ok());
  auto v2 = runtime::CameraPreset("kinect-v2");
  REQUIRE(v2.ok());
  CHECK(cam->name == "kinect-v2");
  CHECK(cam->intrinsics.fx == v2->intrinsics.fx);
  CHECK(cam->intrinsics.cy == v2->intrinsics.cy);
  auto depth = runtime::ReadDepthImage((a / "depth_000001.png").string());
  REQUIRE(depth.ok());
  CHECK(depth->width == 512);
  CHECK(depth->height == 424);
  const std::string mask_bytes = Slurp(a / "mask_000001.png");
  auto mask =
      runtime::DecodePng({reinterpret_cast<const uint8_t*>(mask_bytes.data()), mask_bytes.size()}, "m");
  REQUIRE(mask.ok());
  CHECK(mask->channels == 1);
  CHECK(mask->width == 512);
  int ids[256] = {};
  for (uint8_t v : mask->samples8) ++ids[v];
  CHECK(ids[1] + ids[2] > 200);
  for (int v = 3; v < 256; ++v) CHECK(ids[v] == 0);

  // --fx alone: square pixels; masks without clutter only with --masks.
  const fs::path c = testing::ScratchDir("render-fx");
  REQUIRE(Run({"render", "--out", c.string(), "--count", "1", "--fx", "365", "--masks"}) == 0);
  auto fx = runtime::ReadCameraModelFile((c / "camera.txt").string());
  REQUIRE(fx.ok());
  CHECK(fx->name == "kinect-v1+custom");
  CHECK(fx->intrinsics.fx == 365.0);
  CHECK(fx->intrinsics.fy == 365.0);
  CHECK(fs::exists(c / "mask_000000.png"));
  const fs::path d = testing::ScratchDir("render-plain");
  REQUIRE(Run({"render", "--out", d.string(), "--count", "1"}) == 0);
  CHECK_FALSE(fs::exists(d / "mask_000000.png"));

  // Bad input: exit status 2 before anything is rendered.
  const fs::path e = testing::ScratchDir("render-bad");
  CHECK(Run({"render", "--out", e.string(), "--clutter", "floor,chairs"}) == 2);
  CHECK(Run({"render", "--out", e.string(), "--camera", "kinect-v9"}) == 2);
  CHECK(Run({"render", "--out", e.string(), "--occluders", "99"}) == 2);
  CHECK(Run({"render", "--out", e.string(), "--fx", "-3"}) == 2);
  CHECK_FALSE(fs::exists(e / "depth_000000.png"));
}
