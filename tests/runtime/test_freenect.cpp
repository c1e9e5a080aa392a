// The libfreenect back end against libfreenect's own replay library (fakenect), nothing mocked:
// the project writes fakenect recordings (from the real Kinect frames and from synthetic frames),
// then `poseforest` reads them through libfreenect's API with fakenect's library in place
// (LD_LIBRARY_PATH + FAKENECT_PATH, as Debian's `fakenect` wrapper does). Also: a truncated frame
// file, the end of a recording, a device that stops sending, and no device at all.
#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>

#include "apps/devices/fakenect_recording.h"
#include "runtime/core/forest_format.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

std::string Fakenect(const fs::path& recording) {
  return "LD_LIBRARY_PATH=" + std::string(POSEFOREST_FAKENECT_LIB_DIR) +
         " FAKENECT_PATH=" + recording.string() + " ";
}

std::string Bin() { return (testing::BinDir() / "poseforest").string(); }

std::vector<std::string> RealFrames() {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(testing::DataDir() / "real/skeltrack_kinect_depth"))
    if (e.path().filename().string().rfind("depth-data-", 0) == 0) out.push_back(e.path().string());
  std::sort(out.begin(), out.end());
  return out;
}

// What a frame becomes after the Kinect's disparity encoding and back.
core::DepthImage ThroughDisparity(const core::DepthImage& d) {
  core::DepthImage out = d;
  for (uint16_t& v : out.pixels) v = apps::devices::KinectDisparityToMm(apps::devices::MmToKinectDisparity(v));
  return out;
}

core::DepthImage ReadPng(const fs::path& p) {
  runtime::FrameSourceOptions o;
  auto d = runtime::ReadDepthFile(p.string(), o);
  REQUIRE(d.ok());
  return *d;
}

}  // namespace

TEST_CASE("Kinect disparity <-> mm: nearest value, within the Kinect's quantization", "[freenect]") {
  CHECK(apps::devices::KinectDisparityToMm(apps::devices::kKinectNoDisparity) == 0);
  CHECK(apps::devices::MmToKinectDisparity(0) == apps::devices::kKinectNoDisparity);
  for (int mm = 500; mm <= 4500; mm += 7) {
    const uint16_t back = apps::devices::KinectDisparityToMm(apps::devices::MmToKinectDisparity(uint16_t(mm)));
    const double step = double(mm) * mm * 0.0030711016 / 1000.0;  // dz per disparity unit, mm
    INFO(mm << " mm -> " << back << " mm (step " << step << ")");
    CHECK(std::abs(int(back) - mm) <= int(step / 2 + 1));
  }
}

