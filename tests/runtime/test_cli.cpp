// The `poseforest` program end to end, as a user runs it: real files, a real process.
#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

#include "runtime/classifier.h"
#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "runtime/joint_proposals.h"
#include "runtime/skeleton.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

using testing::RunPoseforest;

TEST_CASE("poseforest help and unknown commands", "[cli]") {
  auto help = RunPoseforest("help");
  CHECK(help.exit_code == 0);
  CHECK_THAT(help.output, Catch::Contains("infer") && Catch::Contains("inspect"));
  auto bad = RunPoseforest("frobnicate");
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("unknown command 'frobnicate'"));
  auto infer_help = RunPoseforest("infer --help");
  CHECK(infer_help.exit_code == 0);
  CHECK_THAT(infer_help.output, Catch::Contains("--forest"));
}

TEST_CASE("infer classifies a depth PNG and writes the part picture, labels and probabilities", "[cli]") {
  const auto dir = testing::ScratchDir("cli-infer");
  testing::RandomForestSpec spec;
  spec.nodes_per_tree = 3000;
  spec.max_depth = 12;
  const core::Forest forest = testing::MakeRandomForest(spec);
  const std::string forest_path = (dir / "f.pff").string();
  REQUIRE(core::SaveForest(forest, forest_path).ok());
  const core::DepthImage depth = testing::MakePersonDepth(2.5);
  const std::string depth_path = (dir / "frame.png").string();
  REQUIRE(runtime::WriteDepthPng(depth_path, depth).ok());

  auto run = RunPoseforest("infer --forest " + forest_path + " --labels --distributions --out-dir " +
                           (dir / "out").string() + " " + depth_path);
  INFO(run.output);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("foreground pixels"));

  // The label PNG equals what the library computes in-process.
  runtime::Classifier classifier(forest);
  runtime::Classification expected;
  classifier.Classify(depth, {}, &expected);
  auto bytes = core::ReadFileBytes((dir / "out" / "frame.labels.png").string());
  REQUIRE(bytes.ok());
  auto png = runtime::DecodePng(*bytes, "frame.labels.png");
  REQUIRE(png.ok());
  CHECK(png->width == 640);
  CHECK(png->channels == 1);
  CHECK(png->samples8 == expected.labels.pixels);
  auto colour = core::ReadFileBytes((dir / "out" / "frame.parts.png").string());
  REQUIRE(colour.ok());
  auto colour_png = runtime::DecodePng(*colour, "frame.parts.png");
  REQUIRE(colour_png.ok());
  CHECK(colour_png->channels == 3);
  // The probabilities file is a float32 NumPy array [480, 640, 31].
  const auto npy = fs::path(dir / "out" / "frame.probs.npy");
  REQUIRE(fs::exists(npy));
  std::ifstream in(npy, std::ios::binary);
  std::string head(128, '\0');
  in.read(head.data(), 128);
  CHECK_THAT(head, Catch::Contains("'shape': (480, 640, 31)"));
  CHECK(fs::file_size(npy) == 128 + size_t(480) * 640 * 31 * 4);
  // infer writes it from the compact foreground sums; every value equals the dense classifier's
  // P(part | pixel), background pixels all zero.
  runtime::ClassifyOptions dense;
  dense.want_distributions = true;
  classifier.Classify(depth, dense, &expected);
  std::vector<float> probs(size_t(480) * 640 * 31);
  in.read(reinterpret_cast<char*>(probs.data()), std::streamsize(probs.size() * 4));
  REQUIRE(in.good());
  size_t mismatches = 0, nonzero = 0;
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      for (int c = 0; c < 31; ++c) {
        const float v = probs[(size_t(y) * 640 + size_t(x)) * 31 + size_t(c)];
        mismatches += v != expected.Probability(x, y, c);
        nonzero += v != 0;
      }
  CHECK(mismatches == 0);
  CHECK(nonzero > 1000);

  // --pixel-stride 2: the labels the library gives on the grid (every foreground pixel off it
  // takes its grid pixel's part), probabilities only at grid pixels.
  auto strided = RunPoseforest("infer --forest " + forest_path +
                               " --labels --distributions --pixel-stride 2 --out-dir " +
                               (dir / "s2").string() + " " + depth_path);
  INFO(strided.output);
  REQUIRE(strided.exit_code == 0);
  runtime::ClassifyOptions grid;
  grid.want_distributions = true;
  grid.pixel_stride = 2;
  runtime::Classification on_grid;
  classifier.Classify(depth, grid, &on_grid);
  auto s2_bytes = core::ReadFileBytes((dir / "s2" / "frame.labels.png").string());
  REQUIRE(s2_bytes.ok());
  auto s2_png = runtime::DecodePng(*s2_bytes, "frame.labels.png");
  REQUIRE(s2_png.ok());
  CHECK(s2_png->samples8 == on_grid.labels.pixels);
  CHECK(s2_png->samples8 != expected.labels.pixels);
  std::ifstream s2_in(dir / "s2" / "frame.probs.npy", std::ios::binary);
  s2_in.read(head.data(), 128);
  s2_in.read(reinterpret_cast<char*>(probs.data()), std::streamsize(probs.size() * 4));
  REQUIRE(s2_in.good());
  mismatches = 0;
  size_t off_grid_nonzero = 0;
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      for (int c = 0; c < 31; ++c) {
        const float v = probs[(size_t(y) * 640 + size_t(x)) * 31 + size_t(c)];
        mismatches += v != on_grid.Probability(x, y, c);
        off_grid_nonzero += (x % 2 || y % 2) && v != 0;
      }
  CHECK(mismatches == 0);
  CHECK(off_grid_nonzero == 0);
  fs::remove_all(dir);
}

