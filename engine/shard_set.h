#pragma once
// What the frontier loop asks of the samples, wherever they are: the shard-set interface.
// A shard set answers for all its shards at once (merged ranges, summed histograms), so the
// loop never sees how many shards there are or where they run. LocalShardSet holds them in
// this process (local_shard_set.h); the coordinator's remote shard set asks its workers over
// DDS. Both only transport and merge: every decision is the loop's (frontier_loop.h).

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/sample_set.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// One batch of frontier nodes whose histograms are built together (bounded by histogram
/// memory; the batching changes no decision).
struct Batch {
  std::vector<NodePlan> plans;                   ///< features drawn; cuts set by pass 1 (fused) or the loop
  std::vector<std::span<const uint64_t>> parts;  ///< kNumParts counts of each plan's node
  /// Pass 1's answer per plan: the response range of every candidate merged over all shards
  /// (empty for a fused plan).
  std::vector<std::vector<ResponseRange>> ranges;
  /// Pass 1's answer per plan: 1 when one shard held all its samples and built it fused
  /// (cuts and histogram at once); such a plan skips pass 2.
  std::vector<uint8_t> fused;
  uint64_t bytes = 0;  ///< histogram bytes of the batch (PlanHistogramBytes summed)
};

/// Receives plan `p`'s histogram, complete over all shards and built with plans[p].cuts. Called
/// once per plan; may be called from several threads at once for different plans.
using HistogramSink = std::function<void(size_t p, const NodeHistogram& hist)>;

class ShardSet {
 public:
  virtual ~ShardSet() = default;

  /// The kNumParts part counts of node `node`'s samples over all shards (the census).
  virtual core::Status CountParts(uint32_t node, std::vector<uint64_t>* parts) = 0;

  /// Pass 1 of a batch at tree `tree`, level `level`: fills batch->ranges and batch->fused; a
  /// fused plan gets its cuts and goes to `sink` here.
  virtual core::Status Ranges(int tree, int level, Batch* batch, const HistogramSink& sink) = 0;

  /// Pass 2: the histograms of the plans `which` (not fused; cuts drawn from their ranges),
  /// summed over shards, each to `sink`.
  /// The plans stay in *batch (a shard set may move them out while it works and back).
  virtual core::Status Histograms(int tree, int level, Batch* batch, std::span<const size_t> which,
                                  const HistogramSink& sink) = 0;

  /// Routes the samples of every split node to its children (Split::left and left + 1);
  /// samples of nodes not split stay where they are.
  virtual core::Status ApplySplits(std::span<const SampleSet::Split> splits) = 0;
};

}  // namespace poseforest::engine
