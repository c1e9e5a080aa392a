// Grid search of the joint-proposal parameters recovers planted best values; the mAP-level
// curve; the PR-curve figure.
#include <catch2/catch.hpp>

#include "runtime/proposal_tuning.h"
#include "runtime/visualize.h"

using namespace poseforest;

namespace {

constexpr int kHead = int(core::Joint::kHead);

// A flat 2 m frame with square patches of `joint` (default head) probability; returns the frame and the 3D
// centre of each patch.
runtime::ValidationFrame Patches(
    const std::vector<std::tuple<int, int, int, float>>& patches /* x, y, half, p */,
    std::vector<Eigen::Vector3f>* centres, int joint = kHead) {
  runtime::ValidationFrame f;
  f.depth = core::DepthImage(640, 480, 0);
  f.probs.width = 640;
  f.probs.height = 480;
  const auto cam = core::CameraIntrinsics::KinectV1();
  for (const auto& [cx, cy, half, p] : patches) {
    for (int y = cy - half; y <= cy + half; ++y)
      for (int x = cx - half; x <= cx + half; ++x) {
        f.depth.at(x, y) = 2000;
        f.probs.pixel.push_back(uint32_t(y * 640 + x));
        std::array<float, core::kNumJoints> pr{};
        pr[size_t(joint)] = p;
        f.probs.prob.push_back(pr);
      }
    if (centres) centres->push_back(cam.PixelToPoint(cx, cy, 2000).cast<float>());
  }
  return f;
}

runtime::PersonJoints HeadAt(const Eigen::Vector3f& p) {
  runtime::PersonJoints person;
  person.position.fill(Eigen::Vector3f(0, 0, 9));
  person.position[kHead] = p;
  person.visible[kHead] = true;
  return person;
}

}  // namespace

TEST_CASE("grid search recovers a planted best bandwidth", "[tuning]") {
  // Two patches 35 px (12 cm at 2 m) apart, the head half way between them, and a smaller
  // distractor 115 px (40 cm) away. Too small a bandwidth leaves two modes 6 cm from the head
  // (false positives at D = 5 cm); the right one merges the pair into one mode on the head;
  // too large a one also swallows the distractor and drags the mode away.
  std::vector<Eigen::Vector3f> c;
  runtime::ValidationFrame frame =
      Patches({{300, 200, 5, 1.0f}, {335, 200, 5, 1.0f}, {450, 200, 3, 1.0f}}, &c);
  frame.people = {HeadAt((c[0] + c[1]) / 2)};
  runtime::TuningGrid grid;
  grid.bandwidth_m = {0.02f, 0.12f, 0.6f};
  grid.prob_threshold = {0.5f};
  grid.z_offset_m = {0.0f};
  runtime::ProposalOptions base;
  base.voxel_fraction = 0.25f;
  base.max_iterations = 200;
  const auto result = runtime::TuneProposalParams({frame, frame}, base, grid, 0.05f);
  CHECK(result.params[kHead].bandwidth_m == 0.12f);
  CHECK(result.ap[kHead] == Approx(1.0));
  // Joints never visible keep their starting parameters.
  CHECK(result.params[int(core::Joint::kLKnee)] == base.params[int(core::Joint::kLKnee)]);
}

TEST_CASE("grid search recovers a planted threshold and z offset", "[tuning]") {
  // The head patch has probability 0.9; a larger patch elsewhere has 0.5, enough weight to be
  // the most confident proposal when it seeds: thresholds below 0.5 let it in. The true joint
  // lies 6 cm behind the surface.
  std::vector<Eigen::Vector3f> c;
  runtime::ValidationFrame frame = Patches({{200, 240, 6, 0.9f}, {450, 240, 12, 0.5f}}, &c);
  frame.people = {HeadAt(c[0] + Eigen::Vector3f(0, 0, 0.06f))};
  runtime::TuningGrid grid;
  grid.bandwidth_m = {0.065f};
  grid.prob_threshold = {0.1f, 0.3f, 0.6f, 0.8f};
  grid.z_offset_m = {0.0f, 0.03f, 0.06f, 0.09f};
  const auto result = runtime::TuneProposalParams({frame, frame, frame}, {}, grid, 0.02f);
  CHECK(result.params[kHead].prob_threshold == 0.6f);
  CHECK(result.params[kHead].z_offset_m == 0.06f);
  CHECK(result.ap[kHead] == Approx(1.0));
  CHECK(result.mean_ap == Approx(1.0));  // the only joint ever visible
}

TEST_CASE("grid search gives the same parameters whatever the thread count", "[tuning]") {
  std::vector<Eigen::Vector3f> c;
  std::vector<runtime::ValidationFrame> frames;
  for (int k = 0; k < 5; ++k) {
    runtime::ValidationFrame f = Patches({{200 + 20 * k, 240, 6, 0.9f}, {450, 200 + 10 * k, 10, 0.4f}}, &c);
    f.people = {HeadAt(c[c.size() - 2] + Eigen::Vector3f(0, 0, 0.03f))};
    frames.push_back(std::move(f));
  }
  runtime::TuningGrid grid;
  grid.bandwidth_m = {0.03f, 0.065f};
  grid.prob_threshold = {0.3f, 0.6f};
  runtime::ProposalOptions one, two;
  one.num_threads = 1;
  two.num_threads = 2;
  int calls = 0;
  const auto a = runtime::TuneProposalParams(frames, one, grid, 0.05f, [&](int done, int total) {
    ++calls;
    CHECK(total == 4);
    CHECK(done == calls);
  });
  const auto b = runtime::TuneProposalParams(frames, two, grid, 0.05f);
  CHECK(calls == 4);
  CHECK(a.params == b.params);
  CHECK(a.ap == b.ap);
  CHECK(a.mean_ap >= a.base_mean_ap);  // the grid holds points at least as good as the start
}

