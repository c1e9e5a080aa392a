#pragma once
// A skeleton made by hand with one joint in each state every output names (tracked, inferred,
// found but not tracked, not found), for the tests of those outputs: the JSON Lines record, the C
// API's layout, the ROS 2 messages and the pictures. Header-only: poseforest_testsupport links
// the core alone, the tests that include this link the runtime.

#include <Eigen/Core>

#include "runtime/core/body_parts.h"
#include "runtime/skeleton.h"

namespace poseforest::testing {

/// Which joint of FourStateSkeleton() is in which state (the rest are not found).
inline constexpr int kTrackedJoint = int(core::Joint::kHead);      // tracked
inline constexpr int kInferredJoint = int(core::Joint::kLKnee);    // found, not tracked, inferred
inline constexpr int kFoundOnlyJoint = int(core::Joint::kRElbow);  // found, not tracked
inline constexpr int kNotFoundJoint = int(core::Joint::kRFoot);    // not found

/// Person id 3 (PersonColour(3)), 1200 pixels, about 2.5 m away. Positions and pixels are set
/// independently (exact binary fractions, so printed values are exact); the pixels lie inside a
/// 640x480 frame. The inferred knee is a vote's (voted), as a hidden joint is.
inline runtime::Skeleton FourStateSkeleton() {
  runtime::Skeleton s;
  s.id = 3;
  s.mask_label = 1;
  s.pixels = 1200;
  s.centroid_m = Eigen::Vector3f(0.1f, -0.2f, 2.5f);
  auto place = [&](int j, Eigen::Vector3f position, Eigen::Vector2f pixel, float confidence) {
    runtime::SkeletonJoint& joint = s.joints[size_t(j)];
    joint.found = true;
    joint.position_m = position;
    joint.pixel = pixel;
    joint.confidence = confidence;
  };
  place(kTrackedJoint, {0.125f, -0.5f, 2.25f}, {330.5f, 100.25f}, 0.875f);
  s.joints[size_t(kTrackedJoint)].tracked = true;
  place(kInferredJoint, {0.0625f, 0.25f, 2.875f}, {339.5f, 302.0f}, 0.75f);
  s.joints[size_t(kInferredJoint)].voted = true;
  s.joints[size_t(kInferredJoint)].inferred = true;
  place(kFoundOnlyJoint, {-0.25f, -0.125f, 2.5f}, {259.0f, 215.0f}, 0.125f);
  return s;
}

}  // namespace poseforest::testing
