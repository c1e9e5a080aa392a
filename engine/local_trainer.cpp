#include "engine/local_trainer.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <sstream>
#include <thread>

#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/sample_set.h"
#include "engine/split_search.h"
#include "engine/tree_assembler.h"

namespace poseforest::coordinator {

using core::Result;
using core::Status;
using worker::NodeHistogram;
using worker::NodePlan;
using worker::ResponseRange;
using worker::SampleSet;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// A frontier node as the coordinator knows it.
struct FrontierNode {
  uint32_t node;                ///< breadth-first index (the file's layout)
  uint64_t position;            ///< heap position: keys the node's random draws (candidates.h)
  std::vector<uint64_t> parts;  ///< kNumParts counts over all shards
  uint64_t total() const {
    uint64_t n = 0;
    for (uint64_t c : parts) n += c;
    return n;
  }
};

}  // namespace

LocalTrainer::LocalTrainer(worker::TrainParams params, LocalTrainerOptions options)
    : params_(std::move(params)), options_(std::move(options)) {
  options_.num_shards = std::max(1, options_.num_shards);
  stats_.threads = params_.threads > 0 ? params_.threads : omp_get_max_threads();
}

Result<core::Forest> LocalTrainer::Train() {
  start_ = Now();
  core::Forest forest;
  forest.constants = params_.constants;
  forest.num_parts = core::kNumParts;
  forest.part_names = core::Forest::DefaultPartNames();
  for (int t = 0; t < params_.num_trees; ++t) {
    auto tree = TrainTree(t);
    if (!tree.ok()) return tree.status();
    forest.trees.push_back(std::move(*tree));
  }
  stats_.total_seconds = Now() - start_;
  POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(forest, "trained forest"));
  return forest;
}

