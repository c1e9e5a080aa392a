// poseforest learn-votes: the offset votes of a trained forest (format 1.5, section JVOT), from
// the job's own training frames, calibrated on validation frames (engine/vote_learning.h).
#include <chrono>
#include <cstdio>
#include <string>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "engine/evaluation.h"
#include "engine/tracking_learning.h"
#include "engine/vote_learning.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {
namespace {
constexpr const char* kUsage =
    R"(usage: poseforest learn-votes --forest F.pff --job JOB.textproto --out F2.pff [options]

Adds offset votes to a forest trained by JOB (`train` or the distributed service: the same
forest): per leaf, the offset from a pixel to each joint that the leaf's training pixels agree
on (Girshick et al. 2011). It renders each tree's training frames again (the same frames and
pixels as training), walks the pixels to their leaves and keeps, per leaf and joint, the main
mode of the offsets shorter than --max-offset-m. Then it measures, on validation frames
(the job's training source with another seed, as tune-joints), how often a vote candidate is
within 0.1 m of its joint per share of the joint's vote weight: the candidates' confidence. At
run time (`live`, `eval`) the votes give every joint candidates, hidden joints included, which
the skeleton weighs against the part proposals. Last, it fits the skeleton's tracking decision
(format 1.6, runtime/core/tracking_model.h) on further validation frames: whether a joint is
tracked is learned from its confidence and cues (votes agreeing, the image border, bone lengths,
its parent) instead of hand-set rules. Run it after tune-joints (it keeps what the forest holds).

options:
  --forest PATH          the trained forest (required)
  --job PATH             the job that trained it (required; its source must render joints)
  --out PATH             where to write the forest with votes (required; may equal --forest)
  --max-offset-m M       longest offset kept, metres (default 0.3)
  --leaf-bandwidth-m B   mean shift over a leaf's offsets (default 0.05)
  --vote-bandwidth-m B   run-time mean shift over the votes, every joint (default: per joint,
                         the best of 0.04, 0.06, 0.09, 0.13 and 0.18 m on the validation frames)
  --min-weight W         a leaf keeps a joint's mode holding at least this share of its
                         pixels (default 0.1)
  --validation-frames N  frames of the calibration (default 60; 0: none, confidences 0)
  --tracking-frames N    validation frames of the tracking decision, after the calibration's
                         (default 200; 0: no tracking model, the skeleton keeps its rules)
  --tracking-only        keep the forest's votes and fit the tracking decision alone
  --seed S               render seed of the validation frames (default: the source's seed +
                         1000003, as tune-joints)
  --threads N            threads (0 = all cores, default)
  --quiet                no progress lines
  --help                 this text
)";

core::Result<double> GetReal(const Args& args, const std::string& name, double fallback, double lo, double hi) {
  const auto v = args.Get(name);
  if (!v) return fallback;
  char* end = nullptr;
  const double x = std::strtod(v->c_str(), &end);
  if (v->empty() || *end != '\0' || !(x >= lo && x <= hi))
    return core::Status(core::ErrorCode::kInvalidArgument, "--" + name + " must be a number in [" +
                                                               std::to_string(lo) + ", " + std::to_string(hi) +
                                                               "], got '" + *v + "'");
  return x;
}
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
  std::printf("tracking decision (%d validation frames, %d found joints, %d Newton steps): P(within 0.1 m) = "
              "sigmoid(a_j + b_j logit(confidence) + w . cues)\n  joint        a_j    b_j\n",
              rep.frames, rep.samples, rep.iterations);
  for (int j = 0; j < core::kNumJoints; ++j)
    std::printf("  %-11s %6.2f %6.2f\n", std::string(core::JointName(j)).c_str(), double(m.intercept[size_t(j)]),
                double(m.slope[size_t(j)]));
  std::printf("  cues:");
  for (int k = 0; k < core::kNumTrackingFeatures; ++k)
    std::printf(" %s %.2f%s", core::TrackingFeatureName(k), double(m.shared[size_t(k)]),
                k + 1 < core::kNumTrackingFeatures ? "," : "\n");
  std::printf("learn-votes: wrote %s; tracking decision on its fitting frames: visible joints tracked within 0.1 m "
              "%.3f (rules %.3f), tracked joints within 0.1 m %.3f (rules %.3f), in %.0f s\n",
              out.c_str(), rep.model_within, rep.rules_within, rep.model_precision, rep.rules_precision, rep.seconds);
}
}  // namespace

