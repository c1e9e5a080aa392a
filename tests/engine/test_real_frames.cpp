// The real-frame scorer (`poseforest eval --real-labels`, engine/real_frames.h) on frames and
// labels the test makes itself: renders (real EGL rendering, procedural bodies and poses) with
// their joints written as a label file, as the hand labels of the shared data's real frames are.
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "engine/real_frames.h"
#include "renderer/synthetic_source.h"
#include "runtime/core/body_parts.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

using namespace poseforest;
using testing::RunPoseforest;
namespace fs = std::filesystem;

namespace {

constexpr int kUpperBody = 10;  // head .. R_hand: the joints the real frames label

struct Rendered {
  engine::RealLabelSet labels;
  std::vector<renderer::RenderedFrame> frames;
};

// `n` renders framed on the upper body, each written as a raw uint16 frame beside a label file
// whose joints are the renders' own visible upper-body joints: uv their projection, xyz_m the
// joint moved kSurfaceToCentreM toward the camera (so the scorer's target is the joint itself).
Rendered RenderLabelled(const fs::path& dir, int n) {
  renderer::SceneConfig config;
  config.variants_per_shape = 1;
  config.framing.upper_body_share = 1.0;
  auto r = renderer::SyntheticRenderer::Create(config);
  REQUIRE(r.ok());
  Rendered out;
  out.labels.camera.intrinsics = config.camera;
  for (int i = 0; i < n; ++i) {
    auto f = (*r)->Render(21, uint64_t(i));
    REQUIRE(f.ok());
    engine::RealFrameLabels frame;
    frame.file = "frame-" + std::to_string(i);
    frame.path = (dir / frame.file).string();
    std::ofstream(frame.path, std::ios::binary)
        .write(reinterpret_cast<const char*>(f->depth.data()), std::streamsize(f->depth.pixels.size() * 2));
    for (int q = 0; q < kUpperBody; ++q) {
      if (!f->visible[0][size_t(q)]) continue;
      const Eigen::Vector3d joint = f->joints[0][size_t(q)].cast<double>();
      engine::RealJointLabel l;
      l.uv = config.camera.Project(joint);
      if (l.uv.x() < 0 || l.uv.y() < 0 || l.uv.x() >= 640 || l.uv.y() >= 480) continue;
      l.surface_m = joint * (1.0 - engine::kSurfaceToCentreM / joint.norm());
      l.err_px = 8;
      frame.joints[size_t(q)] = l;
    }
    out.labels.frames.push_back(frame);
    out.frames.push_back(std::move(*f));
  }
  return out;
}

// A SkeletonFrame holding one skeleton (mask = the render's foreground) whose tracked joints are
// the render's joints moved by `shift`.
runtime::SkeletonFrame GroundTruthFrame(const renderer::RenderedFrame& f, const Eigen::Vector3f& shift,
                                        const core::CameraIntrinsics& camera) {
  runtime::SkeletonFrame s;
  s.masks = core::LabelImage(f.depth.width, f.depth.height, 0);
  for (size_t k = 0; k < f.depth.pixels.size(); ++k) s.masks.pixels[k] = f.depth.pixels[k] != 0 ? 1 : 0;
  runtime::Skeleton sk;
  sk.mask_label = 1;
  sk.pixels = int(core::CountForeground(f.depth));
  for (int q = 0; q < core::kNumJoints; ++q) {
    auto& j = sk.joints[size_t(q)];
    j.found = j.tracked = true;
    j.position_m = f.joints[0][size_t(q)] + shift;
    j.pixel = camera.Project(j.position_m.cast<double>()).cast<float>();
  }
  s.skeletons.push_back(sk);
  s.depth = &f.depth;
  s.classification.labels = f.labels;
  return s;
}

}  // namespace

