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

namespace {
/// Naive mean shift (eq. 7): every point, std::exp, no cut-off, no voxels, no shortcuts; every
/// seed iterates to convergence and arrivals within merge_distance of a mode's first arrival
/// join it.
std::vector<runtime::Mode> NaiveModes(const std::vector<Eigen::Vector3f>& pts, const std::vector<float>& w,
                                      const std::vector<float>& seed, float b, float merge_distance) {
  std::vector<runtime::Mode> modes;
  std::vector<Eigen::Vector3f> sum;
  for (size_t s = 0; s < pts.size(); ++s) {
    if (!(seed[s] > 0)) continue;
    Eigen::Vector3d x = pts[s].cast<double>();
    for (int it = 0; it < 500; ++it) {
      Eigen::Vector3d num = Eigen::Vector3d::Zero();
      double den = 0;
      for (size_t i = 0; i < pts.size(); ++i) {
        const double k = double(w[i]) * std::exp(-(pts[i].cast<double>() - x).squaredNorm() / double(b * b));
        num += k * pts[i].cast<double>();
        den += k;
      }
      const Eigen::Vector3d next = num / den;
      const double step = (next - x).norm();
      x = next;
      if (step < 1e-5 * b) break;
    }
    size_t m = 0;
    while (m < modes.size() && (modes[m].position - x.cast<float>()).norm() > merge_distance) ++m;
    if (m == modes.size()) {
      modes.push_back({x.cast<float>(), 0.0f});
      sum.push_back(Eigen::Vector3f::Zero());
    }
    modes[m].confidence += seed[s];
    sum[m] += seed[s] * x.cast<float>();
  }
  // Positions: the first arrival (the naive one converges tightly, so all arrivals agree).
  std::stable_sort(modes.begin(), modes.end(), [](const runtime::Mode& a, const runtime::Mode& c) {
    return a.confidence > c.confidence;
  });
  return modes;
}
}  // namespace

TEST_CASE("mean shift (grid, cut-off, vector exp, basin shortcut) agrees with a naive one", "[proposals]") {
  core::RngStream rng(core::CounterRng(11));
  std::vector<Eigen::Vector3f> pts;
  std::vector<float> w, seed;
  // Three blobs of different weight and spread, one elongated, plus sparse noise.
  const Eigen::Vector3f c[3] = {{0, 0, 2}, {0.25f, 0.05f, 2.1f}, {-0.2f, 0.3f, 1.9f}};
  for (int i = 0; i < 700; ++i) {
    const int blob = i % 3;
    const Eigen::Vector3f spread(blob == 2 ? 0.06f : 0.025f, 0.025f, 0.02f);
    pts.push_back(c[blob] + spread.cwiseProduct(Eigen::Vector3f(float(rng.Normal()), float(rng.Normal()),
                                                                float(rng.Normal()))));
    w.push_back(blob == 0 ? 1.0f : blob == 1 ? 2.5f : 0.7f);
    seed.push_back(i % 5 == 0 ? 0.0f : w.back());
  }
  const float b = 0.05f, merge = 0.025f;
  const auto want = NaiveModes(pts, w, seed, b, merge);
  const auto got = runtime::MeanShiftModes(pts, w, seed, b, 30, merge);
  REQUIRE(want.size() >= 3);
  REQUIRE(got.size() == want.size());
  for (size_t m = 0; m < want.size(); ++m) {
    INFO("mode " << m << ": naive " << want[m].position.transpose() << " (" << want[m].confidence << "), got "
                 << got[m].position.transpose() << " (" << got[m].confidence << ")");
    CHECK((got[m].position - want[m].position).norm() < 0.001f);
    CHECK(got[m].confidence == Approx(want[m].confidence).epsilon(1e-4));
  }
}

