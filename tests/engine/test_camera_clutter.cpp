// Cameras and clutter, renderer side, through a trained forest: (1) frames rendered with another camera's
// focal length classify about as well as the training camera's once the runtime rescales the
// forest's offsets (its FOCL focal length), and clearly worse without; (2) `poseforest eval` on a
// cluttered `poseforest render` folder scores the runtime segmentation (IoU per person) and the
// mAP after segmentation next to the clean one. A tiny forest trained here (seconds).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "renderer/synthetic_source.h"
#include "runtime/camera_model.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

namespace fs = std::filesystem;
using namespace poseforest;
using testing::RunPoseforest;

namespace {

// One forest for every test case of this file: trained once, on Kinect v1 frames.
const std::string& TrainedForest() {
  static const std::string path = [] {
    const fs::path dir = testing::ScratchDir("camera-clutter-forest");
    const std::string job = (dir / "job.textproto").string(), forest = (dir / "forest.pff").string();
    std::ofstream(job) << "seed: 4 num_trees: 1 max_depth: 20 images_per_tree: 200 pixels_per_image: 1000\n"
                          "candidate_features: 150 thresholds_per_feature: 20\n"
                          "source { rendered { seed: 1 kinect_noise: false rotation_range_deg: 20 } }\n";
    auto train = RunPoseforest("train " + job + " --out " + forest + " --quiet");
    INFO(train.output);
    REQUIRE(train.exit_code == 0);
    return forest;
  }();
  return path;
}

// Fraction of body pixels whose most likely part is the true part.
double PixelAccuracy(const core::Forest& forest, renderer::SyntheticRenderer& r, uint64_t seed, int frames) {
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions opt;
  opt.num_threads = 2;
  runtime::Classification out;
  uint64_t right = 0, total = 0;
  for (int i = 0; i < frames; ++i) {
    auto f = r.Render(seed, uint64_t(i));
    REQUIRE(f.ok());
    classifier.Classify(f->depth, opt, &out);
    for (size_t p = 0; p < f->depth.pixels.size(); ++p) {
      if (f->depth.pixels[p] == 0 || f->labels.pixels[p] == core::kBackgroundLabel) continue;
      ++total;
      right += out.labels.pixels[p] == f->labels.pixels[p];
    }
  }
  REQUIRE(total > 1000);
  return double(right) / double(total);
}

// The number after the last (first) `key` in `text`, or -1.
double NumberAfter(const std::string& text, const std::string& key) {
  const size_t at = text.rfind(key);
  return at == std::string::npos ? -1.0 : std::atof(text.c_str() + at + key.size());
}
double FirstNumberAfter(const std::string& text, const std::string& key) {
  const size_t at = text.find(key);
  return at == std::string::npos ? -1.0 : std::atof(text.c_str() + at + key.size());
}

}  // namespace

