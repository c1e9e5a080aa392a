#pragma once
// `learn-votes`: the offset votes of a trained forest (core::OffsetVotes, format 1.5).
//
// For each tree it renders the tree's training frames again - frame tree * images_per_tree + i
// of the job's source, the pixels SamplePixels drew for it in training - so every leaf gets the
// very pixels that reached it in training, whether the forest came from `train` or from the
// distributed service (both draw the same frames and pixels; the forest does not depend on the
// number of workers, nor does this). Per (leaf, joint), the offsets from the pixels'
// back-projected points to the joint (hidden joints too) shorter than max_offset_m are
// clustered by mean shift; the main mode is kept if it holds at least min_weight of the leaf's
// pixels. Then vote candidates (runtime/joint_votes.h) are made on validation frames and the
// precision of a candidate per bin of its share of the joint's vote weight is measured: the
// table's calibration. Deterministic: same forest, job and options, same table, whatever the
// number of threads.

#include <functional>
#include <string>
#include <vector>

#include "engine/job_spec.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

struct VoteLearningOptions;
/// The longest training offset kept for joint `j` (core::Joint): max_offset_m for the head, neck
/// and shoulders, limb_max_offset_m for the elbows, knees, ankles and feet, hand_max_offset_m for
/// the wrists and hands, each falling back as documented below.
float VoteReach(int j, const VoteLearningOptions& options);

struct VoteLearningOptions {
  /// Longer training offsets to the head, neck and shoulders are not kept (docs/runtime/votes.md).
  float max_offset_m = 0.3f;
  /// The same for the elbows, knees, ankles and feet, which a turned or crossed body hides
  /// farthest from its seen pixels; 0: max_offset_m. 0.9 since 29 Nov 2026: on the main job's
  /// four validation sets, hidden joints placed within 0.15 m +0.02 to +0.05, "not tracked"
  /// really hidden +0.01 to +0.09, visible joints tracked within 0.1 m +0.001 to +0.004
  /// (docs/runtime/votes.md, "The limbs' reach without the hands").
  float limb_max_offset_m = 0.9f;
  /// The same for the wrists and hands; 0: as the other limbs (limb_max_offset_m, else
  /// max_offset_m). 0.3: long votes pull a seen hand away from where it is (votes.md).
  float hand_max_offset_m = 0.3f;
  float leaf_bandwidth_m = 0.05f;  ///< mean shift over a leaf's offsets to one joint
  float vote_bandwidth_m = 0.06f;  ///< run-time mean shift over the votes, without a search (below)
  /// Run-time bandwidths tried per joint on the validation frames (the best placed candidate
  /// wins; the first value wins ties); empty or one value: vote_bandwidth_m for every joint.
  std::vector<float> bandwidth_grid = {0.06f, 0.04f, 0.09f, 0.13f, 0.18f};
  int max_pixels_per_leaf = 64;    ///< a leaf's pixels beyond this are thinned evenly
  float min_weight = 0.1f;         ///< a mode holding less of the leaf's pixels is not kept
  int validation_frames = 60;      ///< 0: no calibration (every candidate's confidence is 0)
  SourceSpec validation;           ///< frames with joints, one person each (others skipped)
  int threads = 0;                 ///< 0 = all cores
  /// Progress lines ("tree 1: rendered 200 / 300 frames (12 s)"); may be empty.
  std::function<void(const std::string&)> progress;
};

struct VoteLearningReport {
  uint64_t pixels = 0;             ///< training pixels walked, over trees
  uint64_t leaves = 0;             ///< leaves over trees
  uint64_t leaves_with_votes = 0;  ///< leaves that kept at least one vote
  uint64_t leaves_unreached = 0;   ///< leaves no training pixel reached (none, for the job's own forest)
  uint64_t votes = 0;
  int validation_frames = 0;       ///< one-person validation frames scored
  uint64_t candidates = 0;         ///< vote candidates scored on them
  /// Per joint, on the validation frames: the joint's most confident vote candidate within 0.1 m.
  std::array<int, core::kNumJoints> top_within{}, scored{};
  std::array<float, core::kNumJoints> bandwidth_m{};  ///< the run-time bandwidths chosen
  double seconds = 0;
};

/// The votes of `forest`, trained by `job`. Errors: a source without joints (procedural) or
/// whose frames are not the training frames (kInvalidArgument), rendering failures, a forest of
/// another tree count or a part set other than the paper's.
core::Result<core::OffsetVotes> LearnOffsetVotes(const core::Forest& forest, const TrainParams& job,
                                                 const VoteLearningOptions& options,
                                                 VoteLearningReport* report = nullptr);

}  // namespace poseforest::engine
