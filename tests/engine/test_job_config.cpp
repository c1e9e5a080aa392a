// Job configs: text format parsing, defaults, and clear errors naming the field.
#include <catch2/catch.hpp>
#include <fstream>
#include <tuple>
#include <nlohmann/json.hpp>

#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "tests/support/paths.h"

using namespace poseforest;

namespace {

core::Result<engine::TrainParams> Parse(const std::string& text) {
  auto config = engine::ParseJobText(text, "job.textproto");
  if (!config.ok()) return config.status();
  return engine::ParamsFromConfig(*config, "job.textproto");
}

std::string ErrorOf(const std::string& text) {
  auto p = Parse(text);
  REQUIRE_FALSE(p.ok());
  CHECK(p.status().code() == core::ErrorCode::kInvalidArgument);
  return p.status().message();
}

}  // namespace

TEST_CASE("a minimal job gets the paper's defaults", "[training][config]") {
  auto p = Parse("images_per_tree: 10 source { procedural { seed: 4 } }");
  REQUIRE(p.ok());
  CHECK(p->num_trees == 3);
  CHECK(p->max_depth == 20);
  CHECK(p->pixels_per_image == 2000);
  CHECK(p->candidate_features == 2000);
  CHECK(p->thresholds_per_feature == 50);
  CHECK(p->max_probe_offset_pixel_m == 129.0);
  CHECK(p->max_offset_units() == 129 * 32);
  CHECK(p->source.kind == engine::SourceKind::kProcedural);
  CHECK(p->source.seed == 4);
  CHECK_FALSE(p->has_test_set);
  CHECK(p->constants.edge == core::ProbeEdge::kBackground);  // the paper's probes
}

TEST_CASE("probe_edge: the paper's rule by default or named, the edge with PROBE_EDGE_CLAMP",
          "[training][config]") {
  const std::string src = " source { procedural { seed: 4 } }";
  for (const auto& [field, edge] :
       {std::pair{"", core::ProbeEdge::kBackground},
        std::pair{"probe_edge: PROBE_EDGE_BACKGROUND", core::ProbeEdge::kBackground},
        std::pair{"probe_edge: PROBE_EDGE_CLAMP", core::ProbeEdge::kClamp}}) {
    INFO(field);
    auto p = Parse(std::string("images_per_tree: 10 ") + field + src);
    REQUIRE(p.ok());
    CHECK(p->constants.edge == edge);
  }
  // A number no name has: the field and the names it takes.
  CHECK_THAT(ErrorOf("images_per_tree: 10 probe_edge: 7" + src),
             Catch::Contains("probe_edge = 7") && Catch::Contains("PROBE_EDGE_CLAMP"));
  CHECK_THAT(ErrorOf("images_per_tree: 10 probe_edge: PROBE_EDGE_MIRROR" + src),
             Catch::Contains("probe_edge"));
}

TEST_CASE("pixel_probe_share: 0 (the paper's draw) by default, 0..1", "[training][config]") {
  const std::string src = " source { procedural { seed: 4 } }";
  auto p = Parse("images_per_tree: 10" + src);
  REQUIRE(p.ok());
  CHECK(p->pixel_probe_share == 0.0);
  CHECK_THAT(engine::DescribeParams(*p), !Catch::Contains("pixel itself"));
  p = Parse("images_per_tree: 10 pixel_probe_share: 0.5" + src);
  REQUIRE(p.ok());
  CHECK(p->pixel_probe_share == 0.5);
  CHECK_THAT(engine::DescribeParams(*p), Catch::Contains("50% of the features against the pixel itself"));
  for (const char* bad : {"-0.1", "1.5", "nan", "inf"}) {
    INFO(bad);
    CHECK_THAT(ErrorOf(std::string("images_per_tree: 10 pixel_probe_share: ") + bad + src),
               Catch::Contains("pixel_probe_share") && Catch::Contains("must be in 0..1"));
  }
}

