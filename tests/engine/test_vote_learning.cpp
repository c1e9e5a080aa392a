// Offset votes (format 1.5): `learn-votes` on a tiny rendered job (real EGL rendering) - the
// votes put the joints of the frames they were learned from where they are, the table does not
// depend on the number of threads, bad inputs are refused - and the command end to end (the
// forest keeps its trees, `inspect` shows the votes, `eval` uses them or not).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <string>

#include "engine/evaluation.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "engine/tracking_learning.h"
#include "engine/vote_learning.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/forest_format.h"
#include "runtime/joint_votes.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

using namespace poseforest;
using testing::RunPoseforest;

namespace {

const char* kJob =
    "seed: 3 num_trees: 2 max_depth: 12 images_per_tree: 16 pixels_per_image: 600\n"
    "candidate_features: 60 thresholds_per_feature: 10\n"
    "source { rendered { seed: 1 } }\n"
    "test_set { source { rendered { seed: 99 } } num_images: 4 }\n";

engine::TrainParams Job() {
  auto c = engine::ParseJobText(kJob, "job.textproto");
  REQUIRE(c.ok());
  auto p = engine::ParamsFromConfig(*c, "job.textproto");
  REQUIRE(p.ok());
  return *p;
}

core::Forest Train(const engine::TrainParams& job) {
  auto forest = engine::LocalTrainer(job, engine::LocalTrainerOptions{}).Train();
  REQUIRE(forest.ok());
  return std::move(*forest);
}

}  // namespace

