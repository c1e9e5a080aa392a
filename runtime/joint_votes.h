#pragma once
// Joint candidates from offset votes (core::OffsetVotes, format 1.5): every sampled pixel of a
// person walks each tree to its leaf and casts the leaf's votes (the pixel's back-projected point
// plus the stored offset, weighted by the vote's weight times the pixel's surface area, d^2); per
// joint, weighted mean shift over the votes gives candidates with their share of the joint's
// vote weight and the calibrated confidence of that share. Hidden joints get candidates too: a
// leaf votes for a wrist behind the back from the pixels of the back.

#include <Eigen/Core>
#include <array>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"
#include "runtime/classifier.h"
#include "runtime/core/forest.h"

namespace poseforest::runtime {

struct VoteCandidate {
  Eigen::Vector3f position{0, 0, 0};  ///< camera frame, metres
  float share = 0;                    ///< the mode's kernel-weighted share of the joint's vote weight, 0..1
  float confidence = 0;               ///< core::OffsetVotes::Confidence(share)
};

/// Per joint (core::Joint order), candidates of one person, most confident first.
using PersonVotes = std::array<std::vector<VoteCandidate>, core::kNumJoints>;

struct VoteOptions {
  /// Pixels of a person that vote: about this many, on a regular grid over the mask.
  int target_pixels = 800;
  int max_candidates = 3;         ///< per joint
  int max_votes_per_joint = 384;  ///< the heaviest are kept (mean shift costs votes x seeds)
  int seeds = 8;                  ///< mean shift starts from the heaviest votes
  int iterations = 8;
  /// Bandwidth scale: the table's per-joint bandwidth times this (1 = as learned).
  float bandwidth_scale = 1.0f;
  int threads = 0;  ///< OpenMP threads over joints (0 = OpenMP's default)
};

/// Leaf index of pixel (x, y) (depth > 0) in `tree`, with the forest's feature constants: what
/// the classifier computes, one pixel at a time.
uint32_t LeafOf(const core::Tree& tree, const core::FeatureConstants& constants, const core::DepthImage& depth,
                int x, int y);

/// Candidates per person label 1..num_people of `masks` (index label - 1); empty candidate lists
/// when the forest has no votes. `depth` is the frame the forest classifies (segmented), in mm.
/// With `classification` of that frame holding foreground_leaves (ClassifyOptions::
/// want_foreground_leaves), its leaves are read (every step-th foreground pixel of a person, about
/// target_pixels of them) instead of walking the trees again; otherwise a regular grid of the
/// person's pixels walks the trees (LeafOf).
std::vector<PersonVotes> CastVotes(const core::Forest& forest, const core::DepthImage& depth,
                                   const core::LabelImage& masks, int num_people,
                                   const core::CameraIntrinsics& camera, const VoteOptions& options = {},
                                   const Classification* classification = nullptr);

}  // namespace poseforest::runtime