TEST_CASE("infer --joints writes proposals as JSON and the pose picture", "[cli]") {
  const auto dir = testing::ScratchDir("cli-joints");
  const core::Forest forest = testing::MakeRandomForest({.max_depth = 10, .nodes_per_tree = 2000});
  REQUIRE(core::SaveForest(forest, (dir / "f.pff").string()).ok());
  REQUIRE(runtime::WriteDepthPng((dir / "d.png").string(), testing::MakePersonDepth(2.5)).ok());
  // What the dense route (W*H*32 sums -> per-pixel joint probabilities -> proposals) gives
  // in-process; infer takes the compact route and must print the same proposals.
  const core::DepthImage depth = testing::MakePersonDepth(2.5);
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions dense;
  dense.want_distributions = true;
  runtime::Classification c;
  classifier.Classify(depth, dense, &c);
  const auto probs = runtime::ProbabilitiesFromClassification(depth, c);
  for (const char* method : {"meanshift", "fast"}) {
    auto run = RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --joints --method " + method + " " +
                             (dir / "d.png").string());
    INFO(run.output);
    REQUIRE(run.exit_code == 0);
    CHECK_THAT(run.output, Catch::Contains("L_elbow") && Catch::Contains(method));
    std::ifstream json(dir / "d.joints.json");
    const auto doc = nlohmann::json::parse(json);
    CHECK(doc["method"] == method);
    REQUIRE(doc["joints"].size() == size_t(core::kNumJoints));
    CHECK(doc["joints"][0]["joint"] == "head");
    CHECK(doc["joints"][core::kNumJoints - 1]["joint"] == "R_foot");
    runtime::ProposalOptions po;
    po.method = std::string(method) == "fast" ? runtime::ProposalMethod::kFastClustering
                                              : runtime::ProposalMethod::kMeanShift;
    const auto expected = runtime::ProposeJoints(depth, probs, po);
    size_t total = 0, count_in_json = 0;
    for (int j = 0; j < core::kNumJoints; ++j) {
      const auto& list = expected[size_t(j)];
      const auto& written = doc["joints"][size_t(j)]["proposals"];
      REQUIRE(written.size() == list.size());
      total += list.size();
      count_in_json += written.size();
      for (size_t k = 0; k < list.size(); ++k) {
        const auto& p = list[k];
        const auto& w = written[k];
        // Positions to 0.1 mm, confidence to 5 significant digits, calibrated to 4 decimals.
        for (int c = 0; c < 3; ++c)
          CHECK(w["position_m"][size_t(c)].get<double>() == runtime::PrintedValue(p.position[c], "%.4f"));
        CHECK(w["confidence"].get<double>() == runtime::PrintedValue(p.confidence, "%.5g"));
        // The forest has no calibration table: the documented fallback of the support.
        CHECK(w["calibrated_confidence"].get<double>() ==
              runtime::PrintedValue(
                  core::FallbackConfidence(float(double(p.confidence) / (po.camera.fx * po.camera.fy))),
                  "%.4f"));
      }
    }
    CHECK(total > 0);
    CHECK(count_in_json == total);
    auto png = core::ReadFileBytes((dir / "d.pose.png").string());
    REQUIRE(png.ok());
    auto fig = runtime::DecodePng(*png, "d.pose.png");
    REQUIRE(fig.ok());
    CHECK(fig->width == 960);
    CHECK(fig->height == 480);
  }
  auto bad = RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --joints --method slow " + (dir / "d.png").string());
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("--method"));
  // A forest with another part table has no joints to propose.
  const core::Forest other = testing::MakeRandomForest({.max_depth = 4, .nodes_per_tree = 20, .num_parts = 25});
  REQUIRE(core::SaveForest(other, (dir / "o.pff").string()).ok());
  auto wrong = RunPoseforest("infer --forest " + (dir / "o.pff").string() + " --joints " + (dir / "d.png").string());
  CHECK(wrong.exit_code == 1);
  CHECK_THAT(wrong.output, Catch::Contains("31-part"));
  fs::remove_all(dir);
}