TEST_CASE("learn-votes: the votes place the joints of the frames they were learned from; same table on 1 and 2 threads",
          "[votes][egl]") {
  const engine::TrainParams job = Job();
  const core::Forest forest = Train(job);
  engine::VoteLearningOptions opt;
  opt.validation = job.source;  // the training frames themselves: tree 0's first frames
  opt.validation_frames = 8;
  opt.threads = 1;
  engine::VoteLearningReport rep;
  auto one = engine::LearnOffsetVotes(forest, job, opt, &rep);
  REQUIRE(one.ok());
  REQUIRE(one->trees.size() == 2);
  CHECK(rep.pixels > 0);
  CHECK(rep.votes == one->total_votes());
  CHECK(rep.leaves_with_votes > rep.leaves / 2);
  CHECK(core::ValidateOffsetVotes(*one, {forest.trees[0].num_leaves, forest.trees[1].num_leaves}, "votes").ok());
  // The default reaches: 0.3 m to the head, neck, shoulders, wrists and hands, 0.9 m to the
  // elbows, knees, ankles and feet; the table records the longest.
  CHECK(engine::VoteReach(int(core::Joint::kHead), opt) == opt.max_offset_m);
  CHECK(engine::VoteReach(int(core::Joint::kRShoulder), opt) == opt.max_offset_m);
  CHECK(engine::VoteReach(int(core::Joint::kLElbow), opt) == opt.limb_max_offset_m);
  CHECK(engine::VoteReach(int(core::Joint::kRFoot), opt) == opt.limb_max_offset_m);
  CHECK(engine::VoteReach(int(core::Joint::kLWrist), opt) == opt.hand_max_offset_m);
  CHECK(engine::VoteReach(int(core::Joint::kRHand), opt) == opt.hand_max_offset_m);
  CHECK(opt.limb_max_offset_m > opt.max_offset_m);
  CHECK(one->max_offset_m == opt.limb_max_offset_m);
  for (const core::JointVote& v : one->trees[0].votes) {
    CHECK(v.weight >= 1);
    // Stored offsets are the modes of offsets shorter than the joint's reach.
    CHECK(std::sqrt(double(v.dx_mm) * v.dx_mm + double(v.dy_mm) * v.dy_mm + double(v.dz_mm) * v.dz_mm) <=
          1000.0 * engine::VoteReach(v.joint, opt) + 1);
  }
  // On frames the tree was grown from, the votes know where the joints are (a sign or frame
  // error in the offsets puts them nowhere near).
  double within = 0;
  int joints = 0;
  for (int j = 0; j < core::kNumJoints; ++j)
    if (rep.scored[size_t(j)]) within += double(rep.top_within[size_t(j)]) / rep.scored[size_t(j)], ++joints;
  REQUIRE(joints == core::kNumJoints);
  INFO("top vote candidate within 0.1 m on the training frames: " << within / joints);
  CHECK(within / joints > 0.6);
  // The calibration: one row per joint, non-decreasing in share.
  const size_t bins = one->share_edges.size();
  REQUIRE(bins > 0);
  REQUIRE(one->precision.size() == bins * core::kNumJoints);
  for (int j = 0; j < core::kNumJoints; ++j)
    for (size_t b = 1; b < bins; ++b)
      CHECK(one->precision[size_t(j) * bins + b] >= one->precision[size_t(j) * bins + b - 1]);

  opt.threads = 2;
  auto two = engine::LearnOffsetVotes(forest, job, opt);
  REQUIRE(two.ok());
  CHECK(*two == *one);

  // One reach for every joint (the limbs' and the hands' 0: as max_offset_m) against a longer
  // one for the limbs: their votes may be longer than max_offset_m, the head's, neck's and
  // shoulders' never; with the hands' reach 0 the wrists and hands take the limbs', else their own.
  {
    engine::VoteLearningOptions flat = opt;
    flat.limb_max_offset_m = 0;
    flat.hand_max_offset_m = 0;
    for (int j = 0; j < core::kNumJoints; ++j) CHECK(engine::VoteReach(j, flat) == flat.max_offset_m);
    auto short_votes = engine::LearnOffsetVotes(forest, job, flat);
    REQUIRE(short_votes.ok());
    CHECK(short_votes->max_offset_m == flat.max_offset_m);
    CHECK(one->total_votes() > short_votes->total_votes());
    for (const float hand : {0.0f, flat.max_offset_m}) {
      engine::VoteLearningOptions limbs = flat;
      limbs.limb_max_offset_m = 2 * opt.max_offset_m;
      limbs.hand_max_offset_m = hand;
      auto reach = engine::LearnOffsetVotes(forest, job, limbs);
      REQUIRE(reach.ok());
      CHECK(reach->max_offset_m == limbs.limb_max_offset_m);
      CHECK(reach->total_votes() > short_votes->total_votes());
      int longer = 0, longer_hands = 0;
      for (const auto& tree : reach->trees)
        for (const core::JointVote& v : tree.votes) {
          const double mm =
              std::sqrt(double(v.dx_mm) * v.dx_mm + double(v.dy_mm) * v.dy_mm + double(v.dz_mm) * v.dz_mm);
          const bool limb = v.joint >= uint8_t(core::Joint::kLElbow);
          const bool hands =
              v.joint >= uint8_t(core::Joint::kLWrist) && v.joint <= uint8_t(core::Joint::kRHand);
          const float reach_j = !limb ? opt.max_offset_m : hands && hand > 0 ? hand : limbs.limb_max_offset_m;
          CHECK(engine::VoteReach(v.joint, limbs) == reach_j);
          CHECK(mm <= 1000.0 * reach_j + 1);
          longer += limb && mm > 1000.0 * opt.max_offset_m + 1;
          longer_hands += hands && mm > 1000.0 * opt.max_offset_m + 1;
        }
      CHECK(longer > 0);
      CHECK((longer_hands > 0) == (hand == 0));
    }
    engine::VoteLearningOptions bad = opt;
    bad.limb_max_offset_m = -0.1f;
    CHECK_FALSE(engine::LearnOffsetVotes(forest, job, bad).ok());
    bad = opt;
    bad.hand_max_offset_m = -0.1f;
    CHECK_FALSE(engine::LearnOffsetVotes(forest, job, bad).ok());
  }

  // The candidates of a training frame: the head's most confident one is near the head.
  auto src = engine::MakeEvalFrameSource(job.source);
  REQUIRE(src.ok());
  auto frame = (*src)->Frame(0);
  REQUIRE(frame.ok());
  REQUIRE(frame->people.size() == 1);
  core::Forest with = forest;
  with.offset_votes = *one;
  core::LabelImage mask(frame->depth.width, frame->depth.height, 0);
  for (size_t k = 0; k < mask.pixels.size(); ++k) mask.pixels[k] = frame->depth.pixels[k] ? 1 : 0;
  const auto cands = runtime::CastVotes(with, frame->depth, mask, 1, (*src)->camera());
  REQUIRE(cands.size() == 1);
  const auto& head = cands[0][size_t(core::Joint::kHead)];
  REQUIRE_FALSE(head.empty());
  CHECK((head[0].position - frame->people[0].position[size_t(core::Joint::kHead)]).norm() < 0.1f);
  CHECK(head[0].share > 0);
  CHECK(head[0].confidence == one->Confidence(int(core::Joint::kHead), head[0].share));
  // A forest without votes casts none.
  const auto none = runtime::CastVotes(forest, frame->depth, mask, 1, (*src)->camera());
  REQUIRE(none.size() == 1);
  for (const auto& c : none[0]) CHECK(c.empty());

  // The tracking decision of the forest with its votes, on frames after the calibration's:
  // fitted on every found joint, the same model on 1 and 2 threads.
  engine::TrackingLearningOptions to;
  to.validation = job.source;
  to.first_index = 8;
  to.frames = 6;
  to.threads = 1;
  engine::TrackingLearningReport trep;
  auto m1 = engine::LearnTrackingModel(with, to, &trep);
  REQUIRE(m1.ok());
  CHECK(trep.frames == 6);
  CHECK(trep.samples > 6 * 8);  // most of 16 joints found per frame
  CHECK(int(m1->samples) == trep.samples);
  CHECK(trep.iterations > 1);
  CHECK(trep.model.visible_within > 0);
  CHECK(core::ValidateTrackingModel(*m1, "model").ok());
  // The seen decision: fitted on the same samples with the renders' `visible` as labels, so
  // weights of its own. On its fitting frames the joints it leaves untracked are hidden more
  // often than those P(within 0.1 m) leaves untracked: what it is fitted for.
  REQUIRE(m1->seen.has_value());
  CHECK(m1->seen->shared != m1->shared);
  INFO("untracked and hidden: seen " << trep.seen.untracked_hidden << ", within " << trep.model.untracked_hidden);
  CHECK(trep.seen.visible_within > 0);
  CHECK(trep.seen.untracked_hidden > trep.model.untracked_hidden);
  // The figures are counted at the run-time thresholds, which the report names.
  CHECK(trep.track_probability == runtime::SkeletonOptions{}.track_probability);
  CHECK(trep.seen_probability == runtime::SkeletonOptions{}.seen_probability);
  CHECK(m1->fit == core::TrackingFit::kKinematic);  // unset: the run-time default, recorded
  to.threads = 2;
  auto m2 = engine::LearnTrackingModel(with, to);
  REQUIRE(m2.ok());
  CHECK(*m2 == *m1);
  // Fitted on the greedy fit's choices: another population of positions, recorded as greedy.
  to.skeleton.fit = runtime::SkeletonFit::kGreedy;
  auto mg = engine::LearnTrackingModel(with, to);
  REQUIRE(mg.ok());
  CHECK(mg->fit == core::TrackingFit::kGreedy);
  CHECK(mg->shared != m1->shared);
  to.skeleton.fit.reset();
  // Without the seen decision: the same P(within 0.1 m) weights, no seen model (a 1.7 decision).
  to.seen_model = false;
  auto plain = engine::LearnTrackingModel(with, to);
  REQUIRE(plain.ok());
  CHECK_FALSE(plain->seen.has_value());
  CHECK(core::TrackingWeights(*plain) == core::TrackingWeights(*m1));
  to.seen_model = true;
  // A procedural source has no joints.
  to.validation = engine::SourceSpec{};
  to.validation.kind = engine::SourceKind::kProcedural;
  auto refused = engine::LearnTrackingModel(with, to);
  REQUIRE_FALSE(refused.ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("no joints"));
}

