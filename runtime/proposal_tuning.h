#pragma once
// Learning the joint-proposal parameters (section 3.4): per joint, the bandwidth b, seed
// threshold lambda and z offset zeta are chosen by grid search to maximize that joint's average
// precision on a held-out validation set. Joints are independent (a joint's proposals depend
// only on its own parameters), so one proposal run per (b, lambda) serves all 16 joints, and
// each joint then picks its own best grid point.

#include <functional>
#include <vector>

#include "runtime/core/confidence_calibration.h"
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

/// The values tried (the paper's learned means 0.065 m, 0.14 and 0.039 m lie inside). On our
/// forests no joint chose b = 0.03 m or lambda = 0.05 and many chose the largest values of a
/// 0.03..0.12 m x 0.05..0.3 grid, then of lambda 0.4, so the grid reaches higher.
struct TuningGrid {
  std::vector<float> bandwidth_m = {0.045f, 0.065f, 0.09f, 0.12f, 0.16f};
  std::vector<float> prob_threshold = {0.1f, 0.14f, 0.2f, 0.3f, 0.4f, 0.55f};
  /// Cheap (it only moves proposals), so finer: 0 .. 0.1 m in 1 cm steps.
  std::vector<float> z_offset_m = {0.0f, 0.01f, 0.02f, 0.03f, 0.04f, 0.05f, 0.06f, 0.07f, 0.08f, 0.09f, 0.1f};
  size_t points() const { return bandwidth_m.size() * prob_threshold.size() * z_offset_m.size(); }
  /// Left and right joints of a pair (core::MirrorJoint) share their parameters, chosen by the
  /// mean of the two APs: half as many values from the same frames (the renderer mirrors half
  /// the frames, so the two sides are alike), less noise from a small validation set.
  bool mirror_pairs = true;
};

struct TuningResult {
  core::ProposalParams params;
  std::array<double, core::kNumJoints> ap{};  ///< validation AP of each joint at its best parameters
  /// Validation AP of each joint with the starting parameters (`base.params`), for comparison.
  std::array<double, core::kNumJoints> base_ap{};
  double mean_ap = 0;       ///< over joints visible in the set, at the learned parameters
  double base_mean_ap = 0;  ///< the same at the starting parameters
};

/// Grid search. `base` supplies the method and camera; its params are the starting point and
/// are returned for joints never visible in the set. `distance_m` is the AP's D.
/// The z offset only moves proposals, so it is searched for each (b, lambda) without
/// re-running mean shift. Frames are processed in parallel (`base.num_threads`, 0 = all
/// cores); the result does not depend on the thread count. `progress` is called after each
/// (b, lambda) grid point with the number done and the total.
TuningResult TuneProposalParams(const std::vector<ValidationFrame>& frames, const ProposalOptions& base,
                                const TuningGrid& grid = {}, float distance_m = 0.1f,
                                const std::function<void(int done, int total)>& progress = {});

/// Measures the joint confidence calibration (format 1.4, JCAL) with `options` (method, camera,
/// the parameters the forest will run with): every proposal of every frame is binned by its
/// support (raw confidence / (fx fy) of options.camera, m^2, bins core::DefaultSupportEdges) and
/// counted as right when it lies within `distance_m` of that joint of some person (visible or
/// not: an occluded elbow found behind the body is found); each joint's precision per bin is
/// then made non-decreasing in support by an isotonic (pool-adjacent-violators) fit weighted by
/// the bins' counts. Bins below a joint's first sample take its first value; a joint never
/// proposed gets the fallback's values at the bin centres.
core::ConfidenceCalibration CalibrateConfidence(const std::vector<ValidationFrame>& frames,
                                                const ProposalOptions& options, float distance_m = 0.1f);

/// The isotonic fit used above (exposed for tests): the non-decreasing sequence closest to
/// `values` in weighted least squares; entries with weight 0 take their left neighbour's value
/// (or the first weighted one's).
std::vector<float> IsotonicFit(const std::vector<double>& values, const std::vector<double>& weights);

}  // namespace poseforest::runtime
