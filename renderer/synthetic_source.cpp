#include "renderer/synthetic_source.h"

#include <time.h>

#include <cmath>
#include <numbers>

#include "renderer/assets/retarget.h"
#include "renderer/egl_renderer.h"
#include "renderer/part_labels.h"
#include "renderer/pose_sampler.h"
#include "renderer/procedural_body.h"
#include "renderer/scene_assets.h"
#include "renderer/skinning.h"
#include "runtime/core/rng.h"

namespace poseforest::renderer {
namespace {

using core::ErrorCode;
using core::Status;
constexpr double kDeg = std::numbers::pi / 180.0;
/// Seed of the procedural family's variations: fixed, so every renderer has the same bodies.
constexpr uint64_t kFamilySeed = 2011;

/// CPU time of the calling thread, milliseconds: with LP_NUM_THREADS=0 llvmpipe rasterizes on
/// this thread, so stage times do not depend on other load on the machine.
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

Status ValidateConfig(const SceneConfig& c) {
  auto bad = [](const std::string& what) {
    return Status(ErrorCode::kInvalidArgument, "SceneConfig: " + what);
  };
  if (c.camera.width <= 0 || c.camera.height <= 0 || !(c.camera.fx > 0) || !(c.camera.fy > 0)) {
    return bad("camera: width, height, fx and fy must be positive");
  }
  if (!c.use_procedural_bodies && c.bodies.empty())
    return bad("no bodies: enable use_procedural_bodies or supply bodies");
  if (c.use_procedural_bodies && (c.variants_per_shape < 1 || c.variants_per_shape > 64)) {
    return bad("variants_per_shape must be in 1..64");
  }
  if (!(c.min_distance_m > 0.3) || !(c.max_distance_m >= c.min_distance_m) || c.max_distance_m > 60) {
    return bad("distance range must satisfy 0.3 < min_distance_m <= max_distance_m <= 60");
  }
  if (c.min_people < 1 || c.max_people < c.min_people || c.max_people > 8)
    return bad("people must satisfy 1 <= min <= max <= 8");
  if (!(c.rotation_range_deg >= 0 && c.rotation_range_deg <= 180))
    return bad("rotation_range_deg must be in [0, 180]");
  if (!(c.turned_share >= 0 && c.turned_share <= 1)) return bad("turned_share must be in [0, 1]");
  if (!(c.turned_range_deg >= 0 && c.turned_range_deg <= 180)) return bad("turned_range_deg must be in [0, 180]");
  if (!(c.mirror_probability >= 0 && c.mirror_probability <= 1))
    return bad("mirror_probability must be in [0, 1]");
  if (!(c.height_jitter >= 0 && c.height_jitter < 0.5)) return bad("height_jitter must be in [0, 0.5)");
  if (!(c.framing.upper_body_share >= 0 && c.framing.upper_body_share <= 1))
    return bad("framing.upper_body_share must be in [0, 1]");
  if (!(c.framing.upper_body_min_distance_m > 0.3) ||
      !(c.framing.upper_body_max_distance_m >= c.framing.upper_body_min_distance_m) ||
      c.framing.upper_body_max_distance_m > 60)
    return bad("framing: 0.3 < upper_body_min_distance_m <= upper_body_max_distance_m <= 60");
  if (!(c.framing.upper_body_camera_below_m >= 0) || !(c.framing.upper_body_camera_above_m >= 0))
    return bad("framing: upper_body_camera_below_m and _above_m must be >= 0");
  if (!(c.arm_pose_share >= 0 && c.arm_pose_share <= 1)) return bad("arm_pose_share must be in [0, 1]");
  if (!(c.sit_share >= 0 && c.sit_share <= 1)) return bad("sit_share must be in [0, 1]");
  if (!(c.lean_share >= 0 && c.lean_share <= 1)) return bad("lean_share must be in [0, 1]");
  if (c.noise.projector_side != 1 && c.noise.projector_side != -1) return bad("noise.projector_side must be +1 or -1");
  if (!(c.noise.min_range_m >= 0 && c.noise.min_range_m < 10)) return bad("noise.min_range_m must be in [0, 10)");
  if (!(c.min_camera_height_m <= c.max_camera_height_m)) return bad("camera height range is empty");
  if (c.clutter.occluders < 0 || c.clutter.occluders > 16) return bad("clutter.occluders must be in 0..16");
  if (!(c.clutter.max_depth_m > 0.5 && c.clutter.max_depth_m <= 60))
    return bad("clutter.max_depth_m must be in (0.5, 60]");
  if (c.noise.enabled &&
      (!(c.noise.focal_px > 0) || !(c.noise.baseline_m > 0) || c.noise.subpixel_steps < 1)) {
    return bad("noise: focal_px, baseline_m and subpixel_steps must be positive");
  }
  for (const double share : {c.noise.flying_pixels, c.noise.range_dropout, c.noise.grazing_dropout})
    if (!(share >= 0 && share <= 1))
      return bad("noise: flying_pixels, range_dropout and grazing_dropout must be in [0, 1]");
  if (!(c.noise.flying_label_mm >= 0) || !(c.noise.flying_void_mm > 0) || !(c.noise.range_dropout_ref_m > 0))
    return bad("noise: flying_label_mm must be >= 0, flying_void_mm and range_dropout_ref_m > 0");
  if (!(c.noise.grazing_start_deg >= 0 && c.noise.grazing_start_deg < 90))
    return bad("noise: grazing_start_deg must be in [0, 90)");
  for (size_t b = 0; b < c.bodies.size(); ++b) {
    const BodyMesh& m = c.bodies[b];
    if (m.vertices.empty() || m.triangles.empty() || m.skin.size() != m.vertices.size()) {
      return bad("body " + std::to_string(b) + " ('" + m.name + "') is empty or lacks skin weights");
    }
    if (!m.part.empty() && m.part.size() != m.vertices.size()) {
      return bad("body " + std::to_string(b) + " ('" + m.name + "') has a part list of the wrong size");
    }
  }
  return Status::Ok();
}

/// The clutter of scene (seed, index), from its own random stream (the scene's other draws do
/// not change when clutter is turned on). `people` are the people's (lateral x, distance) on the
/// floor; world frame as in SceneClutter.
SceneClutter SampleClutter(const ClutterConfig& c, uint64_t seed, uint64_t index, double half_fov_tan,
                           const std::vector<Eigen::Vector2d>& people) {
  SceneClutter out;
  out.max_depth_m = c.max_depth_m;
  out.floor = c.floor;
  core::RngStream rng(core::CounterRng(seed, 0xC1077E, index, 0));
  double far = 0, left = 0, right = 0;  // furthest person; extent of people left and right
  for (const Eigen::Vector2d& p : people) {
    far = std::max(far, p.y());
    left = std::min(left, p.x()), right = std::max(right, p.x());
  }
  const double wall_gap = rng.UniformIn(0.5, 1.5), side_gap = rng.UniformIn(0.6, 1.6);
  const bool side_right = rng.Uniform01() < 0.5;
  if (c.walls) {
    out.back_wall_z = -(far + wall_gap);
    out.side_wall_x = side_right ? right + side_gap : left - side_gap;
  }
  // Boxes stand on the floor; each keeps clear of every person by 0.45 m plus its half size.
  auto clear_of_people = [&](double x, double dist, double half) {
    for (const Eigen::Vector2d& p : people)
      if (std::abs(p.x() - x) < half + 0.45 && std::abs(p.y() - dist) < half + 0.45) return false;
    return true;
  };
  auto box_at = [](double x, double dist, double w, double d, double h, bool occluder) {
    ClutterBox b;
    b.min = Eigen::Vector3d(x - 0.5 * w, 0.0, -dist - 0.5 * d);
    b.max = Eigen::Vector3d(x + 0.5 * w, h, -dist + 0.5 * d);
    b.occluder = occluder;
    return b;
  };
  const int boxes = c.boxes ? rng.UniformIntIn(1, 3) : 0;
  for (int k = 0; k < boxes; ++k) {
    const double w = rng.UniformIn(0.3, 0.9), d = rng.UniformIn(0.3, 0.9), h = rng.UniformIn(0.3, 1.2);
    for (int attempt = 0; attempt < 8; ++attempt) {
      const double dist = rng.UniformIn(1.2, std::max(1.3, far + wall_gap - 0.5 * d - 0.05));
      const double x = rng.UniformIn(-1.0, 1.0) * dist * half_fov_tan;
      if (!clear_of_people(x, dist, 0.5 * std::max(w, d))) continue;
      out.boxes.push_back(box_at(x, dist, w, d, h, false));
      break;
    }
  }
  // Occluders: on the line from the camera to a person, 35-70% of the way, shifted sideways by
  // up to 0.35 m, so they hide part of the person (legs, or more when tall).
  for (int k = 0; k < c.occluders && !people.empty(); ++k) {
    const Eigen::Vector2d& p = people[size_t(k) % people.size()];
    const double frac = rng.UniformIn(0.35, 0.7), shift = rng.UniformIn(-0.35, 0.35);
    const double w = rng.UniformIn(0.4, 0.8), d = rng.UniformIn(0.3, 0.6), h = rng.UniformIn(0.5, 1.1);
    const Eigen::Vector2d dir = p.normalized(), side(dir.y(), -dir.x());
    const Eigen::Vector2d at = frac * p + shift * side;
    out.boxes.push_back(box_at(at.x(), std::max(0.6, at.y()), w, d, h, true));
  }
  return out;
}

}  // namespace

void FaceForward(const SkelPositions& rest, Pose* pose) {
  const SkelPositions posed = PoseJoints(rest, *pose);
  const auto at = [&](SkelJoint j) { return posed[size_t(int(j))]; };
  // The person's left, from the hips and the shoulders (horizontal part); facing = left x up.
  Eigen::Vector3d left =
      (at(SkelJoint::kLHip) - at(SkelJoint::kRHip)) + (at(SkelJoint::kLShoulder) - at(SkelJoint::kRShoulder));
  left.y() = 0;
  if (left.norm() < 1e-6) return;
  const Eigen::Vector3d facing = left.normalized().cross(Eigen::Vector3d::UnitY());
  const double yaw = std::atan2(facing.x(), facing.z());
  const Eigen::Quaterniond undo(Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitY()));
  for (auto& q : pose->rotation) q = (undo * q).normalized();
  pose->root_translation = undo * pose->root_translation;
}

