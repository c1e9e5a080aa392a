#include "runtime/core/offset_votes.h"

#include <algorithm>
#include <cmath>

namespace poseforest::core {

float OffsetVotes::Confidence(int joint, float share) const {
  const size_t n = share_edges.size();
  if (n == 0 || precision.size() != n * kNumJoints || joint < 0 || joint >= kNumJoints || std::isnan(share))
    return 0;
  // The bin whose lower edge is the largest edge <= share; below the first edge, the first bin
  // (its edge is a lower bound of the measured shares, not a hard floor).
  const auto it = std::upper_bound(share_edges.begin(), share_edges.begin() + std::ptrdiff_t(n), share);
  const size_t bin = it == share_edges.begin() ? 0 : size_t(it - share_edges.begin()) - 1;
  return precision[size_t(joint) * n + bin];
}

size_t OffsetVotes::total_votes() const {
  size_t n = 0;
  for (const TreeVotes& t : trees) n += t.votes.size();
  return n;
}

Status ValidateOffsetVotes(const OffsetVotes& votes, const std::vector<uint32_t>& num_leaves,
                           const std::string& where) {
  auto fail = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, where + ": " + what); };
  if (!std::isfinite(votes.max_offset_m) || votes.max_offset_m <= 0)
    return fail("max offset " + std::to_string(votes.max_offset_m) + " m is not finite and positive");
  for (int j = 0; j < kNumJoints; ++j) {
    const float b = votes.bandwidth_m[size_t(j)];
    if (!std::isfinite(b) || b <= 0)
      return fail("joint " + std::string(JointName(j)) + ": bandwidth " + std::to_string(b) +
                  " m is not finite and positive");
  }
  const size_t bins = votes.share_edges.size();
  if (votes.precision.size() != bins * kNumJoints)
    return fail("calibration has " + std::to_string(bins) + " share edges but " +
                std::to_string(votes.precision.size()) + " precisions (expected " +
                std::to_string(bins * kNumJoints) + ": one per joint and bin)");
  for (size_t k = 0; k < bins; ++k) {
    const float e = votes.share_edges[k];
    if (!std::isfinite(e) || e < 0 || e >= 1 || (k > 0 && e <= votes.share_edges[k - 1]))
      return fail("calibration: share edge " + std::to_string(k) + " (" + std::to_string(e) +
                  ") is not in [0, 1) and ascending");
  }
  for (size_t k = 0; k < votes.precision.size(); ++k) {
    const float p = votes.precision[k];
    if (!std::isfinite(p) || p < 0 || p > 1)
      return fail("calibration: precision " + std::to_string(k) + " (" + std::to_string(p) +
                  ") outside [0, 1]");
  }
  if (votes.trees.size() != num_leaves.size())
    return fail("votes for " + std::to_string(votes.trees.size()) + " trees, the forest has " +
                std::to_string(num_leaves.size()));
  for (size_t t = 0; t < votes.trees.size(); ++t) {
    const TreeVotes& tree = votes.trees[t];
    const std::string tree_name = "tree " + std::to_string(t);
    const uint64_t leaves = num_leaves[t];
    if (tree.first.size() != leaves + 1)
      return fail(tree_name + ": " + std::to_string(tree.first.size()) + " leaf offsets (first), expected " +
                  std::to_string(leaves + 1) + " for " + std::to_string(leaves) + " leaves");
    if (tree.first[0] != 0)
      return fail(tree_name + ": first[0] is " + std::to_string(tree.first[0]) + ", not 0");
    if (tree.first.back() != tree.votes.size())
      return fail(tree_name + ": first ends at " + std::to_string(tree.first.back()) +
                  " but the tree holds " + std::to_string(tree.votes.size()) + " votes");
    for (uint32_t l = 0; l < leaves; ++l) {
      const std::string leaf_name = tree_name + " leaf " + std::to_string(l);
      const uint32_t begin = tree.first[l], end = tree.first[l + 1];
      if (end < begin)
        return fail(leaf_name + ": first decreases (" + std::to_string(begin) + " to " + std::to_string(end) +
                    ")");
      // end <= first.back() == votes.size() follows once every step is non-decreasing, but the
      // later steps are checked only after this leaf: bound it here before reading votes.
      if (end > tree.votes.size())
        return fail(leaf_name + ": votes end at " + std::to_string(end) + ", past the tree's " +
                    std::to_string(tree.votes.size()) + " votes");
      for (uint32_t i = begin; i < end; ++i) {
        const JointVote& v = tree.votes[i];
        if (v.joint >= kNumJoints)
          return fail(leaf_name + ": vote joint " + std::to_string(v.joint) + " out of range (" +
                      std::to_string(kNumJoints) + " joints)");
        if (i > begin && v.joint <= tree.votes[i - 1].joint)
          return fail(leaf_name + ": vote joints not increasing (" + std::to_string(v.joint) + " after " +
                      std::to_string(tree.votes[i - 1].joint) + ")");
        if (v.weight == 0)
          return fail(leaf_name + ": vote for joint " + std::string(JointName(v.joint)) +
                      " has weight 0 (1..255)");
      }
    }
  }
  return Status::Ok();
}

}  // namespace poseforest::core
