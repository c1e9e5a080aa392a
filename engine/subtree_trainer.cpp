#include "engine/subtree_trainer.h"

#include <cmath>
#include <string>

#include "engine/candidates.h"
#include "engine/split_search.h"
#include "engine/tree_assembler.h"
#include "runtime/core/body_parts.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

uint64_t Total(std::span<const uint64_t> parts) {
  uint64_t n = 0;
  for (uint64_t c : parts) n += c;
  return n;
}

/// LocalTrainer's rule for "try to split this node".
bool WantsSplit(const worker::TrainParams& params, int depth, std::span<const uint64_t> parts) {
  int present = 0;
  for (uint64_t c : parts) present += c > 0;
  return depth < params.max_depth && int64_t(Total(parts)) >= params.min_samples_split && present > 1;
}

struct Open {
  uint32_t sample_node;  ///< where its samples sit in the SampleSet
  uint32_t local;        ///< index in its root's subtree (TreeAssembler)
  uint64_t position;
  std::vector<uint64_t> parts;
  size_t root;  ///< index in the roots
  int depth;
};

}  // namespace

Result<SubtreeOutput> TrainSubtree(worker::SampleSet& samples, uint32_t root_sample_node,
                                   const worker::TrainParams& params, int tree, uint64_t root_position,
                                   std::span<const uint64_t> root_parts, worker::HistogramBuilder& builder) {
  if (root_parts.size() != size_t(core::kNumParts))
    return Status(ErrorCode::kInvalidArgument, "subtree root: part counts of the wrong length");
  const SubtreeRoot root{root_sample_node, root_position, {root_parts.begin(), root_parts.end()}};
  auto out = TrainSubtrees(samples, std::span<const SubtreeRoot>(&root, 1), params, tree, builder);
  if (!out.ok()) return out.status();
  return std::move((*out)[0]);
}

