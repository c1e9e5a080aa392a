// poseforest eval: per-class accuracy and joint average precision of a forest on held-out
// labelled frames.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <filesystem>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "engine/evaluation.h"
#include "engine/job_spec.h"
#include "engine/real_frames.h"
#include "runtime/camera_model.h"
#include "runtime/core/forest_format.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "runtime/skeleton_pipeline.h"

namespace poseforest::apps::commands {
namespace {
constexpr const char* kUsage = R"(usage: poseforest eval --forest FOREST.pff --test-set SET [options]
       poseforest eval --forest FOREST.pff --real-labels LABELS.json [--png-dir DIR] [options]

Reports the paper's two metrics (section 4) on held-out labelled frames:
  * joint average precision: the forest's joint proposals (mean shift, and the fast bottom-up
    clustering) are ranked by confidence over all frames; the first proposal within D = 0.1 m of
    a visible ground-truth joint is a true positive, every other one a false positive; AP per
    joint, mAP over the 16 joints, and Fig. 7's upper bound: mean shift on the ground-truth part
    labels; the ratio inferred / upper bound. With several people in a frame, proposals are
    counted against each person's joints. Uses the proposal parameters stored in the forest
    (`poseforest tune-joints`), else the paper's means. Needs frames with joints: rendered, or
    a `poseforest render` folder (joints_%06d.json);
  * the average per-class accuracy: the mean of the diagonal of the row-normalized confusion
    matrix between ground-truth and most likely inferred part; the per-part table and the
    confusion matrix as text (and as a picture with --png).

With --real-labels, the skeletons `live` would give on hand-labelled real depth frames are
scored instead: LABELS.json names the camera and, per frame, a depth file beside it (anything
`poseforest frames` reads: raw uint16 mm of the camera's size, a depth PNG, .npy) and the labelled
joints (the format of the shared data's real/skeltrack_kinect_depth/joint_labels.json; its
JOINT_LABELS.md says how they were made). A joint is right when the skeleton tracks it within
0.10 m of the labelled surface point moved 0.04 m along the camera ray. Per joint and per group:
labelled, tracked, tracked within 0.10 m, the median 2D error of tracked joints (pixels), "found
within": the skeleton's position within 0.10 m, tracked or not (the confidence rules aside), and
"any within 0.10 m": that or any of the joint's proposals on the person within 0.10 m (did the
forest find it at all). The same pipeline as `live`: people
segmentation, the forest's tuned proposal parameters and calibration, the skeleton's rules, and
live's pixel stride 2 unless --pixel-stride says otherwise. --png-dir DIR writes one picture per
frame (depth | parts | skeleton, each label a cross: green when right, red otherwise, with a line
to where the skeleton put the joint).

SET is one of:
  DIR                a folder written by `poseforest render` (depth/labels/joints_%06d.*; its
                     camera.txt says the camera, and a forest trained at another focal length
                     has its offsets rescaled)
  JOB.textproto      a training job config: its test_set { } is used (held-out mocap clips)
  procedural:SEED    procedural frames (no joints: accuracy only)

options:
  --forest PATH     forest file (required)
  --test-set SET    (required)
  --images N        frames to evaluate (default: the job's test_set.num_images, else 50; for a
                    folder at most its frame count)
  --first N         first frame index (default 0)
  --people N        render exactly N people per frame (rendered sets; default: the set's own)
  --method M        joint proposals: both (default), meanshift (skips the fast clustering) or
                    none (accuracy only)
  --pr-png DIR      write precision-recall curves: DIR/pr_joints.png (each joint: mean shift,
                    fast, ground-truth parts) and DIR/pr_mean.png (mean over joints)
  --threads N       threads (0 = all cores, default)
  --pixel-stride N  classify and propose from every N-th pixel in x and y only, as `live
                    --pixel-stride N` (default 1: every pixel); the confusion matrix counts every
                    body pixel (off the grid: its grid pixel's part)
  --png PATH        also write the confusion matrix as an RGB PNG
  --segment M       auto (default): on frames with ground-truth person masks (a folder rendered
                    with --clutter/--occluders/--masks), also score the runtime's people
                    segmentation: IoU per person against the masks, and the forest's mAP and
                    accuracy after segmentation next to those on the frames masked by the
                    ground truth (clean); on: require masks; off: never
  --per-person      list each person's segmentation IoU
  --no-rescale      keep the forest's offsets as trained even when the frames' camera (camera.txt)
                    has another focal length (to measure what the rescaling buys)
  --fit F           how the skeleton picks its joints: greedy (default: each joint's most
                    confident proposal on the person) or kinematic (one fit per person choosing
                    among each joint's proposals with bone lengths; runtime/skeleton.h)
  --no-votes        the skeleton ignores the forest's offset votes (format 1.5, `learn-votes`)
  --no-tracking-model  the skeleton's hand-set tracking rules instead of the forest's learned
                    tracking decision (format 1.6, `learn-votes`; runtime/core/tracking_model.h)
  --agree-radius M  a joint whose part proposal and best vote candidate lie within M metres
                    of each other gets their combined confidence (default 0.1; 0: off;
                    runtime/skeleton.h SkeletonOptions::agree_radius_m)
  --real-labels F   score skeletons on hand-labelled real frames (above) instead of --test-set
  --png-dir DIR     with --real-labels: a picture per frame, DIR/<frame file>.png
  --quiet           no progress lines
  --help            this text
)";
// --fit: how skeletons pick their joints.
bool ParseFit(const Args& args, runtime::SkeletonFit* fit) {
  const std::string f = args.GetOr("fit", "greedy");
  const auto parsed = runtime::SkeletonFitFromName(f);
  if (!parsed) {
    std::fprintf(stderr, "poseforest eval: --fit must be kinematic or greedy (got '%s')\n", f.c_str());
    return false;
  }
  *fit = *parsed;
  return true;
}

// --agree-radius: SkeletonOptions::agree_radius_m.
bool ParseAgreeRadius(const Args& args, float* radius) {
  const std::string v = args.GetOr("agree-radius", "");
  if (v.empty()) return true;
  char* end = nullptr;
  const double r = std::strtod(v.c_str(), &end);
  if (end == v.c_str() || *end != '\0' || !(r >= 0 && r <= 1)) {
    std::fprintf(stderr, "poseforest eval: --agree-radius must be metres in [0, 1] (got '%s')\n", v.c_str());
    return false;
  }
  *radius = float(r);
  return true;
}

// eval --real-labels: the skeletons of `live` scored on hand-labelled frames (engine/real_frames.h).
int EvalRealMain(const Args& args) {
  if (!args.Has("forest") || !args.positional().empty()) {
    std::fprintf(stderr, "poseforest eval: --real-labels needs --forest\n\n%s", kUsage);
    return 2;
  }
  for (const char* o : {"test-set", "images", "first", "people", "pr-png", "png", "segment"})
    if (args.Has(o)) {
      std::fprintf(stderr, "poseforest eval: --%s does not go with --real-labels\n", o);
      return 2;
    }
  const std::string method = args.GetOr("method", "meanshift");
  if (method != "meanshift" && method != "fast") {
    std::fprintf(stderr, "poseforest eval: with --real-labels, --method must be meanshift or fast (got '%s')\n",
                 method.c_str());
    return 2;
  }
  auto threads = args.GetInt("threads", 0, 0, 1024);
  auto pixel_stride = args.GetInt("pixel-stride", 2, 1, 16);  // live's default
  for (const auto* r : {&threads, &pixel_stride})
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", r->status().message().c_str());
      return 2;
    }
  const std::string labels_path = *args.Get("real-labels");
  auto labels = engine::ReadRealLabels(labels_path);
  if (!labels.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", labels.status().ToString().c_str());
    return 1;
  }
  const auto png_dir = args.Get("png-dir");
  if (png_dir) {
    std::error_code ec;
    std::filesystem::create_directories(*png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest eval: %s: cannot create folder: %s\n", png_dir->c_str(), ec.message().c_str());
      return 1;
    }
  }
  auto forest = core::LoadForest(*args.Get("forest"));
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  runtime::SkeletonPipelineOptions options;
  options.segment = runtime::SegmentMode::kAuto;
  options.method =
      method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  options.num_threads = int(*threads);
  options.pixel_stride = int(*pixel_stride);
  if (!ParseFit(args, &options.skeleton.fit)) return 2;
  if (!ParseAgreeRadius(args, &options.skeleton.agree_radius_m)) return 2;
  options.votes = !args.Has("no-votes");
  options.skeleton.use_tracking_model = !args.Has("no-tracking-model");
  runtime::FrameSourceOptions source_options;
  source_options.camera = labels->camera;
  source_options.camera_given = true;
  std::vector<engine::RealFrameOutcome> outcomes;
  for (const engine::RealFrameLabels& f : labels->frames) {
    // A pipeline per frame: the frames are independent stills, not a sequence.
    auto pipeline = runtime::SkeletonPipeline::Create(*forest, options);
    if (!pipeline.ok()) {
      std::fprintf(stderr, "poseforest eval: %s: %s\n", args.Get("forest")->c_str(),
                   pipeline.status().message().c_str());
      return 1;
    }
    auto source = runtime::OpenFrameSource(f.path, source_options);
    runtime::Frame frame;
    core::Result<bool> got = source.ok() ? (*source)->Next(&frame) : core::Result<bool>(source.status());
    if (!got.ok() || !*got) {
      std::fprintf(stderr, "poseforest eval: %s: frame %s: %s\n", labels_path.c_str(), f.file.c_str(),
                   got.ok() ? "no frame in the file" : got.status().ToString().c_str());
      return 1;
    }
    runtime::SkeletonFrame result;
    (*pipeline)->Process(frame, &result);
    const int which = engine::PickLabelledSkeleton(f, result);
    outcomes.push_back(engine::ScoreRealFrame(f, result, which));
    const auto& o = outcomes.back();
    int right = 0, labelled = 0;
    for (const auto& j : o.joints) right += j.right, labelled += j.labelled;
    if (!args.Has("quiet"))
      std::fprintf(stderr, "eval: %s: %zu people, %d of %d labelled joints right\n", f.file.c_str(),
                   result.skeletons.size(), right, labelled);
    if (png_dir) {
      const std::string png = (std::filesystem::path(*png_dir) /
                               (std::filesystem::path(f.file).filename().string() + ".png")).string();
      const runtime::RgbImage fig = engine::RealFramePicture(f, result, o);
      if (auto st = runtime::WriteRgbPng(png, fig.width, fig.height, fig.rgb); !st.ok()) {
        std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
        return 1;
      }
    }
  }
  const engine::RealScore score = engine::SummarizeReal(outcomes);
  std::printf("forest %s on %zu real frames (%s), pixel stride %d, %s\n\n", args.Get("forest")->c_str(),
              labels->frames.size(), labels_path.c_str(), options.pixel_stride,
              method == "fast" ? "fast clustering" : "mean shift");
  std::fputs(engine::FormatRealScore(score).c_str(), stdout);
  if (png_dir) std::printf("pictures: %s/<frame>.png\n", png_dir->c_str());
  const auto& all = score.all();
  std::printf(
      "eval: real frames: %d of %d labelled joints tracked within 0.10 m (%.3f), found within %.3f, any within "
      "0.10 m %.3f\n",
      all.right, all.labelled, all.right_fraction(), all.labelled ? double(all.found_right) / all.labelled : 0.0,
      all.any_fraction());
  return 0;
}

}  // namespace

int EvalMain(int argc, char** argv) {
  Args args({"forest", "test-set", "images", "first", "threads", "png", "people", "method", "pr-png",
             "segment", "pixel-stride", "real-labels", "png-dir", "fit", "agree-radius"},
            {"help", "quiet", "per-person", "no-rescale", "no-votes", "no-tracking-model"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (args.Has("real-labels")) return EvalRealMain(args);
  if (args.Has("png-dir")) {
    std::fprintf(stderr, "poseforest eval: --png-dir needs --real-labels\n");
    return 2;
  }
  if (!args.Has("forest") || !args.Has("test-set") || !args.positional().empty()) {
    std::fprintf(stderr, "poseforest eval: need --forest and --test-set (or --real-labels)\n\n%s", kUsage);
    return 2;
  }
  auto images = args.GetInt("images", -1, 1, 10'000'000);
  auto first = args.GetInt("first", 0, 0, 1L << 40);
  auto threads = args.GetInt("threads", 0, 0, 1024);
  auto people = args.GetInt("people", 0, 1, 8);
  auto pixel_stride = args.GetInt("pixel-stride", 1, 1, 16);
  for (const auto* r : {&images, &first, &threads, &people, &pixel_stride}) {
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", r->status().message().c_str());
      return 2;
    }
  }
  const std::string method = args.GetOr("method", "both");
  if (method != "both" && method != "meanshift" && method != "none") {
    std::fprintf(stderr, "poseforest eval: --method must be both, meanshift or none (got '%s')\n",
                 method.c_str());
    return 2;
  }
  const std::string segment = args.GetOr("segment", "auto");
  if (segment != "auto" && segment != "on" && segment != "off") {
    std::fprintf(stderr, "poseforest eval: --segment must be auto, on or off (got '%s')\n", segment.c_str());
    return 2;
  }
  const std::string set = *args.Get("test-set");
  auto named = engine::ResolveSourceArgument(set, engine::JobSource::kTestSet);
  if (!named.ok()) {
    std::fprintf(stderr, "poseforest eval: --test-set %s\n", named.status().ToString().c_str());
    return named.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  const int num_images = *images > 0 ? int(*images) : named->num_images;
  auto forest = core::LoadForest(*args.Get("forest"));
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  engine::JointEvalOptions eo;
  eo.num_images = num_images;
  eo.first_index = uint64_t(*first);
  eo.threads = int(*threads);
  eo.people = int(*people);
  eo.pixel_stride = int(*pixel_stride);
  if (!ParseFit(args, &eo.skeleton_fit)) return 2;
  if (!ParseAgreeRadius(args, &eo.agree_radius_m)) return 2;
  eo.votes = !args.Has("no-votes");
  eo.tracking_model = !args.Has("no-tracking-model");
  eo.fast = method == "both";
  eo.rescale = !args.Has("no-rescale");
  eo.segment = segment == "on"    ? engine::JointEvalOptions::Segment::kOn
               : segment == "off" ? engine::JointEvalOptions::Segment::kOff
                                  : engine::JointEvalOptions::Segment::kAuto;
  const bool quiet = args.Has("quiet");
  if (!quiet)
    eo.progress = [](int done, int total) {
      if (done % 25 == 0 || done == total) std::fprintf(stderr, "eval: %d / %d frames\n", done, total);
    };
  auto e = engine::EvaluateForestJoints(*forest, named->source, eo);
  if (!e.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", e.status().ToString().c_str());
    return e.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  std::printf("forest %s on %s, %d frames", args.Get("forest")->c_str(), set.c_str(), num_images);
  if (eo.pixel_stride > 1) std::printf(", pixel stride %d", eo.pixel_stride);
  std::printf("\n\n");
  std::fputs(engine::FormatConfusionText(e->confusion).c_str(), stdout);
  std::printf("\n");
  std::fputs(engine::FormatAccuracyTable(e->confusion).c_str(), stdout);
  if (auto png = args.Get("png")) {
    if (auto st = engine::WriteConfusionPng(e->confusion, *png); !st.ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
      return 1;
    }
    std::printf("confusion matrix picture: %s\n", png->c_str());
  }
  if (method != "none") {
    std::printf("\n");
    if (!e->has_joints) {
      std::printf("no joint average precision: %s has no ground-truth joints\n", set.c_str());
    } else {
      std::fputs(engine::FormatJointApTable(*e).c_str(), stdout);
      std::printf("\n");
      std::fputs(engine::FormatSkeletonTable(*e).c_str(), stdout);
      std::printf("ms/frame: classify %.1f, mean shift %.1f", e->classify_ms / e->frames,
                  e->mean_shift_ms / e->frames);
      if (e->ran_fast) std::printf(", fast clustering %.1f", e->fast_ms / e->frames);
      std::printf("\n");
      if (auto dir = args.Get("pr-png")) {
        if (auto st = engine::WritePrCurves(*e, *dir); !st.ok()) {
          std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
          return 1;
        }
        std::printf("precision-recall curves: %s/pr_joints.png, %s/pr_mean.png\n", dir->c_str(),
                    dir->c_str());
      }
    }
  }
  if (!e->rescaled && !runtime::SameFocalLength(*forest, e->camera.fx, e->camera.fy))
    std::printf(
        "\ncamera fx %.1f fy %.1f: the forest (trained for fx %.1f fy %.1f) was NOT rescaled "
        "(--no-rescale)\n",
        e->camera.fx, e->camera.fy, double(forest->training_fx), double(forest->training_fy));
  if (e->rescaled)
    std::printf(
        "\ncamera fx %.1f fy %.1f: the forest (trained for fx %.1f fy %.1f) had its offsets rescaled\n",
        e->camera.fx, e->camera.fy, double(forest->training_fx), double(forest->training_fy));
  if (e->segmented) {
    std::printf("\nsegmentation (runtime people segmentation vs the ground-truth person masks):\n");
    if (args.Has("per-person"))
      for (const auto& p : e->segmentation)
        std::printf("  frame %d person %d: %d px, IoU %.3f\n", p.frame, p.person, p.pixels, p.iou);
    int good = 0;
    for (const auto& p : e->segmentation) good += p.iou >= 0.5;
    std::printf(
        "segmentation: %zu people, mean IoU %.3f, %d with IoU >= 0.5; right person count in %d/%d "
        "frames; %.1f ms/frame\n",
        e->segmentation.size(), e->MeanIoU(), good, e->frames_right_count, e->frames,
        e->segment_ms / std::max(1, e->frames));
    const bool ap = e->has_joints && method != "none";
    auto line = [&](const char* what, const engine::ConfusionMatrix& m, const runtime::JointApEvaluator& j) {
      std::printf("  %-44s average per-class accuracy %6.2f%%", what, 100.0 * m.AveragePerClassAccuracy());
      if (ap) std::printf(", mAP %.3f", j.MeanAveragePrecision());
      std::printf("\n");
    };
    line("frames as they are (everything classified):", e->confusion, e->mean_shift);
    line("clean (ground-truth masks):", e->clean_confusion, e->clean_mean_shift);
    line("after segmentation:", e->segmented_confusion, e->segmented_mean_shift);
    if (ap)
      std::printf("eval: segmentation mean IoU %.3f, mAP clean %.3f, after segmentation %.3f\n", e->MeanIoU(),
                  e->clean_mean_shift.MeanAveragePrecision(), e->segmented_mean_shift.MeanAveragePrecision());
  }
  // The headline figures on the last line.
  if (e->has_joints && method != "none")
    std::printf("eval: mAP %.3f (mean shift), upper bound %.3f, average per-class accuracy %.2f%%\n",
                e->mean_shift.MeanAveragePrecision(), e->upper_bound.MeanAveragePrecision(),
                100.0 * e->confusion.AveragePerClassAccuracy());
  return 0;
}

}  // namespace poseforest::apps::commands
