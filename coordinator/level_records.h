#pragma once
// The record of the tree being grown, level by level: its layout (a TreeAssembler), every
// split by heap position (the paths of SubtreeTasks), the SplitDecisions sent to the workers
// (replayed after every new assignment), the decisions logged for the checkpoint, and the
// decided nodes of delegated subtrees not placed yet. Place lays out one decided frontier node
// in all of them at once, so the forest, the workers' routing and the checkpoint cannot
// disagree.

#include <cstdint>
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "engine/frontier_loop.h"
#include "engine/subtree_trainer.h"
#include "engine/tree_assembler.h"
#include "poseforest/v1/checkpoint.pb.h"
#include "poseforest/v1/wire.pb.h"
#include "runtime/core/feature.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

engine::SubtreeNode FromProto(const v1::SubtreeNode& n);
void ToProto(const engine::SubtreeNode& n, v1::SubtreeNode* o);

/// Replays a logged tree's levels into `assembler`; errors if the log is inconsistent.
core::Status ReplayLoggedTree(const v1::LoggedTree& log, engine::TreeAssembler* assembler);

/// What the level's hooks add up for DistLevelStats (reset when a level starts).
struct LevelFigures {
  double t_level = 0;        ///< when the level started
  uint64_t evaluations = 0;  ///< sample x candidate evaluations, subtree tasks' included
  uint64_t samples = 0;      ///< in the frontier
  size_t handed_off = 0;     ///< nodes handed off as SubtreeTasks
  size_t from_subtrees = 0;  ///< nodes decided by SubtreeResults
  size_t frontier_size = 0;
  size_t histogram_nodes = 0;  ///< nodes decided by the histogram rounds
  double entropy_sum = 0, gain_sum = 0;
};

class LevelRecords {
 public:
  using SplitAt = std::pair<core::FeatureOffsets, int32_t>;

  /// Tree `tree` starts: the SplitDecisions of its levels logged in `log` (a resumed tree;
  /// empty for a fresh one) rebuilt for the workers' replays.
  void RestoreDecisions(int tree, const v1::LoggedTree& log);
  /// The layout of the tree in `ckpt.current()` replayed, its splits and the pending nodes of
  /// its delegated subtrees restored (nothing for a fresh tree).
  core::Status BeginTree(const v1::Checkpoint& ckpt);
  /// The tree laid out.
  core::Tree FinishTree();
  uint32_t num_nodes() const { return uint32_t(assembler_->num_nodes()); }

  /// A level's decisions start: the SplitDecisions for the workers, the log in `logged`.
  void BeginLevel(int tree, int level, v1::LoggedLevel* logged);
  /// The level's SplitDecisions as an envelope (sent by the shard set's ApplySplits).
  v1::Envelope* level_decisions() { return &env_; }
  /// `dec` was sent to the workers: kept for the replays of later assignments.
  void AddSent(const v1::SplitDecisions& dec) { tree_decisions_.push_back(dec); }
  const std::vector<v1::SplitDecisions>& tree_decisions() const { return tree_decisions_; }

  /// Lays out frontier node `f` (leaf or split; a delegated node as its SubtreeResult decided,
  /// filling `d` so the loop follows it), logs it, and adds to `figures`. Returns the left
  /// child's index for a split (0 for a leaf).
  core::Result<uint32_t> Place(const engine::OpenNode& f, engine::NodeDecision& d, LevelFigures* figures);

  /// The split at heap position `position`, or null.
  const SplitAt* SplitAtPosition(uint64_t position) const;
  /// Decided nodes of delegated subtrees not placed in the tree yet, by heap position.
  std::map<uint64_t, engine::SubtreeNode>& delegated() { return delegated_; }

 private:
  std::unique_ptr<engine::TreeAssembler> assembler_;
  std::vector<v1::SplitDecisions> tree_decisions_;  ///< per decided level, for replays
  /// Every split of the current tree by heap position (the paths of SubtreeTasks).
  std::map<uint64_t, SplitAt> split_of_;
  std::map<uint64_t, engine::SubtreeNode> delegated_;
  v1::Envelope env_;                    ///< the level's SplitDecisions
  v1::LoggedLevel* logged_ = nullptr;  ///< the level's log (in the checkpoint)
};

}  // namespace poseforest::coordinator
