#pragma once
// Choosing a node's split from its merged histogram: Shannon information gain (eq. 3-6) of
// every (candidate, threshold) by one prefix sum over the threshold bins.

#include <cstdint>
#include <span>
#include <vector>

#include "engine/histogram_builder.h"

namespace poseforest::engine {

/// Shannon entropy in bits of a histogram of counts (0 for an empty one).
double Entropy(std::span<const uint64_t> counts);

/// Eq. 6 in bits: H(Q) - sum_s |Q_s|/|Q| H(Q_s), with Q = left + right per part.
double InformationGain(std::span<const uint64_t> left, std::span<const uint64_t> right);

/// The best split of one node.
struct SplitChoice {
  bool valid = false;  ///< false: no candidate separates anything
  int candidate = -1;  ///< index into the node's candidates
  int threshold = -1;  ///< index of the cut among the candidate's sorted cuts
  int32_t cut = 0;     ///< tau = cut + 0.5 mm
  double gain = 0;     ///< bits
  uint64_t num_left = 0, num_right = 0;
  std::vector<uint64_t> left_parts, right_parts;  ///< kNumParts entries each
};

/// Scores every (candidate, cut) of `hist` (built with `plan`'s cuts) and returns the one of
/// largest gain; ties go to the lower candidate index, then the lower threshold index, so the
/// choice depends on the counts alone. Only thresholds that put at least one sample on each
/// side count. `parent_parts` (kNumParts) are the node's part counts.
SplitChoice FindBestSplit(const NodeHistogram& hist, const NodePlan& plan,
                          std::span<const uint64_t> parent_parts);

/// Reference: the gain of every threshold computed directly from the definition (eq. 3-6)
/// for candidate k, one value per cut (NaN for padding or one-sided cuts). For tests.
std::vector<double> BruteForceGains(const NodeHistogram& hist, const NodePlan& plan, int k);

}  // namespace poseforest::engine
