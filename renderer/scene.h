#pragma once
// Scene sampling and the Kinect-like noise model. A scene is a pure function of (seed, index):
// which bodies, which poses, where the people stand, where the camera is, whether the picture is
// mirrored, and the noise. See renderer/README.md for the distributions and the noise model.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "renderer/body.h"
#include "renderer/skeleton.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"

namespace poseforest::renderer {

/// Kinect v1-like sensor noise, applied to the rendered depth (labels follow: a pixel whose depth
/// is dropped becomes background).
struct NoiseConfig {
  bool enabled = true;
  /// Structured-light disparity quantization: disparity d = f*b/z pixels is rounded to
  /// multiples of 1/subpixel_steps px, so the depth step grows as z^2 / (f*b*subpixel_steps).
  double focal_px = 575.8;    ///< pixels
  double baseline_m = 0.075;  ///< projector-camera baseline, metres
  int subpixel_steps = 8;     ///< Kinect v1: 1/8 pixel disparity resolution
  /// Gaussian noise on the disparity before quantization (pixels of disparity).
  double disparity_sigma_px = 0.05;
  /// Probability of dropping a pixel on a depth discontinuity (silhouette or a jump larger than
  /// discontinuity_mm to a 4-neighbour).
  double edge_dropout = 0.35;
  double discontinuity_mm = 60.0;  ///< millimetres
  /// Probability of dropping any other foreground pixel (isolated speckle holes).
  double speckle_dropout = 0.002;
};

/// The distributions a scene is drawn from. Defaults follow section 2.3 of the paper.
struct SceneConfig {
  core::CameraIntrinsics camera = core::CameraIntrinsics::KinectV1();

  /// Bodies: the procedural family (kNumProceduralShapes base shapes x variants_per_shape
  /// random variants) and/or caller-supplied bodies (MakeHuman, Assimp rigs) with part labels.
  /// Poses are made for the canonical T-pose; a supplied body whose rest pose differs (e.g.
  /// MakeHuman's A-pose, see NeedsPoseAdaptation in scene_assets.h) gets every sampled pose
  /// passed through assets::AdaptPose(pose, body.rest_joints) (decided once per body).
  bool use_procedural_bodies = true;
  int variants_per_shape = 3;
  std::vector<BodyMesh> bodies;
  /// Extra random uniform scale of every body, +- this fraction (height variation).
  double height_jitter = 0.04;

  /// Poses: drawn from `poses` when non-empty (e.g. subsampled mocap), else from
  /// `shared_poses` when non-empty, else from the procedural sampler (renderer/pose_sampler.h).
  std::vector<Pose> poses;
  /// A pose library shared by every renderer (one per thread) without copying it.
  std::shared_ptr<const std::vector<Pose>> shared_poses;

  /// Rotation of each person about the vertical: uniform in +-rotation_range_deg (180 = any).
  double rotation_range_deg = 120.0;
  double mirror_probability = 0.5;  ///< chance the whole frame is mirrored left<->right

  double min_distance_m = 1.5;  ///< camera to person along the ground, metres
  double max_distance_m = 4.5;
  /// Lateral offset of the pelvis as a fraction of the half field of view at its distance:
  /// 1.0 puts it anywhere up to the image edge (so bodies are cropped by the frame edge).
  double lateral_fraction = 0.85;
  double min_camera_height_m = 0.6;  ///< metres above the floor
  double max_camera_height_m = 1.6;
  /// Camera pitch: aimed at the person's mid-height, plus a uniform jitter of +- this (degrees).
  double tilt_jitter_deg = 8.0;
  double camera_roll_deg = 3.0;  ///< uniform in +- this, degrees

  int min_people = 1;  ///< people per frame (each placed independently; they may occlude)
  int max_people = 1;

  NoiseConfig noise;
};

/// One rendered training frame.
struct RenderedFrame {
  core::DepthImage depth;   ///< millimetres, 0 = background / dropped
  core::LabelImage labels;  ///< core::Part per pixel, core::kBackgroundLabel elsewhere
  /// Per person: the 16 evaluation joints (core::Joint order) in the camera frame, metres.
  std::vector<std::array<Eigen::Vector3f, core::kNumJoints>> joints;
  /// Per person: joint projects inside the image and is not hidden more than 10 cm (head: 15 cm,
  /// its joint is the centre of the head) behind the rendered surface at its pixel.
  std::vector<std::array<bool, core::kNumJoints>> visible;
};

/// Where one person is and how they stand; everything needed to draw them.
struct PersonPlacement {
  int body = 0;        ///< index into the renderer's body list
  Pose pose;           ///< bone rotations (body frame)
  double scale = 1.0;  ///< uniform body scale
  Eigen::Isometry3d camera_from_body = Eigen::Isometry3d::Identity();  ///< metres
};

/// A sampled scene: people + mirroring + the noise seed.
struct SceneSample {
  std::vector<PersonPlacement> people;
  bool mirrored = false;
  uint64_t noise_key = 0;
};

/// The 16 evaluation joints (core::Joint order) from posed canonical joints (any frame):
/// head = centre of the head, neck = middle of the neck, hand = centre of the hand, foot =
/// centre of the foot, the others at the skeleton joint.
std::array<Eigen::Vector3d, core::kNumJoints> EvalJoints(const SkelPositions& posed);

/// Applies NoiseConfig to a rendered frame in place, as a pure function of `key`.
void ApplyKinectNoise(const NoiseConfig& noise, uint64_t key, core::DepthImage* depth,
                      core::LabelImage* labels);

/// The depth (mm) the noise model's quantization maps `depth_mm` to (no random noise).
uint16_t QuantizeDepthMm(const NoiseConfig& noise, double depth_mm);

}  // namespace poseforest::renderer
