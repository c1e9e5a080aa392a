// poseforest eval: per-class accuracy and joint average precision of a forest on held-out
// labelled frames.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>

#include <filesystem>

#include "apps/commands/cli.h"
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
class EvalCommand final : public Command {
 public:
  EvalCommand();
  int Run() override;

 private:
  /// eval --test-set SET.
  int RunTestSet();
  /// eval --real-labels: the skeletons of `live` scored on hand-labelled frames (engine/real_frames.h).
  int RunRealLabels();
  /// The segmentation's lines of a --test-set run.
  void PrintSegmentation(const engine::Evaluation& e, bool ap) const;

  std::string forest_, test_set_, pr_png_, png_, real_labels_, png_dir_, segment_ = "auto", fit_;
  std::optional<std::string> method_;  ///< default: both (--test-set), meanshift (--real-labels)
  std::optional<int> images_, people_, pixel_stride_;  ///< pixel stride default: 1, live's 2 with --real-labels
  int64_t first_ = 0;
  int threads_ = 0;
  std::optional<double> agree_radius_, track_probability_, seen_probability_;
  bool quiet_ = false, per_person_ = false, no_rescale_ = false, no_votes_ = false, no_tracking_model_ = false,
       no_seen_model_ = false;
};

EvalCommand::EvalCommand()
    : Command("eval",
                "Reports the paper's two metrics (section 4) on held-out labelled frames:\n"
                "  * joint average precision: the forest's joint proposals (mean shift, and the fast bottom-up\n"
                "    clustering) are ranked by confidence over all frames; the first proposal within D = 0.1 m of\n"
                "    a visible ground-truth joint is a true positive, every other one a false positive; AP per\n"
                "    joint, mAP over the 16 joints, and Fig. 7's upper bound: mean shift on the ground-truth part\n"
                "    labels; the ratio inferred / upper bound. With several people in a frame, proposals are\n"
                "    counted against each person's joints. Uses the proposal parameters stored in the forest\n"
                "    (`poseforest tune-joints`), else the paper's means. Needs frames with joints: rendered, or\n"
                "    a `poseforest render` folder (joints_%06d.json);\n"
                "  * the average per-class accuracy: the mean of the diagonal of the row-normalized confusion\n"
                "    matrix between ground-truth and most likely inferred part; the per-part table and the\n"
                "    confusion matrix as text (and as a picture with --png).\n"
                "\n"
                "With --real-labels, the skeletons `live` would give on hand-labelled real depth frames are\n"
                "scored instead: LABELS.json names the camera and, per frame, a depth file beside it (anything\n"
                "`poseforest frames` reads: raw uint16 mm of the camera's size, a depth PNG, .npy) and the labelled\n"
                "joints (the format of the shared data's real/skeltrack_kinect_depth/joint_labels.json; its\n"
                "JOINT_LABELS.md says how they were made). A joint is right when the skeleton tracks it within\n"
                "0.10 m of the labelled surface point moved 0.04 m along the camera ray. Per joint and per group:\n"
                "labelled, tracked, tracked within 0.10 m, the median 2D error of tracked joints (pixels), \"found\n"
                "within\": the skeleton's position within 0.10 m, tracked or not (the confidence rules aside), and\n"
                "\"any within 0.10 m\": that or any of the joint's proposals on the person within 0.10 m (did the\n"
                "forest find it at all). The same pipeline as `live`: people\n"
                "segmentation, the forest's tuned proposal parameters and calibration, the skeleton's rules, and\n"
                "live's pixel stride 2 unless --pixel-stride says otherwise. --png-dir DIR writes one picture per\n"
                "frame (depth | parts | skeleton, each label a cross: green when right, red otherwise, with a line\n"
                "to where the skeleton put the joint).\n"
                "\n"
                "SET is one of:\n"
                "  DIR                a folder written by `poseforest render` (depth/labels/joints_%06d.*; its\n"
                "                     camera.txt says the camera, and a forest trained at another focal length\n"
                "                     has its offsets rescaled)\n"
                "  JOB.textproto      a training job config: its test_set { } is used (held-out mocap clips)\n"
                "  procedural:SEED    procedural frames (no joints: accuracy only)") {
  app_.add_option("--forest", forest_, "forest file (required)")->type_name("PATH");
  app_.add_option("--test-set", test_set_, "the labelled frames (above; required without --real-labels)")
      ->type_name("SET");
  app_.add_option("--images", images_,
                  "frames to evaluate (default: the job's test_set.num_images, else 50; for a folder at\n"
                  "most its frame count)")
      ->type_name("N")
      ->check(IntIn(1, 10'000'000));
  app_.add_option("--first", first_, "first frame index")->type_name("N")->check(IntIn(0, 1LL << 40));
  app_.add_option("--people", people_, "render exactly N people per frame (rendered sets; default: the set's own)")
      ->type_name("N")
      ->check(IntIn(1, 8));
  app_.add_option("--method", method_,
                  "joint proposals: both (default), meanshift (skips the fast clustering) or none\n"
                  "(accuracy only); with --real-labels meanshift (default) or fast")
      ->type_name("M");
  app_.add_option("--pr-png", pr_png_,
                  "write precision-recall curves: DIR/pr_joints.png (each joint: mean shift, fast,\n"
                  "ground-truth parts) and DIR/pr_mean.png (mean over joints)")
      ->type_name("DIR");
  app_.add_option("--threads", threads_, "threads (0 = all cores)")->type_name("N")->check(IntIn(0, 1024));
  app_.add_option("--pixel-stride", pixel_stride_,
                  "classify and propose from every N-th pixel in x and y only, as `live --pixel-stride N`\n"
                  "(default 1: every pixel; with --real-labels live's 2); the confusion matrix counts every\n"
                  "body pixel (off the grid: its grid pixel's part)")
      ->type_name("N")
      ->check(IntIn(1, 16));
  app_.add_option("--png", png_, "also write the confusion matrix as an RGB PNG")->type_name("PATH");
  app_.add_option("--segment", segment_,
                  "auto: on frames with ground-truth person masks (a folder rendered with\n"
                  "--clutter/--occluders/--masks), also score the runtime's people segmentation: IoU per\n"
                  "person against the masks, and the forest's mAP and accuracy after segmentation next to\n"
                  "those on the frames masked by the ground truth (clean); on: require masks; off: never")
      ->type_name("M")
      ->check(OneOf({"auto", "on", "off"}));
  app_.add_flag("--per-person", per_person_, "list each person's segmentation IoU");
  app_.add_flag("--no-rescale", no_rescale_,
                "keep the forest's offsets as trained even when the frames' camera (camera.txt) has\n"
                "another focal length (to measure what the rescaling buys)");
  app_.add_option("--fit", fit_,
                  "how the skeleton picks its joints: greedy (each joint's most confident proposal on the\n"
                  "person) or kinematic (one fit per person choosing among each joint's proposals with\n"
                  "bone lengths; runtime/skeleton.h) (default: the fit the forest's tracking decision\n"
                  "was learned on, kinematic without one)")
      ->type_name("F")
      ->check(SkeletonFitValidator());
  app_.add_flag("--no-votes", no_votes_, "the skeleton ignores the forest's offset votes (format 1.5, `learn-votes`)");
  app_.add_flag("--no-tracking-model", no_tracking_model_,
                "the skeleton's hand-set tracking rules instead of the forest's learned tracking\n"
                "decision (format 1.6, `learn-votes`; runtime/core/tracking_model.h)");
  app_.add_flag("--no-seen-model", no_seen_model_,
                "with the learned decision: track a joint when P(within 0.1 m) >= 0.5 instead of when the\n"
                "decision's seen model (format 1.8) says the camera likely sees it");
  app_.add_option("--agree-radius", agree_radius_,
                  "a joint whose part proposal and best vote candidate lie within M metres of each other\n"
                  "gets their combined confidence (default 0.1; 0: off; runtime/skeleton.h\n"
                  "SkeletonOptions::agree_radius_m)")
      ->type_name("M")
      ->check(NumberIn(0.0, 1.0, "metres"));
  app_.add_option("--seen-probability", seen_probability_,
                  "as `live --seen-probability`: with the seen model, a joint is tracked when P(seen)\n"
                  "reaches P (default 0.2: not seen only when P(hidden) >= 0.8)")
      ->type_name("P")
      ->check(NumberIn(0.0, 1.0, "a probability"));
  app_.add_option("--track-probability", track_probability_,
                  "as `live --track-probability`: without the seen model (--no-seen-model, forests\n"
                  "before 1.8), a joint is tracked when P(within 0.1 m) reaches P (default 0.5)")
      ->type_name("P")
      ->check(NumberIn(0.0, 1.0, "a probability"));
  app_.add_option("--real-labels", real_labels_,
                  "score skeletons on hand-labelled real frames (above) instead of --test-set")
      ->type_name("FILE");
  app_.add_option("--png-dir", png_dir_, "with --real-labels: a picture per frame, DIR/<frame file>.png")
      ->type_name("DIR");
  app_.add_flag("--quiet", quiet_, "no progress lines");
}

