#pragma once
// Scene sampling and the Kinect-like noise model. A scene is a pure function of (seed, index):
// which bodies, which poses, where the people stand, where the camera is, whether the picture is
// mirrored, and the noise. See renderer/README.md for the distributions and the noise model.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "renderer/body.h"
#include "renderer/skeleton.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"

namespace poseforest::renderer {

/// How the depth camera measures (NoiseConfig::principle).
enum class DepthPrinciple {
  kStructuredLight,  ///< Kinect v1: disparity quantization and noise, projector shadow
  kTimeOfFlight,     ///< Kinect v2, Azure Kinect: Gaussian depth noise growing with depth, no shadow
};

/// Kinect v1-like sensor noise, applied to the rendered depth (labels follow: a pixel whose depth
/// is dropped becomes background). The defaults are the classic Kinect v1 model; the edge and hole
/// effects below (flying_pixels, range_dropout, grazing_dropout) are off, and each draws from a
/// random stream of its own, so switched off they leave every frame byte for byte as before.
/// SensorNoise() gives the presets of other cameras.
struct NoiseConfig {
  bool enabled = true;
  DepthPrinciple principle = DepthPrinciple::kStructuredLight;
  /// The camera's focal length (pixels): structured light's disparity below, and every
  /// principle's surface normals (grazing_dropout). The principal point is taken at the image
  /// centre.
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
  /// Structured light sees only what the projector lights: a surface hidden from the projector
  /// (baseline_m to the camera's +x side on Kinect v1) by a nearer one gives no reading, a band
  /// f*b*(1/z_near - 1/z_far) pixels wide on the side of each depth edge away from the projector
  /// (the left of a hand held before the chest). Applied to the clean depth, before the rest.
  bool projector_shadow = false;
  /// +1: the projector is on the camera's +x side (Kinect v1: shadows fall left of near edges);
  /// -1: on the -x side.
  int projector_side = +1;
  /// Surfaces nearer than this give no reading (Kinect v1's near limit), metres; 0 = none.
  double min_range_m = 0.0;

  /// Time of flight only: the sd of the depth noise, tof_sigma_mm[0] + [1] z + [2] z^2 mm with z
  /// in metres (no quantization: readings are whole millimetres). Defaults: Kinect v2.
  double tof_sigma_mm[3] = {1.5, -0.5, 0.3};

  /// Mixed ("flying") pixels: a pixel that straddles a depth edge (the silhouette, or a jump of
  /// more than discontinuity_mm to a 4-neighbour) sees both surfaces and reads a depth between
  /// them. With probability flying_pixels, a pixel on either side of such an edge reads
  /// own + a (other - own), a uniform in [0, 0.5) (its centre is on its own surface, so the
  /// other covers less than half of it). Where the other side has no reading (depth 0), the
  /// far surface is taken flying_void_mm behind the near one (a wall somewhere behind). Label:
  /// that of a surface the reading lies within flying_label_mm of (the nearer surface first),
  /// else background, so the forest never learns to call points floating between surfaces (off
  /// the body) a body part; a reading that close to a surface is what the camera gives there.
  /// 0 = off.
  double flying_pixels = 0.0;
  double flying_label_mm = 30.0;  ///< millimetres
  double flying_void_mm = 600.0;  ///< millimetres
  /// Holes that grow with distance (the returned light falls as 1/z^2): a foreground pixel is
  /// dropped with probability range_dropout * (z / range_dropout_ref_m)^2 (at most 1), besides
  /// the dropouts above. 0 = off.
  double range_dropout = 0.0;
  double range_dropout_ref_m = 4.0;  ///< metres
  /// Holes on grazing surfaces: with the angle theta between the view ray and the surface normal
  /// (estimated from the clean depth's gradient), a pixel is dropped with probability
  /// grazing_dropout * (theta - grazing_start_deg) / (90 - grazing_start_deg), 0 below
  /// grazing_start_deg. 0 = off.
  double grazing_dropout = 0.0;
  double grazing_start_deg = 60.0;  ///< degrees
};

/// Depth cameras the renderer has presets for.
enum class DepthSensor { kKinectV1, kKinectV2, kAzureKinectNfov };

/// A depth camera as the renderer draws it: its intrinsics and its noise model.
struct SensorPreset {
  core::CameraIntrinsics camera;
  NoiseConfig noise;
};

/// The preset of `sensor` (sources and figures in scene.cpp and renderer/README.md). Kinect v1:
/// CameraIntrinsics::KinectV1() and NoiseConfig{} (the classic model). Kinect v2: 512x424,
/// f = 365.5 px, time of flight. Azure Kinect NFOV unbinned: 640x576, f = 504 px, time of flight.
SensorPreset SensorNoise(DepthSensor sensor);
/// "kinect-v1", "kinect-v2", "azure-nfov".
const char* DepthSensorName(DepthSensor sensor);
/// The sensor named by DepthSensorName; false if the name is unknown.
bool ParseDepthSensor(const std::string& name, DepthSensor* sensor);

/// How the camera frames the first person. By default (upper_body_share 0) the camera stands
/// min..max_distance_m from the person and is aimed at their mid-height, so whole bodies fill
/// the frame. A share of frames is instead framed on the upper body, as at desks, TVs and on
/// robots: the camera upper_body_min..max_distance_m away, aimed at a point between the chest and
/// the head, its height near that point, so the frame cuts the body at the waist or chest.
/// Drawn from its own random stream: a share of 0 leaves every scene as it was.
struct FramingConfig {
  double upper_body_share = 0.0;
  double upper_body_min_distance_m = 0.6;
  double upper_body_max_distance_m = 2.0;
  /// Camera height relative to the aimed point, metres (below: a desk or a robot; above: a TV).
  double upper_body_camera_below_m = 0.4;
  double upper_body_camera_above_m = 0.3;
};

/// Clutter around the people, for test frames of segmentation (docs/renderer/clutter.md). Off by
/// default; drawn from its own random stream, so turning it on changes nothing else in a scene.
struct ClutterConfig {
  bool floor = false;         ///< the ground plane the people stand on
  bool walls = false;         ///< a back wall 0.5-1.5 m behind the furthest person, and a side wall
  bool boxes = false;         ///< 1-3 boxes (0.3-0.9 m wide, 0.3-1.2 m tall) on the floor, away from people
  int occluders = 0;          ///< boxes standing between the camera and a person, hiding part of them
  double max_depth_m = 10.0;  ///< clutter further than this gives no reading (depth 0), metres

