// `poseforest live --dds` read as a ROS 2 node would: a real DDS participant subscribes to both
// topics with the ROS 2 type names and keeps the serialized samples as they came off the wire;
// Node.js then decodes them with Foxglove's ROS 2 CDR reader (@foxglove/rosmsg2-serialization),
// its ROS 2 Humble definitions (@foxglove/rosmsg-msgs-common) and our shipped msg/*.msg parsed by
// @foxglove/rosmsg, and every field must equal the JSON Lines of the same frames
// (ros2_decode.js). The npm packages are installed into the build folder on first use.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "apps/ros2/ros2_messages.h"
#include "apps/ros2/skeleton_publisher.h"
#include "runtime/core/forest_format.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/skeletons.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

void WriteBytes(const fs::path& path, const std::vector<uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

// ros2_decode.js on the samples in `dir` (skeletons-K.bin, markers-K.bin) against the JSON Lines
// `jsonl`, with Foxglove's decoders, installed into the build folder once (the npm registry must
// be reachable). Its exit code and printout ("ok frames=..." or the mismatches).
testing::CommandResult DecodeWithFoxglove(const fs::path& dir, const fs::path& jsonl,
                                          const std::string& frame_id) {
  const std::string modules = std::string(POSEFOREST_NPM_DIR);
  if (!fs::exists(fs::path(modules) / "node_modules/@foxglove/rosmsg2-serialization")) {
    auto npm = testing::RunCommand(
        "mkdir -p " + modules + " && cd " + modules +
        " && npm install --no-audit --no-fund --loglevel=error "
        "@foxglove/rosmsg2-serialization@3 @foxglove/rosmsg-msgs-common@3 @foxglove/rosmsg@5");
    INFO(npm.output);
    REQUIRE(npm.exit_code == 0);
  }
  return testing::RunCommand("NODE_PATH=" + modules + "/node_modules node " +
                             std::string(POSEFOREST_SOURCE_DIR) + "/tests/runtime/ros2_decode.js " +
                             dir.string() + " " + jsonl.string() + " " + std::string(POSEFOREST_SOURCE_DIR) +
                             "/msg " + frame_id);
}

}  // namespace

TEST_CASE("live --dds: the samples off the wire, decoded by Foxglove's ROS 2 decoders, equal the JSON Lines",
          "[live][dds]") {
  const auto dir = testing::ScratchDir("live-dds");
  const fs::path forest = dir / "f.pff";
  REQUIRE(core::SaveForest(testing::MakeRandomForest({.seed = 5, .max_depth = 10, .nodes_per_tree = 2000}),
                           forest.string())
              .ok());
  const int domain = 100 + int(::getpid() % 100);
  auto skeletons = apps::ros2::RawSampleCapture::Create(domain, "rt/pftest/skeletons",
                                                           apps::ros2::kSkeletonsTypeName);
  auto markers = apps::ros2::RawSampleCapture::Create(domain, "rt/pftest/markers",
                                                         apps::ros2::kMarkerArrayTypeName);
  REQUIRE(skeletons.ok());
  REQUIRE(markers.ok());
  // Every joint found is tracked-or-not by the rules; --min-confidence 0 keeps more of the random
  // forest's joints tracked, so the markers have points.
  auto run = testing::RunPoseforest(
      "live --forest " + forest.string() + " --source '" +
      (testing::DataDir() / "real/skeltrack_kinect_depth").string() +
      "/depth-data-*' --threads 2 --dds --dds-domain " + std::to_string(domain) +
      " --dds-topic pftest --dds-frame-id test_camera --dds-wait 1 --min-confidence 0 --jsonl " +
      (dir / "frames.jsonl").string());
  INFO(run.output);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("rt/pftest/skeletons (poseforest_msgs::msg::dds_::Skeletons_)"));
  const auto s = (*skeletons)->Wait(9, 20);
  const auto m = (*markers)->Wait(9, 20);
  REQUIRE(s.size() == 9);
  REQUIRE(m.size() == 9);
  for (size_t k = 0; k < 9; ++k) {
    CHECK(s[k][0] == 0x00);  // CDR_LE encapsulation, as rmw_fastrtps writes
    CHECK(s[k][1] == 0x01);
    WriteBytes(dir / ("skeletons-" + std::to_string(k) + ".bin"), s[k]);
    WriteBytes(dir / ("markers-" + std::to_string(k) + ".bin"), m[k]);
  }
  const auto decode = DecodeWithFoxglove(dir, dir / "frames.jsonl", "test_camera");
  const std::string& decoded = decode.output;
  INFO(decoded);
  REQUIRE(decode.exit_code == 0);
  CHECK_THAT(decoded, Catch::Contains("ok frames=9 people=9 joints=144"));
  int points = 0;
  const auto at = decoded.find("marker_points=");
  REQUIRE(at != std::string::npos);
  points = std::atoi(decoded.c_str() + at + 14);
  CHECK(points > 0);
}

