#pragma once
// Training one node's whole subtree from the samples of that node alone: what a distributed
// worker does with a SubtreeTask (docs/distributed/service.md). It is the engine's frontier
// loop (engine/frontier_loop.h) over this one shard: the same to-split rule, candidates keyed
// by the node's heap position (candidates.h), fused or two-pass histograms, FindBestSplit and
// min_gain, so every decision equals the one the level-wise loop over all samples makes for
// the same node.

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "runtime/core/feature.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// One decided node of a subtree.
struct SubtreeNode {
  uint64_t position = 0;  ///< heap position in the tree (candidates.h)
  bool split = false;
  core::FeatureOffsets offsets;  ///< split only
  int32_t cut = 0;               ///< split only: tau = cut + 0.5 mm
  double gain = 0;               ///< split only: information gain, bits (statistics)
  std::vector<uint64_t> parts;   ///< kNumParts sample counts of the node (every node)
};

struct SubtreeOutput {
  /// Breadth-first order of the subtree (root first; children after their parent, left at the
  /// index TreeAssembler gives it): exactly the order `tree` lays the nodes out.
  std::vector<SubtreeNode> nodes;
  core::Tree tree;           ///< the subtree in the forest format's layout (root = node 0)
  uint64_t evaluations = 0;  ///< sample x candidate evaluations binned
};

/// Trains the subtree rooted at heap position `root_position` (depth PositionDepth of it) of
/// tree `tree`. Every sample of the root sits in node `root_sample_node` of `samples`; samples of
/// other nodes are ignored (ApplySplits drops them). `root_parts`: kNumParts counts of the root,
/// checked against the samples (InvalidArgument when they differ: the caller routed wrongly).
/// `between`, if set, is called between histogram batches and between levels, when neither
/// `samples` nor `builder` is in use (a worker answers the coordinator's rounds there instead of
/// after the whole subtree); it must not touch either.
core::Result<SubtreeOutput> TrainSubtree(SampleSet& samples, uint32_t root_sample_node,
                                         const TrainParams& params, int tree, uint64_t root_position,
                                         std::span<const uint64_t> root_parts, HistogramBuilder& builder,
                                         const std::function<void()>& between = {});

/// One root of TrainSubtrees.
struct SubtreeRoot {
  uint32_t sample_node = 0;  ///< where its samples sit in the SampleSet
  uint64_t position = 0;     ///< heap position in the tree (depth PositionDepth of it)
  std::vector<uint64_t> parts;  ///< kNumParts counts, checked against the samples
};

/// Several subtrees of tree `tree` trained together on one SampleSet (a worker's batch of
/// SubtreeTasks: one set of frames, histogram batches shared): outputs[r] is exactly
/// TrainSubtree's for roots[r] alone. Roots in increasing sample_node order; samples of other
/// nodes are ignored. InvalidArgument naming the root whose counts do not match its samples.
/// `between`: as for TrainSubtree.
core::Result<std::vector<SubtreeOutput>> TrainSubtrees(SampleSet& samples, std::span<const SubtreeRoot> roots,
                                                       const TrainParams& params, int tree,
                                                       HistogramBuilder& builder,
                                                       const std::function<void()>& between = {});

/// Checks a subtree received from elsewhere: nodes[0] is `root_position` with `root_parts`;
/// every split's children follow in TreeAssembler order at positions 2p + 1 / 2p + 2 with part
/// counts that sum to the parent's; no split beyond max_depth or below min_samples_split or
/// with fewer than two parts present; every node decided once. On success `*tree` (optional)
/// gets the subtree laid out as TreeAssembler does. InvalidArgument naming the first problem.
core::Status ValidateSubtree(std::span<const SubtreeNode> nodes, uint64_t root_position,
                             std::span<const uint64_t> root_parts, const TrainParams& params,
                             core::Tree* tree);

}  // namespace poseforest::engine
