#include "engine/evaluation.h"

#include <omp.h>

// Scoring a forest on a test set: part confusion, joint AP per proposal method, the skeleton
// `live` builds, segmentation. The frame sources are in eval_sources.cpp, the tables and
// figures in eval_report.cpp.

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "runtime/camera_model.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/joint_proposals.h"
#include "runtime/segmentation.h"
#include "runtime/skeleton.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

uint64_t ConfusionMatrix::TruthTotal(int part) const {
  uint64_t n = 0;
  for (int p = 0; p < num_parts; ++p) n += counts[size_t(part * num_parts + p)];
  return n;
}

double ConfusionMatrix::PartAccuracy(int part) const {
  const uint64_t n = TruthTotal(part);
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  return double(counts[size_t(part * num_parts + part)]) / double(n);
}

double ConfusionMatrix::AveragePerClassAccuracy() const {
  double sum = 0;
  int k = 0;
  for (int c = 0; c < num_parts; ++c) {
    const double a = PartAccuracy(c);
    if (std::isnan(a)) continue;
    sum += a;
    ++k;
  }
  return k ? sum / k : std::numeric_limits<double>::quiet_NaN();
}

double ConfusionMatrix::PixelAccuracy() const {
  uint64_t right = 0, all = 0;
  for (int c = 0; c < num_parts; ++c) {
    right += counts[size_t(c * num_parts + c)];
    all += TruthTotal(c);
  }
  return all ? double(right) / double(all) : std::numeric_limits<double>::quiet_NaN();
}

int ConfusionMatrix::PartsPresent() const {
  int k = 0;
  for (int c = 0; c < num_parts; ++c) k += TruthTotal(c) > 0;
  return k;
}

void ConfusionMatrix::Add(const ConfusionMatrix& other) {
  for (size_t i = 0; i < counts.size(); ++i) counts[i] += other.counts[i];
}

core::Result<ConfusionMatrix> EvaluateForest(const core::Forest& forest, const SourceSpec& source,
                                             const EvalOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return core::Status(
        core::ErrorCode::kInvalidArgument,
        "forest has " + std::to_string(forest.num_parts) + " parts; evaluation needs the 31-part taxonomy");
  auto src = MakeImageSource(source);
  if (!src.ok()) return src.status();
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  runtime::Classification out;
  ConfusionMatrix m;
  for (int i = 0; i < options.num_images; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    classifier.Classify(frame->depth, copt, &out);
    for (size_t p = 0; p < frame->depth.pixels.size(); ++p) {
      const uint8_t truth = frame->labels.pixels[p];
      if (frame->depth.pixels[p] == 0 || truth >= core::kNumParts) continue;
      const uint8_t pred = out.labels.pixels[p];
      if (pred >= core::kNumParts) continue;  // cannot happen for a foreground pixel
      ++m.counts[size_t(truth) * core::kNumParts + pred];
    }
  }
  return m;
}

