#pragma once
// The frames of SubtreeTasks: a task's node has samples on other workers' shards, whose frames
// this worker renders (or loads) itself. Taken from the own shard's frames when they are there,
// else from the task-frame cache (frames of the tree rendered for earlier tasks, least recently
// used dropped first within WorkerOptions::task_cache_bytes), else rendered.

#include <atomic>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "engine/image_source.h"
#include "engine/shard.h"
#include "runtime/core/result.h"
#include "worker/context.h"

namespace poseforest::worker {

/// Frames of one tree rendered for SubtreeTasks, least recently used dropped first to stay
/// within `cap_bytes` (a frame larger than the cap is not kept).
struct TaskFrameCache {
  uint64_t cap_bytes = 0;
  int tree = -1;
  uint64_t bytes = 0, peak_bytes = 0, evictions = 0;

  void Clear(int new_tree);
  bool Has(uint64_t i) const { return frames_.count(i) > 0; }
  /// The frame (marked as used now), or nullptr.
  const engine::ShardFrame* Find(uint64_t i);
  void Put(uint64_t i, engine::ShardFrame f);

 private:
  std::map<uint64_t, std::pair<engine::ShardFrame, std::list<uint64_t>::iterator>> frames_;
  std::list<uint64_t> lru_;  ///< most recently used first
};

/// Where the frames of subtree tasks come from (see the top of this file). Run()'s thread only,
/// except the per-tree figures the heartbeat thread reads.
class TaskFrames {
 public:
  explicit TaskFrames(Context& ctx) : ctx_(ctx) {}

  /// A new job: the cache emptied and sized (logged), the render source dropped.
  void StartJob();

  /// The frames `wanted` (ascending) of tree `t`: from `own` (the shard's frames, when it holds
  /// tree t; else null) or the task cache, else rendered (into `*loaded`, parallel to
  /// `*missing`; Keep puts them in the task cache once done). `*src`: each wanted frame.
  core::Status Get(int t, const std::vector<uint64_t>& wanted, const std::map<uint64_t, engine::ShardFrame>* own,
                   std::vector<uint64_t>* missing, std::vector<engine::ShardFrame>* loaded,
                   std::vector<const engine::ShardFrame*>* src);
  /// Rendered task frames into the task cache (within its cap) for the tree's later tasks.
  void Keep(const std::vector<uint64_t>& missing, std::vector<engine::ShardFrame>& loaded);

  const TaskFrameCache& cache() const { return cache_; }
  /// Wall seconds spent rendering task frames since the last call (a SubtreeResult's
  /// render_micros).
  double TakeRenderSeconds() {
    const double s = render_unreported_s_;
    render_unreported_s_ = 0;
    return s;
  }

  /// Task frames of tree `tree` (the heartbeats' task_* fields, /metrics).
  std::atomic<uint32_t> tree{0};
  std::atomic<uint64_t> tree_rendered{0}, tree_cached{0}, tree_evictions{0};

 private:
  /// Frames `missing` of tree `t`: in parallel when they are many, else on this thread by
  /// source_ (made once per job: creating a source (renderer context, pose library, bodies)
  /// costs seconds).
  core::Status Render(int t, const std::vector<uint64_t>& missing, std::vector<engine::ShardFrame>* loaded);

  Context& ctx_;
  TaskFrameCache cache_;
  std::unique_ptr<engine::ImageSource> source_;
  uint64_t evictions_at_tree_start_ = 0;
  uint64_t evictions_counted_ = 0;  ///< cache_.evictions already in live.cache_evictions
  double render_unreported_s_ = 0;
};

}  // namespace poseforest::worker
