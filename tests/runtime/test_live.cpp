// `poseforest live` as a user runs it: the real program on the real Kinect frames
// (shared/data/real) and the PCL person cloud, JSON Lines checked by Python's json module, the
// pictures decoded, a clean stop on SIGTERM / SIGINT with its summary, usage errors, and the
// live page in headless Chromium. The forest is a random one (the frames' skeletons are then
// arbitrary but every rule of the output holds); docs/runtime/live.md shows a trained one's.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

std::string Bin() { return (testing::BinDir() / "poseforest").string(); }

std::string RealFrames() {
  return "'" + (testing::DataDir() / "real/skeltrack_kinect_depth").string() + "/depth-data-*'";
}

fs::path Forest(const fs::path& dir, int parts = core::kNumParts) {
  core::Forest forest =
      testing::MakeRandomForest({.seed = 5, .max_depth = 10, .nodes_per_tree = 2000, .num_parts = parts});
  const fs::path path = dir / (parts == core::kNumParts ? "f.pff" : "other.pff");
  REQUIRE(core::SaveForest(forest, path.string()).ok());
  return path;
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Python's json module reads every line and checks the schema of docs/runtime/live.md; prints
// "ok FRAMES PEOPLE TRACKED" or the first violation.
constexpr const char* kSchemaCheck = R"PY(
import json, sys
names = ["head","neck","L_shoulder","R_shoulder","L_elbow","R_elbow","L_wrist","R_wrist","L_hand","R_hand",
         "L_knee","R_knee","L_ankle","R_ankle","L_foot","R_foot"]
frames = people = tracked = 0
last_index = -1
for n, line in enumerate(open(sys.argv[1])):
    f = json.loads(line)
    assert set(f) == {"index", "time_s", "source", "people"}, f.keys()
    assert isinstance(f["index"], int) and f["index"] == last_index + 1, (n, f["index"])
    last_index = f["index"]
    assert isinstance(f["time_s"], float) and isinstance(f["source"], str)
    ids = [p["id"] for p in f["people"]]
    assert ids == sorted(set(ids)) and all(i >= 1 for i in ids), ids
    for p in f["people"]:
        assert set(p) == {"id", "pixels", "centroid_m", "joints"}, p.keys()
        assert p["pixels"] > 0 and len(p["centroid_m"]) == 3 and p["centroid_m"][2] > 0
        assert [j["name"] for j in p["joints"]] == names
        for j in p["joints"]:
            assert set(j) == {"name", "position_m", "pixel", "confidence", "tracked", "state"}, j.keys()
            assert 0.0 <= j["confidence"] <= 1.0 and isinstance(j["tracked"], bool)
            assert j["state"] in ("tracked", "inferred", "not_tracked"), j["state"]
            assert (j["state"] == "tracked") == j["tracked"], (j["name"], j["state"], j["tracked"])
            if j["position_m"] is None:
                assert j["pixel"] is None and not j["tracked"] and j["confidence"] == 0
                assert j["state"] == "not_tracked", (j["name"], j["state"])
            else:
                assert len(j["position_m"]) == 3 and len(j["pixel"]) == 2 and j["position_m"][2] > 0
            tracked += j["tracked"]
        people += 1
    frames += 1
print("ok", frames, people, tracked)
)PY";

std::string CheckJsonl(const fs::path& dir, const fs::path& jsonl) {
  const fs::path script = dir / "schema.py";
  std::ofstream(script) << kSchemaCheck;
  auto r = testing::RunCommand("python3 " + script.string() + " " + jsonl.string());
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  return r.output;
}

}  // namespace