TEST_CASE("the 9 real Kinect frames through a fakenect recording and libfreenect's API come back as written",
          "[freenect][data]") {
  const auto dir = testing::ScratchDir("freenect-real");
  const auto frames = RealFrames();
  REQUIRE(frames.size() == 9);
  std::string list;
  for (const auto& f : frames) list += " " + f;
  auto rec = testing::RunCommand(Bin() + " frames --quiet --fakenect " + (dir / "rec").string() +
                                 " --record-fps 200" + list);
  INFO(rec.output);
  REQUIRE(rec.exit_code == 0);
  REQUIRE(fs::exists(dir / "rec" / "INDEX.txt"));
  // fakenect replays at the recording's own pace: --record-fps 200 spaces the depth frames 5 ms
  // apart (the time is in each name: d-SECONDS-...).
  {
    std::ifstream in(dir / "rec" / "INDEX.txt");
    std::vector<double> times;
    for (std::string line; std::getline(in, line);)
      if (line.rfind("d-", 0) == 0) times.push_back(std::stod(line.substr(2)));
    REQUIRE(times.size() == 9);
    for (size_t k = 1; k < times.size(); ++k) CHECK(std::abs(times[k] - times[k - 1] - 0.005) < 1e-6);
  }

  auto play = testing::RunCommand(Fakenect(dir / "rec") + Bin() + " frames freenect:0 --out-dir " +
                                  (dir / "out").string());
  INFO(play.output);
  REQUIRE(play.exit_code == 0);  // the recording's end is a clean end of stream
  CHECK_THAT(play.output,
             Catch::Contains("fakenect recording") && Catch::Contains("9 frame(s), 0 bad frame(s)"));
  for (size_t k = 0; k < frames.size(); ++k) {
    runtime::FrameSourceOptions o;
    const auto original = runtime::ReadDepthFile(frames[k], o);
    REQUIRE(original.ok());
    char name[32];
    std::snprintf(name, sizeof name, "frame-%06zu.png", k);
    const auto read = ReadPng(dir / "out" / name);
    INFO(frames[k]);
    CHECK(read.pixels == ThroughDisparity(*original).pixels);
    CHECK(core::CountForeground(read) == core::CountForeground(*original));
  }

  // `live` on the same stream: one JSON Lines record per frame, each with the person.
  REQUIRE(core::SaveForest(testing::MakeRandomForest({.max_depth = 8, .nodes_per_tree = 500}),
                           (dir / "f.pff").string())
              .ok());
  auto live =
      testing::RunCommand(Fakenect(dir / "rec") + Bin() + " live --forest " + (dir / "f.pff").string() +
                          " --source freenect:0 --threads 2 --jsonl " + (dir / "live.jsonl").string());
  INFO(live.output);
  REQUIRE(live.exit_code == 0);
  CHECK_THAT(live.output, Catch::Contains("end of source: 9 frames") && Catch::Contains("fakenect"));
  std::ifstream jsonl(dir / "live.jsonl");
  int lines = 0;
  for (std::string line; std::getline(jsonl, line); ++lines) {
    CHECK_THAT(line, Catch::StartsWith("{\"index\":" + std::to_string(lines) + ",") &&
                         Catch::Contains("\"source\":\"freenect:0\"") && Catch::Contains("{\"id\":1,"));
  }
  CHECK(lines == 9);

  // The same command without fakenect's library runs the real libfreenect: no Kinect here.
  auto real = testing::RunCommand("FAKENECT_PATH= " + Bin() + " frames freenect:0");
  CHECK(real.exit_code == 1);
  CHECK_THAT(real.output, Catch::Contains("freenect:0: no Kinect v1 found (libfreenect sees 0 device(s))"));
  fs::remove_all(dir);
}

TEST_CASE("synthetic frames replayed through fakenect; infer runs on the stream", "[freenect]") {
  const auto dir = testing::ScratchDir("freenect-synth");
  std::vector<core::DepthImage> frames;
  for (double z : {1.5, 2.0, 2.5, 3.0, 3.5})
    frames.push_back(testing::MakePersonDepth(z, 640, 480, 0.1 * z - 0.25));
  REQUIRE(apps::devices::WriteFakenectRecording((dir / "rec").string(), frames, 100.0).ok());
  // A second write into the same folder is refused, like fakenect-record.
  CHECK_FALSE(apps::devices::WriteFakenectRecording((dir / "rec").string(), frames, 100.0).ok());
  auto play = testing::RunCommand(Fakenect(dir / "rec") + Bin() + " frames freenect:0 --npy " +
                                  (dir / "read.npy").string());
  INFO(play.output);
  REQUIRE(play.exit_code == 0);
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource((dir / "read.npy").string(), o);
  REQUIRE(src.ok());
  runtime::Frame f;
  for (const auto& expected : frames) {
    REQUIRE(*(*src)->Next(&f));
    CHECK(f.depth.pixels == ThroughDisparity(expected).pixels);
  }
  CHECK_FALSE(*(*src)->Next(&f));

  const core::Forest forest = testing::MakeRandomForest({.max_depth = 8, .nodes_per_tree = 500});
  REQUIRE(core::SaveForest(forest, (dir / "f.pff").string()).ok());
  auto infer =
      testing::RunCommand(Fakenect(dir / "rec") + Bin() + " infer --forest " + (dir / "f.pff").string() +
                          " --out-dir " + (dir / "parts").string() + " --source freenect:0");
  INFO(infer.output);
  CHECK(infer.exit_code == 0);
  CHECK_THAT(infer.output, Catch::Contains("5 frame(s) classified, 0 bad frame(s) skipped"));
  CHECK(fs::exists(dir / "parts" / "freenect_0-000004.parts.png"));
  fs::remove_all(dir);
}

