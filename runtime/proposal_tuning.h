#pragma once
// Learning the joint-proposal parameters (section 3.4): per joint, the bandwidth b, seed
// threshold lambda and z offset zeta are chosen by grid search to maximize that joint's average
// precision on a held-out validation set. Joints are independent (a joint's proposals depend
// only on its own parameters), so each is searched on its own grid.

#include <functional>
#include <vector>

#include "runtime/core/depth_image.h"
#include "runtime/core/proposal_params.h"
#include "runtime/joint_metrics.h"
#include "runtime/joint_proposals.h"

namespace poseforest::runtime {

/// One validation frame: depth, per-pixel joint probabilities (inferred), ground truth people.
struct ValidationFrame {
  core::DepthImage depth;
  JointProbabilities probs;
  std::vector<PersonJoints> people;
};

struct TuningGrid {
  std::vector<float> bandwidth_m = {0.03f, 0.045f, 0.065f, 0.09f, 0.12f};
  std::vector<float> prob_threshold = {0.05f, 0.1f, 0.14f, 0.2f, 0.3f};
  std::vector<float> z_offset_m = {0.0f, 0.02f, 0.039f, 0.06f, 0.08f};
};

struct TuningResult {
  core::ProposalParams params;
  std::array<double, core::kNumJoints> ap{};  ///< validation AP of each joint at its best parameters
  double mean_ap = 0;
};

/// Grid search. `base` supplies the method and camera; its params are the starting point and
/// are returned for joints never visible in the set. `distance_m` is the AP's D.
/// The z offset only moves proposals, so it is searched for each (b, lambda) without
/// re-running mean shift.
TuningResult TuneProposalParams(const std::vector<ValidationFrame>& frames, const ProposalOptions& base,
                                const TuningGrid& grid = {}, float distance_m = 0.1f,
                                const std::function<void(int joint, double ap)>& progress = {});

}  // namespace poseforest::runtime
