#pragma once
// Calibrated joint confidence (format 1.4, optional section JCAL). A joint proposal's raw
// confidence is a summed weight P * d^2 over the seed pixels reaching its mode (eq. 8): unbounded
// and in units that depend on the camera (pixels x m^2). Divided by fx * fy it becomes the
// proposal's *support*, a P-weighted surface area in m^2 that does not depend on the camera.
// `tune-joints` measures, on validation renders, how often a proposal of each joint with a given
// support lies within D = 0.1 m of the true joint (its precision), per bin of support; the
// skeleton's confidence is that precision, read off the table. Forests without a table (files
// before 1.4) get the documented fallback FallbackConfidence.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/result.h"

namespace poseforest::core {

struct ConfidenceCalibration {
  /// Which proposal method the table was measured with (the raw confidences differ).
  enum class Method : uint32_t { kMeanShift = 0, kFastClustering = 1 };
  Method method = Method::kMeanShift;
  /// Lower edges of the support bins, m^2, ascending, > 0 (the last bin is open above).
  std::vector<float> support_edges_m2;
  /// Per joint (core::Joint order), the precision of each bin, in [0, 1], non-decreasing in
  /// support (isotonic fit).
  std::array<std::vector<float>, kNumJoints> precision;
  /// Validation proposals behind the table (informative).
  uint32_t samples = 0;
  bool operator==(const ConfidenceCalibration&) const = default;

  /// Calibrated confidence in [0, 1] of joint j for a proposal of this support (m^2):
  /// piecewise linear in log(support) between the bins' geometric centres, constant beyond.
  float Confidence(int joint, float support_m2) const;
};

/// The support bins tune-joints uses: 24 edges, log-spaced from 1e-5 m^2 (a few pixels of a hand
/// at 3 m) to 0.1 m^2 (a torso).
std::vector<float> DefaultSupportEdges();

/// Without a calibration table (forests before format 1.4): 1 - exp(-support / 0.002 m^2), i.e.
/// 0.5 at ~14 cm^2 of P-weighted surface (a fist's area seen fully). A monotone squashing of
/// the raw confidence into 0..1, NOT a measured precision; `live` says which one it uses.
float FallbackConfidence(float support_m2);

/// Checks a table (sizes, ascending finite edges > 0, precisions in [0, 1]); `where` names it.
Status ValidateCalibration(const ConfidenceCalibration& c, const std::string& where);

}  // namespace poseforest::core
