// Skeletons: the confidence calibration and its forest section (format 1.4, JCAL),
// per-person joints from masks with the tracked / not-tracked rules, person ids over a
// sequence, One Euro smoothing and the JSON Lines record.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include "runtime/core/forest_format.h"
#include "runtime/proposal_tuning.h"
#include "runtime/skeleton.h"
#include "runtime/visualize.h"
#include "tests/support/skeletons.h"
#include "tests/support/synthetic.h"

using namespace poseforest;

namespace {

constexpr int kHead = int(core::Joint::kHead);
constexpr int kLKnee = int(core::Joint::kLKnee);
constexpr int kLHand = int(core::Joint::kLHand);

core::ConfidenceCalibration RampCalibration() {
  core::ConfidenceCalibration cal;
  cal.support_edges_m2 = {1e-4f, 1e-3f, 1e-2f};
  for (auto& row : cal.precision) row = {0.1f, 0.5f, 0.9f};
  cal.samples = 42;
  return cal;
}

// A frame with people as rectangles of constant depth; returns depth and masks.
struct Scene {
  core::DepthImage depth{640, 480, 0};
  core::LabelImage masks{640, 480, 0};
  void Person(int label, int x0, int y0, int x1, int y1, uint16_t mm) {
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) depth.at(x, y) = mm, masks.at(x, y) = uint8_t(label);
  }
};

runtime::JointProposal At(const core::CameraIntrinsics& cam, int x, int y, float z_m, float raw) {
  runtime::JointProposal p;
  p.position = cam.Unproject(x, y, z_m).cast<float>();
  p.pixel = Eigen::Vector2f(float(x), float(y));
  p.confidence = raw;
  return p;
}

// An offset-vote candidate at pixel (x, y) and depth z (share 0.5).
runtime::VoteCandidate VoteAt(const core::CameraIntrinsics& cam, int x, int y, float z_m, float confidence) {
  runtime::VoteCandidate v;
  v.position = cam.Unproject(x, y, z_m).cast<float>();
  v.share = 0.5f;
  v.confidence = confidence;
  return v;
}

// Fit candidates: one more for joint j.
void AddCandidate(runtime::FitCandidates& c, core::Joint j, const Eigen::Vector3f& p, float conf) {
  c[size_t(int(j))].push_back({p, conf});
}

// The fit tests' start: the neck and left shoulder of a person 1.5 m away.
runtime::FitCandidates NeckAndLeftShoulder() {
  runtime::FitCandidates c;
  AddCandidate(c, core::Joint::kNeck, {0, 0, 1.5f}, 0.9f);
  AddCandidate(c, core::Joint::kLShoulder, {0.19f, 0.05f, 1.5f}, 0.9f);
  return c;
}

// The tracking-decision tests' person: an upper body at 1.5 m, cut by the bottom edge, with
// confident proposals for the neck, head, shoulders and left elbow at its surface.
struct UpperBody {
  core::CameraIntrinsics cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  runtime::FrameProposals proposals{};
  UpperBody() {
    scene.Person(1, 200, 100, 440, 479, 1500);
    Put(core::Joint::kNeck, 320, 180);
    Put(core::Joint::kHead, 320, 120);
    Put(core::Joint::kLShoulder, 380, 200);
    Put(core::Joint::kRShoulder, 260, 200);
    Put(core::Joint::kLElbow, 420, 300);
  }
  void Put(core::Joint j, int x, int y, float z = 1.54f) {
    proposals[size_t(j)] = {At(cam, x, y, z, 0.01f * float(cam.fx * cam.fy))};
  }
};

// The vote tests' options: the given fit, no bone or parent rule in the way.
runtime::SkeletonOptions VoteTestOptions(runtime::SkeletonFit fit) {
  runtime::SkeletonOptions opt;
  opt.fit = fit;
  opt.require_tracked_parent = false;
  opt.check_bone_lengths = false;
  return opt;
}

}  // namespace

TEST_CASE("calibrated confidence interpolates the table in log support and stays in 0..1", "[skeleton]") {
  const auto cal = RampCalibration();
  REQUIRE(core::ValidateCalibration(cal, "t").ok());
  CHECK(cal.Confidence(kHead, 1e-6f) == Approx(0.1f));  // below the first centre
  CHECK(cal.Confidence(kHead, 1.0f) == Approx(0.9f));   // beyond the last
  // The geometric centre of [1e-4, 1e-3) is ~3.16e-4: exactly the bin's value there.
  CHECK(cal.Confidence(kHead, 3.1623e-4f) == Approx(0.1f).margin(1e-3));
  CHECK(cal.Confidence(kHead, 1e-3f) == Approx(0.3f).margin(1e-3));  // half way in log
  float last = -1;
  for (double s = 1e-6; s < 10; s *= 1.3) {
    const float c = cal.Confidence(kLHand, float(s));
    CHECK(c >= last);
    CHECK(c >= 0.0f);
    CHECK(c <= 1.0f);
    last = c;
  }
  CHECK(cal.Confidence(kHead, 0.0f) == 0.0f);
  // The fallback is monotone, 0 at 0, 0.5 near 14 cm^2, below 1.
  CHECK(core::FallbackConfidence(0) == 0.0f);
  CHECK(core::FallbackConfidence(0.002f * std::log(2.0f)) == Approx(0.5f));
  CHECK(core::FallbackConfidence(1.0f) <= 1.0f);
  CHECK(core::FallbackConfidence(1e-4f) < core::FallbackConfidence(1e-3f));
  // Bad tables are refused naming the problem.
  auto bad = cal;
  bad.precision[3][1] = 1.5f;
  CHECK(core::ValidateCalibration(bad, "x").message().find("R_shoulder") != std::string::npos);
  bad = cal;
  bad.support_edges_m2 = {1e-3f, 1e-4f, 1e-2f};
  CHECK_FALSE(core::ValidateCalibration(bad, "x").ok());
}

TEST_CASE("the calibration table round trips in the forest (format 1.4, JCAL); older files have none",
          "[skeleton][format]") {
  core::Forest forest = testing::MakeRandomForest({.num_trees = 2, .max_depth = 6, .nodes_per_tree = 200});
  const auto plain = core::SerializeForest(forest);
  auto loaded = core::ParseForest(plain, "plain");
  REQUIRE(loaded.ok());
  CHECK_FALSE(loaded->confidence_calibration);  // the fallback applies
  forest.confidence_calibration = RampCalibration();
  forest.confidence_calibration->method = core::ConfidenceCalibration::Method::kFastClustering;
  const auto bytes = core::SerializeForest(forest);
  CHECK(bytes[10] >= 4);  // minor version: JCAL since 1.4
  CHECK(bytes.size() == plain.size() + 16 + 16 + 3 * 4 + 16 * 3 * 4 + 4 /* padding to 8 */);
  auto again = core::ParseForest(bytes, "mem");
  REQUIRE(again.ok());
  REQUIRE(again->confidence_calibration);
  CHECK(*again->confidence_calibration == *forest.confidence_calibration);
  CHECK(core::SerializeForest(*again) == bytes);
  // Out-of-range values are refused at load, naming the section.
  forest.confidence_calibration->precision[0][0] = -0.5f;
  auto bad = core::ParseForest(core::SerializeForest(forest), "bad.pff");
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.status().message().find("JCAL") != std::string::npos);
}

TEST_CASE("the isotonic fit is non-decreasing, weighted, and fills empty bins", "[skeleton]") {
  const auto f = runtime::IsotonicFit({0.2, 0.0, 0.6, 0.4, 0.9, 0.0}, {1, 0, 1, 3, 2, 0});
  REQUIRE(f.size() == 6);
  CHECK(f[0] == Approx(0.2));
  CHECK(f[1] == Approx(0.2));                  // empty: the left neighbour's
  CHECK(f[2] == Approx((0.6 + 3 * 0.4) / 4));  // pooled with its heavier right neighbour
  CHECK(f[3] == Approx(f[2]));
  CHECK(f[4] == Approx(0.9));
  CHECK(f[5] == Approx(0.9));
}