TEST_CASE("the tracking decision's fit recovers the weights that made its labels, deterministically",
          "[tracking]") {
  // Samples drawn from a known model: every joint a_j = 0.5 - 0.1 j, b_j = 1; cut edge -2,
  // impossible bone -1.5, the proposal-vote gap -3 per metre; the other cues 0.
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<int> joints;
  std::vector<float> conf;
  std::vector<core::TrackingFeatures> cues;
  std::vector<uint8_t> labels;
  auto truth = [](int j, float c, const core::TrackingFeatures& f) {
    const double z = 0.5 - 0.1 * j + core::ClampedLogit(c) - 2.0 * f[core::kFeatNearCutEdge] -
                     1.5 * f[core::kFeatBoneBad] - 3.0 * f[core::kFeatProposalVoteGap];
    return 1 / (1 + std::exp(-z));
  };
  for (int i = 0; i < 40000; ++i) {
    core::TrackingFeatures f{};
    const int j = i % core::kNumJoints;
    const float c = 0.02f + 0.96f * u(rng);
    f[core::kFeatNearCutEdge] = u(rng) < 0.2f;
    f[core::kFeatBoneBad] = u(rng) < 0.3f;
    f[core::kFeatBoneOk] = 1 - f[core::kFeatBoneBad];
    f[core::kFeatProposalVoteGap] = 0.5f * u(rng);
    f[core::kFeatHasProposal] = 1;
    f[core::kFeatHasVote] = u(rng) < 0.5f;
    joints.push_back(j);
    conf.push_back(c);
    cues.push_back(f);
    labels.push_back(u(rng) < truth(j, c, f));
  }
  int steps = 0;
  const core::TrackingModel m = engine::FitTrackingModel(joints, conf, cues, labels, 1.0, &steps);
  CHECK(steps > 2);
  CHECK(steps < 50);
  CHECK(m.samples == 40000);
  // bone ok + bone impossible = 1 = has proposal: only their differences are determined, so
  // compare what the model predicts, and the weights that are identified.
  CHECK(m.shared[core::kFeatNearCutEdge] == Approx(-2.0).margin(0.25));
  CHECK(m.shared[core::kFeatProposalVoteGap] == Approx(-3.0).margin(0.6));
  CHECK(m.shared[core::kFeatBoneBad] - m.shared[core::kFeatBoneOk] == Approx(-1.5).margin(0.25));
  CHECK(m.shared[core::kFeatHasVote] == Approx(0.0).margin(0.25));
  for (int j = 0; j < core::kNumJoints; ++j) CHECK(m.slope[size_t(j)] == Approx(1.0).margin(0.3));
  double worst = 0;
  for (size_t i = 0; i < 2000; ++i)
    worst = std::max(worst, std::abs(m.Probability(joints[i], conf[i], cues[i]) - truth(joints[i], conf[i], cues[i])));
  CHECK(worst < 0.12);
  // The same samples, the same model, bit for bit.
  CHECK(engine::FitTrackingModel(joints, conf, cues, labels, 1.0) == m);
}