TEST_CASE("live --help, and usage errors that name the problem", "[live]") {
  const auto dir = testing::ScratchDir("live-usage");
  auto help = testing::RunPoseforest("live --help");
  CHECK(help.exit_code == 0);
  CHECK_THAT(help.output, Catch::Contains("--jsonl") && Catch::Contains("--png-dir") &&
                              Catch::Contains("--http") && Catch::Contains("--smooth") &&
                              Catch::Contains("SIGINT"));
  CHECK_THAT(testing::RunPoseforest("help").output, Catch::Contains("live"));
  auto none = testing::RunPoseforest("live --source x");
  CHECK(none.exit_code == 2);
  CHECK_THAT(none.output, Catch::Contains("--forest is required"));
  const auto forest = Forest(dir).string();
  auto no_source = testing::RunPoseforest("live --forest " + forest);
  CHECK(no_source.exit_code == 2);
  CHECK_THAT(no_source.output, Catch::Contains("no source"));
  auto seg = testing::RunPoseforest("live --forest " + forest + " --source x --segment maybe");
  CHECK(seg.exit_code == 2);
  CHECK_THAT(seg.output, Catch::Contains("--segment must be auto, on or off"));
  auto beta = testing::RunPoseforest("live --forest " + forest + " --source x --smooth-beta 2");
  CHECK(beta.exit_code == 2);
  CHECK_THAT(beta.output, Catch::Contains("need --smooth"));
  auto conf = testing::RunPoseforest("live --forest " + forest + " --source x --min-confidence 2");
  CHECK(conf.exit_code == 2);
  CHECK_THAT(conf.output, Catch::Contains("--min-confidence"));
#ifndef POSEFOREST_TEST_HAS_DDS
  // Without Fast DDS (the runtime-only build), --dds is a usage error that says why.
  auto dds = testing::RunPoseforest("live --forest " + forest + " --source x --dds");
  CHECK(dds.exit_code == 2);
  CHECK_THAT(dds.output, Catch::Contains("built without Fast DDS"));
#endif
  auto dds_flag = testing::RunPoseforest("live --forest " + forest + " --source x --dds-domain 3");
  CHECK(dds_flag.exit_code == 2);
  CHECK_THAT(dds_flag.output, Catch::Contains("--dds-domain"));
  auto missing = testing::RunPoseforest("live --forest " + forest + " --source " + (dir / "nope").string());
  CHECK(missing.exit_code == 1);
  CHECK_THAT(missing.output, Catch::Contains("nope"));
  // A forest without the paper's parts has no joints.
  auto other =
      testing::RunPoseforest("live --forest " + Forest(dir, 3).string() + " --source " + RealFrames());
  CHECK(other.exit_code == 1);
  CHECK_THAT(other.output, Catch::Contains("31-part") && Catch::Contains("3 parts"));
}

