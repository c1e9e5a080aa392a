#pragma once
// runtime::Skeleton in the C API's layout (pf_skeleton). Internal (not installed): c_api.cpp's
// conversion, in a header so test_api checks it on a skeleton made by hand as well as through a
// stream (a stream gives inferred joints only with a forest that has offset votes).
#include <cstdint>

#include "poseforest/poseforest.h"
#include "runtime/skeleton.h"

namespace poseforest::capi {

static_assert(PF_SKELETON_JOINTS == core::kNumJoints);
static_assert(int(runtime::JointState::kNotTracked) == PF_JOINT_NOT_TRACKED &&
              int(runtime::JointState::kInferred) == PF_JOINT_INFERRED &&
              int(runtime::JointState::kTracked) == PF_JOINT_TRACKED);

/// found, tracked, state always; position, pixel and confidence only for a found joint (else zeros).
inline pf_skeleton_joint ToPfJoint(const runtime::SkeletonJoint& in) {
  pf_skeleton_joint out{};
  out.found = in.found ? 1 : 0;
  out.tracked = in.tracked ? 1 : 0;
  out.state = int32_t(runtime::StateOf(in));
  if (!in.found) return out;
  for (int i = 0; i < 3; ++i) out.position_m[i] = in.position_m[i];
  out.pixel[0] = in.pixel.x();
  out.pixel[1] = in.pixel.y();
  out.confidence = in.confidence;
  return out;
}

inline pf_skeleton ToPfSkeleton(const runtime::Skeleton& s) {
  pf_skeleton out{};
  out.id = s.id;
  out.pixels = s.pixels;
  for (int i = 0; i < 3; ++i) out.centroid_m[i] = s.centroid_m[i];
  for (int j = 0; j < PF_SKELETON_JOINTS; ++j) out.joints[j] = ToPfJoint(s.joints[size_t(j)]);
  return out;
}

}  // namespace poseforest::capi
