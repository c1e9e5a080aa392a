#pragma once
// The learned tracking decision (format 1.6, optional section JTRK). Whether a skeleton joint is
// *tracked* was a chain of hand-set rules: its calibrated confidence above a minimum, not near an
// image border that cuts the person, a bone of possible length to a tracked parent. Each rule is
// one cue of whether the joint's position is right; the model weighs them all, and more, by
// logistic regression on validation renders (`learn-votes` fits it after the votes):
//
//   P(the joint lies within 0.1 m of the truth) = sigmoid(a_j + b_j * logit(c) + w . f)
//
// with c the joint's calibrated confidence (part proposal or vote candidate), a_j and b_j per
// joint, w shared by the joints, and f the cues of TrackingFeature. The skeleton reports P as the
// joint's confidence and tracks the joint when P reaches SkeletonOptions::track_probability
// (0.5: more likely right than wrong) and it lies at the surface's depth.

#include <array>
#include <optional>
#include <string>

#include "runtime/core/body_parts.h"
#include "runtime/core/result.h"

namespace poseforest::core {

/// The shared cues, in the order of TrackingModel::shared (and of the file). Never reorder: a
/// new cue is a new format.
enum TrackingFeature : int {
  kFeatVoted = 0,         ///< the position is a vote candidate's (1) or a part proposal's (0)
  kFeatAgreed,            ///< the best proposal and the best vote candidate lie within agree_radius_m
  kFeatProposalVoteGap,   ///< distance between the best proposal and the best vote candidate, m (0.5 cap; 0.5 if either is missing)
  kFeatHasProposal,       ///< the joint has a part proposal on the person
  kFeatHasVote,           ///< the joint has a usable vote candidate on the person
  kFeatNearCutEdge,       ///< within 0.15 m of an image border that cuts the person's mask
  kFeatBoneOk,            ///< its parent is found and their bone has a possible length (BoneLengthRange)
  kFeatBoneBad,           ///< its parent is found and their bone has an impossible length
  kFeatParentLogit,       ///< logit of the parent's calibrated confidence (0: no parent, or not found)
  kFeatChildrenOk,        ///< how many of its children are found at a possible bone length
  kFeatDepthGap,          ///< |depth - the mask's depth at its pixel|, m (0.5 cap)
  kNumTrackingFeatures
};

/// kFeatNearCutEdge's margin, metres: the cue is fixed, whatever SkeletonOptions::edge_margin_m
/// (the rule it replaces) is set to, so a model reads the cue it was fitted on.
inline constexpr float kCutEdgeCueMarginM = 0.15f;

/// Names of the cues (inspect, learn-votes' report).
const char* TrackingFeatureName(int feature);

using TrackingFeatures = std::array<float, kNumTrackingFeatures>;

/// Which skeleton fit's choices a model was fitted on (runtime::SkeletonFit, the same values): a
/// model weighs the cues of the positions that fit chooses, and another fit's positions are
/// another population. Format 1.7 stores it (section JTFT, written for kKinematic); a model
/// without that section was fitted on kGreedy's choices (every 1.6 file).
enum class TrackingFit : uint8_t { kGreedy = 0, kKinematic = 1 };

/// "greedy" or "kinematic".
const char* TrackingFitName(TrackingFit fit);

/// One logistic model over a joint's confidence and cues: sigmoid(a_j + b_j logit(c) + w . f).
struct TrackingWeights {
  std::array<float, kNumJoints> intercept{};  ///< a_j
  std::array<float, kNumJoints> slope{};      ///< b_j, on logit(calibrated confidence)
  std::array<float, kNumTrackingFeatures> shared{};  ///< w
  bool operator==(const TrackingWeights&) const = default;

  /// The model's probability for joint j with calibrated confidence `confidence` and cues `f`.
  float Probability(int joint, float confidence, const TrackingFeatures& f) const;
};

/// The tracking decision: its own weights give P(within 0.1 m), the joint's confidence.
struct TrackingModel : TrackingWeights {
  uint32_t samples = 0;  ///< validation joints behind the fit (informative)
  TrackingFit fit = TrackingFit::kGreedy;  ///< the skeleton fit whose choices it was fitted on
  /// The seen decision (format 1.8, optional section JSEE), fitted on the same samples:
  /// P(the camera sees the joint: it projects into the picture and lies at most 0.1 m (the head
  /// 0.15 m) behind the surface there), the renders' `visible`. With it a skeleton tracks a joint
  /// when it is likely *seen*, as Kinect's and Azure Kinect's trackers mean "tracked", and a
  /// found joint that is likely hidden is inferred; the confidence stays P(within 0.1 m). Absent
  /// (files before 1.8): tracked means P(within 0.1 m) reached the threshold.
  std::optional<TrackingWeights> seen;
  bool operator==(const TrackingModel&) const = default;
};

/// logit(c) with c clamped to [0.01, 0.99] (the model's first input).
float ClampedLogit(float confidence);

/// Finite weights of magnitude at most 1e3, the seen decision's too; `where` names the table in
/// errors.
Status ValidateTrackingModel(const TrackingModel& model, const std::string& where);

}  // namespace poseforest::core
