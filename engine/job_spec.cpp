#include "engine/job_spec.h"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "engine/image_source.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

class CollectErrors : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, int column, const std::string& message) override {
    if (!text_.empty()) text_ += "; ";
    text_ += "line " + std::to_string(line + 1) + ":" + std::to_string(column + 1) + ": " + message;
  }
  void AddWarning(int line, int column, const std::string& message) override {
    AddError(line, column, message);
  }
  const std::string& text() const { return text_; }

 private:
  std::string text_;
};

Status Bad(const std::string& source, const std::string& field, const std::string& value,
           const std::string& why) {
  return Status(ErrorCode::kInvalidArgument,
                source + ": " + field + (value.empty() ? "" : " = " + value) + ": " + why);
}

template <typename T>
std::string Str(T v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// The rendered scene: seed, view rotation, people, their distances and the pose shares.
Status SceneFromProto(const v1::RenderedSource& r, const std::string& source, const std::string& field,
                      SourceSpec& spec) {
  spec.seed = r.has_seed() ? r.seed() : 1;
  spec.rotation_range_deg = r.has_rotation_range_deg() ? r.rotation_range_deg() : 120.0;
  if (!std::isfinite(spec.rotation_range_deg) || spec.rotation_range_deg < 0 || spec.rotation_range_deg > 180)
    return Bad(source, field + ".rendered.rotation_range_deg", Str(spec.rotation_range_deg),
               "must be in 0..180 degrees");
  spec.turned_share = r.has_turned_share() ? r.turned_share() : 0.0;
  if (!std::isfinite(spec.turned_share) || spec.turned_share < 0 || spec.turned_share > 1)
    return Bad(source, field + ".rendered.turned_share", Str(spec.turned_share), "must be in 0..1");
  spec.turned_range_deg = r.has_turned_range_deg() ? r.turned_range_deg() : 180.0;
  if (!std::isfinite(spec.turned_range_deg) || spec.turned_range_deg < 0 || spec.turned_range_deg > 180)
    return Bad(source, field + ".rendered.turned_range_deg", Str(spec.turned_range_deg),
               "must be in 0..180 degrees");
  spec.max_people = r.has_max_people() ? int(r.max_people()) : 1;
  if (spec.max_people < 1 || spec.max_people > 8)
    return Bad(source, field + ".rendered.max_people", Str(r.max_people()), "must be in 1..8");
  spec.kinect_noise = r.has_kinect_noise() ? r.kinect_noise() : true;
  spec.min_distance_m = r.has_min_distance_m() ? r.min_distance_m() : 1.5;
  spec.max_distance_m = r.has_max_distance_m() ? r.max_distance_m() : 4.5;
  if (!std::isfinite(spec.min_distance_m) || spec.min_distance_m < 0.5 || spec.min_distance_m > 8)
    return Bad(source, field + ".rendered.min_distance_m", Str(spec.min_distance_m), "must be in 0.5..8 m");
  if (!std::isfinite(spec.max_distance_m) || spec.max_distance_m < spec.min_distance_m ||
      spec.max_distance_m > 8)
    return Bad(source, field + ".rendered.max_distance_m", Str(spec.max_distance_m),
               "must be in min_distance_m..8 m");
  const SourceSpec defaults;  // the documented defaults (job.proto)
  auto share = [&](bool has, double v, double def, const char* name, double* out) -> Status {
    *out = has ? v : def;
    if (!std::isfinite(*out) || *out < 0 || *out > 1)
      return Bad(source, field + ".rendered." + name, Str(*out), "must be in 0..1");
    return Status::Ok();
  };
  if (auto st = share(r.has_upper_body_share(), r.upper_body_share(), defaults.upper_body_share,
                      "upper_body_share", &spec.upper_body_share);
      !st.ok())
    return st;
  if (auto st = share(r.has_arm_pose_share(), r.arm_pose_share(), defaults.arm_pose_share, "arm_pose_share",
                      &spec.arm_pose_share);
      !st.ok())
    return st;
  if (auto st = share(r.has_sitting_share(), r.sitting_share(), defaults.sitting_share, "sitting_share",
                      &spec.sitting_share);
      !st.ok())
    return st;
  if (auto st = share(r.has_leaning_share(), r.leaning_share(), defaults.leaning_share, "leaning_share",
                      &spec.leaning_share);
      !st.ok())
    return st;
  spec.upper_body_min_distance_m =
      r.has_upper_body_min_distance_m() ? r.upper_body_min_distance_m() : defaults.upper_body_min_distance_m;
  spec.upper_body_max_distance_m =
      r.has_upper_body_max_distance_m() ? r.upper_body_max_distance_m() : defaults.upper_body_max_distance_m;
  if (!std::isfinite(spec.upper_body_min_distance_m) || spec.upper_body_min_distance_m < 0.4 ||
      spec.upper_body_min_distance_m > 8)
    return Bad(source, field + ".rendered.upper_body_min_distance_m", Str(spec.upper_body_min_distance_m),
               "must be in 0.4..8 m");
  if (!std::isfinite(spec.upper_body_max_distance_m) ||
      spec.upper_body_max_distance_m < spec.upper_body_min_distance_m || spec.upper_body_max_distance_m > 8)
    return Bad(source, field + ".rendered.upper_body_max_distance_m", Str(spec.upper_body_max_distance_m),
               "must be in upper_body_min_distance_m..8 m");
  return Status::Ok();
}

// The depth camera: the projector's shadow, its range, the sensor's artefacts and image size.
Status SensorFromProto(const v1::RenderedSource& r, const std::string& source, const std::string& field,
                       SourceSpec& spec) {
  const SourceSpec defaults;  // the documented defaults (job.proto)
  spec.projector_shadow = r.has_projector_shadow() ? r.projector_shadow() : defaults.projector_shadow;
  spec.min_range_m = r.has_min_range_m() ? r.min_range_m() : defaults.min_range_m;
  if (!std::isfinite(spec.min_range_m) || spec.min_range_m < 0 || spec.min_range_m > 2)
    return Bad(source, field + ".rendered.min_range_m", Str(spec.min_range_m), "must be in 0..2 m");
  switch (r.sensor()) {  // the depth camera's artefacts (fields 25-28)
    case v1::DEPTH_SENSOR_UNSPECIFIED:
    case v1::DEPTH_SENSOR_KINECT_V1:
      spec.sensor = DepthSensor::kKinectV1;
      break;
    case v1::DEPTH_SENSOR_KINECT_V2:
      spec.sensor = DepthSensor::kKinectV2;
      break;
    case v1::DEPTH_SENSOR_AZURE_KINECT_NFOV:
      spec.sensor = DepthSensor::kAzureKinectNfov;
      break;
    default:
      return Bad(source, field + ".rendered.sensor", Str(int(r.sensor())), "unknown depth sensor");
  }
  // Kinect v2 and Azure Kinect NFOV unbinned both read from 0.5 m (renderer::SensorNoise).
  if (spec.sensor != DepthSensor::kKinectV1 && !r.has_min_range_m()) spec.min_range_m = 0.5;
  auto optional_share = [&](bool has, double v, const char* name, std::optional<double>* out) -> Status {
    if (!has) return Status::Ok();  // the sensor's value
    if (!std::isfinite(v) || v < 0 || v > 1)
      return Bad(source, field + ".rendered." + name, Str(v), "must be in 0..1");
    *out = v;
    return Status::Ok();
  };
  if (auto st =
          optional_share(r.has_flying_pixels(), r.flying_pixels(), "flying_pixels", &spec.flying_pixels);
      !st.ok())
    return st;
  if (auto st = optional_share(r.has_range_holes(), r.range_holes(), "range_holes", &spec.range_holes);
      !st.ok())
    return st;
  if (auto st =
          optional_share(r.has_grazing_holes(), r.grazing_holes(), "grazing_holes", &spec.grazing_holes);
      !st.ok())
    return st;
  spec.width = 640;
  spec.height = 480;
  spec.sensor_camera = r.sensor_camera();
  if (spec.sensor_camera) {
    const core::CameraIntrinsics cam = SensorCamera(spec.sensor);
    spec.width = cam.width;
    spec.height = cam.height;
  }
  return Status::Ok();
}

// The pose library and its clip split.
Status PoseLibraryFromProto(const v1::RenderedSource& r, const std::string& source, const std::string& field,
                            SourceSpec& spec) {
  namespace fs = std::filesystem;
  std::error_code ec;
  spec.pose_library = r.pose_library();
  if (!spec.pose_library.empty() && !fs::is_regular_file(spec.pose_library, ec))
    return Bad(source, field + ".rendered.pose_library", "\"" + spec.pose_library + "\"",
               fs::exists(spec.pose_library, ec)
                   ? "is not a file (expected a .pfposes pose library from `poseforest-poselib build`)"
                   : "no such file (expected a .pfposes pose library from `poseforest-poselib build`)");
  switch (r.clips()) {
    case v1::CLIP_SET_UNSPECIFIED:
    case v1::CLIP_SET_ALL:
      spec.clips = ClipSet::kAll;
      break;
    case v1::CLIP_SET_TRAIN:
      spec.clips = ClipSet::kTrain;
      break;
    case v1::CLIP_SET_TEST:
      spec.clips = ClipSet::kTest;
      break;
    default:
      return Bad(source, field + ".rendered.clips", Str(int(r.clips())), "unknown clip set");
  }
  spec.test_fraction = r.has_test_fraction() ? r.test_fraction() : 0.2;
  if (!std::isfinite(spec.test_fraction) || spec.test_fraction < 0 || spec.test_fraction > 1)
    return Bad(source, field + ".rendered.test_fraction", Str(spec.test_fraction), "must be in 0..1");
  spec.split_seed = r.split_seed();
  if (spec.pose_library.empty() && (r.has_clips() || r.has_test_fraction() || r.has_split_seed()))
    return Bad(source, field + ".rendered.pose_library", "",
               "is required when clips, test_fraction or split_seed is set");
  return Status::Ok();
}

// The MakeHuman kit, the rigged body meshes and their bone map.
Status BodyMeshesFromProto(const v1::RenderedSource& r, const std::string& source, const std::string& field,
                           SourceSpec& spec) {
  namespace fs = std::filesystem;
  std::error_code ec;
  spec.makehuman_kit = r.makehuman_kit();
  if (!spec.makehuman_kit.empty() && !fs::is_directory(spec.makehuman_kit, ec))
    return Bad(source, field + ".rendered.makehuman_kit", "\"" + spec.makehuman_kit + "\"",
               "no such folder (expected the MakeHuman hm08 kit, e.g. <data>/meshes/makehuman_hm08_kit)");
  // The kit's files that renderer/assets/makehuman.cpp reads: a folder without them is named here,
  // with the job and field, not later by a bare file name.
  if (!spec.makehuman_kit.empty())
    for (const char* file :
         {"base.obj", "rigs/default.mhskel", "rigs/default_weights.mhw", "targets/macrodetails"})
      if (!fs::exists(fs::path(spec.makehuman_kit) / file, ec))
        return Bad(source, field + ".rendered.makehuman_kit", "\"" + spec.makehuman_kit + "\"",
                   std::string("holds no ") + file +
                       ": not the MakeHuman hm08 kit (e.g. <data>/meshes/makehuman_hm08_kit)");
  for (int i = 0; i < r.body_bone_map_size(); ++i) {
    const auto& e = r.body_bone_map(i);
    spec.body_bone_map.emplace_back(e.joint(), e.bone());
  }
  if (!spec.body_bone_map.empty()) {
    if (r.body_meshes_size() == 0)
      return Bad(source, field + ".rendered.body_bone_map", "",
                 "is only for body_meshes, and there are none");
    if (const Status st = CheckBoneMap(spec.body_bone_map); !st.ok())
      return Bad(source, field + ".rendered.body_bone_map", "", st.message());
  }
  for (int i = 0; i < r.body_meshes_size(); ++i) {
    const std::string& mesh = r.body_meshes(i);
    const std::string name = field + ".rendered.body_meshes[" + Str(i) + "]";
    if (mesh.empty()) return Bad(source, name, "\"\"", "is empty (expected a rigged mesh file)");
    if (!fs::is_regular_file(mesh, ec))
      return Bad(source, name, "\"" + mesh + "\"",
                 fs::exists(mesh, ec) ? "is not a file (expected a rigged mesh: glTF, FBX, ...)"
                                      : "no such file (expected a rigged mesh: glTF, FBX, ...)");
    // Loaded now (and kept for the renderers), so a mesh that cannot be a body fails the job
    // when it is read, not in every worker's first frame. The loader's message names the file.
    const Status loaded = PreloadBodyMesh(mesh, spec.body_bone_map);
    if (!loaded.ok()) return Bad(source, name, "\"" + mesh + "\"", "cannot be a body: " + loaded.message());
    spec.body_meshes.push_back(mesh);
  }
  return Status::Ok();
}

// More MakeHuman bodies (fields 21-24): each needs the kit.
Status MakeHumanBodiesFromProto(const v1::RenderedSource& r, const std::string& source,
                                const std::string& field, SourceSpec& spec) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const SourceSpec defaults;
  spec.makehuman_sampled_bodies = r.has_makehuman_sampled_bodies()
                                      ? int(std::min<uint32_t>(r.makehuman_sampled_bodies(), 1u << 30))
                                      : defaults.makehuman_sampled_bodies;
  spec.makehuman_body_seed =
      r.has_makehuman_body_seed() ? r.makehuman_body_seed() : defaults.makehuman_body_seed;
  spec.makehuman_clothed_share =
      r.has_makehuman_clothed_share() ? r.makehuman_clothed_share() : defaults.makehuman_clothed_share;
  if (spec.makehuman_sampled_bodies > 2000)
    return Bad(source, field + ".rendered.makehuman_sampled_bodies", Str(r.makehuman_sampled_bodies()),
               "must be in 0..2000");
  if (!std::isfinite(spec.makehuman_clothed_share) || spec.makehuman_clothed_share < 0 ||
      spec.makehuman_clothed_share > 1)
    return Bad(source, field + ".rendered.makehuman_clothed_share", Str(spec.makehuman_clothed_share),
               "must be in 0..1");
  const char* needs_kit = nullptr;
  if (spec.makehuman_sampled_bodies > 0) needs_kit = "makehuman_sampled_bodies";
  if (spec.makehuman_clothed_share > 0) needs_kit = "makehuman_clothed_share";
  if (!r.makehuman_clothes().empty()) needs_kit = "makehuman_clothes";
  if (needs_kit && spec.makehuman_kit.empty())
    return Bad(source, field + ".rendered." + needs_kit, "",
               "needs MakeHuman bodies: set makehuman_kit (the hm08 kit folder, e.g. "
               "<data>/meshes/makehuman_hm08_kit)");
  if (!r.makehuman_clothes().empty() && spec.makehuman_clothed_share == 0)
    return Bad(source, field + ".rendered.makehuman_clothes", "\"" + r.makehuman_clothes() + "\"",
               "is unused: set makehuman_clothed_share (the share of bodies dressed) too");
  if (spec.makehuman_clothed_share > 0) {
    fs::path kit = fs::path(spec.makehuman_kit).lexically_normal();
    if (!kit.has_filename()) kit = kit.parent_path();  // ".../makehuman_hm08_kit/"
    spec.makehuman_clothes = r.makehuman_clothes().empty()
                                 ? (kit.parent_path() / "makehuman_clothes").string()
                                 : r.makehuman_clothes();
    if (!fs::is_directory(spec.makehuman_clothes, ec))
      return Bad(
          source, field + ".rendered.makehuman_clothes", "\"" + spec.makehuman_clothes + "\"",
          std::string(r.makehuman_clothes().empty() ? "(the default, beside makehuman_kit): " : "") +
              "no such folder (expected MakeHuman .mhclo clothes, e.g. <data>/meshes/makehuman_clothes)");
  }
  return Status::Ok();
}

