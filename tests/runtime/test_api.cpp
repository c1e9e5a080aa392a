// The public API (poseforest/poseforest.h, poseforest.hpp) through the shared libposeforest, as an
// application calls it: results equal the runtime's and the `poseforest infer` program's byte for
// byte, errors carry the CLI's status and message, and docs/runtime/api.md names every function.
#include <poseforest/poseforest.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <poseforest/poseforest.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "runtime/api/skeleton_layout.h"
#include "runtime/classifier.h"
#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "runtime/joint_proposals.h"
#include "runtime/skeleton_pipeline.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/scene.h"
#include "tests/support/skeletons.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

core::Forest SmallForest(uint64_t seed = 5, int num_parts = core::kNumParts) {
  testing::RandomForestSpec spec;
  spec.seed = seed;
  spec.nodes_per_tree = 3000;
  spec.max_depth = 12;
  spec.num_parts = num_parts;
  return testing::MakeRandomForest(spec);
}

/// A forest file of `forest` in a scratch folder (kept for the process's life).
std::string SaveTo(const core::Forest& forest, const std::string& name) {
  static const fs::path dir = testing::ScratchDir("api");
  const std::string path = (dir / name).string();
  REQUIRE(core::SaveForest(forest, path).ok());
  return path;
}

struct Loaded {
  pf_forest* forest = nullptr;
  ~Loaded() { pf_forest_free(forest); }
};

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

TEST_CASE("version macros and the run-time version agree with the project's", "[api]") {
  CHECK(std::string(POSEFOREST_VERSION_STRING) == POSEFOREST_PROJECT_VERSION);
  CHECK(std::string(pf_version_string()) == POSEFOREST_VERSION_STRING);
  CHECK(pf_version() == uint32_t(POSEFOREST_VERSION_NUMBER));
  CHECK(POSEFOREST_VERSION_NUMBER ==
        ((POSEFOREST_VERSION_MAJOR << 16) | (POSEFOREST_VERSION_MINOR << 8) | POSEFOREST_VERSION_PATCH));
  CHECK(api::Version() == POSEFOREST_PROJECT_VERSION);
  CHECK(std::string(pf_status_name(PF_DATA_LOSS)) == core::ErrorCodeName(core::ErrorCode::kDataLoss));
  CHECK(std::string(pf_status_name(PF_IO)) == core::ErrorCodeName(core::ErrorCode::kIo));
  CHECK(std::string(pf_status_name(static_cast<pf_status>(99))) == "Unknown");
}

TEST_CASE("a forest loads from a file and from memory with the runtime's sizes and names", "[api]") {
  const core::Forest forest = SmallForest();
  const std::string path = SaveTo(forest, "load.pff");
  Loaded a, b;
  REQUIRE(pf_forest_load_file(path.c_str(), &a.forest) == PF_OK);
  CHECK(std::string(pf_last_error_message()).empty());
  const auto bytes = core::SerializeForest(forest);
  REQUIRE(pf_forest_load_memory(bytes.data(), bytes.size(), "mem", &b.forest) == PF_OK);
  for (const pf_forest* f : {a.forest, b.forest}) {
    CHECK(pf_forest_num_trees(f) == int(forest.trees.size()));
    CHECK(pf_forest_num_parts(f) == core::kNumParts);
    CHECK(pf_forest_max_depth(f) == int(forest.max_depth()));
    CHECK(pf_forest_num_nodes(f) == forest.total_nodes());
    CHECK(pf_forest_has_joints(f) == 1);
    CHECK(std::string(pf_forest_part_name(f, 0)) == forest.part_names[0]);
    CHECK(pf_forest_part_name(f, core::kNumParts) == nullptr);
    CHECK(pf_forest_part_name(f, -1) == nullptr);
  }
  CHECK(pf_num_joints() == core::kNumJoints);
  CHECK(std::string(pf_joint_name(0)) == "head");
  CHECK(pf_joint_name(core::kNumJoints) == nullptr);
  CHECK(pf_forest_num_trees(nullptr) == -1);
  CHECK(pf_forest_has_joints(nullptr) == 0);
  pf_forest_free(nullptr);

  api::Forest cpp(path);
  CHECK(cpp.num_trees() == int(forest.trees.size()));
  CHECK(cpp.part_names() == forest.part_names);
  api::Forest moved = std::move(cpp);
  CHECK(moved.num_nodes() == forest.total_nodes());
  CHECK(cpp.handle() == nullptr);
  // Classifying with the moved-from object throws the API's Error, not std::length_error from
  // sizing its distributions by -1 parts.
  const core::DepthImage d = testing::MakePersonDepth(2.5);
  const api::DepthView view{d.pixels.data(), d.width, d.height};
  for (const bool distributions : {false, true}) {
    try {
      (void)cpp.Classify(view, distributions);
      FAIL("no exception");
    } catch (const api::Error& e) {
      CHECK(e.status() == PF_INVALID_ARGUMENT);
    }
  }
}