SyntheticRenderer::SyntheticRenderer(const SceneConfig& config) : config_(config) {}
SyntheticRenderer::~SyntheticRenderer() = default;

core::Result<std::unique_ptr<SyntheticRenderer>> SyntheticRenderer::Create(const SceneConfig& config) {
  POSEFOREST_RETURN_IF_ERROR(ValidateConfig(config));
  std::unique_ptr<SyntheticRenderer> r(new SyntheticRenderer(config));
  auto gl = EglRenderer::Create(config.camera);
  if (!gl.ok()) return gl.status();
  r->gl_ = std::move(gl).value();
  if (config.use_procedural_bodies) {
    for (int s = 0; s < kNumProceduralShapes; ++s) {
      for (int v = 0; v < config.variants_per_shape; ++v) {
        r->bodies_.push_back(MakeProceduralBody(VaryShape(ProceduralBaseShape(s), kFamilySeed, uint64_t(v))));
        r->adapt_pose_.push_back(0);  // built in the canonical T-pose
      }
    }
  }
  for (const BodyMesh& b : config.bodies) {
    r->bodies_.push_back(b);
    if (r->bodies_.back().part.empty()) {  // label from the skeleton, with smooth boundaries
      LabelBodyParts(r->bodies_.back());
      RefinePartBoundaries(r->bodies_.back(), 2);
    }
    // Decided once per body: poses are made for the T-pose, an A-pose body needs them adapted.
    r->adapt_pose_.push_back(NeedsPoseAdaptation(b.rest_joints) ? 1 : 0);
  }
  r->config_.bodies.clear();  // kept once, in bodies_
  for (const BodyMesh& b : r->bodies_) {
    auto handle = r->gl_->UploadMesh(b);
    if (!handle.ok()) return handle.status();
    r->gpu_mesh_.push_back(*handle);
  }
  r->gl_->ReleaseCurrent();  // created on one thread, used on another (a worker's pool)
  return r;
}

