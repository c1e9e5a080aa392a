#include "engine/subtree_trainer.h"

#include <cmath>
#include <string>

#include "engine/candidates.h"
#include "engine/frontier_loop.h"
#include "engine/local_shard_set.h"
#include "engine/split_search.h"
#include "engine/tree_assembler.h"
#include "runtime/core/body_parts.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

uint64_t Total(std::span<const uint64_t> parts) {
  uint64_t n = 0;
  for (uint64_t c : parts) n += c;
  return n;
}

}  // namespace

Result<SubtreeOutput> TrainSubtree(SampleSet& samples, uint32_t root_sample_node, const TrainParams& params,
                                   int tree, uint64_t root_position, std::span<const uint64_t> root_parts,
                                   HistogramBuilder& builder, const std::function<void()>& between) {
  if (root_parts.size() != size_t(core::kNumParts))
    return Status(ErrorCode::kInvalidArgument, "subtree root: part counts of the wrong length");
  const SubtreeRoot root{root_sample_node, root_position, {root_parts.begin(), root_parts.end()}};
  auto out = TrainSubtrees(samples, std::span<const SubtreeRoot>(&root, 1), params, tree, builder, between);
  if (!out.ok()) return out.status();
  return std::move((*out)[0]);
}

Result<std::vector<SubtreeOutput>> TrainSubtrees(SampleSet& samples, std::span<const SubtreeRoot> roots,
                                                 const TrainParams& params, int tree,
                                                 HistogramBuilder& builder,
                                                 const std::function<void()>& between) {
  uint32_t next_sample_node = 0;  // children get fresh sample node ids, increasing in frontier order
  std::vector<OpenNode> frontier;
  for (size_t r = 0; r < roots.size(); ++r) {
    const SubtreeRoot& root = roots[r];
    if (root.parts.size() != size_t(core::kNumParts))
      return Status(ErrorCode::kInvalidArgument, "subtree root: part counts of the wrong length");
    if (r > 0 && root.sample_node <= roots[r - 1].sample_node)
      return Status(ErrorCode::kInternal, "subtree roots out of sample-node order");
    std::vector<uint64_t> have(static_cast<size_t>(core::kNumParts), 0);
    const NodeRange range = samples.RangeOf(root.sample_node);
    if (range.end > range.begin) samples.CountParts(range, core::kNumParts, have.data());
    if (!std::equal(have.begin(), have.end(), root.parts.begin()))
      return Status(ErrorCode::kInvalidArgument, "subtree at position " + std::to_string(root.position) +
                                                     ": " + std::to_string(range.end - range.begin) +
                                                     " samples routed here, the coordinator counts " +
                                                     std::to_string(Total(root.parts)));
    frontier.push_back(
        {root.sample_node, root.position, PositionDepth(root.position), root.parts, uint32_t(r), 0});
    next_sample_node = std::max(next_sample_node, root.sample_node + 1);
  }
  for (const NodeRange& range : samples.ranges())
    next_sample_node = std::max(next_sample_node, range.node + 1);
  std::vector<SubtreeOutput> out(roots.size());
  const uint64_t evals_before = builder.evaluations();
  std::vector<TreeAssembler> assemblers(roots.size(), TreeAssembler(core::kNumParts));
  // This one shard holds every sample of every root: the frontier loop over it alone.
  LocalShardSet shard_set(std::span<SampleSet>(&samples, 1), params, builder,
                          params.threads > 0 ? params.threads : 1);
  FrontierLoopHooks hooks;
  if (between) {
    hooks.after_batch = [&](size_t, uint64_t) { between(); };
    hooks.level_done = [&](const LevelDone&) {
      between();
      return Status::Ok();
    };
  }
  // Each root's nodes in the loop's (breadth-first) order: its subtree's layout.
  hooks.place = [&](const OpenNode& f, NodeDecision& d) -> Result<uint32_t> {
    SubtreeOutput& o = out[f.owner];
    o.evaluations += d.evaluations;  // every node tried is binned once over all its samples
    SubtreeNode& n = o.nodes.emplace_back();
    n.position = f.position;
    n.parts = f.parts;
    if (!d.split) {
      assemblers[f.owner].MakeLeaf(f.local, f.parts);
      return uint32_t(0);
    }
    n.split = true;
    n.offsets = d.offsets;
    n.cut = d.choice.cut;
    n.gain = d.choice.gain;
    return assemblers[f.owner].MakeSplit(f.local, d.offsets, d.choice.cut);
  };
  const int first_level = frontier.empty() ? 0 : frontier[0].depth;
  // With `between`, histogram batches of at most 8 MiB (one dense node; the batch size
  // changes no decision): the caller gets control back every fraction of a second, not after
  // a batch of a hundred roots' top level (seconds).
  const uint64_t batch_bytes =
      between ? std::min<uint64_t>(params.histogram_memory_bytes, uint64_t(8) << 20) : params.histogram_memory_bytes;
  POSEFOREST_RETURN_IF_ERROR(RunFrontierLoop(shard_set, params, tree, first_level, std::move(frontier),
                                             next_sample_node, batch_bytes, hooks));
  uint64_t evaluations = 0;
  for (size_t r = 0; r < roots.size(); ++r)
    out[r].tree = assemblers[r].Finish(), evaluations += out[r].evaluations;
  if (evaluations != builder.evaluations() - evals_before)
    return Status(ErrorCode::kInternal, "subtree evaluations do not add up to the histogram builder's");
  return out;
}

Status ValidateSubtree(std::span<const SubtreeNode> nodes, uint64_t root_position,
                       std::span<const uint64_t> root_parts, const TrainParams& params, core::Tree* tree) {
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
  std::vector<int> depth_of(1, PositionDepth(root_position));
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
    if (l.position != LeftChildPosition(n.position) || r.position != RightChildPosition(n.position))
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

}  // namespace poseforest::engine
