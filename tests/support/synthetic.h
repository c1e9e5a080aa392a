#pragma once
// Synthetic inputs for tests and benchmarks: random but valid forests, and simple depth frames
// (a person-like figure made of capsules and ellipses, or noise). Not training data.

#include <cstdint>

#include "runtime/core/depth_image.h"
#include "runtime/core/forest.h"

namespace poseforest::testing {

struct RandomForestSpec {
  uint64_t seed = 1;
  int num_trees = 3;
  int max_depth = 20;
  int nodes_per_tree = 300000;     ///< target node count (splits + leaves), approximate
  int max_offset = 129;            ///< max |offset| in pixel*metres
  int num_parts = core::kNumParts;
  int max_parts_per_leaf = 4;      ///< leaves mix 1..this many parts
};

/// A random forest that passes core::ValidateForest. Trees are full near the root and thin out
/// with depth so that the node budget is spread over levels; every tree reaches max_depth.
core::Forest MakeRandomForest(const RandomForestSpec& spec);

/// Random but valid offset votes (format 1.5, JVOT) for `forest`'s trees: each leaf votes for a
/// random subset of the joints (about `votes_per_leaf` of them, some leaves none), offsets within
/// max_offset_m = 0.6 m, weights 1..255; bandwidths 0.05..0.08 m (0.05 + 0.002 * joint); a
/// 3-bin calibration (edges 0, 0.1, 0.3; precisions 0.2, 0.5, 0.9). Passes ValidateOffsetVotes.
core::OffsetVotes MakeRandomOffsetVotes(const core::Forest& forest, uint64_t seed, double votes_per_leaf = 3);

/// A 640x480 frame (by default) with one standing person-like figure about `distance_m` away,
/// arms out, ~40k foreground pixels at 2.5 m; background 0.
/// `lateral_m` / `vertical_m` move the figure right / down (metres, on its plane).
core::DepthImage MakePersonDepth(double distance_m = 2.5, int width = 640, int height = 480,
                                 double lateral_m = 0.0, double vertical_m = 0.0);

/// Random depth: blobs of random depth with holes (0), values in [min_mm, max_mm].
core::DepthImage MakeRandomDepth(uint64_t seed, int width, int height, uint16_t min_mm = 500,
                                 uint16_t max_mm = 6000);

}  // namespace poseforest::testing