void SyntheticRenderer::ReleaseContext() { gl_->ReleaseCurrent(); }

std::string SyntheticRenderer::GlRendererString() const {
  return gl_->gl_renderer() + " / " + gl_->gl_version();
}

SceneSample SyntheticRenderer::Sample(uint64_t seed, uint64_t index) const {
  const SceneConfig& c = config_;
  core::RngStream rng(core::CounterRng(seed, 0x5CE7E, index, 0));
  SceneSample scene;
  const int people = rng.UniformIntIn(c.min_people, c.max_people);
  scene.mirrored = rng.Uniform01() < c.mirror_probability;
  scene.noise_key = rng.Bits();
  const double cam_h = rng.UniformIn(c.min_camera_height_m, c.max_camera_height_m);
  const double roll = rng.UniformIn(-c.camera_roll_deg, c.camera_roll_deg);
  const double tilt_jitter = rng.UniformIn(-c.tilt_jitter_deg, c.tilt_jitter_deg);
  const double half_fov_tan = 0.5 * c.camera.width / c.camera.fx;

  // Framing and arm re-posing draw from streams of their own, so with both off (share 0) every
  // scene is what it was before they existed.
  core::RngStream framing_rng(core::CounterRng(seed, 0xF4A3E, index, 0));
  const bool upper_body =
      c.framing.upper_body_share > 0 && framing_rng.Uniform01() < c.framing.upper_body_share;
  core::RngStream arms_rng(core::CounterRng(seed, 0xA4A5, index, 1));
  core::RngStream sit_rng(core::CounterRng(seed, 0x517D, index, 1));
  core::RngStream lean_rng(core::CounterRng(seed, 0x1EA7, index, 1));
  core::RngStream turn_rng(core::CounterRng(seed, 0x7A2E, index, 1));
  double cam_h_used = cam_h;

  double pitch = 0;
  std::vector<Eigen::Vector2d> floor_positions;  // (lateral, distance) of people placed so far
  for (int p = 0; p < people; ++p) {
    PersonPlacement person;
    person.body = int(rng.UniformInt(uint32_t(bodies_.size())));
    const uint64_t pose_bits = rng.Bits();
    if (!c.poses.empty()) {
      person.pose = c.poses[size_t(pose_bits % c.poses.size())];
    } else if (c.shared_poses && !c.shared_poses->empty()) {
      person.pose = (*c.shared_poses)[size_t(pose_bits % c.shared_poses->size())];
    } else {
      person.pose = SampleProceduralPose(pose_bits, 0);
    }
    if (c.arm_pose_share > 0 && arms_rng.Uniform01() < c.arm_pose_share)
      PerturbArms(seed, index * 8 + uint64_t(p), &person.pose);
    if (c.sit_share > 0 && sit_rng.Uniform01() < c.sit_share) SitDown(seed, index * 8 + uint64_t(p), &person.pose);
    if (c.lean_share > 0 && lean_rng.Uniform01() < c.lean_share)
      LeanTrunk(seed, index * 8 + uint64_t(p), &person.pose);
    // Library and procedural poses are relative to the canonical T-pose; re-express them for a
    // body resting in another pose (MakeHuman's A-pose), or its arms would come out ~45 deg off.
    if (adapt_pose_[size_t(person.body)])
      person.pose = assets::AdaptPose(person.pose, bodies_[size_t(person.body)].rest_joints);
    person.scale = 1.0 + rng.UniformIn(-c.height_jitter, c.height_jitter);
    // One draw from rng either way, so the rest of the scene stays what it was.
    const bool turned = c.turned_share > 0 && turn_rng.Uniform01() < c.turned_share;
    const double yaw_range = turned ? c.turned_range_deg : c.rotation_range_deg;
    const double yaw = rng.UniformIn(-yaw_range, yaw_range);
    // Place people at least 0.7 m apart on the floor (a few deterministic retries; after
    // those, the last draw stands even if close: crowded frames are rare and harmless).
    double dist = 0, lateral = 0;
    for (int attempt = 0; attempt < 8; ++attempt) {
      dist = rng.UniformIn(c.min_distance_m, c.max_distance_m);
      lateral = rng.UniformIn(-1.0, 1.0) * c.lateral_fraction * dist * half_fov_tan;
      bool clear = true;
      for (const Eigen::Vector2d& o : floor_positions)
        clear = clear && (o - Eigen::Vector2d(lateral, dist)).norm() >= 0.7;
      if (clear) break;
    }
    if (p == 0 && upper_body) {  // the first person framed on the upper body (FramingConfig)
      dist = framing_rng.UniformIn(c.framing.upper_body_min_distance_m, c.framing.upper_body_max_distance_m);
      lateral = framing_rng.UniformIn(-1.0, 1.0) * c.lateral_fraction * dist * half_fov_tan;
    }
    floor_positions.emplace_back(lateral, dist);

    // Face +Z: mocap clips carry their own heading; the scene's yaw replaces it (section 2.2:
    // rotation about the vertical is added, not recorded). Then ground the feet: the lowest
    // foot joint keeps its rest height; mocap root drift is dropped.
    const BodyMesh& body = bodies_[size_t(person.body)];
    SkelPositions rest = body.rest_joints;
    for (auto& j : rest) j *= person.scale;
    person.pose.root_translation.setZero();
    FaceForward(rest, &person.pose);
    const SkelPositions posed = PoseJoints(rest, person.pose);
    double lift = 1e9;
    for (SkelJoint j : {SkelJoint::kLAnkle, SkelJoint::kRAnkle, SkelJoint::kLToe, SkelJoint::kRToe}) {
      lift = std::min(lift, posed[size_t(int(j))].y() - rest[size_t(int(j))].y());
    }
    person.pose.root_translation = Eigen::Vector3d(0, -lift, 0);

    if (p == 0 && upper_body) {  // aim between the chest and the head, the camera near that height
      const double chest = posed[size_t(int(SkelJoint::kChest))].y() - lift;
      const double head = posed[size_t(int(SkelJoint::kHead))].y() - lift;
      const double aim = chest + framing_rng.Uniform01() * (head - chest);
      cam_h_used = std::max(0.2, aim + framing_rng.UniformIn(-c.framing.upper_body_camera_below_m,
                                                             c.framing.upper_body_camera_above_m));
      pitch = std::atan2(cam_h_used - aim, dist) + tilt_jitter * kDeg;
    } else if (p == 0) {  // aim the camera at the first person's mid-height
      double top = 0;
      for (const auto& j : posed) top = std::max(top, j.y() - lift);
      pitch = std::atan2(cam_h - 0.5 * top, dist) + tilt_jitter * kDeg;
    }
    // World: X right, Y up, Z towards the camera (camera at (0, cam_h, 0) looking along -Z).
    // Camera: x right, y down, z forward = (X, -Y, -Z), then pitch (down +) and roll.
    Eigen::Isometry3d world_from_body = Eigen::Isometry3d::Identity();
    world_from_body.translate(Eigen::Vector3d(lateral, 0, -dist));
    world_from_body.rotate(Eigen::AngleAxisd(yaw * kDeg, Eigen::Vector3d::UnitY()));
    person.camera_from_body = world_from_body;  // camera part added below, once pitch is known
    scene.people.push_back(person);
  }
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.rotate(Eigen::AngleAxisd(roll * kDeg, Eigen::Vector3d::UnitZ()));
  camera_from_world.rotate(Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()));
  camera_from_world.rotate(Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()));
  camera_from_world.translate(Eigen::Vector3d(0, -cam_h_used, 0));
  for (auto& person : scene.people) person.camera_from_body = camera_from_world * person.camera_from_body;
  scene.camera_from_world = camera_from_world;
  if (c.clutter.enabled())
    scene.clutter = SampleClutter(c.clutter, seed, index, half_fov_tan, floor_positions);
  return scene;
}