// A rendered source, its fields checked in the order of job.proto.
Status RenderedFromProto(const v1::RenderedSource& r, const std::string& source, const std::string& field,
                         SourceSpec& spec) {
  spec.kind = SourceKind::kRendered;
  if (Status st = SceneFromProto(r, source, field, spec); !st.ok()) return st;
  if (Status st = SensorFromProto(r, source, field, spec); !st.ok()) return st;
  if (Status st = PoseLibraryFromProto(r, source, field, spec); !st.ok()) return st;
  if (Status st = BodyMeshesFromProto(r, source, field, spec); !st.ok()) return st;
  if (Status st = MakeHumanBodiesFromProto(r, source, field, spec); !st.ok()) return st;
  spec.procedural_bodies = r.has_procedural_bodies() ? r.procedural_bodies() : true;
  if (!spec.procedural_bodies && spec.makehuman_kit.empty() && spec.body_meshes.empty())
    return Bad(source, field + ".rendered.procedural_bodies", "false",
               "leaves no bodies: set makehuman_kit or body_meshes, or keep the procedural bodies");
  return Status::Ok();
}

Result<SourceSpec> SourceFromProto(const v1::ImageSource& src, const std::string& source,
                                   const std::string& field) {
  SourceSpec spec;
  switch (src.kind_case()) {
    case v1::ImageSource::kRendered: {
      if (Status st = RenderedFromProto(src.rendered(), source, field, spec); !st.ok()) return st;
      break;
    }
    case v1::ImageSource::kDataset: {
      const auto& d = src.dataset();
      spec.kind = SourceKind::kDataset;
      if (d.folder().empty())
        return Bad(source, field + ".dataset.folder", "",
                   "is required (a folder written by `poseforest render`)");
      spec.folder = d.folder();
      spec.first_index = d.first_index();
      spec.count = d.count();
      break;
    }
    case v1::ImageSource::kProcedural: {
      const auto& p = src.procedural();
      spec.kind = SourceKind::kProcedural;
      spec.seed = p.has_seed() ? p.seed() : 1;
      spec.width = p.has_width() ? int(p.width()) : 320;
      spec.height = p.has_height() ? int(p.height()) : 240;
      spec.num_parts = p.has_num_parts() ? int(p.num_parts()) : core::kNumParts;
      if (spec.num_parts < 2 || spec.num_parts > core::kNumParts)
        return Bad(source, field + ".procedural.num_parts", Str(spec.num_parts), "must be in 2..31");
      break;
    }
    case v1::ImageSource::KIND_NOT_SET:
      return Bad(source, field, "",
                 "is required: set one of rendered { }, dataset { folder: ... } or procedural { }");
  }
  if (spec.kind != SourceKind::kDataset) {
    if (spec.width < 16 || spec.width > 4096)
      return Bad(source, field + ".width", Str(spec.width), "must be in 16..4096 pixels");
    if (spec.height < 16 || spec.height > 4096)
      return Bad(source, field + ".height", Str(spec.height), "must be in 16..4096 pixels");
  }
  return spec;
}

}  // namespace