TEST_CASE("labels and distributions equal the runtime classifier's", "[api]") {
  const core::Forest forest = SmallForest();
  const std::string path = SaveTo(forest, "classify.pff");
  const core::DepthImage depth = testing::MakePersonDepth(2.5);
  const size_t pixels = depth.pixels.size();
  Loaded f;
  REQUIRE(pf_forest_load_file(path.c_str(), &f.forest) == PF_OK);

  std::vector<uint8_t> labels(pixels);
  std::vector<float> probs(pixels * core::kNumParts, -1.0f);
  REQUIRE(pf_classify(f.forest, depth.data(), depth.width, depth.height, 2, labels.data(), labels.size(),
                      probs.data(), probs.size()) == PF_OK);
  runtime::ClassifyOptions dense;
  dense.want_distributions = true;
  runtime::Classification expected;
  runtime::Classifier(forest).Classify(depth, dense, &expected);
  CHECK(labels == expected.labels.pixels);
  size_t differing = 0;
  for (int y = 0; y < depth.height; ++y)
    for (int x = 0; x < depth.width; ++x)
      for (int p = 0; p < core::kNumParts; ++p)
        differing += probs[(size_t(y) * size_t(depth.width) + size_t(x)) * core::kNumParts + size_t(p)] !=
                     (depth.at(x, y) == 0 ? 0.0f : expected.Probability(x, y, p));
  CHECK(differing == 0);

  // Labels alone, one thread, and through the C++ API: the same.
  std::vector<uint8_t> labels1(pixels);
  REQUIRE(pf_classify(f.forest, depth.data(), depth.width, depth.height, 1, labels1.data(), labels1.size(),
                      nullptr, 0) == PF_OK);
  CHECK(labels1 == labels);
  const api::Forest cpp(path);
  const auto c = cpp.Classify({depth.data(), depth.width, depth.height}, true);
  CHECK(c.labels == labels);
  CHECK(c.distributions == probs);
}