TEST_CASE("a full job parses every field", "[training][config]") {
  auto p = Parse(R"(
    seed: 42 num_trees: 2 max_depth: 12 images_per_tree: 100 pixels_per_image: 500
    candidate_features: 300 thresholds_per_feature: 20 max_probe_offset_pixel_m: 60
    min_samples_split: 4 min_gain: 0.01 threads: 2 threshold_reference_pixels: 100
    part_balance: 0.5 histogram_memory_mb: 64
    source { rendered { seed: 7 rotation_range_deg: 180 max_people: 2 kinect_noise: false } }
    test_set { source { dataset { folder: "/tmp/test" count: 10 } } num_images: 10 }
  )");
  REQUIRE(p.ok());
  CHECK(p->seed == 42);
  CHECK(p->max_depth == 12);
  CHECK(p->min_gain == 0.01);
  CHECK(p->histogram_memory_bytes == (uint64_t(64) << 20));
  CHECK(p->source.kind == engine::SourceKind::kRendered);
  CHECK(p->source.rotation_range_deg == 180.0);
  CHECK(p->source.max_people == 2);
  CHECK_FALSE(p->source.kinect_noise);
  REQUIRE(p->has_test_set);
  CHECK(p->test_source.kind == engine::SourceKind::kDataset);
  CHECK(p->test_source.folder == "/tmp/test");
  CHECK(p->test_images == 10);
}

