#include "runtime/camera_model.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>

#include "runtime/core/forest_format.h"

namespace poseforest::runtime {
namespace {

// f = (size / 2) / tan(fov / 2): the nominal focal length of a documented field of view.
double FocalFromFov(int size_px, double fov_deg) {
  return 0.5 * size_px / std::tan(0.5 * fov_deg * std::numbers::pi / 180.0);
}

/// A pinhole of focal length f px (both axes), principal point at the centre.
CameraModel Calibrated(const std::string& name, int w, int h, double f) {
  CameraModel m;
  m.name = name;
  m.intrinsics.width = w;
  m.intrinsics.height = h;
  m.intrinsics.fx = m.intrinsics.fy = f;
  m.intrinsics.cx = 0.5 * w - 0.5;
  m.intrinsics.cy = 0.5 * h - 0.5;
  return m;
}

CameraModel Nominal(const std::string& name, int w, int h, double hfov_deg, double vfov_deg,
                    double scale = 1.0) {
  CameraModel m;
  m.name = name;
  m.intrinsics.width = w;
  m.intrinsics.height = h;
  m.intrinsics.fx = FocalFromFov(w, hfov_deg) * scale;
  m.intrinsics.fy = FocalFromFov(h, vfov_deg) * scale;
  m.intrinsics.cx = 0.5 * w - 0.5;
  m.intrinsics.cy = 0.5 * h - 0.5;
  return m;
}

}  // namespace

std::string CameraModel::Describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s %dx%d fx %.1f fy %.1f cx %.1f cy %.1f", name.c_str(), intrinsics.width,
                intrinsics.height, intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy);
  std::string s = buf;
  if (depth_scale_mm != 1.0) {
    std::snprintf(buf, sizeof buf, " depth-scale %g mm", depth_scale_mm);
    s += buf;
  }
  return s;
}

std::vector<std::string> CameraPresetNames() {
  return {"kinect-v1",  "kinect-v2",           "azure-nfov",     "azure-nfov-binned",
          "azure-wfov", "azure-wfov-unbinned", "realsense-d435", "realsense-d435-640"};
}

core::Result<CameraModel> CameraPreset(const std::string& name) {
  if (name == "kinect-v1") {
    CameraModel m;  // PCL / OpenNI's Kinect v1 depth calibration (runtime/core/camera.h)
    m.name = name;
    return m;
  }
  // Documented depth fields of view (manufacturers' hardware specifications):
  // Kinect v2 70.6 x 60 deg; Azure Kinect NFOV 75 x 65, WFOV 120 x 120 (a fisheye: the pinhole
  // model is rough near the edges); RealSense D435 87 x 58 at 848x480 (1280x720 scaled by 0.6625).
  if (name == "kinect-v2") return Nominal(name, 512, 424, 70.6, 60.0);
  // Azure Kinect NFOV from the factory calibration, not the documented 75 x 65 deg (which gives
  // 417 x 452 px, ~20 % short): the depth camera's intrinsics are stored normalized to its
  // 1024x1024 sensor, fx ~ fy ~ 0.492 (503.9 px; e.g. a device's calibration blob quoted in
  // microsoft/Azure-Kinect-Sensor-SDK#1488: 0.49204, 0.49193), and NFOV unbinned is the sensor's
  // central 640x576 at full resolution, binned the same halved.
  if (name == "azure-nfov") return Calibrated(name, 640, 576, 504.0);
  if (name == "azure-nfov-binned") return Calibrated(name, 320, 288, 252.0);
  if (name == "azure-wfov") return Nominal(name, 512, 512, 120.0, 120.0);
  if (name == "azure-wfov-unbinned") return Nominal(name, 1024, 1024, 120.0, 120.0);
  if (name == "realsense-d435") return Nominal(name, 848, 480, 87.0, 58.0);
  if (name == "realsense-d435-640") {
    // 640x480 is the 1280x800 sensor scaled by 0.6 and cropped, where 848x480 is 1280x720
    // scaled by 0.6625: the same optics at 0.6 / 0.6625 of the 848x480 focal lengths.
    CameraModel m = Nominal(name, 848, 480, 87.0, 58.0, 0.6 / 0.6625);
    m.intrinsics.width = 640;
    m.intrinsics.cx = 319.5;
    return m;
  }
  std::string list;
  for (const auto& n : CameraPresetNames()) list += (list.empty() ? "" : ", ") + n;
  return core::Status(core::ErrorCode::kInvalidArgument,
                      "unknown camera preset '" + name + "' (presets: " + list + ")");
}