TEST_CASE("bad arguments give a status and a message, never a crash", "[api]") {
  const std::string path = SaveTo(SmallForest(), "args.pff");
  Loaded f;
  REQUIRE(pf_forest_load_file(path.c_str(), &f.forest) == PF_OK);
  const core::DepthImage depth = testing::MakePersonDepth(2.5, 64, 48);
  std::vector<uint8_t> labels(depth.pixels.size());
  std::vector<float> probs(depth.pixels.size() * core::kNumParts);

  CHECK(pf_classify(nullptr, depth.data(), 64, 48, 0, labels.data(), labels.size(), nullptr, 0) ==
        PF_INVALID_ARGUMENT);
  CHECK_THAT(pf_last_error_message(), Catch::StartsWith("InvalidArgument: pf_classify: forest is NULL"));
  CHECK(pf_classify(f.forest, nullptr, 64, 48, 0, labels.data(), labels.size(), nullptr, 0) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_classify(f.forest, depth.data(), 0, 48, 0, labels.data(), labels.size(), nullptr, 0) ==
        PF_INVALID_ARGUMENT);
  CHECK_THAT(pf_last_error_message(), Catch::Contains("0x48"));
  CHECK(pf_classify(f.forest, depth.data(), 64, 48, 0, nullptr, 0, nullptr, 0) == PF_INVALID_ARGUMENT);
  CHECK(pf_classify(f.forest, depth.data(), 64, 48, -1, labels.data(), labels.size(), nullptr, 0) ==
        PF_INVALID_ARGUMENT);
  std::vector<uint8_t> before = labels;
  CHECK(pf_classify(f.forest, depth.data(), 64, 48, 0, labels.data(), labels.size() - 1, nullptr, 0) ==
        PF_BUFFER_TOO_SMALL);
  CHECK_THAT(pf_last_error_message(), Catch::Contains("labels holds 3071 bytes, needs 3072"));
  CHECK(pf_classify(f.forest, depth.data(), 64, 48, 0, labels.data(), labels.size(), probs.data(),
                    probs.size() - 1) == PF_BUFFER_TOO_SMALL);
  CHECK(labels == before);  // nothing written
  // A success clears the message.
  CHECK(pf_classify(f.forest, depth.data(), 64, 48, 0, labels.data(), labels.size(), nullptr, 0) == PF_OK);
  CHECK(std::string(pf_last_error_message()).empty());

  pf_forest* out = reinterpret_cast<pf_forest*>(&labels);  // must be reset to NULL
  CHECK(pf_forest_load_file(nullptr, &out) == PF_INVALID_ARGUMENT);
  CHECK(out == nullptr);
  CHECK(pf_forest_load_file(path.c_str(), nullptr) == PF_INVALID_ARGUMENT);
  CHECK(pf_forest_load_memory(nullptr, 10, nullptr, &out) == PF_INVALID_ARGUMENT);
  size_t count = 7;
  CHECK(pf_propose_joints(f.forest, depth.data(), 64, 48, static_cast<pf_proposal_method>(7), 0, nullptr, 0,
                          &count, nullptr, 0) == PF_INVALID_ARGUMENT);
  CHECK_THAT(pf_last_error_message(), Catch::Contains("unknown method 7"));
  CHECK(pf_propose_joints(f.forest, depth.data(), 64, 48, PF_MEAN_SHIFT, 0, nullptr, 0, nullptr, nullptr,
                          0) == PF_INVALID_ARGUMENT);

  // The C++ API throws the same status and message.
  const api::Forest cpp(path);
  try {
    (void)cpp.Classify({depth.data(), 0, 48});
    FAIL("no exception");
  } catch (const api::Error& e) {
    CHECK(e.status() == PF_INVALID_ARGUMENT);
    CHECK_THAT(e.what(), Catch::Contains("0x48"));
  }
}

TEST_CASE("a corrupt, truncated, missing or future forest gives the CLI's status and message", "[api]") {
  const core::Forest forest = SmallForest();
  const auto good = core::SerializeForest(forest);
  const fs::path dir = testing::ScratchDir("api-errors");
  const core::DepthImage depth = testing::MakePersonDepth(2.5, 64, 48);
  REQUIRE(runtime::WriteDepthPng((dir / "frame.png").string(), depth).ok());

  struct Case {
    std::string name;
    std::vector<uint8_t> bytes;
    pf_status status;
  };
  std::vector<Case> cases;
  auto flipped = good;
  flipped[good.size() / 2] ^= 0x40;  // payload damage: the checksum catches it
  cases.push_back({"flipped.pff", flipped, PF_DATA_LOSS});
  cases.push_back({"truncated.pff", std::vector<uint8_t>(good.begin(), good.begin() + long(good.size() / 3)),
                   PF_DATA_LOSS});
  cases.push_back({"empty.pff", {}, PF_DATA_LOSS});
  auto future = good;
  future[8] = 2;  // major version 2
  const uint32_t crc = core::Crc32(future.data(), future.size() - 8);
  for (int i = 0; i < 4; ++i) future[future.size() - 8 + size_t(i)] = uint8_t(crc >> (8 * i));
  cases.push_back({"future.pff", future, PF_VERSION_MISMATCH});

  for (const Case& c : cases) {
    INFO(c.name);
    const std::string path = (dir / c.name).string();
    REQUIRE(core::WriteFileAtomic(path, c.bytes).ok());
    const core::Status expected = core::LoadForest(path).status();
    REQUIRE_FALSE(expected.ok());

    pf_forest* out = nullptr;
    CHECK(pf_forest_load_file(path.c_str(), &out) == c.status);
    CHECK(out == nullptr);
    const std::string message = pf_last_error_message();
    CHECK(message == expected.ToString());
    // The program prints the same message after its prefix.
    const auto run =
        testing::RunPoseforest("infer --quiet --forest " + path + " " + (dir / "frame.png").string());
    CHECK(run.exit_code == 1);
    CHECK(run.output == "poseforest infer: " + message + "\n");
    // From memory: the same status, the message names the source.
    CHECK(pf_forest_load_memory(c.bytes.data(), c.bytes.size(), c.name.c_str(), &out) == c.status);
    CHECK(out == nullptr);
    CHECK(std::string(pf_last_error_message()) == core::ParseForest(c.bytes, c.name).status().ToString());
    // C++: an exception with the same status and message.
    try {
      api::Forest f(path);
      FAIL("no exception");
    } catch (const api::Error& e) {
      CHECK(e.status() == c.status);
      CHECK(std::string(e.what()) == message);
    }
  }

  const std::string missing = (dir / "missing.pff").string();
  pf_forest* out = nullptr;
  CHECK(pf_forest_load_file(missing.c_str(), &out) == PF_NOT_FOUND);
  const auto run =
      testing::RunPoseforest("infer --quiet --forest " + missing + " " + (dir / "frame.png").string());
  CHECK(run.output == "poseforest infer: " + std::string(pf_last_error_message()) + "\n");
  CHECK_THAT(pf_last_error_message(), Catch::StartsWith("NotFound: ") && Catch::Contains("missing.pff"));
}