namespace {
bool HasJointTaxonomy(const core::Forest& forest) {
  return forest.num_parts == core::kNumParts && forest.part_names == core::Forest::DefaultPartNames();
}
void AddConfusion(const EvalFrame& frame, const core::LabelImage& predicted, ConfusionMatrix* m) {
  for (size_t p = 0; p < frame.depth.pixels.size(); ++p) {
    const uint8_t truth = frame.labels.pixels[p];
    if (frame.depth.pixels[p] == 0 || truth >= core::kNumParts) continue;
    const uint8_t pred = predicted.pixels[p];
    if (pred >= core::kNumParts) continue;
    ++m->counts[size_t(truth) * core::kNumParts + pred];
  }
}
double MsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

// The frame with every pixel outside `keep` (nonzero) set to 0: what a segmentation hands the
// forest.
EvalFrame Masked(const EvalFrame& frame, const core::LabelImage& keep) {
  EvalFrame m;
  m.depth = frame.depth;
  m.labels = frame.labels;
  for (size_t p = 0; p < m.depth.pixels.size(); ++p)
    if (keep.pixels[p] == 0) m.depth.pixels[p] = 0;
  return m;
}

// Segmentation of one frame against its ground-truth masks (IoU per person), and the forest on
// the frame masked by the truth ("clean") and by the segmentation.
void ScoreSegmentation(const runtime::Classifier& classifier, const runtime::ClassifyOptions& copt,
                       const runtime::ProposalOptions& ms, bool joints, int index, const EvalFrame& frame,
                       runtime::SegmentationResult* seg, Evaluation* e) {
  const auto t = std::chrono::steady_clock::now();
  runtime::SegmentationOptions so;
  so.presegmented = false;  // a frame of one person alone would pass unchanged anyway
  runtime::SegmentPeople(frame.depth, e->camera, so, seg);
  e->segment_ms += MsSince(t);
  int truth_people = 0;
  std::vector<int> pixels(256, 0);
  for (uint8_t k : frame.person_masks.pixels) ++pixels[k];
  for (int k = 1; k < 256; ++k) {
    if (pixels[size_t(k)] == 0) continue;
    ++truth_people;
    PersonSegmentation p{index, k, pixels[size_t(k)], 0.0};
    for (int j = 1; j <= int(seg->people.size()); ++j)
      p.iou = std::max(p.iou, runtime::MaskIoU(frame.person_masks, k, seg->labels, j));
    e->segmentation.push_back(p);
  }
  e->frames_right_count += truth_people == int(seg->people.size());
  runtime::Classification out;
  for (int pass = 0; pass < 2; ++pass) {
    const EvalFrame m = Masked(frame, pass == 0 ? frame.person_masks : seg->labels);
    classifier.Classify(m.depth, copt, &out);
    AddConfusion(m, out.labels, pass == 0 ? &e->clean_confusion : &e->segmented_confusion);
    if (joints)
      (pass == 0 ? e->clean_mean_shift : e->segmented_mean_shift)
          .AddFrame(runtime::ProposeJointsFromClassification(m.depth, out, ms), frame.people);
  }
}
// Whether a point (camera frame, metres) projects into a width x height picture: behind the
// camera or beyond an edge it does not.
bool InPicture(const Eigen::Vector3f& p, const core::CameraIntrinsics& camera, int width, int height) {
  if (!(p.z() > 0)) return false;
  return runtime::PixelInImage(camera.Project(p.cast<double>()).cast<float>(), width, height);
}

// The skeleton of a one-person frame as `live` builds it, scored against the person's joints.
void ScoreSkeleton(const runtime::Classifier& classifier, const runtime::Classification& out,
                   const runtime::FrameProposals& proposals, const EvalFrame& frame,
                   const core::CameraIntrinsics& camera, const core::ConfidenceCalibration* calibration,
                   const JointEvalOptions& options, SkeletonAccuracy* skeleton) {
  // The skeleton as `live` builds it: the person's mask is the ground-truth mask when the
  // frames have one (clutter), else every pixel with depth.
  const bool has_mask =
      frame.person_masks.width == frame.depth.width && frame.person_masks.height == frame.depth.height;
  core::LabelImage mask(frame.depth.width, frame.depth.height, 0);
  for (size_t k = 0; k < mask.pixels.size(); ++k)
    mask.pixels[k] = has_mask ? (frame.person_masks.pixels[k] == 1) : (frame.depth.pixels[k] ? 1 : 0);
  runtime::SkeletonOptions so;
  so.fit = options.skeleton_fit;
  so.use_tracking_model = options.tracking_model;
  so.use_seen_model = options.seen_model;
  const auto& model = classifier.forest().tracking_model;
  skeleton->fit = runtime::ResolveSkeletonFit(so, so.use_tracking_model && model ? &*model : nullptr);
  so.agree_radius_m = options.agree_radius_m;
  so.track_probability = options.track_probability;
  so.seen_probability = options.seen_probability;
  // The forest's offset votes (format 1.5), when it has them and they are not turned off.
  std::vector<runtime::PersonVotes> votes;
  if (options.votes && classifier.forest().offset_votes)
    votes = runtime::CastVotes(classifier.forest(), frame.depth, mask, 1, camera, {}, &out);
  const auto skeletons = runtime::BuildSkeletons(proposals, mask, 1, frame.depth, camera, calibration, so,
                                                 votes.empty() ? nullptr : &votes, model ? &*model : nullptr);
  if (!skeletons.empty()) {
    auto& acc = *skeleton;
    ++acc.frames;
    const auto& truth = frame.people[0];
    for (int j = 0; j < core::kNumJoints; ++j) {
      const auto& joint = skeletons[0].joints[size_t(j)];
      const bool near =
          joint.found && (joint.position_m - truth.position[size_t(j)]).norm() <= options.distance_m;
      const bool visible = truth.visible[size_t(j)];
      acc.visible[size_t(j)] += visible;
      acc.tracked_within[size_t(j)] += visible && joint.tracked && near;
      acc.found_within[size_t(j)] += visible && near;
      acc.hidden[size_t(j)] += !visible;
      const bool hidden_within =
          !visible && joint.found && (joint.position_m - truth.position[size_t(j)]).norm() <= 0.15f;
      acc.hidden_within[size_t(j)] += hidden_within;
      if (!visible && !InPicture(truth.position[size_t(j)], camera, frame.depth.width, frame.depth.height)) {
        ++acc.hidden_outside[size_t(j)];
        acc.hidden_outside_within[size_t(j)] += hidden_within;
      }
      acc.tracked[size_t(j)] += joint.tracked;
      acc.tracked_right[size_t(j)] += joint.tracked && near;
      acc.untracked[size_t(j)] += !joint.tracked;
      acc.untracked_invisible[size_t(j)] += !joint.tracked && !visible;
    }
  }
}

}  // namespace

