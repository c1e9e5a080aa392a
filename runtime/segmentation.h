#pragma once
// People segmentation of raw depth frames: what the forest was trained on is a person alone, with
// everything else at the feature's background value (depth 0 here: a probe on 0 reads
// FeatureConstants::background_mm). A raw frame has a floor, walls and furniture; this finds
// the people in it:
//   1. floor: a seeded (deterministic) RANSAC plane fit on back-projected points, kept only if it
//      is roughly horizontal and below the camera, or a plane given by the caller; pixels within
//      floor_distance_m of it are removed;
//   2. a depth band [near_m, far_m];
//   3. depth-aware connected components: 4-neighbours join only if their depths differ by at most
//      max(jump_mm, jump_fraction * depth), so people touching in the image at different depths
//      split; pieces too small to be a person (an arm in front of the body) rejoin the
//      neighbouring component nearest in depth, and two pieces of one body cut apart by something
//      in front (another person's arm) rejoin;
//   4. size limits: a person is a component of metric height, width and area within limits that
//      does not fill its bounding box like a box or a wall panel (fill ratio), and is not
//      background seen through a gap (a component behind everything it touches across a jump).
// Pre-segmented input (most pixels 0 and no floor) passes unchanged; `presegmented` forces it.

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"

namespace poseforest::runtime {

struct SegmentationOptions {
  /// A known floor plane n.p + d = 0 (camera frame, metres, |n| = 1); skips the RANSAC fit.
  std::optional<Eigen::Vector4d> floor_plane;
  bool find_floor = true;                  ///< fit the floor when none is given
  double floor_distance_m = 0.06;          ///< points this close to the floor are floor
  int ransac_iterations = 96;              ///< plane hypotheses
  int ransac_samples = 1024;               ///< points the fit scores hypotheses on (a grid over the frame)
  uint64_t seed = 1;                       ///< RANSAC draws; the result is deterministic
  double floor_max_tilt_deg = 45;          ///< floor normal within this of the camera's up axis
  double min_floor_fraction = 0.03;        ///< a floor holds at least this fraction of the sampled points
  double floor_min_depth_range_m = 0.5;    ///< ... spanning at least this range of depths
  double floor_min_width_m = 1.0;          ///< ... and at least this width
  double floor_max_below_fraction = 0.02;  ///< ... with at most this fraction of points beyond it
  double near_m = 0.4, far_m = 4.5;        ///< depth band, metres
  int jump_mm = 50;                        ///< neighbour depth jump that separates components ...
  double jump_fraction = 0.03;             ///< ... or this fraction of the depth, whichever is larger
  double merge_distance_m = 0.3;           ///< pieces of one body rejoin within this depth gap ...
  double occlusion_gap_m = 0.6;            ///< ... and, cut apart by something in front, this far apart
  double min_height_m = 0.35, max_height_m = 2.3;  ///< person's extent along the image's vertical
  double min_width_m = 0.15, max_width_m = 2.6;
  double min_area_m2 = 0.04, max_area_m2 = 2.0;  ///< silhouette area (pixels x (d/f)^2)
  double max_fill = 0.86;                        ///< a component filling more of its bounding box is a box
  /// Pre-segmented detection: at least this fraction of pixels 0 and no floor -> unchanged.
  double presegmented_zero_fraction = 0.5;
  /// Force: true = always pass unchanged, false = always segment; unset = detect.
  std::optional<bool> presegmented;
};

struct PersonInfo {
  int label = 0;  ///< 1-based value in SegmentationResult::labels
  int pixels = 0;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< bounding box, inclusive pixels
  double height_m = 0, width_m = 0, area_m2 = 0, mean_depth_m = 0;
};

struct SegmentationResult {
  core::DepthImage depth;                ///< people only; everything else 0 (the background value)
  core::LabelImage labels;               ///< 0 = background, 1..people.size() = person
  std::vector<PersonInfo> people;        ///< ordered by pixel count, largest first
  bool presegmented = false;             ///< passed through unchanged
  std::optional<Eigen::Vector4d> floor;  ///< the floor plane used, if any
  int floor_pixels = 0;
  int components = 0;  ///< components considered (before size limits)
};

/// Segments one frame; `out` storage is reused. Thread-safe for distinct outputs.
void SegmentPeople(const core::DepthImage& depth, const core::CameraIntrinsics& camera,
                   const SegmentationOptions& options, SegmentationResult* out);

/// The depth of one person (label) alone, for per-person classification.
core::DepthImage PersonDepth(const SegmentationResult& seg, int label);

/// Intersection over union of two masks: a's pixels equal to `a_label` against b's equal to
/// `b_label`. 1 when both are empty.
double MaskIoU(const core::LabelImage& a, int a_label, const core::LabelImage& b, int b_label);

}  // namespace poseforest::runtime