TEST_CASE("labels and distributions equal `poseforest infer --labels --distributions` byte for byte",
          "[api][cli]") {
  const fs::path dir = testing::ScratchDir("api-cli");
  const std::string path = SaveTo(SmallForest(9), "cli.pff");
  const core::DepthImage depth = testing::MakePersonDepth(2.2, 640, 480, 0.2);
  // A raw frame, as a camera gives it.
  const std::string raw = (dir / "frame.raw").string();
  REQUIRE(core::WriteFileAtomic(
              raw, std::span(reinterpret_cast<const uint8_t*>(depth.data()), depth.pixels.size() * 2))
              .ok());
  const auto run = testing::RunPoseforest("infer --quiet --labels --distributions --forest " + path +
                                          " --out-dir " + (dir / "out").string() + " " + raw);
  INFO(run.output);
  REQUIRE(run.exit_code == 0);

  const api::Forest forest(path);
  const auto c = forest.Classify({depth.data(), 640, 480}, true);
  const std::string npy = Slurp(dir / "out" / "frame.probs.npy");
  REQUIRE(npy.size() == 128 + c.distributions.size() * 4);
  CHECK(std::memcmp(npy.data() + 128, c.distributions.data(), c.distributions.size() * 4) == 0);
  const auto png = core::ReadFileBytes((dir / "out" / "frame.labels.png").string());
  REQUIRE(png.ok());
  const auto decoded = runtime::DecodePng(*png, "frame.labels.png");
  REQUIRE(decoded.ok());
  CHECK(decoded->samples8 == c.labels);
}

TEST_CASE("joint proposals equal the runtime's; the buffer protocol and the 31-part rule", "[api]") {
  const core::Forest forest = SmallForest(11);
  const std::string path = SaveTo(forest, "joints.pff");
  const core::DepthImage depth = testing::MakePersonDepth(2.5);
  Loaded f;
  REQUIRE(pf_forest_load_file(path.c_str(), &f.forest) == PF_OK);

  for (pf_proposal_method method : {PF_MEAN_SHIFT, PF_FAST_CLUSTERING}) {
    INFO("method " << int(method));
    runtime::ProposalOptions options;
    options.method = method == PF_MEAN_SHIFT ? runtime::ProposalMethod::kMeanShift
                                             : runtime::ProposalMethod::kFastClustering;
    options.params = forest.ProposalParamsFor(method == PF_FAST_CLUSTERING).params;
    runtime::ClassifyOptions copt;
    copt.want_foreground_distributions = true;
    runtime::Classification c;
    runtime::Classifier(forest).Classify(depth, copt, &c);
    const auto expected = runtime::ProposeJointsFromClassification(depth, c, options);
    size_t n_expected = 0;
    for (const auto& l : expected) n_expected += l.size();
    REQUIRE(n_expected > 0);

    size_t count = 0;
    CHECK(pf_propose_joints(f.forest, depth.data(), depth.width, depth.height, method, 0, nullptr, 0, &count,
                            nullptr, 0) == PF_BUFFER_TOO_SMALL);
    CHECK(count == n_expected);
    std::vector<pf_joint_proposal> got(count);
    std::vector<uint8_t> labels(depth.pixels.size());
    REQUIRE(pf_propose_joints(f.forest, depth.data(), depth.width, depth.height, method, 0, got.data(),
                              got.size(), &count, labels.data(), labels.size()) == PF_OK);
    REQUIRE(count == n_expected);
    CHECK(labels == c.labels.pixels);
    size_t k = 0;
    for (int j = 0; j < core::kNumJoints; ++j)
      for (const auto& p : expected[size_t(j)]) {
        CHECK(got[k].joint == j);
        CHECK(got[k].position_m[0] == p.position.x());
        CHECK(got[k].position_m[2] == p.position.z());
        CHECK(got[k].pixel[1] == p.pixel.y());
        CHECK(got[k].confidence == p.confidence);
        ++k;
      }
    // The C++ API grows its buffer as needed.
    const auto cpp = api::Forest(path).Joints(
        {depth.data(), depth.width, depth.height},
        method == PF_MEAN_SHIFT ? api::Method::kMeanShift : api::Method::kFastClustering);
    REQUIRE(cpp.size() == got.size());
    CHECK(std::memcmp(cpp.data(), got.data(), got.size() * sizeof(pf_joint_proposal)) == 0);
  }

  // A forest with another part table has no joints: the CLI's rule and wording.
  const std::string five = SaveTo(SmallForest(3, 5), "five.pff");
  Loaded g;
  REQUIRE(pf_forest_load_file(five.c_str(), &g.forest) == PF_OK);
  CHECK(pf_forest_has_joints(g.forest) == 0);
  size_t count = 0;
  CHECK(pf_propose_joints(g.forest, depth.data(), depth.width, depth.height, PF_MEAN_SHIFT, 0, nullptr, 0,
                          &count, nullptr, 0) == PF_INVALID_ARGUMENT);
  CHECK(std::string(pf_last_error_message()) ==
        "InvalidArgument: " + five +
            ": joint proposals need a forest with the paper's 31-part taxonomy (this one has 5 parts)");
}