TEST_CASE("label files: round trip, and bad files refused naming the file", "[real][unit]") {
  const fs::path dir = testing::ScratchDir("real-labels-io");
  engine::RealLabelSet set;
  set.camera.intrinsics.fx = 500, set.camera.intrinsics.fy = 501;
  engine::RealFrameLabels f;
  f.file = "a.raw";
  engine::RealJointLabel l;
  l.uv = {100, 200}, l.err_px = 6, l.occluded = true, l.surface_m = {0.1, -0.2, 1.3};
  f.joints[size_t(core::Joint::kLWrist)] = l;
  set.frames.push_back(f);
  const std::string path = (dir / "labels.json").string();
  REQUIRE(engine::WriteRealLabels(path, set).ok());
  auto back = engine::ReadRealLabels(path);
  REQUIRE(back.ok());
  CHECK(back->camera.intrinsics.fx == 500);
  CHECK(back->camera.intrinsics.fy == 501);
  REQUIRE(back->frames.size() == 1);
  CHECK(back->frames[0].path == (dir / "a.raw").string());
  const auto& w = back->frames[0].joints[size_t(core::Joint::kLWrist)];
  REQUIRE(w.has_value());
  CHECK(w->occluded);
  CHECK(w->uv == l.uv);
  CHECK((w->Target() - l.surface_m).norm() == Approx(engine::kSurfaceToCentreM));
  CHECK(w->Target().z() > l.surface_m.z());  // further from the camera
  for (int q = 0; q < core::kNumJoints; ++q)
    if (q != int(core::Joint::kLWrist)) CHECK_FALSE(back->frames[0].joints[size_t(q)].has_value());

  // A folder given as the label file (it used to abort on an uncaught stream exception).
  const auto folder = dir / "labels_folder.json";
  fs::create_directories(folder);
  auto in_folder = engine::ReadRealLabels(folder.string());
  REQUIRE_FALSE(in_folder.ok());
  CHECK_THAT(in_folder.status().message(), Catch::Contains(folder.string() + ": is a folder, not a file"));

  auto refused = [&](const std::string& text, const std::string& why) {
    std::ofstream(path) << text;
    auto r = engine::ReadRealLabels(path);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == core::ErrorCode::kDataLoss);
    CHECK_THAT(r.status().message(), Catch::Contains(path) && Catch::Contains(why));
  };
  const std::string cam = R"("camera": {"fx": 575.8, "fy": 575.8, "cx": 319.5, "cy": 239.5, "width": 640, "height": 480})";
  refused("{ not json", "not JSON");
  refused("{\"frames\": []}", "\"camera\"");
  refused("{" + cam + ", \"frames\": []}", "empty");
  refused("{" + cam + R"(, "frames": [{"file": "x", "joints": {"L_elbo": null}}]})", "unknown joint 'L_elbo'");
  refused("{" + cam + R"(, "frames": [{"file": "x", "joints": {"head": {"uv": [700, 10], "xyz_m": [0, 0, 1]}}}]})",
          "outside the 640x480 camera");
  refused("{" + cam + R"(, "frames": [{"file": "x", "joints": {"head": {"uv": [7, 10]}}}]})", "malformed");
  CHECK(engine::ReadRealLabels((dir / "missing.json").string()).status().code() ==
        core::ErrorCode::kNotFound);
}

TEST_CASE("the scorer on renders and their own joints: right, wrong, found but not tracked", "[real][egl]") {
  const fs::path dir = testing::ScratchDir("real-frames-score");
  const Rendered r = RenderLabelled(dir, 4);
  const core::CameraIntrinsics& cam = r.labels.camera.intrinsics;
  std::vector<engine::RealFrameOutcome> exact, off, found;
  int labelled = 0;
  for (size_t i = 0; i < r.frames.size(); ++i) {
    const auto& labels = r.labels.frames[i];
    for (const auto& l : labels.joints) labelled += l.has_value();
    // The joints themselves: every labelled joint right, 2D error ~0.
    const runtime::SkeletonFrame truth = GroundTruthFrame(r.frames[i], Eigen::Vector3f::Zero(), cam);
    REQUIRE(engine::PickLabelledSkeleton(labels, truth) == 0);
    exact.push_back(engine::ScoreRealFrame(labels, truth, 0));
    // 0.12 m off (beyond 0.10 m): tracked, none right.
    const runtime::SkeletonFrame moved = GroundTruthFrame(r.frames[i], Eigen::Vector3f(0.12f, 0, 0), cam);
    off.push_back(engine::ScoreRealFrame(labels, moved, 0));
    // Not tracked, but a proposal on the person at the joint: "any within" only.
    runtime::SkeletonFrame untracked = moved;
    for (auto& j : untracked.skeletons[0].joints) j.tracked = false;
    for (int q = 0; q < core::kNumJoints; ++q) {
      runtime::JointProposal p;
      p.position = r.frames[i].joints[0][size_t(q)];
      p.pixel = cam.Project(p.position.cast<double>()).cast<float>();
      // Its pixel must lie on the mask: the labelled uv does (the joint is visible).
      untracked.proposals[size_t(q)].push_back(p);
    }
    found.push_back(engine::ScoreRealFrame(labels, untracked, 0));
    // No person: nothing tracked.
    const auto none = engine::ScoreRealFrame(labels, untracked, -1);
    for (const auto& o : none.joints) CHECK_FALSE((o.tracked || o.any_right));
  }
  REQUIRE(labelled >= 20);  // upper-body renders show most of their 10 upper-body joints
  const engine::RealScore s_exact = engine::SummarizeReal(exact), s_off = engine::SummarizeReal(off),
                          s_found = engine::SummarizeReal(found);
  INFO(engine::FormatRealScore(s_exact));
  CHECK(s_exact.all().labelled == labelled);
  CHECK(s_exact.all().right == labelled);
  CHECK(s_exact.all().median_error_px < 0.01);
  CHECK(s_off.all().tracked == labelled);
  CHECK(s_off.all().right == 0);
  CHECK(s_off.all().any_right == 0);
  CHECK(s_off.all().median_error_px > 10);  // 0.12 m at ~1-2 m is tens of pixels
  CHECK(s_found.all().tracked == 0);
  CHECK(s_found.all().right == 0);
  CHECK(s_found.all().any_right > labelled * 9 / 10);  // proposals at the joints (a few off-mask pixels aside)
  const std::string table = engine::FormatRealScore(s_exact);
  CHECK_THAT(table, Catch::Contains("elbows") && Catch::Contains("hands") && Catch::Contains("all"));
  // The overlay picture: three panels of the frame.
  const auto fig = engine::RealFramePicture(r.labels.frames[0], GroundTruthFrame(r.frames[0], {}, cam), exact[0]);
  CHECK(fig.width == 3 * 640);
  CHECK(fig.height == 480);
}

