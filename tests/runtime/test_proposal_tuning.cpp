// Grid search of the joint-proposal parameters recovers planted best values.
#include <catch2/catch.hpp>

#include "runtime/proposal_tuning.h"

using namespace poseforest;

namespace {

constexpr int kHead = int(core::Joint::kHead);

// A flat 2 m frame with square patches of head probability; returns the frame and the 3D
// centre of each patch.
runtime::ValidationFrame Patches(const std::vector<std::tuple<int, int, int, float>>& patches /* x, y, half, p */,
                                 std::vector<Eigen::Vector3f>* centres) {
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
        pr[kHead] = p;
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
  runtime::ValidationFrame frame = Patches({{300, 200, 5, 1.0f}, {335, 200, 5, 1.0f}, {450, 200, 3, 1.0f}}, &c);
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
