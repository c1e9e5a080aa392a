#pragma once
// Skeletons scored against hand-labelled real depth frames (`poseforest eval --real-labels`).
//
// A label file (the format of ../shared/data/real/skeltrack_kinect_depth/joint_labels.json, see
// its JOINT_LABELS.md) names a camera and, per frame, a depth file beside it and the 16 joints:
// `uv` (pixel), `err_px` (the labeller's error radius), `occluded`, and `xyz_m`: `uv`
// back-projected at the depth of the body surface there, or null when the joint is not labelled.
// A joint's centre lies behind that surface, so a labelled joint is *right* when the skeleton
// tracks it within kRealHitRadiusM of the surface point moved kSurfaceToCentreM further along the
// camera ray (the label file's own scoring rule).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "runtime/camera_model.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/result.h"
#include "runtime/skeleton_pipeline.h"
#include "runtime/visualize.h"

namespace poseforest::engine {

inline constexpr double kRealHitRadiusM = 0.10;    ///< a tracked joint this close to its target is right
inline constexpr double kSurfaceToCentreM = 0.04;  ///< labelled surface point -> joint centre, along the ray

struct RealJointLabel {
  Eigen::Vector2d uv{0, 0};         ///< pixel (u right, v down)
  double err_px = 0;                ///< the labeller's error radius, pixels
  bool occluded = false;            ///< placed from its neighbours (e.g. a wrist behind its fist)
  Eigen::Vector3d surface_m{0, 0, 0};  ///< xyz_m: the labelled point on the body surface, camera frame
  /// Where the joint's centre is taken to be: surface_m moved kSurfaceToCentreM along its ray.
  Eigen::Vector3d Target() const;
};

struct RealFrameLabels {
  std::string file;  ///< as in the label file
  std::string path;  ///< resolved against the label file's folder
  std::array<std::optional<RealJointLabel>, core::kNumJoints> joints;  ///< nullopt = not labelled
};

struct RealLabelSet {
  runtime::CameraModel camera;
  std::vector<RealFrameLabels> frames;
};

/// Reads a label file. Errors name the file and what is wrong (kIo: unreadable; kDataLoss: not
/// JSON, a missing or mistyped field, an unknown joint name, a non-finite or off-camera value).
core::Result<RealLabelSet> ReadRealLabels(const std::string& path);
/// Writes `set` in the same format (frames' `file` as given). For labels made from renders.
core::Status WriteRealLabels(const std::string& path, const RealLabelSet& set);

/// What the skeleton did with one labelled joint.
struct RealJointOutcome {
  bool labelled = false;
  bool tracked = false;     ///< the skeleton tracks the joint
  bool right = false;       ///< tracked, within kRealHitRadiusM of the target
  bool found_right = false;  ///< the skeleton's position (tracked or not) within kRealHitRadiusM
  bool any_right = false;   ///< the skeleton's position or any proposal on the person within kRealHitRadiusM
  double error_m = -1;      ///< tracked: 3D distance to the target
  double error_px = -1;     ///< tracked: 2D distance of its pixel to uv
};

struct RealFrameOutcome {
  std::string file;
  int skeleton = -1;  ///< index into the frame's skeletons, -1: no person found
  std::array<RealJointOutcome, core::kNumJoints> joints;
};

/// The skeleton of `frame` that is the labelled person: the one whose mask holds the most
/// labelled pixels (within 3 px), ties to the larger mask; -1 when none holds any.
int PickLabelledSkeleton(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame);

/// Scores skeleton `skeleton` of `frame` (-1: none) against `labels`. "Any position on the
/// person" counts the skeleton's position and every proposal of the joint whose pixel lies on the
/// person's mask (within 2 px), tracked or not.
RealFrameOutcome ScoreRealFrame(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame, int skeleton);

/// Per joint and per group (head-neck-shoulders, elbows, wrists, hands, all labelled joints).
struct RealScoreRow {
  std::string name;
  int labelled = 0, tracked = 0, right = 0, found_right = 0, any_right = 0;
  double median_error_px = -1;  ///< over tracked joints; -1 when none
  double right_fraction() const { return labelled ? double(right) / labelled : 0.0; }
  double any_fraction() const { return labelled ? double(any_right) / labelled : 0.0; }
};
struct RealScore {
  std::vector<RealScoreRow> joints;  ///< labelled joints only, core::Joint order
  std::vector<RealScoreRow> groups;  ///< the last is "all"
  const RealScoreRow& all() const { return groups.back(); }
};
RealScore SummarizeReal(const std::vector<RealFrameOutcome>& frames);
/// The table `eval --real-labels` prints.
std::string FormatRealScore(const RealScore& score);

/// depth | parts | depth with the skeleton, each labelled joint drawn as a ring at its uv, green
/// when the skeleton has it right, red otherwise, with a line to where the skeleton put it.
runtime::RgbImage RealFramePicture(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame,
                                   const RealFrameOutcome& outcome);

}  // namespace poseforest::engine
