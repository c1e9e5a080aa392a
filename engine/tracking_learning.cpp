#include "engine/tracking_learning.h"

#include <Eigen/Dense>

#include <chrono>
#include <cmath>

#include "engine/evaluation.h"
#include "runtime/classifier.h"
#include "runtime/joint_proposals.h"
#include "runtime/joint_votes.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Status;

namespace {

// Parameter layout: [intercept x joints | slope x joints | shared cues].
constexpr int kParams = 2 * core::kNumJoints + core::kNumTrackingFeatures;

void Design(int joint, float confidence, const core::TrackingFeatures& f, Eigen::VectorXd* x) {
  x->setZero(kParams);
  (*x)[joint] = 1.0;
  (*x)[core::kNumJoints + joint] = core::ClampedLogit(confidence);
  for (int k = 0; k < core::kNumTrackingFeatures; ++k) (*x)[2 * core::kNumJoints + k] = f[size_t(k)];
}

}  // namespace

core::TrackingModel FitTrackingModel(const std::vector<int>& joints, const std::vector<float>& confidences,
                                     const std::vector<core::TrackingFeatures>& cues,
                                     const std::vector<uint8_t>& labels, double l2, int* iterations) {
  const size_t n = joints.size();
  Eigen::VectorXd w = Eigen::VectorXd::Zero(kParams), x(kParams);
  int it = 0;
  // Newton's method on the penalized log-likelihood (convex: it converges from zero); the
  // samples are summed in their order, so the result does not depend on threads.
  for (; it < 50; ++it) {
    Eigen::VectorXd g = l2 * w;
    Eigen::MatrixXd h = l2 * Eigen::MatrixXd::Identity(kParams, kParams);
    for (size_t i = 0; i < n; ++i) {
      Design(joints[i], confidences[i], cues[i], &x);
      const double p = 1.0 / (1.0 + std::exp(-x.dot(w)));
      g += (p - double(labels[i])) * x;
      h.selfadjointView<Eigen::Lower>().rankUpdate(x, p * (1 - p));
    }
    const Eigen::VectorXd step = h.selfadjointView<Eigen::Lower>().ldlt().solve(g);
    w -= step;
    if (step.lpNorm<Eigen::Infinity>() < 1e-6) {
      ++it;
      break;
    }
  }
  if (iterations) *iterations = it;
  core::TrackingModel m;
  for (int j = 0; j < core::kNumJoints; ++j) {
    m.intercept[size_t(j)] = float(w[j]);
    m.slope[size_t(j)] = float(w[core::kNumJoints + j]);
  }
  for (int k = 0; k < core::kNumTrackingFeatures; ++k) m.shared[size_t(k)] = float(w[2 * core::kNumJoints + k]);
  m.samples = uint32_t(n);
  return m;
}