TEST_CASE("infer reads raw Kinect frames from the shared data", "[cli][data]") {
  const auto frames = testing::DataDir() / "real" / "skeltrack_kinect_depth";
  REQUIRE(fs::exists(frames));  // CI and developers have ../shared/data
  std::string first;
  for (auto& e : fs::directory_iterator(frames))
    if (e.is_regular_file() && e.path().filename().string().rfind("depth-data", 0) == 0) {
      first = e.path().string();
      break;
    }
  REQUIRE_FALSE(first.empty());
  const auto dir = testing::ScratchDir("cli-raw");
  const core::Forest forest = testing::MakeRandomForest({.max_depth = 8, .nodes_per_tree = 500});
  REQUIRE(core::SaveForest(forest, (dir / "f.pff").string()).ok());
  auto run = RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --out " + (dir / "p.png").string() + " " + first);
  INFO(run.output);
  CHECK(run.exit_code == 0);
  CHECK(fs::exists(dir / "p.png"));
  fs::remove_all(dir);
}

TEST_CASE("infer and inspect give clear errors on bad input and lose nothing", "[cli]") {
  const auto dir = testing::ScratchDir("cli-bad");
  const core::Forest forest = testing::MakeRandomForest({.max_depth = 6, .nodes_per_tree = 200});
  const std::string good = (dir / "good.pff").string();
  REQUIRE(core::SaveForest(forest, good).ok());
  // A corrupt copy: one flipped byte in the middle.
  auto bytes = core::ReadFileBytes(good);
  REQUIRE(bytes.ok());
  (*bytes)[bytes->size() / 2] ^= 0x10;
  const std::string corrupt = (dir / "corrupt.pff").string();
  REQUIRE(core::WriteFileAtomic(corrupt, *bytes).ok());
  const std::string depth_path = (dir / "d.png").string();
  REQUIRE(runtime::WriteDepthPng(depth_path, testing::MakePersonDepth(3.0)).ok());

  auto r1 = RunPoseforest("infer --forest " + corrupt + " " + depth_path);
  CHECK(r1.exit_code == 1);
  CHECK_THAT(r1.output, Catch::Contains("corrupt.pff") && Catch::Contains("checksum"));
  CHECK_FALSE(fs::exists(dir / "d.parts.png"));  // nothing written on failure

  auto r2 = RunPoseforest("inspect " + good + " " + corrupt);
  CHECK(r2.exit_code == 1);
  CHECK_THAT(r2.output, Catch::Contains("good.pff: valid") && Catch::Contains("corrupt.pff"));

  auto r3 = RunPoseforest("infer " + depth_path);
  CHECK(r3.exit_code == 2);
  CHECK_THAT(r3.output, Catch::Contains("--forest is required"));

  // A depth file of the wrong size: named, with the sizes; other inputs still processed.
  std::ofstream((dir / "short.raw").string(), std::ios::binary) << "12345";
  auto r4 = RunPoseforest("infer --forest " + good + " --out-dir " + (dir / "o").string() + " " +
                          (dir / "short.raw").string() + " " + depth_path);
  CHECK(r4.exit_code == 1);
  CHECK_THAT(r4.output, Catch::Contains("short.raw"));
  CHECK(fs::exists(dir / "o" / "d.parts.png"));

  // A folder given as the forest: named, exit 1 (it used to abort on std::bad_alloc).
  fs::create_directories(dir / "folder.pff");
  const std::string folder = (dir / "folder.pff").string();
  for (const std::string& cmd : {"inspect " + folder, "infer --forest " + folder + " " + depth_path}) {
    auto r = RunPoseforest(cmd);
    INFO(cmd << "\n" << r.output);
    CHECK(r.exit_code == 1);
    CHECK_THAT(r.output, Catch::Contains(folder + ": is a folder, not a file"));
  }

  // --out naming an input (the forest, the depth frame) would destroy it: refused, both kept.
  const auto forest_bytes = core::ReadFileBytes(good), depth_bytes = core::ReadFileBytes(depth_path);
  for (const std::string& target : {good, depth_path}) {
    auto r = RunPoseforest("infer --forest " + good + " --out " + target + " " + depth_path);
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.output, Catch::Contains("--out " + target + ": the same file as the input " + target));
  }
  CHECK(core::ReadFileBytes(good).value() == forest_bytes.value());
  CHECK(core::ReadFileBytes(depth_path).value() == depth_bytes.value());
  // With --out, the other outputs go into its folder, not beside the input.
  fs::create_directories(dir / "side");
  auto side = RunPoseforest("infer --forest " + good + " --out " + (dir / "side" / "p.png").string() +
                            " --labels --masks " + depth_path);
  INFO(side.output);
  CHECK(side.exit_code == 0);
  CHECK(fs::exists(dir / "side" / "p.png"));
  CHECK(fs::exists(dir / "side" / "d.labels.png"));
  CHECK(fs::exists(dir / "side" / "d.mask.png"));
  CHECK_FALSE(fs::exists(dir / "d.labels.png"));
  // Two inputs of one name into one --out-dir: the second is refused, the first's output kept.
  fs::create_directories(dir / "A");
  fs::create_directories(dir / "B");
  fs::copy_file(depth_path, dir / "A" / "x.png");
  REQUIRE(runtime::WriteDepthPng((dir / "B" / "x.png").string(), testing::MakePersonDepth(2.0)).ok());
  auto same_name = RunPoseforest("infer --forest " + good + " --out-dir " + (dir / "same").string() + " " +
                                 (dir / "A" / "x.png").string() + " " + (dir / "B" / "x.png").string());
  INFO(same_name.output);
  CHECK(same_name.exit_code == 1);
  CHECK_THAT(same_name.output, Catch::Contains((dir / "B" / "x.png").string() + ": its outputs") &&
                                   Catch::Contains("would overwrite those of an earlier input"));
  // The refused one is counted as not written, not as classified.
  CHECK_THAT(same_name.output,
             Catch::Contains("1 frame(s) classified, 1 not written (above), 0 bad frame(s)"));
  auto alone = RunPoseforest("infer --forest " + good + " --out " + (dir / "alone.png").string() + " " +
                             (dir / "A" / "x.png").string());
  REQUIRE(alone.exit_code == 0);
  CHECK(core::ReadFileBytes((dir / "same" / "x.parts.png").string()).value() ==
        core::ReadFileBytes((dir / "alone.png").string()).value());

  auto r5 = RunPoseforest("infer --forest " + good + " --threads many " + depth_path);
  CHECK(r5.exit_code == 2);
  CHECK_THAT(r5.output, Catch::Contains("--threads"));

  // Joint-proposal sections that do not hold 16 joints (behind a valid checksum): infer and
  // inspect name the file and the section, and write nothing.
  core::Forest tuned = forest;
  tuned.proposal_params = core::DefaultProposalParams();
  tuned.fast_proposal_params = core::DefaultProposalParams();
  (*tuned.fast_proposal_params)[0].bandwidth_m = 0.1f;
  for (const char* tag : {"JPAR", "JPFC"}) {
    auto b = core::SerializeForest(tuned);
    const std::string bytes_text(b.begin(), b.end());
    const size_t at = bytes_text.rfind(tag);
    REQUIRE(at != std::string::npos);
    b[at + 16] = 15;  // joint count 15: the payload no longer matches
    const uint32_t crc = core::Crc32(b.data(), b.size() - 8);
    for (int i = 0; i < 4; ++i) b[b.size() - 8 + size_t(i)] = uint8_t(crc >> (8 * i));
    const std::string bad_path = (dir / (std::string(tag) + ".pff")).string();
    REQUIRE(core::WriteFileAtomic(bad_path, b).ok());
    const auto out_dir = dir / (std::string("out_") + tag);
    auto infer = RunPoseforest("infer --forest " + bad_path + " --joints --out-dir " + out_dir.string() +
                               " " + depth_path);
    INFO(infer.output);
    CHECK(infer.exit_code == 1);
    CHECK_THAT(infer.output, Catch::Contains(bad_path) && Catch::Contains(std::string(tag) + " holds") &&
                                 Catch::Contains("15 joints"));
    CHECK_FALSE(fs::exists(out_dir / "d.parts.png"));
    auto inspect = RunPoseforest("inspect " + bad_path);
    CHECK(inspect.exit_code == 1);
    CHECK_THAT(inspect.output, Catch::Contains(bad_path) && Catch::Contains(tag));
  }
  fs::remove_all(dir);
}