TEST_CASE("CalibrateConfidence: big supports on the joint are precise, small ones elsewhere are not",
          "[skeleton]") {
  // Each frame: a large head-probability patch at the true head, a small one 40 cm away.
  const auto cam = core::CameraIntrinsics::KinectV1();
  std::vector<runtime::ValidationFrame> frames;
  for (int k = 0; k < 6; ++k) {
    runtime::ValidationFrame f;
    f.depth = core::DepthImage(640, 480, 0);
    f.probs.width = 640, f.probs.height = 480;
    const int hx = 200 + 20 * k, hy = 200;
    for (const auto& [cx, cy, half] : {std::tuple{hx, hy, 12}, std::tuple{hx + 115, hy, 2}})
      for (int y = cy - half; y <= cy + half; ++y)
        for (int x = cx - half; x <= cx + half; ++x) {
          f.depth.at(x, y) = 2000;
          f.probs.pixel.push_back(uint32_t(y * 640 + x));
          std::array<float, core::kNumJoints> pr{};
          pr[kHead] = 1.0f;
          f.probs.prob.push_back(pr);
        }
    runtime::PersonJoints person;
    person.position.fill(Eigen::Vector3f(0, 0, 9));
    person.position[kHead] = cam.Unproject(hx, hy, 2.0 + 0.039).cast<float>();
    person.visible[kHead] = true;
    f.people = {person};
    frames.push_back(std::move(f));
  }
  runtime::ProposalOptions options;
  options.num_threads = 1;
  const auto cal = runtime::CalibrateConfidence(frames, options);
  REQUIRE(core::ValidateCalibration(cal, "measured").ok());
  CHECK(cal.samples == 12);
  // Big patch: 625 px * 4 m^2 / (fx fy) ~ 7.5e-3 m^2, always right; small: 25 px ~ 3e-4, always wrong.
  CHECK(cal.Confidence(kHead, 7.5e-3f) == Approx(1.0f));
  CHECK(cal.Confidence(kHead, 3e-4f) == Approx(0.0f));
  // A joint never proposed keeps the fallback's shape.
  CHECK(cal.Confidence(kLKnee, 1e-3f) == Approx(core::FallbackConfidence(1e-3f)).epsilon(0.5));
}

TEST_CASE("each person's pixel count and centroid equal a sum over every pixel", "[skeleton]") {
  // BuildSkeletons sums the mask run by run and skips the background eight labels at a time;
  // this compares it with the plain sum over every pixel, on masks whose runs start and end at
  // every offset, with holes in the depth and labels above the number of people (ignored).
  const auto cam = core::CameraIntrinsics::KinectV1();
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const int w = 37 + trial * 13, h = 29 + trial * 3, num_people = 1 + trial % 3;
    core::LabelImage masks(w, h, 0);
    core::DepthImage depth(w, h, 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w;) {
        const int len = 1 + int(rng() % 23);
        const int label = rng() % 3 == 0 ? int(rng() % uint32_t(num_people + 2)) : 0;
        for (int i = x; i < std::min(w, x + len); ++i) {
          masks.at(i, y) = uint8_t(label);
          depth.at(i, y) = rng() % 7 == 0 ? 0 : uint16_t(800 + rng() % 3000);
        }
        x += len;
      }
    auto skeletons =
        runtime::BuildSkeletons(runtime::FrameProposals{}, masks, num_people, depth, cam, nullptr, {});
    for (int label = 1; label <= num_people; ++label) {
      double d = 0, xd = 0, yd = 0;
      int count = 0;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (masks.at(x, y) == label && depth.at(x, y) != 0) {
            const double z = depth.at(x, y);
            d += z, xd += x * z, yd += y * z, ++count;
          }
      const auto it = std::find_if(skeletons.begin(), skeletons.end(),
                                   [&](const runtime::Skeleton& s) { return s.mask_label == label; });
      if (count == 0) {
        CHECK(it == skeletons.end());
        continue;
      }
      REQUIRE(it != skeletons.end());
      CHECK(it->pixels == count);
      const double z = d * 1e-3 / count;
      CHECK(it->centroid_m.z() == Approx(z).epsilon(1e-6));
      CHECK(it->centroid_m.x() == Approx((xd * 1e-3 / count - cam.cx * z) / cam.fx).epsilon(1e-5));
      CHECK(it->centroid_m.y() == Approx((yd * 1e-3 / count - cam.cy * z) / cam.fy).epsilon(1e-5));
    }
    CHECK(skeletons.size() <= size_t(num_people));
  }
}

TEST_CASE("skeletons: per person the best proposal on its mask; no invented joints", "[skeleton]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 100, 100, 250, 479, 2000);  // person 1 at 2 m
  scene.Person(2, 400, 150, 520, 300, 3000);  // person 2 at 3 m, upper body only
  runtime::FrameProposals proposals{};
  const float big = 0.01f * float(cam.fx * cam.fy);  // support 0.01 m^2
  // Heads: the most confident lies on person 2, the next on person 1.
  proposals[kHead] = {At(cam, 450, 170, 3.04f, big * 2), At(cam, 170, 120, 2.04f, big)};
  // A knee below person 2's mask (out of view: no legs there) and one on person 1.
  proposals[kLKnee] = {At(cam, 450, 420, 3.04f, big * 3), At(cam, 150, 380, 2.04f, big)};
  // Person 1's hand: tiny support; person 2's: its depth is 1 m off the mask's.
  proposals[kLHand] = {At(cam, 120, 250, 2.04f, 1e-6f * float(cam.fx * cam.fy)),
                       At(cam, 500, 200, 4.0f, big)};
  const auto cal = RampCalibration();
  runtime::SkeletonOptions opt;
  opt.require_tracked_parent = false;  // the knee has no tracked shoulder here; see the next test
  auto skeletons = runtime::BuildSkeletons(proposals, scene.masks, 2, scene.depth, cam, &cal, opt);
  REQUIRE(skeletons.size() == 2);
  const auto& p1 = skeletons[0];
  const auto& p2 = skeletons[1];
  CHECK(p1.mask_label == 1);
  CHECK(p2.mask_label == 2);
  CHECK(p1.centroid_m.z() == Approx(2.0f));
  CHECK(p2.pixels == 151 * 121);
  CHECK(p1.joints[kHead].tracked);
  CHECK(p1.joints[kHead].pixel.x() == 170);
  CHECK(p1.joints[kHead].support_m2 == Approx(0.01f));
  CHECK(p1.joints[kHead].confidence == Approx(cal.Confidence(kHead, 0.01f)));
  CHECK(p2.joints[kHead].tracked);
  CHECK(p2.joints[kHead].pixel.x() == 450);
  CHECK(p1.joints[kLKnee].tracked);
  // Person 2 has no knee: the strongest knee proposal lies off its mask.
  CHECK_FALSE(p2.joints[kLKnee].found);
  CHECK_FALSE(p2.joints[kLKnee].tracked);
  CHECK(p2.joints[kLKnee].confidence == 0.0f);
  // Found but not tracked: too little support; off the person's depth.
  CHECK(p1.joints[kLHand].found);
  CHECK_FALSE(p1.joints[kLHand].tracked);
  CHECK(p2.joints[kLHand].found);
  CHECK_FALSE(p2.joints[kLHand].tracked);
  // A low calibrated confidence alone also untracks: raise the bar above the head's 0.9.
  opt.min_confidence = 0.95f;
  skeletons = runtime::BuildSkeletons(proposals, scene.masks, 2, scene.depth, cam, &cal, opt);
  CHECK_FALSE(skeletons[0].joints[kHead].tracked);
  // Without a table: the fallback.
  skeletons = runtime::BuildSkeletons(proposals, scene.masks, 2, scene.depth, cam, nullptr, opt);
  CHECK(skeletons[0].joints[kHead].confidence == Approx(core::FallbackConfidence(0.01f)));
  // No people, no skeletons.
  CHECK(runtime::BuildSkeletons(proposals, scene.masks, 0, scene.depth, cam, &cal, {}).empty());
}

TEST_CASE("skeletons: a proposal whose pixel is not finite or far outside the image is off every mask",
          "[skeleton][hostile]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 0, 100, 150, 479, 2000);  // touches column 0, where a wrapped pixel would land
  const float big = 0.01f * float(cam.fx * cam.fy);
  for (const float x : {std::nanf(""), std::numeric_limits<float>::infinity(), -3e9f, 2147483648.0f}) {
    INFO(x);
    runtime::FrameProposals proposals{};
    runtime::JointProposal head = At(cam, 60, 120, 2.04f, big);
    head.pixel.x() = x;  // rounding it to int would overflow (or give column 0)
    proposals[kHead] = {head};
    runtime::SkeletonOptions opt;
    const auto cal = RampCalibration();
    const auto skeletons = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt);
    REQUIRE(skeletons.size() == 1);
    CHECK_FALSE(skeletons[0].joints[kHead].found);
  }
}

