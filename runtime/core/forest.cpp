#include "runtime/core/forest.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace poseforest::core {

uint32_t Forest::max_depth() const {
  uint32_t d = 0;
  for (const Tree& t : trees) d = std::max(d, t.depth);
  return d;
}

size_t Forest::total_nodes() const {
  size_t n = 0;
  for (const Tree& t : trees) n += t.nodes.size();
  return n;
}

std::vector<std::string> Forest::DefaultPartNames() {
  std::vector<std::string> names;
  for (int i = 0; i < kNumParts; ++i) names.emplace_back(PartName(i));
  return names;
}

std::string Forest::TaxonomyDifference() const {
  if (num_parts != kNumParts) return "this one has " + std::to_string(num_parts) + " parts";
  const std::vector<std::string> paper = DefaultPartNames();
  for (size_t i = 0; i < paper.size(); ++i)
    if (i >= part_names.size() || part_names[i] != paper[i])
      return "its part " + std::to_string(i) + " is '" + (i < part_names.size() ? part_names[i] : "") +
             "', the paper's '" + paper[i] + "'";
  return "";
}

void QuantizeDistribution(const float* p, int n, uint8_t* out) {
  double sum = 0;
  for (int i = 0; i < n; ++i) sum += (std::isfinite(p[i]) && p[i] > 0) ? double(p[i]) : 0.0;
  if (n <= 0) return;
  std::vector<double> remainder(size_t(n), 0.0);
  int assigned = 0;
  for (int i = 0; i < n; ++i) {
    const double v = sum > 0 ? ((std::isfinite(p[i]) && p[i] > 0 ? double(p[i]) : 0.0) * kLeafTotal / sum)
                             : double(kLeafTotal) / n;
    const double f = std::floor(v);
    out[i] = uint8_t(f);
    remainder[size_t(i)] = v - f;
    assigned += int(f);
  }
  // Hand the missing units to the largest remainders; ties to the lower index (stable sort).
  std::vector<int> order(static_cast<size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return remainder[size_t(a)] > remainder[size_t(b)]; });
  for (int k = 0; assigned < kLeafTotal; ++k, ++assigned) ++out[order[size_t(k % n)]];
}

