#pragma once
// A training job, validated and with every default filled in: the plain C++ form of
// poseforest.v1.TrainerConfig that the worker and coordinator code works with. Parsing and
// validation live here (not in the coordinator) because workers receive the same config.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "runtime/core/feature.h"
#include "runtime/core/result.h"

namespace poseforest::v1 {
class TrainerConfig;
}

namespace poseforest::engine {

enum class SourceKind { kRendered, kDataset, kProcedural };

/// Clips of a pose library a rendered source draws poses from (poseforest.v1.ClipSet).
enum class ClipSet { kAll, kTrain, kTest };

/// The depth camera a rendered source models (poseforest.v1.DepthSensor).
enum class DepthSensor { kKinectV1, kKinectV2, kAzureKinectNfov };

/// Where labelled frames come from (poseforest.v1.ImageSource with defaults applied).
struct SourceSpec {
  SourceKind kind = SourceKind::kProcedural;
  uint64_t seed = 1;                ///< rendered / procedural: frame i is a pure function of (seed, i)
  double rotation_range_deg = 120;  ///< rendered: +- yaw, degrees
  double turned_share = 0.0;        ///< rendered: share of people turned further (job.proto field 32)
  double turned_range_deg = 180;    ///< rendered: their +- yaw, degrees (field 33)
  int max_people = 1;               ///< rendered
  bool kinect_noise = true;         ///< rendered: the renderer's Kinect v1 noise model
  double min_distance_m = 1.5;      ///< rendered: metres
  double max_distance_m = 4.5;      ///< rendered: metres
  /// rendered: realism (job.proto fields 14-19; defaults in job_spec.cpp, kRealism*)
  double upper_body_share = 0.25;
  double upper_body_min_distance_m = 0.6;
  double upper_body_max_distance_m = 2.0;
  double arm_pose_share = 0.5;
  double sitting_share = 0.0;  ///< rendered: share of people sat down (job.proto field 29)
  double leaning_share = 0.0;  ///< rendered: share of people leaning their upper body (field 30)
  bool projector_shadow = true;
  double min_range_m = 0.45;
  /// rendered: the depth camera's artefacts (job.proto fields 25-28). Unset: the sensor's value
  /// (renderer/scene.h SensorNoise; Kinect v1: 0, the classic model). Shares in [0, 1].
  DepthSensor sensor = DepthSensor::kKinectV1;
  /// Share of depth-edge pixels read as mixed pixels.
  std::optional<double> flying_pixels;
  /// Dropout probability at 4 m, growing as z^2.
  std::optional<double> range_holes;
  /// Dropout probability on surfaces seen edge-on.
  std::optional<double> grazing_holes;
  /// rendered: frames at the sensor's own size and intrinsics (job.proto field 31), not the
  /// Kinect v1's; width and height are then the sensor's.
  bool sensor_camera = false;
  int width = 640, height = 480;    ///< rendered / procedural: pixels
  std::string folder;               ///< dataset
  uint32_t first_index = 0;         ///< dataset: first file index
  uint32_t count = 0;               ///< dataset: frames to use (0 = every consecutive file)
  int num_parts = 31;               ///< procedural: labels used
  /// rendered: a .pfposes pose library ("" = procedural poses). Relative paths are relative to
  /// the working directory here: LoadJob has already resolved them against the job file's folder.
  std::string pose_library;
  ClipSet clips = ClipSet::kAll;  ///< rendered: clips of pose_library used
  double test_fraction = 0.2;     ///< rendered: share of clips in the test set, [0, 1]
  uint64_t split_seed = 0;        ///< rendered: seed of the clip split
  std::string makehuman_kit;      ///< rendered: MakeHuman hm08 kit folder ("" = none)
  bool procedural_bodies = true;  ///< rendered: the procedural body family
  /// rendered, with makehuman_kit (job.proto fields 21-24): continuously sampled MakeHuman bodies
  /// after the presets, the seed of their shapes and outfits, the share of MakeHuman bodies
  /// dressed, and the clothes folder (resolved: set whenever makehuman_clothed_share > 0).
  int makehuman_sampled_bodies = 0;
  uint64_t makehuman_body_seed = 1;
  double makehuman_clothed_share = 0.0;
  std::string makehuman_clothes;
  /// rendered: rigged mesh files (glTF, FBX, ... through Assimp) used as bodies after the
  /// MakeHuman presets, in this order (the order is part of the job: body i of a scene). Paths
  /// as pose_library; ParamsFromConfig has loaded each once (PreloadBodyMesh), so they are known good.
  std::vector<std::string> body_meshes;
  /// rendered: (canonical joint, bone) pairs for body meshes no built-in name map knows
  /// (job.proto body_bone_map), in job order.
  std::vector<std::pair<std::string, std::string>> body_bone_map;
};

/// Everything the trainer needs, validated: see job.proto for meanings and defaults.
struct TrainParams {
  uint64_t seed = 1;
  int num_trees = 3;
  int max_depth = 20;
  int images_per_tree = 0;
  int pixels_per_image = 2000;
  int candidate_features = 2000;
  int thresholds_per_feature = 50;
  double max_probe_offset_pixel_m = 129;
  int64_t min_samples_split = 10;
  double min_gain = 1e-6;  ///< bits
  int threads = 0;         ///< 0 = all cores
  uint64_t threshold_reference_pixels = 500;
  double part_balance = 1.0;
  /// Share of candidate features with v = 0 (job.proto pixel_probe_share); 0 = the paper's draw.
  double pixel_probe_share = 0.0;
  uint64_t histogram_memory_bytes = uint64_t(1) << 30;
  /// Distributed service: nodes of at most this many samples (all shards) are trained whole by
  /// one worker (SubtreeTask); 0 = never. The forest does not depend on it.
  uint64_t subtree_max_samples = 4096;
  /// ... and nodes whose samples lie in at most this many frames, up to 16 x subtree_max_samples
  /// samples and 1/(4 x workers) of the tree's (job.proto); 0 = only the sample rule.
  uint32_t subtree_max_frames = 256;
  core::FeatureConstants constants;
  SourceSpec source;
  bool has_test_set = false;
  SourceSpec test_source;
  int test_images = 50;
  int test_pixels_per_image = 0;  ///< 0 = every foreground pixel