int TrainParams::max_offset_units() const {
  return int(std::floor(max_probe_offset_pixel_m / double(constants.offset_unit) + 1e-9));
}

Result<v1::TrainerConfig> ParseJobText(const std::string& text, const std::string& source_name) {
  v1::TrainerConfig config;
  google::protobuf::TextFormat::Parser parser;
  CollectErrors errors;
  parser.RecordErrorsTo(&errors);
  if (!parser.ParseFromString(text, &config)) {
    return Status(ErrorCode::kInvalidArgument,
                  source_name + ": not a valid poseforest.v1.TrainerConfig text proto: " + errors.text());
  }
  return config;
}

Result<TrainParams> ParamsFromConfig(const v1::TrainerConfig& c, const std::string& source) {
  TrainParams p;
  p.seed = c.has_seed() ? c.seed() : 1;
  p.num_trees = c.has_num_trees() ? int(c.num_trees()) : 3;
  if (c.has_num_trees() && (c.num_trees() < 1 || c.num_trees() > 64))
    return Bad(source, "num_trees", Str(c.num_trees()), "must be in 1..64");
  p.max_depth = c.has_max_depth() ? int(c.max_depth()) : 20;
  if (c.has_max_depth() && (c.max_depth() < 1 || c.max_depth() > 30))
    return Bad(source, "max_depth", Str(c.max_depth()), "must be in 1..30");
  if (!c.has_images_per_tree())
    return Bad(source, "images_per_tree", "", "is required (frames per tree, > 0)");
  if (c.images_per_tree() < 1 || c.images_per_tree() > 10'000'000)
    return Bad(source, "images_per_tree", Str(c.images_per_tree()), "must be in 1..10000000");
  p.images_per_tree = int(c.images_per_tree());
  p.pixels_per_image = c.has_pixels_per_image() ? int(c.pixels_per_image()) : 2000;
  if (c.has_pixels_per_image() && (c.pixels_per_image() < 1 || c.pixels_per_image() > 1'000'000))
    return Bad(source, "pixels_per_image", Str(c.pixels_per_image()), "must be in 1..1000000");
  const uint64_t total = uint64_t(p.images_per_tree) * uint64_t(p.pixels_per_image);
  if (total > (uint64_t(1) << 31))
    return Bad(source, "images_per_tree * pixels_per_image", Str(total),
               "must be at most 2^31 samples per tree");
  p.candidate_features = c.has_candidate_features() ? int(c.candidate_features()) : 2000;
  if (c.has_candidate_features() && (c.candidate_features() < 1 || c.candidate_features() > 100000))
    return Bad(source, "candidate_features", Str(c.candidate_features()), "must be in 1..100000");
  p.thresholds_per_feature = c.has_thresholds_per_feature() ? int(c.thresholds_per_feature()) : 50;
  if (c.has_thresholds_per_feature() && (c.thresholds_per_feature() < 1 || c.thresholds_per_feature() > 255))
    return Bad(source, "thresholds_per_feature", Str(c.thresholds_per_feature()), "must be in 1..255");
  p.max_probe_offset_pixel_m = c.has_max_probe_offset_pixel_m() ? c.max_probe_offset_pixel_m() : 129.0;
  const double max_pm = 32767.0 * double(p.constants.offset_unit);
  if (!std::isfinite(p.max_probe_offset_pixel_m) || p.max_probe_offset_pixel_m < 0 ||
      p.max_probe_offset_pixel_m > max_pm)
    return Bad(source, "max_probe_offset_pixel_m", Str(p.max_probe_offset_pixel_m),
               "must be in 0.." + Str(max_pm) + " pixel*m (int16 offsets of " + Str(p.constants.offset_unit) +
                   " pixel*m)");
  p.min_samples_split = c.has_min_samples_split() ? int64_t(c.min_samples_split()) : 10;
  if (p.min_samples_split < 2)
    return Bad(source, "min_samples_split", Str(p.min_samples_split), "must be at least 2");
  p.min_gain = c.has_min_gain() ? c.min_gain() : 1e-6;
  if (!std::isfinite(p.min_gain) || p.min_gain < 0)
    return Bad(source, "min_gain", Str(p.min_gain), "must be finite and >= 0 bits");
  p.threads = int(c.threads());
  if (c.threads() > 1024)
    return Bad(source, "threads", Str(c.threads()), "must be in 0..1024 (0 = all cores)");
  p.threshold_reference_pixels = c.has_threshold_reference_pixels() ? c.threshold_reference_pixels() : 500;
  if (p.threshold_reference_pixels < 2)
    return Bad(source, "threshold_reference_pixels", Str(p.threshold_reference_pixels), "must be at least 2");
  if (c.threshold_mode() != v1::THRESHOLD_MODE_UNSPECIFIED &&
      c.threshold_mode() != v1::THRESHOLD_MODE_REFERENCE_RANGE)
    return Bad(source, "threshold_mode", Str(int(c.threshold_mode())), "unknown mode");
  switch (c.probe_edge()) {
    case v1::PROBE_EDGE_UNSPECIFIED:
    case v1::PROBE_EDGE_BACKGROUND:
      p.constants.edge = core::ProbeEdge::kBackground;
      break;
    case v1::PROBE_EDGE_CLAMP:
      p.constants.edge = core::ProbeEdge::kClamp;
      break;
    default:
      return Bad(source, "probe_edge", Str(int(c.probe_edge())),
                 "unknown: PROBE_EDGE_BACKGROUND (the paper's) or PROBE_EDGE_CLAMP");
  }
  p.pixel_probe_share = c.has_pixel_probe_share() ? c.pixel_probe_share() : 0.0;
  if (!std::isfinite(p.pixel_probe_share) || p.pixel_probe_share < 0 || p.pixel_probe_share > 1)
    return Bad(source, "pixel_probe_share", Str(p.pixel_probe_share), "must be in 0..1");
  p.part_balance = c.has_part_balance() ? c.part_balance() : 1.0;
  if (!std::isfinite(p.part_balance) || p.part_balance < 0 || p.part_balance > 1)
    return Bad(source, "part_balance", Str(p.part_balance), "must be in 0..1");
  if (c.has_histogram_memory_mb()) {
    if (c.histogram_memory_mb() < 16 || c.histogram_memory_mb() > (uint64_t(1) << 20))
      return Bad(source, "histogram_memory_mb", Str(c.histogram_memory_mb()), "must be in 16..1048576 MiB");
    p.histogram_memory_bytes = c.histogram_memory_mb() << 20;
  }
  if (c.has_subtree_max_samples()) p.subtree_max_samples = c.subtree_max_samples();
  if (c.has_subtree_max_frames()) p.subtree_max_frames = c.subtree_max_frames();
  if (!c.has_source())
    return Bad(source, "source", "",
               "is required: set one of rendered { }, dataset { folder: ... } or procedural { }");
  auto src = SourceFromProto(c.source(), source, "source");
  if (!src.ok()) return src.status();
  p.source = *src;
  if (c.has_test_set()) {
    if (!c.test_set().has_source())
      return Bad(source, "test_set.source", "", "is required when test_set is given");
    auto test = SourceFromProto(c.test_set().source(), source, "test_set.source");
    if (!test.ok()) return test.status();
    p.has_test_set = true;
    p.test_source = *test;
    p.test_images = c.test_set().has_num_images() ? int(c.test_set().num_images()) : 50;
    if (p.test_images < 1 || p.test_images > 1'000'000)
      return Bad(source, "test_set.num_images", Str(p.test_images), "must be in 1..1000000");
    p.test_pixels_per_image = int(c.test_set().pixels_per_image());
  }
  return p;
}