TEST_CASE("mAP-level curve: mean interpolated precision over joints", "[ap]") {
  // Head: one true positive (confidence 2), then one false positive: AP 1. Neck: a false
  // positive first, then the true one: precision 0.5 at recall 1, AP 0.5.
  runtime::PersonJoints person;
  person.position.fill(Eigen::Vector3f(0, 0, 3));
  person.position[kHead] = {0, 0, 2};
  person.position[int(core::Joint::kNeck)] = {0, 0.2f, 2};
  person.visible[kHead] = person.visible[int(core::Joint::kNeck)] = true;
  runtime::FrameProposals f;
  f[kHead] = {{{0, 0, 2.01f}, {0, 0}, 2.0f}, {{1, 0, 2}, {0, 0}, 1.0f}};
  f[int(core::Joint::kNeck)] = {{{1, 0, 2}, {0, 0}, 2.0f}, {{0, 0.2f, 2}, {0, 0}, 1.0f}};
  runtime::JointApEvaluator ev;
  ev.AddFrame(f, {person});
  CHECK(ev.AveragePrecision(kHead) == Approx(1.0));
  CHECK(ev.AveragePrecision(int(core::Joint::kNeck)) == Approx(0.5));
  const auto mean = ev.MeanCurve(11);
  REQUIRE(mean.size() == 11);
  for (const auto& p : mean) CHECK(p.precision == Approx(0.75));  // (1 + 0.5) / 2 at every recall
  CHECK(mean.front().recall == 0.0);
  CHECK(mean.back().recall == 1.0);
}

TEST_CASE("PR figure: text in the built-in font and curves in the series' colours", "[visualize]") {
  runtime::RgbImage img(40, 10, 255);
  runtime::DrawText(img, 0, 0, "1", {0, 0, 0});
  int dark = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3) dark += img.rgb[i] == 0;
  CHECK(dark == 10);  // the glyph '1' has 10 set pixels
  CHECK(runtime::TextWidth("ab") == 11);

  runtime::PrPanel panel{"head",
                         {{"mean shift", {31, 119, 180}, {{1.0f, 1.0, 0.5}, {0.5f, 0.5, 1.0}}, 0.75}}};
  const auto fig = runtime::PrCurvesFigure({panel, panel}, 2, 200, 180);
  CHECK(fig.width == 400);
  CHECK(fig.height == 180 + 14);
  int blue = 0;
  for (size_t i = 0; i < fig.rgb.size(); i += 3)
    blue += fig.rgb[i] == 31 && fig.rgb[i + 1] == 119 && fig.rgb[i + 2] == 180;
  CHECK(blue > 200);  // two curves, the legend swatch and the AP labels
}

TEST_CASE("left and right joints share parameters unless asked not to", "[tuning]") {
  // Left shoulder: a 0.9 patch on the joint and a larger 0.5 distractor that wins when it seeds
  // (thresholds below 0.5). Right shoulder: the 0.9 patch alone, so every threshold is perfect
  // and on its own it keeps the smallest. As a pair, both take the threshold that suits both.
  const int left = int(core::Joint::kLShoulder), right = int(core::Joint::kRShoulder);
  std::vector<Eigen::Vector3f> c;
  runtime::ValidationFrame fl = Patches({{200, 240, 6, 0.9f}, {450, 240, 12, 0.5f}}, &c, left);
  runtime::PersonJoints pl;
  pl.position.fill(Eigen::Vector3f(0, 0, 9));
  pl.position[size_t(left)] = c[0];
  pl.visible[size_t(left)] = true;
  fl.people = {pl};
  runtime::ValidationFrame fr = Patches({{300, 240, 6, 0.9f}}, &c, right);
  runtime::PersonJoints pr;
  pr.position.fill(Eigen::Vector3f(0, 0, 9));
  pr.position[size_t(right)] = c.back();
  pr.visible[size_t(right)] = true;
  fr.people = {pr};
  runtime::TuningGrid grid;
  grid.bandwidth_m = {0.065f};
  grid.prob_threshold = {0.1f, 0.6f};
  grid.z_offset_m = {0.0f};
  const auto paired = runtime::TuneProposalParams({fl, fr}, {}, grid, 0.05f);
  CHECK(paired.params[size_t(left)].prob_threshold == 0.6f);
  CHECK(paired.params[size_t(right)].prob_threshold == 0.6f);
  CHECK(paired.ap[size_t(left)] == Approx(1.0));
  CHECK(paired.ap[size_t(right)] == Approx(1.0));
  grid.mirror_pairs = false;
  const auto single = runtime::TuneProposalParams({fl, fr}, {}, grid, 0.05f);
  CHECK(single.params[size_t(left)].prob_threshold == 0.6f);
  CHECK(single.params[size_t(right)].prob_threshold == 0.1f);
}
