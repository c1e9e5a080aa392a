#pragma once
// Depth frame in, skeletons out: people segmentation, per-pixel classification, joint proposals
// and skeletons with ids, with the time each stage took. One object per stream (it holds the
// tracker and the forest rescaled to the stream's camera); `poseforest live` and bench/live run
// it.

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "runtime/classifier.h"
#include "runtime/core/forest.h"
#include "runtime/frame_source.h"
#include "runtime/joint_proposals.h"
#include "runtime/segmentation.h"
#include "runtime/skeleton.h"

namespace poseforest::runtime {

enum class SegmentMode {
  kAuto,  ///< segment raw frames, pass pre-segmented ones unchanged
  kOn,    ///< always segment
  kOff,   ///< every pixel with depth is one person
};

struct SkeletonPipelineOptions {
  SegmentMode segment = SegmentMode::kAuto;
  SegmentationOptions segmentation;
  ProposalMethod method = ProposalMethod::kMeanShift;
  SkeletonOptions skeleton;
  int num_threads = 0;  ///< OpenMP threads of the classifier and the proposals; 0 = all
  /// Classify (and propose from) every pixel_stride-th pixel in x and y only
  /// (ClassifyOptions::pixel_stride; 2: a quarter of the pixels). 1 = every pixel.
  int pixel_stride = 1;
  /// Cast the forest's offset votes (format 1.5) when it has them (runtime/joint_votes.h).
  bool votes = true;
  VoteOptions vote_options;
};

/// Milliseconds per stage of one frame.
struct StageTimes {
  double segment_ms = 0, classify_ms = 0, proposals_ms = 0, votes_ms = 0, skeletons_ms = 0;
  double total() const { return segment_ms + classify_ms + proposals_ms + votes_ms + skeletons_ms; }
};

struct SkeletonFrame {
  SegmentationResult segmentation;
  /// The depth the forest saw: the segmented people (or the frame itself when pre-segmented or
  /// with segmentation off).
  const core::DepthImage* depth = nullptr;
  Classification classification;
  FrameProposals proposals;
  /// Vote candidates per person (index mask label - 1); empty when the forest has no votes or
  /// SkeletonPipelineOptions::votes is off.
  std::vector<PersonVotes> votes;
  core::LabelImage masks;  ///< 0 background, k = person k (what skeletons are built from)
  int num_people = 0;
  std::vector<Skeleton> skeletons;  ///< ordered by id
  StageTimes times;
  bool presegmented = false;
};

class SkeletonPipeline {
 public:
  /// `forest` must outlive the pipeline and have the paper's 31 parts (Create checks).
  static core::Result<std::unique_ptr<SkeletonPipeline>> Create(const core::Forest& forest,
                                                                const SkeletonPipelineOptions& options);
  /// Runs one frame; `out` storage is reused between frames.
  void Process(const Frame& frame, SkeletonFrame* out);
  /// The calibration table in use (the forest's, if measured for this proposal method), or null.
  const core::ConfidenceCalibration* calibration() const { return calibration_; }
  /// Where the proposal parameters come from (core::DescribeProposalParamsSource).
  core::ProposalParamsSource params_source() const { return params_source_; }
  const SkeletonTracker& tracker() const { return tracker_; }
  /// Non-empty after a frame whose camera needed the forest's offsets rescaled: says by how much.
  const std::string& rescale_note() const { return rescale_note_; }

 private:
  SkeletonPipeline(const core::Forest& forest, const SkeletonPipelineOptions& options);
  const core::Forest& forest_;
  SkeletonPipelineOptions options_;
  ProposalOptions proposal_options_;
  core::ProposalParamsSource params_source_;
  const core::ConfidenceCalibration* calibration_ = nullptr;
  SkeletonTracker tracker_;
  std::optional<core::Forest> rescaled_;
  double rescaled_fx_ = 0, rescaled_fy_ = 0;
  std::string rescale_note_;
};

}  // namespace poseforest::runtime
