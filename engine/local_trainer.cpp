#include "engine/local_trainer.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <sstream>
#include <thread>

#include "engine/candidates.h"
#include "engine/frontier_loop.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/local_shard_set.h"
#include "engine/sample_set.h"
#include "engine/shard.h"
#include "engine/split_search.h"
#include "engine/tree_assembler.h"

namespace poseforest::engine {

using core::Result;
using core::Status;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

LocalTrainer::LocalTrainer(TrainParams params, LocalTrainerOptions options)
    : params_(std::move(params)), options_(std::move(options)) {
  options_.num_shards = std::max(1, options_.num_shards);
  stats_.threads = params_.threads > 0 ? params_.threads : omp_get_max_threads();
}

Result<core::Forest> LocalTrainer::Train() {
  start_ = level_mark_ = Now();
  auto shell = EmptyForest(params_);
  if (!shell.ok()) return shell.status();
  core::Forest forest = std::move(*shell);
  for (int t = 0; t < params_.num_trees; ++t) {
    auto tree = TrainTree(t);
    if (!tree.ok()) return tree.status();
    forest.trees.push_back(std::move(*tree));
  }
  stats_.total_seconds = Now() - start_;
  POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(forest, "trained forest"));
  return forest;
}

Status LocalTrainer::LoadShards(int tree, std::vector<SampleSet>* shards) {
  const int num_shards = options_.num_shards;
  const int ipt = params_.images_per_tree;
  shards->assign(static_cast<size_t>(num_shards), SampleSet{});
  // Every frame of the tree, loaded in parallel (engine::LoadFrames: compacted and sampled
  // frame by frame, in per-frame slots), then spread over shards in contiguous blocks of frame
  // indices.
  std::vector<uint64_t> indices(static_cast<size_t>(ipt));
  for (int i = 0; i < ipt; ++i) indices[size_t(i)] = uint64_t(i);
  std::vector<ShardFrame> frames;
  POSEFOREST_RETURN_IF_ERROR(LoadFrames(params_, tree, indices, stats_.threads, &frames));
  // Exact room first: a grown vector's slack would cost up to as much as its contents.
  struct Room {
    size_t frames = 0, pixels = 0, samples = 0, rows = 0;
  };
  std::vector<Room> room(static_cast<size_t>(num_shards));
  for (int i = 0; i < ipt; ++i) {
    if (frames[size_t(i)].picked.empty()) continue;  // no body in view
    Room& r = room[size_t(int64_t(i) * num_shards / ipt)];
    ++r.frames;
    r.pixels += frames[size_t(i)].frame.pixels.size();
    r.rows += frames[size_t(i)].frame.rows.size();
    r.samples += frames[size_t(i)].picked.size();
  }
  for (size_t k = 0; k < shards->size(); ++k)
    (*shards)[k].Reserve(room[k].frames, room[k].pixels, room[k].samples, room[k].rows);
  for (int i = 0; i < ipt; ++i) {
    if (frames[size_t(i)].picked.empty()) continue;  // no body in view
    const auto shard = size_t(int64_t(i) * num_shards / ipt);
    (*shards)[shard].AddFrame(uint64_t(i), frames[size_t(i)].frame, frames[size_t(i)].picked, params_.constants);
    frames[size_t(i)] = {};
  }
  return Status::Ok();
}

