#pragma once
// Accuracy of a forest on labelled frames (section 4): the confusion matrix between
// ground-truth part and most likely inferred part over body pixels, and the average per-class
// accuracy = mean of its row-normalized diagonal; and the joint average precision of the joint
// proposals (mean shift, the fast clustering, and Fig. 7's upper bound: mean shift on the
// ground-truth parts), counted against every person's joints.

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/image_source.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"
#include "runtime/joint_metrics.h"
#include "runtime/skeleton.h"
#include "runtime/proposal_tuning.h"

namespace poseforest::engine {

struct ConfusionMatrix {
  int num_parts = core::kNumParts;
  std::vector<uint64_t> counts;  ///< [truth * num_parts + predicted], pixels

  ConfusionMatrix() : counts(size_t(core::kNumParts) * core::kNumParts, 0) {}
  uint64_t TruthTotal(int part) const;
  /// Fraction of pixels of `part` classified as `part`; NaN if the part never occurs.
  double PartAccuracy(int part) const;
  /// Mean of PartAccuracy over parts that occur (the paper's metric).
  double AveragePerClassAccuracy() const;
  /// Fraction of all body pixels classified correctly.
  double PixelAccuracy() const;
  int PartsPresent() const;
  void Add(const ConfusionMatrix& other);
};

struct EvalOptions {
  int num_images = 50;
  uint64_t first_index = 0;  ///< frames first_index .. first_index + num_images - 1
  int threads = 0;           ///< 0 = all cores
};

/// Classifies every frame with runtime::Classifier and accumulates the confusion matrix over
/// body pixels (depth > 0 and a part label). Frames are independent of thread count.
core::Result<ConfusionMatrix> EvaluateForest(const core::Forest& forest, const SourceSpec& source,
                                             const EvalOptions& options);

/// The per-part accuracy table and the confusion matrix (percent of each truth row) as text.
std::string FormatAccuracyTable(const ConfusionMatrix& m);
std::string FormatConfusionText(const ConfusionMatrix& m);
/// The row-normalized confusion matrix as an RGB picture (cell_px square cells, white = 100%,
/// diagonal tinted green, a border between parts).
core::Status WriteConfusionPng(const ConfusionMatrix& m, const std::string& path, int cell_px = 16);

/// A labelled frame and the ground-truth joints of each person in it.
struct EvalFrame {
  core::DepthImage depth;
  core::LabelImage labels;
  std::vector<runtime::PersonJoints> people;  ///< empty when the source has no joints
  /// Ground-truth person masks (0 = none, k = people[k-1]); empty when the source has none.
  core::LabelImage person_masks;
};

/// Labelled frames with joints: rendered (the renderer's joints), a `poseforest render` folder
/// (joints_%06d.json next to depth/labels) or procedural (no joints). One instance per thread.
class EvalFrameSource {
 public:
  virtual ~EvalFrameSource() = default;
  virtual core::Result<EvalFrame> Frame(uint64_t index) = 0;
  /// Whether frames carry ground-truth joints (joint AP is possible).
  virtual bool has_joints() const = 0;
  /// Distinct frames, or 0 when unbounded.
  virtual uint64_t size() const = 0;
  virtual std::string Describe() const = 0;
  /// Whether frames carry ground-truth person masks (segmentation can be scored).
  virtual bool has_masks() const { return false; }
  /// The camera the frames were taken with (a render folder's camera.txt; Kinect v1 otherwise).
  virtual core::CameraIntrinsics camera() const { return core::CameraIntrinsics::KinectV1(); }
};

/// `people` > 0 renders exactly that many people per frame (rendered sources only; others
/// refuse it with InvalidArgument); 0 keeps the source's own setting.
core::Result<std::unique_ptr<EvalFrameSource>> MakeEvalFrameSource(const SourceSpec& source, int people = 0);

/// Reads joints_%06d.json as `poseforest render` writes it. Errors name the file.
core::Result<std::vector<runtime::PersonJoints>> ReadJointsJson(const std::string& path);

struct JointEvalOptions {
  int num_images = 50;
  uint64_t first_index = 0;
  int threads = 0;          ///< 0 = all cores
  int people = 0;           ///< see MakeEvalFrameSource
  /// Classify and propose from every pixel_stride-th pixel in x and y only
  /// (runtime::ClassifyOptions::pixel_stride, as `live --pixel-stride`); 1 = every pixel.
  int pixel_stride = 1;
  /// The skeleton uses the forest's offset votes (format 1.5) when it has them.
  bool votes = true;
  /// The skeleton's tracked decision is the forest's learned model (format 1.6) when it has one.
  bool tracking_model = true;
  /// With it, "tracked" is the model's seen decision (format 1.8) when the forest has one.
  bool seen_model = true;
  /// How the skeleton (the `skeleton accuracy` table) picks its joints (runtime::SkeletonFit);
  /// unset: as `live` does by default (runtime::ResolveSkeletonFit).
  std::optional<runtime::SkeletonFit> skeleton_fit;
  float agree_radius_m = runtime::SkeletonOptions{}.agree_radius_m;  ///< SkeletonOptions::agree_radius_m
  float track_probability = runtime::SkeletonOptions{}.track_probability;  ///< SkeletonOptions'
  float seen_probability = runtime::SkeletonOptions{}.seen_probability;    ///< SkeletonOptions'
  bool fast = true;         ///< also the fast clustering
  bool upper_bound = true;  ///< also mean shift on the ground-truth parts
  /// Proposal parameters of mean shift (and the upper bound) and of the fast clustering; unset =
  /// the forest's for each method (core::Forest::ProposalParamsFor).
  std::optional<core::ProposalParams> params;
  std::optional<core::ProposalParams> fast_params;
  float distance_m = 0.1f;  ///< the AP's D
  /// Segmentation: kAuto scores it when the frames have person masks (a render folder with
  /// mask_%06d.png), kOn requires masks, kOff never.
  enum class Segment { kAuto, kOn, kOff } segment = Segment::kAuto;
  /// Rescale the forest's offsets to the frames' focal length when it differs from the forest's
  /// training focal length (runtime::ForestForFocalLength); false only to measure what that buys.
  bool rescale = true;
  std::function<void(int done, int total)> progress;
};

/// How runtime::SegmentPeople did on one ground-truth person.
struct PersonSegmentation {
  int frame = 0;   ///< frame index
  int person = 0;  ///< 1-based, the order of the frame's joints
  int pixels = 0;  ///< ground-truth visible pixels
  double iou = 0;  ///< best IoU over the segmented people (0 when none overlaps)
};

/// The skeleton's own accuracy (`live`'s output: one position per joint, tracked or not), on
/// frames with exactly one person (the rendered person's mask is every pixel with depth). Per
/// joint: how often it was tracked within D of the truth when visible, and how often "not
/// tracked" was right (the joint was not visible: occluded or out of the picture).
struct SkeletonAccuracy {
  int frames = 0;  ///< one-person frames scored
  runtime::SkeletonFit fit = runtime::SkeletonFit::kKinematic;  ///< the fit that chose the positions
  std::array<int, core::kNumJoints> visible{}, tracked_within{}, tracked{}, tracked_right{}, untracked{},
      untracked_invisible{};
  /// Visible and the skeleton's position (tracked or not) within D: what a better tracked
  /// decision could reach.
  std::array<int, core::kNumJoints> found_within{};
  /// Hidden (not visible: occluded or out of the picture) and the position within 0.15 m: a
  /// joint placed where the camera cannot see it (offset votes).
  std::array<int, core::kNumJoints> hidden{}, hidden_within{};
  /// Of those, the joints whose true position projects outside the picture (a head above the
  /// top edge, feet below the bottom one), as against those inside it behind a body part or
  /// another person: the two are placed by different evidence (votes beyond the frame, votes
  /// behind the surface), so each has its own figure.
  std::array<int, core::kNumJoints> hidden_outside{}, hidden_outside_within{};
};

struct Evaluation {
  ConfusionMatrix confusion;
  bool has_joints = false;
  int frames = 0;
  int people = 0;  ///< people summed over frames
  float distance_m = 0.1f;
  bool learned_params = false;                     ///< mean shift ran with the forest's learned set
  bool ran_fast = false, ran_upper_bound = false;  ///< which of the three were scored
  core::ProposalParams params;                     ///< mean shift's (and the upper bound's)
  core::ProposalParams fast_params;                ///< the fast clustering's
  /// Where each set came from: the forest (core::Forest::ProposalParamsFor) or, when given,
  /// JointEvalOptions.
  core::ProposalParamsSource params_source = core::ProposalParamsSource::kPaperMeans;
  core::ProposalParamsSource fast_params_source = core::ProposalParamsSource::kPaperMeans;
  bool params_given = false, fast_params_given = false;
  runtime::JointApEvaluator mean_shift, fast, upper_bound;
  double classify_ms = 0, mean_shift_ms = 0, fast_ms = 0;  ///< summed over frames
  /// The frames' camera; the forest's offsets were rescaled when its focal length differs.
  core::CameraIntrinsics camera = core::CameraIntrinsics::KinectV1();
  bool rescaled = false;

