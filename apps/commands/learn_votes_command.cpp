// poseforest learn-votes: the offset votes of a trained forest (format 1.5, section JVOT), from
// the job's own training frames, calibrated on validation frames (engine/vote_learning.h).
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "engine/evaluation.h"
#include "engine/tracking_learning.h"
#include "engine/vote_learning.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {
namespace {
void PrintVotes(const core::Forest& forest, const engine::VoteLearningReport& rep, const std::string& out) {
  const auto& v = *forest.offset_votes;
  std::printf("votes: %llu training pixels over %zu trees, %llu of %llu leaves vote (%.1f votes per leaf), %llu "
              "votes (%.1f MiB), max offset %.2f m\n",
              (unsigned long long)rep.pixels, forest.trees.size(), (unsigned long long)rep.leaves_with_votes,
              (unsigned long long)rep.leaves, rep.leaves ? double(rep.votes) / double(rep.leaves) : 0.0,
              (unsigned long long)rep.votes, double(rep.votes) * 8 / (1 << 20), double(v.max_offset_m));
  if (!v.share_edges.empty()) {
    std::printf("calibration (%d validation frames, %llu candidates): precision within 0.1 m by share of the "
                "joint's vote weight, per joint\n  share      ",
                rep.validation_frames, (unsigned long long)rep.candidates);
    for (float e : v.share_edges) std::printf(" %5.2f", double(e));
    std::printf("\n");
    const size_t bins = v.share_edges.size();
    for (int j = 0; j < core::kNumJoints; ++j) {
      std::printf("  %-11s", std::string(core::JointName(j)).c_str());
      for (size_t b = 0; b < bins; ++b) std::printf(" %5.2f", double(v.precision[size_t(j) * bins + b]));
      std::printf("\n");
    }
    std::printf("most weighted vote candidate within 0.1 m, per joint (run-time bandwidth):\n");
    double mean = 0;
    int joints = 0;
    for (int j = 0; j < core::kNumJoints; ++j) {
      const int n = rep.scored[size_t(j)];
      const double r = n ? double(rep.top_within[size_t(j)]) / n : 0.0;
      std::printf("  %-11s %.3f (%.2f m)\n", std::string(core::JointName(j)).c_str(), r,
                  double(v.bandwidth_m[size_t(j)]));
      if (n) mean += r, ++joints;
    }
    std::printf("learn-votes: wrote %s in %.0f s; validation: top vote candidate within 0.1 m %.3f (mean over "
                "joints)\n",
                out.c_str(), rep.seconds, joints ? mean / joints : 0.0);
  } else {
    std::printf("learn-votes: wrote %s in %.0f s (no calibration)\n", out.c_str(), rep.seconds);
  }
}

void PrintTracking(const core::TrackingModel& m, const engine::TrackingLearningReport& rep, const std::string& out) {
  std::printf("tracking decision (%s fit, %d validation frames, %d found joints, %d Newton steps): P(within "
              "0.1 m) = sigmoid(a_j + b_j logit(confidence) + w . cues)\n  joint        a_j    b_j\n",
              core::TrackingFitName(m.fit), rep.frames, rep.samples, rep.iterations);
  for (int j = 0; j < core::kNumJoints; ++j)
    std::printf("  %-11s %6.2f %6.2f\n", std::string(core::JointName(j)).c_str(), double(m.intercept[size_t(j)]),
                double(m.slope[size_t(j)]));
  std::printf("  cues:");
  for (int k = 0; k < core::kNumTrackingFeatures; ++k)
    std::printf(" %s %.2f%s", core::TrackingFeatureName(k), double(m.shared[size_t(k)]),
                k + 1 < core::kNumTrackingFeatures ? "," : "\n");
  if (m.seen) {
    std::printf(
        "seen decision (format 1.8): P(the camera sees the joint), the same form and samples; a joint is "
        "tracked when it reaches %.2g (`live --seen-probability`)\n  cues:",
        double(rep.seen_probability));
    for (int k = 0; k < core::kNumTrackingFeatures; ++k)
      std::printf(" %s %.2f%s", core::TrackingFeatureName(k), double(m.seen->shared[size_t(k)]),
                  k + 1 < core::kNumTrackingFeatures ? "," : "\n");
  }
  auto line = [](const char* what, const engine::TrackingLearningReport::Figures& f) {
    std::printf("  %-37s visible tracked within 0.1 m %.3f, tracked right %.3f, not tracked and hidden %.3f\n", what,
                f.visible_within, f.precision, f.untracked_hidden);
  };
  std::printf("on its fitting frames (the same positions; only the decision differs):\n");
  line("the hand-set rules:", rep.rules);
  char what[64];
  std::snprintf(what, sizeof what, "tracked when P(within 0.1 m) >= %.2g:", double(rep.track_probability));
  line(what, rep.model);
  std::snprintf(what, sizeof what, "tracked when P(seen) >= %.2g:", double(rep.seen_probability));
  if (m.seen) line(what, rep.seen);
  std::printf("learn-votes: wrote %s; tracking decision fitted in %.0f s\n", out.c_str(), rep.seconds);
}

class LearnVotesCommand final : public Command {
 public:
  LearnVotesCommand()
      : Command("learn-votes",
                "Adds offset votes to a forest trained by JOB (`train` or the distributed service: the same\n"
                "forest): per leaf, the offset from a pixel to each joint that the leaf's training pixels agree\n"
                "on (Girshick et al. 2011). It renders each tree's training frames again (the same frames and\n"
                "pixels as training), walks the pixels to their leaves and keeps, per leaf and joint, the main\n"
                "mode of the offsets shorter than --max-offset-m. Then it measures, on validation frames\n"
                "(the job's training source with another seed, as tune-joints), how often a vote candidate is\n"
                "within 0.1 m of its joint per share of the joint's vote weight: the candidates' confidence. At\n"
                "run time (`live`, `eval`) the votes give every joint candidates, hidden joints included, which\n"
                "the skeleton weighs against the part proposals. Last, it fits the skeleton's tracking decision\n"
                "(format 1.6, runtime/core/tracking_model.h) on further validation frames: whether a joint is\n"
                "tracked is learned from its confidence and cues (votes agreeing, the image border, bone lengths,\n"
                "its parent) instead of hand-set rules: P(within 0.1 m) is the joint's confidence, and a seen\n"
                "decision (format 1.8) on the same cues, P(the camera sees the joint), says which joints are\n"
                "tracked (seen) and which inferred. Run it after tune-joints (it keeps what the forest holds).") {
    app_.add_option("--forest", forest_, "the trained forest")->type_name("PATH")->required();
    app_.add_option("--job", job_, "the job that trained it (its source must render joints)")
        ->type_name("PATH")
        ->required();
    app_.add_option("--out", out_, "where to write the forest with votes (may equal --forest)")
        ->type_name("PATH")
        ->required();
    app_.add_option("--max-offset-m", max_offset_m_,
                    "longest offset kept to the head, neck and shoulders, metres")
        ->type_name("M")
        ->check(NumberIn(0.05, 3.0));
    app_.add_option("--limb-max-offset-m", limb_max_offset_m_,
                    "longest offset kept for elbows, knees, ankles and feet (0: --max-offset-m)")
        ->type_name("M")
        ->check(NumberIn(0.0, 3.0));
    app_.add_option("--hand-max-offset-m", hand_max_offset_m_,
                    "longest offset kept for wrists and hands (0: as --limb-max-offset-m)")
        ->type_name("M")
        ->check(NumberIn(0.0, 3.0));
    app_.add_option("--leaf-bandwidth-m", leaf_bandwidth_m_, "mean shift over a leaf's offsets")
        ->type_name("B")
        ->check(NumberIn(0.005, 0.5));
    app_.add_option("--vote-bandwidth-m", vote_bandwidth_m_,
                    "run-time mean shift over the votes, every joint (default: per joint, the best of\n"
                    "0.04, 0.06, 0.09, 0.13 and 0.18 m on the validation frames)")
        ->type_name("B")
        ->check(NumberIn(0.005, 0.5));
    app_.add_option("--min-weight", min_weight_, "a leaf keeps a joint's mode holding at least this share of its pixels")
        ->type_name("W")
        ->check(NumberIn(0.001, 1.0));
    app_.add_option("--validation-frames", validation_frames_, "frames of the calibration (0: none, confidences 0)")
        ->type_name("N")
        ->check(IntIn(0, 1'000'000));
    app_.add_option("--tracking-frames", tracking_frames_,
                    "validation frames of the tracking decision, after the calibration's (0: no\n"
                    "tracking model, the skeleton keeps its rules)")
        ->type_name("N")
        ->check(IntIn(0, 1'000'000));
    app_.add_flag("--tracking-only", tracking_only_, "keep the forest's votes and fit the tracking decision alone");
    app_.add_option("--fit", fit_,
                    "the skeleton fit whose choices the tracking decision learns from, and which `live`\n"
                    "and `eval` then run by default: kinematic or greedy (runtime/skeleton.h)")
        ->type_name("F")
        ->check(SkeletonFitValidator());
    app_.add_option("--seed", seed_,
                    "render seed of the validation frames (default: the source's seed + 1000003, as\n"
                    "tune-joints)")
        ->type_name("S")
        ->check(IntIn(0, 1LL << 62));
    app_.add_option("--threads", threads_, "threads (0 = all cores)")->type_name("N")->check(IntIn(0, 1024));
    app_.add_flag("--quiet", quiet_, "no progress lines");
  }
  int Run() override;

