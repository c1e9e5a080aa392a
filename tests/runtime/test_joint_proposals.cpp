// Joint proposals (eq. 7-8) and the AP metric of section 4.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

#include "runtime/core/rng.h"
#include "runtime/joint_metrics.h"
#include "runtime/joint_proposals.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
using runtime::JointProposal;

namespace {

constexpr int kHead = int(core::Joint::kHead);
constexpr int kLHand = int(core::Joint::kLHand);

// Labels the synthetic figure of MakePersonDepth by where a pixel's surface point lies on the
// body: head above 0.5 m, the far ends of the arms are hands (left = image right for a person
// facing the camera).
core::LabelImage LabelFigure(const core::DepthImage& depth, double lateral = 0, double vertical = 0) {
  const auto cam = core::CameraIntrinsics::KinectV1();
  core::LabelImage labels(depth.width, depth.height, core::kBackgroundLabel);
  for (int y = 0; y < depth.height; ++y)
    for (int x = 0; x < depth.width; ++x) {
      if (depth.at(x, y) == 0) continue;
      const Eigen::Vector3d p = cam.PixelToPoint(x, y, depth.at(x, y));  // the surface point
      const double bx = p.x() - lateral, by = p.y() - vertical;
      uint8_t l = uint8_t(core::Part::kLUTorso);
      if (by < -0.5) l = uint8_t(core::Part::kLUHead);
      else if (bx > 0.7) l = uint8_t(core::Part::kLHand);
      else if (bx < -0.7) l = uint8_t(core::Part::kRHand);
      labels.at(x, y) = l;
    }
  return labels;
}

}  // namespace

TEST_CASE("mean shift finds the known modes of weighted point sets", "[proposals]") {
  core::RngStream rng(core::CounterRng(5));
  std::vector<Eigen::Vector3f> pts;
  std::vector<float> w, seed;
  const Eigen::Vector3f a(0, 0, 2), b(0.4f, 0.1f, 2.5f);
  for (int i = 0; i < 2000; ++i) {
    const bool first = i < 1200;
    const Eigen::Vector3f c = first ? a : b;
    pts.push_back(c + 0.02f * Eigen::Vector3f(float(rng.Normal()), float(rng.Normal()), float(rng.Normal())));
    w.push_back(first ? 1.0f : 2.0f);
    seed.push_back(w.back());
  }
  const auto modes = runtime::MeanShiftModes(pts, w, seed, 0.05f, 50, 0.025f);
  REQUIRE(modes.size() == 2);
  // b carries 800 * 2 = 1600 of seed weight, a 1200: b is the more confident mode.
  CHECK((modes[0].position - b).norm() < 0.005f);
  CHECK((modes[1].position - a).norm() < 0.005f);
  CHECK(modes[0].confidence == Approx(1600).epsilon(1e-4));
  CHECK(modes[1].confidence == Approx(1200).epsilon(1e-4));
  // Seeds restricted to one blob: only that mode.
  std::vector<float> seed_a(seed.size(), 0.0f);
  for (int i = 0; i < 100; ++i) seed_a[size_t(i)] = 1.0f;
  const auto only_a = runtime::MeanShiftModes(pts, w, seed_a, 0.05f, 50, 0.025f);
  REQUIRE(only_a.size() == 1);
  CHECK((only_a[0].position - a).norm() < 0.005f);
  CHECK(runtime::MeanShiftModes({}, {}, {}, 0.05f, 50, 0.025f).empty());
}

