#pragma once
// Split candidates of a node, derived from (job seed, tree, node position) alone so that every
// worker and the coordinator compute the same ones without exchanging them. The position is the
// node's heap index (NodePosition), not its breadth-first index in the file: it does not depend
// on how many nodes other subtrees grew, so one worker can train a subtree alone (SubtreeTask)
// and draw exactly the candidates the level-wise loop would. See
// docs/training/thresholds.md for why thresholds come from a hash-selected reference subsample.

#include <climits>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/job_spec.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/feature.h"
#include "runtime/core/rng.h"

namespace poseforest::engine {

/// CounterRng streams (the 4th key component) of the training draws.
inline constexpr uint64_t kFeatureStream = 1;
inline constexpr uint64_t kThresholdStream = 2;
inline constexpr uint64_t kReferenceStream = 3;
inline constexpr uint64_t kSamplingStream = 4;

/// Min and max feature response (mm) over a set of samples; lo > hi when the set is empty.
struct ResponseRange {
  int32_t lo = INT32_MAX;
  int32_t hi = INT32_MIN;
  void Add(int32_t f) {
    lo = f < lo ? f : lo;
    hi = f > hi ? f : hi;
  }
  void Merge(const ResponseRange& o) {
    lo = o.lo < lo ? o.lo : lo;
    hi = o.hi > hi ? o.hi : hi;
  }
  bool operator==(const ResponseRange&) const = default;
};

/// Thresholds are stored as integer cuts: tau = cut + 0.5 mm, so for the integer responses of
/// eq. 1, "f < tau" is "f <= cut". Cuts per candidate are padded with kNoCut to a power of two.
inline constexpr int32_t kNoCut = INT32_MAX;
/// Cut slots per candidate: thresholds_per_feature rounded up to a power of two.
int CutStride(int thresholds_per_feature);

/// Position id of a node: its heap index (root 0, children of p at 2p + 1 and 2p + 2). Depth is
/// at most 30 (TrainParams::max_depth), so positions stay below 2^31.
inline constexpr uint64_t kRootPosition = 0;
inline constexpr uint64_t LeftChildPosition(uint64_t p) { return 2 * p + 1; }
inline constexpr uint64_t RightChildPosition(uint64_t p) { return 2 * p + 2; }
inline constexpr uint64_t ParentPosition(uint64_t p) { return (p - 1) / 2; }
/// Depth of a position (root = 0).
inline constexpr int PositionDepth(uint64_t p) {
  int d = 0;
  for (; p > 0; p = ParentPosition(p)) ++d;
  return d;
}

/// The candidate features theta of the node at `position` in `tree`: u, v uniform in +-max
/// offset per coordinate, in offset units; with TrainParams::pixel_probe_share > 0, each feature
/// with that probability has v = 0 (its u drawn as before), so a share of 0 draws the paper's
/// features exactly as before the field existed.
std::vector<core::FeatureOffsets> DrawFeatures(const TrainParams& params, int tree, uint64_t position);

/// Whether a sample (by its global uid) belongs to the threshold reference subsample of a node
/// that holds `node_samples` samples in all shards: selected with probability
/// min(1, threshold_reference_pixels / node_samples) by a hash of (seed, tree, position, uid).
class ReferenceSelector {
 public:
  ReferenceSelector(const TrainParams& params, int tree, uint64_t position, uint64_t node_samples);
  bool Selected(uint64_t uid) const { return all_ || rng_.Bits(uid) < limit_; }
  /// True when every sample is selected (the node holds at most threshold_reference_pixels).
  bool all() const { return all_; }

 private:
  core::CounterRng rng_;
  uint64_t limit_ = 0;
  bool all_ = false;
};

/// Cuts of every candidate from the merged response ranges: thresholds_per_feature integers in
/// [lo, hi - 1] (so each tau separates lo from hi), stratified: cut j uniform in the j-th of
/// thresholds_per_feature equal parts of the range; ascending, duplicates dropped, padded
/// with kNoCut to CutStride. A candidate whose range is empty or constant gets no cuts.
/// Returns features.size() * CutStride values.
std::vector<int32_t> DrawCuts(const TrainParams& params, int tree, uint64_t position,
                              std::span<const ResponseRange> ranges);

}  // namespace poseforest::engine
