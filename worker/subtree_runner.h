#pragma once
// SubtreeTasks: a small node's whole subtree trained on this worker (engine/subtree_trainer.h)
// from the node's samples, which the task lists (or, without a list, every sample of its frames
// routed along the task's path), on frames from the shard, the task-frame cache or rendered
// (task_frame_cache.h); one SubtreeResult per task. Listed tasks of one tree that arrive
// together train as one batch (one SampleSet, one TrainSubtrees).

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/sample_set.h"
#include "engine/shard.h"
#include "engine/subtree_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/result.h"
#include "worker/context.h"
#include "worker/shard_server.h"
#include "worker/task_frame_cache.h"

namespace poseforest::worker {

class SubtreeRunner {
 public:
  /// `pause`: called between a task's histogram batches and levels (ServeRounds answers the
  /// shard's queued rounds there).
  SubtreeRunner(Context& ctx, const ShardServer& shard, TaskFrames& frames, std::function<void()> pause)
      : ctx_(ctx), shard_(shard), frames_(frames), pause_(std::move(pause)) {}

  /// A new job (ctx.params set): a new histogram builder, no frames kept.
  void StartJob();

  /// Whether a task lists its samples (SubtreeTask.sample_frames).
  static bool Listed(const v1::SubtreeTask& t) { return t.sample_frames_size() > 0; }

  /// Trains the subtree of a SubtreeTask and sends the SubtreeResult: the node's frames (from
  /// the shard's cache or the task cache, else rendered and then kept in the task cache), the
  /// node's samples (listed in the task, else every sample of the frames routed along the
  /// task's path), then TrainSubtree (the engine's own loop and keys).
  core::Status Run(const v1::SubtreeTask& task);

  /// SubtreeTasks of one tree that all list their samples, trained together: one SampleSet of
  /// the union of their frames (each frame copied once), the node of each task a root of
  /// TrainSubtrees (the same subtrees as one by one), one SubtreeResult each. A task that fails
  /// its checks is dropped (logged); if the batch as a whole fails, the tasks run one by one.
  void RunBatch(const std::vector<v1::Envelope>& batch, const std::string& sender);

  /// Wall seconds of rounds answered inside the current task or batch (not subtree work).
  void AddServedSeconds(double s) { served_in_batch_s_ += s; }

 private:
  /// Checks a SubtreeTask; `*wanted`: the tree-local frames it needs (its sample frames when it
  /// lists its samples, else its ranges' frames), ascending.
  core::Status Check(const v1::SubtreeTask& task, std::vector<uint64_t>* wanted) const;
  /// The frames `wanted` (`src`) of `task` into `set` with its samples: the listed ones, or
  /// every sampled pixel when it lists none.
  core::Status TaskSamples(const v1::SubtreeTask& task, const std::vector<uint64_t>& wanted,
                           const std::vector<const engine::ShardFrame*>& src, engine::SampleSet* set) const;
  /// The samples of a batch's `tasks` into task_set_ (frames `wanted`, `src`; `users[frame]`:
  /// which task lists samples there, at which entry), each at node = its task's index.
  core::Status BatchSamples(const std::vector<const v1::SubtreeTask*>& tasks, const std::vector<uint64_t>& wanted,
                            const std::vector<const engine::ShardFrame*>& src,
                            std::map<uint64_t, std::vector<std::pair<size_t, size_t>>>& users);
  /// Sends the SubtreeResult of `task` (+ the progress lines); t0: when the task started.
  core::Status SendResult(const v1::SubtreeTask& task, const engine::SubtreeOutput& out, double t0,
                          uint64_t num_samples, size_t num_frames, size_t rendered);
  /// The SubtreeResult of `task` (tampered with while corrupt_left_ > 0: tests' hostile worker).
  v1::Envelope ResultOf(const v1::SubtreeTask& task, const engine::SubtreeOutput& out);
  void Drop(const v1::SubtreeTask& task, const std::string& sender, const core::Status& st) const;

  Context& ctx_;
  const ShardServer& shard_;
  TaskFrames& frames_;
  std::function<void()> pause_;
  /// Subtree tasks' own builder: a round answered in the middle of a batch (ServeRounds) uses
  /// the shard's while the batch's TrainSubtrees counts its evaluations on this one.
  std::unique_ptr<engine::HistogramBuilder> builder_;
  /// The frames batches of SubtreeTasks of tree `task_set_tree_` trained on, each copied into
  /// the set's probe buffer once (not once per batch); its samples are a batch's. Dropped and
  /// started again when the tree changes or its frames would pass the task cache's cap.
  engine::SampleSet task_set_;
  int task_set_tree_ = -1;
  std::map<uint64_t, uint32_t> task_set_frames_;  ///< frame -> local id in task_set_
  int corrupt_left_ = 0;
  int log_tree_ = -1;  ///< progress lines of subtree tasks: tree, count, nodes, seconds
  uint64_t done_ = 0, nodes_done_ = 0;
  double busy_s_ = 0;      ///< wall seconds of subtree work of tree log_tree_
  double mark_ = 0;        ///< when the last SubtreeResult was built (SendResult)
  double served_in_batch_s_ = 0;
};

}  // namespace poseforest::worker