TEST_CASE("proposals are depth invariant: the same body at 2 m and 4 m", "[proposals]") {
  for (auto method : {runtime::ProposalMethod::kMeanShift, runtime::ProposalMethod::kFastClustering}) {
    runtime::ProposalOptions opt;
    opt.method = method;
    // The head on the optical axis (figure moved down 0.62 m), so that perspective shows the
    // same side of it at both distances; only the pixel density changes, which eq. 8's d^2
    // weight must undo.
    std::array<Eigen::Vector3f, 2> head, hand;
    std::array<size_t, 2> props_count{};
    const double distances[2] = {2.0, 4.0};
    for (int k = 0; k < 2; ++k) {
      const auto depth = testing::MakePersonDepth(distances[k], 640, 480, 0.0, 0.62);
      const auto probs = runtime::ProbabilitiesFromLabels(depth, LabelFigure(depth, 0.0, 0.62));
      const auto props = runtime::ProposeJoints(depth, probs, opt);
      REQUIRE_FALSE(props[kHead].empty());
      REQUIRE_FALSE(props[kLHand].empty());
      const Eigen::Vector3f origin(0, 0.62f, float(distances[k]));
      head[size_t(k)] = props[kHead][0].position - origin;
      hand[size_t(k)] = props[kLHand][0].position - origin;
      props_count[size_t(k)] = props[kHead].size();
    }
    INFO("method " << int(method) << " head " << head[0].transpose() << " / " << head[1].transpose());
    CHECK((head[0] - head[1]).norm() < 0.005f);
    CHECK(props_count[0] == 1);
    CHECK(props_count[1] == 1);
    // And in the right place: the head mode near the head centre (0, -0.62) pushed back by zeta.
    CHECK(std::abs(head[0].y() + 0.62f) < 0.01f);
    CHECK(std::abs(head[0].x()) < 0.01f);
    // The hands are off-axis: perspective shows them from another angle at each distance, so
    // they agree less tightly (the paper: invariant "modulo perspective effects").
    CHECK((hand[0] - hand[1]).norm() < 0.03f);
  }
}

TEST_CASE("two people give two proposals per joint", "[proposals]") {
  // Two figures side by side: the union of two renders.
  auto left = testing::MakePersonDepth(3.0, 640, 480, -0.9), right = testing::MakePersonDepth(3.0, 640, 480, 0.9);
  core::DepthImage both = left;
  for (size_t i = 0; i < both.pixels.size(); ++i)
    if (right.pixels[i] != 0 && (both.pixels[i] == 0 || right.pixels[i] < both.pixels[i])) both.pixels[i] = right.pixels[i];
  core::LabelImage labels = LabelFigure(left, -0.9), l2 = LabelFigure(right, 0.9);
  for (size_t i = 0; i < labels.pixels.size(); ++i)
    if (right.pixels[i] != 0 && both.pixels[i] == right.pixels[i]) labels.pixels[i] = l2.pixels[i];
  for (auto method : {runtime::ProposalMethod::kMeanShift, runtime::ProposalMethod::kFastClustering}) {
    runtime::ProposalOptions opt;
    opt.method = method;
    const auto props = runtime::ProposeJoints(both, runtime::ProbabilitiesFromLabels(both, labels), opt);
    INFO("method " << int(method));
    for (auto& p : props[kHead]) INFO(p.position.transpose() << " conf " << p.confidence);
    REQUIRE(props[kHead].size() == 2);
    CHECK(std::abs(std::abs(props[kHead][0].position.x()) - 0.9f) < 0.03f);
    CHECK(std::abs(props[kHead][0].position.x() + props[kHead][1].position.x()) < 0.05f);
  }
}

TEST_CASE("empty, all-background and NaN inputs give no proposals and no crash", "[proposals]") {
  runtime::ProposalOptions opt;
  core::DepthImage empty;
  CHECK(runtime::ProposeJoints(empty, {}, opt)[kHead].empty());
  core::DepthImage bg(64, 48, 0);
  runtime::Classification c;
  auto probs = runtime::ProbabilitiesFromLabels(bg, core::LabelImage(64, 48, core::kBackgroundLabel));
  CHECK(probs.pixel.empty());
  for (auto method : {runtime::ProposalMethod::kMeanShift, runtime::ProposalMethod::kFastClustering}) {
    opt.method = method;
    for (const auto& j : runtime::ProposeJoints(bg, probs, opt)) CHECK(j.empty());
    core::DepthImage flat(64, 48, 2000);
    runtime::JointProbabilities nan;
    nan.width = 64;
    nan.height = 48;
    for (uint32_t i = 0; i < 64 * 48; ++i) {
      nan.pixel.push_back(i);
      std::array<float, core::kNumJoints> p;
      p.fill(std::numeric_limits<float>::quiet_NaN());
      nan.prob.push_back(p);
    }
    for (const auto& j : runtime::ProposeJoints(flat, nan, opt)) CHECK(j.empty());
  }
  // A classification without distributions gives no probabilities rather than garbage.
  CHECK(runtime::ProbabilitiesFromClassification(bg, c).pixel.empty());
}

