// poseforest tune-joints: learns the joint-proposal parameters (b, lambda, zeta per joint) of a
// forest on rendered validation frames and stores them in the forest, one set per proposal
// method (format 1.2: JPAR for mean shift, JPFC for the fast clustering).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <optional>
#include <string>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "engine/evaluation.h"
#include "runtime/core/forest_format.h"
#include "runtime/proposal_tuning.h"

namespace poseforest::apps::commands {
namespace {

class TuneJointsCommand final : public Command {
 public:
  TuneJointsCommand()
      : Command("tune-joints",
                "Learns the joint-proposal parameters of section 3.4 for this forest: for each of the 16 joints,\n"
                "the mean-shift bandwidth b, the seed probability threshold lambda and the surface-to-interior\n"
                "z offset zeta that maximize the joint's average precision (D = 0.1 m) on validation frames, by\n"
                "grid search (b in 0.045..0.16 m, lambda in 0.1..0.55, zeta in 0..0.1 m). The forest's inferred\n"
                "parts are used, as at run time. Each proposal method gets its own set (by default both: mean\n"
                "shift and the fast bottom-up clustering, on the same validation frames). Writes the forest with\n"
                "the parameters stored in it (format 1.2: section JPAR for mean shift, JPFC for the fast\n"
                "clustering) and the joint confidence calibration (format 1.4, JCAL: per joint, the precision\n"
                "mean-shift proposals of each support had on the validation frames; `live` reports it as each\n"
                "joint's confidence), so `poseforest infer --joints` and `poseforest eval` use each method's own set with\n"
                "no other file.\n"
                "\n"
                "SET is one of:\n"
                "  JOB.textproto   render validation frames from the job: by default from its training source\n"
                "                  (the train clips) with another seed, i.e. frames the forest was not trained\n"
                "                  on but no pose of the held-out test clips; --from test uses the job's\n"
                "                  test_set source (the held-out clips) with another seed than the test set\n"
                "  DIR             a folder written by `poseforest render` (depth/labels/joints_%06d.*)") {
    app_.add_option("--forest", forest_, "forest to tune (its own stored parameters are the starting point)")
        ->type_name("PATH")
        ->required();
    app_.add_option("--validation", validation_, "the validation frames (above)")->type_name("SET")->required();
    app_.add_option("--out", out_, "where to write the tuned forest (may equal --forest)")
        ->type_name("PATH")
        ->required();
    app_.add_option("--frames", frames_, "validation frames (the paper used 5000)")
        ->type_name("N")
        ->check(IntIn(1, 1'000'000));
    app_.add_option("--from", from_, "which source of a job to render from")
        ->type_name("train|test")
        ->check(OneOf({"train", "test"}));
    app_.add_option("--seed", seed_, "render seed of the validation frames (default: the source's seed + 1000003)")
        ->type_name("S")
        ->check(IntIn(0, 1LL << 62));
    app_.add_option("--people", people_, "render exactly N people per frame (default: the source's setting)")
        ->type_name("N")
        ->check(IntIn(1, 8));
    app_.add_option("--method", method_,
                    "which method's parameters to learn: both, meanshift or fast; the other method's\n"
                    "stored set is kept as it was (a fast clustering with no set of its own runs with\n"
                    "the mean-shift set, so tuning only mean shift then stores the set the fast\n"
                    "clustering ran with as its own)")
        ->type_name("M")
        ->check(OneOf({"both", "meanshift", "fast"}));
    app_.add_flag("--per-joint", per_joint_,
                  "search each joint alone; by default left and right joints of a pair share\n"
                  "parameters (chosen by the pair's mean AP: less noise from few frames)");
    app_.add_option("--threads", threads_, "threads (0 = all cores)")->type_name("N")->check(IntIn(0, 1024));
    app_.add_flag("--quiet", quiet_, "no progress lines");
  }
  int Run() override;

 private:
  /// Tunes one method's parameters on `valid` into `tuned`, printing the table.
  void TuneMethod(bool fast, const std::vector<runtime::ValidationFrame>& valid, const core::CameraIntrinsics& camera,
                  const runtime::TuningGrid& grid, const core::ProposalParamsChoice& before, core::Forest* tuned,
                  const std::function<double()>& seconds) const;
  /// The skeleton's confidence (format 1.4, JCAL) for `tuned`'s parameters, printed.
  void Calibrate(const std::vector<runtime::ValidationFrame>& valid, core::Forest* tuned) const;