core::Status CheckFrameSize(const CameraModel& camera, int width, int height, const std::string& what) {
  if (width == camera.intrinsics.width && height == camera.intrinsics.height) return core::Status::Ok();
  return {core::ErrorCode::kInvalidArgument,
          what + " is " + std::to_string(width) + "x" + std::to_string(height) + " but the camera model " +
              camera.name + " is " + std::to_string(camera.intrinsics.width) + "x" +
              std::to_string(camera.intrinsics.height) +
              " (choose --camera or --fx/--fy/--cx/--cy for this size)"};
}

core::Status WriteCameraModelFile(const std::string& path, const CameraModel& camera) {
  const core::CameraIntrinsics& k = camera.intrinsics;
  char buf[320];
  std::snprintf(
      buf, sizeof buf,
      "# poseforest camera model: name width height fx fy cx cy (pixels)\n%s %d %d %.17g %.17g %.17g "
      "%.17g\n",
      camera.name.c_str(), k.width, k.height, k.fx, k.fy, k.cx, k.cy);
  std::ofstream out(path, std::ios::binary);
  out << buf;
  if (!out) return {core::ErrorCode::kIo, path + ": write failed"};
  return core::Status::Ok();
}

core::Result<CameraModel> ReadCameraModelFile(const std::string& path) {
  auto text = core::ReadFileText(path);
  if (!text.ok()) return text.status();
  std::istringstream in(*text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    CameraModel m;
    core::CameraIntrinsics& k = m.intrinsics;
    std::string rest;
    if (!(fields >> m.name >> k.width >> k.height >> k.fx >> k.fy >> k.cx >> k.cy) || (fields >> rest) ||
        k.width <= 0 || k.height <= 0 || k.width > 32768 || k.height > 32768 || !(k.fx > 0) || !(k.fy > 0) ||
        !std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) || !std::isfinite(k.cy))
      return core::Status(core::ErrorCode::kDataLoss,
                          path +
                              ": expected \"NAME WIDTH HEIGHT FX FY CX CY\" with a positive size and focal "
                              "lengths, got '" +
                              line + "'");
    return m;
  }
  return core::Status(core::ErrorCode::kDataLoss, path + ": no camera line");
}

bool SameFocalLength(const core::Forest& forest, double fx, double fy) {
  return std::abs(fx / forest.training_fx - 1.0) < 1e-4 && std::abs(fy / forest.training_fy - 1.0) < 1e-4;
}

core::Forest ForestForFocalLength(const core::Forest& forest, double fx, double fy) {
  core::Forest out = forest;
  if (SameFocalLength(forest, fx, fy)) return out;
  const double sx = fx / forest.training_fx, sy = fy / forest.training_fy;
  // x: exact, through the offset unit (pixels = stored * unit * 1000 / d).
  out.constants.offset_unit = float(double(forest.constants.offset_unit) * sx);
  // y: whatever the x scale did not already do.
  const double ry = sy / sx;
  if (std::abs(ry - 1.0) > 1e-4) {
    auto scale = [ry](int16_t v) {
      const double s = std::round(double(v) * ry);
      return int16_t(std::clamp(s, -32768.0, 32767.0));
    };
    for (core::Tree& tree : out.trees)
      for (core::Node& n : tree.nodes) {
        if (n.is_leaf()) continue;
        n.offsets.uy = scale(n.offsets.uy);
        n.offsets.vy = scale(n.offsets.vy);
      }
  }
  out.training_fx = float(fx);
  out.training_fy = float(fy);
  return out;
}

}  // namespace poseforest::runtime