core::Result<RenderedFrame> SyntheticRenderer::RenderScene(const SceneSample& scene) {
  const double t0 = ThreadCpuMs();
  Eigen::Matrix3d flip = Eigen::Matrix3d::Identity();
  if (scene.mirrored) flip(0, 0) = -1.0;  // mirror the camera x axis (pixel u -> 2 cx - u)
  RenderedFrame frame;
  std::vector<JointMatrices> matrices(scene.people.size());
  for (size_t p = 0; p < scene.people.size(); ++p) {
    const PersonPlacement& person = scene.people[p];
    if (person.body < 0 || size_t(person.body) >= bodies_.size()) {
      return Status(ErrorCode::kInvalidArgument,
                    "RenderScene: body index " + std::to_string(person.body) + " out of range");
    }
    const BodyMesh& body = bodies_[size_t(person.body)];
    SkelPositions rest = body.rest_joints;
    for (auto& j : rest) j *= person.scale;
    const SkinTransforms t = ComputeSkinTransforms(rest, person.pose);
    Eigen::Matrix4d cam = Eigen::Matrix4d::Identity();
    cam.topLeftCorner<3, 3>() = flip * person.camera_from_body.linear();
    cam.topRightCorner<3, 1>() = flip * person.camera_from_body.translation();
    for (int j = 0; j < kNumSkelJoints; ++j) {
      // The GPU holds the unscaled rest mesh: M_j = camera * T_j * diag(s, s, s, 1).
      Eigen::Matrix4d ms = cam * t[size_t(j)].matrix();
      ms.topLeftCorner<3, 3>() *= person.scale;
      matrices[p][size_t(j)] = ms.topRows<3>().cast<float>();
    }
    const SkelPositions posed = PoseJoints(rest, person.pose);
    const auto eval = EvalJoints(posed);
    std::array<Eigen::Vector3f, core::kNumJoints> joints;
    for (int j = 0; j < core::kNumJoints; ++j) {
      const int src = scene.mirrored ? core::MirrorJoint(j) : j;
      joints[size_t(j)] =
          (cam.topLeftCorner<3, 3>() * eval[size_t(src)] + cam.topRightCorner<3, 1>()).cast<float>();
    }
    frame.joints.push_back(joints);
  }
  const double t1 = ThreadCpuMs();
  POSEFOREST_RETURN_IF_ERROR(gl_->BeginFrame());
  for (size_t p = 0; p < scene.people.size(); ++p) {
    gl_->Draw(gpu_mesh_[size_t(scene.people[p].body)], matrices[p], scene.mirrored, int(p) + 1);
  }
  if (profile_stages_) gl_->Finish();
  const double t2 = ThreadCpuMs();
  POSEFOREST_RETURN_IF_ERROR(gl_->ReadFrame(&frame.depth, &frame.labels, &frame.people));
  const double t3 = ThreadCpuMs();
  const SceneClutter& clutter = scene.clutter;
  if (clutter.floor || clutter.back_wall_z < 0 || clutter.side_wall_x != 0 || !clutter.boxes.empty()) {
    // Composite by depth: clutter nearer than the person (or where there is none) wins.
    RayCastClutter(clutter, scene.camera_from_world, scene.mirrored, config_.camera, &clutter_depth_);
    const size_t n = frame.depth.pixels.size();
    for (size_t i = 0; i < n; ++i) {
      const uint16_t c = clutter_depth_.pixels[i];
      if (c != 0 && (frame.depth.pixels[i] == 0 || c < frame.depth.pixels[i])) {
        frame.depth.pixels[i] = c;
        frame.labels.pixels[i] = core::kBackgroundLabel;
        frame.people.pixels[i] = 0;
      }
    }
  }

  // Visibility from the clean depth, before noise.
  const core::CameraIntrinsics& cam = config_.camera;
  for (const auto& joints : frame.joints) {
    std::array<bool, core::kNumJoints> vis{};
    for (int j = 0; j < core::kNumJoints; ++j) {
      const Eigen::Vector3d q = joints[size_t(j)].cast<double>();
      if (q.z() <= 0.05) continue;
      const Eigen::Vector2d uv = cam.Project(q);
      const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
      if (!frame.depth.InBounds(u, v)) continue;
      const uint16_t d = frame.depth.at(u, v);
      // The head joint is the centre of the head, about 10 cm behind its front surface.
      const double slack = j == int(core::Joint::kHead) ? 0.15 : 0.10;
      vis[size_t(j)] = d == 0 || double(d) * 1e-3 >= q.z() - slack;
    }
    frame.visible.push_back(vis);
  }
  ApplyKinectNoise(config_.noise, scene.noise_key, &frame.depth, &frame.labels, &frame.people);
  if (config_.noise.enabled)
    for (size_t i = 0; i < frame.depth.pixels.size(); ++i)
      if (frame.depth.pixels[i] == 0) frame.people.pixels[i] = 0;
  const double t4 = ThreadCpuMs();
  times_.pose_ms += t1 - t0;
  times_.draw_ms += t2 - t1;
  times_.readback_ms += t3 - t2;
  times_.post_ms += t4 - t3;
  ++times_.frames;
  return frame;
}

core::Result<RenderedFrame> SyntheticRenderer::Render(uint64_t seed, uint64_t index) {
  return RenderScene(Sample(seed, index));
}

}  // namespace poseforest::renderer