  /// Segmentation (JointEvalOptions::segment): each ground-truth person's IoU, and the forest on
  /// the frames masked by the ground truth ("clean": perfect segmentation) and by
  /// runtime::SegmentPeople with its default options. `confusion`, `mean_shift` above are on the
  /// frames as they are (clutter classified too).
  bool segmented = false;
  std::vector<PersonSegmentation> segmentation;
  int frames_right_count = 0;  ///< frames where segmentation found as many people as are visible
  ConfusionMatrix clean_confusion, segmented_confusion;
  runtime::JointApEvaluator clean_mean_shift, segmented_mean_shift;
  double segment_ms = 0;
  double MeanIoU() const;
  SkeletonAccuracy skeleton;
  bool calibrated = false;  ///< the skeleton's confidence came from the forest's table (JCAL)
};

/// Classifies every frame (confusion matrix over body pixels) and, when the source has joints
/// and the forest the 31-part taxonomy, proposes joints and scores them (section 4's AP).
core::Result<Evaluation> EvaluateForestJoints(const core::Forest& forest, const SourceSpec& source,
                                              const JointEvalOptions& options);

/// Per-joint AP table (mean shift, fast, ground-truth parts), mAP of each, the ratio
/// inferred / upper bound, and the parameters used.
std::string FormatJointApTable(const Evaluation& e);
/// The skeleton table: per joint, tracked within D when visible, precision of "tracked", how
/// often "not tracked" was right; and the means.
std::string FormatSkeletonTable(const Evaluation& e);
/// Writes DIR/pr_joints.png (precision-recall curves of each joint, the three methods) and
/// DIR/pr_mean.png (the mAP-level curve: mean interpolated precision over joints per recall).
core::Status WritePrCurves(const Evaluation& e, const std::string& dir);

/// A frame source named on the command line, and how many frames it suggests.
struct NamedSource {
  SourceSpec source;
  int num_images = 50;  ///< a job's test_set.num_images, a folder's frame count, else 50
};
/// Which source of a job config a JOB.textproto argument means.
enum class JobSource { kTestSet, kTraining };
/// Resolves a SET argument: DIR (a `poseforest render` folder), JOB.textproto (its test_set or
/// its training source) or procedural:SEED. Errors say which form was expected.
core::Result<NamedSource> ResolveSourceArgument(const std::string& set, JobSource which);

/// Renders `num_images` validation frames (from `first_index`), classifies them and keeps the
/// inferred joint probabilities and the ground truth: the input of runtime::TuneProposalParams.
/// Frames of another focal length than the forest's (a render folder's camera.txt) are classified
/// with its offsets rescaled; `camera`, when given, receives the frames' camera (for the proposals).
core::Result<std::vector<runtime::ValidationFrame>> MakeValidationFrames(
    const core::Forest& forest, const SourceSpec& source, int num_images, uint64_t first_index, int threads,
    int people, const std::function<void(int done, int total)>& progress = {},
    core::CameraIntrinsics* camera = nullptr);

}  // namespace poseforest::engine