TEST_CASE("skeletons: no knees at the border that cuts an upper body, bone lengths, unbroken chains",
          "[skeleton]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 200, 100, 440, 479, 1500);  // an upper body at 1.5 m, cut by the bottom edge
  runtime::FrameProposals proposals{};
  const float big = 0.01f * float(cam.fx * cam.fy);
  using J = core::Joint;
  auto put = [&](J j, int x, int y) { proposals[size_t(j)] = {At(cam, x, y, 1.54f, big)}; };
  put(J::kNeck, 320, 180);
  put(J::kHead, 320, 120);       // 0.16 m above the neck
  put(J::kLShoulder, 380, 200);  // 0.2 m from the neck
  put(J::kRShoulder, 260, 200);
  put(J::kLElbow, 420, 300);  // 0.28 m from the shoulder
  put(J::kRElbow, 262, 205);  // 1.3 cm from its shoulder: no such arm
  put(J::kRWrist, 262, 320);  // would be fine, but its elbow is not tracked
  put(J::kLKnee, 380, 460);   // 19 px from the bottom edge (0.15 m = 56 px at 1.54 m)
  put(J::kRKnee, 262, 400);   // far from the edge but 0.53 m below its shoulder: allowed
  put(J::kLAnkle, 380, 470);  // below a knee that is not tracked
  const auto cal = RampCalibration();
  runtime::SkeletonOptions opt;
  auto s = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt);
  REQUIRE(s.size() == 1);
  const auto& j = s[0].joints;
  for (J ok : {J::kNeck, J::kHead, J::kLShoulder, J::kRShoulder, J::kLElbow, J::kRKnee}) {
    INFO(core::JointName(int(ok)));
    CHECK(j[size_t(ok)].tracked);
  }
  for (J no : {J::kRElbow, J::kRWrist, J::kLKnee, J::kLAnkle}) {
    INFO(core::JointName(int(no)));
    CHECK(j[size_t(no)].found);
    CHECK_FALSE(j[size_t(no)].tracked);
  }
  // Each rule can be turned off.
  opt.edge_margin_m = 0;
  opt.check_bone_lengths = false;
  opt.require_tracked_parent = false;
  s = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt);
  for (J all : {J::kRElbow, J::kRWrist, J::kLKnee, J::kLAnkle}) CHECK(s[0].joints[size_t(all)].tracked);
  // The same knee on a whole body (the mask ends above the edge) is tracked.
  Scene whole;
  whole.Person(1, 200, 100, 440, 470, 1500);
  opt = {};
  put(J::kLKnee, 380, 430);
  s = runtime::BuildSkeletons(proposals, whole.masks, 1, whole.depth, cam, &cal, opt);
  CHECK(s[0].joints[size_t(J::kLKnee)].tracked);
}

TEST_CASE("skeletons with a learned tracking decision: the cues, P as confidence, tracked at P >= 0.5",
          "[skeleton][tracking]") {
  UpperBody body;
  const auto& cam = body.cam;
  const auto& scene = body.scene;
  const auto& proposals = body.proposals;
  using J = core::Joint;
  body.Put(J::kRElbow, 262, 205);        // 1.3 cm from its shoulder: an impossible bone
  body.Put(J::kLKnee, 380, 460);         // at the bottom edge that cuts the person
  body.Put(J::kRKnee, 262, 400, 2.0f);   // 0.5 m behind the surface
  const auto cal = RampCalibration();
  runtime::SkeletonOptions opt;
  // Without a model: the rules, and the cues filled all the same.
  auto rules = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt);
  REQUIRE(rules.size() == 1);
  const auto& r = rules[0].joints;
  CHECK_FALSE(r[size_t(J::kLKnee)].tracked);
  CHECK_FALSE(r[size_t(J::kRElbow)].tracked);
  const float c = cal.Confidence(int(J::kNeck), 0.01f);
  for (const auto& joint : r) {
    if (!joint.found) continue;
    CHECK(joint.base_confidence == Approx(c));
    CHECK(joint.cues[core::kFeatHasProposal] == 1);
    CHECK(joint.cues[core::kFeatHasVote] == 0);
    CHECK(joint.cues[core::kFeatProposalVoteGap] == 0.5f);
    CHECK(joint.cues[core::kFeatVoted] == 0);
  }
  CHECK(r[size_t(J::kLKnee)].cues[core::kFeatNearCutEdge] == 1);
  CHECK(r[size_t(J::kLElbow)].cues[core::kFeatNearCutEdge] == 0);
  CHECK(r[size_t(J::kRElbow)].cues[core::kFeatBoneBad] == 1);
  CHECK(r[size_t(J::kLElbow)].cues[core::kFeatBoneOk] == 1);
  CHECK(r[size_t(J::kLElbow)].cues[core::kFeatParentLogit] == Approx(core::ClampedLogit(c)));
  CHECK(r[size_t(J::kNeck)].cues[core::kFeatParentLogit] == 0);  // the root
  // The neck's children at possible lengths: head and both shoulders.
  CHECK(r[size_t(J::kNeck)].cues[core::kFeatChildrenOk] == 3);
  CHECK(r[size_t(J::kRKnee)].cues[core::kFeatDepthGap] == Approx(0.5f));
  CHECK(r[size_t(J::kHead)].cues[core::kFeatDepthGap] == Approx(0.04f).margin(0.005f));

  // A model that trusts everything but cut edges a little: the knee at the cut edge is tracked
  // (the rules drop it), the knee behind the surface is not (found, not at the surface).
  core::TrackingModel model;
  model.intercept.fill(2.0f);
  model.shared[core::kFeatNearCutEdge] = -1.0f;
  auto learned = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  const auto& m = learned[0].joints;
  for (J j : {J::kNeck, J::kHead, J::kLShoulder, J::kRShoulder, J::kLElbow, J::kRElbow, J::kLKnee}) {
    INFO(core::JointName(int(j)));
    CHECK(m[size_t(j)].tracked);
    CHECK(m[size_t(j)].confidence == Approx(model.Probability(int(j), c, m[size_t(j)].cues)));
    CHECK(m[size_t(j)].base_confidence == Approx(c));
  }
  CHECK(m[size_t(J::kLKnee)].confidence == Approx(1 / (1 + std::exp(-1.0))));
  CHECK(m[size_t(J::kRKnee)].found);
  CHECK_FALSE(m[size_t(J::kRKnee)].tracked);
  CHECK_FALSE(m[size_t(J::kLWrist)].found);
  // Cut edges weigh more: P = sigmoid(2 - 3) < 0.5, the edge knee is not tracked; the threshold
  // moves the decision.
  model.shared[core::kFeatNearCutEdge] = -3.0f;
  learned = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  CHECK_FALSE(learned[0].joints[size_t(J::kLKnee)].tracked);
  CHECK(learned[0].joints[size_t(J::kLElbow)].tracked);
  opt.track_probability = 0.2f;
  learned = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  CHECK(learned[0].joints[size_t(J::kLKnee)].tracked);
  // A model that distrusts everything tracks nothing; use_tracking_model = false restores the rules.
  model.intercept.fill(-5.0f);
  learned = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  for (const auto& joint : learned[0].joints) CHECK_FALSE(joint.tracked);
  opt.use_tracking_model = false;
  learned = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  for (int j = 0; j < core::kNumJoints; ++j) {
    CHECK(learned[0].joints[size_t(j)].tracked == r[size_t(j)].tracked);
    CHECK(learned[0].joints[size_t(j)].confidence == r[size_t(j)].confidence);
  }
}

TEST_CASE("skeletons with a seen decision (format 1.8): tracked when likely seen, P(within) the confidence",
          "[skeleton][tracking]") {
  UpperBody body;
  const auto& cam = body.cam;
  const auto& scene = body.scene;
  const auto& proposals = body.proposals;
  using J = core::Joint;
  body.Put(J::kRKnee, 262, 400, 2.0f);  // 0.5 m behind the surface
  const auto cal = RampCalibration();
  const float c = cal.Confidence(int(J::kNeck), 0.01f);
  runtime::SkeletonOptions opt;
  // P(within 0.1 m) high for every joint; P(seen) high but for the left elbow, which the seen
  // model calls hidden, and the right knee, which lies behind the surface.
  core::TrackingModel model;
  model.intercept.fill(2.0f);
  core::TrackingWeights seen;
  seen.intercept.fill(3.0f);
  seen.intercept[size_t(J::kLElbow)] = -3.0f;
  model.seen = seen;
  auto sk = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  REQUIRE(sk.size() == 1);
  const auto& m = sk[0].joints;
  for (J j : {J::kNeck, J::kHead, J::kLShoulder, J::kRShoulder}) {
    INFO(core::JointName(int(j)));
    CHECK(m[size_t(j)].tracked);
    CHECK(runtime::StateOf(m[size_t(j)]) == runtime::JointState::kTracked);
  }
  for (J j : {J::kNeck, J::kHead, J::kLShoulder, J::kRShoulder, J::kLElbow, J::kRKnee}) {
    INFO(core::JointName(int(j)));
    CHECK(m[size_t(j)].found);
    // The confidence a user reads is the position's P(within 0.1 m), not P(seen).
    CHECK(m[size_t(j)].confidence == Approx(model.Probability(int(j), c, m[size_t(j)].cues)));
  }
  // Likely hidden, its candidate confident: placed and inferred, not tracked.
  CHECK_FALSE(m[size_t(J::kLElbow)].tracked);
  CHECK(runtime::StateOf(m[size_t(J::kLElbow)]) == runtime::JointState::kInferred);
  // Seen by the model but behind the surface: never tracked.
  CHECK_FALSE(m[size_t(J::kRKnee)].tracked);
  // use_seen_model = false: tracked by P(within 0.1 m) as before 1.8, the elbow included.
  opt.use_seen_model = false;
  sk = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  CHECK(sk[0].joints[size_t(J::kLElbow)].tracked);
  CHECK(sk[0].joints[size_t(J::kLElbow)].confidence == Approx(m[size_t(J::kLElbow)].confidence));
  // seen_probability applies to P(seen): a seen model unsure of every joint (P = 0.27) tracks
  // all at the surface at the default 0.2 (not seen only when P(hidden) >= 0.8), none at 0.5;
  // track_probability does not move the seen decision.
  opt.use_seen_model = true;
  model.seen->intercept.fill(-1.0f);
  REQUIRE(opt.seen_probability == 0.2f);
  sk = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  CHECK(sk[0].joints[size_t(J::kLElbow)].tracked);
  CHECK(sk[0].joints[size_t(J::kHead)].tracked);
  CHECK_FALSE(sk[0].joints[size_t(J::kRKnee)].tracked);
  opt.seen_probability = 0.5f;
  opt.track_probability = 0.2f;
  sk = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, nullptr, &model);
  for (const auto& joint : sk[0].joints) CHECK_FALSE(joint.tracked);
  CHECK(runtime::StateOf(sk[0].joints[size_t(J::kLElbow)]) == runtime::JointState::kInferred);
}