double Evaluation::MeanIoU() const {
  if (segmentation.empty()) return 0;
  double sum = 0;
  for (const PersonSegmentation& p : segmentation) sum += p.iou;
  return sum / double(segmentation.size());
}

Result<Evaluation> EvaluateForestJoints(const core::Forest& forest, const SourceSpec& source,
                                        const JointEvalOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return Status(ErrorCode::kInvalidArgument, "forest has " + std::to_string(forest.num_parts) +
                                                   " parts; evaluation needs the 31-part taxonomy");
  auto src = MakeEvalFrameSource(source, options.people);
  if (!src.ok()) return src.status();
  Evaluation e{.mean_shift = runtime::JointApEvaluator(options.distance_m),
               .fast = runtime::JointApEvaluator(options.distance_m),
               .upper_bound = runtime::JointApEvaluator(options.distance_m),
               .clean_mean_shift = runtime::JointApEvaluator(options.distance_m),
               .segmented_mean_shift = runtime::JointApEvaluator(options.distance_m)};
  using Segment = JointEvalOptions::Segment;
  if (options.segment == Segment::kOn && !(*src)->has_masks())
    return Status(ErrorCode::kInvalidArgument,
                  (*src)->Describe() +
                      ": has no ground-truth person masks (render with --clutter, "
                      "--occluders or --masks)");
  e.segmented = options.segment != Segment::kOff && (*src)->has_masks();
  // Frames of another focal length: the forest's offsets rescaled (runtime/camera_model.h).
  e.camera = (*src)->camera();
  e.rescaled = options.rescale && !runtime::SameFocalLength(forest, e.camera.fx, e.camera.fy);
  const core::Forest scaled =
      e.rescaled ? runtime::ForestForFocalLength(forest, e.camera.fx, e.camera.fy) : core::Forest();
  const core::Forest& model = e.rescaled ? scaled : forest;
  e.distance_m = options.distance_m;
  e.ran_fast = options.fast;
  e.ran_upper_bound = options.upper_bound;
  e.has_joints = (*src)->has_joints() && HasJointTaxonomy(forest);
  // Each method with its own set (core::Forest::ProposalParamsFor), unless given.
  const auto ms_choice = forest.ProposalParamsFor(false), fast_choice = forest.ProposalParamsFor(true);
  e.params_given = options.params.has_value();
  e.params = e.params_given ? *options.params : ms_choice.params;
  e.params_source = ms_choice.source;
  e.learned_params = !e.params_given && ms_choice.source == core::ProposalParamsSource::kLearned;
  e.fast_params_given = options.fast_params.has_value();
  e.fast_params = e.fast_params_given ? *options.fast_params : fast_choice.params;
  e.fast_params_source = fast_choice.source;
  runtime::Classifier classifier(model);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  // The compact per-foreground-pixel sums (what the proposals read; the confusion matrix uses
  // the classifier's argmax labels, computed from the same sums).
  copt.want_foreground_distributions = e.has_joints;
  copt.want_foreground_leaves = e.has_joints && options.votes && classifier.forest().offset_votes.has_value();
  copt.pixel_stride = options.pixel_stride;
  runtime::ProposalOptions ms;
  ms.params = e.params;
  ms.num_threads = options.threads;
  ms.camera = e.camera;
  runtime::ProposalOptions fast = ms;
  fast.method = runtime::ProposalMethod::kFastClustering;
  fast.params = e.fast_params;
  // The skeleton's confidence: the forest's calibration if measured for mean shift.
  const core::ConfidenceCalibration* calibration = forest.CalibrationFor(/*fast_clustering=*/false);
  e.calibrated = calibration != nullptr;
  runtime::Classification out;
  runtime::SegmentationResult seg;
  for (int i = 0; i < options.num_images; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    if (e.segmented && (frame->person_masks.width != frame->depth.width ||
                        frame->person_masks.height != frame->depth.height))
      return Status(ErrorCode::kDataLoss, (*src)->Describe() + ": frame " +
                                              std::to_string(options.first_index + uint64_t(i)) +
                                              " has no person mask of the depth's size");
    auto t = std::chrono::steady_clock::now();
    classifier.Classify(frame->depth, copt, &out);
    e.classify_ms += MsSince(t);
    AddConfusion(*frame, out.labels, &e.confusion);
    ++e.frames;
    if (e.has_joints) {
      e.people += int(frame->people.size());
      t = std::chrono::steady_clock::now();
      const auto proposals = runtime::ProposeJointsFromClassification(frame->depth, out, ms);
      e.mean_shift.AddFrame(proposals, frame->people);
      e.mean_shift_ms += MsSince(t);
      if (frame->people.size() == 1)
        ScoreSkeleton(classifier, out, proposals, *frame, ms.camera, calibration, options, &e.skeleton);
      if (options.fast) {
        t = std::chrono::steady_clock::now();
        e.fast.AddFrame(runtime::ProposeJointsFromClassification(frame->depth, out, fast), frame->people);
        e.fast_ms += MsSince(t);
      }
      if (options.upper_bound)
        e.upper_bound.AddFrame(
            runtime::ProposeJoints(frame->depth,
                                   runtime::ProbabilitiesFromLabels(frame->depth, frame->labels), ms),
            frame->people);
    }
    if (e.segmented) ScoreSegmentation(classifier, copt, ms, e.has_joints, i, *frame, &seg, &e);
    if (options.progress) options.progress(i + 1, options.num_images);
  }
  return e;
}

