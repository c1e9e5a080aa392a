// Writes the pictures of docs/renderer/: the procedural family in a labelled front T-pose, front
// and back views, a Fig. 2-style montage of sampled training frames, and cluttered frames before
// and after the runtime's people segmentation (clutter_segmentation.png).
//   render_docs OUT_DIR
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "renderer/montage.h"
#include "renderer/procedural_body.h"
#include "renderer/synthetic_source.h"
#include "runtime/image_io.h"
#include "runtime/segmentation.h"

#ifdef POSEFOREST_DOCS_WITH_ASSETS
#include "renderer/assets/makehuman.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/assets/retarget.h"
#include "renderer/pose_sampler.h"
#include "renderer/scene_assets.h"
#endif

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

SceneSample Front(int body, double yaw_deg, double dist, double cam_h) {
  SceneSample s;
  PersonPlacement p;
  p.body = body;
  Eigen::Isometry3d world_from_body = Eigen::Isometry3d::Identity();
  world_from_body.translate(Eigen::Vector3d(0, 0, -dist));
  world_from_body.rotate(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.rotate(Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()));
  camera_from_world.translate(Eigen::Vector3d(0, -cam_h, 0));
  p.camera_from_body = camera_from_world * world_from_body;
  s.people.push_back(p);
  return s;
}

/// Copies `src` (w x h) into `dst` at (x0, y0).
void Blit(const RgbImage& src, RgbImage* dst, int x0, int y0) {
  for (int y = 0; y < src.height && y0 + y < dst->height; ++y) {
    for (int x = 0; x < src.width && x0 + x < dst->width; ++x) {
      for (int c = 0; c < 3; ++c) {
        dst->rgb[(size_t(y0 + y) * size_t(dst->width) + size_t(x0 + x)) * 3 + size_t(c)] =
            src.rgb[(size_t(y) * size_t(src.width) + size_t(x)) * 3 + size_t(c)];
      }
    }
  }
}

/// The horizontal window [x0, x0 + w) of a picture.
RgbImage CropX(const RgbImage& src, int x0, int w) {
  RgbImage out;
  out.width = w;
  out.height = src.height;
  out.rgb.assign(size_t(w) * size_t(src.height) * 3, 0);
  for (int y = 0; y < src.height; ++y) {
    for (int x = 0; x < w; ++x) {
      if (x0 + x < 0 || x0 + x >= src.width) continue;
      for (int c = 0; c < 3; ++c) {
        out.rgb[(size_t(y) * size_t(w) + size_t(x)) * 3 + size_t(c)] =
            src.rgb[(size_t(y) * size_t(src.width) + size_t(x0 + x)) * 3 + size_t(c)];
      }
    }
  }
  return out;
}

// Person ids as colours over the dimmed depth (0 = the depth, dimmed).
RgbImage IdsOverDepth(const core::DepthImage& depth, const core::LabelImage& ids, int downsample) {
  static const uint8_t kColours[6][3] = {{230, 60, 50},  {50, 140, 230}, {60, 200, 80},
                                         {240, 200, 40}, {200, 80, 220}, {40, 220, 220}};
  RgbImage img = DepthToGrey(depth, downsample);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      uint8_t* px = &img.rgb[(size_t(y) * size_t(img.width) + size_t(x)) * 3];
      const int id = ids.at(x * downsample, y * downsample);
      for (int k = 0; k < 3; ++k) px[k] = id ? kColours[(id - 1) % 6][k] : uint8_t(px[k] / 3);
    }
  return img;
}

int Fail(const core::Status& st) {
  std::fprintf(stderr, "render_docs: %s\n", st.ToString().c_str());
  return 1;
}

// 1. The family, front T-pose, labels: 8 x 2 cells cropped around the body.
core::Status WriteFamily(SyntheticRenderer& r, const std::filesystem::path& out) {
  const int cell_w = 220, cols = 8;
  RgbImage grid;
  grid.width = cols * cell_w;
  grid.height = 2 * 240;
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 0);
  for (int b = 0; b < kNumProceduralShapes; ++b) {
    auto f = r.RenderScene(Front(b, 0, 4.2, 1.0));
    if (!f.ok()) return f.status();
    const RgbImage pic = CropX(LabelsToColour(f->labels, 2), 160 - cell_w / 2, cell_w);
    Blit(pic, &grid, (b % cols) * cell_w, (b / cols) * 240);
  }
  if (auto st =
          runtime::WriteRgbPng((out / "procedural_family.png").string(), grid.width, grid.height, grid.rgb);
      !st.ok())
    return st;
  return core::Status::Ok();
}

