// Training on rendered frames whose poses come from a mocap pose library (and MakeHuman bodies):
// a tiny job read from a file (library path relative to the job file), trained and evaluated on
// frames rendered from the library's test clips.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "engine/evaluation.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "renderer/assets/pose_library.h"
#include "runtime/core/forest_format.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using namespace poseforest;

namespace {

/// Four bandai clips, 60 frames each, thinned at 2 cm. `split_seed` (when given) receives the
/// first seed whose split at test fraction 0.5 puts clips on both sides.
fs::path WriteLibrary(const fs::path& dir, uint64_t* split_seed = nullptr) {
  std::vector<fs::path> files;
  for (const char* f :
       {"bandai_namco_2/dataset-2_raise-up-both-hands_normal_001.bvh",
        "bandai_namco_1/dataset-1_bow_normal_001.bvh", "bandai_namco_1/dataset-1_dash_normal_001.bvh",
        "bandai_namco_1/dataset-1_bye_normal_001.bvh"})
    files.push_back(testing::DataDir() / "mocap" / f);
  renderer::assets::BuildOptions o;
  o.min_distance_m = 0.02;
  o.max_frames_per_clip = 60;
  auto lib = renderer::assets::BuildPoseLibrary(files, o);
  REQUIRE(lib.ok());
  if (split_seed) {
    bool found = false;
    for (uint64_t seed = 0; seed < 64 && !found; ++seed) {
      int test = 0;
      for (const auto& c : lib->clips) test += renderer::assets::IsTestClip(c, 0.5, seed);
      if (test > 0 && test < int(lib->clips.size())) *split_seed = seed, found = true;
    }
    REQUIRE(found);
  }
  const fs::path path = dir / "poses" / "small.pfposes";
  fs::create_directories(path.parent_path());
  REQUIRE(renderer::assets::SavePoseLibrary(*lib, path).ok());
  return path;
}

}  // namespace

TEST_CASE("a tiny job with a mocap pose library trains and evaluates on its test clips",
          "[training][mocap][egl][data]") {
  const fs::path dir = testing::ScratchDir("mocap-train");
  uint64_t split = 0;
  WriteLibrary(dir, &split);
  const fs::path job = dir / "job.textproto";
  const std::string seed = " split_seed: " + std::to_string(split);
  std::ofstream(job)
      << "seed: 5 num_trees: 1 max_depth: 6 images_per_tree: 4 pixels_per_image: 300\n"
         "candidate_features: 40 thresholds_per_feature: 8 threads: 2\n"
         "source { rendered { seed: 3 pose_library: \"poses/small.pfposes\" clips: CLIP_SET_TRAIN\n"
         "                    test_fraction: 0.5 kinect_noise: false"
      << seed
      << " } }\n"
         "test_set { source { rendered { seed: 4 pose_library: \"poses/small.pfposes\"\n"
         "                    clips: CLIP_SET_TEST test_fraction: 0.5"
      << seed << " } } num_images: 2 }\n";
  auto params = engine::LoadJob(job.string());
  REQUIRE(params.ok());
  CHECK(params->source.pose_library == (dir / "poses" / "small.pfposes").string());

  // The source describes itself with its clips; both clip sets are non-empty.
  auto train_source = engine::MakeImageSource(params->source);
  REQUIRE(train_source.ok());
  CHECK_THAT((*train_source)->Describe(), Catch::Contains("train clips of"));
  auto test_source = engine::MakeImageSource(params->test_source);
  REQUIRE(test_source.ok());

  engine::LocalTrainer trainer(*params, {});
  auto forest = trainer.Train();
  REQUIRE(forest.ok());
  REQUIRE(forest->trees.size() == 1);
  CHECK(trainer.stats().samples > 0);
  engine::EvalOptions eo;
  eo.num_images = params->test_images;
  eo.threads = 2;
  auto m = engine::EvaluateForest(*forest, params->test_source, eo);
  REQUIRE(m.ok());
  uint64_t pixels = 0;
  for (int c = 0; c < m->num_parts; ++c) pixels += m->TruthTotal(c);
  CHECK(pixels > 100);

  // Same job, same forest (the shared library cache does not change frames).
  engine::LocalTrainer again(*params, {});
  auto forest2 = again.Train();
  REQUIRE(forest2.ok());
  CHECK(core::SerializeForest(*forest2) == core::SerializeForest(*forest));
  fs::remove_all(dir);
}

TEST_CASE("a rendered source with an empty clip selection fails naming the library",
          "[training][mocap][data]") {
  const fs::path dir = testing::ScratchDir("mocap-train-empty");
  const fs::path lib = WriteLibrary(dir);
  engine::SourceSpec spec;
  spec.kind = engine::SourceKind::kRendered;
  spec.pose_library = lib.string();
  spec.clips = engine::ClipSet::kTest;
  spec.test_fraction = 0;  // no test clips at all
  auto src = engine::MakeImageSource(spec);
  REQUIRE_FALSE(src.ok());
  CHECK_THAT(src.status().message(), Catch::Contains(lib.string()) && Catch::Contains("test clips"));
  fs::remove_all(dir);
}

TEST_CASE("a rendered source with MakeHuman bodies and library poses gives labelled frames",
          "[training][mocap][egl][data]") {
  const fs::path dir = testing::ScratchDir("mocap-train-mh");
  engine::SourceSpec spec;
  spec.kind = engine::SourceKind::kRendered;
  spec.seed = 6;
  spec.kinect_noise = false;
  spec.pose_library = WriteLibrary(dir).string();
  spec.makehuman_kit = (testing::DataDir() / "meshes" / "makehuman_hm08_kit").string();
  spec.procedural_bodies = false;
  auto a = engine::MakeImageSource(spec);
  REQUIRE(a.ok());
  CHECK_THAT((*a)->Describe(), Catch::Contains("MakeHuman"));
  auto b = engine::MakeImageSource(spec);  // second source: bodies and poses from the cache
  REQUIRE(b.ok());
  for (uint64_t i = 0; i < 2; ++i) {
    auto fa = (*a)->Frame(i);
    auto fb = (*b)->Frame(i);
    REQUIRE(fa.ok());
    REQUIRE(fb.ok());
    CHECK(fa->depth.pixels == fb->depth.pixels);
    CHECK(fa->labels.pixels == fb->labels.pixels);
    CHECK(core::CountForeground(fa->depth) > 500);
  }
  fs::remove_all(dir);
}
