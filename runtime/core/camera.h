#pragma once
// Pinhole camera intrinsics and pixel <-> 3D reprojection. Camera frame: x right, y down,
// z forward (depth), metres. Defaults approximate the Kinect v1 depth camera at 640x480.

#include <cstdint>

#include <Eigen/Core>

namespace poseforest::core {

struct CameraIntrinsics {
  int width = 640;    ///< pixels
  int height = 480;   ///< pixels
  double fx = 575.8;  ///< focal length, pixels (Kinect v1 depth camera; PCL/OpenNI use 575.8)
  double fy = 575.8;  ///< pixels
  double cx = 319.5;  ///< principal point, pixels (centre of a 640x480 image)
  double cy = 239.5;  ///< pixels

  /// Kinect v1 depth camera defaults (640x480, ~57 degree horizontal field of view).
  static CameraIntrinsics KinectV1() { return {}; }

  /// 3D point (metres, camera frame) seen at pixel (u, v) with depth z metres (z > 0).
  Eigen::Vector3d Unproject(double u, double v, double z_m) const {
    return {(u - cx) * z_m / fx, (v - cy) * z_m / fy, z_m};
  }
  /// Pixel coordinates (u, v) of a 3D point (metres, camera frame); requires p.z() > 0.
  Eigen::Vector2d Project(const Eigen::Vector3d& p) const {
    return {fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy};
  }
  /// 3D point for integer pixel (x, y) holding depth `depth_mm` (> 0) millimetres.
  Eigen::Vector3d PixelToPoint(int x, int y, uint16_t depth_mm) const {
    return Unproject(double(x), double(y), double(depth_mm) * 1e-3);
  }
};

}  // namespace poseforest::core