// 2. Front and back of two bodies (labels + depth), full resolution crops.
core::Status WriteFrontBack(SyntheticRenderer& r, const std::filesystem::path& out) {
  RgbImage grid;
  const int cell_w = 360;
  grid.width = 4 * cell_w;
  grid.height = 480;
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 0);
  int k = 0;
  for (int b : {11, 6}) {
    for (double yaw : {0.0, 180.0}) {
      auto f = r.RenderScene(Front(b, yaw, 2.6, 0.95));
      if (!f.ok()) return f.status();
      Blit(CropX(LabelsToColour(f->labels, 1), 320 - cell_w / 2, cell_w), &grid, k * cell_w, 0);
      ++k;
    }
  }
  if (auto st = runtime::WriteRgbPng((out / "front_back.png").string(), grid.width, grid.height, grid.rgb);
      !st.ok())
    return st;
  return core::Status::Ok();
}

// 3. Fig. 2-style montage of sampled training frames (noise on, some with 2 people).
core::Status WriteMontage(const std::filesystem::path& out) {
  SceneConfig c2;
  c2.min_people = 1;
  c2.max_people = 2;
  c2.rotation_range_deg = 180;
  auto r2 = SyntheticRenderer::Create(c2);
  if (!r2.ok()) return r2.status();
  std::vector<RenderedFrame> frames;
  for (uint64_t i = 0; i < 8; ++i) {
    auto f = (*r2)->Render(2011, i);
    if (!f.ok()) return f.status();
    frames.push_back(std::move(f).value());
  }
  const RgbImage m = MakeMontage(frames, 4, 2, 2);
  if (auto st = runtime::WriteRgbPng((out / "montage.png").string(), m.width, m.height, m.rgb); !st.ok())
    return st;
  return core::Status::Ok();
}

// 4. Close-up at 2 m with Kinect noise: depth | labels at full resolution, two poses.
core::Status WriteCloseup(const std::filesystem::path& out) {
  SceneConfig c3;
  c3.min_distance_m = c3.max_distance_m = 2.0;
  c3.lateral_fraction = 0.0;
  c3.mirror_probability = 0.0;
  auto r3 = SyntheticRenderer::Create(c3);
  if (!r3.ok()) return r3.status();
  RgbImage grid;
  const int cell_w = 320;
  grid.width = 4 * cell_w;
  grid.height = 480;
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 0);
  for (int k = 0; k < 2; ++k) {
    auto f = (*r3)->Render(5, uint64_t(k + 1));
    if (!f.ok()) return f.status();
    Blit(CropX(DepthToGrey(f->depth, 1), 160, cell_w), &grid, 2 * k * cell_w, 0);
    Blit(CropX(LabelsToColour(f->labels, 1), 160, cell_w), &grid, (2 * k + 1) * cell_w, 0);
  }
  if (auto st = runtime::WriteRgbPng((out / "closeup_noise.png").string(), grid.width, grid.height, grid.rgb);
      !st.ok())
    return st;
  return core::Status::Ok();
}

// 6. Cluttered frames (floor, walls, boxes, one occluder; two people; Kinect noise): depth |
//    ground-truth person masks | the runtime's segmentation | the depth the forest then sees.
core::Status WriteClutter(const std::filesystem::path& out) {
  SceneConfig c6;
  c6.min_people = c6.max_people = 2;
  c6.clutter.floor = c6.clutter.walls = c6.clutter.boxes = true;
  c6.clutter.occluders = 1;
  auto r6 = SyntheticRenderer::Create(c6);
  if (!r6.ok()) return r6.status();
  const int ds = 2, w = c6.camera.width / ds, h = c6.camera.height / ds;
  const uint64_t frames[] = {1, 3, 4};
  RgbImage grid;
  grid.width = 4 * w;
  grid.height = 3 * h;
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 0);
  runtime::SegmentationResult seg;
  for (int row = 0; row < 3; ++row) {
    auto f = (*r6)->Render(14, frames[row]);
    if (!f.ok()) return f.status();
    runtime::SegmentPeople(f->depth, c6.camera, runtime::SegmentationOptions{}, &seg);
    Blit(DepthToGrey(f->depth, ds), &grid, 0, row * h);
    Blit(IdsOverDepth(f->depth, f->people, ds), &grid, w, row * h);
    Blit(IdsOverDepth(f->depth, seg.labels, ds), &grid, 2 * w, row * h);
    Blit(DepthToGrey(seg.depth, ds), &grid, 3 * w, row * h);
    std::printf("clutter frame %llu: floor %s, %zu segmented people;",
                static_cast<unsigned long long>(frames[row]), seg.floor ? "found" : "not found",
                seg.people.size());
    for (int k = 1; k <= int(f->joints.size()); ++k) {
      double best = 0;
      for (int j = 1; j <= int(seg.people.size()); ++j)
        best = std::max(best, runtime::MaskIoU(f->people, k, seg.labels, j));
      std::printf(" person %d IoU %.3f", k, best);
    }
    std::printf("\n");
  }
  if (auto st = runtime::WriteRgbPng((out / "clutter_segmentation.png").string(), grid.width, grid.height,
                                     grid.rgb);
      !st.ok())
    return st;
  return core::Status::Ok();
}

