#pragma once
// The level-wise frontier loop (Shotton et al. 2011, section 3.3), once: the single-process
// engine (LocalTrainer), a worker's subtree training (SubtreeTrainer) and the distributed
// coordinator all decide nodes here, over a ShardSet (shard_set.h), so the split rule (which
// nodes to try, candidates keyed by heap position, cuts from the merged ranges, FindBestSplit,
// min_gain) exists in one place and the forest is the same whoever holds the samples.

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "engine/job_spec.h"
#include "engine/shard_set.h"
#include "engine/split_search.h"
#include "runtime/core/feature.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// A node of the frontier.
struct OpenNode {
  uint32_t node = 0;            ///< where its samples sit in the shards (sample-node id)
  uint64_t position = 0;        ///< heap position: keys the node's random draws (candidates.h)
  int depth = 0;                ///< root = 0
  std::vector<uint64_t> parts;  ///< kNumParts counts over all shards
  uint32_t owner = 0;           ///< the caller's: which tree or subtree the node belongs to
  uint32_t local = 0;           ///< the caller's: the node's index in its owner's layout
  uint64_t total() const;
};

/// The rule for "try to split this node": above max_depth, at least min_samples_split samples,
/// at least two parts present.
bool WantsSplit(const TrainParams& params, int depth, std::span<const uint64_t> parts);

/// What the loop decided for one node.
struct NodeDecision {
  bool tried = false;               ///< WantsSplit held and its histogram was searched
  bool split = false;               ///< tried, a valid split found with gain >= min_gain
  SplitChoice choice;               ///< tried only
  core::FeatureOffsets offsets;     ///< split only: the chosen candidate
  uint64_t evaluations = 0;         ///< tried only: num_samples x candidates
};

/// Decides the nodes frontier[to_split[j]] (to_split increasing) at tree `tree`, level
/// `level`: batches bounded by `max_batch_bytes` of histogram memory, candidates drawn, pass 1
/// through `shards`, cuts drawn from the merged ranges, pass 2, FindBestSplit and min_gain,
/// each node independently. (*decisions)[i] (sized frontier.size()) is set for every i in
/// to_split. `after_batch` (optional) is told how many of to_split are decided so far and the
/// batch's histogram bytes.
core::Status DecideNodes(ShardSet& shards, const TrainParams& params, int tree, int level,
                         std::span<const OpenNode> frontier, std::span<const size_t> to_split,
                         uint64_t max_batch_bytes, std::vector<NodeDecision>* decisions,
                         const std::function<void(size_t decided, uint64_t batch_bytes)>& after_batch = {});

/// One finished level of RunFrontierLoop.
struct LevelDone {
  int level = 0;
  size_t frontier_nodes = 0;
  size_t split_nodes = 0;
  uint64_t samples = 0;            ///< in the frontier
  uint64_t max_batch_bytes = 0;    ///< largest histogram batch of the level
  std::span<const OpenNode> next;  ///< the next level's frontier
};

/// What a user of the loop adds around it. Only `place` is required. A hook's error ends the
/// loop with that error.
struct FrontierLoopHooks {
  /// Before a level's nodes are decided: may take nodes out of `to_split` (those decided
  /// elsewhere, e.g. a distributed coordinator's delegated subtrees), order kept.
  std::function<core::Status(int level, std::span<const OpenNode> frontier, std::vector<size_t>* to_split)>
      before_decide;
  /// After each batch: how many of to_split are decided so far, the batch's histogram bytes.
  std::function<void(size_t decided, uint64_t batch_bytes)> after_batch;
  /// After every node of to_split is decided, before any is placed.
  std::function<core::Status(int level)> after_decide;
  /// Called for every frontier node in frontier order once its level is decided: the caller
  /// lays it out (a leaf, or a split whose left child's index in the owner's layout it
  /// returns; the right child is left + 1; ignored for a leaf). A node taken out of to_split
  /// arrives untried; the caller may fill in the decision made elsewhere (split, offsets,
  /// choice.cut, choice.left_parts/right_parts), which the loop then follows.
  std::function<core::Result<uint32_t>(const OpenNode&, NodeDecision&)> place;
  /// After the level's splits are applied.
  std::function<core::Status(const LevelDone&)> level_done;
};

/// Grows `frontier` level by level until no node is left open: DecideNodes on every node that
/// WantsSplit, `place` in frontier order, children given sample-node ids next_node, next_node
/// + 1, ... in that order (left first), ApplySplits, next level. `first_level` is what the
/// shard set is told for the first level (counted up from there).
core::Status RunFrontierLoop(ShardSet& shards, const TrainParams& params, int tree, int first_level,
                             std::vector<OpenNode> frontier, uint32_t next_node, uint64_t max_batch_bytes,
                             const FrontierLoopHooks& hooks);

}  // namespace poseforest::engine