TEST_CASE(
    "live on the 9 real Kinect frames: JSON Lines by the schema, the same on stdout, pictures with bones",
    "[live][data]") {
  const auto dir = testing::ScratchDir("live-real");
  const auto forest = Forest(dir).string();
  auto run = testing::RunPoseforest("live --forest " + forest + " --source " + RealFrames() +
                                    " --threads 2 --jsonl " + (dir / "out.jsonl").string() + " --png-dir " +
                                    (dir / "png").string());
  INFO(run.output);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("end of source: 9 frames") && Catch::Contains("latency p50") &&
                             Catch::Contains("uncalibrated fallback") && Catch::Contains("people seen"));
  const std::string ok = CheckJsonl(dir, dir / "out.jsonl");
  CHECK_THAT(ok, Catch::StartsWith("ok 9 9 "));  // one person in each frame
  // Deterministic: the same records on stdout (progress and summary go to stderr).
  auto stdout_run = testing::RunCommand("(" + Bin() + " live --quiet --forest " + forest + " --source " +
                                        RealFrames() + " --threads 2 --jsonl - 2>/dev/null)");
  REQUIRE(stdout_run.exit_code == 0);
  // Files carry the time since the source opened: all but time_s is the same.
  const std::regex time_s("\"time_s\":[0-9.]+");
  const std::string a = std::regex_replace(stdout_run.output, time_s, "");
  const std::string b = std::regex_replace(Slurp(dir / "out.jsonl"), time_s, "");
  CHECK(a.size() > 9 * 1000);
  CHECK(a == b);
  for (int k = 0; k < 9; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame-%06d.png", k);
    const std::string bytes = Slurp(dir / "png" / name);
    auto png =
        runtime::DecodePng(std::span(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()), name);
    REQUIRE(png.ok());
    CHECK(png->width == 3 * 640);
    CHECK(png->height == 480);
  }
  // Raw frames on a pipe (stdin) and a .npy are sources too.
  const std::string real_dir = (testing::DataDir() / "real/skeltrack_kinect_depth").string();
  auto pipe = testing::RunCommand("cat " + real_dir + "/depth-data-1028894671 " + real_dir +
                                  "/depth-data-1038901490 | " + Bin() + " live --forest " + forest +
                                  " --threads 2 --source - --jsonl " + (dir / "pipe.jsonl").string());
  INFO(pipe.output);
  REQUIRE(pipe.exit_code == 0);
  CHECK_THAT(pipe.output, Catch::Contains("end of source: 2 frames"));
  CHECK_THAT(CheckJsonl(dir, dir / "pipe.jsonl"), Catch::StartsWith("ok 2 2 "));
  CHECK(Slurp(dir / "pipe.jsonl").find("\"source\":\"stdin\"") != std::string::npos);
  // --loop on a pipe: the replay of an ended stdin gives nothing, and that ends it (no busy loop).
  auto pipe_loop = testing::RunCommand("cat " + real_dir + "/depth-data-1028894671 | timeout 60 " + Bin() +
                                       " live --forest " + forest + " --threads 2 --loop --source - --jsonl /dev/null");
  INFO(pipe_loop.output);
  CHECK(pipe_loop.exit_code == 0);
  CHECK_THAT(pipe_loop.output, Catch::Contains("end of source: 1 frames"));
  // The PCL person cloud (.pcd) is a source too; and --max-frames / --loop.
  auto pcd = testing::RunPoseforest(
      "live --forest " + forest + " --threads 2 --loop --max-frames 3 --jsonl " +
      (dir / "pcd.jsonl").string() + " " + (testing::DataDir() / "real/pcl_person_pcd/person.pcd").string());
  INFO(pcd.output);
  REQUIRE(pcd.exit_code == 0);
  CHECK_THAT(pcd.output, Catch::Contains("3 frames") && Catch::Contains("2 replays"));
  CHECK_THAT(CheckJsonl(dir, dir / "pcd.jsonl"), Catch::StartsWith("ok 3 3 "));
  // The same person over the replays keeps id 1.
  CHECK(Slurp(dir / "pcd.jsonl").find("\"id\":2") == std::string::npos);
  // A JSON Lines output that cannot be written (a full disk): said once, counted, exit 1.
  auto full = testing::RunPoseforest("live --forest " + forest +
                                     " --threads 2 --loop --max-frames 3 --jsonl /dev/full " +
                                     (testing::DataDir() / "real/pcl_person_pcd/person.pcd").string());
  INFO(full.output);
  CHECK(full.exit_code == 1);
  CHECK_THAT(full.output, Catch::Contains("--jsonl: a write failed at frame 0: No space left on device") &&
                              Catch::Contains("3 write errors"));
  CHECK(full.output.find("a write failed at frame 1") == std::string::npos);
}

TEST_CASE("live --pixel-stride 2: valid records, other positions than every pixel, said on stderr",
          "[live][data]") {
  const auto dir = testing::ScratchDir("live-stride");
  const auto forest = Forest(dir).string();
  std::string records[2];
  for (int stride : {1, 2}) {
    const fs::path jsonl = dir / ("s" + std::to_string(stride) + ".jsonl");
    auto run = testing::RunPoseforest("live --forest " + forest + " --source " + RealFrames() +
                                      " --threads 2 --pixel-stride " + std::to_string(stride) + " --jsonl " +
                                      jsonl.string());
    INFO(run.output);
    REQUIRE(run.exit_code == 0);
    CHECK_THAT(run.output, Catch::Contains("end of source: 9 frames"));
    CHECK((run.output.find("pixel stride 2: one pixel in 2x2 classified") != std::string::npos) ==
          (stride == 2));
    CHECK_THAT(CheckJsonl(dir, jsonl), Catch::StartsWith("ok 9 9 "));
    records[stride - 1] = std::regex_replace(Slurp(jsonl), std::regex("\"time_s\":[0-9.]+"), "");
  }
  // The same people (the masks come from the segmentation, at every pixel), other joints.
  const std::regex pixels("\"pixels\":[0-9]+");
  auto all = [](const std::string& s, const std::regex& re) {
    std::string out;
    for (auto it = std::sregex_iterator(s.begin(), s.end(), re); it != std::sregex_iterator(); ++it)
      out += it->str();
    return out;
  };
  CHECK(all(records[0], pixels) == all(records[1], pixels));
  CHECK(records[0] != records[1]);
  auto bad =
      testing::RunPoseforest("live --forest " + forest + " --source " + RealFrames() + " --pixel-stride 0");
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("pixel-stride"));
}