#ifdef POSEFOREST_DOCS_WITH_ASSETS
// 5. The asset bodies (MakeHuman kit presets, Assimp rigged meshes), labelled by
//    LabelBodyParts, in their rest pose, front and back.
core::Status WriteAssetBodies(const std::filesystem::path& data, const assets::MakeHumanKit& kit,
                              const std::filesystem::path& out) {
  SceneConfig c4;
  c4.use_procedural_bodies = false;
  c4.noise.enabled = false;
  for (const char* name : {"girl-8", "female-young-average", "male-young-heavy"}) {
    for (const auto& p : assets::MakeHumanPresets()) {
      if (p.name != name) continue;
      auto body = kit.Build(p);
      if (!body.ok()) return body.status();
      c4.bodies.push_back(std::move(body).value());
    }
  }
  for (const char* f : {"cesium_man/CesiumMan.glb", "quaternius_modular_women/Soldier.gltf",
                        "quaternius_casual_female/Casual_Female.gltf"}) {
    auto body = assets::LoadRiggedMesh(data / "meshes" / f);
    if (!body.ok()) return body.status();
    c4.bodies.push_back(std::move(body).value());
  }
  auto r4 = SyntheticRenderer::Create(c4);
  if (!r4.ok()) return r4.status();
  const int n = int((*r4)->bodies().size()), cell_w = 200;
  RgbImage grid;
  grid.width = n * cell_w;
  grid.height = 2 * 240;
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 0);
  for (int b = 0; b < n; ++b) {
    for (int k = 0; k < 2; ++k) {
      auto f = (*r4)->RenderScene(Front(b, k ? 180.0 : 0.0, 3.2, 0.95));
      if (!f.ok()) return f.status();
      Blit(CropX(LabelsToColour(f->labels, 2), 160 - cell_w / 2, cell_w), &grid, b * cell_w, k * 240);
    }
  }
  if (auto st = runtime::WriteRgbPng((out / "asset_bodies.png").string(), grid.width, grid.height, grid.rgb);
      !st.ok())
    return st;
  std::printf("wrote %s/asset_bodies.png\n", out.c_str());
  return core::Status::Ok();
}