TEST_CASE("inspect shows the offset votes (format 1.5, JVOT), or says there are none", "[cli]") {
  const auto dir = testing::ScratchDir("cli-votes");
  core::Forest forest = testing::MakeRandomForest({.num_trees = 2, .max_depth = 6, .nodes_per_tree = 200});
  const std::string plain = (dir / "plain.pff").string();
  REQUIRE(core::SaveForest(forest, plain).ok());
  forest.offset_votes = testing::MakeRandomOffsetVotes(forest, 5);
  const std::string votes = (dir / "votes.pff").string();
  REQUIRE(core::SaveForest(forest, votes).ok());

  size_t leaves = 0;
  for (const auto& tree : forest.trees) leaves += tree.num_leaves;
  const size_t total = forest.offset_votes->total_votes();
  char per_leaf[32];
  std::snprintf(per_leaf, sizeof per_leaf, "(%.1f per leaf)", double(total) / double(leaves));
  auto run = RunPoseforest("inspect " + votes);
  INFO(run.output);
  CHECK(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("format 1.9") &&
                             Catch::Contains("offset votes (JVOT): " + std::to_string(total) +
                                             " votes over 2 trees " + per_leaf +
                                             ", max offset 0.60 m, bandwidths 0.05..0.08 m, "
                                             "calibration 3 bins"));
  auto none = RunPoseforest("inspect " + plain);
  INFO(none.output);
  CHECK(none.exit_code == 0);
  CHECK_THAT(none.output, Catch::Contains("offset votes: none"));
  // The probe edge: the paper's unless the forest says otherwise (PEDG, format 1.9).
  CHECK_THAT(none.output, Catch::Contains("probes past the image's edge read the background"));
  forest.constants.edge = core::ProbeEdge::kClamp;
  const std::string clamp = (dir / "clamp.pff").string();
  REQUIRE(core::SaveForest(forest, clamp).ok());
  auto edge = RunPoseforest("inspect " + clamp);
  INFO(edge.output);
  CHECK(edge.exit_code == 0);
  CHECK_THAT(edge.output, Catch::Contains("probes past the image's edge read the edge (PEDG)"));
  fs::remove_all(dir);
}