TEST_CASE("person ids stay with the nearest centroid over a sequence", "[skeleton]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  runtime::SkeletonOptions opt;
  opt.max_missed_frames = 2;
  runtime::SkeletonTracker tracker(opt);
  auto person = [](float x, float z) {
    runtime::Skeleton s;
    s.centroid_m = Eigen::Vector3f(x, 0, z);
    return s;
  };
  auto ids = [&](std::vector<runtime::Skeleton> in, double t) {
    std::vector<std::pair<int, float>> out;
    for (const auto& s : tracker.Update(std::move(in), t, cam)) out.emplace_back(s.id, s.centroid_m.x());
    return out;
  };
  auto a = ids({person(-1, 2), person(1, 2)}, 0.0);
  REQUIRE(a.size() == 2);
  CHECK(a[0] == std::pair<int, float>(1, -1.0f));
  CHECK(a[1] == std::pair<int, float>(2, 1.0f));
  // Listed the other way round (the segmentation orders by size) and moved a little: same ids.
  auto b = ids({person(0.9f, 2), person(-0.8f, 2)}, 0.033);
  CHECK(b[0] == std::pair<int, float>(1, -0.8f));
  CHECK(b[1] == std::pair<int, float>(2, 0.9f));
  // Person 1 leaves for two frames and comes back: still id 1 (max_missed_frames = 2).
  ids({person(0.9f, 2)}, 0.066);
  ids({person(0.9f, 2)}, 0.1);
  auto c = ids({person(-0.8f, 2), person(0.9f, 2)}, 0.133);
  CHECK(c[0].first == 1);
  // Gone for longer: forgotten; someone far away is somebody new.
  for (int k = 0; k < 3; ++k) ids({person(0.9f, 2)}, 0.2 + k * 0.033);
  auto d = ids({person(-0.8f, 2), person(0.9f, 2)}, 0.4);
  CHECK(d[0].first == 2);
  CHECK(d[1].first == 3);
  CHECK(d[1].second == -0.8f);
  auto e = ids({person(0.9f, 2), person(-0.8f, 3.5f)}, 0.433);  // 1.5 m jump: new id
  CHECK(e[1].first == 4);
  CHECK(tracker.people_seen() == 4);
}

TEST_CASE("One Euro smoothing: less jitter at rest, follows a move", "[skeleton]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  auto run = [&](bool smooth, const std::vector<float>& xs) {
    runtime::SkeletonOptions opt;
    opt.smooth = smooth;
    runtime::SkeletonTracker tracker(opt);
    std::vector<float> out;
    for (size_t k = 0; k < xs.size(); ++k) {
      runtime::Skeleton s;
      s.centroid_m = Eigen::Vector3f(0, 0, 2);
      auto& head = s.joints[kHead];
      head.found = head.tracked = true;
      head.position_m = Eigen::Vector3f(xs[k], 0, 2);
      auto r = tracker.Update({s}, double(k) / 30, cam);
      out.push_back(r[0].joints[kHead].position_m.x());
      if (smooth)
        CHECK(r[0].joints[kHead].pixel.x() ==
              Approx(cam.Project(Eigen::Vector3d(out.back(), 0, 2)).x()).margin(1e-3));
    }
    return out;
  };
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0, 0.01f);
  std::vector<float> still(60);
  for (float& x : still) x = noise(rng);
  auto spread = [](const std::vector<float>& v) {
    double s = 0;
    for (size_t k = 10; k < v.size(); ++k) s += double(v[k]) * v[k];
    return std::sqrt(s / double(v.size() - 10));
  };
  const auto raw = run(false, still), smooth = run(true, still);
  CHECK(raw == still);
  CHECK(spread(smooth) < 0.5 * spread(raw));
  // A 0.5 m step: within 5 cm after half a second.
  std::vector<float> step(60, 0.0f);
  for (size_t k = 15; k < step.size(); ++k) step[k] = 0.5f;
  const auto moved = run(true, step);
  CHECK(moved[30] == Approx(0.5f).margin(0.05f));
}

TEST_CASE("the JSON Lines record: one line, people, 16 named joints, null for joints not found",
          "[skeleton]") {
  runtime::Skeleton s;
  s.id = 3;
  s.pixels = 10;
  s.centroid_m = Eigen::Vector3f(0.1f, -0.2f, 2.5f);
  s.joints[kHead].found = s.joints[kHead].tracked = true;
  s.joints[kHead].position_m = Eigen::Vector3f(0.125f, -0.5f, 2.25f);
  s.joints[kHead].pixel = Eigen::Vector2f(330.5f, 100.25f);
  s.joints[kHead].confidence = 0.875f;
  const std::string line = runtime::SkeletonsJsonLine(7, 0.25, "a\"b\\c\n", {s});
  CHECK(line.find('\n') == std::string::npos);
  CHECK(line.rfind("{\"index\":7,\"time_s\":0.25,\"source\":\"a\\\"b\\\\c\\n\",\"people\":[{\"id\":3,", 0) ==
        0);
  CHECK(line.find("{\"name\":\"head\",\"position_m\":[0.125,-0.5,2.25],\"pixel\":[330.5,100.2],"
                  "\"confidence\":0.875,\"tracked\":true,\"state\":\"tracked\"}") != std::string::npos);
  CHECK(line.find("{\"name\":\"R_foot\",\"position_m\":null,\"pixel\":null,\"confidence\":0.0,\"tracked\":"
                  "false,\"state\":\"not_tracked\"}]}]}") != std::string::npos);
  CHECK(runtime::SkeletonsJsonLine(0, 0, "x", {}) ==
        "{\"index\":0,\"time_s\":0.0,\"source\":\"x\",\"people\":[]}");
}

TEST_CASE("the JSON Lines record escapes its source: one valid line whatever the name", "[skeleton]") {
  const std::string line =
      runtime::SkeletonsJsonLine(0, 0, std::string("a\"b\\c\nd\te\x01\x1f\x7f") + "\xc3\xa9" + "\xff", {});
  CHECK(line.find('\n') == std::string::npos);
  // Control characters escaped, UTF-8 kept, a byte that is not UTF-8 replaced by U+FFFD.
  CHECK(line.find("\"source\":\"a\\\"b\\\\c\\nd\\te\\u0001\\u001f\x7f\xc3\xa9\xef\xbf\xbd\"") !=
        std::string::npos);
}

TEST_CASE("joint states: tracked, inferred, not tracked, in the JSON Lines record", "[skeleton]") {
  using runtime::JointState;
  const runtime::Skeleton s = testing::FourStateSkeleton();
  CHECK(runtime::StateOf(s.joints[testing::kTrackedJoint]) == JointState::kTracked);
  CHECK(runtime::StateOf(s.joints[testing::kInferredJoint]) == JointState::kInferred);
  CHECK(runtime::StateOf(s.joints[testing::kFoundOnlyJoint]) == JointState::kNotTracked);
  CHECK(runtime::StateOf(s.joints[testing::kNotFoundJoint]) == JointState::kNotTracked);
  // Tracked wins over a stray `inferred`; `inferred` on a joint not found means nothing.
  runtime::SkeletonJoint both = s.joints[testing::kTrackedJoint];
  both.inferred = true;
  CHECK(runtime::StateOf(both) == JointState::kTracked);
  runtime::SkeletonJoint lost;
  lost.inferred = true;
  CHECK(runtime::StateOf(lost) == JointState::kNotTracked);
  CHECK(runtime::JointStateName(JointState::kTracked) == "tracked");
  CHECK(runtime::JointStateName(JointState::kInferred) == "inferred");
  CHECK(runtime::JointStateName(JointState::kNotTracked) == "not_tracked");
  // The numbers are the C API's PF_JOINT_* and the ROS 2 message's constants.
  CHECK(int(JointState::kNotTracked) == 0);
  CHECK(int(JointState::kInferred) == 1);
  CHECK(int(JointState::kTracked) == 2);

  const std::string line = runtime::SkeletonsJsonLine(1, 0.5, "hand", {s});
  CHECK(line.find("{\"name\":\"head\",\"position_m\":[0.125,-0.5,2.25],\"pixel\":[330.5,100.2],"
                  "\"confidence\":0.875,\"tracked\":true,\"state\":\"tracked\"}") != std::string::npos);
  CHECK(line.find("{\"name\":\"L_knee\",\"position_m\":[0.0625,0.25,2.875],\"pixel\":[339.5,302.0],"
                  "\"confidence\":0.75,\"tracked\":false,\"state\":\"inferred\"}") != std::string::npos);
  CHECK(line.find("{\"name\":\"R_elbow\",\"position_m\":[-0.25,-0.125,2.5],\"pixel\":[259.0,215.0],"
                  "\"confidence\":0.125,\"tracked\":false,\"state\":\"not_tracked\"}") != std::string::npos);
  CHECK(line.find("{\"name\":\"R_foot\",\"position_m\":null,\"pixel\":null,\"confidence\":0.0,"
                  "\"tracked\":false,\"state\":\"not_tracked\"}") != std::string::npos);
  // Every joint says its state, once.
  size_t states = 0;
  for (size_t at = line.find("\"state\":"); at != std::string::npos; at = line.find("\"state\":", at + 1))
    ++states;
  CHECK(states == size_t(core::kNumJoints));
}