Result<std::vector<SubtreeOutput>> TrainSubtrees(worker::SampleSet& samples, std::span<const SubtreeRoot> roots,
                                                 const worker::TrainParams& params, int tree,
                                                 worker::HistogramBuilder& builder) {
  uint32_t next_sample_node = 0;  // children get fresh sample node ids, increasing in frontier order
  std::vector<Open> frontier;
  for (size_t r = 0; r < roots.size(); ++r) {
    const SubtreeRoot& root = roots[r];
    if (root.parts.size() != size_t(core::kNumParts))
      return Status(ErrorCode::kInvalidArgument, "subtree root: part counts of the wrong length");
    if (r > 0 && root.sample_node <= roots[r - 1].sample_node)
      return Status(ErrorCode::kInternal, "subtree roots out of sample-node order");
    std::vector<uint64_t> have(static_cast<size_t>(core::kNumParts), 0);
    const worker::NodeRange range = samples.RangeOf(root.sample_node);
    if (range.end > range.begin) samples.CountParts(range, core::kNumParts, have.data());
    if (!std::equal(have.begin(), have.end(), root.parts.begin()))
      return Status(ErrorCode::kInvalidArgument, "subtree at position " + std::to_string(root.position) + ": " +
                                                     std::to_string(range.end - range.begin) +
                                                     " samples routed here, the coordinator counts " +
                                                     std::to_string(Total(root.parts)));
    frontier.push_back({root.sample_node, 0, root.position, root.parts, r, worker::PositionDepth(root.position)});
    next_sample_node = std::max(next_sample_node, root.sample_node + 1);
  }
  for (const worker::NodeRange& range : samples.ranges())
    next_sample_node = std::max(next_sample_node, range.node + 1);
  std::vector<SubtreeOutput> out(roots.size());
  const uint64_t evals_before = builder.evaluations();
  std::vector<TreeAssembler> assemblers(roots.size(), TreeAssembler(core::kNumParts));
  const int t_count = params.thresholds_per_feature;
  const int cut_stride = worker::CutStride(t_count);
  while (!frontier.empty()) {
    std::vector<size_t> to_split;
    for (size_t i = 0; i < frontier.size(); ++i)
      if (WantsSplit(params, frontier[i].depth, frontier[i].parts)) to_split.push_back(i);
    std::vector<SplitChoice> choices(frontier.size());
    std::vector<core::FeatureOffsets> chosen(frontier.size());
    std::vector<uint8_t> is_split(frontier.size(), 0);
    for (size_t b0 = 0; b0 < to_split.size();) {
      // Batches bounded by histogram memory (they do not change any decision).
      std::vector<worker::NodePlan> plans;
      uint64_t batch_bytes = 0;
      size_t b1 = b0;
      while (b1 < to_split.size()) {
        const Open& f = frontier[to_split[b1]];
        worker::NodePlan plan;
        plan.node = f.sample_node;
        plan.position = f.position;
        plan.num_samples = Total(f.parts);
        plan.SetParts(f.parts);
        plan.sample_bins = worker::UseSampleBins(plan.num_samples, t_count, plan.num_slots);
        plan.features.resize(size_t(params.candidate_features));
        const uint64_t bytes = worker::PlanHistogramBytes(plan, t_count);
        if (!plans.empty() && batch_bytes + bytes > params.histogram_memory_bytes) break;
        batch_bytes += bytes;
        plan.features = worker::DrawFeatures(params, tree, f.position);
        plan.cut_stride = cut_stride;
        plans.push_back(std::move(plan));
        ++b1;
      }
      // This one shard holds every sample: fused where the reference subsample is the whole
      // node, else ranges + cuts + histograms (the same histograms and cuts either way).
      std::vector<worker::NodePlan> normal, fused;
      std::vector<std::pair<bool, size_t>> where(plans.size());
      for (size_t p = 0; p < plans.size(); ++p) {
        const bool f = worker::HistogramBuilder::CanFuse(samples, params, plans[p]);
        where[p] = {f, f ? fused.size() : normal.size()};
        (f ? fused : normal).push_back(std::move(plans[p]));
      }
      std::vector<worker::NodeHistogram> normal_hists, fused_hists;
      if (!normal.empty()) {
        std::vector<std::vector<worker::ResponseRange>> ranges;
        builder.ComputeRanges(samples, params, tree, normal, &ranges);
        for (size_t p = 0; p < normal.size(); ++p)
          normal[p].cuts = worker::DrawCuts(params, tree, normal[p].position, ranges[p]);
        builder.Build(samples, normal, t_count, &normal_hists);
      }
      if (!fused.empty()) builder.BuildFused(samples, params, tree, fused, &fused_hists);
      for (size_t p = 0; p < plans.size(); ++p) {
        const auto [f, j] = where[p];
        const worker::NodePlan& plan = f ? fused[j] : normal[j];
        const worker::NodeHistogram& hist = f ? fused_hists[j] : normal_hists[j];
        const size_t fi = to_split[b0 + p];
        // Every node tried is binned once over all its samples and candidates.
        out[frontier[fi].root].evaluations += plan.num_samples * uint64_t(plan.features.size());
        choices[fi] = FindBestSplit(hist, plan, frontier[fi].parts);
        if (choices[fi].valid && choices[fi].gain >= params.min_gain) {
          is_split[fi] = 1;
          chosen[fi] = plan.features[size_t(choices[fi].candidate)];
        }
      }
      b0 = b1;
    }
    // Decide in node order: each subtree's breadth-first layout.
    std::vector<Open> next;
    std::vector<worker::SampleSet::Split> splits;
    for (size_t i = 0; i < frontier.size(); ++i) {
      Open& f = frontier[i];
      TreeAssembler& assembler = assemblers[f.root];
      SubtreeNode n;
      n.position = f.position;
      n.parts = f.parts;
      if (!is_split[i]) {
        assembler.MakeLeaf(f.local, f.parts);
      } else {
        const SplitChoice& c = choices[i];
        n.split = true;
        n.offsets = chosen[i];
        n.cut = c.cut;
        n.gain = c.gain;
        const uint32_t left = assembler.MakeSplit(f.local, chosen[i], c.cut);
        const uint32_t left_node = next_sample_node;
        next_sample_node += 2;
        splits.push_back({f.sample_node, chosen[i], c.cut, left_node});
        next.push_back({left_node, left, worker::LeftChildPosition(f.position), c.left_parts, f.root, f.depth + 1});
        next.push_back(
            {left_node + 1, left + 1, worker::RightChildPosition(f.position), c.right_parts, f.root, f.depth + 1});
      }
      out[f.root].nodes.push_back(std::move(n));
    }
    samples.ApplySplits(splits, params.constants, params.threads > 0 ? params.threads : 1);
    frontier.swap(next);
  }
  uint64_t evaluations = 0;
  for (size_t r = 0; r < roots.size(); ++r) out[r].tree = assemblers[r].Finish(), evaluations += out[r].evaluations;
  if (evaluations != builder.evaluations() - evals_before)
    return Status(ErrorCode::kInternal, "subtree evaluations do not add up to the histogram builder's");
  return out;
}