TEST_CASE("bad configs give errors naming the field", "[training][config]") {
  const std::string src = " source { procedural { } }";
  CHECK_THAT(ErrorOf("source { procedural { } }"),
             Catch::Contains("images_per_tree") && Catch::Contains("required"));
  CHECK_THAT(ErrorOf("images_per_tree: 0" + src), Catch::Contains("images_per_tree = 0"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 thresholds_per_feature: 300" + src),
             Catch::Contains("thresholds_per_feature = 300") && Catch::Contains("1..255"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 max_probe_offset_pixel_m: -1" + src),
             Catch::Contains("max_probe_offset_pixel_m"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 max_probe_offset_pixel_m: 5000" + src),
             Catch::Contains("max_probe_offset_pixel_m"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 max_depth: 0" + src), Catch::Contains("max_depth"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 num_trees: 0" + src), Catch::Contains("num_trees"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 min_samples_split: 1" + src), Catch::Contains("min_samples_split"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 min_gain: -0.5" + src), Catch::Contains("min_gain"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 part_balance: 2" + src), Catch::Contains("part_balance"));
  CHECK_THAT(ErrorOf("images_per_tree: 5"), Catch::Contains("source") && Catch::Contains("required"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { dataset { } }"), Catch::Contains("source.dataset.folder"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { procedural { num_parts: 1 } }"),
             Catch::Contains("source.procedural.num_parts"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { rendered { rotation_range_deg: 400 } }"),
             Catch::Contains("source.rendered.rotation_range_deg"));
  CHECK_THAT(ErrorOf("images_per_tree: 5" + src + " test_set { num_images: 3 }"),
             Catch::Contains("test_set.source"));
  CHECK_THAT(ErrorOf("images_per_tree: 5000000 pixels_per_image: 2000" + src), Catch::Contains("2^31"));
  // Syntax errors and unknown fields name the file and the position.
  CHECK_THAT(ErrorOf("images_per_tree: 5 no_such_field: 3" + src),
             Catch::Contains("job.textproto") && Catch::Contains("line 1"));
  CHECK_THAT(ErrorOf("images_per_tree: {"), Catch::Contains("job.textproto: not a valid"));
}

TEST_CASE("LoadJob reads a file and names it in errors", "[training][config]") {
  const auto dir = testing::ScratchDir("job-config");
  const auto path = (dir / "job.textproto").string();
  std::ofstream(path) << "# a comment\nimages_per_tree: 3\nsource { procedural { seed: 9 } }\n";
  auto p = engine::LoadJob(path);
  REQUIRE(p.ok());
  CHECK(p->images_per_tree == 3);
  auto missing = engine::LoadJob((dir / "missing.textproto").string());
  REQUIRE_FALSE(missing.ok());
  CHECK(missing.status().code() == core::ErrorCode::kNotFound);
  CHECK_THAT(missing.status().message(), Catch::Contains("missing.textproto"));
  // A folder given as the job (it used to read as an empty job: "images_per_tree: is required").
  std::filesystem::create_directories(dir / "folder.textproto");
  auto folder = engine::LoadJob((dir / "folder.textproto").string());
  REQUIRE_FALSE(folder.ok());
  CHECK_THAT(folder.status().message(), Catch::Contains("folder.textproto: is a folder, not a file"));
  std::ofstream(path) << "images_per_tree: 3\nthresholds_per_feature: 0\nsource { procedural { } }\n";
  auto bad = engine::LoadJob(path);
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(), Catch::Contains(path) && Catch::Contains("thresholds_per_feature"));
}

TEST_CASE("mocap pose library and MakeHuman options parse, with paths relative to the job file",
          "[training][config][mocap]") {
  const auto dir = testing::ScratchDir("job-config-mocap");
  std::filesystem::create_directories(dir / "poses");
  std::filesystem::create_directories(dir / "kit" / "rigs");
  std::filesystem::create_directories(dir / "kit" / "targets" / "macrodetails");
  for (const char* file : {"base.obj", "rigs/default.mhskel", "rigs/default_weights.mhw"})
    std::ofstream(dir / "kit" / file) << "not parsed here";
  std::ofstream(dir / "poses" / "lib.pfposes") << "not parsed here";
  const auto path = (dir / "job.textproto").string();
  std::ofstream(path) << R"(images_per_tree: 3
source { rendered { pose_library: "poses/lib.pfposes" clips: CLIP_SET_TRAIN test_fraction: 0.25
                    split_seed: 9 makehuman_kit: "kit" procedural_bodies: false } }
test_set { source { rendered { pose_library: "poses/lib.pfposes" clips: CLIP_SET_TEST } } }
)";
  auto p = engine::LoadJob(path);
  REQUIRE(p.ok());
  CHECK(p->source.pose_library == (dir / "poses" / "lib.pfposes").string());
  CHECK(p->source.clips == engine::ClipSet::kTrain);
  CHECK(p->source.test_fraction == 0.25);
  CHECK(p->source.split_seed == 9);
  CHECK(p->source.makehuman_kit == (dir / "kit").string());
  CHECK_FALSE(p->source.procedural_bodies);
  REQUIRE(p->has_test_set);
  CHECK(p->test_source.clips == engine::ClipSet::kTest);
  CHECK(p->test_source.test_fraction == 0.2);  // defaults
  CHECK(p->test_source.split_seed == 0);
  CHECK(p->test_source.procedural_bodies);
  CHECK(p->test_source.makehuman_kit.empty());

  // Without options: procedural poses and bodies, as before.
  auto plain = Parse("images_per_tree: 5 source { rendered { } }");
  REQUIRE(plain.ok());
  CHECK(plain->source.pose_library.empty());
  CHECK(plain->source.clips == engine::ClipSet::kAll);
  CHECK(plain->source.procedural_bodies);
  std::filesystem::remove_all(dir);
}

TEST_CASE("bad mocap options give errors naming the field and the path", "[training][config][mocap]") {
  const std::string missing = "/nonexistent/poses/lib.pfposes";
  const std::string e =
      ErrorOf("images_per_tree: 5 source { rendered { pose_library: \"" + missing + "\" } }");
  CHECK_THAT(e, Catch::Contains("source.rendered.pose_library") && Catch::Contains(missing) &&
                    Catch::Contains("no such file"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { procedural { } } test_set { source { rendered { "
                     "pose_library: \"" +
                     missing + "\" } } }"),
             Catch::Contains("test_set.source.rendered.pose_library") && Catch::Contains(missing));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { rendered { makehuman_kit: \"/nonexistent/kit\" } }"),
             Catch::Contains("source.rendered.makehuman_kit") && Catch::Contains("/nonexistent/kit"));
  {
    // A folder that is not the kit is named with the job's field, not later by a bare file name.
    const auto not_kit = testing::ScratchDir("job-config-not-a-kit");
    CHECK_THAT(
        ErrorOf("images_per_tree: 5 source { rendered { makehuman_kit: \"" + not_kit.string() + "\" } }"),
        Catch::Contains("source.rendered.makehuman_kit") && Catch::Contains(not_kit.string()) &&
            Catch::Contains("holds no base.obj: not the MakeHuman hm08 kit"));
  }
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { rendered { clips: CLIP_SET_TEST } }"),
             Catch::Contains("source.rendered.pose_library") && Catch::Contains("required"));
  CHECK_THAT(ErrorOf("images_per_tree: 5 source { rendered { procedural_bodies: false } }"),
             Catch::Contains("source.rendered.procedural_bodies"));
  const auto dir = testing::ScratchDir("job-config-mocap-bad");
  const auto lib = (dir / "lib.pfposes").string();
  std::ofstream(lib) << "x";
  CHECK_THAT(
      ErrorOf("images_per_tree: 5 source { rendered { pose_library: \"" + lib + "\" test_fraction: 1.5 } }"),
      Catch::Contains("source.rendered.test_fraction = 1.5"));
  // A relative path that does not exist next to the job file: the error names the resolved path.
  const auto job = (dir / "job.textproto").string();
  std::ofstream(job) << "images_per_tree: 3 source { rendered { pose_library: \"nope.pfposes\" } }\n";
  auto bad = engine::LoadJob(job);
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(), Catch::Contains(job) &&
                                         Catch::Contains("source.rendered.pose_library") &&
                                         Catch::Contains((dir / "nope.pfposes").string()));
  std::filesystem::remove_all(dir);
}

TEST_CASE("body_meshes name rigged meshes, with paths relative to the job file",
          "[training][config][mesh][data]") {
  namespace fs = std::filesystem;
  const auto dir = testing::ScratchDir("job-config-meshes");
  // The job's folder sees the shared meshes as meshes/ (a link: shared data is never copied).
  fs::create_directory_symlink(testing::DataDir() / "meshes", dir / "meshes");
  const fs::path cesium = testing::DataDir() / "meshes" / "cesium_man" / "CesiumMan.glb";
  const auto path = (dir / "job.textproto").string();
  std::ofstream(path)
      << "images_per_tree: 3\n"
         "source { rendered { body_meshes: \"meshes/cesium_man/CesiumMan.glb\"\n"
         "                    body_meshes: \""
      << cesium.string()
      << "\" procedural_bodies: false } }\n"
         "test_set { source { rendered { body_meshes: \"meshes/cesium_man/CesiumMan.glb\" } } }\n";
  auto p = engine::LoadJob(path);
  REQUIRE(p.ok());
  // Job order, relative paths against the job's folder, absolute ones as given.
  REQUIRE(p->source.body_meshes.size() == 2);
  CHECK(p->source.body_meshes[0] == (dir / "meshes" / "cesium_man" / "CesiumMan.glb").string());
  CHECK(p->source.body_meshes[1] == cesium.string());
  CHECK_FALSE(p->source.procedural_bodies);  // the meshes are bodies enough
  CHECK(engine::DescribeBodies(p->source) == "mesh CesiumMan.glb + mesh CesiumMan.glb");
  REQUIRE(p->has_test_set);
  REQUIRE(p->test_source.body_meshes.size() == 1);
  CHECK(p->test_source.procedural_bodies);
  CHECK(engine::DescribeBodies(p->test_source) == "mesh CesiumMan.glb + procedural");
  CHECK(engine::DescribeBodies(engine::SourceSpec{}) == "");
  fs::remove_all(dir);
}

TEST_CASE("body_meshes that cannot be bodies are refused naming the field and the file",
          "[training][config][mesh][data]") {
  namespace fs = std::filesystem;
  const auto dir = testing::ScratchDir("job-config-meshes-bad");
  auto job_error = [&](const std::string& meshes) {
    const auto path = (dir / "job.textproto").string();
    std::ofstream(path) << "images_per_tree: 3 source { procedural { } }\n"
                           "test_set { source { rendered { "
                        << meshes << " procedural_bodies: false } } }\n";
    auto p = engine::LoadJob(path);
    REQUIRE_FALSE(p.ok());
    CHECK(p.status().code() == core::ErrorCode::kInvalidArgument);
    CHECK_THAT(p.status().message(), Catch::Contains(path));
    return p.status().message();
  };
  SECTION("a missing file (relative: the error names the resolved path)") {
    CHECK_THAT(job_error("body_meshes: \"bodies/nope.glb\""),
               Catch::Contains("test_set.source.rendered.body_meshes[0]") &&
                   Catch::Contains((dir / "bodies" / "nope.glb").string()) &&
                   Catch::Contains("no such file"));
  }
  SECTION("a folder") {
    CHECK_THAT(job_error("body_meshes: \"" + dir.string() + "\""),
               Catch::Contains("body_meshes[0]") && Catch::Contains("is not a file"));
  }
  SECTION("an empty path") {
    CHECK_THAT(job_error("body_meshes: \"\""), Catch::Contains("body_meshes[0]") && Catch::Contains("empty"));
  }
#if POSEFOREST_HAS_RENDERER
  const fs::path cesium = testing::DataDir() / "meshes" / "cesium_man" / "CesiumMan.glb";
  SECTION("a mesh without bones (the staged MakeHuman m07 OBJ), after a good one") {
    const fs::path obj = testing::DataDir() / "meshes" / "makehuman_m07_pcl_bodypart_labels" / "base_m07.obj";
    CHECK_THAT(job_error("body_meshes: \"" + cesium.string() + "\" body_meshes: \"" + obj.string() + "\""),
               Catch::Contains("test_set.source.rendered.body_meshes[1]") && Catch::Contains(obj.string()) &&
                   Catch::Contains("cannot be a body") && Catch::Contains("no skinned mesh"));
  }
  SECTION("a file that is no mesh at all") {
    const fs::path text = testing::DataDir() / "meshes" / "cesium_man" / "LICENSE.md";
    CHECK_THAT(job_error("body_meshes: \"" + text.string() + "\""),
               Catch::Contains("body_meshes[0]") && Catch::Contains(text.string()) &&
                   Catch::Contains("cannot be a body") && Catch::Contains("Assimp cannot read it"));
  }
  SECTION("junk named .glb") {
    const fs::path junk = dir / "junk.glb";
    std::ofstream(junk) << "this is not a mesh at all";
    CHECK_THAT(job_error("body_meshes: \"junk.glb\""),
               Catch::Contains(junk.string()) && Catch::Contains("Assimp cannot read it"));
  }
#endif
  fs::remove_all(dir);
}

TEST_CASE("the rendering realism fields: defaults, values, the scene they make, bad values named",
          "[training][config][realism]") {
  auto d = Parse("images_per_tree: 5 source { rendered { } }");
  REQUIRE(d.ok());
  CHECK(d->source.upper_body_share == 0.25);
  CHECK(d->source.upper_body_min_distance_m == 0.6);
  CHECK(d->source.upper_body_max_distance_m == 2.0);
  CHECK(d->source.arm_pose_share == 0.5);
  CHECK(d->source.projector_shadow);
  CHECK(d->source.min_range_m == 0.45);
  auto c = Parse(
      "images_per_tree: 5 source { rendered { upper_body_share: 0 arm_pose_share: 1 projector_shadow: false "
      "min_range_m: 0 upper_body_min_distance_m: 0.8 upper_body_max_distance_m: 1.5 } }");
  REQUIRE(c.ok());
  CHECK(c->source.upper_body_share == 0);
  CHECK(c->source.arm_pose_share == 1);
  CHECK_FALSE(c->source.projector_shadow);
  CHECK(c->source.min_range_m == 0);
  CHECK(c->source.upper_body_min_distance_m == 0.8);
  CHECK(c->source.upper_body_max_distance_m == 1.5);
  const std::string r = "images_per_tree: 5 source { rendered { ";
  CHECK_THAT(ErrorOf(r + "upper_body_share: 1.5 } }"), Catch::Contains("source.rendered.upper_body_share = 1.5"));
  CHECK_THAT(ErrorOf(r + "arm_pose_share: -0.1 } }"), Catch::Contains("source.rendered.arm_pose_share"));
  CHECK_THAT(ErrorOf(r + "upper_body_min_distance_m: 0.2 } }"),
             Catch::Contains("source.rendered.upper_body_min_distance_m"));
  CHECK_THAT(ErrorOf(r + "upper_body_min_distance_m: 1.5 upper_body_max_distance_m: 1 } }"),
             Catch::Contains("source.rendered.upper_body_max_distance_m"));
  CHECK_THAT(ErrorOf(r + "min_range_m: 3 } }"), Catch::Contains("source.rendered.min_range_m"));
  // The test set has its own fields (the default job pins it to the classic renders).
  auto t = Parse("images_per_tree: 5 source { rendered { } } test_set { source { rendered { upper_body_share: 0 } } }");
  REQUIRE(t.ok());
  CHECK(t->source.upper_body_share == 0.25);
  CHECK(t->test_source.upper_body_share == 0);
  // Sitting and leaning: off by default, shares in [0, 1], passed to the scene.
  CHECK(d->source.sitting_share == 0);
  CHECK(d->source.leaning_share == 0);
  auto sl = Parse("images_per_tree: 5 source { rendered { sitting_share: 0.3 leaning_share: 0.6 } }");
  REQUIRE(sl.ok());
  CHECK(sl->source.sitting_share == 0.3);
  CHECK(sl->source.leaning_share == 0.6);
  CHECK_THAT(ErrorOf(r + "sitting_share: 2 } }"), Catch::Contains("source.rendered.sitting_share"));
  CHECK_THAT(ErrorOf(r + "leaning_share: -1 } }"), Catch::Contains("source.rendered.leaning_share"));
  // The heading mixture: off by default (every person within rotation_range_deg), values kept,
  // bad values named.
  CHECK(d->source.turned_share == 0);
  CHECK(d->source.turned_range_deg == 180);
  auto tm = Parse("images_per_tree: 5 source { rendered { rotation_range_deg: 60 turned_share: 0.25 turned_range_deg: 120 } }");
  REQUIRE(tm.ok());
  CHECK(tm->source.turned_share == 0.25);
  CHECK(tm->source.turned_range_deg == 120);
  CHECK_THAT(ErrorOf(r + "turned_share: 1.5 } }"), Catch::Contains("source.rendered.turned_share"));
  CHECK_THAT(ErrorOf(r + "turned_range_deg: 200 } }"), Catch::Contains("source.rendered.turned_range_deg"));
}

#if POSEFOREST_HAS_RENDERER
TEST_CASE("body_bone_map: a rig no built-in name map knows (Rigify names) becomes a body",
          "[training][config][mesh][data]") {
  namespace fs = std::filesystem;
  const auto dir = testing::ScratchDir("job-config-bone-map");
  // Quaternius' Casual_Female with its bones renamed as Blender's Rigify names them.
  const std::vector<std::pair<std::string, std::string>> rigify = {
      {"Hips", "spine"},           {"Abdomen", "spine.001"},    {"Torso", "spine.003"},
      {"Neck", "spine.004"},       {"Head", "spine.006"},       {"Shoulder.L", "shoulder.L"},
      {"UpperArm.L", "upper_arm.L"}, {"LowerArm.L", "forearm.L"}, {"Fist.L", "hand.L"},
      {"UpperLeg.L", "thigh.L"},   {"LowerLeg.L", "shin.L"},    {"Foot.L", "foot.L"}};
  nlohmann::json gltf;
  std::ifstream(testing::DataDir() / "meshes" / "quaternius_casual_female" / "Casual_Female.gltf") >> gltf;
  int renamed = 0;
  for (auto& node : gltf["nodes"]) {
    if (!node.contains("name")) continue;
    std::string name = node["name"];
    for (const auto& [from, to] : rigify) {
      for (const char* side : {"", "R"}) {
        std::string f = from, t = to;
        if (*side) {
          if (f.size() < 2 || f.substr(f.size() - 2) != ".L") continue;
          f.back() = 'R', t.back() = 'R';
        }
        if (name == f) node["name"] = t, ++renamed;
      }
    }
  }
  REQUIRE(renamed == 19);  // 5 trunk bones + 7 bones per side
  const fs::path mesh = dir / "rigify_female.gltf";
  std::ofstream(mesh) << gltf.dump();
  auto job = [&](const std::string& map) {
    const auto path = (dir / "job.textproto").string();
    std::ofstream(path) << "images_per_tree: 3 source { rendered { body_meshes: \"rigify_female.gltf\" " << map
                        << " } }\n";
    return engine::LoadJob(path);
  };
  // Without a map: refused, naming the rig's bones and the missing joints.
  auto refused = job("");
  REQUIRE_FALSE(refused.ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("body_meshes[0]") && Catch::Contains("unknown skeleton") &&
                                             Catch::Contains("forearm.L"));
  // With the job's bone map: a body.
  std::string map;
  for (const auto& [joint, bone] :
       std::vector<std::pair<std::string, std::string>>{{"pelvis", "spine"},       {"spine", "spine.001"},
                                                        {"chest", "spine.003"},    {"neck", "spine.004"},
                                                        {"head", "spine.006"},     {"L_collar", "shoulder.L"},
                                                        {"L_shoulder", "upper_arm.L"}, {"L_elbow", "forearm.L"},
                                                        {"L_wrist", "hand.L"},     {"L_hip", "thigh.L"},
                                                        {"L_knee", "shin.L"},      {"L_ankle", "foot.L"}}) {
    map += "body_bone_map { joint: \"" + joint + "\" bone: \"" + bone + "\" } ";
    if (joint.rfind("L_", 0) == 0) {
      std::string rj = joint, rb = bone;
      rj[0] = 'R', rb.back() = 'R';
      map += "body_bone_map { joint: \"" + rj + "\" bone: \"" + rb + "\" } ";
    }
  }
  auto ok = job(map);
  INFO(ok.status().ToString());
  REQUIRE(ok.ok());
  CHECK(ok->source.body_bone_map.size() == 19);
  // An unknown joint name in the map is refused naming the field.
  auto bad = job(map + "body_bone_map { joint: \"L_elbo\" bone: \"forearm.L\" }");
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(),
             Catch::Contains("source.rendered.body_bone_map") && Catch::Contains("unknown canonical joint 'L_elbo'"));
  fs::remove_all(dir);
}
#endif

#if POSEFOREST_HAS_RENDERER
#include "engine/rendered_scene.h"

TEST_CASE("sitting and leaning shares reach the scene", "[training][config][realism]") {
  auto sl = Parse("images_per_tree: 5 source { rendered { sitting_share: 0.3 leaning_share: 0.6 } }");
  REQUIRE(sl.ok());
  renderer::SceneConfig scene;
  REQUIRE(engine::ApplySceneOptions(sl->source, &scene).ok());
  CHECK(scene.sit_share == 0.3);
  CHECK(scene.lean_share == 0.6);
  auto tm = Parse("images_per_tree: 5 source { rendered { turned_share: 0.25 turned_range_deg: 150 } }");
  REQUIRE(tm.ok());
  REQUIRE(engine::ApplySceneOptions(tm->source, &scene).ok());
  CHECK(scene.turned_share == 0.25);
  CHECK(scene.turned_range_deg == 150);
}
#endif

TEST_CASE("the sensor fields: defaults classic, values, the noise they make, bad values named",
          "[training][config][realism]") {
  auto d = Parse("images_per_tree: 5 source { rendered { } }");
  REQUIRE(d.ok());
  CHECK(d->source.sensor == engine::DepthSensor::kKinectV1);
  CHECK_FALSE(d->source.flying_pixels.has_value());
  CHECK_FALSE(d->source.range_holes.has_value());
  CHECK_FALSE(d->source.grazing_holes.has_value());
  auto c = Parse(
      "images_per_tree: 5 source { rendered { flying_pixels: 0.4 range_holes: 0.1 grazing_holes: 0.6 "
      "sensor: DEPTH_SENSOR_KINECT_V2 } }");
  REQUIRE(c.ok());
  CHECK(c->source.sensor == engine::DepthSensor::kKinectV2);
  CHECK(c->source.flying_pixels == 0.4);
  CHECK(c->source.range_holes == 0.1);
  CHECK(c->source.grazing_holes == 0.6);
  CHECK(c->source.min_range_m == 0.5);  // the ToF cameras' near limit unless given
  const std::string r = "images_per_tree: 5 source { rendered { ";
  CHECK_THAT(ErrorOf(r + "flying_pixels: 1.5 } }"), Catch::Contains("source.rendered.flying_pixels = 1.5"));
  CHECK_THAT(ErrorOf(r + "range_holes: -0.1 } }"), Catch::Contains("source.rendered.range_holes"));
  CHECK_THAT(ErrorOf(r + "grazing_holes: 2 } }"), Catch::Contains("source.rendered.grazing_holes"));
#if POSEFOREST_HAS_RENDERER
  // Unset: the classic Kinect v1 model, every new effect off (frames as before the fields).
  renderer::SceneConfig classic;
  REQUIRE(engine::ApplySceneOptions(d->source, &classic).ok());
  const renderer::NoiseConfig v1;
  CHECK(classic.noise.principle == renderer::DepthPrinciple::kStructuredLight);
  CHECK(classic.noise.flying_pixels == 0);
  CHECK(classic.noise.range_dropout == 0);
  CHECK(classic.noise.grazing_dropout == 0);
  CHECK(classic.noise.focal_px == v1.focal_px);
  CHECK(classic.noise.edge_dropout == v1.edge_dropout);
  CHECK(classic.noise.disparity_sigma_px == v1.disparity_sigma_px);
  // Kinect v2: time of flight at the render camera's focal length, the job's shares.
  renderer::SceneConfig tof;
  REQUIRE(engine::ApplySceneOptions(c->source, &tof).ok());
  CHECK(tof.noise.principle == renderer::DepthPrinciple::kTimeOfFlight);
  CHECK(tof.noise.flying_pixels == 0.4);
  CHECK(tof.noise.range_dropout == 0.1);
  CHECK(tof.noise.grazing_dropout == 0.6);
  CHECK(tof.noise.focal_px == tof.camera.fx);
  CHECK(tof.camera.width == 640);  // frames keep the Kinect v1 size without sensor_camera
  CHECK(tof.camera.fx == 575.8);
  CHECK_FALSE(c->source.sensor_camera);
  CHECK(c->source.width == 640);
  // sensor_camera: the sensor's own size and intrinsics, in the spec and the scene.
  for (const auto& [name, w, h, f] : {std::tuple{"DEPTH_SENSOR_KINECT_V2", 512, 424, 365.5},
                                      std::tuple{"DEPTH_SENSOR_AZURE_KINECT_NFOV", 640, 576, 504.0},
                                      std::tuple{"DEPTH_SENSOR_KINECT_V1", 640, 480, 575.8}}) {
    INFO(name);
    auto own = Parse(std::string("images_per_tree: 5 source { rendered { sensor_camera: true sensor: ") + name + " } }");
    REQUIRE(own.ok());
    CHECK(own->source.sensor_camera);
    CHECK(own->source.width == w);
    CHECK(own->source.height == h);
    auto cam = engine::SourceCamera(own->source);
    REQUIRE(cam.ok());
    CHECK(cam->fx == f);
    auto forest = engine::EmptyForest(*own);
    REQUIRE(forest.ok());
    CHECK(forest->training_fx == float(f));
    CHECK(forest->training_fy == float(f));
    renderer::SceneConfig scene;
    REQUIRE(engine::ApplySceneOptions(own->source, &scene).ok());
    CHECK(scene.camera.width == w);
    CHECK(scene.camera.height == h);
    CHECK(scene.camera.fx == f);
    CHECK(scene.noise.focal_px == f);
  }
  // Without it, every source trains for the Kinect v1's focal length.
  auto plain = engine::EmptyForest(*c);
  REQUIRE(plain.ok());
  CHECK(plain->training_fx == float(core::kKinectV1FocalPx));
  // Unset shares under a ToF sensor: the sensor's own.
  auto a = Parse("images_per_tree: 5 source { rendered { sensor: DEPTH_SENSOR_AZURE_KINECT_NFOV } }");
  REQUIRE(a.ok());
  renderer::SceneConfig azure;
  REQUIRE(engine::ApplySceneOptions(a->source, &azure).ok());
  const renderer::NoiseConfig azure_preset = renderer::SensorNoise(renderer::DepthSensor::kAzureKinectNfov).noise;
  CHECK(azure.noise.flying_pixels == azure_preset.flying_pixels);
#endif
}