TEST_CASE("skeleton streams equal the runtime's pipeline: ids over frames, joints, the buffer protocol",
          "[api]") {
  // The documented layout (docs/runtime/api.md): 0.4 appended `state` to the 0.3 joint.
  CHECK(sizeof(pf_skeleton_joint) == 36);
  CHECK(offsetof(pf_skeleton_joint, confidence) == 28);
  CHECK(offsetof(pf_skeleton_joint, state) == 32);
  CHECK(sizeof(pf_skeleton) == 596);
  const core::Forest forest = SmallForest(11);
  const std::string path = SaveTo(forest, "skeletons.pff");
  Loaded f;
  REQUIRE(pf_forest_load_file(path.c_str(), &f.forest) == PF_OK);
  // Raw cluttered frames with two people walking (segmented by the stream), as bench/live makes.
  const auto cam = core::CameraIntrinsics::KinectV1();
  testing::ClutterSpec spec;
  spec.floor_y_m = 1.1;
  spec.back_wall_z_m = 4.6;
  spec.boxes.push_back({{0.9, 0.85, 3.0}, {1.6, 1.1, 3.5}});
  std::vector<core::DepthImage> frames;
  for (int k = 0; k < 4; ++k)
    frames.push_back(testing::ComposeScene(cam, spec,
                                           {testing::MakePersonDepth(2.2 + 0.02 * k, 640, 480, -0.7, 0.12),
                                            testing::MakePersonDepth(3.0 - 0.02 * k, 640, 480, 0.6, 0.12)})
                         .depth);

  runtime::SkeletonPipelineOptions options;
  auto pipeline = runtime::SkeletonPipeline::Create(forest, options);
  REQUIRE(pipeline.ok());
  pf_skeleton_stream* stream = nullptr;
  REQUIRE(pf_skeleton_stream_create(f.forest, 0, &stream) == PF_OK);
  REQUIRE(stream != nullptr);
  int found = 0, tracked = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    INFO("frame " << k);
    runtime::Frame frame;
    frame.depth = frames[k];
    frame.timestamp_s = double(k) / 30;
    runtime::SkeletonFrame expected;
    (*pipeline)->Process(frame, &expected);
    REQUIRE(expected.skeletons.size() == 2);  // two people, not the clutter

    size_t count = 99;
    std::vector<pf_skeleton> got(1);  // too small: the frame is kept, fetched with _last
    CHECK(pf_skeleton_stream_process(stream, frames[k].data(), 640, 480, frame.timestamp_s, got.data(),
                                     got.size(), &count) == PF_BUFFER_TOO_SMALL);
    CHECK(std::string(pf_last_error_message()) ==
          "BufferTooSmall: pf_skeleton_stream_process: skeletons holds 1 skeletons, needs 2");
    REQUIRE(count == 2);
    got.resize(count);
    REQUIRE(pf_skeleton_stream_last(stream, got.data(), got.size(), &count) == PF_OK);
    REQUIRE(count == 2);
    for (size_t s = 0; s < count; ++s) {
      const runtime::Skeleton& e = expected.skeletons[s];
      CHECK(got[s].id == e.id);
      CHECK(got[s].id == int(s) + 1);  // the same two ids on every frame
      CHECK(got[s].pixels == e.pixels);
      CHECK(got[s].centroid_m[0] == e.centroid_m.x());
      CHECK(got[s].centroid_m[2] == e.centroid_m.z());
      for (int j = 0; j < PF_SKELETON_JOINTS; ++j) {
        const runtime::SkeletonJoint& ej = e.joints[size_t(j)];
        const pf_skeleton_joint& gj = got[s].joints[j];
        CHECK(gj.found == int(ej.found));
        CHECK(gj.tracked == int(ej.tracked));
        CHECK(gj.position_m[0] == (ej.found ? ej.position_m.x() : 0.0f));
        CHECK(gj.position_m[1] == (ej.found ? ej.position_m.y() : 0.0f));
        CHECK(gj.position_m[2] == (ej.found ? ej.position_m.z() : 0.0f));
        CHECK(gj.pixel[0] == (ej.found ? ej.pixel.x() : 0.0f));
        CHECK(gj.pixel[1] == (ej.found ? ej.pixel.y() : 0.0f));
        CHECK(gj.confidence == (ej.found ? ej.confidence : 0.0f));
        CHECK(gj.confidence >= 0.0f);
        CHECK(gj.confidence <= 1.0f);
        CHECK(gj.state == int32_t(runtime::StateOf(ej)));
        CHECK((gj.state == PF_JOINT_TRACKED) == (gj.tracked == 1));
        CHECK((gj.state != PF_JOINT_INFERRED || (gj.found == 1 && gj.tracked == 0)));
        found += gj.found;
        tracked += gj.tracked;
      }
    }
  }
  CHECK(found > 0);
  INFO("tracked joints over the frames: " << tracked);
  // An empty frame: no people; no buffer needed.
  const std::vector<uint16_t> empty(640 * 480, 0);
  size_t count = 5;
  CHECK(pf_skeleton_stream_process(stream, empty.data(), 640, 480, 1.0, nullptr, 0, &count) == PF_OK);
  CHECK(count == 0);
  CHECK(pf_skeleton_stream_last(stream, nullptr, 0, &count) == PF_OK);
  CHECK(count == 0);

  // Bad arguments: a status and a message, never a crash.
  CHECK(pf_skeleton_stream_process(stream, nullptr, 640, 480, 0.0, nullptr, 0, &count) ==
        PF_INVALID_ARGUMENT);
  CHECK(std::string(pf_last_error_message()) ==
        "InvalidArgument: pf_skeleton_stream_process: depth_mm is NULL");
  CHECK(pf_skeleton_stream_process(stream, empty.data(), 0, 480, 0.0, nullptr, 0, &count) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_process(stream, empty.data(), 640, 480, std::nan(""), nullptr, 0, &count) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_process(stream, empty.data(), 640, 480, 0.0, nullptr, 3, &count) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_process(nullptr, empty.data(), 640, 480, 0.0, nullptr, 0, &count) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_process(stream, empty.data(), 640, 480, 0.0, nullptr, 0, nullptr) ==
        PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_last(nullptr, nullptr, 0, &count) == PF_INVALID_ARGUMENT);
  pf_skeleton_stream_free(stream);
  pf_skeleton_stream_free(nullptr);
  pf_skeleton_stream* none = nullptr;
  CHECK(pf_skeleton_stream_create(nullptr, 0, &none) == PF_INVALID_ARGUMENT);
  CHECK(none == nullptr);
  CHECK(pf_skeleton_stream_create(f.forest, -1, &none) == PF_INVALID_ARGUMENT);
  CHECK(pf_skeleton_stream_create(f.forest, 0, nullptr) == PF_INVALID_ARGUMENT);

  // A forest with another part table has no skeletons.
  const std::string five = SaveTo(SmallForest(3, 5), "five-skeletons.pff");
  Loaded g;
  REQUIRE(pf_forest_load_file(five.c_str(), &g.forest) == PF_OK);
  CHECK(pf_skeleton_stream_create(g.forest, 0, &none) == PF_INVALID_ARGUMENT);
  CHECK(none == nullptr);
  CHECK(std::string(pf_last_error_message()) ==
        "InvalidArgument: " + five +
            ": skeletons need a forest with the paper's 31-part taxonomy (this one has 5 parts)");
}

