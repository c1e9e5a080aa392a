#pragma once
// The workers' shards as the frontier loop sees them (engine/shard_set.h): each pass is one
// request/reply Round over the assigned workers (lost workers' frames handed on, the round
// asked again), the replies merged here. Nothing is decided here: the loop
// (engine/frontier_loop.h) does that.

#include <cstdint>
#include <span>
#include <vector>

#include "coordinator/level_records.h"
#include "coordinator/rounds.h"
#include "coordinator/session.h"
#include "coordinator/worker_registry.h"
#include "engine/shard_set.h"
#include "poseforest/v1/wire.pb.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

class RemoteShardSet final : public engine::ShardSet {
 public:
  /// `merge_threads`: OpenMP threads for summing histograms.
  RemoteShardSet(Session& session, WorkerRegistry& registry, Rounds& rounds, LevelRecords& records,
                 int merge_threads);

  /// The root's census (a COUNTS round); only node 0.
  core::Status CountParts(uint32_t node, std::vector<uint64_t>* parts) override;
  core::Status Ranges(int tree, int level, engine::Batch* batch, const engine::HistogramSink& sink) override;
  core::Status Histograms(int tree, int level, engine::Batch* batch, std::span<const size_t> which,
                          const engine::HistogramSink& sink) override;
  /// Sends `decisions` (the level's, LevelRecords') to every worker.
  core::Status ApplySplits(std::span<const engine::SampleSet::Split> splits) override;

  /// Set by the coordinator while it places a level's nodes: the decisions ApplySplits sends.
  v1::Envelope* decisions = nullptr;

  /// Seconds of the current level: in the rounds (and waiting for subtree results), merging.
  double hist_seconds() const { return hist_s_; }
  double merge_seconds() const { return merge_s_; }
  void AddWait(double seconds) { hist_s_ += seconds; }
  /// A level starts: both from zero.
  void ResetTimes() { hist_s_ = merge_s_ = 0; }

 private:
  Session& s_;
  WorkerRegistry& registry_;
  Rounds& rounds_;
  LevelRecords& records_;
  int merge_threads_;
  double hist_s_ = 0, merge_s_ = 0;  ///< of the current level: rounds, merging
};

}  // namespace poseforest::coordinator