TEST_CASE("learn-votes refuses a procedural job and a forest of another job", "[votes][egl]") {
  engine::TrainParams job = Job();
  const core::Forest forest = Train(job);
  engine::VoteLearningOptions opt;
  opt.validation = job.source;
  opt.validation_frames = 0;
  engine::TrainParams other = job;
  other.num_trees = 3;
  auto wrong = engine::LearnOffsetVotes(forest, other, opt);
  REQUIRE_FALSE(wrong.ok());
  CHECK(wrong.status().code() == core::ErrorCode::kInvalidArgument);
  CHECK_THAT(wrong.status().message(), Catch::Contains("not the forest of this job"));
  // The same tree count, but other training frames: the leaves the forest's own pixels made are
  // not reached by these, and that is refused after the first tree.
  engine::TrainParams reseeded = job;
  reseeded.source.seed += 1;
  engine::TrainParams fewer = job;
  fewer.images_per_tree /= 2;
  for (const engine::TrainParams* other_frames : {&reseeded, &fewer}) {
    auto r = engine::LearnOffsetVotes(forest, *other_frames, opt);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == core::ErrorCode::kInvalidArgument);
    CHECK_THAT(r.status().message(), Catch::StartsWith("tree 0: ") &&
                                         Catch::Contains("reached by none of the job's training pixels") &&
                                         Catch::Contains("not the forest of this job"));
  }
  engine::VoteLearningReport own;
  REQUIRE(engine::LearnOffsetVotes(forest, job, opt, &own).ok());
  CHECK(own.leaves_unreached == 0);
  CHECK(own.leaves > 0);
  engine::TrainParams procedural = job;
  procedural.source = engine::SourceSpec{};
  procedural.source.kind = engine::SourceKind::kProcedural;
  auto proc = engine::LearnOffsetVotes(forest, procedural, opt);
  REQUIRE_FALSE(proc.ok());
  CHECK(proc.status().code() == core::ErrorCode::kInvalidArgument);
  CHECK_THAT(proc.status().message(), Catch::Contains("no joints"));
}

