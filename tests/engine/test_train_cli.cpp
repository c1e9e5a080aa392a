// `poseforest train` and `poseforest eval` end to end, as a user runs them.

#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "runtime/core/forest_format.h"
#include "tests/support/dds_domain.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"

using namespace poseforest;

using testing::RunPoseforest;

TEST_CASE("train a forest from a job file, then evaluate it", "[cli][training]") {
  const auto dir = testing::ScratchDir("cli-train");
  const std::string job = (dir / "job.textproto").string(), forest = (dir / "forest.pff").string();
  std::ofstream(job)
      << "seed: 3 num_trees: 1 max_depth: 8 images_per_tree: 6 pixels_per_image: 300\n"
         "candidate_features: 60 thresholds_per_feature: 10 threads: 2\n"
         "source { procedural { seed: 5 width: 160 height: 120 } }\n"
         "test_set { source { procedural { seed: 6 width: 160 height: 120 } } num_images: 3 }\n";
  auto train = RunPoseforest("train " + job + " --out " + forest + " --shards 2");
  INFO(train.output);
  REQUIRE(train.exit_code == 0);
  CHECK_THAT(train.output, Catch::Contains("tree 0 level  0:") && Catch::Contains("evaluations/s") &&
                               Catch::Contains("memory:") && Catch::Contains("average per-class accuracy"));
  auto loaded = core::LoadForest(forest);
  REQUIRE(loaded.ok());
  CHECK(loaded->trees.size() == 1);

  const std::string png = (dir / "confusion.png").string();
  auto eval = RunPoseforest("eval --forest " + forest + " --test-set " + job + " --png " + png);
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(eval.output, Catch::Contains("confusion (rows = truth") && Catch::Contains("LU_head") &&
                              Catch::Contains("average per-class accuracy:"));
  CHECK(core::ReadFileBytes(png).ok());
  auto eval_proc = RunPoseforest("eval --forest " + forest + " --test-set procedural:6 --images 2");
  CHECK(eval_proc.exit_code == 0);
}

TEST_CASE("train --local-workers 2 runs the distributed service and writes the same forest", "[cli][training]") {
  const auto dir = testing::ScratchDir("cli-train-dist");
  const std::string job = (dir / "job.textproto").string();
  const std::string single = (dir / "single.pff").string(), dist = (dir / "dist.pff").string();
  std::ofstream(job) << "seed: 4 num_trees: 2 max_depth: 7 images_per_tree: 6 pixels_per_image: 300\n"
                        "candidate_features: 40 thresholds_per_feature: 8 threads: 1\n"
                        "source { procedural { seed: 7 width: 160 height: 120 } }\n";
  auto one = RunPoseforest("train " + job + " --out " + single + " --quiet");
  INFO(one.output);
  REQUIRE(one.exit_code == 0);
  // Its own domain, held machine-wide, so parallel test runs do not meet.
  const std::string domain = std::to_string(testing::UniqueDomain(0));
  auto two = RunPoseforest("train " + job + " --out " + dist + " --local-workers 2 --domain " + domain);
  INFO(two.output);
  REQUIRE(two.exit_code == 0);
  CHECK_THAT(two.output, Catch::Contains("wrote " + dist) && Catch::Contains("0 messages rejected"));
  auto a = core::ReadFileBytes(single), b = core::ReadFileBytes(dist);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  CHECK(*a == *b);
}

TEST_CASE("a job at the Kinect v2's own size trains for its focal length, the same through the service",
          "[cli][training][egl]") {
  const auto dir = testing::ScratchDir("cli-train-sensor-camera");
  const std::string job = (dir / "job.textproto").string();
  const std::string single = (dir / "single.pff").string(), dist = (dir / "dist.pff").string();
  std::ofstream(job) << "seed: 5 num_trees: 2 max_depth: 6 images_per_tree: 4 pixels_per_image: 300\n"
                        "candidate_features: 30 thresholds_per_feature: 6 threads: 1\n"
                        "source { rendered { seed: 2 sensor: DEPTH_SENSOR_KINECT_V2 sensor_camera: true } }\n"
                        "test_set { source { rendered { seed: 9 sensor: DEPTH_SENSOR_KINECT_V2 sensor_camera: true } }"
                        " num_images: 2 }\n";
  auto one = RunPoseforest("train " + job + " --out " + single + " --quiet");
  INFO(one.output);
  REQUIRE(one.exit_code == 0);
  auto forest = core::LoadForest(single);
  REQUIRE(forest.ok());
  CHECK(forest->training_fx == 365.5f);
  CHECK(forest->training_fy == 365.5f);
  const std::string domain = std::to_string(testing::UniqueDomain(1));
  const std::string checkpoint = (dir / "checkpoint").string(), exported = (dir / "exported.pff").string();
  auto two = RunPoseforest("train " + job + " --out " + dist + " --local-workers 2 --domain " + domain +
                           " --checkpoint " + checkpoint);
  INFO(two.output);
  REQUIRE(two.exit_code == 0);
  auto a = core::ReadFileBytes(single), b = core::ReadFileBytes(dist);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  CHECK(*a == *b);
  // The checkpoint records the focal length: the export writes the same file.
  auto exp = RunPoseforest("export --checkpoint " + checkpoint + " --out " + exported);
  INFO(exp.output);
  REQUIRE(exp.exit_code == 0);
  auto c = core::ReadFileBytes(exported);
  REQUIRE(c.ok());
  CHECK(*c == *a);
  // Its test renders are the Kinect v2's too: eval needs no rescaling.
  auto eval = RunPoseforest("eval --forest " + single + " --test-set " + job + " --images 2");
  INFO(eval.output);
  REQUIRE(eval.exit_code == 0);
  CHECK_THAT(eval.output, !Catch::Contains("rescal"));
}

