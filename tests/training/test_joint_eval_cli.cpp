// `poseforest tune-joints` and `poseforest eval` (joint AP) end to end, as a user runs them, on
// a tiny forest trained on rendered frames (real EGL rendering, procedural bodies and poses).
#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

using namespace poseforest;
using testing::RunPoseforest;

namespace {

// The number after `key` in `text` (e.g. "upper bound "), or -1.
double NumberAfter(const std::string& text, const std::string& key) {
  const size_t at = text.rfind(key);
  return at == std::string::npos ? -1.0 : std::atof(text.c_str() + at + key.size());
}

}  // namespace

TEST_CASE("tune-joints stores learned parameters; eval prints joint AP, upper bound and accuracy",
          "[cli][joints]") {
  const auto dir = testing::ScratchDir("cli-joint-eval");
  const std::string job = (dir / "job.textproto").string(), forest = (dir / "forest.pff").string(),
                    tuned = (dir / "tuned.pff").string();
  std::ofstream(job) << "seed: 3 num_trees: 1 max_depth: 10 images_per_tree: 8 pixels_per_image: 400\n"
                        "candidate_features: 40 thresholds_per_feature: 10\n"
                        "source { rendered { seed: 1 } }\n"
                        "test_set { source { rendered { seed: 99 } } num_images: 3 }\n";
  auto train = RunPoseforest("train " + job + " --out " + forest + " --quiet");
  INFO(train.output);
  REQUIRE(train.exit_code == 0);

  auto tune = RunPoseforest("tune-joints --forest " + forest + " --validation " + job + " --out " + tuned +
                            " --frames 3");
  INFO(tune.output);
  REQUIRE(tune.exit_code == 0);
  CHECK_THAT(tune.output, Catch::Contains("train clips, frames not trained on") &&
                              Catch::Contains("AP before") && Catch::Contains("mean: b =") &&
                              Catch::Contains("wrote " + tuned));
  auto before = core::LoadForest(forest);
  auto after = core::LoadForest(tuned);
  REQUIRE(before.ok());
  REQUIRE(after.ok());
  CHECK_FALSE(before->proposal_params.has_value());
  REQUIRE(after->proposal_params.has_value());
  CHECK(after->total_nodes() == before->total_nodes());  // the trees are untouched
  CHECK(*after->proposal_params !=
        core::DefaultProposalParams());  // the grid holds none of the means' triples

  auto inspect = RunPoseforest("inspect --joints " + tuned);
  CHECK(inspect.exit_code == 0);
  CHECK_THAT(inspect.output, Catch::Contains("learned parameters (JPAR)") && Catch::Contains("joint head"));

  const auto pr = dir / "pr";
  auto eval =
      RunPoseforest("eval --forest " + tuned + " --test-set " + job + " --images 3 --pr-png " + pr.string());
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(eval.output,
             Catch::Contains("AP gt-parts") && Catch::Contains("learned (stored in the forest)") &&
                 Catch::Contains("L_shoulder") && Catch::Contains("mAP: mean shift") &&
                 Catch::Contains("average per-class accuracy:") && Catch::Contains("3 frames, 3 people"));
  // The ground-truth parts locate visible joints well even on three frames.
  CHECK(NumberAfter(eval.output, "upper bound ") > 0.6);
  for (const char* name : {"pr_joints.png", "pr_mean.png"}) {
    auto bytes = core::ReadFileBytes((pr / name).string());
    REQUIRE(bytes.ok());
    auto png = runtime::DecodePng(*bytes, name);
    REQUIRE(png.ok());
    CHECK(png->width > 500);
  }

  // Two people per frame: proposals are counted against each person's joints.
  auto two = RunPoseforest("eval --forest " + tuned + " --test-set " + job +
                           " --images 2 --people 2 --quiet --method meanshift");
  INFO(two.output);
  REQUIRE(two.exit_code == 0);
  CHECK_THAT(two.output, Catch::Contains("2 frames, 4 people"));
  // The fast clustering did not run: no figures for it, not zeros.
  CHECK_THAT(two.output, !Catch::Contains("fast clustering") && Catch::Contains("mAP: mean shift"));

  // infer uses the stored parameters.
  REQUIRE(RunPoseforest("render --out " + (dir / "frames").string() + " --count 1 --seed 5").exit_code == 0);
  auto infer = RunPoseforest("infer --forest " + tuned + " --joints --out-dir " + (dir / "infer").string() +
                             " " + (dir / "frames" / "depth_000000.png").string());
  INFO(infer.output);
  CHECK(infer.exit_code == 0);
  CHECK_THAT(infer.output, Catch::Contains("the forest's learned parameters"));
  // ... and they change the proposals: the untuned forest (same trees) proposes otherwise.
  auto plain = RunPoseforest("infer --forest " + forest + " --joints --quiet --out-dir " +
                             (dir / "plain").string() + " " + (dir / "frames" / "depth_000000.png").string());
  REQUIRE(plain.exit_code == 0);
  auto tuned_json = core::ReadFileBytes((dir / "infer" / "depth_000000.joints.json").string());
  auto plain_json = core::ReadFileBytes((dir / "plain" / "depth_000000.joints.json").string());
  REQUIRE(tuned_json.ok());
  REQUIRE(plain_json.ok());
  CHECK(*tuned_json != *plain_json);

  // A rendered folder (with joints_*.json) works as a test set too.
  auto folder =
      RunPoseforest("eval --forest " + tuned + " --test-set " + (dir / "frames").string() + " --quiet");
  INFO(folder.output);
  CHECK(folder.exit_code == 0);
  CHECK_THAT(folder.output, Catch::Contains("1 frames, 1 people"));
}