void ResolveJobPaths(const std::string& job_path, v1::TrainerConfig* config) {
  namespace fs = std::filesystem;
  const fs::path base = fs::path(job_path).parent_path();
  auto fix = [&](std::string* p) {
    if (!p->empty() && fs::path(*p).is_relative()) *p = (base / *p).lexically_normal().string();
  };
  for (v1::ImageSource* src : {config->has_source() ? config->mutable_source() : nullptr,
                               config->has_test_set() && config->test_set().has_source()
                                   ? config->mutable_test_set()->mutable_source()
                                   : nullptr}) {
    if (!src || !src->has_rendered()) continue;
    v1::RenderedSource* r = src->mutable_rendered();
    if (r->has_pose_library()) fix(r->mutable_pose_library());
    if (r->has_makehuman_kit()) fix(r->mutable_makehuman_kit());
    if (r->has_makehuman_clothes()) fix(r->mutable_makehuman_clothes());
    for (std::string& mesh : *r->mutable_body_meshes()) fix(&mesh);
  }
}

Result<TrainParams> LoadJob(const std::string& path) {
  auto text = core::ReadFileText(path);
  if (!text.ok()) return Status(text.status().code(), text.status().message() + " (the job config)");
  auto config = ParseJobText(*text, path);
  if (!config.ok()) return config.status();
  ResolveJobPaths(path, &*config);
  return ParamsFromConfig(*config, path);
}

