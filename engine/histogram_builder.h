#pragma once
// The worker's hot loop: for a batch of frontier nodes, evaluate every candidate feature on
// every sample of the node once, drop the response into the candidate's threshold bins and
// count per (bin, part). Everything the coordinator needs to score every (theta, tau) of the
// node comes out of these counts by one prefix sum (engine/split_search.h).

#include <cstdint>
#include <span>
#include <vector>

#include "engine/candidates.h"
#include "engine/sample_set.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/feature.h"

namespace poseforest::engine {

/// What a worker needs to know about one frontier node (identical on every worker).
struct NodePlan {
  uint32_t node = 0;         ///< index in the tree's breadth-first node array (where the samples sit)
  uint64_t position = 0;     ///< heap position (candidates.h): keys every random draw of the node
  uint64_t num_samples = 0;  ///< samples of the node over all shards
  /// Compact "slot" of each part present in the node (kNumParts entries, 0xFF = absent);
  /// histograms only count present parts, which keeps deep nodes' histograms small.
  std::vector<uint8_t> part_slot;
  int num_slots = 0;
  std::vector<core::FeatureOffsets> features;  ///< candidates theta (DrawFeatures)
  std::vector<int32_t> cuts;                   ///< features.size() * cut_stride ascending cuts (DrawCuts)
  int cut_stride = 0;
  /// Per-sample form of the histogram (see NodeHistogram); set with UseSampleBins().
  bool sample_bins = false;

  /// Sets part_slot/num_slots from per-part counts (kNumParts entries).
  void SetParts(std::span<const uint64_t> part_counts);
  /// The histogram's shape: SetParts(part_counts), then its form for num_samples
  /// (UseSampleBins) and cut_stride (CutStride) for `thresholds_per_feature`. What every holder
  /// of a node's plan (the frontier loop, a worker's shard) sets before drawing cuts.
  void SetShape(std::span<const uint64_t> part_counts, int thresholds_per_feature);
};

/// Whether a node of `node_samples` samples (all shards) ships per-sample bins instead of dense
/// counts: true when that is smaller (n * (K + 1) bytes < K * bins * slots * 4 bytes). Deep
/// nodes hold a few dozen samples, and their dense histograms would be mostly zeros that cost
/// memory, zeroing, cache misses and (distributed) network traffic.
bool UseSampleBins(uint64_t node_samples, int thresholds_per_feature, int slots);

/// The histogram of one node, in one of two forms:
///  - dense: counts[(k * num_bins + bin) * num_slots + slot];
///  - sample bins (small nodes): for each of the node's samples its slot (sample_slot[i]) and
///    its bin under every candidate (sample_bin[i * num_candidates + k]).
/// bin = number of cuts strictly below the response (bin b goes left for every threshold
/// index >= b). Merging shards sums counts or concatenates samples; both are exact, and the
/// scores depend only on the counts, so the forest is the same however samples are sharded.
struct NodeHistogram {
  uint32_t node = 0;
  int num_candidates = 0;
  int num_bins = 0;   ///< thresholds_per_feature + 1 (<= 256)
  int num_slots = 0;  ///< parts present in the node
  bool sample_bins = false;
  std::vector<uint32_t> counts;      ///< dense form
  std::vector<uint8_t> sample_slot;  ///< sample-bins form
  std::vector<uint8_t> sample_bin;   ///< sample-bins form

  void Reset(uint32_t node_id, int candidates, int bins, int slots, bool per_sample = false);
  /// this += other (same shape); the merge of shards.
  void Add(const NodeHistogram& other);
  /// Dense counts of candidate k: num_bins * num_slots values into `out`.
  void CandidateCounts(int k, uint32_t* out) const;
  /// The dense form of this histogram (a copy, or the sample bins counted).
  NodeHistogram ToDense() const;
  /// this = parent - other: the sibling histogram by subtraction, valid when both were built
  /// with the same candidates and cuts (same shape, dense).
  void SetDifference(const NodeHistogram& parent, const NodeHistogram& other);
  uint64_t bytes() const { return counts.size() * sizeof(uint32_t) + sample_slot.size() + sample_bin.size(); }
  bool operator==(const NodeHistogram&) const = default;
};

/// Bytes of a node's dense histogram (to bound the memory of a batch before building it).
uint64_t HistogramBytes(int candidates, int thresholds_per_feature, int slots);
/// Bytes of the histogram `plan` will produce (either form).
uint64_t PlanHistogramBytes(const NodePlan& plan, int thresholds_per_feature);

class HistogramBuilder {
 public:
  /// `threads`: OpenMP threads (>= 1).
  HistogramBuilder(const core::FeatureConstants& constants, int threads);

  /// Pass 1: per plan, per candidate, min/max response over this shard's samples of the node
  /// that the node's ReferenceSelector picks. out[i] has plans[i].features.size() ranges.
  void ComputeRanges(const SampleSet& samples, const TrainParams& params, int tree,
                     std::span<const NodePlan> plans, std::vector<std::vector<ResponseRange>>* out);

  /// Pass 2: the histograms of this shard's samples. out[i] belongs to plans[i].
  void Build(const SampleSet& samples, std::span<const NodePlan> plans, int thresholds_per_feature,
             std::vector<NodeHistogram>* out);

  /// Whether `plan` can be built by BuildFused on this shard: the shard holds every sample of
  /// the node and the node's reference subsample is the whole node (num_samples <=
  /// threshold_reference_pixels), so this shard alone knows the merged ranges.
  static bool CanFuse(const SampleSet& samples, const TrainParams& params, const NodePlan& plan);

  /// Both passes in one for plans that CanFuse: each sample's responses are computed once, the
  /// ranges taken from them, plan.cuts = DrawCuts(ranges), and the responses binned. Results
  /// are identical to ComputeRanges + DrawCuts + Build (tested); deep levels, where most nodes
  /// are small, save one evaluation per sample and candidate.
  void BuildFused(const SampleSet& samples, const TrainParams& params, int tree, std::span<NodePlan> plans,
                  std::vector<NodeHistogram>* out);

  /// Candidate evaluations (sample x candidate) done by Build so far.
  uint64_t evaluations() const { return evaluations_; }

 private:
  core::FeatureConstants constants_;
  int threads_;
  uint64_t evaluations_ = 0;
};

}  // namespace poseforest::engine