TEST_CASE("live stops cleanly on SIGTERM and SIGINT with a summary; every line written is whole",
          "[live][data]") {
  const auto dir = testing::ScratchDir("live-signal");
  const auto forest = Forest(dir).string();
  for (const char* sig : {"TERM", "INT"}) {
    const fs::path jsonl = dir / (std::string(sig) + ".jsonl");
    auto run =
        testing::RunCommand(Bin() + " live --forest " + forest + " --source " + RealFrames() +
                            " --threads 2 --loop --fps 20 --jsonl " + jsonl.string() +
                            " 2>&1 & pid=$!; sleep 2; kill -" + sig + " $pid; wait $pid; echo exit=$?");
    INFO(run.output);
    CHECK_THAT(run.output, Catch::Contains("stopped by signal") && Catch::Contains("exit=0") &&
                               Catch::Contains("latency p50"));
    const std::string ok = CheckJsonl(dir, jsonl);
    int frames = 0;
    std::sscanf(ok.c_str(), "ok %d", &frames);
    CHECK(frames >= 1);  // (how many depends on the machine's load)
  }
}

#ifdef POSEFOREST_TEST_HTTP
TEST_CASE("the live page in headless Chromium: frames arrive by server-sent events with the people",
          "[live][http]") {
  REQUIRE(fs::exists("/usr/bin/chromium"));  // scripts/setup.sh installs it
  const auto dir = testing::ScratchDir("live-http");
  const auto forest = Forest(dir).string();
  const fs::path log = dir / "live.log";
  // Port 0: the program picks one and prints the page's address.
  const std::string start =
      Bin() + " live --forest " + forest + " --source " + RealFrames() +
      " --threads 2 --loop --fps 10 --http 127.0.0.1:0 2>" + log.string() +
      " & pid=$!; for i in $(seq 100); do grep -q 'live page is at' " + log.string() +
      " && break; sleep 0.1; done; url=$(grep -o 'http://[0-9.:]*/' " + log.string() +
      "); for i in $(seq 300); do curl -s \"${url}skeletons.json\" | grep -q index && break; "
      "sleep 0.1; done";
  // ?frames=5: the page's event stream ends after 5 frames, so headless Chromium's virtual time
  // can run out and the DOM is dumped with what the events put there.
  const std::string dom_file = (dir / "dom.html").string();
  const std::string chromium =
      "timeout 90 /usr/bin/chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync --disable-dev-shm-usage "
      "--user-data-dir=" +
      (dir / "profile").string() +
      " --virtual-time-budget=5000 --dump-dom \"${url}?frames=5\" "
      "2>/dev/null > " +
      dom_file;
  auto run = testing::RunCommand(start + "; " + chromium + "; curl -s \"${url}skeletons.json\" > " +
                                 (dir / "latest.json").string() + "; curl -s -o " +
                                 (dir / "frame.png").string() + " \"${url}frame.png\"" +
                                 "; kill -INT $pid; wait $pid; echo exit=$?; cat " + log.string());
  INFO(run.output);
  CHECK_THAT(run.output, Catch::Contains("exit=0") && Catch::Contains("stopped by signal"));
  const std::string dom = Slurp(dir / "dom.html");
  INFO(dom.substr(0, 3000));
  CHECK_THAT(dom, Catch::Contains("class=\"person\" data-id=\"1\""));  // the page got a frame's people
  CHECK_THAT(dom, Catch::Contains("/frame.png?index="));               // and set the picture
  int index = -1;
  const size_t at = dom.find("id=\"frame\">");
  REQUIRE(at != std::string::npos);
  std::sscanf(dom.c_str() + at + 11, "%d", &index);
  CHECK(index >= 4);  // five frames came (indices count up from the first one the page saw)
  CHECK_THAT(Slurp(dir / "latest.json"), Catch::StartsWith("{\"index\":"));
  const std::string png = Slurp(dir / "frame.png");
  auto decoded =
      runtime::DecodePng(std::span(reinterpret_cast<const uint8_t*>(png.data()), png.size()), "frame.png");
  REQUIRE(decoded.ok());
  CHECK(decoded->width == 3 * 640);
}
#endif