TEST_CASE("pictures: inferred joints are hollow circles with no bones, tracked ones discs", "[skeleton]") {
  runtime::Skeleton s = testing::FourStateSkeleton();
  // A tracked left shoulder: were the knee tracked, a bone would join them.
  const int shoulder = int(core::Joint::kLShoulder);
  s.joints[size_t(shoulder)] = s.joints[size_t(testing::kTrackedJoint)];
  s.joints[size_t(shoulder)].pixel = Eigen::Vector2f(339.5f, 160.0f);
  const Eigen::Vector2f knee = s.joints[size_t(testing::kInferredJoint)].pixel;
  auto pixel = [](const runtime::RgbImage& img, float x, float y) {
    const uint8_t* p = &img.rgb[(size_t(std::lround(y)) * size_t(img.width) + size_t(std::lround(x))) * 3];
    return std::array<int, 3>{p[0], p[1], p[2]};
  };
  auto colour = [](int joint) {
    const core::Rgb c = core::PartColour(core::JointParts(joint).front());
    return std::array<int, 3>{c.r, c.g, c.b};
  };
  const std::array<int, 3> black{0, 0, 0};
  runtime::RgbImage picture(640, 480, 0);
  runtime::DrawSkeletons(picture, {s});
  CHECK(pixel(picture, 330.5f, 100.25f) == colour(testing::kTrackedJoint));          // a disc
  CHECK(pixel(picture, knee.x(), knee.y()) == black);                                // hollow ...
  CHECK(pixel(picture, knee.x() + 4, knee.y()) == colour(testing::kInferredJoint));  // ... its rim
  CHECK(pixel(picture, knee.x(), (knee.y() + 160.0f) / 2) == black);                 // no bone to it
  CHECK(pixel(picture, 259.0f, 215.0f) == std::array<int, 3>{110, 110, 110});        // found, not tracked
  // The same knee tracked: a disc, and the bone from the shoulder.
  runtime::Skeleton t = s;
  t.joints[size_t(testing::kInferredJoint)].inferred = false;
  t.joints[size_t(testing::kInferredJoint)].tracked = true;
  runtime::RgbImage tracked(640, 480, 0);
  runtime::DrawSkeletons(tracked, {t});
  CHECK(pixel(tracked, knee.x(), knee.y()) == colour(testing::kInferredJoint));
  const core::Rgb person = runtime::PersonColour(s.id);
  CHECK(pixel(tracked, knee.x(), (knee.y() + 160.0f) / 2) ==
        std::array<int, 3>{person.r, person.g, person.b});
  // live's whole figure draws them too (half size).
  core::DepthImage depth(640, 480, 0);
  for (int y = 50; y < 400; ++y)
    for (int x = 200; x < 450; ++x) depth.at(x, y) = 2500;
  const runtime::RgbImage fig = runtime::SkeletonFigure(depth, core::LabelImage(640, 480, 0), {s}, 2);
  CHECK(fig.width == 3 * 320);
  CHECK(fig.height == 240);
}

TEST_CASE("the kinematic fit is exact: dynamic programming equals brute force", "[skeleton][fit]") {
  using J = core::Joint;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-0.35f, 0.35f), conf(0.01f, 1.0f);
  std::uniform_int_distribution<int> count(0, 3);
  // The neck, the left shoulder and arm, and the head: 3-4 candidates each, brute-forced.
  const std::vector<int> joints = {int(J::kNeck), int(J::kHead), int(J::kLShoulder), int(J::kLElbow),
                                   int(J::kLWrist), int(J::kLHand)};
  for (const bool parent_rule : {true, false})
    for (int trial = 0; trial < 200; ++trial) {
      runtime::SkeletonOptions opt;
      opt.require_tracked_parent = parent_rule;
      runtime::FitCandidates cands;
      Eigen::Vector3f at(0, 0, 1.5f);
      for (int j : joints) {
        const int n = count(rng);
        for (int k = 0; k < n; ++k) {
          runtime::FitCandidate c;
          c.position = at + Eigen::Vector3f(u(rng), u(rng), u(rng));
          c.confidence = conf(rng);
          c.excluded = count(rng) == 0;  // a quarter of them may not be chosen
          cands[size_t(j)].push_back(c);
        }
        if (n) at = cands[size_t(j)][0].position;
      }
      const auto fit = runtime::FitSkeleton(cands, opt);
      const double fit_score = runtime::FitScore(cands, fit, opt);
      // Every combination.
      std::array<int, core::kNumJoints> choice;
      choice.fill(-1);
      double best = -1e300;
      std::function<void(size_t)> all = [&](size_t k) {
        if (k == joints.size()) {
          best = std::max(best, runtime::FitScore(cands, choice, opt));
          return;
        }
        const int j = joints[k];
        for (int s = -1; s < int(cands[size_t(j)].size()); ++s) {
          choice[size_t(j)] = s;
          all(k + 1);
        }
        choice[size_t(j)] = -1;
      };
      all(0);
      INFO("trial " << trial << (parent_rule ? " with" : " without") << " the parent rule");
      REQUIRE(fit_score == Approx(best).margin(1e-9));
      for (int j = 0; j < core::kNumJoints; ++j) {
        REQUIRE(fit[size_t(j)] < int(cands[size_t(j)].size()));
        if (fit[size_t(j)] >= 0) REQUIRE_FALSE(cands[size_t(j)][size_t(fit[size_t(j)])].excluded);
      }
    }
}

TEST_CASE("the kinematic fit keeps a left joint and its right counterpart apart (SeparateCounterparts)",
          "[skeleton][fit]") {
  using J = core::Joint;
  runtime::SkeletonOptions opt;
  REQUIRE(opt.counterpart_min_distance_m == Approx(0.12f));
  runtime::FitCandidates c = NeckAndLeftShoulder();
  AddCandidate(c, J::kRShoulder, {-0.19f, 0.05f, 1.5f}, 0.9f);
  AddCandidate(c, J::kLElbow, {0.3f, 0.3f, 1.45f}, 0.8f);
  AddCandidate(c, J::kRElbow, {-0.1f, 0.3f, 1.45f}, 0.8f);
  // Both wrists' best candidate is one place in front of the belly (the right forearm crossed
  // over): the left wrist has a second candidate a forearm from its elbow, the right none.
  const Eigen::Vector3f belly(0.1f, 0.45f, 1.35f);
  AddCandidate(c, J::kLWrist, belly, 0.7f);
  AddCandidate(c, J::kLWrist, {0.35f, 0.52f, 1.4f}, 0.3f);
  AddCandidate(c, J::kRWrist, belly + Eigen::Vector3f(0.02f, 0, 0), 0.6f);
  const int lw = int(J::kLWrist), rw = int(J::kRWrist);
  auto chosen = runtime::FitSkeleton(c, opt);
  REQUIRE(chosen[size_t(lw)] == 0);  // the exact fit alone: both at the belly
  REQUIRE(chosen[size_t(rw)] == 0);
  runtime::FitCandidates separated = c;
  runtime::SeparateCounterparts(separated, chosen, opt);
  // The left wrist gives way (its other candidate costs less than a missing right wrist).
  CHECK(chosen[size_t(lw)] == 1);
  CHECK(chosen[size_t(rw)] == 0);
  CHECK(separated[size_t(lw)][0].excluded);
  CHECK_FALSE(separated[size_t(rw)][0].excluded);
  CHECK(chosen == runtime::FitSkeleton(separated, opt));
  CHECK(runtime::FitScore(separated, chosen, opt) < runtime::FitScore(c, runtime::FitSkeleton(c, opt), opt));
  // With a second right-wrist candidate that is more likely than the left's, the right gives way.
  runtime::FitCandidates both = c;
  both[size_t(rw)].push_back({{-0.15f, 0.55f, 1.4f}, 0.55f});
  chosen = runtime::FitSkeleton(both, opt);
  runtime::SeparateCounterparts(both, chosen, opt);
  CHECK(chosen[size_t(lw)] == 0);
  CHECK(chosen[size_t(rw)] == 1);
  // Apart by more than the distance, or the rule off: nothing changes.
  runtime::SkeletonOptions off = opt;
  off.counterpart_min_distance_m = 0;
  chosen = runtime::FitSkeleton(c, off);
  runtime::FitCandidates untouched = c;
  runtime::SeparateCounterparts(untouched, chosen, off);
  CHECK(chosen[size_t(lw)] == 0);
  CHECK(chosen[size_t(rw)] == 0);
  runtime::SkeletonOptions near = opt;
  near.counterpart_min_distance_m = 0.01f;  // the two wrists are 0.02 m apart
  chosen = runtime::FitSkeleton(c, near);
  untouched = c;
  runtime::SeparateCounterparts(untouched, chosen, near);
  CHECK(chosen[size_t(lw)] == 0);
  CHECK(chosen[size_t(rw)] == 0);
}

