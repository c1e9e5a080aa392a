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

struct TrackingModel {
  std::array<float, kNumJoints> intercept{};  ///< a_j
  std::array<float, kNumJoints> slope{};      ///< b_j, on logit(calibrated confidence)
  std::array<float, kNumTrackingFeatures> shared{};  ///< w
  uint32_t samples = 0;  ///< validation joints behind the fit (informative)
  TrackingFit fit = TrackingFit::kGreedy;  ///< the skeleton fit whose choices it was fitted on
  bool operator==(const TrackingModel&) const = default;

  /// P(within 0.1 m) of joint j with calibrated confidence `confidence` and cues `f`.
  float Probability(int joint, float confidence, const TrackingFeatures& f) const;
};

/// logit(c) with c clamped to [0.01, 0.99] (the model's first input).
float ClampedLogit(float confidence);

/// Finite weights of magnitude at most 1e3; `where` names the table in errors.
Status ValidateTrackingModel(const TrackingModel& model, const std::string& where);

}  // namespace poseforest::core