TEST_CASE("eval --real-labels end to end: table, pictures, clear errors", "[real][cli][egl]") {
  const fs::path dir = testing::ScratchDir("real-frames-cli");
  const Rendered r = RenderLabelled(dir, 3);
  const std::string labels = (dir / "labels.json").string();
  REQUIRE(engine::WriteRealLabels(labels, r.labels).ok());
  int labelled = 0;
  for (const auto& f : r.labels.frames)
    for (const auto& l : f.joints) labelled += l.has_value();
  // A tiny forest on upper-body renders of other seeds.
  const std::string job = (dir / "job.textproto").string(), forest = (dir / "forest.pff").string();
  std::ofstream(job) << "seed: 3 num_trees: 1 max_depth: 10 images_per_tree: 8 pixels_per_image: 400\n"
                        "candidate_features: 40 thresholds_per_feature: 10\n"
                        "source { rendered { seed: 1 upper_body_share: 1 } }\n";
  auto train = RunPoseforest("train " + job + " --out " + forest + " --quiet");
  INFO(train.output);
  REQUIRE(train.exit_code == 0);
  const fs::path pngs = dir / "pictures";
  auto eval = RunPoseforest("eval --forest " + forest + " --real-labels " + labels + " --png-dir " + pngs.string());
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(eval.output, Catch::Contains("on 3 real frames") && Catch::Contains("pixel stride 2") &&
                              Catch::Contains("head, neck, shoulders") && Catch::Contains("any within 0.10 m") &&
                              Catch::Contains("labelled joints tracked within 0.10 m"));
  // The last line counts every labelled joint.
  CHECK_THAT(eval.output, Catch::Contains("of " + std::to_string(labelled) + " labelled joints"));
  for (const auto& f : r.labels.frames) CHECK(fs::file_size(pngs / (f.file + ".png")) > 1000);

  // A label file naming a frame that is not there: exit 1, the frame named.
  engine::RealLabelSet missing = r.labels;
  missing.frames[1].file = "no-such-frame";
  const std::string bad = (dir / "missing.json").string();
  REQUIRE(engine::WriteRealLabels(bad, missing).ok());
  auto e1 = RunPoseforest("eval --forest " + forest + " --real-labels " + bad);
  CHECK(e1.exit_code == 1);
  CHECK_THAT(e1.output, Catch::Contains("no-such-frame"));
  // Not JSON: exit 1, the file named. Options that belong to --test-set: usage error.
  std::ofstream(bad) << "garbage";
  auto e2 = RunPoseforest("eval --forest " + forest + " --real-labels " + bad);
  CHECK(e2.exit_code == 1);
  CHECK_THAT(e2.output, Catch::Contains(bad) && Catch::Contains("not JSON"));
  auto e3 = RunPoseforest("eval --forest " + forest + " --real-labels " + labels + " --images 3");
  CHECK(e3.exit_code == 2);
  CHECK_THAT(e3.output, Catch::Contains("--images does not go with --real-labels"));
}