std::string DescribeBodies(const SourceSpec& spec) {
  if (spec.makehuman_kit.empty() && spec.body_meshes.empty()) return "";
  std::string bodies;
  auto add = [&](const std::string& b) { bodies += (bodies.empty() ? "" : " + ") + b; };
  if (!spec.makehuman_kit.empty()) {
    std::string mh = "MakeHuman";
    if (spec.makehuman_sampled_bodies > 0) mh += " (18 presets + " + Str(spec.makehuman_sampled_bodies) + " sampled";
    if (spec.makehuman_clothed_share > 0)
      mh += std::string(spec.makehuman_sampled_bodies > 0 ? ", " : " (") + Str(spec.makehuman_clothed_share) +
            " clothed";
    if (spec.makehuman_sampled_bodies > 0 || spec.makehuman_clothed_share > 0) mh += ")";
    add(mh);
  }
  for (const std::string& m : spec.body_meshes) add("mesh " + std::filesystem::path(m).filename().string());
  if (spec.procedural_bodies) add("procedural");
  return bodies;
}

std::string DescribeParams(const TrainParams& p) {
  std::ostringstream s;
  s << p.num_trees << " trees, depth " << p.max_depth << ", " << p.images_per_tree << " images/tree x "
    << p.pixels_per_image << " pixels, " << p.candidate_features << " features x " << p.thresholds_per_feature
    << " thresholds, max offset " << p.max_probe_offset_pixel_m << " pixel*m"
    << (p.constants.edge == core::ProbeEdge::kClamp ? " (probes past the edge read the edge)" : "");
  if (p.pixel_probe_share > 0)
    s << ", " << p.pixel_probe_share * 100 << "% of the features against the pixel itself";
  s << ", seed " << p.seed;
  return s.str();
}

std::string DefaultJobId(const v1::TrainerConfig& config) {
  std::string bytes;
  config.SerializeToString(&bytes);
  const uint32_t crc = core::Crc32(bytes.data(), bytes.size());
  char buf[32];
  std::snprintf(buf, sizeof buf, "job-%08x", crc);
  return buf;
}

}  // namespace poseforest::engine