Result<std::vector<runtime::ValidationFrame>> MakeValidationFrames(
    const core::Forest& forest, const SourceSpec& source, int num_images, uint64_t first_index, int threads,
    int people, const std::function<void(int done, int total)>& progress, core::CameraIntrinsics* camera) {
  if (!HasJointTaxonomy(forest))
    return Status(ErrorCode::kInvalidArgument,
                  "the forest has " + std::to_string(forest.num_parts) +
                      " parts; joint proposals need the paper's 31-part taxonomy");
  auto src = MakeEvalFrameSource(source, people);
  if (!src.ok()) return src.status();
  if (!(*src)->has_joints())
    return Status(ErrorCode::kInvalidArgument,
                  (*src)->Describe() +
                      ": has no ground-truth joints (use rendered frames or a `poseforest render` folder)");
  // Frames of another focal length (a render folder's camera.txt): the forest rescaled, as eval does.
  const core::CameraIntrinsics cam = (*src)->camera();
  if (camera) *camera = cam;
  const bool rescale = !runtime::SameFocalLength(forest, cam.fx, cam.fy);
  const core::Forest scaled = rescale ? runtime::ForestForFocalLength(forest, cam.fx, cam.fy) : core::Forest();
  runtime::Classifier classifier(rescale ? scaled : forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = threads;
  copt.want_foreground_distributions = true;  // compact sums: ProbabilitiesFromClassification reads them
  runtime::Classification out;
  std::vector<runtime::ValidationFrame> frames;
  frames.reserve(size_t(num_images));
  for (int i = 0; i < num_images; ++i) {
    auto frame = (*src)->Frame(first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    classifier.Classify(frame->depth, copt, &out);
    runtime::ValidationFrame v;
    v.probs = runtime::ProbabilitiesFromClassification(frame->depth, out, threads);
    v.depth = std::move(frame->depth);
    v.people = std::move(frame->people);
    frames.push_back(std::move(v));
    if (progress) progress(i + 1, num_images);
  }
  return frames;
}

}  // namespace poseforest::engine