TEST_CASE("the kinematic fit prefers a reachable wrist to a confident one on the other arm", "[skeleton][fit]") {
  using J = core::Joint;
  runtime::SkeletonOptions opt;
  runtime::FitCandidates c = NeckAndLeftShoulder();
  AddCandidate(c, J::kRShoulder, {-0.19f, 0.05f, 1.5f}, 0.9f);
  AddCandidate(c, J::kLElbow, {0.45f, 0.1f, 1.45f}, 0.6f);
  AddCandidate(c, J::kLWrist, {-0.65f, 0.1f, 1.4f}, 0.5f);  // beyond the right elbow: the other arm
  AddCandidate(c, J::kLWrist, {0.68f, 0.05f, 1.35f}, 0.2f);
  const auto fit = runtime::FitSkeleton(c, opt);
  CHECK(fit[size_t(int(J::kLWrist))] == 1);
  CHECK(fit[size_t(int(J::kLElbow))] == 0);
  // The greedy choice would be candidate 0; with it the forearm would be 1.1 m long: implausible,
  // costing implausible_bone_log (log 0.05), or impossible when that is -1e30.
  std::array<int, core::kNumJoints> greedy = fit;
  greedy[size_t(int(J::kLWrist))] = 0;
  REQUIRE(opt.implausible_bone_log == Approx(-3.0f));
  CHECK(runtime::FitScore(c, greedy, opt) < runtime::FitScore(c, fit, opt) - 1.0);
  runtime::SkeletonOptions hard = opt;
  hard.implausible_bone_log = -1e30f;
  CHECK(runtime::FitScore(c, greedy, hard) < -1e29);
  CHECK(runtime::FitSkeleton(c, hard) == fit);
  // No candidate: missing.
  CHECK(fit[size_t(int(J::kRElbow))] == -1);
}

TEST_CASE("the kinematic fit: a wrong elbow does not drag a well-found wrist and hand with it", "[skeleton][fit]") {
  using J = core::Joint;
  runtime::SkeletonOptions opt;
  runtime::FitCandidates c = NeckAndLeftShoulder();
  AddCandidate(c, J::kLElbow, {0.2f, 0.62f, 1.5f}, 0.5f);    // the only elbow: 0.57 m below the shoulder, too far
  AddCandidate(c, J::kLWrist, {0.4f, 0.1f, 1.3f}, 0.85f);    // where the forest is sure the wrist is
  AddCandidate(c, J::kLWrist, {0.2f, 0.85f, 1.5f}, 0.02f);   // a stray proposal a forearm from that elbow
  AddCandidate(c, J::kLHand, {0.43f, 0.06f, 1.27f}, 0.8f);   // beside the sure wrist
  AddCandidate(c, J::kLHand, {0.2f, 0.92f, 1.5f}, 0.02f);    // beside the stray one
  const auto fit = runtime::FitSkeleton(c, opt);
  // The upper arm is implausible either way; the wrist and hand keep what the forest is sure of.
  CHECK(fit[size_t(int(J::kLElbow))] == 0);
  CHECK(fit[size_t(int(J::kLWrist))] == 0);
  CHECK(fit[size_t(int(J::kLHand))] == 0);
  // With implausible bones impossible, the wrong elbow decides: the whole arm follows it.
  runtime::SkeletonOptions hard = opt;
  hard.implausible_bone_log = -1e30f;
  const auto chained = runtime::FitSkeleton(c, hard);
  CHECK(chained[size_t(int(J::kLElbow))] == -1);  // no possible upper arm: missing, and with it the
  CHECK(chained[size_t(int(J::kLWrist))] == -1);  // wrist and hand (a joint below the shoulder
  CHECK(chained[size_t(int(J::kLHand))] == -1);   // hangs from a present parent)
}

TEST_CASE("the skeleton's fit: set, else the one the forest's tracking decision learned, else kinematic",
          "[skeleton][fit]") {
  runtime::SkeletonOptions opt;
  CHECK_FALSE(opt.fit.has_value());
  core::TrackingModel greedy, kinematic;
  kinematic.fit = core::TrackingFit::kKinematic;
  CHECK(runtime::ResolveSkeletonFit(opt, nullptr) == runtime::SkeletonFit::kKinematic);
  CHECK(runtime::ResolveSkeletonFit(opt, &greedy) == runtime::SkeletonFit::kGreedy);  // a 1.6 forest
  CHECK(runtime::ResolveSkeletonFit(opt, &kinematic) == runtime::SkeletonFit::kKinematic);
  opt.use_tracking_model = false;  // --no-tracking-model: the model does not choose
  CHECK(runtime::ResolveSkeletonFit(opt, &greedy) == runtime::SkeletonFit::kKinematic);
  opt.use_tracking_model = true;
  opt.fit = runtime::SkeletonFit::kGreedy;
  CHECK(runtime::ResolveSkeletonFit(opt, &kinematic) == runtime::SkeletonFit::kGreedy);
  opt.fit = runtime::SkeletonFit::kKinematic;
  CHECK(runtime::ResolveSkeletonFit(opt, &greedy) == runtime::SkeletonFit::kKinematic);
  CHECK(runtime::SkeletonFitName(runtime::SkeletonFit::kKinematic) == "kinematic");
  CHECK(runtime::SkeletonFitFromName(runtime::SkeletonFitName(runtime::SkeletonFit::kGreedy)) ==
        runtime::SkeletonFit::kGreedy);
}

TEST_CASE("skeletons with offset votes: a confident vote on the mask wins, a hidden one is found not tracked",
          "[skeleton][votes]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 100, 100, 250, 479, 2000);  // a person at 2 m
  runtime::FrameProposals proposals{};
  const float big = 0.01f * float(cam.fx * cam.fy);
  proposals[kHead] = {At(cam, 170, 120, 2.04f, big)};  // calibrated 0.9 (RampCalibration)
  const auto cal = RampCalibration();
  auto vote = [&](int x, int y, float z, float confidence) { return VoteAt(cam, x, y, z, confidence); };
  std::vector<runtime::PersonVotes> votes(1);
  votes[0][kHead] = {vote(175, 125, 2.06f, 0.5f)};         // less confident than the proposal
  votes[0][kLHand] = {vote(130, 250, 2.05f, 0.8f)};        // on the mask, at its depth
  votes[0][kLKnee] = {vote(150, 380, 2.4f, 0.8f)};         // 0.4 m behind the surface: hidden
  votes[0][int(core::Joint::kRHand)] = {vote(400, 250, 2.05f, 0.9f)};  // off the mask
  for (const auto fit : {runtime::SkeletonFit::kGreedy, runtime::SkeletonFit::kKinematic}) {
    DYNAMIC_SECTION("fit " << int(fit)) {
      const runtime::SkeletonOptions opt = VoteTestOptions(fit);
      const auto plain = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt);
      const auto s = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &votes);
      REQUIRE(s.size() == 1);
      REQUIRE(plain.size() == 1);
      CHECK_FALSE(plain[0].joints[kLHand].found);  // no proposal: nothing without the votes
      // The head keeps its more confident proposal (greedy; the fit has no bones to weigh here).
      CHECK_FALSE(s[0].joints[kHead].voted);
      CHECK(s[0].joints[kHead].pixel.x() == 170);
      // The hand: the vote, tracked (confident, at the mask's depth).
      CHECK(s[0].joints[kLHand].found);
      CHECK(s[0].joints[kLHand].voted);
      CHECK(s[0].joints[kLHand].tracked);
      CHECK(s[0].joints[kLHand].confidence == Approx(0.8f));
      CHECK(s[0].joints[kLHand].pixel.x() == Approx(130).margin(0.01));
      CHECK(s[0].joints[kLHand].support_m2 == 0.0f);
      // The knee: placed behind the surface - found, not tracked.
      CHECK(s[0].joints[kLKnee].found);
      CHECK(s[0].joints[kLKnee].voted);
      CHECK_FALSE(s[0].joints[kLKnee].tracked);
      CHECK(s[0].joints[kLKnee].inferred);  // confident, hidden: placed by the body model
      CHECK_FALSE(s[0].joints[kLHand].inferred);  // tracked joints are not "inferred"
      CHECK_FALSE(s[0].joints[kHead].inferred);
      CHECK(runtime::StateOf(s[0].joints[kLKnee]) == runtime::JointState::kInferred);
      CHECK(runtime::StateOf(s[0].joints[kLHand]) == runtime::JointState::kTracked);
      const std::string line = runtime::SkeletonsJsonLine(0, 0, "x", s);
      const size_t knee = line.find("{\"name\":\"L_knee\"");
      REQUIRE(knee != std::string::npos);
      CHECK_THAT(line.substr(knee, line.find('}', knee) - knee + 1),
                 Catch::EndsWith(",\"tracked\":false,\"state\":\"inferred\"}"));
      CHECK(s[0].joints[kLKnee].position_m.z() == Approx(2.4f));
      // Off the person: not used.
      CHECK_FALSE(s[0].joints[int(core::Joint::kRHand)].found);
      // A vote more than max_vote_behind_m behind the surface is not used either.
      auto far = votes;
      far[0][kLKnee] = {vote(150, 380, 2.7f, 0.8f)};
      const auto f = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &far);
      CHECK_FALSE(f[0].joints[kLKnee].found);
      // A vote more confident than the proposal takes the joint (0.14 m away: they do not agree).
      auto sure = votes;
      sure[0][kHead] = {vote(210, 125, 2.06f, 0.95f)};
      const auto h = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &sure);
      CHECK(h[0].joints[kHead].voted);
      CHECK(h[0].joints[kHead].tracked);
    }
  }
}

