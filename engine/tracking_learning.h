#pragma once
// Fitting the learned tracking decision (core::TrackingModel, format 1.6) on validation renders.
//
// Each validation frame (one person) is classified, its joints proposed and voted as `live` does,
// and its skeleton built with the hand-set rules, options.skeleton's fit choosing the positions;
// every joint the skeleton found gives one sample: its joint, calibrated confidence and cues
// (SkeletonJoint::cues), whether it lies within 0.1 m of the true joint, and whether the camera
// sees the true joint (the renders' `visible`). Logistic regression (Newton's method, an L2
// penalty on the weights) fits P(within 0.1 m), and on the same samples the seen decision
// P(seen) (format 1.8). The frames are the validation source's frames
// [first_index, first_index + frames): after the vote calibration's, so the model is not fitted
// on the frames its inputs were calibrated on. Deterministic: same forest and options, same
// model, whatever the number of threads.

#include <functional>
#include <string>

#include "engine/job_spec.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"
#include "runtime/skeleton.h"

namespace poseforest::engine {

struct TrackingLearningOptions {
  SourceSpec validation;      ///< frames with joints, one person each (others skipped)
  uint64_t first_index = 60;  ///< the first validation frame used (after the vote calibration's 60)
  int frames = 200;
  int threads = 0;            ///< 0 = all cores
  double l2 = 1.0;            ///< penalty on the squared weights (the log-likelihood's scale)
  /// How positions are chosen: the fit (unset: kinematic, the run-time default) whose choices
  /// the model learns from, and which it records (core::TrackingModel::fit).
  runtime::SkeletonOptions skeleton;
  /// Also fit the seen decision (core::TrackingModel::seen, format 1.8): P(the camera sees the
  /// joint) on the same samples.
  bool seen_model = true;
  std::function<void(const std::string&)> progress;  ///< may be empty
};

struct TrackingLearningReport {
  int frames = 0;       ///< one-person frames used
  int samples = 0;      ///< found joints (the fit's samples)
  int iterations = 0;   ///< Newton steps
  /// On the fitting frames: visible joints tracked within 0.1 m (mean over joints), the share
  /// of tracked joints within 0.1 m, and the share of joints left untracked that are hidden.
  struct Figures {
    double visible_within = 0, precision = 0, untracked_hidden = 0;
  };
  /// By the hand-set rules, by the model's P(within 0.1 m), and by its seen decision.
  Figures rules, model, seen;
  /// The thresholds those figures were counted at: options.skeleton's track_probability and
  /// seen_probability (the run-time defaults unless the caller changed them).
  float track_probability = 0, seen_probability = 0;
  double seconds = 0;
};

/// The tracking model of `forest` (with its calibration and, if it has them, its votes).
/// Errors: frames without joints, no one-person frame, rendering failures.
core::Result<core::TrackingModel> LearnTrackingModel(const core::Forest& forest,
                                                     const TrackingLearningOptions& options,
                                                     TrackingLearningReport* report = nullptr);

/// The fit alone (exposed for tests): samples' joints, calibrated confidences, cues and labels
/// (1: within 0.1 m) -> the penalized maximum-likelihood model. `iterations` (optional) gets
/// the number of Newton steps.
core::TrackingModel FitTrackingModel(const std::vector<int>& joints, const std::vector<float>& confidences,
                                     const std::vector<core::TrackingFeatures>& cues,
                                     const std::vector<uint8_t>& labels, double l2, int* iterations = nullptr);

}  // namespace poseforest::engine
