#pragma once
// Builds one core::Tree level by level: nodes are allocated breadth-first (children after
// their parent, left at `child`, right at `child + 1`), leaves numbered in node order.

#include <cstdint>
#include <span>
#include <vector>

#include "runtime/core/forest.h"

namespace poseforest::engine {

class TreeAssembler {
 public:
  /// Starts a tree with an undecided root (node 0).
  explicit TreeAssembler(int num_parts);

  /// Makes `node` a split (go left if f < cut + 0.5) and allocates its two children at the end
  /// of the array; returns the left child's index. Call in increasing node order per level.
  uint32_t MakeSplit(uint32_t node, const core::FeatureOffsets& offsets, int32_t cut);
  /// Makes `node` a leaf holding the normalized `part_counts` (num_parts entries), quantized
  /// by core::QuantizeDistribution.
  void MakeLeaf(uint32_t node, std::span<const uint64_t> part_counts);

  size_t num_nodes() const { return nodes_.size(); }
  /// Leaves made so far; the next MakeLeaf creates leaf number num_leaves().
  uint32_t num_leaves() const { return num_leaves_; }
  /// The finished tree; every node must have been decided.
  core::Tree Finish();

 private:
  int num_parts_;
  std::vector<core::Node> nodes_;
  std::vector<uint8_t> decided_;
  std::vector<uint32_t> depth_;
  std::vector<uint8_t> leaves_;
  uint32_t num_leaves_ = 0;
};

}  // namespace poseforest::engine