TEST_CASE("skeleton joints carry their state: tracked, inferred, not tracked", "[api]") {
  CHECK(PF_JOINT_NOT_TRACKED == 0);
  CHECK(PF_JOINT_INFERRED == 1);
  CHECK(PF_JOINT_TRACKED == 2);
  CHECK(std::string(pf_joint_state_name(PF_JOINT_NOT_TRACKED)) == "not_tracked");
  CHECK(std::string(pf_joint_state_name(PF_JOINT_INFERRED)) == "inferred");
  CHECK(std::string(pf_joint_state_name(PF_JOINT_TRACKED)) == "tracked");
  CHECK(pf_joint_state_name(-1) == nullptr);
  CHECK(pf_joint_state_name(3) == nullptr);
  // A skeleton made by hand, one joint in each state, in the C layout the streams write (a
  // stream gives inferred joints only with a forest that has offset votes).
  const runtime::Skeleton s = testing::FourStateSkeleton();
  const pf_skeleton c = capi::ToPfSkeleton(s);
  CHECK(c.id == 3);
  CHECK(c.pixels == 1200);
  const pf_skeleton_joint& tracked = c.joints[testing::kTrackedJoint];
  CHECK((tracked.found == 1 && tracked.tracked == 1 && tracked.state == PF_JOINT_TRACKED));
  CHECK(tracked.confidence == 0.875f);
  const pf_skeleton_joint& inferred = c.joints[testing::kInferredJoint];
  CHECK((inferred.found == 1 && inferred.tracked == 0 && inferred.state == PF_JOINT_INFERRED));
  CHECK(inferred.position_m[2] == 2.875f);
  CHECK(inferred.pixel[0] == 339.5f);
  CHECK(inferred.confidence == 0.75f);
  const pf_skeleton_joint& found_only = c.joints[testing::kFoundOnlyJoint];
  CHECK((found_only.found == 1 && found_only.tracked == 0 && found_only.state == PF_JOINT_NOT_TRACKED));
  const pf_skeleton_joint& lost = c.joints[testing::kNotFoundJoint];
  CHECK((lost.found == 0 && lost.tracked == 0 && lost.state == PF_JOINT_NOT_TRACKED));
  CHECK((lost.position_m[0] == 0.0f && lost.pixel[0] == 0.0f && lost.confidence == 0.0f));
  int states[3] = {0, 0, 0};
  for (const pf_skeleton_joint& j : c.joints) ++states[j.state];
  CHECK(states[PF_JOINT_TRACKED] == 1);
  CHECK(states[PF_JOINT_INFERRED] == 1);
  CHECK(states[PF_JOINT_NOT_TRACKED] == PF_SKELETON_JOINTS - 2);
  // The name the JSON Lines record gives each state.
  for (const pf_skeleton_joint& j : c.joints)
    CHECK(std::string(pf_joint_state_name(j.state)) ==
          std::string(runtime::JointStateName(runtime::JointState(j.state))));
}