  /// max_probe_offset_pixel_m in stored offset units (FeatureConstants::offset_unit).
  int max_offset_units() const;
};

/// Parses protobuf text format; errors name `source_name` with line and column.
core::Result<v1::TrainerConfig> ParseJobText(const std::string& text, const std::string& source_name);

/// Validates a config and fills defaults. Errors are InvalidArgument naming the field, e.g.
/// "job.textproto: thresholds_per_feature = 300: must be in 1..255". Files a rendered source
/// names must exist; its body_meshes are loaded here (once per process, see PreloadBodyMesh in
/// image_source.h), so a mesh that cannot be a body fails the job when it is read.
core::Result<TrainParams> ParamsFromConfig(const v1::TrainerConfig& config, const std::string& source_name);

/// Makes the relative file paths of a config (source / test_set.source rendered.pose_library,
/// rendered.makehuman_kit and rendered.body_meshes) relative to the folder of `job_path` (the job file), so
/// the job means the same whatever the working directory. Absolute and empty paths stay as they are.
void ResolveJobPaths(const std::string& job_path, v1::TrainerConfig* config);

/// Reads, parses (ResolveJobPaths against `path`) and validates a job file.
core::Result<TrainParams> LoadJob(const std::string& path);

/// The bodies of a rendered source for its description line: "MakeHuman + mesh CesiumMan.glb +
/// procedural" (job order); "" when it has only the procedural family (the default).
std::string DescribeBodies(const SourceSpec& spec);

/// One-line human summary ("3 trees, depth 20, 1000 images/tree, ...").
std::string DescribeParams(const TrainParams& params);

/// "job-<crc32 of the serialized config>": the same job file gives the same id (--resume); the
/// default job id of the coordinator and of the workers given the job file.
std::string DefaultJobId(const v1::TrainerConfig& config);

}  // namespace poseforest::engine
