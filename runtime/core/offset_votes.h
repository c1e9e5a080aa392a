#pragma once
// Offset votes (format 1.5, optional section JVOT): per tree and leaf, up to one 3D offset per
// joint from a pixel that reaches the leaf to that joint (Girshick et al., ICCV 2011, "Efficient
// regression of general-activity human poses from depth images"). At run time each pixel of a
// person casts its leaves' votes (pixel point + offset), and mean shift over the votes gives
// joint candidates, hidden joints included; they join the part proposals in the skeleton fit.
//
// `learn-votes` builds the table after training: it renders each tree's training frames again
// (the same frames and sampled pixels as the training job, so the result is the same whether the
// forest came from `train` or from the distributed service), walks every sampled pixel to its
// leaf and, per (leaf, joint), finds the main mode of the offsets by mean shift. It then measures
// on validation frames how often a vote candidate with a given share of its joint's vote weight
// lies within 0.1 m of the joint (`calibration`).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/result.h"

namespace poseforest::core {

/// One vote of a leaf: the offset (millimetres, camera frame: x right, y down, z away) from the
/// pixel's back-projected point to `joint`, and its weight: the fraction of the leaf's training
/// pixels whose offset to that joint lies within the mode's bandwidth, quantized to 1..255.
struct JointVote {
  int16_t dx_mm = 0, dy_mm = 0, dz_mm = 0;
  uint8_t joint = 0;   ///< core::Joint
  uint8_t weight = 0;  ///< fraction * 255, >= 1
  bool operator==(const JointVote&) const = default;
};
static_assert(sizeof(JointVote) == 8, "JointVote is 8 bytes on disk");

/// The votes of one tree: leaf l's votes are votes[first[l], first[l + 1]), in joint order, at
/// most one per joint.
struct TreeVotes {
  std::vector<uint32_t> first;  ///< num_leaves + 1 entries; first[0] == 0, non-decreasing
  std::vector<JointVote> votes;
  bool operator==(const TreeVotes&) const = default;
};

struct OffsetVotes {
  /// Training offsets longer than this were not kept (a pixel says little about far joints).
  float max_offset_m = 0.3f;
  /// Mean shift bandwidth over the votes at run time, per joint, metres.
  std::array<float, kNumJoints> bandwidth_m{};
  /// Calibration: the lower edges of the share bins (ascending, in [0, 1)) and, per joint and
  /// bin (joint-major: precision[joint * bins + bin]), the precision measured on validation
  /// frames (a candidate within 0.1 m of its joint), in [0, 1], non-decreasing in share. A
  /// candidate's confidence is read off its joint's row by its share of the joint's vote weight.
  std::vector<float> share_edges;
  std::vector<float> precision;  ///< kNumJoints x share_edges.size()
  std::vector<TreeVotes> trees;  ///< one per tree of the forest, in order
  bool operator==(const OffsetVotes&) const = default;

  /// Calibrated confidence in [0, 1] of a vote candidate of `joint` holding `share` (0..1) of the
  /// joint's vote weight: the precision of its bin (0 without a table).
  float Confidence(int joint, float share) const;
  /// Votes stored over all trees.
  size_t total_votes() const;
};

/// Checks the table against the forest's trees' leaf counts (`num_leaves[t]`): one TreeVotes per
/// tree, `first` of num_leaves + 1 non-decreasing entries from 0 to votes.size(), joints in range
/// and increasing within a leaf, weights >= 1, finite positive max offset and bandwidths, a
/// calibration of equal sizes with ascending edges in [0, 1) and precisions in [0, 1]. `where`
/// names the file in errors.
Status ValidateOffsetVotes(const OffsetVotes& votes, const std::vector<uint32_t>& num_leaves,
                           const std::string& where);

}  // namespace poseforest::core
