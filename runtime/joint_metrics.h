#pragma once
// Joint prediction accuracy exactly as section 4 of the paper defines it: per joint, proposals of
// all test frames are ranked by confidence; within a frame, the first (most confident) proposal
// within D = 0.1 m of a visible ground-truth joint is a true positive, further proposals within D
// of that joint are false positives, proposals farther than D from every ground-truth joint are
// false positives; every proposal counts, not only the most confident. Joints invisible in the
// image are not penalized as false negatives (they are not in the recall denominator) and
// proposals near them count neither way. Average precision is the area under the
// precision-recall curve (all-point interpolation, as PASCAL VOC); mAP averages the 16 joints.

#include <Eigen/Core>
#include <array>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/joint_proposals.h"

namespace poseforest::runtime {

/// Ground truth of one person: 16 joints (camera frame, metres) and whether each is visible.
struct PersonJoints {
  std::array<Eigen::Vector3f, core::kNumJoints> position;
  std::array<bool, core::kNumJoints> visible{};
};

struct PrPoint {
  float threshold;  ///< confidence threshold
  double precision, recall;
};

class JointApEvaluator {
 public:
  explicit JointApEvaluator(float distance_m = 0.1f) : distance_(distance_m) {}

  /// Scores one frame's proposals against the people in it.
  void AddFrame(const FrameProposals& proposals, const std::vector<PersonJoints>& people);

  /// Average precision of joint j (0 if it never appeared visibly).
  double AveragePrecision(int joint) const;
  /// Mean over the joints that appeared visibly at least once.
  double MeanAveragePrecision() const;
  /// The precision-recall curve of joint j as the confidence threshold falls.
  std::vector<PrPoint> Curve(int joint) const;
  /// The mAP-level curve: at `levels` recalls evenly from 0 to 1, the mean over the joints that
  /// appeared of each joint's interpolated precision (the best precision at that recall or more;
  /// 0 past its highest recall). The area under it is MeanAveragePrecision up to the sampling.
  std::vector<PrPoint> MeanCurve(int levels = 101) const;
  int positives(int joint) const { return positives_[size_t(joint)]; }
  /// Proposals scored for joint j (true and false positives).
  size_t scored(int joint) const { return scored_[size_t(joint)].size(); }

 private:
  struct Scored {
    float confidence;
    bool true_positive;
  };
  float distance_;
  std::array<std::vector<Scored>, core::kNumJoints> scored_;
  std::array<int, core::kNumJoints> positives_{};
};

}  // namespace poseforest::runtime
