#include "runtime/core/confidence_calibration.h"

#include <algorithm>
#include <cmath>

namespace poseforest::core {

std::vector<float> DefaultSupportEdges() {
  std::vector<float> edges;
  const int n = 24;
  for (int i = 0; i < n; ++i) edges.push_back(float(std::pow(10.0, -5.0 + 4.0 * i / (n - 1))));
  return edges;
}

float FallbackConfidence(float support_m2) {
  if (!(support_m2 > 0)) return 0;
  return float(1.0 - std::exp(-double(support_m2) / 0.002));
}

float ConfidenceCalibration::Confidence(int joint, float support_m2) const {
  const auto& p = precision[size_t(joint)];
  const size_t n = support_edges_m2.size();
  if (n == 0 || p.size() != n) return FallbackConfidence(support_m2);
  if (!(support_m2 > 0)) return 0;
  // Bin centres: geometric mean of the edges; the last bin's centre one bin width above its edge.
  auto centre = [&](size_t k) {
    const double lo = std::log(double(support_edges_m2[k]));
    const double hi = k + 1 < n ? std::log(double(support_edges_m2[k + 1]))
                                : lo + (n > 1 ? lo - std::log(double(support_edges_m2[k - 1])) : 1.0);
    return 0.5 * (lo + hi);
  };
  const double x = std::log(double(support_m2));
  if (x <= centre(0)) return p[0];
  for (size_t k = 0; k + 1 < n; ++k) {
    const double a = centre(k), b = centre(k + 1);
    if (x <= b) return float(double(p[k]) + (double(p[k + 1]) - double(p[k])) * (x - a) / (b - a));
  }
  return p[n - 1];
}

Status ValidateCalibration(const ConfidenceCalibration& c, const std::string& where) {
  auto fail = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, where + ": " + what); };
  const size_t n = c.support_edges_m2.size();
  if (n < 1 || n > 256) return fail("confidence calibration has " + std::to_string(n) + " bins (1..256)");
  if (c.method != ConfidenceCalibration::Method::kMeanShift &&
      c.method != ConfidenceCalibration::Method::kFastClustering)
    return fail("confidence calibration: unknown proposal method " + std::to_string(uint32_t(c.method)));
  for (size_t k = 0; k < n; ++k) {
    const float e = c.support_edges_m2[k];
    if (!std::isfinite(e) || e <= 0 || (k > 0 && e <= c.support_edges_m2[k - 1]))
      return fail("confidence calibration: support edge " + std::to_string(k) + " (" + std::to_string(e) +
                  " m^2) is not finite, positive and ascending");
  }
  for (int j = 0; j < kNumJoints; ++j) {
    const auto& p = c.precision[size_t(j)];
    if (p.size() != n)
      return fail("confidence calibration: joint " + std::string(JointName(j)) + " has " +
                  std::to_string(p.size()) + " bins, expected " + std::to_string(n));
    for (float v : p)
      if (!std::isfinite(v) || v < 0 || v > 1)
        return fail("confidence calibration: joint " + std::string(JointName(j)) + ": precision " +
                    std::to_string(v) + " outside [0, 1]");
  }
  return Status::Ok();
}

}  // namespace poseforest::core