// 6. MakeHuman bodies in MakeHuman clothes, hair and shoes: a skirt, long hair, an
//    open jacket, dungarees, a suit and a hat among them, then two sampled clothed bodies; per
//    body, clean depth and parts in the rest pose (from the front left) and in a procedural
//    pose (from behind).
core::Status WriteClothedBodies(const std::filesystem::path& data, const assets::MakeHumanKit& kit,
                                const std::filesystem::path& out) {
  const auto clothes_dir = data / "meshes" / "makehuman_clothes";
  auto wardrobe = assets::LoadMakeHumanWardrobe(clothes_dir, kit.base_vertex_count());
  if (!wardrobe.ok()) return wardrobe.status();
  auto find = [&](const std::string& name) -> const assets::MhcloProxy* {
    for (const auto* list : {&wardrobe->outfits, &wardrobe->hair, &wardrobe->hats, &wardrobe->shoes})
      for (const auto& p : *list)
        if (p->name == name) return p.get();
    return nullptr;
  };
  const std::pair<const char*, std::vector<const char*>> dressed[] = {
      {"female-young-average", {"female_elegantsuit01", "long01", "shoes01"}},
      {"male-young-average", {"male_casualsuit05", "short02", "shoes02"}},
      {"female-young-thin", {"female_casualsuit02", "ponytail01", "shoes02"}},
      {"male-young-heavy", {"male_worksuit01", "afro01", "shoes03"}},
      {"girl-11-thin", {"female_sportsuit01", "braid01", "shoes02"}},
      {"male-old", {"male_elegantsuit01", "short04", "fedora_cocked", "shoes03"}},
  };
  SceneConfig c6;
  c6.use_procedural_bodies = false;
  c6.noise.enabled = false;
  for (const auto& [preset, names] : dressed) {
    std::vector<const assets::MhcloProxy*> outfit;
    for (const char* n : names)
      if (const auto* p = find(n)) outfit.push_back(p);
    for (const auto& p : assets::MakeHumanPresets()) {
      if (p.name != preset) continue;
      auto body = kit.BuildDressed(p, outfit);
      if (!body.ok()) return body.status();
      c6.bodies.push_back(AssembleDressedBody(std::move(body).value()));
    }
  }
  MakeHumanBodyOptions sampled{2, 3, 1.0, clothes_dir};
  auto more = MakeHumanBodies(data / "meshes" / "makehuman_hm08_kit", sampled);
  if (!more.ok()) return more.status();
  for (size_t k = more->size() - 2; k < more->size(); ++k) c6.bodies.push_back((*more)[k]);
  auto r6 = SyntheticRenderer::Create(c6);
  if (!r6.ok()) return r6.status();
  const int n6 = int((*r6)->bodies().size()), w6 = 150;
  RgbImage clothed;
  clothed.width = n6 * w6;
  clothed.height = 4 * 240;
  clothed.rgb.assign(size_t(clothed.width) * size_t(clothed.height) * 3, 0);
  for (int b = 0; b < n6; ++b) {
    for (int k = 0; k < 2; ++k) {
      SceneSample scene = Front(b, k ? 150.0 : 20.0, 2.5, 0.95);
      if (k) {
        const BodyMesh& body = (*r6)->bodies()[size_t(b)];
        scene.people[0].pose = assets::AdaptPose(SampleProceduralPose(17, uint64_t(b)), body.rest_joints);
      }
      auto f = (*r6)->RenderScene(scene);
      if (!f.ok()) return f.status();
      Blit(CropX(DepthToGrey(f->depth, 2), 160 - w6 / 2, w6), &clothed, b * w6, 2 * k * 240);
      Blit(CropX(LabelsToColour(f->labels, 2), 160 - w6 / 2, w6), &clothed, b * w6, (2 * k + 1) * 240);
    }
  }
  if (auto st = runtime::WriteRgbPng((out / "clothed_bodies.png").string(), clothed.width, clothed.height,
                                     clothed.rgb);
      !st.ok())
    return st;
  std::printf("wrote %s/clothed_bodies.png\n", out.c_str());
  return core::Status::Ok();
}
#endif

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 && argc != 3) {
    std::fprintf(stderr, "usage: render_docs OUT_DIR [DATA_DIR]\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  std::filesystem::create_directories(out);
  SceneConfig config;
  config.variants_per_shape = 1;
  config.noise.enabled = false;
  auto r = SyntheticRenderer::Create(config);
  if (!r.ok()) return Fail(r.status());
  std::printf("GL: %s\n", (*r)->GlRendererString().c_str());

  if (auto st = WriteFamily(**r, out); !st.ok()) return Fail(st);
  if (auto st = WriteFrontBack(**r, out); !st.ok()) return Fail(st);
  if (auto st = WriteMontage(out); !st.ok()) return Fail(st);
  if (auto st = WriteCloseup(out); !st.ok()) return Fail(st);
  if (auto st = WriteClutter(out); !st.ok()) return Fail(st);
#ifdef POSEFOREST_DOCS_WITH_ASSETS
  if (argc == 3) {
    const std::filesystem::path data = argv[2];
    auto kit = assets::MakeHumanKit::Load(data / "meshes" / "makehuman_hm08_kit");
    if (!kit.ok()) return Fail(kit.status());
    if (auto st = WriteAssetBodies(data, **kit, out); !st.ok()) return Fail(st);
    if (auto st = WriteClothedBodies(data, **kit, out); !st.ok()) return Fail(st);
  }
#endif
  std::printf("wrote %s/{procedural_family,front_back,montage,closeup_noise,clutter_segmentation}.png\n",
              out.c_str());
  return 0;
}