int LearnVotesMain(int argc, char** argv) {
  Args args({"forest", "job", "out", "max-offset-m", "leaf-bandwidth-m", "vote-bandwidth-m", "min-weight",
             "validation-frames", "seed", "threads", "tracking-frames"},
            {"help", "quiet", "tracking-only"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!args.Has("forest") || !args.Has("job") || !args.Has("out") || !args.positional().empty()) {
    std::fprintf(stderr, "poseforest learn-votes: need --forest, --job and --out\n\n%s", kUsage);
    return 2;
  }
  engine::VoteLearningOptions opt;
  auto max_offset = GetReal(args, "max-offset-m", opt.max_offset_m, 0.05, 3.0);
  auto leaf_bw = GetReal(args, "leaf-bandwidth-m", opt.leaf_bandwidth_m, 0.005, 0.5);
  auto vote_bw = GetReal(args, "vote-bandwidth-m", opt.vote_bandwidth_m, 0.005, 0.5);
  auto min_weight = GetReal(args, "min-weight", opt.min_weight, 0.001, 1.0);
  for (const auto* r : {&max_offset, &leaf_bw, &vote_bw, &min_weight})
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest learn-votes: %s\n", r->status().message().c_str());
      return 2;
    }
  auto frames = args.GetInt("validation-frames", opt.validation_frames, 0, 1'000'000);
  auto tracking_frames = args.GetInt("tracking-frames", 200, 0, 1'000'000);
  auto seed = args.GetInt("seed", -1, 0, 1L << 62);
  auto threads = args.GetInt("threads", 0, 0, 1024);
  for (const auto* r : {&frames, &seed, &threads, &tracking_frames})
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest learn-votes: %s\n", r->status().message().c_str());
      return 2;
    }
  auto job = engine::LoadJob(*args.Get("job"));
  if (!job.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", job.status().ToString().c_str());
    return job.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
  }
  if (job->source.kind == engine::SourceKind::kProcedural) {
    std::fprintf(stderr, "poseforest learn-votes: %s: procedural frames have no joints\n",
                 args.Get("job")->c_str());
    return 2;
  }
  auto forest = core::LoadForest(*args.Get("forest"));
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const bool quiet = args.Has("quiet");
  opt.max_offset_m = float(*max_offset);
  opt.leaf_bandwidth_m = float(*leaf_bw);
  opt.vote_bandwidth_m = float(*vote_bw);
  if (args.Has("vote-bandwidth-m")) opt.bandwidth_grid.clear();
  opt.min_weight = float(*min_weight);
  opt.validation_frames = int(*frames);
  opt.threads = int(*threads);
  opt.validation = job->source;
  if (opt.validation.kind == engine::SourceKind::kRendered)
    opt.validation.seed = *seed >= 0 ? uint64_t(*seed) : job->source.seed + 1000003;
  if (!quiet)
    opt.progress = [](const std::string& line) {
      std::fprintf(stderr, "learn-votes: %s\n", line.c_str());
    };
  const bool tracking_only = args.Has("tracking-only");
  if (tracking_only && !forest->offset_votes) {
    std::fprintf(stderr, "poseforest learn-votes: --tracking-only: %s has no offset votes to keep\n",
                 args.Get("forest")->c_str());
    return 2;
  }
  if (tracking_only && *tracking_frames == 0) {
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
  if (*tracking_frames > 0) {
    engine::TrackingLearningOptions to;
    to.validation = opt.validation;
    to.first_index = uint64_t(opt.validation_frames);
    to.frames = int(*tracking_frames);
    to.threads = opt.threads;
    to.progress = opt.progress;
    auto model = engine::LearnTrackingModel(*forest, to, &trep);
    if (!model.ok()) {
      std::fprintf(stderr, "poseforest learn-votes: %s\n", model.status().ToString().c_str());
      return model.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    forest->tracking_model = *model;
  }
  if (auto st = core::SaveForest(*forest, *args.Get("out")); !st.ok()) {
    std::fprintf(stderr, "poseforest learn-votes: %s\n", st.ToString().c_str());
    return 1;
  }
  if (!tracking_only) PrintVotes(*forest, rep, *args.Get("out"));
  if (forest->tracking_model) PrintTracking(*forest->tracking_model, trep, *args.Get("out"));
  return 0;
}

}  // namespace poseforest::apps::commands
