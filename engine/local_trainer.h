#pragma once
// The single-process training engine: the coordinator's level-wise loop and N worker shards
// in one process. Shards are exactly what a distributed worker holds (its frames and
// samples); the coordinator only sees their range and histogram replies, summed, so the
// forest is byte-identical whatever the shard count and the thread count.

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// Reported once per finished level.
struct LevelProgress {
  int tree = 0;
  int level = 0;                 ///< depth of the frontier nodes (root = 0)
  size_t frontier_nodes = 0;     ///< nodes at this level
  size_t split_nodes = 0;        ///< of which became splits
  uint64_t samples = 0;          ///< samples in the frontier
  uint64_t evaluations = 0;      ///< sample x candidate evaluations of this level
  double evaluations_per_s = 0;  ///< evaluations / histogram-building seconds (all threads)
  double elapsed_s = 0;          ///< since Train() started
  uint64_t memory_bytes = 0;     ///< samples + frames + largest histogram batch so far
  /// Wall seconds of this level: since the previous level ended (or Train() started), less the
  /// tree's frame loading when it is the tree's first level.
  double level_seconds = 0;
};

struct LocalTrainerOptions {
  int num_shards = 1;                                  ///< worker shards the frames are spread over
  std::function<void(const LevelProgress&)> progress;  ///< optional
  std::function<void(const std::string&)> log;         ///< optional free-text messages
  /// Optional: the exact part counts of every leaf as it is made (tree, leaf index, kNumParts
  /// counts), before the file format quantizes them; used to measure the encoding's cost.
  std::function<void(int tree, uint32_t leaf, std::span<const uint64_t> counts)> leaf_counts;
};

struct TrainingStats {
  uint64_t evaluations = 0;      ///< total sample x candidate evaluations
  double histogram_seconds = 0;  ///< wall time in HistogramBuilder::Build
  double range_seconds = 0;      ///< wall time computing threshold ranges
  double load_seconds = 0;       ///< frame loading + sampling
  double total_seconds = 0;
  uint64_t peak_sample_bytes = 0;     ///< frames + per-sample arrays, all shards
  uint64_t peak_histogram_bytes = 0;  ///< histograms held at once
  uint64_t samples = 0;               ///< training samples, all trees
  int threads = 0;
};

class LocalTrainer {
 public:
  LocalTrainer(TrainParams params, LocalTrainerOptions options);

  /// Trains params.num_trees trees. Errors: frame loading failures (naming the frame).
  core::Result<core::Forest> Train();
  /// Trains tree `tree` alone (tree index keys its frames and random draws).
  core::Result<core::Tree> TrainTree(int tree);

  const TrainingStats& stats() const { return stats_; }

 private:
  /// Tree `tree`'s frames loaded and sampled into options_.num_shards shards (contiguous
  /// blocks of frame indices; frames without a body in view hold no samples and are left out).
  core::Status LoadShards(int tree, std::vector<SampleSet>* shards);

  TrainParams params_;
  LocalTrainerOptions options_;
  TrainingStats stats_;
  double start_ = 0;
  double level_mark_ = 0;  ///< where the next level's seconds count from
};

}  // namespace poseforest::engine