Result<core::Tree> LocalTrainer::TrainTree(int tree) {
  if (start_ == 0) start_ = level_mark_ = Now();
  const int threads = stats_.threads;
  const int num_shards = options_.num_shards;
  const int ipt = params_.images_per_tree;

  // --- Frames and samples, spread over shards in contiguous blocks of frame indices. ---
  const double t_load = Now();
  std::vector<SampleSet> shards;
  POSEFOREST_RETURN_IF_ERROR(LoadShards(tree, &shards));
  uint64_t sample_bytes = 0, num_samples = 0;
  for (auto& s : shards) {
    s.StartTree(0);
    sample_bytes += s.MemoryBytes();
    num_samples += s.num_samples();
  }
  if (num_samples == 0)
    return Status(core::ErrorCode::kInvalidArgument,
                  "tree " + std::to_string(tree) + ": no body pixels in any of its " + std::to_string(ipt) +
                      " frames (labels must be part indices 0..30 on depth > 0)");
  stats_.samples += num_samples;
  stats_.peak_sample_bytes = std::max(stats_.peak_sample_bytes, sample_bytes);
  stats_.load_seconds += Now() - t_load;
  level_mark_ += Now() - t_load;  // frame loading is not part of the first level
  if (options_.log) {
    std::ostringstream m;
    m << "tree " << tree << ": " << num_samples << " samples from " << ipt << " frames in " << num_shards
      << " shard(s), " << (sample_bytes >> 20) << " MiB frames+samples ("
      << sample_bytes / uint64_t(std::max(1, ipt)) << " bytes per image), loaded in " << (Now() - t_load)
      << " s";
    options_.log(m.str());
  }

  // --- Level-wise growth: the frontier loop over the shards held here. ---
  HistogramBuilder builder(params_.constants, threads);
  LocalShardSet shard_set(shards, params_, builder, threads);
  std::vector<OpenNode> frontier(1);
  frontier[0].node = 0;
  frontier[0].position = kRootPosition;
  POSEFOREST_RETURN_IF_ERROR(shard_set.CountParts(0, &frontier[0].parts));
  TreeAssembler assembler(core::kNumParts);
  FrontierLoopHooks hooks;
  // One tree: a node's sample-node id is its breadth-first index, the assembler's.
  hooks.place = [&](const OpenNode& f, NodeDecision& d) -> Result<uint32_t> {
    POSEFOREST_CHECK(f.node == f.local);
    if (!d.split) {
      if (options_.leaf_counts) options_.leaf_counts(tree, assembler.num_leaves(), f.parts);
      assembler.MakeLeaf(f.node, f.parts);
      return uint32_t(0);
    }
    return assembler.MakeSplit(f.node, d.offsets, d.choice.cut);
  };
  uint64_t evals_before = builder.evaluations();
  double hist_before = shard_set.histogram_seconds();
  hooks.level_done = [&](const LevelDone& done) -> Status {
    stats_.peak_histogram_bytes =
        std::max(stats_.peak_histogram_bytes, done.max_batch_bytes * (shards.size() > 1 ? 2 : 1));
    const double level_hist_s = shard_set.histogram_seconds() - hist_before;
    const double now = Now();
    if (options_.progress) {
      LevelProgress lp;
      lp.tree = tree;
      lp.level = done.level;
      lp.frontier_nodes = done.frontier_nodes;
      lp.split_nodes = done.split_nodes;
      lp.samples = done.samples;
      lp.evaluations = builder.evaluations() - evals_before;
      lp.evaluations_per_s = level_hist_s > 0 ? double(lp.evaluations) / level_hist_s : 0;
      lp.elapsed_s = now - start_;
      lp.level_seconds = now - level_mark_;
      lp.memory_bytes = stats_.peak_sample_bytes + stats_.peak_histogram_bytes;
      options_.progress(lp);
    }
    evals_before = builder.evaluations();
    hist_before = shard_set.histogram_seconds();
    level_mark_ = now;
    return Status::Ok();
  };
  POSEFOREST_RETURN_IF_ERROR(RunFrontierLoop(shard_set, params_, tree, 0, std::move(frontier), 1,
                                             params_.histogram_memory_bytes, hooks));
  stats_.range_seconds += shard_set.range_seconds();  // the shard set is this tree's
  stats_.histogram_seconds += shard_set.histogram_seconds();
  stats_.evaluations += builder.evaluations();
  return assembler.Finish();
}

}  // namespace poseforest::engine