TEST_CASE("--resume from a corrupt checkpoint is an error naming the file, not a crash", "[cli][training]") {
  const auto dir = testing::ScratchDir("cli-resume-bad");
  const std::string job = (dir / "job.textproto").string(), out = (dir / "forest.pff").string();
  const std::string ckpt_dir = (dir / "ckpt").string(), ckpt = (dir / "ckpt" / "checkpoint.pb").string();
  std::ofstream(job) << "seed: 4 num_trees: 2 max_depth: 6 images_per_tree: 4 pixels_per_image: 200\n"
                        "candidate_features: 30 thresholds_per_feature: 6 threads: 1\n"
                        "source { procedural { seed: 7 width: 160 height: 120 } }\n";
  const std::string domain = std::to_string(testing::UniqueDomain(2));
  const std::string cmd = "train " + job + " --out " + out + " --local-workers 1 --domain " + domain +
                          " --checkpoint " + ckpt_dir + " --resume";
  // A real checkpoint of the finished job first.
  auto ok = RunPoseforest(cmd);
  INFO(ok.output);
  REQUIRE(ok.exit_code == 0);
  auto bytes = core::ReadFileBytes(ckpt);
  REQUIRE(bytes.ok());
  REQUIRE(bytes->size() > 64);
  std::filesystem::remove(out);
  // Truncated to half, then garbage: each refused before any replay, naming the file.
  const std::vector<uint8_t> half(bytes->begin(), bytes->begin() + std::ptrdiff_t(bytes->size() / 2));
  const std::vector<uint8_t> garbage(300, 0xA7);
  for (const auto* content : {&half, &garbage}) {
    std::ofstream(ckpt, std::ios::binary | std::ios::trunc)
        .write(reinterpret_cast<const char*>(content->data()), std::streamsize(content->size()));
    auto bad = RunPoseforest(cmd);
    INFO(bad.output);
    CHECK(bad.exit_code == 1);
    CHECK_THAT(bad.output, Catch::Contains("cannot resume") && Catch::Contains("checkpoint.pb"));
    CHECK_FALSE(std::filesystem::exists(out));
  }
}

TEST_CASE("train and eval refuse bad input with clear messages", "[cli][training]") {
  const auto dir = testing::ScratchDir("cli-train-bad");
  const std::string job = (dir / "bad.textproto").string();
  std::ofstream(job) << "images_per_tree: 5 candidate_features: 0 source { procedural { } }\n";
  auto bad = RunPoseforest("train " + job + " --out " + (dir / "f.pff").string());
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("bad.textproto") && Catch::Contains("candidate_features = 0"));
  auto no_out = RunPoseforest("train " + job);
  CHECK(no_out.exit_code == 2);
  CHECK_THAT(no_out.output, Catch::Contains("--out"));
  // An output that would destroy the job, or that cannot be written: refused before training.
  const std::string good_job = (dir / "good.textproto").string();
  const std::string job_text = "images_per_tree: 2 max_depth: 3 source { procedural { } }\n";
  std::ofstream(good_job) << job_text;
  auto over_job = RunPoseforest("train " + good_job + " --out " + good_job);
  CHECK(over_job.exit_code == 2);
  CHECK_THAT(over_job.output,
             Catch::Contains("--out " + good_job + ": the same file as the input " + good_job));
  std::ifstream kept(good_job);
  CHECK(std::string(std::istreambuf_iterator<char>(kept), {}) == job_text);
  auto no_folder = RunPoseforest("train " + good_job + " --out " + (dir / "none" / "f.pff").string());
  CHECK(no_folder.exit_code == 2);
  CHECK_THAT(no_folder.output, Catch::Contains("folder " + (dir / "none").string() + " does not exist"));
  CHECK_THAT(no_folder.output, !Catch::Contains("training tree"));
  auto help = RunPoseforest("train --help");
  CHECK(help.exit_code == 0);
  CHECK_THAT(help.output, Catch::Contains("usage: poseforest train"));
  auto eval_help = RunPoseforest("eval --help");
  CHECK(eval_help.exit_code == 0);
  CHECK_THAT(eval_help.output, Catch::Contains("average per-class accuracy"));
  auto missing = RunPoseforest("eval --forest " + (dir / "none.pff").string() + " --test-set procedural:1");
  CHECK(missing.exit_code == 1);
  CHECK_THAT(missing.output, Catch::Contains("none.pff"));
}