TEST_CASE("frames of another focal length classify like the training camera's after rescaling",
          "[training][egl][camera]") {
  auto forest = core::LoadForest(TrainedForest());
  REQUIRE(forest.ok());
  REQUIRE(forest->training_fx == float(core::kKinectV1FocalPx));
  renderer::SceneConfig kinect;
  kinect.noise.enabled = false;
  kinect.rotation_range_deg = 20;  // as trained: a narrower problem, so a tiny forest learns it
  auto v1 = renderer::SyntheticRenderer::Create(kinect);
  REQUIRE(v1.ok());
  const double acc_v1 = PixelAccuracy(*forest, **v1, 77, 8);
  // 640x480 at fx = fy = 365 (a wide lens; about the Kinect v2's and the Azure WFOV's class), and
  // a non-square 640x576 at fx 417, fy 452 (what the Azure NFOV's documented field of view gives:
  // both axes rescaled, by different ratios). The Azure NFOV preset itself (504 px, from factory
  // calibrations) is too near the training camera's 575.8 for the 5-point margin below: it is
  // checked in "the renderer takes a camera model" (test_render_clutter).
  for (const std::string name : {"fx365", "nonsquare"}) {
    renderer::SceneConfig other = kinect;
    if (name == "fx365") {
      other.camera.fx = other.camera.fy = 365.0;
    } else {
      other.camera.width = 640;
      other.camera.height = 576;
      other.camera.fx = 417.0;
      other.camera.fy = 452.1;
      other.camera.cx = 319.5;
      other.camera.cy = 287.5;
    }
    auto r = renderer::SyntheticRenderer::Create(other);
    REQUIRE(r.ok());
    const core::Forest rescaled = runtime::ForestForFocalLength(*forest, other.camera.fx, other.camera.fy);
    const double acc_rescaled = PixelAccuracy(rescaled, **r, 77, 8);
    const double acc_plain = PixelAccuracy(*forest, **r, 77, 8);
    INFO(name << ": per-pixel accuracy Kinect v1 " << acc_v1 << ", rescaled " << acc_rescaled
              << ", not rescaled " << acc_plain);
    std::printf("%s: per-pixel accuracy kinect-v1 frames %.3f; %s frames rescaled %.3f, not rescaled %.3f\n",
                name.c_str(), acc_v1, name.c_str(), acc_rescaled, acc_plain);
    CHECK(acc_v1 > 0.3);  // the forest learned something (31 parts: chance is about 0.03)
    // Within 10% (relative) of the training camera's accuracy (measured: 5%) ...
    CHECK(acc_rescaled > 0.9 * acc_v1);
    // ... and clearly better than the same forest without rescaling: at least 5 points, and at
    // least 3/4 of what the other focal length costs is won back.
    CHECK(acc_rescaled > acc_plain + 0.05);
    CHECK(acc_rescaled - acc_plain > 0.75 * (acc_v1 - acc_plain));
  }
}

