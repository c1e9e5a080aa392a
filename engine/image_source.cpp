#include "engine/image_source.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "runtime/core/body_parts.h"
#include "runtime/core/forest_format.h"
#include "runtime/camera_model.h"
#include "runtime/core/rng.h"
#include "runtime/image_io.h"
#if POSEFOREST_HAS_RENDERER
#include <deque>
#include <mutex>
#include <utility>

#include "engine/rendered_scene.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/part_labels.h"
#include "renderer/scene_assets.h"
#include "renderer/synthetic_source.h"
#endif

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {


class ProceduralImageSource final : public ImageSource {
 public:
  explicit ProceduralImageSource(SourceSpec spec) : spec_(std::move(spec)) {}
  Result<LabelledFrame> Frame(uint64_t index) override { return MakeProceduralFrame(spec_, index); }
  uint64_t size() const override { return 0; }
  std::string Describe() const override {
    return "procedural seed " + std::to_string(spec_.seed) + " (" + std::to_string(spec_.width) + "x" +
           std::to_string(spec_.height) + ", " + std::to_string(spec_.num_parts) + " parts)";
  }

 private:
  SourceSpec spec_;
};

class DatasetImageSource final : public ImageSource {
 public:
  DatasetImageSource(SourceSpec spec, uint64_t count) : spec_(std::move(spec)), count_(count) {}
  Result<LabelledFrame> Frame(uint64_t index) override {
    return ReadDatasetFrame(spec_.folder, spec_.first_index + index % count_);
  }
  uint64_t size() const override { return count_; }
  std::string Describe() const override {
    return "dataset " + spec_.folder + " (" + std::to_string(count_) + " frames from " +
           std::to_string(spec_.first_index) + ")";
  }

 private:
  SourceSpec spec_;
  uint64_t count_;
};

#if POSEFOREST_HAS_RENDERER
/// A small process-wide cache of loaded assets: every thread (and every tree) of a job creates
/// its own ImageSource, but the pose library is read and the MakeHuman bodies are built once.
/// Keys name the file and its size + modification time, so an edited library is reloaded; the
/// `max_entries` most recent entries are kept (a long-lived worker may see several jobs).
template <typename T>
class AssetCache {
 public:
  explicit AssetCache(size_t max_entries = 4) : max_entries_(max_entries) {}
  template <typename Make>
  Result<std::shared_ptr<const T>> Get(const std::string& key, Make make) {
    std::lock_guard<std::mutex> lock(mu_);  // held while loading: the other threads wait for it
    for (const auto& [k, v] : entries_)
      if (k == key) return v;
    Result<std::shared_ptr<const T>> made = make();
    if (!made.ok()) return made.status();
    entries_.emplace_back(key, *made);
    if (entries_.size() > max_entries_) entries_.pop_front();
    return made;
  }

 private:
  const size_t max_entries_;
  std::mutex mu_;
  std::deque<std::pair<std::string, std::shared_ptr<const T>>> entries_;
};

std::string FileKey(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  std::string key = fs::absolute(path, ec).lexically_normal().string();
  const auto size = fs::file_size(path, ec);
  if (!ec) key.append(1, '|').append(std::to_string(size));
  const auto time = fs::last_write_time(path, ec);
  if (!ec) key.append(1, '|').append(std::to_string(time.time_since_epoch().count()));
  return key;
}

Result<std::shared_ptr<const std::vector<renderer::Pose>>> SharedPoses(const SourceSpec& spec) {
  static AssetCache<std::vector<renderer::Pose>> cache;
  renderer::PoseSelection sel;
  sel.library = spec.pose_library;
  sel.clips = spec.clips == ClipSet::kTrain  ? renderer::ClipSet::kTrain
              : spec.clips == ClipSet::kTest ? renderer::ClipSet::kTest
                                             : renderer::ClipSet::kAll;
  sel.test_fraction = spec.test_fraction;
  sel.split_seed = spec.split_seed;
  char tail[96];
  std::snprintf(tail, sizeof tail, "|%s|%.17g|%llu", renderer::ClipSetName(sel.clips), sel.test_fraction,
                static_cast<unsigned long long>(sel.split_seed));
  return cache.Get(FileKey(spec.pose_library) + tail, [&] { return renderer::LoadPoseSelection(sel); });
}

Result<std::shared_ptr<const std::vector<renderer::BodyMesh>>> SharedMakeHumanBodies(const SourceSpec& spec) {
  static AssetCache<std::vector<renderer::BodyMesh>> cache;
  renderer::MakeHumanBodyOptions options;
  options.sampled_bodies = spec.makehuman_sampled_bodies;
  options.seed = spec.makehuman_body_seed;
  options.clothed_share = spec.makehuman_clothed_share;
  options.clothes_dir = spec.makehuman_clothes;
  std::string key = FileKey(spec.makehuman_kit);
  if (options.sampled_bodies > 0 || options.clothed_share > 0) {  // presets alone keep their key
    char tail[96];
    std::snprintf(tail, sizeof tail, "|%d|%llu|%.17g|", options.sampled_bodies,
                  static_cast<unsigned long long>(options.seed), options.clothed_share);
    key += tail + (options.clothed_share > 0 ? FileKey(spec.makehuman_clothes) : std::string());
  }
  return cache.Get(
      key, [&]() -> Result<std::shared_ptr<const std::vector<renderer::BodyMesh>>> {
        auto bodies = renderer::MakeHumanBodies(spec.makehuman_kit, options);
        if (!bodies.ok()) return bodies.status();
        return std::make_shared<const std::vector<renderer::BodyMesh>>(std::move(bodies).value());
      });
}

/// Rigged meshes, each labelled once here (as MakeHumanPresetBodies labels its presets) so the
/// renderer of every thread does not label it again. Room for the meshes of a few jobs.
Result<std::shared_ptr<const renderer::BodyMesh>> SharedBodyMesh(
    const std::string& path, const std::vector<std::pair<std::string, std::string>>& bone_map) {
  static AssetCache<renderer::BodyMesh> cache(32);
  std::string key = FileKey(path);  // a mesh loaded with another bone map is another body
  for (const auto& [joint, bone] : bone_map) key += "|" + joint + "=" + bone;
  return cache.Get(key, [&]() -> Result<std::shared_ptr<const renderer::BodyMesh>> {
    renderer::assets::MeshLoadOptions options;
    if (!bone_map.empty()) {
      auto map = renderer::assets::BoneMapFromPairs(bone_map, "job body_bone_map");
      if (!map.ok()) return map.status();
      options.bone_maps.push_back(std::move(map).value());
    }
    auto body = renderer::assets::LoadRiggedMesh(path, options);
    if (!body.ok()) return body.status();
    renderer::LabelBodyParts(*body);
    renderer::RefinePartBoundaries(*body, 2);
    return std::make_shared<const renderer::BodyMesh>(std::move(body).value());
  });
}
#endif

}  // namespace