TEST_CASE("poseforest learn-votes end to end: votes added, trees kept, inspect and eval", "[votes][cli][egl]") {
  const auto dir = testing::ScratchDir("cli-learn-votes");
  const std::string job = (dir / "job.textproto").string(), forest = (dir / "forest.pff").string(),
                    voted = (dir / "voted.pff").string();
  std::ofstream(job) << kJob;
  auto train = RunPoseforest("train " + job + " --out " + forest + " --quiet");
  INFO(train.output);
  REQUIRE(train.exit_code == 0);
  auto learn = RunPoseforest("learn-votes --forest " + forest + " --job " + job + " --out " + voted +
                             " --validation-frames 4 --tracking-frames 5");
  INFO(learn.output);
  REQUIRE(learn.exit_code == 0);
  CHECK_THAT(learn.output, Catch::Contains("learn-votes: tree 1: 16 / 16 training frames") &&
                               Catch::Contains("votes: ") && Catch::Contains("calibration (4 validation frames") &&
                               Catch::Contains("learn-votes: wrote " + voted) &&
                               Catch::Contains("tracking decision (kinematic fit, 5 validation frames"));
  auto before = core::LoadForest(forest);
  auto after = core::LoadForest(voted);
  REQUIRE(before.ok());
  REQUIRE(after.ok());
  CHECK_FALSE(before->offset_votes.has_value());
  REQUIRE(after->offset_votes.has_value());
  REQUIRE(after->trees.size() == before->trees.size());
  for (size_t t = 0; t < after->trees.size(); ++t) {
    const auto& a = after->trees[t].nodes;
    const auto& b = before->trees[t].nodes;
    REQUIRE(a.size() == b.size());
    CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(core::Node)) == 0);
    CHECK(after->trees[t].leaves == before->trees[t].leaves);
  }
  REQUIRE(after->tracking_model.has_value());
  CHECK_FALSE(before->tracking_model.has_value());
  auto inspect = RunPoseforest("inspect " + voted);
  CHECK(inspect.exit_code == 0);
  CHECK_THAT(inspect.output, Catch::Contains("offset votes (JVOT): ") &&
                                 Catch::Contains("tracking decision (JTRK): learned on " +
                                                 std::to_string(after->tracking_model->samples) +
                                                 " validation joints of the kinematic fit (JTFT)"));
  CHECK(after->tracking_model->fit == core::TrackingFit::kKinematic);
  auto inspect_plain = RunPoseforest("inspect " + forest);
  CHECK_THAT(inspect_plain.output, Catch::Contains("tracking decision: the hand-set rules (no JTRK section)"));
  // --tracking-only keeps the votes and fits the same model again: the same file.
  const std::string again = (dir / "again.pff").string();
  auto only = RunPoseforest("learn-votes --tracking-only --forest " + voted + " --job " + job + " --out " + again +
                            " --validation-frames 4 --tracking-frames 5");
  INFO(only.output);
  REQUIRE(only.exit_code == 0);
  CHECK_THAT(only.output, Catch::Contains("tracking decision (kinematic fit, 5 validation frames"));
  // Its in-sample lines name the thresholds they were counted at (0.2 for P(seen) since 29 Nov).
  CHECK_THAT(only.output,
             Catch::Contains("a joint is tracked when it reaches 0.2 (`live --seen-probability`)") &&
                 Catch::Contains("tracked when P(seen) >= 0.2:") &&
                 Catch::Contains("tracked when P(within 0.1 m) >= 0.5:"));
  CHECK_THAT(only.output, !Catch::Contains("training frames"));  // no votes learned again
  CHECK(core::ReadFileBytes(again).value() == core::ReadFileBytes(voted).value());
  auto no_votes = RunPoseforest("learn-votes --tracking-only --forest " + forest + " --job " + job + " --out " + again);
  CHECK(no_votes.exit_code == 2);
  CHECK_THAT(no_votes.output, Catch::Contains("--tracking-only: " + forest + " has no offset votes to keep"));
  auto no_frames = RunPoseforest("learn-votes --tracking-only --forest " + voted + " --job " + job + " --out " + again +
                                 " --tracking-frames 0");
  CHECK(no_frames.exit_code == 2);
  CHECK_THAT(no_frames.output, Catch::Contains("--tracking-only needs --tracking-frames > 0"));
  // eval's skeleton table with and without the votes (both run; the numbers are the figures'
  // business, not this test's), and which fit chose the positions: by default the one the
  // forest's decision learned, kinematic without one, or --fit's.
  for (const auto& [extra, fit] : std::vector<std::pair<std::string, std::string>>{
           {"", "kinematic"}, {" --no-votes", "kinematic"}, {" --no-tracking-model", "kinematic"},
           {" --fit greedy", "greedy"}}) {
    auto eval = RunPoseforest("eval --forest " + voted + " --test-set " + job + " --images 3 --quiet" + extra);
    INFO(eval.output);
    CHECK(eval.exit_code == 0);
    CHECK_THAT(eval.output, Catch::Contains("found within") && Catch::Contains(", " + fit + " fit):"));
  }
  // A decision learned on the greedy fit's choices: eval runs greedy unless told otherwise.
  const std::string greedy = (dir / "greedy.pff").string();
  auto learn_greedy = RunPoseforest("learn-votes --tracking-only --fit greedy --forest " + voted + " --job " + job +
                                    " --out " + greedy + " --validation-frames 4 --tracking-frames 5");
  INFO(learn_greedy.output);
  REQUIRE(learn_greedy.exit_code == 0);
  CHECK_THAT(learn_greedy.output, Catch::Contains("tracking decision (greedy fit, 5 validation frames"));
  CHECK(core::LoadForest(greedy)->tracking_model->fit == core::TrackingFit::kGreedy);
  auto eval_greedy = RunPoseforest("eval --forest " + greedy + " --test-set " + job + " --images 3 --quiet");
  INFO(eval_greedy.output);
  CHECK_THAT(eval_greedy.output, Catch::Contains(", greedy fit):"));
  auto bad_fit = RunPoseforest("learn-votes --tracking-only --fit exact --forest " + voted + " --job " + job +
                               " --out " + greedy);
  CHECK(bad_fit.exit_code == 2);
  CHECK_THAT(bad_fit.output, Catch::Contains("must be kinematic or greedy (got 'exact')"));
  // Errors: a usage error names what is missing; a procedural job has no joints.
  auto usage = RunPoseforest("learn-votes --forest " + forest + " --out " + voted);
  CHECK(usage.exit_code == 2);
  CHECK_THAT(usage.output, Catch::Contains("--job is required"));
  const std::string proc = (dir / "proc.textproto").string();
  std::ofstream(proc) << "seed: 3 num_trees: 2 images_per_tree: 4 source { procedural { seed: 1 } }\n";
  auto no_joints = RunPoseforest("learn-votes --forest " + forest + " --job " + proc + " --out " + voted);
  CHECK(no_joints.exit_code == 2);
  CHECK_THAT(no_joints.output, Catch::Contains("procedural frames have no joints"));
  auto bad = RunPoseforest("learn-votes --forest " + forest + " --job " + job + " --out " + voted +
                           " --max-offset-m 9");
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("--max-offset-m must be a number in"));
}
