#pragma once
// One shard: the samples of some of a tree's frames and what the frontier loop asks of them
// (their census, the candidates' response ranges, fused nodes, histograms, routing down the
// splits), and the loading of its frames. The single-process engine holds N shards side by
// side (LocalShardSet), a distributed worker holds one and answers the coordinator's rounds
// through it (worker/shard_server.h, the replies in the wire codec's form), a subtree task
// holds one (subtree_trainer.h): one implementation of each operation, whoever holds it.

#include <cstdint>
#include <span>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// A frame as a shard keeps it for training: what features can read of its depth (no labels:
/// its sampled pixels carry their parts).
struct ShardFrame {
  CompactFrame frame;
  std::vector<PixelSample> picked;  ///< SamplePixels of the frame (empty: no body in view)
  uint64_t Bytes() const { return frame.Bytes() + picked.size() * sizeof(PixelSample); }
};

/// Tree-local frame `frame` of tree `tree` (job frame tree * images_per_tree + frame) from
/// `source`: its pixels sampled (keyed by the job seed, the tree and the frame, so the same
/// whoever loads it) and its depth compacted.
core::Result<ShardFrame> LoadFrame(ImageSource& source, const TrainParams& params, int tree, uint64_t frame);

/// LoadFrame of every tree-local frame of `frames` into (*out)[j], on up to `threads` plain
/// threads, each with its own ImageSource made, used and destroyed on that thread (a
/// renderer's GL context is bound to one thread); frame j goes to thread j % threads and lands
/// in its own slot, so the outcome does not depend on timing. `cpu_seconds` (optional): the
/// loading threads' CPU time is added to it. Errors: the first thread's failure (naming the
/// frame), exceptions caught.
core::Status LoadFrames(const TrainParams& params, int tree, std::span<const uint64_t> frames, int threads,
                        std::vector<ShardFrame>* out, double* cpu_seconds = nullptr);

/// The same on the calling thread with `source` (a few frames: no thread pool, and a source made
/// once serves many calls).
core::Status LoadFramesWith(ImageSource& source, const TrainParams& params, int tree,
                            std::span<const uint64_t> frames, std::vector<ShardFrame>* out);

/// One shard's operations on its samples. A view: the SampleSet, the parameters and the
/// histogram builder belong to the holder and must outlive the Shard.
class Shard {
 public:
  Shard(SampleSet& samples, const TrainParams& params, HistogramBuilder& builder)
      : samples_(&samples), params_(&params), builder_(&builder) {}

  SampleSet& samples() const { return *samples_; }

  /// The kNumParts part counts of node `node`'s samples here (zeros when it has none).
  std::vector<uint64_t> CountParts(uint32_t node) const;

  /// Whether this shard alone can build `plan` in one fused pass (HistogramBuilder::CanFuse:
  /// it holds every sample of the node and the reference subsample is the whole node).
  bool CanFuse(const NodePlan& plan) const;

  /// Pass 1: per plan, per candidate, the response range over this shard's reference samples.
  void Ranges(int tree, std::span<const NodePlan> plans, std::vector<std::vector<ResponseRange>>* out) const;

  /// Both passes at once for plans this shard CanFuse: their cuts drawn (plan.cuts), (*out)[i]
  /// the histogram of plans[i].
  void BuildFused(int tree, std::span<NodePlan> plans, std::vector<NodeHistogram>* out) const;

  /// Pass 2: the histograms of this shard's samples with the plans' cuts.
  void Histograms(std::span<const NodePlan> plans, std::vector<NodeHistogram>* out) const;

  /// Routes the samples of every split node to its children (SampleSet::ApplySplits).
  void ApplySplits(std::span<const SampleSet::Split> splits, int threads) const;

 private:
  SampleSet* samples_;
  const TrainParams* params_;
  HistogramBuilder* builder_;
};

/// Pass 1 of a batch of plans over some shards (a worker's one, LocalShardSet's N).
struct FirstPass {
  /// Per plan: 1 when one shard held all its samples and built it fused (its cuts set in the
  /// plan, its histogram in hists[p]); such a plan skips pass 2.
  std::vector<uint8_t> fused;
  /// Per plan not fused: the response range of every candidate merged over the shards (min/max:
  /// order-independent); empty for a fused plan.
  std::vector<std::vector<ResponseRange>> ranges;
  std::vector<NodeHistogram> hists;  ///< per plan: the fused histogram (empty when not fused)
  double range_seconds = 0;          ///< wall time computing ranges
  double fused_seconds = 0;          ///< wall time building fused histograms
};

/// Runs pass 1 of `plans` over `shards`: a plan that one shard CanFuse is built there fused,
/// every other plan gets its ranges from every shard. The plans are moved out while a shard
/// works on them and back.
void RunFirstPass(std::span<const Shard> shards, int tree, std::span<NodePlan> plans, FirstPass* out);

/// Pass 2 of `plans` over `shards`: each plan's histogram summed over the shards (integer sums:
/// order-independent) into (*out)[i].
void SumHistograms(std::span<const Shard> shards, std::span<const NodePlan> plans,
                   std::vector<NodeHistogram>* out);

}  // namespace poseforest::engine