TEST_CASE("ROS 2 messages carry each joint's state; inferred joints are their own paler markers",
          "[live][dds]") {
  // Made by hand, one joint in each state (tracked, inferred, found not tracked, not found), and
  // a second person with no inferred joint (so no inferred marker); encoded as `live --dds`
  // publishes and checked by the same decoders against the JSON Lines record.
  const auto dir = testing::ScratchDir("ros2-states");
  runtime::Skeleton first = testing::FourStateSkeleton();
  runtime::Skeleton second = testing::FourStateSkeleton();
  second.id = 4;
  second.joints[size_t(testing::kInferredJoint)].inferred = false;  // found, not tracked
  const std::vector<runtime::Skeleton> people = {first, second};
  const apps::ros2::FrameStamp stamp{5, 1.25, "by hand", "test_camera"};
  WriteBytes(dir / "skeletons-0.bin", apps::ros2::EncodeSkeletons(stamp, people));
  WriteBytes(dir / "markers-0.bin", apps::ros2::EncodeMarkerArray(stamp, people));
  std::ofstream(dir / "frames.jsonl")
      << runtime::SkeletonsJsonLine(stamp.index, stamp.time_s, stamp.source, people) << "\n";
  const auto decode = DecodeWithFoxglove(dir, dir / "frames.jsonl", "test_camera");
  INFO(decode.output);
  REQUIRE(decode.exit_code == 0);
  // Two people: 2 tracked heads, 1 inferred knee; spheres: 2 heads + 1 inferred knee, no bones.
  CHECK_THAT(decode.output,
             Catch::Contains("ok frames=1 people=2 joints=32 marker_points=3 tracked=2 inferred=1"));

  // The decoder reads the state: a message whose knee is not inferred disagrees with the record.
  first.joints[size_t(testing::kInferredJoint)].inferred = false;
  WriteBytes(dir / "skeletons-0.bin", apps::ros2::EncodeSkeletons(stamp, {first, second}));
  const auto wrong = DecodeWithFoxglove(dir, dir / "frames.jsonl", "test_camera");
  INFO(wrong.output);
  CHECK(wrong.exit_code != 0);
  CHECK_THAT(wrong.output, Catch::Contains("L_knee: state 0 vs inferred"));
}

TEST_CASE("ROS 2 encoding: XCDR1 little endian, alignment padding written as zeros", "[dds][ros2]") {
  // A frame with no people, every field by hand: the padding before the int64 and the double
  // must be zeros (Fast CDR skips it; the encoder zero-fills), so the bytes depend on the message
  // alone.
  apps::ros2::FrameStamp st;
  st.index = 7;
  st.time_s = 2.5;
  st.source = "ab";
  st.frame_id = "f";
  const std::vector<uint8_t> expected = {
      0x00, 0x01, 0x00, 0x00,                          // encapsulation: CDR_LE, options 0
      0x02, 0x00, 0x00, 0x00,                          // header.stamp.sec = 2
      0x00, 0x65, 0xcd, 0x1d,                          // header.stamp.nanosec = 5e8
      0x02, 0x00, 0x00, 0x00, 'f', 0x00,               // header.frame_id "f"
      0x00, 0x00,                                      // padding to 8
      0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // index = 7
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x04, 0x40,  // time_s = 2.5
      0x03, 0x00, 0x00, 0x00, 'a',  'b',  0x00,        // source "ab"
      0x00,                                            // padding to 4
      0x00, 0x00, 0x00, 0x00};                         // people: 0
  CHECK(apps::ros2::EncodeSkeletons(st, {}) == expected);
  // Larger messages (each joint's bool, bool, float: padding after every joint): two encodings
  // of the same frame are the same bytes, and every byte between fields is zero.
  std::vector<runtime::Skeleton> people(2);
  for (size_t k = 0; k < people.size(); ++k) {
    people[k].id = int(k) + 1;
    for (int j = 0; j < core::kNumJoints; ++j) {
      people[k].joints[size_t(j)].found = (j + int(k)) % 3 != 0;
      people[k].joints[size_t(j)].tracked = j % 2 == 0 && people[k].joints[size_t(j)].found;
      people[k].joints[size_t(j)].confidence = 0.5f;
    }
  }
  const auto a = apps::ros2::EncodeMarkerArray(st, people), b = apps::ros2::EncodeMarkerArray(st, people);
  CHECK(a == b);
  CHECK(apps::ros2::EncodeSkeletons(st, people) == apps::ros2::EncodeSkeletons(st, people));
}