TEST_CASE("the fast proposal defaults agree with exact mean shift on a soft probability field", "[proposals]") {
  // The figure at 2.5 m (head on the optical axis, as above) with soft probabilities: the
  // labelled joint gets 0.8, every other foreground pixel a little of each joint (0.01: below
  // the default floor), and the torso 0.1 of the neck (density, no seeds).
  const auto depth = testing::MakePersonDepth(2.5, 640, 480, 0.0, 0.62);
  const auto labels = LabelFigure(depth, 0.0, 0.62);
  auto probs = runtime::ProbabilitiesFromLabels(depth, labels);
  const int kNeck = int(core::Joint::kNeck);
  for (size_t k = 0; k < probs.pixel.size(); ++k) {
    const bool torso = labels.pixels[probs.pixel[k]] == uint8_t(core::Part::kLUTorso);
    for (int j = 0; j < core::kNumJoints; ++j) {
      float& p = probs.prob[k][size_t(j)];
      p = p > 0 ? 0.8f : (torso && j == kNeck ? 0.1f : 0.01f);
    }
  }
  runtime::ProposalOptions exact, fast;
  exact.voxel_fraction = 0;
  exact.seed_cell_fraction = 0;
  exact.min_probability = 0;
  exact.max_iterations = 100;
  REQUIRE(fast.seed_cell_fraction > 0);  // the defaults are the fast ones
  REQUIRE(fast.min_probability > 0);
  const auto want = runtime::ProposeJoints(depth, probs, exact);
  const auto got = runtime::ProposeJoints(depth, probs, fast);
  for (int j : {kHead, kLHand, int(core::Joint::kRHand)}) {
    INFO("joint " << core::JointName(j));
    REQUIRE_FALSE(want[size_t(j)].empty());
    REQUIRE_FALSE(got[size_t(j)].empty());
    INFO("exact " << want[size_t(j)][0].position.transpose() << " fast " << got[size_t(j)][0].position.transpose());
    CHECK((got[size_t(j)][0].position - want[size_t(j)][0].position).norm() < 0.01f);
    // The top proposal carries (nearly) all the seed weight in both.
    CHECK(got[size_t(j)][0].confidence == Approx(want[size_t(j)][0].confidence).epsilon(0.05));
  }
}

TEST_CASE("probabilities from the compact foreground output equal those from the dense one", "[proposals]") {
  testing::RandomForestSpec spec;
  spec.seed = 41;
  spec.nodes_per_tree = 3000;
  spec.max_depth = 12;
  const core::Forest forest = testing::MakeRandomForest(spec);
  const runtime::Classifier classifier(forest);
  const auto depth = testing::MakePersonDepth(2.5, 160, 120);
  runtime::Classification dense, compact;
  runtime::ClassifyOptions dense_opt, compact_opt;
  dense_opt.want_distributions = true;
  compact_opt.want_foreground_distributions = true;
  classifier.Classify(depth, dense_opt, &dense);
  classifier.Classify(depth, compact_opt, &compact);
  REQUIRE(compact.sums.empty());
  const auto want = runtime::ProbabilitiesFromClassification(depth, dense);
  REQUIRE(want.pixel.size() == size_t(core::CountForeground(depth)));
  for (int threads : {1, 2}) {
    const auto got = runtime::ProbabilitiesFromClassification(depth, compact, threads);
    CHECK(got.width == want.width);
    CHECK(got.height == want.height);
    CHECK(got.pixel == want.pixel);
    CHECK(got.prob == want.prob);
  }
  // And so the proposals are the same.
  const auto a = runtime::ProposeJoints(depth, want, runtime::ProposalOptions{});
  const auto b = runtime::ProposeJoints(depth, runtime::ProbabilitiesFromClassification(depth, compact), runtime::ProposalOptions{});
  // The fused path (parts pooled inside the proposals' first pass), from either output.
  const auto fused = runtime::ProposeJointsFromClassification(depth, compact, runtime::ProposalOptions{});
  const auto fused_dense = runtime::ProposeJointsFromClassification(depth, dense, runtime::ProposalOptions{});
  size_t total = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    REQUIRE(a[size_t(j)].size() == b[size_t(j)].size());
    REQUIRE(a[size_t(j)].size() == fused[size_t(j)].size());
    REQUIRE(a[size_t(j)].size() == fused_dense[size_t(j)].size());
    total += a[size_t(j)].size();
    for (size_t m = 0; m < a[size_t(j)].size(); ++m) {
      CHECK(a[size_t(j)][m].position == b[size_t(j)][m].position);
      CHECK(a[size_t(j)][m].position == fused[size_t(j)][m].position);
      CHECK(a[size_t(j)][m].confidence == fused[size_t(j)][m].confidence);
      CHECK(a[size_t(j)][m].position == fused_dense[size_t(j)][m].position);
    }
  }
  CHECK(total > 0);
  // A classification without distributions, or of another size, gives no proposals.
  runtime::Classification none;
  classifier.Classify(depth, runtime::ClassifyOptions{}, &none);
  for (const auto& j : runtime::ProposeJointsFromClassification(depth, none, runtime::ProposalOptions{}))
    CHECK(j.empty());
  for (const auto& j : runtime::ProposeJointsFromClassification(testing::MakePersonDepth(2.5, 80, 60), compact,
                                                                runtime::ProposalOptions{}))
    CHECK(j.empty());
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