core::CameraIntrinsics SensorCamera(DepthSensor sensor) {
#if POSEFOREST_HAS_RENDERER
  return renderer::SensorNoise(sensor == DepthSensor::kKinectV2          ? renderer::DepthSensor::kKinectV2
                               : sensor == DepthSensor::kAzureKinectNfov ? renderer::DepthSensor::kAzureKinectNfov
                                                                         : renderer::DepthSensor::kKinectV1)
      .camera;
#else
  (void)sensor;
  return core::CameraIntrinsics::KinectV1();
#endif
}

Result<core::CameraIntrinsics> SourceCamera(const SourceSpec& spec) {
  switch (spec.kind) {
    case SourceKind::kRendered:
      return spec.sensor_camera ? SensorCamera(spec.sensor) : core::CameraIntrinsics::KinectV1();
    case SourceKind::kProcedural:
      // Flat figures with no camera of their own: the Kinect v1's focal length, as the
      // procedural test frames' (evaluation.h EvalFrameSource::camera).
      return core::CameraIntrinsics::KinectV1();
    case SourceKind::kDataset: {
      const std::string camera_file = (std::filesystem::path(spec.folder) / "camera.txt").string();
      std::error_code ec;
      if (!std::filesystem::exists(camera_file, ec)) return core::CameraIntrinsics::KinectV1();
      auto model = runtime::ReadCameraModelFile(camera_file);
      if (!model.ok()) return model.status();
      return model->intrinsics;
    }
  }
  return Status(ErrorCode::kInternal, "unknown source kind");
}