TEST_CASE("eval on a cluttered render folder reports segmentation IoU and mAP clean vs segmented",
          "[training][egl][clutter][cli]") {
  const std::string forest = TrainedForest();
  const fs::path dir = testing::ScratchDir("eval-clutter");
  const fs::path set = dir / "set";
  auto render =
      RunPoseforest("render --out " + set.string() +
                    " --count 6 --seed 9 --people 2 --clutter floor,walls,boxes --occluders 1 --fx 500");
  INFO(render.output);
  REQUIRE(render.exit_code == 0);
  auto eval = RunPoseforest("eval --forest " + forest + " --test-set " + set.string() +
                            " --per-person --method meanshift --threads 2");
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(eval.output,
             Catch::Contains("camera fx 500.0 fy 500.0: the forest (trained for fx 575.8 fy 575.8) "
                             "had its offsets rescaled") &&
                 Catch::Contains("frame 0 person 1: ") && Catch::Contains("clean (ground-truth masks):") &&
                 Catch::Contains("after segmentation:"));
  const double iou = NumberAfter(eval.output, "segmentation mean IoU ");
  const double clean = NumberAfter(eval.output, "mAP clean "),
               segmented = NumberAfter(eval.output, "after segmentation ");
  CHECK(iou > 0.6);
  CHECK(iou <= 1.0);
  CHECK(clean > 0.0);
  CHECK(segmented > 0.0);
  CHECK(segmented <= 1.0);
  // The clean frames (the truth's masks) classify better than the frames as they are, clutter and all.
  const size_t as_is = eval.output.find("frames as they are"),
               masked = eval.output.find("clean (ground-truth");
  REQUIRE(as_is != std::string::npos);
  REQUIRE(masked != std::string::npos);
  CHECK(FirstNumberAfter(eval.output.substr(masked), "accuracy ") >
        FirstNumberAfter(eval.output.substr(as_is), "accuracy ") + 5.0);

  // eval rescales for the folder's camera by itself; --no-rescale shows what that buys.
  const fs::path wide = dir / "wide";
  REQUIRE(
      RunPoseforest("render --out " + wide.string() + " --count 4 --seed 21 --no-noise --fx 365").exit_code ==
      0);
  auto scaled = RunPoseforest("eval --forest " + forest + " --test-set " + wide.string() + " --method none");
  auto unscaled = RunPoseforest("eval --forest " + forest + " --test-set " + wide.string() +
                                " --method none --no-rescale");
  REQUIRE(scaled.exit_code == 0);
  REQUIRE(unscaled.exit_code == 0);
  CHECK_THAT(scaled.output, Catch::Contains("had its offsets rescaled"));
  CHECK_THAT(unscaled.output, Catch::Contains("was NOT rescaled (--no-rescale)"));
  // Pixel accuracy (measured 18.5% vs 13.3%: this forest knows only +-20 deg of rotation, the
  // render has +-120).
  const double acc_scaled = NumberAfter(scaled.output, "(pixel accuracy "),
               acc_unscaled = NumberAfter(unscaled.output, "(pixel accuracy ");
  INFO(scaled.output);
  CHECK(acc_scaled > 1.2 * acc_unscaled);

  // tune-joints on that folder classifies with the rescaled forest and proposes joints through
  // its camera (with the Kinect v1's, every proposal missed: mAP 0.001 on the main job's forest).
  auto tune = RunPoseforest("tune-joints --forest " + forest + " --validation " + wide.string() +
                            " --frames 4 --out " + (dir / "tuned.pff").string() + " --quiet");
  INFO(tune.output);
  REQUIRE(tune.exit_code == 0);
  const size_t ms_line = tune.output.find("validation mAP (mean shift): ");
  REQUIRE(ms_line != std::string::npos);
  const double tune_before = std::atof(tune.output.c_str() + ms_line + 29);
  std::printf("tune-joints on fx 365 frames: validation mAP (mean shift) %.3f before tuning\n", tune_before);
  CHECK(tune_before > 0.05);

  // --segment off: no segmentation; --segment on needs masks.
  auto off = RunPoseforest("eval --forest " + forest + " --test-set " + set.string() +
                           " --method none --segment off --images 1");
  CHECK(off.exit_code == 0);
  CHECK_THAT(off.output, !Catch::Contains("segmentation:"));
  const fs::path plain = dir / "plain";
  REQUIRE(RunPoseforest("render --out " + plain.string() + " --count 1").exit_code == 0);
  auto on = RunPoseforest("eval --forest " + forest + " --test-set " + plain.string() + " --segment on");
  CHECK(on.exit_code == 2);
  CHECK_THAT(on.output, Catch::Contains("has no ground-truth person masks"));
  auto bad = RunPoseforest("eval --forest " + forest + " --test-set " + set.string() + " --segment maybe");
  CHECK(bad.exit_code == 2);
  // A mask or label file of another PNG type is refused from its header, naming the file and
  // what it is, before anything is decoded (runtime::DecodeLabelPng).
  for (const char* stem : {"mask", "labels"}) {
    const fs::path hostile = dir / (std::string("hostile-") + stem);
    fs::copy(set, hostile, fs::copy_options::recursive);
    const fs::path file = hostile / (std::string(stem) + "_000000.png");
    const auto rgb = runtime::EncodePng8(640, 480, 3, std::vector<uint8_t>(size_t(640) * 480 * 3, 1));
    std::ofstream(file, std::ios::binary)
        .write(reinterpret_cast<const char*>(rgb.data()), std::streamsize(rgb.size()));
    auto refused =
        RunPoseforest("eval --forest " + forest + " --test-set " + hostile.string() + " --images 1");
    INFO(refused.output);
    CHECK(refused.exit_code != 0);
    CHECK_THAT(refused.output,
               Catch::Contains(file.string() + ": a label image must be an 8-bit greyscale PNG of "
                                               "raw values; this one has 3 channel(s) of 8-bit samples"));
  }
  {  // A mask of another size than its depth image.
    const fs::path small = dir / "small-mask";
    fs::copy(set, small, fs::copy_options::recursive);
    const auto grey = runtime::EncodePng8(320, 240, 1, std::vector<uint8_t>(size_t(320) * 240, 0));
    std::ofstream(small / "mask_000000.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(grey.data()), std::streamsize(grey.size()));
    auto refused = RunPoseforest("eval --forest " + forest + " --test-set " + small.string() + " --images 1");
    INFO(refused.output);
    CHECK(refused.exit_code != 0);
    CHECK_THAT(refused.output,
               Catch::Contains("mask_000000.png: a person mask must have its depth image's size; "
                               "it is 320x240, the depth 640x480"));
  }
  // A broken camera.txt is refused naming the file.
  std::ofstream(set / "camera.txt") << "kinect 640 x480\n";
  auto broken = RunPoseforest("eval --forest " + forest + " --test-set " + set.string());
  CHECK(broken.exit_code != 0);
  CHECK_THAT(broken.output, Catch::Contains("camera.txt: expected"));
}
