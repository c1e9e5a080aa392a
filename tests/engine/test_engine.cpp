// The single-process engine end to end: determinism across threads and shards, a separable
// problem learned perfectly, and a trained forest that loads and classifies.
#include <catch2/catch.hpp>

#include "engine/evaluation.h"
#include "engine/local_trainer.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"

using namespace poseforest;

namespace {

engine::TrainParams ProceduralParams() {
  engine::TrainParams p;
  p.seed = 2026;
  p.num_trees = 2;
  p.max_depth = 10;
  p.images_per_tree = 8;
  p.pixels_per_image = 400;
  p.candidate_features = 80;
  p.thresholds_per_feature = 16;
  p.max_probe_offset_pixel_m = 80;
  p.min_samples_split = 4;
  p.threshold_reference_pixels = 120;
  p.source.kind = engine::SourceKind::kProcedural;
  p.source.seed = 77;
  p.source.width = 160;
  p.source.height = 120;
  return p;
}

std::vector<uint8_t> TrainBytes(engine::TrainParams p, int threads, int shards) {
  p.threads = threads;
  engine::LocalTrainerOptions o;
  o.num_shards = shards;
  engine::LocalTrainer trainer(p, o);
  auto forest = trainer.Train();
  REQUIRE(forest.ok());
  return core::SerializeForest(*forest);
}

}  // namespace

TEST_CASE("the forest is byte-identical across thread counts and shard counts", "[training][determinism]") {
  const engine::TrainParams p = ProceduralParams();
  const std::vector<uint8_t> one = TrainBytes(p, 1, 1);
  CHECK(TrainBytes(p, 2, 1) == one);
  CHECK(TrainBytes(p, 1, 3) == one);
  CHECK(TrainBytes(p, 2, 3) == one);
  // Batching the frontier by histogram memory (here: one node per batch) changes nothing.
  engine::TrainParams small_batches = p;
  small_batches.histogram_memory_bytes = 1;
  CHECK(TrainBytes(small_batches, 2, 2) == one);
  // A different job seed gives a different forest (the check above is not vacuous).
  engine::TrainParams q = p;
  q.seed = p.seed + 1;
  CHECK(TrainBytes(q, 2, 1) != one);
}

TEST_CASE("a trained forest loads and classifies far better than chance", "[training][engine]") {
  engine::TrainParams p = ProceduralParams();
  p.threads = 2;
  std::vector<engine::LevelProgress> levels;
  engine::LocalTrainerOptions o;
  o.progress = [&](const engine::LevelProgress& lp) { levels.push_back(lp); };
  engine::LocalTrainer trainer(p, o);
  auto forest = trainer.Train();
  REQUIRE(forest.ok());
  REQUIRE(forest->trees.size() == 2);
  CHECK(forest->max_depth() <= 10);
  CHECK(forest->max_depth() >= 5);
  // Progress: one report per level per tree, root first with every sample.
  REQUIRE(!levels.empty());
  CHECK(levels[0].level == 0);
  CHECK(levels[0].frontier_nodes == 1);
  CHECK(levels[0].samples == trainer.stats().samples / 2);
  CHECK(trainer.stats().evaluations > 0);
  CHECK(trainer.stats().peak_sample_bytes > 0);

  const auto dir = testing::ScratchDir("engine");
  const std::string path = (dir / "forest.pff").string();
  REQUIRE(core::SaveForest(*forest, path).ok());
  auto loaded = core::LoadForest(path);
  REQUIRE(loaded.ok());
  CHECK(core::SerializeForest(*loaded) == core::SerializeForest(*forest));

  // Training frames (every body pixel, not only the sampled ones) and held-out frames.
  engine::EvalOptions eo;
  eo.num_images = p.images_per_tree;
  eo.threads = 2;
  auto train = engine::EvaluateForest(*loaded, p.source, eo);
  REQUIRE(train.ok());
  eo.first_index = 1000;
  auto held_out = engine::EvaluateForest(*loaded, p.source, eo);
  REQUIRE(held_out.ok());
  const double chance = 1.0 / 31.0;
  INFO("train " << train->AveragePerClassAccuracy() << " held-out " << held_out->AveragePerClassAccuracy());
  CHECK(train->PartsPresent() == 31);
  CHECK(train->AveragePerClassAccuracy() > 10 * chance);
  CHECK(held_out->AveragePerClassAccuracy() > 5 * chance);
}

TEST_CASE("a tiny separable problem is learned perfectly", "[training][engine]") {
  // Frames: a vertical bar 8 pixels wide at 2 m on background; its left half is one part, its
  // right half another. A probe a few pixels to the side tells them apart.
  const auto dir = testing::ScratchDir("separable");
  for (int i = 0; i < 6; ++i) {
    core::DepthImage depth(48, 32, 0);
    core::LabelImage labels(48, 32, core::kBackgroundLabel);
    const int x0 = 10 + 3 * i;
    for (int y = 0; y < 32; ++y)
      for (int x = x0; x < x0 + 8; ++x) {
        depth.at(x, y) = 2000;
        labels.at(x, y) = x < x0 + 4 ? uint8_t(core::Part::kLHand) : uint8_t(core::Part::kRHand);
      }
    char name[64];
    std::snprintf(name, sizeof(name), "depth_%06d.png", i);
    REQUIRE(runtime::WriteDepthPng((dir / name).string(), depth).ok());
    std::snprintf(name, sizeof(name), "labels_%06d.png", i);
    REQUIRE(runtime::WriteLabelPng((dir / name).string(), labels).ok());
  }
  engine::TrainParams p;
  p.seed = 5;
  p.num_trees = 1;
  p.max_depth = 8;
  p.images_per_tree = 6;
  p.pixels_per_image = 1000;  // every bar pixel
  p.candidate_features = 200;
  p.thresholds_per_feature = 8;
  p.max_probe_offset_pixel_m = 20;  // up to 10 pixels at 2 m
  p.min_samples_split = 2;
  p.threads = 2;
  p.source.kind = engine::SourceKind::kDataset;
  p.source.folder = dir.string();
  engine::LocalTrainer trainer(p, {});
  auto forest = trainer.Train();
  REQUIRE(forest.ok());
  CHECK(trainer.stats().samples == 6 * 8 * 32);
  engine::EvalOptions eo;
  eo.num_images = 6;
  auto m = engine::EvaluateForest(*forest, p.source, eo);
  REQUIRE(m.ok());
  CHECK(m->PartsPresent() == 2);
  CHECK(m->AveragePerClassAccuracy() == 1.0);
  // The text and picture outputs of `poseforest eval` for it.
  CHECK_THAT(engine::FormatAccuracyTable(*m), Catch::Contains("average per-class accuracy: 100.00%"));
  REQUIRE(engine::WriteConfusionPng(*m, (dir / "confusion.png").string()).ok());
  auto png = core::ReadFileBytes((dir / "confusion.png").string());
  REQUIRE(png.ok());
  auto decoded = runtime::DecodePng(*png, "confusion.png");
  REQUIRE(decoded.ok());
  CHECK(decoded->width == 31 * 16 + 1);
}

TEST_CASE("frame loading errors name the frame", "[training][engine]") {
  engine::TrainParams p = ProceduralParams();
  p.source.kind = engine::SourceKind::kDataset;
  p.source.folder = (testing::ScratchDir("no-frames") / "nothing").string();
  engine::LocalTrainer trainer(p, {});
  auto forest = trainer.Train();
  REQUIRE_FALSE(forest.ok());
  CHECK_THAT(forest.status().message(), Catch::Contains("nothing"));
}
