#include "engine/tree_assembler.h"

#include <algorithm>

namespace poseforest::engine {

TreeAssembler::TreeAssembler(int num_parts) : num_parts_(num_parts) {
  nodes_.emplace_back();
  decided_.push_back(0);
  depth_.push_back(0);
}

uint32_t TreeAssembler::MakeSplit(uint32_t node, const core::FeatureOffsets& offsets, int32_t cut) {
  POSEFOREST_CHECK(node < nodes_.size() && !decided_[node]);
  const auto left = uint32_t(nodes_.size());
  // cut + 0.5 is exact in float for |cut| < 2^22; responses are within +-65535.
  nodes_[node] = core::Node::Split(offsets, float(cut) + 0.5f, left);
  decided_[node] = 1;
  for (int i = 0; i < 2; ++i) {
    nodes_.emplace_back();
    decided_.push_back(0);
    depth_.push_back(depth_[node] + 1);
  }
  return left;
}

void TreeAssembler::MakeLeaf(uint32_t node, std::span<const uint64_t> part_counts) {
  POSEFOREST_CHECK(node < nodes_.size() && !decided_[node] && int(part_counts.size()) == num_parts_);
  std::vector<float> p(static_cast<size_t>(num_parts_));
  for (int c = 0; c < num_parts_; ++c) p[size_t(c)] = float(part_counts[size_t(c)]);
  const int stride = core::LeafStride(num_parts_);
  leaves_.resize(size_t(num_leaves_ + 1) * size_t(stride), 0);
  core::QuantizeDistribution(p.data(), num_parts_, leaves_.data() + size_t(num_leaves_) * size_t(stride));
  nodes_[node] = core::Node::Leaf(num_leaves_++);
  decided_[node] = 1;
}

core::Tree TreeAssembler::Finish() {
  core::Tree tree;
  uint32_t depth = 0;
  for (size_t i = 0; i < nodes_.size(); ++i) {
    POSEFOREST_CHECK_MSG(decided_[i], "TreeAssembler::Finish: undecided node");
    if (nodes_[i].is_leaf()) depth = std::max(depth, depth_[i]);
  }
  tree.nodes.assign(nodes_.begin(), nodes_.end());
  tree.leaves.assign(leaves_.begin(), leaves_.end());
  tree.num_leaves = num_leaves_;
  tree.depth = depth;
  return tree;
}

}  // namespace poseforest::engine