  bool enabled() const { return floor || walls || boxes || occluders > 0; }
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
  /// A mixture of headings: this share of the people turn further, their yaw uniform in
  /// +-turned_range_deg instead. Drawn from its own random stream: 0 leaves every scene as it was.
  double turned_share = 0.0;
  double turned_range_deg = 180.0;
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

  FramingConfig framing;
  /// Share of people whose arms are re-posed (PerturbArms in pose_sampler.h: reaching toward or
  /// across the camera, hands near the face or body) on top of their library or procedural pose.
  /// Drawn from its own random stream: 0 leaves every scene as it was.
  double arm_pose_share = 0.0;
  /// Share of people sat down (SitDown in pose_sampler.h: thighs forward, knees bent, on no
  /// visible seat) and share leaning their upper body (LeanTrunk: forward over a desk, back,
  /// sideways), each on top of the pose and the arms. Each from its own random stream: 0 leaves
  /// every scene as it was.
  double sit_share = 0.0;
  double lean_share = 0.0;

  int min_people = 1;  ///< people per frame (each placed independently; they may occlude)
  int max_people = 1;

  NoiseConfig noise;
  ClutterConfig clutter;
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
  /// Ground-truth person masks: 0 = no person, k = person k-1 (the order of `joints`) where
  /// that person is the visible surface (after clutter, occluders and noise).
  core::LabelImage people;
};

/// Where one person is and how they stand; everything needed to draw them.
struct PersonPlacement {
  int body = 0;        ///< index into the renderer's body list
  Pose pose;           ///< bone rotations (body frame)
  double scale = 1.0;  ///< uniform body scale
  Eigen::Isometry3d camera_from_body = Eigen::Isometry3d::Identity();  ///< metres
};

/// An axis-aligned box in the world frame (metres; y up, the floor at y = 0).
struct ClutterBox {
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  bool occluder = false;  ///< placed between the camera and a person
};

/// The clutter of one scene, in the world frame: X right, Y up (floor y = 0), the camera at
/// (0, camera height, 0) looking along -Z.
struct SceneClutter {
  bool floor = false;
  double back_wall_z = 0;  ///< the back wall's plane z = this (< 0), 0 = none
  double side_wall_x = 0;  ///< a side wall's plane x = this, 0 = none
  std::vector<ClutterBox> boxes;
  double max_depth_m = 10.0;
};

/// A sampled scene: people + mirroring + the noise seed (+ clutter).
struct SceneSample {
  std::vector<PersonPlacement> people;
  bool mirrored = false;
  uint64_t noise_key = 0;
  /// The camera's pose (before mirroring); camera_from_body = camera_from_world * world_from_body.
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  SceneClutter clutter;
};

/// Ray-casts `clutter` for every pixel of `camera` (mirrored as the scene is) into `depth`
/// (mm, 0 = nothing within clutter.max_depth_m); `depth` is resized to the camera's size.
void RayCastClutter(const SceneClutter& clutter, const Eigen::Isometry3d& camera_from_world, bool mirrored,
                    const core::CameraIntrinsics& camera, core::DepthImage* depth);

/// The 16 evaluation joints (core::Joint order) from posed canonical joints (any frame):
/// head = centre of the head, neck = middle of the neck, hand = centre of the hand, foot =
/// centre of the foot, the others at the skeleton joint.
std::array<Eigen::Vector3d, core::kNumJoints> EvalJoints(const SkelPositions& posed);

/// Applies NoiseConfig to a rendered frame in place, as a pure function of `key`. `people`
/// (optional, the person masks of RenderedFrame) follows the labels of mixed pixels.
void ApplyKinectNoise(const NoiseConfig& noise, uint64_t key, core::DepthImage* depth,
                      core::LabelImage* labels, core::LabelImage* people = nullptr);

/// Kinect v1's projector shadow (NoiseConfig::projector_shadow) alone, in place: pixels the
/// projector cannot light become 0 / background. ApplyKinectNoise calls it when enabled.
void ApplyProjectorShadow(const NoiseConfig& noise, core::DepthImage* depth, core::LabelImage* labels);

/// The depth (mm) the noise model's quantization maps `depth_mm` to (no random noise).
uint16_t QuantizeDepthMm(const NoiseConfig& noise, double depth_mm);

}  // namespace poseforest::renderer
