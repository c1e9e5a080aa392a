#include "engine/frontier_loop.h"

#include <algorithm>

#include "engine/candidates.h"
#include "runtime/core/body_parts.h"

namespace poseforest::engine {

using core::Status;

uint64_t OpenNode::total() const {
  uint64_t n = 0;
  for (uint64_t c : parts) n += c;
  return n;
}

bool WantsSplit(const TrainParams& params, int depth, std::span<const uint64_t> parts) {
  uint64_t n = 0;
  int present = 0;
  for (uint64_t c : parts) n += c, present += c > 0;
  return depth < params.max_depth && int64_t(n) >= params.min_samples_split && present > 1;
}

Status DecideNodes(ShardSet& shards, const TrainParams& params, int tree, int level,
                   std::span<const OpenNode> frontier, std::span<const size_t> to_split,
                   uint64_t max_batch_bytes, std::vector<NodeDecision>* decisions,
                   const std::function<void(size_t decided, uint64_t batch_bytes)>& after_batch) {
  const int t_count = params.thresholds_per_feature;
  for (size_t b0 = 0; b0 < to_split.size();) {
    // Batches bounded by histogram memory: the split choice is per node, so the batching does
    // not change any decision.
    Batch batch;
    size_t b1 = b0;
    while (b1 < to_split.size()) {
      const OpenNode& f = frontier[to_split[b1]];
      NodePlan plan;
      plan.node = f.node;
      plan.position = f.position;
      plan.num_samples = f.total();
      plan.SetShape(f.parts, t_count);
      plan.features.resize(size_t(params.candidate_features));  // sized for the byte count
      const uint64_t bytes = PlanHistogramBytes(plan, t_count);
      if (!batch.plans.empty() && batch.bytes + bytes > max_batch_bytes) break;
      batch.bytes += bytes;
      plan.features = DrawFeatures(params, tree, f.position);
      batch.plans.push_back(std::move(plan));
      batch.parts.emplace_back(f.parts);
      ++b1;
    }
    // Each node's decision depends on its own histogram alone (thread-safe per node).
    const HistogramSink decide = [&](size_t p, const NodeHistogram& hist) {
      const size_t fi = to_split[b0 + p];
      const NodePlan& plan = batch.plans[p];
      NodeDecision& d = (*decisions)[fi];
      d.tried = true;
      d.evaluations = plan.num_samples * uint64_t(plan.features.size());
      d.choice = FindBestSplit(hist, plan, frontier[fi].parts);
      d.split = d.choice.valid && d.choice.gain >= params.min_gain;
      if (d.split) d.offsets = plan.features[size_t(d.choice.candidate)];
    };
    POSEFOREST_RETURN_IF_ERROR(shards.Ranges(tree, level, &batch, decide));
    std::vector<size_t> rest;  // plans that need pass 2
    for (size_t p = 0; p < batch.plans.size(); ++p) {
      if (batch.fused[p]) continue;
      batch.plans[p].cuts = DrawCuts(params, tree, batch.plans[p].position, batch.ranges[p]);
      rest.push_back(p);
    }
    if (!rest.empty()) POSEFOREST_RETURN_IF_ERROR(shards.Histograms(tree, level, &batch, rest, decide));
    b0 = b1;
    if (after_batch) after_batch(b0, batch.bytes);
  }
  return Status::Ok();
}

Status RunFrontierLoop(ShardSet& shards, const TrainParams& params, int tree, int first_level,
                       std::vector<OpenNode> frontier, uint32_t next_node, uint64_t max_batch_bytes,
                       const FrontierLoopHooks& hooks) {
  for (int level = first_level; !frontier.empty(); ++level) {
    LevelDone done;
    done.level = level;
    done.frontier_nodes = frontier.size();
    std::vector<size_t> to_split;
    for (size_t i = 0; i < frontier.size(); ++i) {
      done.samples += frontier[i].total();
      if (WantsSplit(params, frontier[i].depth, frontier[i].parts)) to_split.push_back(i);
    }
    if (hooks.before_decide) POSEFOREST_RETURN_IF_ERROR(hooks.before_decide(level, frontier, &to_split));
    std::vector<NodeDecision> decisions(frontier.size());
    POSEFOREST_RETURN_IF_ERROR(DecideNodes(shards, params, tree, level, frontier, to_split, max_batch_bytes,
                                           &decisions, [&](size_t decided, uint64_t bytes) {
                                             done.max_batch_bytes = std::max(done.max_batch_bytes, bytes);
                                             if (hooks.after_batch) hooks.after_batch(decided, bytes);
                                           }));
    if (hooks.after_decide) POSEFOREST_RETURN_IF_ERROR(hooks.after_decide(level));
    // Children in frontier order: the breadth-first layout.
    std::vector<OpenNode> next;
    std::vector<SampleSet::Split> splits;
    for (size_t i = 0; i < frontier.size(); ++i) {
      const OpenNode& f = frontier[i];
      NodeDecision& d = decisions[i];
      const core::Result<uint32_t> placed = hooks.place(f, d);
      if (!placed.ok()) return placed.status();
      if (!d.split) continue;
      const uint32_t left = *placed;
      ++done.split_nodes;
      const uint32_t left_node = next_node;
      next_node += 2;
      splits.push_back({f.node, d.offsets, d.choice.cut, left_node});
      next.push_back({left_node, LeftChildPosition(f.position), f.depth + 1, std::move(d.choice.left_parts),
                      f.owner, left});
      next.push_back({left_node + 1, RightChildPosition(f.position), f.depth + 1,
                      std::move(d.choice.right_parts), f.owner, left + 1});
    }
    POSEFOREST_RETURN_IF_ERROR(shards.ApplySplits(splits));
    done.next = next;
    if (hooks.level_done) POSEFOREST_RETURN_IF_ERROR(hooks.level_done(done));
    frontier.swap(next);
  }
  return Status::Ok();
}

}  // namespace poseforest::engine
