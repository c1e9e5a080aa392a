// Bodies: the job fields for sampled and clothed MakeHuman bodies
// (RenderedSource fields 21-24): defaults, validation, and a rendered source that uses them.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using namespace poseforest;

namespace {

std::string Kit() { return (testing::DataDir() / "meshes" / "makehuman_hm08_kit").string(); }

core::Result<engine::TrainParams> Params(const std::string& rendered_fields) {
  auto config =
      engine::ParseJobText("images_per_tree: 5 source { rendered { " + rendered_fields + " } }", "job.txt");
  REQUIRE(config.ok());
  return engine::ParamsFromConfig(*config, "job.txt");
}

std::string ErrorOf(const std::string& rendered_fields) {
  auto p = Params(rendered_fields);
  REQUIRE_FALSE(p.ok());
  CHECK(p.status().code() == core::ErrorCode::kInvalidArgument);
  return p.status().message();
}

}  // namespace

TEST_CASE("MakeHuman body job fields: defaults off, validation, the clothes folder", "[unit][data]") {
  const std::string kit = "makehuman_kit: \"" + Kit() + "\" ";
  auto defaults = Params(kit);
  REQUIRE(defaults.ok());
  CHECK(defaults->source.makehuman_sampled_bodies == 0);
  CHECK(defaults->source.makehuman_body_seed == 1);
  CHECK(defaults->source.makehuman_clothed_share == 0.0);
  CHECK(defaults->source.makehuman_clothes.empty());
  CHECK(engine::DescribeBodies(defaults->source) == "MakeHuman + procedural");

  // One field each turns them on; the clothes folder defaults to the kit's sibling.
  auto on = Params(kit + "makehuman_sampled_bodies: 40 makehuman_clothed_share: 0.5 makehuman_body_seed: 9");
  INFO(on.status().ToString());
  REQUIRE(on.ok());
  CHECK(on->source.makehuman_sampled_bodies == 40);
  CHECK(on->source.makehuman_body_seed == 9);
  CHECK(on->source.makehuman_clothed_share == 0.5);
  CHECK(fs::equivalent(on->source.makehuman_clothes, testing::DataDir() / "meshes" / "makehuman_clothes"));
  CHECK(engine::DescribeBodies(on->source) ==
        "MakeHuman (18 presets + 40 sampled, 0.5 clothed) + procedural");
  auto trailing = Params("makehuman_kit: \"" + Kit() + "/\" makehuman_clothed_share: 1");
  REQUIRE(trailing.ok());
  CHECK(fs::equivalent(trailing->source.makehuman_clothes, testing::DataDir() / "meshes" / "makehuman_clothes"));

  // Without a kit: a clear error naming the field and what is missing.
  for (const char* field : {"makehuman_sampled_bodies: 10", "makehuman_clothed_share: 0.3",
                            "makehuman_clothes: \"/tmp\" makehuman_clothed_share: 0.3"}) {
    const std::string e = ErrorOf(field);
    CHECK_THAT(e, Catch::Contains("job.txt: source.rendered.makehuman_") && Catch::Contains("set makehuman_kit"));
  }
  CHECK_THAT(ErrorOf(kit + "makehuman_sampled_bodies: 5000"),
             Catch::Contains("source.rendered.makehuman_sampled_bodies = 5000") && Catch::Contains("0..2000"));
  CHECK_THAT(ErrorOf(kit + "makehuman_clothed_share: 1.5"),
             Catch::Contains("source.rendered.makehuman_clothed_share = 1.5") && Catch::Contains("0..1"));
  CHECK_THAT(ErrorOf(kit + "makehuman_clothed_share: nan"), Catch::Contains("makehuman_clothed_share"));
  CHECK_THAT(ErrorOf(kit + "makehuman_clothed_share: 0.5 makehuman_clothes: \"/nonexistent/clothes\""),
             Catch::Contains("source.rendered.makehuman_clothes = \"/nonexistent/clothes\"") &&
                 Catch::Contains("no such folder"));
  CHECK_THAT(ErrorOf(kit + "makehuman_clothes: \"/tmp\""),
             Catch::Contains("makehuman_clothes") && Catch::Contains("set makehuman_clothed_share"));
  // A kit whose folder has no makehuman_clothes beside it: the default is named as such.
  const auto dir = testing::ScratchDir("mh-job");
  fs::create_directories(dir / "kit" / "rigs");
  fs::create_directories(dir / "kit" / "targets" / "macrodetails");
  for (const char* file : {"base.obj", "rigs/default.mhskel", "rigs/default_weights.mhw"})
    std::ofstream(dir / "kit" / file) << "a kit's file, not read here";
  CHECK_THAT(ErrorOf("makehuman_kit: \"" + (dir / "kit").string() + "\" makehuman_clothed_share: 0.5"),
             Catch::Contains("the default, beside makehuman_kit") && Catch::Contains("makehuman_clothes"));
  fs::remove_all(dir);

  // Relative clothes paths resolve against the job file like the kit.
  auto config = engine::ParseJobText(
      "images_per_tree: 5 source { rendered { makehuman_kit: \"k\" "
      "makehuman_clothes: \"c\" makehuman_clothed_share: 1 } }",
      "x");
  REQUIRE(config.ok());
  engine::ResolveJobPaths("/jobs/a/job.textproto", &*config);
  CHECK(config->source().rendered().makehuman_clothes() == "/jobs/a/c");
}

TEST_CASE("a rendered source with sampled, clothed MakeHuman bodies renders them deterministically",
          "[egl][data]") {
  auto p = Params("makehuman_kit: \"" + Kit() +
                  "\" procedural_bodies: false makehuman_sampled_bodies: 6 makehuman_clothed_share: 1 "
                  "kinect_noise: false seed: 4");
  INFO(p.status().ToString());
  REQUIRE(p.ok());
  auto a = engine::MakeImageSource(p->source);
  if (!a.ok()) WARN("no renderer: " << a.status().ToString());
  REQUIRE(a.ok());
  auto b = engine::MakeImageSource(p->source);  // another thread's source: the cached bodies
  REQUIRE(b.ok());
  for (uint64_t i = 0; i < 3; ++i) {
    auto fa = (*a)->Frame(i);
    auto fb = (*b)->Frame(i);
    REQUIRE(fa.ok());
    REQUIRE(fb.ok());
    CHECK(fa->depth.pixels == fb->depth.pixels);
    CHECK(fa->labels.pixels == fb->labels.pixels);
  }
}
