#include "runtime/core/tracking_model.h"

#include <algorithm>
#include <cmath>

namespace poseforest::core {

const char* TrackingFeatureName(int feature) {
  static const char* const kNames[kNumTrackingFeatures] = {
      "voted",           "agreed",          "proposal-vote gap", "has proposal", "has vote",
      "near cut edge",   "bone ok",         "bone impossible",   "parent logit", "children ok",
      "depth gap"};
  return feature >= 0 && feature < kNumTrackingFeatures ? kNames[feature] : "?";
}

const char* TrackingFitName(TrackingFit fit) {
  return fit == TrackingFit::kKinematic ? "kinematic" : "greedy";
}

float ClampedLogit(float confidence) {
  const float c = std::clamp(confidence, 0.01f, 0.99f);
  return std::log(c / (1.0f - c));
}

float TrackingWeights::Probability(int joint, float confidence, const TrackingFeatures& f) const {
  if (joint < 0 || joint >= kNumJoints) return 0.0f;
  double z = double(intercept[size_t(joint)]) + double(slope[size_t(joint)]) * ClampedLogit(confidence);
  for (int k = 0; k < kNumTrackingFeatures; ++k) z += double(shared[size_t(k)]) * double(f[size_t(k)]);
  return float(1.0 / (1.0 + std::exp(-z)));
}

namespace {

Status ValidateWeights(const TrackingWeights& model, const std::string& where) {
  auto ok = [](float v) { return std::isfinite(v) && std::abs(v) <= 1e3f; };
  for (int j = 0; j < kNumJoints; ++j)
    if (!ok(model.intercept[size_t(j)]) || !ok(model.slope[size_t(j)]))
      return Status(ErrorCode::kDataLoss, where + ": joint " + std::to_string(j) +
                                              " has a weight that is not finite or beyond 1e3");
  for (int k = 0; k < kNumTrackingFeatures; ++k)
    if (!ok(model.shared[size_t(k)]))
      return Status(ErrorCode::kDataLoss, where + ": cue '" + TrackingFeatureName(k) +
                                              "' has a weight that is not finite or beyond 1e3");
  return Status::Ok();
}

}  // namespace

Status ValidateTrackingModel(const TrackingModel& model, const std::string& where) {
  POSEFOREST_RETURN_IF_ERROR(ValidateWeights(model, where));
  if (model.seen) POSEFOREST_RETURN_IF_ERROR(ValidateWeights(*model.seen, where + ", its seen decision (JSEE)"));
  return Status::Ok();
}

}  // namespace poseforest::core