int EvalCommand::Run() {
  if (Given("png"))
    if (const std::string bad = CheckOutputFile("--png", png_, {forest_, test_set_}); !bad.empty())
      return UsageError(bad);
  if (Given("real-labels")) return RunRealLabels();
  if (Given("png-dir")) return UsageError("--png-dir needs --real-labels");
  if (!Given("forest") || !Given("test-set")) return UsageError("need --forest and --test-set (or --real-labels)");
  return RunTestSet();
}

// eval --real-labels: the skeletons of `live` scored on hand-labelled frames (engine/real_frames.h).
int EvalCommand::RunRealLabels() {
  if (!Given("forest")) return UsageError("--real-labels needs --forest");
  for (const char* o : {"test-set", "images", "first", "people", "pr-png", "png", "segment"})
    if (Given(o)) return UsageError(std::string("--") + o + " does not go with --real-labels");
  const std::string method = method_.value_or("meanshift");
  if (method != "meanshift" && method != "fast")
    return UsageError("with --real-labels, --method must be meanshift or fast (got '" + method + "')");
  const std::string& labels_path = real_labels_;
  auto labels = engine::ReadRealLabels(labels_path);
  if (!labels.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", labels.status().ToString().c_str());
    return 1;
  }
  const std::optional<std::string> png_dir =
      Given("png-dir") ? std::optional<std::string>(png_dir_) : std::nullopt;
  if (png_dir) {
    std::error_code ec;
    std::filesystem::create_directories(*png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest eval: %s: cannot create folder: %s\n", png_dir->c_str(), ec.message().c_str());
      return 1;
    }
  }
  auto forest = core::LoadForest(forest_);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  runtime::SkeletonPipelineOptions options;
  options.segment = runtime::SegmentMode::kAuto;
  options.method =
      method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  options.num_threads = threads_;
  options.pixel_stride = pixel_stride_.value_or(2);  // live's default
  if (!fit_.empty()) options.skeleton.fit = *runtime::SkeletonFitFromName(fit_);
  if (agree_radius_) options.skeleton.agree_radius_m = float(*agree_radius_);
  if (track_probability_) options.skeleton.track_probability = float(*track_probability_);
  if (seen_probability_) options.skeleton.seen_probability = float(*seen_probability_);
  options.votes = !no_votes_;
  options.skeleton.use_tracking_model = !no_tracking_model_;
  options.skeleton.use_seen_model = !no_seen_model_;
  runtime::FrameSourceOptions source_options;
  source_options.camera = labels->camera;
  source_options.camera_given = true;
  std::vector<engine::RealFrameOutcome> outcomes;
  for (const engine::RealFrameLabels& f : labels->frames) {
    // A pipeline per frame: the frames are independent stills, not a sequence.
    auto pipeline = runtime::SkeletonPipeline::Create(*forest, options);
    if (!pipeline.ok()) {
      std::fprintf(stderr, "poseforest eval: %s: %s\n", forest_.c_str(),
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
    if (!quiet_)
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
  const auto& model = forest->tracking_model;
  const runtime::SkeletonFit fit = runtime::ResolveSkeletonFit(
      options.skeleton, options.skeleton.use_tracking_model && model ? &*model : nullptr);
  std::printf("forest %s on %zu real frames (%s), pixel stride %d, %s, %s fit\n\n", forest_.c_str(),
              labels->frames.size(), labels_path.c_str(), options.pixel_stride,
              method == "fast" ? "fast clustering" : "mean shift", std::string(runtime::SkeletonFitName(fit)).c_str());
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

int EvalCommand::RunTestSet() {
  const std::string method = method_.value_or("both");
  if (method != "both" && method != "meanshift" && method != "none")
    return UsageError("--method must be both, meanshift or none (got '" + method + "')");
  const std::string& set = test_set_;
  auto named = engine::ResolveSourceArgument(set, engine::JobSource::kTestSet);
  if (!named.ok()) {
    std::fprintf(stderr, "poseforest eval: --test-set %s\n", named.status().ToString().c_str());
    return named.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  int num_images = images_ ? *images_ : named->num_images;
  if (named->source.kind == engine::SourceKind::kDataset) {
    // A folder: by default every frame from --first on.
    int64_t count = 0;
    if (const std::string bad =
            FolderFrameCount("--test-set", set, named->num_images, first_, "--images",
                             images_ ? std::optional<int64_t>(*images_) : std::nullopt, &count);
        !bad.empty())
      return UsageError(bad);
    num_images = int(count);
  }
  auto forest = core::LoadForest(forest_);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  engine::JointEvalOptions eo;
  eo.num_images = num_images;
  eo.first_index = uint64_t(first_);
  eo.threads = threads_;
  eo.people = people_.value_or(0);
  eo.pixel_stride = pixel_stride_.value_or(1);
  if (!fit_.empty()) eo.skeleton_fit = *runtime::SkeletonFitFromName(fit_);
  if (agree_radius_) eo.agree_radius_m = float(*agree_radius_);
  if (track_probability_) eo.track_probability = float(*track_probability_);
  if (seen_probability_) eo.seen_probability = float(*seen_probability_);
  eo.votes = !no_votes_;
  eo.tracking_model = !no_tracking_model_;
  eo.seen_model = !no_seen_model_;
  eo.fast = method == "both";
  eo.rescale = !no_rescale_;
  eo.segment = segment_ == "on"    ? engine::JointEvalOptions::Segment::kOn
               : segment_ == "off" ? engine::JointEvalOptions::Segment::kOff
                                   : engine::JointEvalOptions::Segment::kAuto;
  const bool quiet = quiet_;
  if (!quiet)
    eo.progress = [](int done, int total) {
      if (done % 25 == 0 || done == total) std::fprintf(stderr, "eval: %d / %d frames\n", done, total);
    };
  auto e = engine::EvaluateForestJoints(*forest, named->source, eo);
  if (!e.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", e.status().ToString().c_str());
    return e.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  std::printf("forest %s on %s, %d frames", forest_.c_str(), set.c_str(), num_images);
  if (eo.pixel_stride > 1) std::printf(", pixel stride %d", eo.pixel_stride);
  std::printf("\n\n");
  std::fputs(engine::FormatConfusionText(e->confusion).c_str(), stdout);
  std::printf("\n");
  std::fputs(engine::FormatAccuracyTable(e->confusion).c_str(), stdout);
  if (const std::string& png = png_; Given("png")) {
    if (auto st = engine::WriteConfusionPng(e->confusion, png); !st.ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
      return 1;
    }
    std::printf("confusion matrix picture: %s\n", png.c_str());
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
      if (const std::string& dir = pr_png_; Given("pr-png")) {
        if (auto st = engine::WritePrCurves(*e, dir); !st.ok()) {
          std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
          return 1;
        }
        std::printf("precision-recall curves: %s/pr_joints.png, %s/pr_mean.png\n", dir.c_str(), dir.c_str());
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
  if (e->segmented) PrintSegmentation(*e, e->has_joints && method != "none");
  // The headline figures on the last line.
  if (e->has_joints && method != "none")
    std::printf("eval: mAP %.3f (mean shift), upper bound %.3f, average per-class accuracy %.2f%%\n",
                e->mean_shift.MeanAveragePrecision(), e->upper_bound.MeanAveragePrecision(),
                100.0 * e->confusion.AveragePerClassAccuracy());
  return 0;
}

void EvalCommand::PrintSegmentation(const engine::Evaluation& e, bool ap) const {
  std::printf("\nsegmentation (runtime people segmentation vs the ground-truth person masks):\n");
  if (per_person_)
    for (const auto& p : e.segmentation)
      std::printf("  frame %d person %d: %d px, IoU %.3f\n", p.frame, p.person, p.pixels, p.iou);
  int good = 0;
  for (const auto& p : e.segmentation) good += p.iou >= 0.5;
  std::printf(
      "segmentation: %zu people, mean IoU %.3f, %d with IoU >= 0.5; right person count in %d/%d "
      "frames; %.1f ms/frame\n",
      e.segmentation.size(), e.MeanIoU(), good, e.frames_right_count, e.frames,
      e.segment_ms / std::max(1, e.frames));
  auto line = [&](const char* what, const engine::ConfusionMatrix& m, const runtime::JointApEvaluator& j) {
    std::printf("  %-44s average per-class accuracy %6.2f%%", what, 100.0 * m.AveragePerClassAccuracy());
    if (ap) std::printf(", mAP %.3f", j.MeanAveragePrecision());
    std::printf("\n");
  };
  line("frames as they are (everything classified):", e.confusion, e.mean_shift);
  line("clean (ground-truth masks):", e.clean_confusion, e.clean_mean_shift);
  line("after segmentation:", e.segmented_confusion, e.segmented_mean_shift);
  if (ap)
    std::printf("eval: segmentation mean IoU %.3f, mAP clean %.3f, after segmentation %.3f\n", e.MeanIoU(),
                e.clean_mean_shift.MeanAveragePrecision(), e.segmented_mean_shift.MeanAveragePrecision());
}

}  // namespace

std::unique_ptr<Command> MakeEvalCommand() { return std::make_unique<EvalCommand>(); }

}  // namespace poseforest::apps::commands
