#pragma once
// Subtree hand-off: small frontier nodes go to one worker each, whole (SubtreeTask), which
// trains the node's subtree from its samples alone while the histogram rounds of the other
// nodes run. The scheduler picks the nodes, asks the workers which frames hold their samples,
// balances the tasks over the workers, checks every SubtreeResult against its task (a result
// that does not fit gets its sender evicted for good) and hands the task of a lost worker to
// another one. Which worker trains a subtree never changes it: it depends on the node's samples
// alone.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "coordinator/level_records.h"
#include "coordinator/rounds.h"
#include "coordinator/session.h"
#include "coordinator/worker_registry.h"
#include "engine/frontier_loop.h"
#include "engine/subtree_trainer.h"
#include "poseforest/v1/wire.pb.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

/// A node handed to one worker whole (SubtreeTask), until its SubtreeResult is in.
struct SubtreeJob {
  uint32_t node = 0;  ///< breadth-first id
  uint64_t position = 0;
  std::vector<uint64_t> parts;
  std::vector<uint32_t> frames;  ///< tree-local frames holding its samples
  /// The samples themselves when every holder listed them (FRAMES round): per frame of
  /// `frames`, how many, and their delta-coded pixel indices (SubtreeTask.sample_*).
  std::vector<uint32_t> sample_counts, pixel_deltas;
  std::map<std::string, uint64_t> holders;  ///< worker -> samples of the node in its shard
  std::string worker;                       ///< who has it now
  uint64_t epoch = 0;                       ///< of the task sent to `worker`
  double sent = 0;
  bool done = false;
  std::vector<engine::SubtreeNode> nodes;  ///< the result
};

class SubtreeScheduler {
 public:
  SubtreeScheduler(Session& session, WorkerRegistry& registry, Rounds& rounds, LevelRecords& records);

  /// No task outstanding (a new tree).
  void Clear();

  /// A level starts: its subtree figures from zero.
  void BeginLevel() { level_subtree_evaluations_ = 0; }

  /// Hands off the small nodes among frontier[*to_split] of level `level` (`level_samples`:
  /// the frontier's samples) and sends their tasks; they leave *to_split. Returns how many.
  core::Result<size_t> HandOff(int level, std::span<const engine::OpenNode> frontier, uint64_t level_samples,
                               std::vector<size_t>* to_split);

  /// A SubtreeResult from `sender` (Pump): kept if it fits its task; stale or rejected if not.
  void OnSubtreeResult(const std::string& sender, const v1::SubtreeResult& res);

  bool has_tasks() const { return !tasks_.empty(); }

  /// Waits for every outstanding SubtreeTask's result, handing the task of a worker that is
  /// lost (or evicted, or silent past reply_timeout) to another one: same result, since the
  /// subtree depends on the node's samples alone.
  core::Status WaitSubtrees();

  /// The results' nodes into `delegated` (by heap position); no task outstanding after it.
  void TakeResults(std::map<uint64_t, engine::SubtreeNode>* delegated);

  uint64_t rejected() const { return subtree_rejected_; }
  // The level's figures (DistLevelStats' subtree_*).
  uint64_t level_evaluations() const { return level_subtree_evaluations_; }
  const std::map<std::string, uint64_t>& level_handed() const { return level_handed_; }
  uint64_t level_largest_task() const { return level_largest_task_; }
  uint64_t level_task_messages() const { return level_task_messages_; }

 private:
  /// A SubtreeResult that does not fit its task: dropped, counted, and its sender (if it is one
  /// of our workers) evicted for good; its task goes to another worker.
  void RejectSubtree(const std::string& sender, const std::string& why);
  /// Takes `job`'s samples off its worker's outstanding subtree load (done or handed on).
  void ReleaseLoad(const SubtreeJob& job);
  core::Status SendTask(SubtreeJob& job);
  core::Status FlushTasks();
  /// The nodes `ask` of `frontier` made tasks from the FRAMES round's replies (those with too
  /// many frames go to `keep` instead), then sent. Returns how many were handed off.
  core::Result<size_t> MakeTasks(std::span<const engine::OpenNode> frontier, const std::vector<size_t>& ask,
                                 const std::vector<Reply>& replies, uint64_t by_samples,
                                 std::vector<size_t>* keep);

  Session& s_;
  WorkerRegistry& registry_;
  Rounds& rounds_;
  LevelRecords& records_;
  std::map<uint64_t, SubtreeJob> tasks_;  ///< outstanding SubtreeTasks of this level, by position
  /// Samples of each worker's unfinished SubtreeTasks of this level (SendTask balances them).
  std::map<std::string, uint64_t> subtree_load_;
  std::map<std::string, uint64_t> level_handed_;  ///< samples of SubtreeTasks sent this level, per worker
  uint64_t level_largest_task_ = 0;               ///< samples of the largest SubtreeTask of this level
  /// SubtreeTasks chosen by SendTask, per worker, until FlushTasks sends them.
  std::map<std::string, std::vector<v1::SubtreeTask>> task_outbox_;
  uint64_t level_task_messages_ = 0;  ///< SubtreeTasks messages sent this level
  uint64_t subtree_rejected_ = 0;
  uint64_t level_subtree_evaluations_ = 0;
};

}  // namespace poseforest::coordinator
