#include "runtime/skeleton_pipeline.h"

#include <chrono>
#include <cstdio>

#include "runtime/camera_model.h"

namespace poseforest::runtime {
namespace {
double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

core::Result<std::unique_ptr<SkeletonPipeline>> SkeletonPipeline::Create(
    const core::Forest& forest, const SkeletonPipelineOptions& options) {
  if (const std::string differs = forest.TaxonomyDifference(); !differs.empty())
    return core::Status(core::ErrorCode::kInvalidArgument,
                        "skeletons need a forest with the paper's 31-part taxonomy (" + differs + ")");
  return std::unique_ptr<SkeletonPipeline>(new SkeletonPipeline(forest, options));
}

SkeletonPipeline::SkeletonPipeline(const core::Forest& forest, const SkeletonPipelineOptions& options)
    : forest_(forest), options_(options), tracker_(options.skeleton) {
  proposal_options_.method = options.method;
  const auto params = forest.ProposalParamsFor(options.method == ProposalMethod::kFastClustering);
  proposal_options_.params = params.params;
  params_source_ = params.source;
  proposal_options_.num_threads = options.num_threads;
  if (options.segment == SegmentMode::kOn) options_.segmentation.presegmented = false;
  calibration_ = forest.CalibrationFor(options.method == ProposalMethod::kFastClustering);
}

void SkeletonPipeline::Process(const Frame& frame, SkeletonFrame* out) {
  const auto& cam = frame.camera.intrinsics;
  const core::Forest* forest = &forest_;
  if (!SameFocalLength(forest_, cam.fx, cam.fy)) {
    if (!rescaled_ || rescaled_fx_ != cam.fx || rescaled_fy_ != cam.fy) {
      rescaled_ = ForestForFocalLength(forest_, cam.fx, cam.fy);
      rescaled_fx_ = cam.fx, rescaled_fy_ = cam.fy;
      char buf[160];
      std::snprintf(buf, sizeof buf,
                    "the forest was trained for fx %.1f fy %.1f; offsets rescaled by %.4f x %.4f",
                    double(forest_.training_fx), double(forest_.training_fy), cam.fx / forest_.training_fx,
                    cam.fy / forest_.training_fy);
      rescale_note_ = buf;
    }
    forest = &*rescaled_;
  }
  out->times = {};
  auto t0 = std::chrono::steady_clock::now();
  out->depth = &frame.depth;
  out->presegmented = true;
  if (options_.segment != SegmentMode::kOff) {
    SegmentPeople(frame.depth, cam, options_.segmentation, &out->segmentation);
    out->presegmented = out->segmentation.presegmented;
    if (!out->presegmented) out->depth = &out->segmentation.depth;
  }
  out->times.segment_ms = MsSince(t0);

  t0 = std::chrono::steady_clock::now();
  ClassifyOptions classify;
  classify.num_threads = options_.num_threads;
  classify.want_foreground_distributions = true;
  classify.want_foreground_leaves = options_.votes && forest->offset_votes.has_value();
  classify.pixel_stride = options_.pixel_stride;
  Classifier(*forest).Classify(*out->depth, classify, &out->classification);
  out->times.classify_ms = MsSince(t0);

  t0 = std::chrono::steady_clock::now();
  proposal_options_.camera = cam;
  out->proposals = ProposeJointsFromClassification(*out->depth, out->classification, proposal_options_);
  out->times.proposals_ms = MsSince(t0);

  t0 = std::chrono::steady_clock::now();
  if (!out->presegmented) {
    out->masks = out->segmentation.labels;
    out->num_people = int(out->segmentation.people.size());
  } else {
    // Pre-segmented (or segmentation off): everything with depth is one person.
    const core::DepthImage& d = *out->depth;
    out->masks = core::LabelImage(d.width, d.height, 0);
    bool any = false;
    for (size_t i = 0; i < d.pixels.size(); ++i)
      if (d.pixels[i]) out->masks.pixels[i] = 1, any = true;
    out->num_people = any ? 1 : 0;
  }
  out->times.skeletons_ms = MsSince(t0);
  t0 = std::chrono::steady_clock::now();
  out->votes.clear();
  if (options_.votes && forest->offset_votes) {
    VoteOptions vo = options_.vote_options;
    if (vo.threads <= 0) vo.threads = options_.num_threads;
    out->votes = CastVotes(*forest, *out->depth, out->masks, out->num_people, cam, vo, &out->classification);
  }
  out->times.votes_ms = MsSince(t0);
  t0 = std::chrono::steady_clock::now();
  auto skeletons = BuildSkeletons(out->proposals, out->masks, out->num_people, *out->depth, cam, calibration_,
                                  options_.skeleton, out->votes.empty() ? nullptr : &out->votes,
                                  forest->tracking_model ? &*forest->tracking_model : nullptr);
  out->skeletons = tracker_.Update(std::move(skeletons), frame.timestamp_s, cam);
  out->times.skeletons_ms += MsSince(t0);
}

}  // namespace poseforest::runtime