Result<core::Forest> EmptyForest(const TrainParams& params) {
  auto camera = SourceCamera(params.source);
  if (!camera.ok()) return camera.status();
  core::Forest forest;
  forest.constants = params.constants;
  forest.num_parts = core::kNumParts;
  forest.part_names = core::Forest::DefaultPartNames();
  forest.training_fx = float(camera->fx);
  forest.training_fy = float(camera->fy);
  return forest;
}

#if POSEFOREST_HAS_RENDERER
Status ApplySceneOptions(const SourceSpec& spec, renderer::SceneConfig* scene) {
  scene->rotation_range_deg = spec.rotation_range_deg;
  scene->turned_share = spec.turned_share;
  scene->turned_range_deg = spec.turned_range_deg;
  scene->min_people = 1;
  scene->max_people = spec.max_people;
  scene->noise.enabled = spec.kinect_noise;
  scene->min_distance_m = spec.min_distance_m;
  scene->max_distance_m = spec.max_distance_m;
  scene->framing.upper_body_share = spec.upper_body_share;
  scene->framing.upper_body_min_distance_m = spec.upper_body_min_distance_m;
  scene->framing.upper_body_max_distance_m = spec.upper_body_max_distance_m;
  scene->arm_pose_share = spec.arm_pose_share;
  scene->sit_share = spec.sitting_share;
  scene->lean_share = spec.leaning_share;
  // The sensor's own camera (sensor_camera), else the Kinect v1's, whatever the sensor.
  if (spec.sensor_camera) scene->camera = SensorCamera(spec.sensor);
  {
    // The sensor's noise model (Kinect v1: the classic one), at the render camera's focal length.
    const renderer::DepthSensor sensor =
        spec.sensor == DepthSensor::kKinectV2          ? renderer::DepthSensor::kKinectV2
        : spec.sensor == DepthSensor::kAzureKinectNfov ? renderer::DepthSensor::kAzureKinectNfov
                                                       : renderer::DepthSensor::kKinectV1;
    const bool enabled = scene->noise.enabled;
    scene->noise = renderer::SensorNoise(sensor).noise;
    scene->noise.enabled = enabled;
    scene->noise.focal_px = scene->camera.fx;
    if (spec.flying_pixels) scene->noise.flying_pixels = *spec.flying_pixels;
    if (spec.range_holes) scene->noise.range_dropout = *spec.range_holes;
    if (spec.grazing_holes) scene->noise.grazing_dropout = *spec.grazing_holes;
  }
  scene->noise.projector_shadow = spec.projector_shadow;
  scene->noise.min_range_m = spec.min_range_m;
  if (!spec.pose_library.empty()) {
    auto poses = SharedPoses(spec);
    if (!poses.ok()) return poses.status();
    scene->shared_poses = *poses;
  }
  scene->use_procedural_bodies = spec.procedural_bodies;
  if (!spec.makehuman_kit.empty()) {
    auto bodies = SharedMakeHumanBodies(spec);
    if (!bodies.ok()) return bodies.status();
    scene->bodies = **bodies;  // the renderer keeps its own copy (uploaded to its GL context)
  }
  for (const std::string& path : spec.body_meshes) {  // after the presets, in job order
    auto body = SharedBodyMesh(path, spec.body_bone_map);
    if (!body.ok()) return body.status();
    scene->bodies.push_back(**body);
  }
  return Status::Ok();
}
#endif

Status PreloadBodyMesh(const std::string& path, const std::vector<std::pair<std::string, std::string>>& bone_map) {
#if POSEFOREST_HAS_RENDERER
  auto body = SharedBodyMesh(path, bone_map);
  return body.ok() ? Status::Ok() : body.status();
#else
  (void)path, (void)bone_map;
  return Status::Ok();
#endif
}