TEST_CASE("skeletons with offset votes: a joint beyond the frame's edge that cuts the person is inferred",
          "[skeleton][votes]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  const auto cal = RampCalibration();
  const runtime::FrameProposals proposals{};
  const int lfoot = int(core::Joint::kLFoot), rfoot = int(core::Joint::kRFoot);
  auto vote = [&](int x, int y, float z, float confidence) { return VoteAt(cam, x, y, z, confidence); };
  std::vector<runtime::PersonVotes> votes(1);
  votes[0][lfoot] = {vote(150, 560, 2.1f, 0.8f)};  // below the image: the bottom edge cuts the person
  votes[0][rfoot] = {vote(-40, 300, 2.1f, 0.8f)};  // left of it: the left edge does not
  for (const auto fit : {runtime::SkeletonFit::kGreedy, runtime::SkeletonFit::kKinematic}) {
    DYNAMIC_SECTION("fit " << int(fit)) {
      const runtime::SkeletonOptions opt = VoteTestOptions(fit);
      Scene scene;
      scene.Person(1, 100, 100, 250, 479, 2000);  // cut by the bottom edge only
      const auto s = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &votes);
      REQUIRE(s.size() == 1);
      const runtime::SkeletonJoint& foot = s[0].joints[size_t(lfoot)];
      CHECK(foot.found);
      CHECK(foot.voted);
      CHECK_FALSE(foot.tracked);  // the camera does not see it
      CHECK(foot.inferred);       // confident: placed by the votes
      CHECK(foot.pixel.y() == Approx(560).margin(0.01));
      CHECK_FALSE(runtime::PixelInImage(foot.pixel, 640, 480));
      CHECK(foot.position_m.z() == Approx(2.1f));
      CHECK_FALSE(s[0].joints[size_t(rfoot)].found);  // beyond a side that does not cut the person
      const std::string line = runtime::SkeletonsJsonLine(0, 0, "x", s);
      const size_t at = line.find("{\"name\":\"L_foot\"");
      REQUIRE(at != std::string::npos);
      CHECK_THAT(line.substr(at, line.find('}', at) - at + 1),
                 Catch::Contains("\"pixel\":[150.0,560.0]") && Catch::EndsWith("\"state\":\"inferred\"}"));
      // Not confident enough: found beyond the frame, not inferred.
      auto weak = votes;
      weak[0][lfoot] = {vote(150, 560, 2.1f, 0.1f)};
      const auto w = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &weak);
      CHECK(w[0].joints[size_t(lfoot)].found);
      CHECK(runtime::StateOf(w[0].joints[size_t(lfoot)]) == runtime::JointState::kNotTracked);
      // Turned off: neither foot.
      runtime::SkeletonOptions off = opt;
      off.votes_beyond_frame = false;
      const auto o = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, off, &votes);
      CHECK_FALSE(o[0].joints[size_t(lfoot)].found);
      CHECK_FALSE(o[0].joints[size_t(rfoot)].found);
      // A person the left edge cuts: the vote left of the image places that foot.
      Scene left;
      left.Person(1, 0, 100, 150, 400, 2000);
      const auto l = runtime::BuildSkeletons(proposals, left.masks, 1, left.depth, cam, &cal, opt, &votes);
      CHECK(l[0].joints[size_t(rfoot)].found);
      CHECK(l[0].joints[size_t(rfoot)].inferred);
      CHECK_FALSE(l[0].joints[size_t(lfoot)].found);  // the bottom edge does not cut this one
      // live's picture does not draw it (it would land on the parts panel, left of the skeletons').
      auto without = l;
      without[0].joints[size_t(rfoot)] = runtime::SkeletonJoint();
      const core::LabelImage labels(640, 480, 0);
      // (bools: Catch would print two 2.8 MB vectors on a failure)
      const bool figure_unchanged = runtime::SkeletonFigure(left.depth, labels, l, 1).rgb ==
                                    runtime::SkeletonFigure(left.depth, labels, without, 1).rgb;
      CHECK(figure_unchanged);
      runtime::RgbImage plain(3 * 640, 480, 0), clipped(3 * 640, 480, 0);
      runtime::DrawSkeletons(plain, l, 1.0f, 1280, 0);  // no frame size: drawn where it projects
      runtime::DrawSkeletons(clipped, l, 1.0f, 1280, 0, 640, 480);
      const bool drawn_without_size = plain.rgb != clipped.rgb;
      CHECK(drawn_without_size);
    }
  }
}

TEST_CASE("skeletons with offset votes: a proposal and a vote that agree combine their confidences",
          "[skeleton][votes]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 100, 100, 250, 479, 2000);
  const auto cal = RampCalibration();
  runtime::FrameProposals proposals{};
  // Support 3e-3 m^2: calibrated between 0.3 and 0.9 (RampCalibration); set min_confidence
  // above it, so the proposal alone is not tracked.
  proposals[kLHand] = {At(cam, 130, 250, 2.04f, 3e-3f * float(cam.fx * cam.fy))};
  const float cp = cal.Confidence(kLHand, 3e-3f);
  REQUIRE(cp > 0.3f);
  REQUIRE(cp < 0.9f);
  auto vote = [&](int x, int y, float z, float confidence) { return VoteAt(cam, x, y, z, confidence); };
  std::vector<runtime::PersonVotes> near(1), far(1);
  near[0][kLHand] = {vote(134, 252, 2.05f, 0.4f)};  // 1.5 cm from the proposal
  far[0][kLHand] = {vote(200, 250, 2.05f, 0.4f)};   // 0.24 m from it
  for (const auto fit : {runtime::SkeletonFit::kGreedy, runtime::SkeletonFit::kKinematic}) {
  DYNAMIC_SECTION("fit " << runtime::SkeletonFitName(fit)) {
  near[0][kLHand] = {vote(134, 252, 2.05f, 0.4f)};
  runtime::SkeletonOptions opt = VoteTestOptions(fit);
  opt.min_confidence = 1.0f - (1.0f - cp) * (1.0f - 0.4f) - 0.01f;  // reached only together
  REQUIRE(opt.agree_radius_m == Approx(0.1f));  // the default
  const auto agree = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &near);
  REQUIRE(agree.size() == 1);
  const runtime::SkeletonJoint& hand = agree[0].joints[kLHand];
  CHECK(hand.found);
  CHECK_FALSE(hand.voted);  // the proposal is the more confident: its position
  CHECK(hand.pixel.x() == 130);
  CHECK(hand.confidence == Approx(1.0f - (1.0f - cp) * (1.0f - 0.4f)).margin(1e-4));
  CHECK(hand.tracked);
  // Apart, each alone is below the threshold: found, not tracked.
  const auto apart = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &far);
  CHECK(apart[0].joints[kLHand].found);
  CHECK_FALSE(apart[0].joints[kLHand].tracked);
  CHECK(apart[0].joints[kLHand].confidence == Approx(cp).margin(1e-4));
  // Radius 0: the rule is off.
  opt.agree_radius_m = 0;
  const auto off = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &near);
  CHECK_FALSE(off[0].joints[kLHand].tracked);
  // A more confident vote that agrees: its position, the combined confidence.
  opt.agree_radius_m = 0.1f;
  const float cv = cp + 0.05f;
  near[0][kLHand] = {vote(134, 252, 2.05f, cv)};
  const auto v = runtime::BuildSkeletons(proposals, scene.masks, 1, scene.depth, cam, &cal, opt, &near);
  // Greedy takes the more confident one's position; in the kinematic fit both candidates carry
  // the combined confidence, and of equals the earlier (the proposal) wins.
  CHECK(v[0].joints[kLHand].voted == (fit == runtime::SkeletonFit::kGreedy));
  CHECK(v[0].joints[kLHand].tracked);
  CHECK(v[0].joints[kLHand].confidence == Approx(1.0f - (1.0f - cp) * (1.0f - cv)).margin(1e-4));
  }
  }
}