TEST_CASE("tune-joints and eval refuse bad input with clear messages", "[cli][joints]") {
  const auto dir = testing::ScratchDir("cli-joint-eval-bad");
  const std::string job = (dir / "job.textproto").string(), forest = (dir / "f.pff").string();
  std::ofstream(job)
      << "seed: 3 num_trees: 1 max_depth: 4 images_per_tree: 4 pixels_per_image: 200\n"
         "candidate_features: 10 thresholds_per_feature: 5\n"
         "source { procedural { seed: 5 width: 160 height: 120 } }\n"
         "test_set { source { procedural { seed: 6 width: 160 height: 120 } } num_images: 2 }\n";
  REQUIRE(RunPoseforest("train " + job + " --out " + forest + " --quiet").exit_code == 0);

  auto no_out = RunPoseforest("tune-joints --forest " + forest + " --validation " + job);
  CHECK(no_out.exit_code == 2);
  CHECK_THAT(no_out.output, Catch::Contains("--out"));
  auto procedural =
      RunPoseforest("tune-joints --forest " + forest + " --validation procedural:3 --out x.pff");
  CHECK(procedural.exit_code == 2);
  CHECK_THAT(procedural.output, Catch::Contains("procedural frames have no joints"));
  auto no_joints = RunPoseforest("tune-joints --forest " + forest + " --validation " + job + " --out " +
                                 (dir / "t.pff").string() + " --frames 1");
  CHECK(no_joints.exit_code == 2);
  CHECK_THAT(no_joints.output, Catch::Contains("procedural frames have no joints"));
  CHECK_FALSE(core::ReadFileBytes((dir / "t.pff").string()).ok());  // nothing written
  auto missing = RunPoseforest("tune-joints --forest " + (dir / "none.pff").string() + " --validation " +
                               (dir / "nowhere").string() + " --out x.pff");
  CHECK(missing.exit_code != 0);
  CHECK_THAT(missing.output, Catch::Contains("nowhere"));
  auto bad_frames =
      RunPoseforest("tune-joints --forest " + forest + " --validation " + job + " --out x --frames 0");
  CHECK(bad_frames.exit_code == 2);
  CHECK_THAT(bad_frames.output, Catch::Contains("--frames"));
  auto bad_method =
      RunPoseforest("tune-joints --forest " + forest + " --validation " + job + " --out x --method slow");
  CHECK(bad_method.exit_code == 2);
  CHECK_THAT(bad_method.output, Catch::Contains("--method must be meanshift or fast"));
  auto help = RunPoseforest("tune-joints --help");
  CHECK(help.exit_code == 0);
  CHECK_THAT(help.output, Catch::Contains("usage: poseforest tune-joints") && Catch::Contains("--per-joint"));

  auto people = RunPoseforest("eval --forest " + forest + " --test-set procedural:3 --people 2");
  CHECK(people.exit_code == 2);
  CHECK_THAT(people.output, Catch::Contains("--people needs a rendered test set"));
  auto method = RunPoseforest("eval --forest " + forest + " --test-set procedural:3 --method bogus");
  CHECK(method.exit_code == 2);
  CHECK_THAT(method.output, Catch::Contains("--method must be"));
  // A set without joints still gives the accuracy, and says why there is no AP.
  auto accuracy = RunPoseforest("eval --forest " + forest + " --test-set " + job + " --quiet");
  CHECK(accuracy.exit_code == 0);
  CHECK_THAT(accuracy.output,
             Catch::Contains("average per-class accuracy:") && Catch::Contains("has no ground-truth joints"));
  // A folder whose joints file is corrupt: the error names the file.
  REQUIRE(RunPoseforest("render --out " + (dir / "frames").string() + " --count 1 --seed 5").exit_code == 0);
  std::ofstream((dir / "frames" / "joints_000000.json").string())
      << "{\"people\": [{\"joints\": [{\"x\": oops}]}]}";
  auto corrupt = RunPoseforest("eval --forest " + forest + " --test-set " + (dir / "frames").string());
  CHECK(corrupt.exit_code == 1);
  CHECK_THAT(corrupt.output, Catch::Contains("joints_000000.json") && Catch::Contains("not a number"));
}