Status CheckBoneMap(const std::vector<std::pair<std::string, std::string>>& bone_map) {
#if POSEFOREST_HAS_RENDERER
  auto map = renderer::assets::BoneMapFromPairs(bone_map, "job body_bone_map");
  return map.ok() ? Status::Ok() : map.status();
#else
  (void)bone_map;
  return Status::Ok();
#endif
}

namespace {
#if POSEFOREST_HAS_RENDERER

class RenderedImageSource final : public ImageSource {
 public:
  RenderedImageSource(SourceSpec spec, std::unique_ptr<renderer::SyntheticRenderer> r)
      : spec_(std::move(spec)), renderer_(std::move(r)) {}
  Result<LabelledFrame> Frame(uint64_t index) override {
    auto frame = renderer_->Render(spec_.seed, index);
    if (!frame.ok()) return frame.status();
    LabelledFrame out;
    out.depth = std::move(frame->depth);
    out.labels = std::move(frame->labels);
    return out;
  }
  uint64_t size() const override { return 0; }
  std::string Describe() const override {
    std::string d = "rendered seed " + std::to_string(spec_.seed);
    if (!spec_.pose_library.empty()) {
      const char* clips = spec_.clips == ClipSet::kTrain  ? "train"
                          : spec_.clips == ClipSet::kTest ? "test"
                                                          : "all";
      d += ", poses: " + std::string(clips) + " clips of " + spec_.pose_library;
    }
    if (const std::string bodies = DescribeBodies(spec_); !bodies.empty()) d += ", bodies: " + bodies;
    return d;
  }

 private:
  SourceSpec spec_;
  std::unique_ptr<renderer::SyntheticRenderer> renderer_;
};
#endif

}  // namespace

LabelledFrame MakeProceduralFrame(const SourceSpec& spec, uint64_t index) {
  const core::CounterRng rng(spec.seed, index, 0, 0x50524F43);  // "PROC"
  core::RngStream draw(rng);
  LabelledFrame frame{core::DepthImage(spec.width, spec.height, 0),
                      core::LabelImage(spec.width, spec.height, core::kBackgroundLabel)};
  const double f = 575.8 * spec.width / 640.0;  // Kinect-like field of view at any resolution
  const int cols = 4, rows = (spec.num_parts + cols - 1) / cols;
  const double distance_m = draw.UniformIn(1.5, 4.0);
  const double fig_w = draw.UniformIn(0.40, 0.60), fig_h = draw.UniformIn(1.3, 1.9);  // metres
  const double cell_w = fig_w / cols, cell_h = fig_h / rows;
  const double cx = spec.width * draw.UniformIn(0.3, 0.7),
               top = spec.height * 0.5 - f * fig_h / distance_m * 0.5;
  const double tilt_mm = draw.UniformIn(-150.0, 150.0);  // depth change across the figure's width
  for (int r = 0; r < rows; ++r) {
    const double shift_m = draw.UniformIn(-0.6, 0.6) * cell_w;  // a crude per-row "pose"
    for (int c = 0; c < cols; ++c) {
      const int part = r * cols + c;
      const double bump_mm = 40.0 * ((r + 2 * c) % 3) + draw.UniformIn(-10.0, 10.0);
      if (part >= spec.num_parts) continue;
      const int x0 = int(std::lround(cx + f * ((c - cols * 0.5) * cell_w + shift_m) / distance_m));
      const int x1 = int(std::lround(cx + f * ((c + 1 - cols * 0.5) * cell_w + shift_m) / distance_m));
      const int y0 = int(std::lround(top + f * r * cell_h / distance_m));
      const int y1 = int(std::lround(top + f * (r + 1) * cell_h / distance_m));
      for (int y = std::max(0, y0); y < std::min(spec.height, y1); ++y) {
        for (int x = std::max(0, x0); x < std::min(spec.width, x1); ++x) {
          const double z =
              distance_m * 1000.0 + bump_mm + tilt_mm * (double(x) - cx) / (f * fig_w / distance_m);
          frame.depth.at(x, y) = uint16_t(std::clamp(std::lround(z), 1L, 9000L));
          frame.labels.at(x, y) = uint8_t(part);
        }
      }
    }
  }
  return frame;
}