TEST_CASE("a truncated frame file in a recording is named, skipped and counted; the rest replays",
          "[freenect]") {
  const auto dir = testing::ScratchDir("freenect-cut");
  std::vector<core::DepthImage> frames;
  for (double z : {1.5, 2.0, 2.5, 3.0}) frames.push_back(testing::MakePersonDepth(z));
  REQUIRE(apps::devices::WriteFakenectRecording((dir / "rec").string(), frames, 100.0).ok());
  std::vector<std::string> index;
  {
    std::ifstream in(dir / "rec" / "INDEX.txt");
    for (std::string line; std::getline(in, line);) index.push_back(line);
  }
  REQUIRE(index.size() == 4);
  fs::resize_file(dir / "rec" / index[2], 100000);  // frame 2 cut short
  auto play = testing::RunCommand(Fakenect(dir / "rec") + Bin() + " frames freenect:0 --npy " +
                                  (dir / "read.npy").string());
  INFO(play.output);
  CHECK(play.exit_code == 1);
  CHECK_THAT(play.output, Catch::Contains("freenect:0 frame 2") && Catch::Contains(index[2]) &&
                              Catch::Contains("truncated: 100000 of 614417 bytes") &&
                              Catch::Contains("3 frame(s), 1 bad frame(s) skipped"));
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource((dir / "read.npy").string(), o);
  REQUIRE(src.ok());
  runtime::Frame f;
  for (int k : {0, 1, 3}) {
    REQUIRE(*(*src)->Next(&f));
    CHECK(f.depth.pixels == ThroughDisparity(frames[size_t(k)]).pixels);
  }
  // The recording itself is left as it was (fakenect replayed a filtered copy of the index).
  CHECK(fs::file_size(dir / "rec" / index[2]) == 100000);
  fs::remove_all(dir);
}

TEST_CASE("a device that stops sending mid-stream is reported as lost; nothing hangs", "[freenect]") {
  const auto dir = testing::ScratchDir("freenect-lost");
  std::vector<core::DepthImage> frames;
  for (double z : {1.5, 2.0, 2.5}) frames.push_back(testing::MakePersonDepth(z));
  REQUIRE(apps::devices::WriteFakenectRecording((dir / "rec").string(), frames, 100.0).ok());
  // The third frame arrives 3 s after the second: fakenect replays that silence faithfully.
  std::vector<std::string> index;
  {
    std::ifstream in(dir / "rec" / "INDEX.txt");
    for (std::string line; std::getline(in, line);) index.push_back(line);
  }
  const std::string late = "d-1700000003.020000-9999999.pgm";
  fs::rename(dir / "rec" / index[2], dir / "rec" / late);
  index[2] = late;
  {
    std::ofstream out(dir / "rec" / "INDEX.txt");
    for (const auto& l : index) out << l << '\n';
  }
  // The reader gives up 0.5 s after frame 1 and so never sees the third frame: a reader that waited
  // out the 3 s silence would count 3 frames and no lost device.
  auto play = testing::RunCommand(Fakenect(dir / "rec") + Bin() + " frames freenect:0,timeout=0.5");
  INFO(play.output);
  CHECK(play.exit_code == 1);
  CHECK_THAT(play.output, Catch::Contains("freenect:0: device lost: no frame for 0.5 s after frame 1") &&
                              Catch::Contains("2 frame(s), 1 bad frame(s) skipped"));
  fs::remove_all(dir);
}
