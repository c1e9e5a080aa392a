// `poseforest tune-joints` and `poseforest eval` (joint AP) end to end, as a user runs them, on
// a tiny forest trained on rendered frames (real EGL rendering, procedural bodies and poses).
#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "runtime/core/body_parts.h"
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

// The skeleton table's hidden joints, summed over its 16 joint rows: each row ends with the
// "hidden: in 0.15 m" cell, "FRACTION (COUNT)" or "- (0)".
int HiddenJointsInTable(const std::string& text) {
  int sum = 0, rows = 0;
  const size_t table = text.find("skeleton accuracy");
  std::istringstream in(table == std::string::npos ? std::string() : text.substr(table));
  for (std::string line; std::getline(in, line);)
    for (int j = 0; j < core::kNumJoints; ++j)
      if (line.rfind(std::string(core::JointName(j)) + " ", 0) == 0 && line.back() == ')') {
        sum += std::atoi(line.c_str() + line.rfind('(') + 1);
        ++rows;
      }
  return rows == core::kNumJoints ? sum : -1;
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
  // By default both methods are tuned, each its own set, on the same frames.
  CHECK_THAT(tune.output,
             Catch::Contains("train clips, frames not trained on") && Catch::Contains("AP before") &&
                 Catch::Contains("mean: b =") && Catch::Contains("\nmean shift:\n") &&
                 Catch::Contains("\nfast clustering:\n") &&
                 Catch::Contains("validation mAP (fast clustering)") &&
                 Catch::Contains("wrote " + tuned + " with the learned parameters (mean shift and fast"));
  auto before = core::LoadForest(forest);
  auto after = core::LoadForest(tuned);
  REQUIRE(before.ok());
  REQUIRE(after.ok());
  CHECK_FALSE(before->proposal_params.has_value());
  CHECK_FALSE(before->fast_proposal_params.has_value());
  REQUIRE(after->proposal_params.has_value());
  REQUIRE(after->fast_proposal_params.has_value());
  CHECK(after->total_nodes() == before->total_nodes());  // the trees are untouched
  // The skeleton's confidence calibration (format 1.4, JCAL) is measured on the same frames.
  CHECK_FALSE(before->confidence_calibration.has_value());
  REQUIRE(after->confidence_calibration.has_value());
  CHECK(after->confidence_calibration->method == core::ConfidenceCalibration::Method::kMeanShift);
  CHECK(after->confidence_calibration->samples > 0);
  CHECK_THAT(tune.output, Catch::Contains("confidence calibration (mean shift, ") &&
                              Catch::Contains("and the confidence calibration"));
  // The grid holds none of the means' triples.
  CHECK(*after->proposal_params != core::DefaultProposalParams());
  CHECK(*after->fast_proposal_params != core::DefaultProposalParams());

  auto inspect = RunPoseforest("inspect --joints " + tuned);
  CHECK(inspect.exit_code == 0);
  CHECK_THAT(inspect.output, Catch::Contains("mean shift: learned parameters (JPAR)") &&
                                 Catch::Contains("fast clustering: learned parameters (JPFC)") &&
                                 Catch::Contains("joint head"));

  const auto pr = dir / "pr";
  auto eval =
      RunPoseforest("eval --forest " + tuned + " --test-set " + job + " --images 3 --pr-png " + pr.string());
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(
      eval.output,
      Catch::Contains("AP gt-parts") &&
          Catch::Contains("proposal parameters, mean shift (and gt-parts): learned (stored in the forest)") &&
          Catch::Contains("proposal parameters, fast clustering: learned (stored in the forest)") &&
          Catch::Contains("L_shoulder") && Catch::Contains("mAP: mean shift") &&
          Catch::Contains("average per-class accuracy:") && Catch::Contains("3 frames, 3 people"));
  // The skeleton's own accuracy, with the forest's calibration.
  CHECK_THAT(eval.output, Catch::Contains("skeleton accuracy") && Catch::Contains("3 one-person frames") &&
                              Catch::Contains("confidence calibrated (JCAL)") &&
                              Catch::Contains("not tracked right") &&
                              Catch::Contains("mean over joints: tracked within"));
  // The hidden joints split into those outside the picture and those inside it, behind
  // something: the two counts add up to the table's hidden joints, the placed ones to at most
  // that.
  {
    const std::string pooled = "hidden joints placed within 0.15 m, pooled: outside the picture ";
    REQUIRE_THAT(eval.output, Catch::Contains(pooled));
    int outside_within = -1, outside = -1, inside_within = -1, inside = -1;
    double outside_fraction = -1, inside_fraction = -1;
    REQUIRE(std::sscanf(eval.output.c_str() + eval.output.find(pooled) + pooled.size(),
                        "%lf (%d of %d), inside it behind something %lf (%d of %d)", &outside_fraction,
                        &outside_within, &outside, &inside_fraction, &inside_within, &inside) == 6);
    CHECK(outside + inside == HiddenJointsInTable(eval.output));
    CHECK(outside + inside > 0);  // three frames of whole people still hide some joints
    CHECK(
        (outside_within >= 0 && outside_within <= outside && inside_within >= 0 && inside_within <= inside));
  }
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
  CHECK_THAT(two.output,
             Catch::Contains("0 one-person frames"));  // skeletons are scored on one-person frames only
  CHECK_THAT(two.output, Catch::Contains("no figures: the test set has no one-person frames") &&
                             !Catch::Contains("mean over joints"));  // not a table of zeros
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

  // Each method runs with its own set: a forest whose fast-clustering set is changed (mean
  // shift's kept) gives other fast proposals and the same mean-shift ones, in infer and eval.
  core::Forest planted = *after;
  for (auto& p : *planted.fast_proposal_params) p = {0.3f, 0.02f, 0.09f};
  const std::string planted_path = (dir / "planted.pff").string();
  REQUIRE(core::SaveForest(planted, planted_path).ok());
  auto json_of = [&](const std::string& f, const std::string& method, const std::string& out) {
    auto r = RunPoseforest("infer --forest " + f + " --joints --quiet --method " + method + " --out-dir " +
                           (dir / out).string() + " " + (dir / "frames" / "depth_000000.png").string());
    REQUIRE(r.exit_code == 0);
    auto bytes = core::ReadFileBytes((dir / out / "depth_000000.joints.json").string());
    REQUIRE(bytes.ok());
    return std::string(bytes->begin(), bytes->end());
  };
  CHECK(json_of(tuned, "meanshift", "t_ms") == json_of(planted_path, "meanshift", "p_ms"));
  CHECK(json_of(tuned, "fast", "t_fast") != json_of(planted_path, "fast", "p_fast"));
  auto planted_eval =
      RunPoseforest("eval --forest " + planted_path + " --test-set " + job + " --images 3 --quiet");
  REQUIRE(planted_eval.exit_code == 0);
  CHECK(NumberAfter(planted_eval.output, "mAP: mean shift ") == NumberAfter(eval.output, "mAP: mean shift "));
  CHECK_THAT(planted_eval.output,
             Catch::Contains("fast clustering: learned (stored in the forest), mean b = 0.300 m"));

  // Tuning one method keeps the other's set.
  const std::string fast_only = (dir / "fast_only.pff").string();
  auto tune_fast = RunPoseforest("tune-joints --forest " + planted_path + " --validation " + job + " --out " +
                                 fast_only + " --frames 2 --method fast --quiet");
  INFO(tune_fast.output);
  REQUIRE(tune_fast.exit_code == 0);
  CHECK_THAT(tune_fast.output, Catch::Contains("fast clustering:") && !Catch::Contains("mean shift:"));
  auto fast_tuned = core::LoadForest(fast_only);
  REQUIRE(fast_tuned.ok());
  CHECK(fast_tuned->proposal_params == planted.proposal_params);
  CHECK(fast_tuned->fast_proposal_params != planted.fast_proposal_params);

  // A format 1.1 forest (one set, written by the code before per-method sets) works as before:
  // both methods run with its set; tuning mean shift alone keeps the fast clustering's.
  const std::string old_file =
      std::string(POSEFOREST_SOURCE_DIR) + "/tests/runtime/data/forest_v1_1_jpar.pff";
  auto old_inspect = RunPoseforest("inspect " + old_file);
  CHECK(old_inspect.exit_code == 0);
  CHECK_THAT(old_inspect.output, Catch::Contains("format 1.1") &&
                                     Catch::Contains("mean shift: learned parameters (JPAR)") &&
                                     Catch::Contains("format 1.1's one set for both methods"));
  auto old_infer =
      RunPoseforest("infer --forest " + old_file + " --joints --method fast --out-dir " +
                    (dir / "old").string() + " " + (dir / "frames" / "depth_000000.png").string());
  CHECK(old_infer.exit_code == 0);
  CHECK_THAT(old_infer.output, Catch::Contains("learned mean-shift parameters (none learned for the fast"));
  const std::string old_tuned = (dir / "old_tuned.pff").string();
  auto old_tune = RunPoseforest("tune-joints --forest " + old_file + " --validation " + job + " --out " +
                                old_tuned + " --frames 2 --method meanshift --quiet");
  INFO(old_tune.output);
  REQUIRE(old_tune.exit_code == 0);
  CHECK_THAT(old_tune.output, Catch::Contains("keeps the set it ran with"));
  auto old_forest = core::LoadForest(old_file);
  auto new_forest = core::LoadForest(old_tuned);
  REQUIRE(old_forest.ok());
  REQUIRE(new_forest.ok());
  CHECK(new_forest->fast_proposal_params == old_forest->proposal_params);

  // A rendered folder (with joints_*.json) works as a test set too.
  auto folder =
      RunPoseforest("eval --forest " + tuned + " --test-set " + (dir / "frames").string() + " --quiet");
  INFO(folder.output);
  CHECK(folder.exit_code == 0);
  CHECK_THAT(folder.output, Catch::Contains("1 frames, 1 people"));
  // More frames than the folder holds, asked of eval or tune-joints: refused at once, naming the
  // count (it used to fail on the first missing file); tune-joints' default takes what there is.
  const std::string frames = (dir / "frames").string();
  for (const std::string& args : {"eval --forest " + tuned + " --test-set " + frames + " --images 5",
                                  "eval --forest " + tuned + " --test-set " + frames + " --first 1",
                                  "tune-joints --forest " + tuned + " --validation " + frames +
                                      " --frames 5 --out " + (dir / "t.pff").string()}) {
    auto more = RunPoseforest(args);
    INFO(args << "\n" << more.output);
    CHECK(more.exit_code == 2);
    CHECK_THAT(more.output, Catch::Contains(frames + " holds 1 frames"));
  }
  // A folder has no job source to choose and nothing to render: --from and --seed are refused.
  for (const char* flag : {" --from test", " --seed 5"}) {
    auto ignored = RunPoseforest("tune-joints --forest " + tuned + " --validation " + frames + flag +
                                 " --out " + (dir / "t.pff").string());
    INFO(flag << "\n" << ignored.output);
    CHECK(ignored.exit_code == 2);
    CHECK_THAT(ignored.output,
               Catch::Contains("is for a job's rendered source") && Catch::Contains("a folder of frames"));
  }
  auto all = RunPoseforest("tune-joints --forest " + tuned + " --validation " + frames +
                           " --method meanshift --out " + (dir / "t.pff").string());
  INFO(all.output);
  CHECK(all.exit_code == 0);
  CHECK_THAT(all.output, Catch::Contains("validation: 1 frames, folder " + frames));
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
  CHECK_THAT(bad_method.output, Catch::Contains("--method must be both, meanshift or fast"));
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
  CHECK_THAT(corrupt.output, Catch::Contains("joints_000000.json") && Catch::Contains("not valid JSON"));
  // Valid JSON of the wrong shape: the error names the file, the person, the joint and the key.
  std::string joints;
  for (int j = 0; j < core::kNumJoints; ++j)
    joints += std::string(j ? "," : "") + "{\"x\": 0.1, \"y\": 0.2, \"z\": " + (j == 3 ? "\"far\"" : "2") +
              ", \"visible\": true}";
  std::ofstream((dir / "frames" / "joints_000000.json").string())
      << "{\"people\": [{\"joints\": [" + joints + "]}]}";
  auto wrong = RunPoseforest("eval --forest " + forest + " --test-set " + (dir / "frames").string());
  CHECK(wrong.exit_code == 1);
  CHECK_THAT(wrong.output, Catch::Contains("joints_000000.json: person 0, joint 3") &&
                               Catch::Contains("\"z\" is not a number"));
  std::ofstream((dir / "frames" / "joints_000000.json").string()) << "{\"people\": [{\"joints\": []}]}";
  auto short_list = RunPoseforest("eval --forest " + forest + " --test-set " + (dir / "frames").string());
  CHECK(short_list.exit_code == 1);
  CHECK_THAT(short_list.output,
             Catch::Contains("person 0: 0 joints, expected " + std::to_string(core::kNumJoints)));
}