TEST_CASE("many threads classify with one forest at once", "[api]") {
  const std::string path = SaveTo(SmallForest(13), "threads.pff");
  const api::Forest forest(path);
  const core::DepthImage depth = testing::MakePersonDepth(2.5);
  const auto reference = forest.Classify({depth.data(), depth.width, depth.height}, true, 1);
  std::vector<int> equal(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int i = 0; i < 3; ++i) {
        const auto c = forest.Classify({depth.data(), depth.width, depth.height}, true, 1);
        equal[size_t(t)] += c.labels == reference.labels && c.distributions == reference.distributions;
      }
    });
  for (auto& t : threads) t.join();
  CHECK(equal == std::vector<int>(4, 3));
}

TEST_CASE("docs/runtime/api.md names every function and type of the public headers, and no others",
          "[api][docs]") {
  const fs::path src = POSEFOREST_SOURCE_DIR;
  const std::string header = Slurp(src / "runtime/api/include/poseforest/poseforest.h");
  std::string cpp = Slurp(src / "runtime/api/include/poseforest/poseforest.hpp");
  // Private members are not the API.
  for (size_t p; (p = cpp.find(" private:")) != std::string::npos;) cpp.erase(p, cpp.find("};", p) - p);
  const std::string doc = Slurp(src / "docs/runtime/api.md");
  REQUIRE_FALSE(header.empty());
  REQUIRE_FALSE(doc.empty());

  std::set<std::string> declared;
  const std::regex fn(R"(PF_API[^;(]*\b(pf_\w+)\s*\()");
  for (auto it = std::sregex_iterator(header.begin(), header.end(), fn); it != std::sregex_iterator(); ++it)
    declared.insert((*it)[1]);
  CHECK(declared.size() >= 15);
  for (const std::string& name : declared) {
    INFO("exported function " << name << " is not in docs/runtime/api.md");
    CHECK(doc.find("`" + name + "`") != std::string::npos);
  }
  // Every pf_ function the page mentions exists (no stale names).
  const std::regex mentioned(R"(\b(pf_[a-z_]+)\s*\()");
  std::set<std::string> types = {"pf_status", "pf_forest", "pf_joint_proposal", "pf_proposal_method"};
  for (auto it = std::sregex_iterator(doc.begin(), doc.end(), mentioned); it != std::sregex_iterator();
       ++it) {
    INFO("docs/runtime/api.md mentions " << (*it)[1] << "(), which poseforest.h does not declare");
    CHECK((declared.count((*it)[1]) == 1 || types.count((*it)[1]) == 1));
  }
  for (const std::string& t : types) {
    INFO("type " << t);
    const bool typedefd = header.find("typedef struct " + t) != std::string::npos ||
                          header.find("typedef enum " + t) != std::string::npos;
    CHECK(typedefd);
    CHECK(doc.find(t) != std::string::npos);
  }
  // The C++ API's classes and functions.
  const std::regex cpp_names(
      R"((?:class|struct|enum class) (\w+)|\n  [\w:<>,*& ]+ (\w+)\([^)]*\) const|inline [\w:<>]+ (\w+)\(|static \w+ (\w+)\()");
  std::set<std::string> cpp_declared;
  for (auto it = std::sregex_iterator(cpp.begin(), cpp.end(), cpp_names); it != std::sregex_iterator(); ++it)
    for (int g = 1; g <= 4; ++g)
      if ((*it)[g].matched) cpp_declared.insert((*it)[g]);
  for (const char* must : {"Forest", "Error", "Classification", "DepthView", "Method", "Classify", "Joints",
                           "FromMemory", "Version", "JointNames"})
    CHECK(cpp_declared.count(must) == 1);
  for (const std::string& name : cpp_declared) {
    INFO("C++ API name " << name << " is not in docs/runtime/api.md");
    CHECK(doc.find(name) != std::string::npos);
  }
}