std::string DatasetFramePath(const std::string& folder, const char* stem, uint64_t index, const char* ext) {
  char name[64];
  std::snprintf(name, sizeof(name), "%s_%06llu.%s", stem, static_cast<unsigned long long>(index), ext);
  return (std::filesystem::path(folder) / name).string();
}

Result<LabelledFrame> ReadDatasetFrame(const std::string& folder, uint64_t index) {
  const std::string depth_path = DatasetFramePath(folder, "depth", index),
                    label_path = DatasetFramePath(folder, "labels", index);
  auto depth = runtime::ReadDepthImage(depth_path);
  if (!depth.ok()) return depth.status();
  auto bytes = core::ReadFileBytes(label_path);
  if (!bytes.ok()) return bytes.status();
  // 8-bit greyscale only, refused from the header before decoding (runtime/image_io.h).
  auto labels = runtime::DecodeLabelPng(*bytes, label_path);
  if (!labels.ok()) return labels.status();
  if (labels->width != depth->width || labels->height != depth->height)
    return Status(ErrorCode::kInvalidArgument, label_path + ": size differs from " + depth_path);
  LabelledFrame frame;
  frame.depth = std::move(*depth);
  frame.labels = std::move(*labels);
  for (size_t i = 0; i < frame.labels.pixels.size(); ++i) {
    const uint8_t l = frame.labels.pixels[i];
    if (l >= core::kNumParts && l != core::kBackgroundLabel)
      return Status(ErrorCode::kDataLoss, label_path + ": label " + std::to_string(l) + " at pixel " +
                                              std::to_string(i) +
                                              " is neither a part (0..30) nor background (255)");
  }
  return frame;
}

Result<std::unique_ptr<ImageSource>> MakeImageSource(const SourceSpec& spec) {
  switch (spec.kind) {
    case SourceKind::kProcedural:
      return std::unique_ptr<ImageSource>(new ProceduralImageSource(spec));
    case SourceKind::kDataset: {
      namespace fs = std::filesystem;
      std::error_code ec;
      if (!fs::is_directory(spec.folder, ec))
        return Status(ErrorCode::kNotFound, spec.folder + ": dataset folder not found");
      uint64_t count = spec.count;
      if (count == 0) {
        while (fs::exists(DatasetFramePath(spec.folder, "depth", spec.first_index + count), ec)) ++count;
        if (count == 0)
          return Status(ErrorCode::kNotFound,
                        spec.folder + ": no " +
                            fs::path(DatasetFramePath(spec.folder, "depth", spec.first_index)).filename().string() +
                            " (expected depth_%06d.png + labels_%06d.png from `poseforest render`)");
      } else if (!fs::exists(DatasetFramePath(spec.folder, "depth", spec.first_index + count - 1), ec)) {
        return Status(ErrorCode::kNotFound, DatasetFramePath(spec.folder, "depth", spec.first_index + count - 1) +
                                                ": missing (dataset.count = " + std::to_string(count) + ")");
      }
      return std::unique_ptr<ImageSource>(new DatasetImageSource(spec, count));
    }
    case SourceKind::kRendered: {
#if POSEFOREST_HAS_RENDERER
      renderer::SceneConfig scene;
      POSEFOREST_RETURN_IF_ERROR(ApplySceneOptions(spec, &scene));
      auto r = renderer::SyntheticRenderer::Create(scene);
      if (!r.ok()) return r.status();
      return std::unique_ptr<ImageSource>(new RenderedImageSource(spec, std::move(*r)));
#else
      return Status(
          ErrorCode::kUnimplemented,
          "source.rendered: this build has no synthetic renderer; use a dataset folder or procedural source");
#endif
    }
  }
  return Status(ErrorCode::kInternal, "unknown source kind");
}

}  // namespace poseforest::engine