 private:
  std::string forest_, job_, out_, fit_ = "kinematic";
  // The defaults are engine::VoteLearningOptions'.
  std::optional<double> vote_bandwidth_m_;
  double max_offset_m_ = kDefaults.max_offset_m, limb_max_offset_m_ = kDefaults.limb_max_offset_m,
         hand_max_offset_m_ = kDefaults.hand_max_offset_m, leaf_bandwidth_m_ = kDefaults.leaf_bandwidth_m,
         min_weight_ = kDefaults.min_weight;
  int validation_frames_ = kDefaults.validation_frames, tracking_frames_ = 200, threads_ = 0;
  std::optional<int64_t> seed_;
  bool tracking_only_ = false, quiet_ = false;
  static inline const engine::VoteLearningOptions kDefaults{};
};

int LearnVotesCommand::Run() {
  // --out may equal --forest (votes added in place), never the job.
  if (const std::string bad = CheckOutputFile("--out", out_, {job_}); !bad.empty()) return UsageError(bad);
  engine::VoteLearningOptions opt;
  auto job = engine::LoadJob(job_);
  if (!job.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", job.status().ToString().c_str());
    return job.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  if (job->source.kind == engine::SourceKind::kProcedural) {
    std::fprintf(stderr, "poseforest learn-votes: %s: procedural frames have no joints\n",
                 job_.c_str());
    return 2;
  }
  auto forest = core::LoadForest(forest_);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const bool quiet = quiet_;
  opt.max_offset_m = float(max_offset_m_);
  opt.limb_max_offset_m = float(limb_max_offset_m_);
  opt.hand_max_offset_m = float(hand_max_offset_m_);
  opt.leaf_bandwidth_m = float(leaf_bandwidth_m_);
  if (vote_bandwidth_m_) {
    opt.vote_bandwidth_m = float(*vote_bandwidth_m_);
    opt.bandwidth_grid.clear();
  }
  opt.min_weight = float(min_weight_);
  opt.validation_frames = validation_frames_;
  opt.threads = threads_;
  opt.validation = job->source;
  if (opt.validation.kind == engine::SourceKind::kRendered)
    opt.validation.seed = seed_ ? uint64_t(*seed_) : job->source.seed + 1000003;
  if (!quiet)
    opt.progress = [](const std::string& line) {
      std::fprintf(stderr, "learn-votes: %s\n", line.c_str());
    };
  const bool tracking_only = tracking_only_;
  if (tracking_only && !forest->offset_votes) {
    std::fprintf(stderr, "poseforest learn-votes: --tracking-only: %s has no offset votes to keep\n",
                 forest_.c_str());
    return 2;
  }
  if (tracking_only && tracking_frames_ == 0) {
    std::fprintf(stderr, "poseforest learn-votes: --tracking-only needs --tracking-frames > 0\n");
    return 2;
  }
  engine::VoteLearningReport rep;
  if (!tracking_only) {
    auto votes = engine::LearnOffsetVotes(*forest, *job, opt, &rep);
    if (!votes.ok()) {
      std::fprintf(stderr, "poseforest learn-votes: %s\n", votes.status().ToString().c_str());
      return votes.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    forest->offset_votes = std::move(*votes);
    forest->tracking_model.reset();  // fitted for other votes
  }
  engine::TrackingLearningReport trep;
  if (tracking_frames_ > 0) {
    engine::TrackingLearningOptions to;
    to.validation = opt.validation;
    to.first_index = uint64_t(opt.validation_frames);
    to.frames = tracking_frames_;
    to.threads = opt.threads;
    to.progress = opt.progress;
    to.skeleton.fit = *runtime::SkeletonFitFromName(fit_);
    auto model = engine::LearnTrackingModel(*forest, to, &trep);
    if (!model.ok()) {
      std::fprintf(stderr, "poseforest learn-votes: %s\n", model.status().ToString().c_str());
      return model.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    forest->tracking_model = *model;
  }
  if (auto st = core::SaveForest(*forest, out_); !st.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", st.ToString().c_str());
    return 1;
  }
  if (!tracking_only) PrintVotes(*forest, rep, out_);
  if (forest->tracking_model) PrintTracking(*forest->tracking_model, trep, out_);
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeLearnVotesCommand() { return std::make_unique<LearnVotesCommand>(); }

}  // namespace poseforest::apps::commands