TEST_CASE("the README's snippets of the runtime library are lines of the tested examples", "[api][docs]") {
  const fs::path src = POSEFOREST_SOURCE_DIR;
  const std::string readme = Slurp(src / "README.md");
  const size_t begin = readme.find("\n## Use the runtime from your program");
  REQUIRE(begin != std::string::npos);
  const std::string section = readme.substr(begin, readme.find("\n## ", begin + 1) - begin);
  auto trim = [](std::string l) {
    l.erase(0, l.find_first_not_of(" \t"));
    l.erase(l.find_last_not_of(" \t\r") + 1);
    return l;
  };
  auto lines = [&](const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) out.push_back(trim(l));
    return out;
  };
  int blocks = 0;
  const std::regex fence("```\\w*\\n(?:#|//) (examples/[\\w.]+)\\n([\\s\\S]*?)```");
  for (auto it = std::sregex_iterator(section.begin(), section.end(), fence); it != std::sregex_iterator();
       ++it) {
    const std::string file = (*it)[1];
    const auto have = lines(Slurp(src / file));
    REQUIRE_FALSE(have.empty());
    for (const std::string& line : lines((*it)[2])) {
      if (line.empty()) continue;
      INFO("README snippet line not in " << file << ": " << line);
      CHECK(std::find(have.begin(), have.end(), line) != have.end());
    }
    ++blocks;
  }
  CHECK(blocks == 3);  // CMake, C, Python (the Makefile and the C++ example are named beside them)
}
