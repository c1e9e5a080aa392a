#pragma once
// Shards held in this process: what a distributed worker holds (its frames and samples), N of
// them side by side (engine::Shard, shard.h), answering for all at once. The single-process
// engine uses N; a worker's subtree training uses its one SampleSet.

#include <span>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "engine/shard.h"
#include "engine/shard_set.h"

namespace poseforest::engine {

class LocalShardSet final : public ShardSet {
 public:
  /// `threads` (>= 1): OpenMP threads for routing samples and handing histograms to the sink.
  /// All references must outlive the shard set.
  LocalShardSet(std::span<SampleSet> shards, const TrainParams& params, HistogramBuilder& builder,
                int threads);

  core::Status CountParts(uint32_t node, std::vector<uint64_t>* parts) override;
  /// Ranges merged by min/max over shards (order-independent); a node whose samples all sit
  /// on one shard and whose reference subsample is the whole node is built there alone in one
  /// fused pass (the same histogram and cuts, half the evaluations).
  core::Status Ranges(int tree, int level, Batch* batch, const HistogramSink& sink) override;
  /// Histograms summed over shards (integer sums: order-independent).
  core::Status Histograms(int tree, int level, Batch* batch, std::span<const size_t> which,
                          const HistogramSink& sink) override;
  core::Status ApplySplits(std::span<const SampleSet::Split> splits) override;

  double range_seconds() const { return range_seconds_; }          ///< wall time of pass 1 ranges
  double histogram_seconds() const { return histogram_seconds_; }  ///< wall time building histograms

 private:
  /// sink(which[j], hists[j]) for every j, in parallel (nodes are independent).
  void Sink(std::span<const size_t> which, std::span<const NodeHistogram> hists,
            const HistogramSink& sink) const;

  std::vector<Shard> shards_;
  int threads_;
  double range_seconds_ = 0, histogram_seconds_ = 0;
};

}  // namespace poseforest::engine