core::Result<core::TrackingModel> LearnTrackingModel(const core::Forest& forest,
                                                     const TrackingLearningOptions& options,
                                                     TrackingLearningReport* report) {
  const auto t0 = std::chrono::steady_clock::now();
  TrackingLearningReport rep;
  if (options.frames <= 0) return Status(ErrorCode::kInvalidArgument, "tracking model: no validation frames asked");
  auto src = MakeEvalFrameSource(options.validation);
  if (!src.ok()) return src.status();
  if (!(*src)->has_joints())
    return Status(ErrorCode::kInvalidArgument, (*src)->Describe() + ": validation frames have no joints");
  const core::CameraIntrinsics cam = (*src)->camera();
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  copt.want_foreground_distributions = true;
  copt.want_foreground_leaves = forest.offset_votes.has_value();
  runtime::ProposalOptions po;
  po.params = forest.ProposalParamsFor(false).params;
  po.num_threads = options.threads;
  po.camera = cam;
  const core::ConfidenceCalibration* calibration = forest.CalibrationFor(/*fast_clustering=*/false);
  runtime::VoteOptions vo;
  vo.threads = options.threads;
  std::vector<int> joints;
  std::vector<float> confidences;
  std::vector<core::TrackingFeatures> cues;
  std::vector<uint8_t> labels, visible;
  std::vector<uint8_t> rules_tracked;
  runtime::Classification out;
  for (int i = 0; i < options.frames; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    if ((i + 1) % 50 == 0 && options.progress)
      options.progress("tracking model: " + std::to_string(i + 1) + " / " + std::to_string(options.frames) +
                       " validation frames");
    if (frame->people.size() != 1) continue;
    ++rep.frames;
    const bool has_mask = frame->person_masks.pixels.size() == frame->depth.pixels.size();
    core::LabelImage mask(frame->depth.width, frame->depth.height, 0);
    for (size_t k = 0; k < mask.pixels.size(); ++k)
      mask.pixels[k] = has_mask ? (frame->person_masks.pixels[k] == 1) : (frame->depth.pixels[k] ? 1 : 0);
    classifier.Classify(frame->depth, copt, &out);
    const auto proposals = runtime::ProposeJointsFromClassification(frame->depth, out, po);
    std::vector<runtime::PersonVotes> votes;
    if (forest.offset_votes) votes = runtime::CastVotes(forest, frame->depth, mask, 1, cam, vo, &out);
    const auto skeletons = runtime::BuildSkeletons(proposals, mask, 1, frame->depth, cam, calibration,
                                                   options.skeleton, votes.empty() ? nullptr : &votes);
    if (skeletons.empty()) continue;
    const auto& truth = frame->people[0];
    for (int j = 0; j < core::kNumJoints; ++j) {
      const runtime::SkeletonJoint& joint = skeletons[0].joints[size_t(j)];
      const bool seen = truth.visible[size_t(j)];
      // A joint the skeleton did not find, or placed beyond the frame
      // (SkeletonOptions::votes_beyond_frame), is never tracked: scored, not a sample of the fit.
      if (!joint.found || !runtime::PixelInImage(joint.pixel, frame->depth.width, frame->depth.height)) {
        joints.push_back(-1 - j);  // the marker
        confidences.push_back(0);
        cues.push_back({});
        labels.push_back(0);
        visible.push_back(seen);
        rules_tracked.push_back(0);
        continue;
      }
      joints.push_back(j);
      confidences.push_back(joint.base_confidence);
      cues.push_back(joint.cues);
      labels.push_back((joint.position_m - truth.position[size_t(j)]).norm() <= 0.1f);
      visible.push_back(seen);
      rules_tracked.push_back(joint.tracked);
    }
  }
  if (rep.frames == 0)
    return Status(ErrorCode::kInvalidArgument, (*src)->Describe() + ": no one-person validation frame");
  std::vector<int> fj;
  std::vector<float> fc;
  std::vector<core::TrackingFeatures> ff;
  std::vector<uint8_t> fl, fv;
  for (size_t i = 0; i < joints.size(); ++i)
    if (joints[i] >= 0)
      fj.push_back(joints[i]), fc.push_back(confidences[i]), ff.push_back(cues[i]), fl.push_back(labels[i]),
          fv.push_back(visible[i]);
  core::TrackingModel model = FitTrackingModel(fj, fc, ff, fl, options.l2, &rep.iterations);
  // The seen decision: the same samples and form, labelled by whether the camera sees the joint.
  if (options.seen_model) model.seen = core::TrackingWeights(FitTrackingModel(fj, fc, ff, fv, options.l2));
  // The skeletons above had no model to resolve the fit from: options.skeleton.fit, else kinematic.
  model.fit = core::TrackingFit(runtime::ResolveSkeletonFit(options.skeleton, nullptr));
  rep.samples = int(fj.size());
  // In-sample figures, rules against model (the same positions; only the decision differs).
  struct Tally {
    std::array<double, core::kNumJoints> hit{};
    double tracked = 0, right = 0, untracked = 0, untracked_hidden = 0;
  };
  std::array<double, core::kNumJoints> vis{};
  Tally rules, within, seen;
  auto count = [&](Tally& t, size_t i, int j, bool tracked) {
    if (visible[i]) t.hit[size_t(j)] += tracked && labels[i];
    t.tracked += tracked, t.right += tracked && labels[i];
    t.untracked += !tracked, t.untracked_hidden += !tracked && !visible[i];
  };
  for (size_t i = 0; i < joints.size(); ++i) {
    const int j = joints[i] >= 0 ? joints[i] : -1 - joints[i];
    const bool at_surface = joints[i] >= 0 && cues[i][core::kFeatDepthGap] <= options.skeleton.max_depth_gap_m;
    const float p = options.skeleton.track_probability;
    vis[size_t(j)] += visible[i];
    count(rules, i, j, rules_tracked[i]);
    count(within, i, j, at_surface && model.Probability(j, confidences[i], cues[i]) >= p);
    if (model.seen)
      count(seen, i, j,
            at_surface &&
                model.seen->Probability(j, confidences[i], cues[i]) >= options.skeleton.seen_probability);
  }
  auto figures = [&](const Tally& t, TrackingLearningReport::Figures& f) {
    int scored = 0;
    for (int j = 0; j < core::kNumJoints; ++j)
      if (vis[size_t(j)] > 0) f.visible_within += t.hit[size_t(j)] / vis[size_t(j)], ++scored;
    if (scored) f.visible_within /= scored;
    f.precision = t.tracked > 0 ? t.right / t.tracked : 0;
    f.untracked_hidden = t.untracked > 0 ? t.untracked_hidden / t.untracked : 0;
  };
  rep.track_probability = options.skeleton.track_probability;
  rep.seen_probability = options.skeleton.seen_probability;
  figures(rules, rep.rules);
  figures(within, rep.model);
  if (model.seen) figures(seen, rep.seen);
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (report) *report = rep;
  return model;
}

}  // namespace poseforest::engine