Result<core::Tree> LocalTrainer::TrainTree(int tree) {
  if (start_ == 0) start_ = Now();
  const int threads = stats_.threads;
  const int num_shards = options_.num_shards;
  const int ipt = params_.images_per_tree;

  // --- Frames and samples, spread over shards in contiguous blocks of frame indices. ---
  const double t_load = Now();
  std::vector<SampleSet> shards(static_cast<size_t>(num_shards));
  {
    // Plain threads, each with its own ImageSource created, used and destroyed on that thread
    // (a renderer's GL context is bound to one thread). Frame i goes to thread i % threads;
    // results land in per-frame slots, so the outcome does not depend on timing.
    std::vector<core::DepthImage> depth(static_cast<size_t>(ipt));
    std::vector<std::vector<worker::PixelSample>> picked(static_cast<size_t>(ipt));
    std::vector<Status> errors(static_cast<size_t>(threads));
    std::vector<std::thread> pool;
    for (int tid = 0; tid < threads; ++tid) {
      pool.emplace_back([&, tid] {
        try {
          auto source = worker::MakeImageSource(params_.source);
          if (!source.ok()) {
            errors[size_t(tid)] = source.status();
            return;
          }
          for (int i = tid; i < ipt; i += threads) {
            const uint64_t index = uint64_t(tree) * uint64_t(ipt) + uint64_t(i);
            auto frame = (*source)->Frame(index);
            if (!frame.ok()) {
              errors[size_t(tid)] = frame.status();
              return;
            }
            picked[size_t(i)] = worker::SamplePixels(
                *frame, params_.pixels_per_image, params_.part_balance,
                core::CounterRng(params_.seed, uint64_t(tree), index, worker::kSamplingStream));
            depth[size_t(i)] = std::move(frame->depth);
          }
        } catch (const std::exception& e) {
          errors[size_t(tid)] =
              Status(core::ErrorCode::kInternal, std::string("loading frames: ") + e.what());
        }
      });
    }
    for (auto& t : pool) t.join();
    for (const Status& e : errors)
      if (!e.ok()) return e;
    for (int i = 0; i < ipt; ++i) {
      if (picked[size_t(i)].empty()) continue;  // no body in view
      const auto shard = size_t(int64_t(i) * num_shards / ipt);
      shards[shard].AddFrame(uint64_t(i), std::move(depth[size_t(i)]), picked[size_t(i)], params_.constants);
      depth[size_t(i)] = {};
      picked[size_t(i)] = {};
    }
  }
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
  if (options_.log) {
    std::ostringstream m;
    m << "tree " << tree << ": " << num_samples << " samples from " << ipt << " frames in " << num_shards
      << " shard(s), " << (sample_bytes >> 20) << " MiB frames+samples, loaded in " << (Now() - t_load)
      << " s";
    options_.log(m.str());
  }

  // --- Level-wise growth. ---
  TreeAssembler assembler(core::kNumParts);
  std::vector<FrontierNode> frontier(1);
  frontier[0].node = 0;
  frontier[0].position = worker::kRootPosition;
  frontier[0].parts.assign(core::kNumParts, 0);
  for (auto& s : shards) {
    if (s.ranges().empty()) continue;
    std::vector<uint64_t> c(core::kNumParts);
    s.CountParts(s.ranges()[0], core::kNumParts, c.data());
    for (int p = 0; p < core::kNumParts; ++p) frontier[0].parts[size_t(p)] += c[size_t(p)];
  }
  worker::HistogramBuilder builder(params_.constants, threads);
  const int t_count = params_.thresholds_per_feature;
  const int cut_stride = worker::CutStride(t_count);

  for (int level = 0; !frontier.empty(); ++level) {
    const uint64_t evals_before = builder.evaluations();
    double level_hist_s = 0;
    uint64_t level_samples = 0;
    std::vector<FrontierNode> next;
    std::vector<SampleSet::Split> splits;
    // Which nodes are candidates for splitting at all.
    std::vector<size_t> to_split;
    for (size_t i = 0; i < frontier.size(); ++i) {
      const FrontierNode& f = frontier[i];
      const uint64_t n = f.total();
      level_samples += n;
      int present = 0;
      for (uint64_t c : f.parts) present += c > 0;
      if (level < params_.max_depth && int64_t(n) >= params_.min_samples_split && present > 1)
        to_split.push_back(i);
    }
    // Decisions are made in node order, batch by batch (batches bounded by histogram memory).
    std::vector<uint8_t> is_split(frontier.size(), 0);
    std::vector<SplitChoice> choices(frontier.size());
    std::vector<core::FeatureOffsets> chosen_offsets(frontier.size());
    for (size_t b0 = 0; b0 < to_split.size();) {
      std::vector<NodePlan> plans;
      uint64_t batch_bytes = 0;
      size_t b1 = b0;
      while (b1 < to_split.size()) {
        const FrontierNode& f = frontier[to_split[b1]];
        NodePlan plan;
        plan.node = f.node;
        plan.position = f.position;
        plan.num_samples = f.total();
        plan.SetParts(f.parts);
        plan.sample_bins = worker::UseSampleBins(plan.num_samples, t_count, plan.num_slots);
        plan.features.resize(size_t(params_.candidate_features));  // sized for the byte count
        const uint64_t bytes = worker::PlanHistogramBytes(plan, t_count);
        if (!plans.empty() && batch_bytes + bytes > params_.histogram_memory_bytes) break;
        batch_bytes += bytes;
        plan.features = worker::DrawFeatures(params_, tree, f.position);
        plan.cut_stride = cut_stride;
        plans.push_back(std::move(plan));
        ++b1;
      }
      // Nodes whose samples all sit on one shard and whose reference subsample is the whole
      // node are built by that shard alone in one fused pass (same result, half the
      // evaluations); a distributed coordinator knows this from the shards' sample counts.
      std::vector<int> fuse_shard(plans.size(), -1);
      std::vector<NodePlan> normal;
      std::vector<std::vector<NodePlan>> fused(shards.size());
      std::vector<std::pair<int, size_t>> where(plans.size());  // (-1 | shard, index in list)
      for (size_t p = 0; p < plans.size(); ++p) {
        for (size_t s = 0; s < shards.size() && fuse_shard[p] < 0; ++s)
          if (worker::HistogramBuilder::CanFuse(shards[s], params_, plans[p])) fuse_shard[p] = int(s);
        if (fuse_shard[p] < 0) {
          where[p] = {-1, normal.size()};
          normal.push_back(std::move(plans[p]));
        } else {
          where[p] = {fuse_shard[p], fused[size_t(fuse_shard[p])].size()};
          fused[size_t(fuse_shard[p])].push_back(std::move(plans[p]));
        }
      }
      // Pass 1: threshold ranges, merged over shards (min/max: order-independent).
      const double t_range = Now();
      if (!normal.empty()) {
        std::vector<std::vector<ResponseRange>> merged, part;
        for (size_t s = 0; s < shards.size(); ++s) {
          builder.ComputeRanges(shards[s], params_, tree, normal, s == 0 ? &merged : &part);
          if (s == 0) continue;
          for (size_t p = 0; p < normal.size(); ++p)
            for (size_t k = 0; k < merged[p].size(); ++k) merged[p][k].Merge(part[p][k]);
        }
        for (size_t p = 0; p < normal.size(); ++p)
          normal[p].cuts = worker::DrawCuts(params_, tree, normal[p].position, merged[p]);
      }
      stats_.range_seconds += Now() - t_range;
      // Pass 2: histograms, summed over shards (integer sums: order-independent).
      const double t_hist = Now();
      std::vector<NodeHistogram> normal_hists, shard_hists;
      if (!normal.empty()) {
        for (size_t s = 0; s < shards.size(); ++s) {
          builder.Build(shards[s], normal, t_count, s == 0 ? &normal_hists : &shard_hists);
          if (s == 0) continue;
          for (size_t p = 0; p < normal.size(); ++p) normal_hists[p].Add(shard_hists[p]);
        }
      }
      std::vector<std::vector<NodeHistogram>> fused_hists(shards.size());
      for (size_t s = 0; s < shards.size(); ++s)
        if (!fused[s].empty()) builder.BuildFused(shards[s], params_, tree, fused[s], &fused_hists[s]);
      // Back to node order.
      std::vector<NodeHistogram> hists(plans.size());
      for (size_t p = 0; p < plans.size(); ++p) {
        const auto [sh, i] = where[p];
        if (sh < 0) {
          plans[p] = std::move(normal[i]);
          hists[p] = std::move(normal_hists[i]);
        } else {
          plans[p] = std::move(fused[size_t(sh)][i]);
          hists[p] = std::move(fused_hists[size_t(sh)][i]);
        }
      }
      const double dt = Now() - t_hist;
      level_hist_s += dt;
      stats_.histogram_seconds += dt;
      stats_.peak_histogram_bytes =
          std::max(stats_.peak_histogram_bytes, batch_bytes * (shards.size() > 1 ? 2 : 1));
      // Split choice per node (independent: parallel, deterministic per node).
      const auto np = int64_t(plans.size());
      std::exception_ptr error;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
      for (int64_t p = 0; p < np; ++p) {
        try {
          const size_t fi = to_split[b0 + size_t(p)];
          choices[fi] = FindBestSplit(hists[size_t(p)], plans[size_t(p)], frontier[fi].parts);
          if (choices[fi].valid && choices[fi].gain >= params_.min_gain) {
            is_split[fi] = 1;
            chosen_offsets[fi] = plans[size_t(p)].features[size_t(choices[fi].candidate)];
          }
        } catch (...) {
#pragma omp critical(poseforest_local_trainer_error)
          if (!error) error = std::current_exception();
        }
      }
      if (error) std::rethrow_exception(error);
      b0 = b1;
    }
    // Allocate children in node order: breadth-first layout.
    size_t num_split = 0;
    for (size_t i = 0; i < frontier.size(); ++i) {
      const FrontierNode& f = frontier[i];
      if (!is_split[i]) {
        if (options_.leaf_counts) options_.leaf_counts(tree, assembler.num_leaves(), f.parts);
        assembler.MakeLeaf(f.node, f.parts);
        continue;
      }
      ++num_split;
      const SplitChoice& c = choices[i];
      const uint32_t left = assembler.MakeSplit(f.node, chosen_offsets[i], c.cut);
      splits.push_back({f.node, chosen_offsets[i], c.cut, left});
      next.push_back({left, worker::LeftChildPosition(f.position), c.left_parts});
      next.push_back({left + 1, worker::RightChildPosition(f.position), c.right_parts});
    }
    for (auto& s : shards) s.ApplySplits(splits, params_.constants, threads);
    if (options_.progress) {
      LevelProgress lp;
      lp.tree = tree;
      lp.level = level;
      lp.frontier_nodes = frontier.size();
      lp.split_nodes = num_split;
      lp.samples = level_samples;
      lp.evaluations = builder.evaluations() - evals_before;
      lp.evaluations_per_s = level_hist_s > 0 ? double(lp.evaluations) / level_hist_s : 0;
      lp.elapsed_s = Now() - start_;
      lp.memory_bytes = stats_.peak_sample_bytes + stats_.peak_histogram_bytes;
      options_.progress(lp);
    }
    frontier.swap(next);
  }
  stats_.evaluations += builder.evaluations();
  return assembler.Finish();
}

}  // namespace poseforest::coordinator