namespace {
runtime::FrameProposals One(int joint, std::vector<std::pair<Eigen::Vector3f, float>> list) {
  runtime::FrameProposals f;
  for (auto& [p, c] : list) f[size_t(joint)].push_back({p, Eigen::Vector2f::Zero(), c});
  return f;
}
runtime::PersonJoints Person(const Eigen::Vector3f& head, bool visible = true) {
  runtime::PersonJoints p;
  p.position.fill(Eigen::Vector3f(0, 0, 10));
  p.position[kHead] = head;
  p.visible[kHead] = visible;
  return p;
}
}  // namespace

TEST_CASE("AP: a duplicate near proposal is a false positive", "[ap]") {
  runtime::JointApEvaluator ev;
  const Eigen::Vector3f gt(0, 0, 2);
  ev.AddFrame(One(kHead, {{gt + Eigen::Vector3f(0.02f, 0, 0), 0.9f}, {gt + Eigen::Vector3f(0, 0.03f, 0), 0.5f}}), {Person(gt)});
  const auto curve = ev.Curve(kHead);
  REQUIRE(curve.size() == 2);
  CHECK(curve[0].precision == 1.0);
  CHECK(curve[0].recall == 1.0);
  CHECK(curve[1].precision == 0.5);  // the second, less confident one counts against precision
  CHECK(ev.AveragePrecision(kHead) == Approx(1.0));
  // Now the duplicate is more confident than a true positive of another frame.
  ev.AddFrame(One(kHead, {{gt, 0.3f}}), {Person(gt)});
  // Ranked: TP(0.9) FP(0.5) TP(0.3): recall 0.5 at precision 1, recall 1 at precision 2/3.
  CHECK(ev.AveragePrecision(kHead) == Approx(0.5 * 1.0 + 0.5 * 2.0 / 3.0));
}

TEST_CASE("AP: far proposals are false positives; invisible joints add no false negative", "[ap]") {
  runtime::JointApEvaluator ev;
  const Eigen::Vector3f gt(0, 0, 2);
  ev.AddFrame(One(kHead, {{gt + Eigen::Vector3f(0.2f, 0, 0), 0.9f}}), {Person(gt)});  // 20 cm off: FP
  ev.AddFrame(One(kHead, {{gt, 0.5f}}), {Person(gt)});
  CHECK(ev.positives(kHead) == 2);
  CHECK(ev.AveragePrecision(kHead) == Approx(0.5 * 0.5));  // recall 0.5 at precision 0.5
  runtime::JointApEvaluator inv;
  inv.AddFrame(One(kHead, {}), {Person(gt, /*visible=*/false)});  // hidden, not proposed: no FN
  inv.AddFrame(One(kHead, {{gt, 0.7f}}), {Person(gt)});
  CHECK(inv.positives(kHead) == 1);
  CHECK(inv.AveragePrecision(kHead) == Approx(1.0));
  // A proposal at a hidden joint counts neither way.
  inv.AddFrame(One(kHead, {{gt, 0.95f}}), {Person(gt, false)});
  CHECK(inv.AveragePrecision(kHead) == Approx(1.0));
  // Joints never visible are left out of the mean.
  CHECK(inv.MeanAveragePrecision() == Approx(1.0));
}

TEST_CASE("AP: each person's joints are matched separately", "[ap]") {
  runtime::JointApEvaluator ev;
  const Eigen::Vector3f a(-0.5f, 0, 3), b(0.5f, 0, 3);
  ev.AddFrame(One(kHead, {{a, 0.8f}, {b, 0.6f}, {b + Eigen::Vector3f(0.01f, 0, 0), 0.4f}}), {Person(a), Person(b)});
  const auto curve = ev.Curve(kHead);
  REQUIRE(curve.size() == 3);
  CHECK(curve[1].recall == 1.0);
  CHECK(curve[2].precision == Approx(2.0 / 3.0));
  CHECK(ev.AveragePrecision(kHead) == Approx(1.0));
}