Status ValidateForest(const Forest& forest, const std::string& source) {
  auto fail = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, source + ": " + what); };
  if (forest.num_parts < 1 || forest.num_parts > 254)
    return fail("part count " + std::to_string(forest.num_parts) + " is outside 1..254");
  if (forest.part_names.size() != size_t(forest.num_parts))
    return fail("part table has " + std::to_string(forest.part_names.size()) + " names for " +
                std::to_string(forest.num_parts) + " parts");
  for (size_t i = 0; i < forest.part_names.size(); ++i)
    if (forest.part_names[i].empty() || forest.part_names[i].size() > 64)
      return fail("part " + std::to_string(i) + " has an empty or over-long name");
  if (forest.trees.empty()) return fail("forest has no trees");
  // Sums of 255 over trees must fit the classifier's uint16 accumulators.
  if (forest.trees.size() > 256) return fail("forest has " + std::to_string(forest.trees.size()) + " trees (at most 256)");
  if (forest.constants.background_mm == 0) return fail("background depth constant is 0 mm");
  if (forest.constants.edge != ProbeEdge::kBackground && forest.constants.edge != ProbeEdge::kClamp)
    return fail("probe edge " + std::to_string(int(forest.constants.edge)) +
                " is neither background nor clamp");
  if (!std::isfinite(forest.constants.offset_unit) || forest.constants.offset_unit <= 0 ||
      forest.constants.offset_unit > 64)
    return fail("offset unit " + std::to_string(forest.constants.offset_unit) + " is not in (0, 64] pixel*m");
  for (const float f : {forest.training_fx, forest.training_fy})
    if (!std::isfinite(f) || f < 1 || f > 100000)
      return fail("training focal length " + std::to_string(f) + " px is not in [1, 100000] (FOCL)");
  if (forest.confidence_calibration)
    POSEFOREST_RETURN_IF_ERROR(ValidateCalibration(*forest.confidence_calibration, source + ": JCAL"));
  if (forest.offset_votes) {
    std::vector<uint32_t> num_leaves;
    for (const Tree& t : forest.trees) num_leaves.push_back(t.num_leaves);
    POSEFOREST_RETURN_IF_ERROR(ValidateOffsetVotes(*forest.offset_votes, num_leaves, source + ": JVOT"));
  }
  if (forest.tracking_model)
    POSEFOREST_RETURN_IF_ERROR(ValidateTrackingModel(*forest.tracking_model, source + ": JTRK"));
  for (const bool fast : {false, true}) {
    const auto& params = fast ? forest.fast_proposal_params : forest.proposal_params;
    if (!params) continue;
    for (int j = 0; j < kNumJoints; ++j) {
      const JointParams& p = (*params)[size_t(j)];
      const std::string joint =
          std::string(fast ? "fast clustering parameters (JPFC)" : "mean shift parameters (JPAR)") +
          ", joint " + std::string(JointName(j));
      if (!std::isfinite(p.bandwidth_m) || p.bandwidth_m <= 0 || p.bandwidth_m > 2)
        return fail(joint + ": bandwidth " + std::to_string(p.bandwidth_m) + " m outside (0, 2]");
      if (!std::isfinite(p.prob_threshold) || p.prob_threshold < 0 || p.prob_threshold > 1)
        return fail(joint + ": probability threshold " + std::to_string(p.prob_threshold) +
                    " outside [0, 1]");
      if (!std::isfinite(p.z_offset_m) || std::abs(p.z_offset_m) > 1)
        return fail(joint + ": z offset " + std::to_string(p.z_offset_m) + " m outside [-1, 1]");
    }
  }
  const int stride = forest.leaf_stride();

  for (size_t t = 0; t < forest.trees.size(); ++t) {
    const Tree& tree = forest.trees[t];
    const std::string where = "tree " + std::to_string(t) + ": ";
    const size_t n = tree.nodes.size();
    if (n == 0) return fail(where + "no nodes");
    if (n >= kLeafBit) return fail(where + "too many nodes");
    if (tree.leaves.size() != size_t(tree.num_leaves) * size_t(stride))
      return fail(where + "leaf table holds " + std::to_string(tree.leaves.size()) + " bytes, expected " +
                  std::to_string(size_t(tree.num_leaves) * size_t(stride)));
    // Depth of each node, computed forwards: children always come after their parent, so one
    // pass in index order sees each parent before its children.
    std::vector<uint32_t> depth(n, 0);
    std::vector<uint8_t> has_parent(n, 0);
    uint32_t max_depth = 0;
    for (size_t i = 0; i < n; ++i) {
      const Node& node = tree.nodes[i];
      if (i > 0 && !has_parent[i]) return fail(where + "node " + std::to_string(i) + " is unreachable");
      if (node.is_leaf()) {
        if (node.leaf_index() >= tree.num_leaves)
          return fail(where + "node " + std::to_string(i) + " points at leaf " + std::to_string(node.leaf_index()) +
                      " of " + std::to_string(tree.num_leaves));
        max_depth = std::max(max_depth, depth[i]);
        continue;
      }
      const uint64_t left = node.child;
      if (left <= i || left + 1 >= n)
        return fail(where + "node " + std::to_string(i) + " has children " + std::to_string(left) + "," +
                    std::to_string(left + 1) + " outside (" + std::to_string(i) + ", " + std::to_string(n) + ")");
      if (!std::isfinite(node.threshold))
        return fail(where + "node " + std::to_string(i) + " has a non-finite threshold");
      for (uint64_t c = left; c <= left + 1; ++c) {
        if (has_parent[c]) return fail(where + "node " + std::to_string(c) + " has two parents");
        has_parent[c] = 1;
        depth[c] = depth[i] + 1;
      }
    }
    if (max_depth != tree.depth)
      return fail(where + "recorded depth " + std::to_string(tree.depth) + " but the deepest leaf is at " +
                  std::to_string(max_depth));
    for (uint32_t l = 0; l < tree.num_leaves; ++l) {
      const uint8_t* row = tree.leaf(l, stride);
      int sum = 0;
      for (int c = 0; c < forest.num_parts; ++c) sum += row[c];
      for (int c = forest.num_parts; c < stride; ++c)
        if (row[c] != 0) return fail(where + "leaf " + std::to_string(l) + " has non-zero padding");
      if (sum != kLeafTotal)
        return fail(where + "leaf " + std::to_string(l) + " sums to " + std::to_string(sum) + ", not 255");
    }
  }
  return Status::Ok();
}

}  // namespace poseforest::core