  std::string forest_, validation_, out_, from_ = "train", method_ = "both";
  int frames_ = 100, threads_ = 0;
  std::optional<int64_t> seed_;
  std::optional<int> people_;
  bool per_joint_ = false, quiet_ = false;
};

int TuneJointsCommand::Run() {
  // --out may equal --forest (tuned in place), never the validation job.
  if (const std::string bad = CheckOutputFile("--out", out_, {validation_}); !bad.empty())
    return UsageError(bad);
  const std::string &from = from_, &method = method_;
  const bool tune_ms = method != "fast", tune_fast = method != "meanshift";
  const std::string& set = validation_;
  auto named = engine::ResolveSourceArgument(
      set, from == "test" ? engine::JobSource::kTestSet : engine::JobSource::kTraining);
  if (!named.ok()) {
    std::fprintf(stderr, "poseforest tune-joints: --validation %s\n", named.status().ToString().c_str());
    return named.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  engine::SourceSpec source = named->source;
  std::string what;
  if (source.kind == engine::SourceKind::kRendered) {
    source.seed = seed_ ? uint64_t(*seed_) : source.seed + 1000003;
    what = "rendered seed " + std::to_string(source.seed) + ", " +
           (from == "test" ? "the job's test_set source (held-out clips)"
                           : "the job's training source (train clips, frames not trained on)");
  } else if (source.kind == engine::SourceKind::kDataset) {
    // A folder's frames are what they are: no job source to choose, nothing to render.
    if (Given("from") || Given("seed"))
      return UsageError(std::string(Given("from") ? "--from" : "--seed") +
                        " is for a job's rendered source; --validation " + set + " is a folder of frames");
    what = "folder " + source.folder;
    // A folder: the default --frames takes at most what it holds.
    int64_t count = 0;
    if (const std::string bad = FolderFrameCount(
            "--validation", set, named->num_images, 0, "--frames",
            Given("frames") ? std::optional<int64_t>(frames_)
                            : std::optional<int64_t>(std::min<int64_t>(frames_, named->num_images)),
            &count);
        !bad.empty())
      return UsageError(bad);
    frames_ = decltype(frames_)(count);
  } else {
    std::fprintf(stderr, "poseforest tune-joints: --validation %s: procedural frames have no joints\n",
                 set.c_str());
    return 2;
  }
  auto forest = core::LoadForest(forest_);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest tune-joints: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const bool quiet = quiet_;
  const auto t0 = std::chrono::steady_clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  const int n = frames_;
  if (!quiet) std::printf("validation: %d frames, %s\n", n, what.c_str());
  std::fflush(stdout);
  core::CameraIntrinsics camera;
  auto valid = engine::MakeValidationFrames(
      *forest, source, n, 0, threads_, people_.value_or(0),
      [&](int d, int t) {
        if (!quiet && (d % 20 == 0 || d == t))
          std::fprintf(stderr, "tune-joints: rendered + classified %d / %d frames (%.0f s)\n", d, t,
                       seconds());
      },
      &camera);
  if (!valid.ok()) {
    std::fprintf(stderr, "poseforest tune-joints: %s\n", valid.status().ToString().c_str());
    return valid.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  runtime::TuningGrid grid;
  grid.mirror_pairs = !per_joint_;
  if (!quiet)
    std::printf("grid: %zu bandwidths x %zu thresholds x %zu z offsets per %s\n", grid.bandwidth_m.size(),
                grid.prob_threshold.size(), grid.z_offset_m.size(),
                grid.mirror_pairs ? "joint pair (left and right share)" : "joint");

  core::Forest tuned = std::move(*forest);
  // What each method ran with before, for the other method's set and the report.
  const core::ProposalParamsChoice before[2] = {tuned.ProposalParamsFor(false),
                                                tuned.ProposalParamsFor(true)};
  for (const bool fast : {false, true})
    if (fast ? tune_fast : tune_ms) TuneMethod(fast, *valid, camera, grid, before[fast], &tuned, seconds);
  // Tuning mean shift alone must not change what the fast clustering runs with: without a set
  // of its own it ran with the old mean-shift set, which becomes its own.
  if (tune_ms && !tune_fast && !tuned.fast_proposal_params &&
      before[1].source == core::ProposalParamsSource::kMeanShiftSet) {
    tuned.fast_proposal_params = before[1].params;
    std::printf("fast clustering: keeps the set it ran with (the previous mean-shift set), now its own\n");
  }
  Calibrate(*valid, &tuned);
  // The tracking decision (format 1.6) was fitted on the confidences of the old parameters and
  // calibration: it would misread the new ones.
  if (tuned.tracking_model) {
    tuned.tracking_model.reset();
    std::printf("\nthe forest's tracking decision (JTRK) was fitted for the old parameters: dropped; run "
                "`poseforest learn-votes --tracking-only` to fit it again\n");
  }
  if (auto st = core::SaveForest(tuned, out_); !st.ok()) {
    std::fprintf(stderr, "poseforest tune-joints: %s\n", st.ToString().c_str());
    return 1;
  }
  std::printf("wrote %s with the learned parameters (%s) and the confidence calibration (%.0f s)\n",
              out_.c_str(),
              tune_ms && tune_fast ? "mean shift and fast clustering"
              : tune_ms            ? "mean shift"
                                   : "fast clustering",
              seconds());
  return 0;
}

void TuneJointsCommand::TuneMethod(bool fast, const std::vector<runtime::ValidationFrame>& valid, const core::CameraIntrinsics& camera,
                                   const runtime::TuningGrid& grid, const core::ProposalParamsChoice& before,
                                   core::Forest* tuned, const std::function<double()>& seconds) const {
  const char* name = fast ? "fast clustering" : "mean shift";
  runtime::ProposalOptions base;
  base.params = before.params;  // the starting point, kept for joints never visible
  base.num_threads = threads_;
  base.camera = camera;  // the validation frames' (a render folder's camera.txt)
  if (fast) base.method = runtime::ProposalMethod::kFastClustering;
  const auto result = runtime::TuneProposalParams(valid, base, grid, 0.1f, [&](int d, int t) {
    if (!quiet_ && (d % 5 == 0 || d == t))
      std::fprintf(stderr, "tune-joints: %s: grid %d / %d (b, lambda) points (%.0f s)\n", name, d, t,
                   seconds());
  });
  std::printf("\n%s:\n", name);
  std::printf("%-11s %8s %8s %8s %9s %9s\n", "joint", "b (m)", "lambda", "zeta (m)", "AP before",
              "AP after");
  double b = 0, lambda = 0, zeta = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    const auto& p = result.params[size_t(j)];
    b += p.bandwidth_m, lambda += p.prob_threshold, zeta += p.z_offset_m;
    std::printf("%-11s %8.3f %8.2f %8.3f %9.3f %9.3f\n", std::string(core::JointName(j)).c_str(),
                double(p.bandwidth_m), double(p.prob_threshold), double(p.z_offset_m),
                result.base_ap[size_t(j)], result.ap[size_t(j)]);
  }
  std::printf("mean: b = %.3f m, lambda = %.3f, zeta = %.3f m (the paper: 0.065 m, 0.14, 0.039 m)\n",
              b / core::kNumJoints, lambda / core::kNumJoints, zeta / core::kNumJoints);
  const char* from = before.source == core::ProposalParamsSource::kLearned ? "forest's previous"
                     : before.source == core::ProposalParamsSource::kMeanShiftSet
                         ? "forest's mean-shift"
                         : "paper's mean";
  std::printf("validation mAP (%s): %.3f with the %s parameters -> %.3f tuned\n", name, result.base_mean_ap,
              from, result.mean_ap);
  (fast ? tuned->fast_proposal_params : tuned->proposal_params) = result.params;
}

// The skeleton's confidence (format 1.4, JCAL): the precision the mean-shift proposals, with
// the parameters the forest now holds, have on these validation frames per bin of support.
// Measured on the frames the parameters were chosen on (a slightly optimistic precision; the
// parameters only move proposals, the table is what they then achieve).
void TuneJointsCommand::Calibrate(const std::vector<runtime::ValidationFrame>& valid, core::Forest* tuned) const {
  runtime::ProposalOptions cal_options;
  cal_options.params = tuned->ProposalParamsFor(false).params;
  cal_options.num_threads = threads_;
  tuned->confidence_calibration = runtime::CalibrateConfidence(valid, cal_options, 0.1f);
  const auto& cal = *tuned->confidence_calibration;
  std::printf("\nconfidence calibration (mean shift, %u validation proposals): precision at support\n",
              cal.samples);
  const float probes[] = {1e-4f, 3e-4f, 1e-3f, 3e-3f, 1e-2f};
  std::printf("%-11s", "joint");
  for (float p : probes) std::printf(" %8.0e", double(p));
  std::printf("  (m^2)\n");
  for (int j = 0; j < core::kNumJoints; ++j) {
    std::printf("%-11s", std::string(core::JointName(j)).c_str());
    for (float p : probes) std::printf(" %8.3f", double(cal.Confidence(j, p)));
    std::printf("\n");
  }
}

}  // namespace

std::unique_ptr<Command> MakeTuneJointsCommand() { return std::make_unique<TuneJointsCommand>(); }

}  // namespace poseforest::apps::commands