namespace {

// A forest of single-leaf trees (every pixel reaches leaf 0 of each) whose offset votes are
// `leaf_votes[t]` for tree t (in joint order, at most one per joint), bandwidth 0.06 m, and
// confidence 0.2 for a share below 0.5, 0.7 above.
core::Forest SingleLeafVoteForest(const std::vector<std::vector<core::JointVote>>& leaf_votes) {
  core::Forest forest;
  forest.num_parts = core::kNumParts;
  forest.part_names = core::Forest::DefaultPartNames();
  core::OffsetVotes table;
  table.bandwidth_m.fill(0.06f);
  table.share_edges = {0.0f, 0.5f};
  for (int j = 0; j < core::kNumJoints; ++j) table.precision.insert(table.precision.end(), {0.2f, 0.7f});
  for (const auto& votes : leaf_votes) {
    core::Tree tree;
    tree.nodes.push_back(core::Node::Leaf(0));
    tree.num_leaves = 1;
    tree.leaves.assign(size_t(forest.leaf_stride()), 0);
    tree.leaves[0] = 255;
    forest.trees.push_back(tree);
    core::TreeVotes tv;
    tv.first = {0, uint32_t(votes.size())};
    tv.votes = votes;
    table.trees.push_back(tv);
  }
  forest.offset_votes = table;
  return forest;
}

}  // namespace

TEST_CASE("CastVotes: every pixel votes its leaf's offset; mean shift finds the mode; confidence from the table",
          "[skeleton][votes]") {
  // One tree that is a single leaf: every pixel of the patch casts the same offsets.
  const core::Forest forest =
      SingleLeafVoteForest({{{0, -300, 100, uint8_t(kHead), 255}, {50, 0, 80, uint8_t(kLHand), 128}}});
  REQUIRE(core::ValidateForest(forest, "votes").ok());
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 300, 200, 309, 209, 2000);  // a 10 x 10 pixel patch at 2 m (3.5 cm wide)
  const auto votes = runtime::CastVotes(forest, scene.depth, scene.masks, 1, cam);
  REQUIRE(votes.size() == 1);
  Eigen::Vector3f centre(0, 0, 0);
  for (int y = 200; y <= 209; ++y)
    for (int x = 300; x <= 309; ++x) centre += cam.Unproject(x, y, 2.0).cast<float>();
  centre /= 100.0f;
  REQUIRE(votes[0][kHead].size() == 1);  // one mode: the patch is narrower than the bandwidth
  const auto& head = votes[0][kHead][0];
  CHECK((head.position - (centre + Eigen::Vector3f(0, -0.3f, 0.1f))).norm() < 0.01f);
  CHECK(head.share > 0.8f);
  CHECK(head.confidence == 0.7f);
  REQUIRE(votes[0][kLHand].size() == 1);
  CHECK((votes[0][kLHand][0].position - (centre + Eigen::Vector3f(0.05f, 0, 0.08f))).norm() < 0.01f);
  CHECK(votes[0][kLKnee].empty());  // no leaf votes for it
  // A person elsewhere in the frame, another label: its own candidates; none for an empty label.
  const auto none = runtime::CastVotes(forest, scene.depth, scene.masks, 2, cam);
  REQUIRE(none.size() == 2);
  CHECK(none[1][kHead].empty());
  // The leaf walk: a root leaf is leaf 0 for any pixel.
  CHECK(runtime::LeafOf(forest.trees[0], forest.constants, scene.depth, 305, 205) == 0);
}

TEST_CASE("CastVotes: the kept votes and the modes equal a plain reference (stable sort, std::exp)",
          "[skeleton][votes]") {
  // Three single-leaf trees, each one vote per joint, the same for every joint: trees 0 and 1 a
  // few cm apart, tree 2 0.3 m away, so two modes. Depths vary over the patch, so the votes'
  // weights (leaf weight x d^2) vary and many tie; more votes than the cap, so which are kept
  // matters. Every joint is checked: the joints' loop runs on several threads (OpenMP).
  const int16_t dx[3] = {0, 30, 300}, dz[3] = {100, 80, 0};
  const uint8_t weight[3] = {200, 255, 90};
  std::vector<std::vector<core::JointVote>> leaf_votes(3);
  for (int t = 0; t < 3; ++t)
    for (int j = 0; j < core::kNumJoints; ++j) leaf_votes[size_t(t)].push_back({dx[t], -50, dz[t], uint8_t(j), weight[t]});
  const core::Forest forest = SingleLeafVoteForest(leaf_votes);
  REQUIRE(core::ValidateForest(forest, "votes").ok());
  const auto cam = core::CameraIntrinsics::KinectV1();
  Scene scene;
  scene.Person(1, 300, 200, 319, 219, 2000);  // 20 x 20 pixels: all vote (below target_pixels)
  for (int y = 200; y <= 219; ++y)
    for (int x = 300; x <= 319; ++x) scene.depth.at(x, y) = uint16_t(2000 + (x * 7 + y * 3) % 40);
  runtime::VoteOptions options;
  options.max_votes_per_joint = 500;  // of 1,200
  const auto got = runtime::CastVotes(forest, scene.depth, scene.masks, 1, cam, options);
  REQUIRE(got.size() == 1);

  // The reference: votes in cast order (pixels row by row, trees in order), the heaviest kept
  // by a stable sort, mean shift with std::exp over them.
  struct V {
    Eigen::Vector3f p;
    float w;
  };
  std::vector<V> all;
  for (int y = 200; y <= 219; ++y)
    for (int x = 300; x <= 319; ++x) {
      const uint16_t d = scene.depth.at(x, y);
      const Eigen::Vector3f point = cam.Unproject(x, y, d * 1e-3).cast<float>();
      for (int t = 0; t < 3; ++t)
        all.push_back({point + Eigen::Vector3f(dx[t], -50, dz[t]) * 1e-3f,
                       float(weight[t]) / 255.0f * float(d) * float(d) * 1e-6f});
    }
  float total = 0;
  for (const V& v : all) total += v.w;
  std::stable_sort(all.begin(), all.end(), [](const V& a, const V& b) { return a.w > b.w; });
  all.resize(size_t(options.max_votes_per_joint));
  const float b = 0.06f;
  auto density = [&](const Eigen::Vector3f& q, Eigen::Vector3f* mean) {
    Eigen::Vector3f s(0, 0, 0);
    float sw = 0;
    for (const V& v : all) {
      const float d2 = (v.p - q).squaredNorm();
      if (d2 > 9 * b * b) continue;
      const float k = v.w * std::exp(-d2 / (b * b));
      s += k * v.p;
      sw += k;
    }
    if (mean && sw > 0) *mean = s / sw;
    return sw;
  };
  std::vector<std::pair<Eigen::Vector3f, float>> modes;
  for (int i = 0; i < options.seeds; ++i) {
    Eigen::Vector3f q = all[size_t(i)].p;
    for (int it = 0; it < options.iterations; ++it) {
      Eigen::Vector3f next = q;
      if (!(density(q, &next) > 0)) break;
      const float step = (next - q).norm();
      q = next;
      if (step < 1e-3f) break;
    }
    const float score = density(q, nullptr);
    bool merged = false;
    for (auto& [m, sc] : modes)
      if ((m - q).norm() < 0.5f * b) {
        if (score > sc) m = q, sc = score;
        merged = true;
        break;
      }
    if (!merged) modes.emplace_back(q, score);
  }
  std::stable_sort(modes.begin(), modes.end(), [](const auto& x, const auto& y) { return x.second > y.second; });
  // The seeds are the heaviest votes: tree 1's (weight 255) at the deepest pixels, one mode.
  REQUIRE(modes.size() == 1);
  for (int j = 0; j < core::kNumJoints; ++j) {
    INFO("joint " << j);
    const auto& cands = got[0][size_t(j)];
    REQUIRE(cands.size() == modes.size());
    CHECK((cands[0].position - modes[0].first).norm() < 1e-4f);
    CHECK(cands[0].share == Approx(modes[0].second / total).epsilon(1e-4));
  }
  // Seeds from every vote (tree 2's are the lightest): the far mode too, after the near one.
  options.max_votes_per_joint = 1200;
  options.seeds = 1200;
  const auto both = runtime::CastVotes(forest, scene.depth, scene.masks, 1, cam, options);
  REQUIRE(both[0][kLHand].size() == 2);
  CHECK((both[0][kLHand][0].position - both[0][kLHand][1].position).norm() > 0.25f);
}