TEST_CASE("proposals from a subsampled grid (pixel_stride 2) keep positions and confidences", "[proposals]") {
  const auto depth = testing::MakePersonDepth(2.5, 640, 480, 0.0, 0.62);
  const auto labels = LabelFigure(depth, 0.0, 0.62);
  const auto all = runtime::ProbabilitiesFromLabels(depth, labels);
  // Every second pixel in x and y, each standing for 2 x 2 pixels.
  runtime::JointProbabilities grid;
  grid.width = all.width;
  grid.height = all.height;
  for (size_t k = 0; k < all.pixel.size(); ++k) {
    const uint32_t x = all.pixel[k] % uint32_t(depth.width), y = all.pixel[k] / uint32_t(depth.width);
    if (x % 2 || y % 2) continue;
    grid.pixel.push_back(all.pixel[k]);
    grid.prob.push_back(all.prob[k]);
  }
  REQUIRE(grid.pixel.size() * 5 < all.pixel.size() * 2);
  for (auto method : {runtime::ProposalMethod::kMeanShift, runtime::ProposalMethod::kFastClustering}) {
    INFO("method " << int(method));
    runtime::ProposalOptions opt;
    opt.method = method;
    const auto want = runtime::ProposeJoints(depth, all, opt);
    grid.pixel_stride = 1;
    const auto unweighted = runtime::ProposeJoints(depth, grid, opt);
    grid.pixel_stride = 2;
    const auto got = runtime::ProposeJoints(depth, grid, opt);
    for (int j : {kHead, kLHand}) {
      REQUIRE(want[size_t(j)].size() == 1);
      REQUIRE(got[size_t(j)].size() == 1);
      REQUIRE(unweighted[size_t(j)].size() == 1);
      const auto& a = want[size_t(j)][0];
      const auto& b = got[size_t(j)][0];
      CHECK((a.position - b.position).norm() < 0.01f);
      // The confidence (summed P * d^2 of the seed pixels) keeps its scale: each grid pixel
      // weighs 4; unweighted it would be about a quarter.
      CHECK(std::abs(b.confidence / a.confidence - 1.0f) < 0.05f);
      CHECK(std::abs(unweighted[size_t(j)][0].confidence / a.confidence - 0.25f) < 0.02f);
      CHECK(unweighted[size_t(j)][0].position == b.position);
    }
  }
  // From a classification on the grid: the stride travels with it.
  testing::RandomForestSpec spec;
  spec.seed = 43;
  spec.nodes_per_tree = 2000;
  spec.max_depth = 11;
  const core::Forest forest = testing::MakeRandomForest(spec);
  runtime::ClassifyOptions copt;
  copt.want_foreground_distributions = true;
  copt.pixel_stride = 2;
  runtime::Classification c;
  runtime::Classifier(forest).Classify(depth, copt, &c);
  const auto probs = runtime::ProbabilitiesFromClassification(depth, c);
  CHECK(probs.pixel_stride == 2);
  CHECK(probs.pixel == c.foreground);
  const auto fused = runtime::ProposeJointsFromClassification(depth, c, runtime::ProposalOptions{});
  const auto split = runtime::ProposeJoints(depth, probs, runtime::ProposalOptions{});
  size_t total = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    REQUIRE(fused[size_t(j)].size() == split[size_t(j)].size());
    total += fused[size_t(j)].size();
    for (size_t m = 0; m < fused[size_t(j)].size(); ++m) {
      CHECK(fused[size_t(j)][m].position == split[size_t(j)][m].position);
      CHECK(fused[size_t(j)][m].confidence == split[size_t(j)][m].confidence);
    }
  }
  CHECK(total > 0);
  // The dense output on the grid lists the same pixels.
  copt.want_foreground_distributions = false;
  copt.want_distributions = true;
  runtime::Classification d;
  runtime::Classifier(forest).Classify(depth, copt, &d);
  const auto dense_probs = runtime::ProbabilitiesFromClassification(depth, d);
  CHECK(dense_probs.pixel == probs.pixel);
  CHECK(dense_probs.prob == probs.prob);
  CHECK(dense_probs.pixel_stride == 2);
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