Status ValidateSubtree(std::span<const SubtreeNode> nodes, uint64_t root_position,
                       std::span<const uint64_t> root_parts, const worker::TrainParams& params,
                       core::Tree* tree) {
  auto bad = [](const std::string& m) { return Status(ErrorCode::kInvalidArgument, "subtree: " + m); };
  if (nodes.empty()) return bad("no nodes");
  if (nodes.size() > (uint64_t(1) << 24)) return bad("too many nodes");
  if (nodes[0].position != root_position)
    return bad("root at position " + std::to_string(nodes[0].position) + ", expected " +
               std::to_string(root_position));
  if (root_parts.size() != size_t(core::kNumParts) ||
      !std::equal(root_parts.begin(), root_parts.end(), nodes[0].parts.begin(), nodes[0].parts.end()))
    return bad("root part counts differ from the coordinator's");
  TreeAssembler assembler(core::kNumParts);
  std::vector<int> depth_of(1, worker::PositionDepth(root_position));
  for (size_t i = 0; i < nodes.size(); ++i) {
    const SubtreeNode& n = nodes[i];
    if (i >= assembler.num_nodes()) return bad("node " + std::to_string(i) + " has no parent");
    if (n.parts.size() != size_t(core::kNumParts)) return bad("part counts of node " + std::to_string(i));
    if (!n.split) {
      assembler.MakeLeaf(uint32_t(i), n.parts);
      continue;
    }
    if (!WantsSplit(params, depth_of[i], n.parts)) return bad("node " + std::to_string(i) + " may not split");
    if (n.cut <= -(1 << 22) || n.cut >= (1 << 22)) return bad("cut of node " + std::to_string(i));
    if (!std::isfinite(n.gain) || n.gain < 0) return bad("gain of node " + std::to_string(i));
    const uint32_t left = assembler.MakeSplit(uint32_t(i), n.offsets, n.cut);
    depth_of.push_back(depth_of[i] + 1);
    depth_of.push_back(depth_of[i] + 1);
    if (left + 1 >= nodes.size()) return bad("children of node " + std::to_string(i) + " missing");
    const SubtreeNode &l = nodes[left], &r = nodes[left + 1];
    if (l.position != worker::LeftChildPosition(n.position) ||
        r.position != worker::RightChildPosition(n.position))
      return bad("children of node " + std::to_string(i) + " at the wrong positions");
    if (l.parts.size() != size_t(core::kNumParts) || r.parts.size() != size_t(core::kNumParts))
      return bad("part counts of the children of node " + std::to_string(i));
    for (int p = 0; p < core::kNumParts; ++p)
      if (l.parts[size_t(p)] + r.parts[size_t(p)] != n.parts[size_t(p)] ||
          l.parts[size_t(p)] > n.parts[size_t(p)])
        return bad("children of node " + std::to_string(i) + " do not add up to it");
    if (Total(l.parts) == 0 || Total(r.parts) == 0) return bad("an empty child of node " + std::to_string(i));
  }
  if (assembler.num_nodes() != nodes.size()) return bad("node count does not match the splits");
  core::Tree t = assembler.Finish();
  if (tree) *tree = std::move(t);
  return Status::Ok();
}

}  // namespace poseforest::coordinator
