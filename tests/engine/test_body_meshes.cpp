// Rigged meshes as the bodies of a rendered job (RenderedSource.body_meshes): the frames really
// show them, training is byte-identical whatever the threads and shards, and the job's test set
// renders the same bodies for evaluation.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "engine/evaluation.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/forest_format.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using namespace poseforest;

namespace {

size_t Foreground(const core::LabelImage& labels) {
  size_t n = 0;
  for (uint8_t l : labels.pixels) n += l != core::kBackgroundLabel;
  return n;
}

core::Forest TrainWith(engine::TrainParams params, int threads, int shards) {
  params.threads = threads;
  engine::LocalTrainerOptions opt;
  opt.num_shards = shards;
  engine::LocalTrainer trainer(params, opt);
  auto forest = trainer.Train();
  REQUIRE(forest.ok());
  return std::move(forest).value();
}

}  // namespace

TEST_CASE("a job whose only bodies are rigged meshes renders them, trains and evaluates",
          "[training][mesh][egl][data]") {
  const fs::path dir = testing::ScratchDir("mesh-bodies");
  fs::create_directory_symlink(testing::DataDir() / "meshes", dir / "meshes");  // never copied
  const fs::path job = dir / "job.textproto";
  std::ofstream(job)
      << "seed: 5 num_trees: 1 max_depth: 5 images_per_tree: 3 pixels_per_image: 200\n"
         "candidate_features: 20 thresholds_per_feature: 6\n"
         "source { rendered { seed: 3 kinect_noise: false procedural_bodies: false\n"
         "                    body_meshes: \"meshes/cesium_man/CesiumMan.glb\" } }\n"
         "test_set { source { rendered { seed: 4 kinect_noise: false procedural_bodies: false\n"
         "                    body_meshes: \"meshes/cesium_man/CesiumMan.glb\" } } num_images: 2 }\n";
  auto params = engine::LoadJob(job.string());
  REQUIRE(params.ok());
  REQUIRE(params->source.body_meshes.size() == 1);

  // The frames show the mesh: they differ from the same job's frames with procedural bodies.
  auto meshes = engine::MakeImageSource(params->source);
  REQUIRE(meshes.ok());
  CHECK_THAT((*meshes)->Describe(), Catch::EndsWith("bodies: mesh CesiumMan.glb"));
  engine::SourceSpec procedural = params->source;
  procedural.body_meshes.clear();
  procedural.procedural_bodies = true;
  auto plain = engine::MakeImageSource(procedural);
  REQUIRE(plain.ok());
  int differ = 0;
  for (uint64_t i = 0; i < 3; ++i) {
    auto a = (*meshes)->Frame(i);
    auto b = (*plain)->Frame(i);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(Foreground(a->labels) > 500);
    differ += a->depth.pixels != b->depth.pixels;
  }
  CHECK(differ == 3);

  // Byte-identical forests with 1 thread and 1 shard or 2 threads and 2 shards.
  const core::Forest one = TrainWith(*params, 1, 1);
  const core::Forest two = TrainWith(*params, 2, 2);
  REQUIRE(one.trees.size() == 1);
  CHECK(one.total_nodes() > 3);
  CHECK(core::SerializeForest(one) == core::SerializeForest(two));

  // Evaluation (eval, tune-joints) renders the job's test set with the same bodies as training would.
  auto eval = engine::MakeEvalFrameSource(params->test_source);
  REQUIRE(eval.ok());
  CHECK_THAT((*eval)->Describe(), Catch::Contains("bodies: mesh CesiumMan.glb"));
  auto train_view = engine::MakeImageSource(params->test_source);
  REQUIRE(train_view.ok());
  auto e = (*eval)->Frame(1);
  auto t = (*train_view)->Frame(1);
  REQUIRE(e.ok());
  REQUIRE(t.ok());
  CHECK(e->depth.pixels == t->depth.pixels);
  CHECK(e->labels.pixels == t->labels.pixels);
  CHECK(e->people.size() == 1);
  engine::EvalOptions eo;
  eo.num_images = params->test_images;
  eo.threads = 2;
  auto m = engine::EvaluateForest(one, params->test_source, eo);
  REQUIRE(m.ok());
  uint64_t pixels = 0;
  for (int c = 0; c < m->num_parts; ++c) pixels += m->TruthTotal(c);
  CHECK(pixels > 500);
  fs::remove_all(dir);
}

TEST_CASE("the job's order of body_meshes is the scene's order of bodies", "[training][mesh][egl][data]") {
  const fs::path meshes = testing::DataDir() / "meshes";
  const std::string cesium = (meshes / "cesium_man" / "CesiumMan.glb").string(),
                    female = (meshes / "quaternius_casual_female" / "Casual_Female.gltf").string();
  auto params = [&](const std::string& first, const std::string& second) {
    auto config = engine::ParseJobText(
        "images_per_tree: 4 source { rendered { seed: 8 kinect_noise: false "
        "procedural_bodies: false body_meshes: \"" +
            first + "\" body_meshes: \"" + second + "\" } }",
        "job.textproto");
    REQUIRE(config.ok());
    auto p = engine::ParamsFromConfig(*config, "job.textproto");
    REQUIRE(p.ok());
    return *p;
  };
  const engine::TrainParams ab = params(cesium, female), ba = params(female, cesium);
  REQUIRE(ab.source.body_meshes == std::vector<std::string>{cesium, female});
  auto a1 = engine::MakeImageSource(ab.source);
  auto a2 = engine::MakeImageSource(ab.source);
  auto b = engine::MakeImageSource(ba.source);
  REQUIRE(a1.ok());
  REQUIRE(a2.ok());
  REQUIRE(b.ok());
  CHECK_THAT((*a1)->Describe(), Catch::EndsWith("bodies: mesh CesiumMan.glb + mesh Casual_Female.gltf"));
  int differ = 0;
  for (uint64_t i = 0; i < 4; ++i) {
    auto x = (*a1)->Frame(i), y = (*a2)->Frame(i), z = (*b)->Frame(i);
    REQUIRE(x.ok());
    REQUIRE(y.ok());
    REQUIRE(z.ok());
    CHECK(x->labels.pixels == y->labels.pixels);  // a pure function of (job, seed, index)
    CHECK(x->depth.pixels == y->depth.pixels);
    differ += x->depth.pixels != z->depth.pixels;
  }
  CHECK(differ > 0);  // the same draws pick the other mesh
}
