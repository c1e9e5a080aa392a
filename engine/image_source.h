#pragma once
// Labelled training frames: where they come from is hidden behind ImageSource, so the
// sampler and the histogram builder never know whether a frame was rendered, read from a
// dataset folder or generated procedurally.

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "engine/job_spec.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// A depth frame (mm, 0 = background) and its per-pixel part labels (kBackgroundLabel off
/// the body). Both images have the same size.
struct LabelledFrame {
  core::DepthImage depth;
  core::LabelImage labels;
};

/// Produces frame `index` as a pure function of the source's spec and `index`.
/// Not thread-safe: use one instance per thread (the renderer owns a GL context).
class ImageSource {
 public:
  virtual ~ImageSource() = default;
  virtual core::Result<LabelledFrame> Frame(uint64_t index) = 0;
  /// Number of distinct frames, or 0 when unbounded (rendered / procedural).
  virtual uint64_t size() const = 0;
  /// e.g. "dataset /data/train (1000 frames)".
  virtual std::string Describe() const = 0;
};

/// The intrinsics of a depth sensor the renderer models (renderer::SensorNoise's presets).
core::CameraIntrinsics SensorCamera(DepthSensor sensor);

/// The camera a source's frames are taken with: a rendered source's Kinect v1 camera, or its
/// sensor's with sensor_camera; a procedural source's, the Kinect v1's (its flat figures have no
/// camera); a dataset folder's camera.txt (poseforest render writes it), else the Kinect v1's. The forest a job trains records its focal length (Forest::training_fx).
core::Result<core::CameraIntrinsics> SourceCamera(const SourceSpec& spec);

/// A forest with no trees yet for a job: its feature constants, the 31 parts and the training
/// focal length of SourceCamera(params.source). The engine, the coordinator and the checkpoint
/// export all start from it, so they write the same forest.
core::Result<core::Forest> EmptyForest(const TrainParams& params);

/// Creates a source for `spec`. Dataset sources check that the folder holds at least one
/// frame; rendered sources fail with Unimplemented in builds without the renderer.
core::Result<std::unique_ptr<ImageSource>> MakeImageSource(const SourceSpec& spec);

/// Loads the rigged mesh at `path` as a body (Assimp, retargeted to the canonical skeleton and
/// labelled with the 31 parts) into a process-wide cache keyed by the file's path, size and
/// modification time, where the rendered sources of every thread take it from. Ok when it can be
/// a body; else the loader's error, which names the file: kNotFound, kIo (Assimp cannot read it),
/// kInvalidArgument (no bones, bones that do not map to the canonical skeleton). Builds without
/// the renderer cannot load meshes and return Ok (their rendered sources fail in MakeImageSource).
core::Status PreloadBodyMesh(const std::string& path,
                             const std::vector<std::pair<std::string, std::string>>& bone_map = {});
/// Checks a job's body_bone_map (canonical joint names, non-empty bones); OK without the renderer.
core::Status CheckBoneMap(const std::vector<std::pair<std::string, std::string>>& bone_map);

/// Procedural frame `index` (see ProceduralSource in job.proto): a blocky figure of
/// spec.num_parts labelled cells at 1.5..4 m, randomly placed and deformed per frame.
LabelledFrame MakeProceduralFrame(const SourceSpec& spec, uint64_t index);

/// `folder`/STEM_NNNNNN.EXT: how `poseforest render` names a data set's files (depth, labels,
/// joints, mask), the index zero-padded to six digits.
std::string DatasetFramePath(const std::string& folder, const char* stem, uint64_t index, const char* ext = "png");

/// Reads depth_%06d.png (16-bit mm) and labels_%06d.png (8-bit) from `folder`; errors name
/// the file. Sizes must agree; labels must be < 31 or 255.
core::Result<LabelledFrame> ReadDatasetFrame(const std::string& folder, uint64_t index);

}  // namespace poseforest::engine
