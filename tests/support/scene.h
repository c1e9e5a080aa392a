#pragma once
// Cluttered depth scenes with ground truth, for segmentation tests and bench/segment: a floor,
// walls and boxes ray-cast with the camera's intrinsics, and people composited in from
// pre-segmented person depth images (synthetic figures or real frames) by depth test.

#include <Eigen/Core>
#include <vector>

#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"

namespace poseforest::testing {

struct Box {
  Eigen::Vector3d min, max;  ///< axis-aligned, camera frame, metres (y down)
};

struct ClutterSpec {
  double floor_y_m = 1.0;       ///< floor plane y = this (camera frame, y down); <= 0: none
  double back_wall_z_m = 4.0;   ///< wall z = this; <= 0: none
  double side_wall_x_m = -1.8;  ///< wall x = this (either sign); 0: none
  std::vector<Box> boxes;
};

struct ClutteredFrame {
  core::DepthImage depth;  ///< mm
  core::LabelImage truth;  ///< 0 = not a person, k = people[k-1] where it is visible
};

/// Ray-casts the clutter and composites `people` (depth images of the camera's size, 0 = not
/// the person; `shift_mm[k]` is added to person k's depth) in front of it by depth.
ClutteredFrame ComposeScene(const core::CameraIntrinsics& camera, const ClutterSpec& spec,
                            const std::vector<core::DepthImage>& people,
                            const std::vector<int>& shift_mm = {});

/// A pre-segmented person image moved `dz_mm` back and `dx_m` sideways (the silhouette shrinks
/// with depth; pinholes closed), for scenes built from real frames' people.
core::DepthImage MovePerson(const core::DepthImage& person, const core::CameraIntrinsics& camera, int dz_mm,
                            double dx_m);

}  // namespace poseforest::testing
