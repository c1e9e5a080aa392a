#pragma once
// Camera models for the frames the runtime reads: pinhole intrinsics, the unit of the raw depth
// values, documented presets, and the rescaling of a forest's learned offsets to another focal
// length. docs/runtime/frames.md lists the presets with their numbers and where they come from.

#include <string>
#include <vector>

#include "runtime/core/camera.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::runtime {

/// A depth camera: its pinhole intrinsics (size, focal lengths and principal point in pixels) and
/// the unit of its raw depth values.
struct CameraModel {
  std::string name = "kinect-v1";     ///< preset name, or "custom"
  core::CameraIntrinsics intrinsics;  ///< pixels; defaults: Kinect v1 640x480
  double depth_scale_mm = 1.0;        ///< millimetres per raw depth unit (1: raw is mm)

  /// One line for messages: "kinect-v1 640x480 fx 575.8 fy 575.8 cx 319.5 cy 239.5".
  std::string Describe() const;
};

/// Names of the presets, in the order `poseforest infer --help` lists them.
std::vector<std::string> CameraPresetNames();

/// A preset by name: kinect-v1, kinect-v2, azure-nfov (NFOV unbinned), azure-nfov-binned,
/// azure-wfov (WFOV 2x2 binned), azure-wfov-unbinned, realsense-d435 (848x480),
/// realsense-d435-640. Except for the Kinect v1 (PCL/OpenNI's calibration), the focal lengths are
/// NOMINAL: computed from the manufacturer's documented field of view, f = (size/2) / tan(fov/2),
/// with the principal point at the image centre. A real unit differs by a few percent; pass its
/// calibration with --fx --fy --cx --cy for best results. Unknown names are an InvalidArgument
/// error listing the presets.
core::Result<CameraModel> CameraPreset(const std::string& name);

/// Refuses a frame whose size contradicts the camera model, naming both ("SOURCE: frame 3 is
/// 512x424 but the camera model kinect-v1 is 640x480").
core::Status CheckFrameSize(const CameraModel& camera, int width, int height, const std::string& what);

/// The forest to run on frames of a camera with focal lengths (fx, fy) pixels. A forest's offsets
/// are pixel*metres at its training focal length (Forest::training_fx/fy): at focal length f the
/// same metres on the body are f / f_train times as many pixels, so the offsets scale by that
/// ratio (eq. 1's u / d(x) becomes u * f / (f_train * d(x))). The x scale is folded into the
/// offset unit (exact); if fx/fy differs from the training camera's ratio, the y offsets are
/// also rescaled (rounded to the stored unit, saturating at the int16 range). The result
/// records (fx, fy) as its training focal length, so rescaling twice is harmless.
core::Forest ForestForFocalLength(const core::Forest& forest, double fx, double fy);

/// Writes `camera` as `poseforest render` records it next to a data set (camera.txt): a comment
/// line, then "NAME WIDTH HEIGHT FX FY CX CY" (pixels, full precision).
core::Status WriteCameraModelFile(const std::string& path, const CameraModel& camera);
/// Reads a file WriteCameraModelFile wrote; errors (kIo, kDataLoss) name the file.
core::Result<CameraModel> ReadCameraModelFile(const std::string& path);

/// True when the forest needs no rescaling for (fx, fy) (within 1e-4 relative).
bool SameFocalLength(const core::Forest& forest, double fx, double fy);

}  // namespace poseforest::runtime
