// Frames in: camera models (presets, size checks, the forest rescaled to another focal length),
// frame sources (files, folders, globs, .npy, stdin through a real pipe, pacing) and
// `poseforest infer` on them, with bad frames named, skipped and counted.
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <span>
#include <vector>

#include "runtime/camera_model.h"
#include "runtime/classifier.h"
#include "runtime/core/feature.h"
#include "runtime/core/forest_format.h"
#include "runtime/core/rng.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"
#include "tests/support/process.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

// Frame B of camera `b` that sees exactly what frame A of camera `a` sees (same rays, depth along
// the optical axis unchanged), by nearest-neighbour resampling.
core::DepthImage Resample(const core::DepthImage& a_img, const core::CameraIntrinsics& a,
                          const core::CameraIntrinsics& b) {
  core::DepthImage out(b.width, b.height, 0);
  for (int v = 0; v < b.height; ++v)
    for (int u = 0; u < b.width; ++u) {
      const int ua = int(std::lround(a.cx + a.fx * (u - b.cx) / b.fx));
      const int va = int(std::lround(a.cy + a.fy * (v - b.cy) / b.fy));
      if (a_img.InBounds(ua, va)) out.at(u, v) = a_img.at(ua, va);
    }
  return out;
}

std::vector<std::string> ListFiles(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

TEST_CASE("camera presets: sizes, nominal focal lengths, unknown names", "[frames][camera]") {
  for (const auto& name : runtime::CameraPresetNames()) {
    auto m = runtime::CameraPreset(name);
    REQUIRE(m.ok());
    CHECK(m->name == name);
    CHECK(m->intrinsics.fx > 100);
    CHECK(m->intrinsics.fx < 1200);
    CHECK(m->intrinsics.cx == Approx((m->intrinsics.width - 1) / 2.0));
  }
  CHECK(runtime::CameraPreset("kinect-v1")->intrinsics.fx == 575.8);
  const auto v2 = *runtime::CameraPreset("kinect-v2");
  CHECK(v2.intrinsics.width == 512);
  CHECK(v2.intrinsics.height == 424);
  CHECK(v2.intrinsics.fx == Approx(361.7).margin(0.2));  // 256 / tan(70.6 deg / 2)
  const auto nfov = *runtime::CameraPreset("azure-nfov");
  CHECK(nfov.intrinsics.width == 640);
  CHECK(nfov.intrinsics.height == 576);
  CHECK(nfov.intrinsics.fx == 504.0);  // factory calibrations, not the documented FOV's 417
  CHECK(nfov.intrinsics.fy == 504.0);
  CHECK(runtime::CameraPreset("azure-nfov-binned")->intrinsics.fx == 252.0);
  CHECK(runtime::CameraPreset("realsense-d435")->intrinsics.width == 848);
  auto bad = runtime::CameraPreset("kinect-v9");
  REQUIRE_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("kinect-v9") && Catch::Contains("kinect-v2"));

  const auto st = runtime::CheckFrameSize(v2, 640, 480, "a.png");
  REQUIRE_FALSE(st.ok());
  CHECK_THAT(st.message(), Catch::Contains("a.png") && Catch::Contains("640x480") &&
                               Catch::Contains("kinect-v2") && Catch::Contains("512x424"));
  CHECK(runtime::CheckFrameSize(v2, 512, 424, "a.png").ok());
}

TEST_CASE("another focal length: rescaled offsets probe the same metres on the body", "[frames][camera]") {
  const auto a = core::CameraIntrinsics::KinectV1();
  const auto b = runtime::CameraPreset("kinect-v2")->intrinsics;  // fx 361.7, fy 367.2: anisotropic ratio
  const core::DepthImage img_a = testing::MakePersonDepth(2.2);
  const core::DepthImage img_b = Resample(img_a, a, b);
  REQUIRE(core::CountForeground(img_b) > 5000);

  testing::RandomForestSpec spec;
  spec.seed = 7;
  spec.num_trees = 3;
  spec.max_depth = 12;
  spec.nodes_per_tree = 4000;
  spec.max_offset = 60;
  const core::Forest forest = testing::MakeRandomForest(spec);
  const core::Forest for_b = runtime::ForestForFocalLength(forest, b.fx, b.fy);
  CHECK(for_b.training_fx == float(b.fx));
  CHECK(for_b.constants.offset_unit == Approx(forest.constants.offset_unit * b.fx / a.fx));
  REQUIRE(core::ValidateForest(for_b, "rescaled").ok());
  CHECK(runtime::SameFocalLength(forest, a.fx, a.fy));
  CHECK_FALSE(runtime::SameFocalLength(forest, b.fx, b.fy));

  // Feature level: for body pixels of B and random offsets, the response in B with the rescaled
  // forest's offsets equals the response at the same ray in A with the original ones (up to
  // resampling); with the original offsets on B it does not.
  core::RngStream rng(core::CounterRng(3, 0, 0, 1));
  int same_rescaled = 0, same_plain = 0, n = 0;
  for (int trial = 0; trial < 200000; ++trial) {
    const int u = int(rng.UniformInt(uint32_t(b.width))), v = int(rng.UniformInt(uint32_t(b.height)));
    if (!img_b.at(u, v)) continue;
    const int ua = int(std::lround(a.cx + a.fx * (u - b.cx) / b.fx)),
              va = int(std::lround(a.cy + a.fy * (v - b.cy) / b.fy));
    if (img_a.at(ua, va) != img_b.at(u, v)) continue;
    const auto& tree = forest.trees[rng.UniformInt(uint32_t(forest.trees.size()))];
    const size_t k = rng.UniformInt(uint32_t(tree.nodes.size()));
    if (tree.nodes[k].is_leaf()) continue;
    core::FeatureOffsets fa = tree.nodes[k].offsets;
    core::FeatureOffsets fb = for_b.trees[size_t(&tree - forest.trees.data())].nodes[k].offsets;
    const int32_t ra = core::FeatureResponse(img_a, ua, va, fa, forest.constants);
    const int32_t rb = core::FeatureResponse(img_b, u, v, fb, for_b.constants);
    const int32_t rp = core::FeatureResponse(img_b, u, v, fa, forest.constants);
    same_rescaled += std::abs(ra - rb) <= 30;
    same_plain += std::abs(ra - rp) <= 30;
    ++n;
  }
  REQUIRE(n > 2000);
  INFO("same response (30 mm): rescaled " << same_rescaled << " / " << n << ", not rescaled " << same_plain);
  CHECK(same_rescaled > 0.93 * n);
  CHECK(same_plain < 0.85 * n);
  CHECK(same_rescaled > same_plain + n / 10);

  // Classifier level: labels of corresponding body pixels agree.
  runtime::Classifier ca(forest), cb(for_b), cplain(forest);
  runtime::Classification la, lb, lp;
  ca.Classify(img_a, {}, &la);
  cb.Classify(img_b, {}, &lb);
  cplain.Classify(img_b, {}, &lp);
  int agree = 0, agree_plain = 0, total = 0;
  for (int v = 0; v < b.height; ++v)
    for (int u = 0; u < b.width; ++u) {
      if (!img_b.at(u, v)) continue;
      const int ua = int(std::lround(a.cx + a.fx * (u - b.cx) / b.fx)),
                va = int(std::lround(a.cy + a.fy * (v - b.cy) / b.fy));
      ++total;
      agree += la.labels.at(ua, va) == lb.labels.at(u, v);
      agree_plain += la.labels.at(ua, va) == lp.labels.at(u, v);
    }
  INFO("labels agree: rescaled " << agree << " / " << total << ", not rescaled " << agree_plain);
  CHECK(agree > 0.85 * total);
  CHECK(agree > agree_plain + total / 10);
}

TEST_CASE("files, folders and globs in name order; bad frames named, skipped and counted",
          "[frames][source]") {
  const auto dir = testing::ScratchDir("frames-folder");
  const core::DepthImage person = testing::MakePersonDepth(2.5);
  // Written out of order: the folder reads them by name.
  REQUIRE(runtime::WriteDepthPng((dir / "f2.png").string(), testing::MakePersonDepth(3.0)).ok());
  REQUIRE(runtime::WriteDepthPng((dir / "f0.png").string(), person).ok());
  {
    std::ofstream raw((dir / "f1.raw").string(), std::ios::binary);
    for (uint16_t d : testing::MakePersonDepth(2.0).pixels) raw.put(char(d & 0xFF)).put(char(d >> 8));
  }
  {
    // A truncated raw frame (half of it).
    std::ofstream raw((dir / "f1b.raw").string(), std::ios::binary);
    for (size_t i = 0; i < person.pixels.size() / 2; ++i)
      raw.put(char(person.pixels[i] & 0xFF)).put(char(person.pixels[i] >> 8));
  }
  REQUIRE(runtime::WriteDepthPng((dir / "small.png").string(), core::DepthImage(320, 240, 1000)).ok());
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource(dir.string(), o);
  REQUIRE(src.ok());
  std::vector<std::string> names, errors;
  runtime::Frame f;
  int guard = 0;
  while (guard++ < 100) {
    auto r = (*src)->Next(&f);
    if (!r.ok()) {
      errors.push_back(r.status().message());
      continue;
    }
    if (!*r) break;
    names.push_back(fs::path(f.source).filename().string());
    CHECK(f.camera.name == "kinect-v1");
  }
  CHECK(names == std::vector<std::string>{"f0.png", "f1.raw", "f2.png"});
  REQUIRE(errors.size() == 2);
  CHECK_THAT(errors[0], Catch::Contains("f1b.raw") && Catch::Contains("truncated"));
  CHECK_THAT(errors[1], Catch::Contains("small.png") && Catch::Contains("320x240") &&
                            Catch::Contains("kinect-v1") && Catch::Contains("640x480"));

  // A glob: only the PNGs, sorted.
  auto glob = runtime::ExpandFrameFiles((dir / "f*.png").string());
  REQUIRE(glob.ok());
  REQUIRE(glob->size() == 2);
  CHECK(fs::path((*glob)[0]).filename() == "f0.png");
  auto none = runtime::ExpandFrameFiles((dir / "*.xyz").string());
  REQUIRE_FALSE(none.ok());
  CHECK_THAT(none.status().message(), Catch::Contains("*.xyz"));
  fs::remove_all(dir);
}

TEST_CASE("a folder leaves out files that are not frames (earlier outputs, text, licences) and names them",
          "[frames][source]") {
  for (const char* name :
       {"x.parts.png", "x.labels.png", "x.mask.png", "x.pose.png", "x.probs.npy", "x.joints.json",
        "camera.txt", "montage.png", "labels_000003.png", "joints_000003.json", "COPYING", "JOINT_LABELS.md",
        "notes.TXT", "f.pff", "job.textproto"})
    CHECK(runtime::IsNotAFrameFile(name));
  for (const char* name : {"depth_000003.png", "x.png", "x.npy", "a.pcd", "f1.raw", "depth-data-1028894671",
                           "labels_x.png", "FRAME.png", "ABC"})
    CHECK_FALSE(runtime::IsNotAFrameFile(name));

  const auto dir = testing::ScratchDir("frames-not-frames");
  REQUIRE(runtime::WriteDepthPng((dir / "f0.png").string(), testing::MakePersonDepth(2.5)).ok());
  {
    std::ofstream raw((dir / "depth-data-1").string(), std::ios::binary);
    for (uint16_t d : testing::MakePersonDepth(2.0).pixels) raw.put(char(d & 0xFF)).put(char(d >> 8));
  }
  // An earlier infer's outputs and a data set's papers: none of them is a frame.
  REQUIRE(runtime::WriteLabelPng((dir / "f0.parts.png").string(), core::LabelImage(640, 480, 3)).ok());
  REQUIRE(runtime::WriteDepthNpy((dir / "f0.probs.npy").string(), {testing::MakePersonDepth(2.5)}).ok());
  for (const char* name : {"COPYING", "README.md", "joint_labels.json"})
    std::ofstream((dir / name).string()) << "text\n";
  std::vector<std::string> left_out;
  auto files = runtime::ExpandFrameFiles(dir.string(), &left_out);
  REQUIRE(files.ok());
  REQUIRE(files->size() == 2);
  CHECK(fs::path((*files)[0]).filename() == "depth-data-1");
  CHECK(fs::path((*files)[1]).filename() == "f0.png");
  CHECK(left_out == std::vector<std::string>{"COPYING", "README.md", "f0.parts.png", "f0.probs.npy",
                                             "joint_labels.json"});
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource(dir.string(), o);
  REQUIRE(src.ok());
  CHECK_THAT((*src)->Describe(), Catch::Contains("(2 files; 5 not frames, left out: COPYING, README.md, "
                                                 "f0.parts.png, ...)"));
  runtime::Frame f;
  int frames = 0, bad = 0;
  for (int guard = 0; guard < 20; ++guard) {
    auto r = (*src)->Next(&f);
    if (!r.ok()) {
      ++bad;
      continue;
    }
    if (!*r) break;
    ++frames;
  }
  CHECK(frames == 2);
  CHECK(bad == 0);
  // A glob keeps what it matches (the user chose those files), and a folder of no frames says so.
  auto glob = runtime::ExpandFrameFiles((dir / "f0*").string());
  REQUIRE(glob.ok());
  CHECK(glob->size() == 3);
  const auto papers = dir / "papers";
  fs::create_directories(papers);
  std::ofstream((papers / "COPYING").string()) << "text\n";
  auto none = runtime::ExpandFrameFiles(papers.string());
  REQUIRE_FALSE(none.ok());
  CHECK_THAT(none.status().message(), Catch::Contains("no frame files (only 1 others, such as COPYING)"));
  fs::remove_all(dir);
}

TEST_CASE(".npy: uint16 mm and float32 m, one frame or many; other dtypes refused clearly", "[frames][npy]") {
  const auto dir = testing::ScratchDir("frames-npy");
  const core::DepthImage a = testing::MakePersonDepth(2.5), b = testing::MakePersonDepth(3.0);
  REQUIRE(runtime::WriteDepthNpy((dir / "two.npy").string(), {a, b}).ok());
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource((dir / "two.npy").string(), o);
  REQUIRE(src.ok());
  runtime::Frame f;
  REQUIRE(*(*src)->Next(&f));
  CHECK(f.depth.pixels == a.pixels);
  CHECK(f.index == 0);
  CHECK_THAT(f.Name(), Catch::Contains("two.npy[0]"));
  REQUIRE(*(*src)->Next(&f));
  CHECK(f.depth.pixels == b.pixels);
  CHECK_FALSE(*(*src)->Next(&f));

  // float32 metres, written by hand as NumPy does (format 1.0, 64-byte aligned header).
  auto write_npy = [&](const std::string& name, const std::string& descr, const std::string& shape,
                       const std::vector<uint8_t>& data) {
    std::string header = "{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + shape + ", }";
    while ((10 + header.size() + 1) % 64 != 0) header += ' ';
    header += '\n';
    std::ofstream out((dir / name).string(), std::ios::binary);
    out << "\x93NUMPY" << char(1) << char(0) << char(header.size() & 0xFF) << char(header.size() >> 8)
        << header;
    out.write(reinterpret_cast<const char*>(data.data()), std::streamsize(data.size()));
  };
  std::vector<uint8_t> metres(a.pixels.size() * 4);
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    const float m = a.pixels[i] ? float(a.pixels[i]) / 1000.0f : std::nanf("");
    std::memcpy(metres.data() + 4 * i, &m, 4);
  }
  write_npy("m.npy", "<f4", "(480, 640)", metres);
  auto m = runtime::ReadDepthFile((dir / "m.npy").string(), o);
  REQUIRE(m.ok());
  CHECK(m->pixels == a.pixels);

  write_npy("f8.npy", "<f8", "(480, 640)", std::vector<uint8_t>(480 * 640 * 8));
  auto f8 = runtime::ReadDepthFile((dir / "f8.npy").string(), o);
  REQUIRE_FALSE(f8.ok());
  CHECK_THAT(f8.status().message(),
             Catch::Contains("f8.npy") && Catch::Contains("<f8") && Catch::Contains("uint16"));
  write_npy("big.npy", ">u2", "(480, 640)", std::vector<uint8_t>(480 * 640 * 2));
  CHECK_FALSE(runtime::ReadDepthFile((dir / "big.npy").string(), o).ok());
  write_npy("rgb.npy", "<u2", "(480, 640, 3)", std::vector<uint8_t>(480 * 640 * 6));
  auto rgb = runtime::OpenFrameSource((dir / "rgb.npy").string(), o);
  REQUIRE(rgb.ok());
  auto r = (*rgb)->Next(&f);  // 480 frames of 640x3: the size check names both
  REQUIRE_FALSE(r.ok());
  CHECK_THAT(r.status().message(), Catch::Contains("3x640") && Catch::Contains("640x480"));
  write_npy("short.npy", "<u2", "(480, 640)", std::vector<uint8_t>(1000));
  auto short_npy = runtime::ReadDepthFile((dir / "short.npy").string(), o);
  REQUIRE_FALSE(short_npy.ok());
  CHECK_THAT(short_npy.status().message(), Catch::Contains("short.npy") && Catch::Contains("truncated"));
  auto header = runtime::ParseNpyHeader({0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, 200, 0, '{'}, "cut.npy");
  REQUIRE_FALSE(header.ok());
  CHECK_THAT(header.status().message(), Catch::Contains("cut.npy"));
  fs::remove_all(dir);
}

TEST_CASE("--fps paces a folder; timestamps are index / fps", "[frames][source]") {
  const auto dir = testing::ScratchDir("frames-fps");
  for (const char* name : {"f0.png", "f1.png", "f2.png", "f3.png"})
    REQUIRE(runtime::WriteDepthPng((dir / name).string(), core::DepthImage(640, 480, 1500)).ok());
  // A fake clock: sleeping moves it on; frame 2 comes 80 ms late (a slow consumer).
  using Clock = std::chrono::steady_clock;
  using std::chrono::milliseconds;
  const Clock::time_point t0{};
  Clock::time_point t = t0;
  std::vector<Clock::time_point> sleeps;
  runtime::FrameSourceOptions o;
  o.fps = 20;
  o.pace_now = [&] { return t; };
  o.pace_sleep_until = [&](Clock::time_point until) {
    sleeps.push_back(until);
    t = until;
  };
  auto src = runtime::OpenFrameSource(dir.string(), o);
  REQUIRE(src.ok());
  runtime::Frame f;
  int n = 0;
  while (true) {
    if (n == 2) t += milliseconds(80);
    auto more = (*src)->Next(&f);
    REQUIRE(more.ok());
    if (!*more) break;
    CHECK(f.timestamp_s == Approx(n / 20.0));
    ++n;
  }
  CHECK(n == 4);
  // Frame 1 waits for its 50 ms slot; frame 2, late, goes at once (no burst to catch up); frame 3
  // waits one period after it.
  CHECK(sleeps == std::vector<Clock::time_point>{t0 + milliseconds(50), t0 + milliseconds(180)});
  fs::remove_all(dir);
}

TEST_CASE("infer reads raw frames from a pipe, names and counts a truncated one, refuses a wrong size",
          "[frames][cli]") {
  const auto dir = testing::ScratchDir("frames-cli");
  const core::Forest forest = testing::MakeRandomForest({.max_depth = 8, .nodes_per_tree = 500});
  REQUIRE(core::SaveForest(forest, (dir / "f.pff").string()).ok());
  const core::DepthImage person = testing::MakePersonDepth(2.5);
  {
    std::ofstream raw((dir / "frames.raw").string(), std::ios::binary);
    for (int k = 0; k < 2; ++k)
      for (uint16_t d : person.pixels) raw.put(char(d & 0xFF)).put(char(d >> 8));
    for (int i = 0; i < 1000; ++i) raw.put(1);  // a third frame cut short
  }
  // A real pipe: cat | poseforest infer -  (the old reader seeked and failed on a pipe).
  const std::string bin = (testing::BinDir() / "poseforest").string();
  auto run = testing::RunCommand("cat " + (dir / "frames.raw").string() + " | " + bin + " infer --forest " +
                                 (dir / "f.pff").string() + " --out-dir " + (dir / "out").string() + " -");
  INFO(run.output);
  CHECK(run.exit_code == 1);  // one bad frame
  CHECK_THAT(run.output, Catch::Contains("stdin frame 2") && Catch::Contains("truncated") &&
                             Catch::Contains("2 frame(s) classified, 1 bad frame(s) skipped"));
  CHECK(ListFiles(dir / "out") ==
        std::vector<std::string>{"stdin-000000.parts.png", "stdin-000001.parts.png"});
  // The part pictures equal the library's on the same frame.
  runtime::Classifier classifier(forest);
  runtime::Classification expected;
  classifier.Classify(person, {}, &expected);
  auto png_bytes = core::ReadFileBytes((dir / "out" / "stdin-000001.parts.png").string());
  REQUIRE(png_bytes.ok());
  REQUIRE(runtime::WriteLabelColourPng((dir / "expected.png").string(), expected.labels).ok());
  CHECK(*png_bytes == *core::ReadFileBytes((dir / "expected.png").string()));

  // A size that contradicts the camera: refused naming both; --camera and --source.
  REQUIRE(runtime::WriteDepthPng((dir / "a.png").string(), person).ok());
  auto wrong = testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() +
                                      " --camera kinect-v2 --source " + (dir / "a.png").string());
  CHECK(wrong.exit_code == 1);
  CHECK_THAT(wrong.output, Catch::Contains("a.png") && Catch::Contains("640x480") &&
                               Catch::Contains("kinect-v2") && Catch::Contains("512x424"));
  // Another focal length: the forest is rescaled, and says so.
  auto custom = testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --fx 500 --out-dir " +
                                       (dir / "o2").string() + " " + (dir / "a.png").string());
  INFO(custom.output);
  CHECK(custom.exit_code == 0);
  CHECK_THAT(custom.output, Catch::Contains("rescaled by 0.868"));
  // `frames --out-dir` numbers the frames over all its sources: two sources each start at frame 0,
  // and the second used to write over the first.
  REQUIRE(runtime::WriteDepthPng((dir / "b.png").string(), testing::MakePersonDepth(3.0)).ok());
  auto two = testing::RunPoseforest("frames --out-dir " + (dir / "fo").string() + " " +
                                    (dir / "a.png").string() + " " + (dir / "b.png").string());
  INFO(two.output);
  CHECK(two.exit_code == 0);
  CHECK(ListFiles(dir / "fo") == std::vector<std::string>{"frame-000000.png", "frame-000001.png"});
  CHECK(*core::ReadFileBytes((dir / "fo" / "frame-000001.png").string()) ==
        *core::ReadFileBytes((dir / "b.png").string()));
  // A source that does not exist, and a back end not built in.
  auto missing =
      testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() + " " + (dir / "nope").string());
  CHECK(missing.exit_code == 1);
  CHECK_THAT(missing.output, Catch::Contains("nope"));
  auto scheme = testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() + " nosuch:0");
  CHECK(scheme.exit_code == 1);
  CHECK_THAT(scheme.output, Catch::Contains("nosuch:0") && Catch::Contains("back end"));
  fs::remove_all(dir);
}

TEST_CASE("infer segments a raw cluttered frame, passes a pre-segmented one unchanged",
          "[frames][cli][segmentation]") {
  const auto dir = testing::ScratchDir("frames-seg");
  const core::Forest forest = testing::MakeRandomForest({.max_depth = 8, .nodes_per_tree = 500});
  REQUIRE(core::SaveForest(forest, (dir / "f.pff").string()).ok());
  const fs::path pcd = testing::DataDir() / "real/pcl_person_pcd/person.pcd";
  REQUIRE(fs::exists(pcd));
  auto run = testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --masks --out-dir " +
                                    (dir / "out").string() + " " + pcd.string());
  INFO(run.output);
  REQUIRE(run.exit_code == 0);
  CHECK_THAT(run.output, Catch::Contains("segmentation: 1 person(s)"));
  auto mask_bytes = core::ReadFileBytes((dir / "out" / "person.mask.png").string());
  REQUIRE(mask_bytes.ok());
  auto mask = runtime::DecodePng(*mask_bytes, "person.mask.png");
  REQUIRE(mask.ok());
  int person = 0, other = 0;
  for (uint8_t v : mask->samples8) person += v == 1, other += v > 1;
  CHECK(person > 40000);
  CHECK(other == 0);
  // The part picture has parts only on the person.
  auto parts = core::ReadFileBytes((dir / "out" / "person.parts.png").string());
  REQUIRE(parts.ok());
  auto rgb = runtime::DecodePng(*parts, "person.parts.png");
  REQUIRE(rgb.ok());
  int coloured_off_person = 0;
  for (size_t i = 0; i < mask->samples8.size(); ++i) {
    const bool coloured = rgb->samples8[3 * i] || rgb->samples8[3 * i + 1] || rgb->samples8[3 * i + 2];
    coloured_off_person += coloured && mask->samples8[i] == 0;
  }
  CHECK(coloured_off_person == 0);
  // --segment off: the walls get body parts, as before this issue.
  auto off =
      testing::RunPoseforest("infer --forest " + (dir / "f.pff").string() + " --segment off --out-dir " +
                             (dir / "off").string() + " " + pcd.string());
  CHECK(off.exit_code == 0);
  CHECK_THAT(off.output, Catch::Contains("24") || Catch::Contains("foreground pixels"));
  fs::remove_all(dir);
}

namespace {

// Writes bytes with no fsync (the hostile loops write thousands of files).
void QuickWrite(const std::string& path, std::span<const uint8_t> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  REQUIRE(out.good());
}

// A small organized PCD (x y z float32 metres, or float64 with `doubles`) in one of PCL's encodings.
// binary_compressed is written as LZF literal runs (valid LZF, as liblzf decodes it), fields one after the
// other.
/// A 16x12 frame with a 10x8 patch of depths 1.1-1.6 m (each pixel its own) for the .pcd tests.
core::DepthImage PcdTestDepth() {
  core::DepthImage d(16, 12, 0);
  for (int y = 2; y < 10; ++y)
    for (int x = 3; x < 13; ++x) d.at(x, y) = uint16_t(1000 + 37 * x + 11 * y);
  return d;
}

std::vector<uint8_t> MakePcd(const core::DepthImage& d, const std::string& encoding,
                             const core::CameraIntrinsics& cam = core::CameraIntrinsics::KinectV1(),
                             float x_shift_m = 0, bool doubles = false) {
  std::string header = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE " +
                       std::string(doubles ? "8 8 8" : "4 4 4") + "\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " +
                       std::to_string(d.width) + "\nHEIGHT " + std::to_string(d.height) +
                       "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + std::to_string(d.width * d.height) + "\nDATA " +
                       encoding + "\n";
  std::vector<float> xyz;  // point-major
  for (int y = 0; y < d.height; ++y)
    for (int x = 0; x < d.width; ++x) {
      const uint16_t mm = d.at(x, y);
      if (!mm) {
        for (int k = 0; k < 3; ++k) xyz.push_back(std::nanf(""));
        continue;
      }
      const auto p = cam.PixelToPoint(x, y, mm);
      xyz.push_back(float(p.x()) + x_shift_m), xyz.push_back(float(p.y())),
          xyz.push_back(float(mm) / 1000.0f);
    }
  std::vector<uint8_t> out(header.begin(), header.end());
  if (encoding == "ascii") {
    std::string text;
    for (size_t i = 0; i < xyz.size(); i += 3) {
      char line[96];
      std::snprintf(line, sizeof line, "%.6f %.6f %.6f\n", double(xyz[i]), double(xyz[i + 1]),
                    double(xyz[i + 2]));
      text += line;
    }
    out.insert(out.end(), text.begin(), text.end());
  } else if (encoding == "binary") {
    const std::vector<double> xyz64(xyz.begin(), xyz.end());
    const auto* b = doubles ? reinterpret_cast<const uint8_t*>(xyz64.data())
                            : reinterpret_cast<const uint8_t*>(xyz.data());
    out.insert(out.end(), b, b + xyz.size() * (doubles ? 8 : 4));
  } else {
    std::vector<float> soa;
    for (int f = 0; f < 3; ++f)
      for (size_t i = f; i < xyz.size(); i += 3) soa.push_back(xyz[i]);
    const std::vector<double> soa64(soa.begin(), soa.end());
    const auto* raw = doubles ? reinterpret_cast<const uint8_t*>(soa64.data())
                              : reinterpret_cast<const uint8_t*>(soa.data());
    const size_t n = soa.size() * (doubles ? 8 : 4);
    std::vector<uint8_t> lzf;
    for (size_t i = 0; i < n; i += 32) {
      const size_t len = std::min<size_t>(32, n - i);
      lzf.push_back(uint8_t(len - 1));
      lzf.insert(lzf.end(), raw + i, raw + i + len);
    }
    const uint32_t sizes[2] = {uint32_t(lzf.size()), uint32_t(n)};
    const auto* s = reinterpret_cast<const uint8_t*>(sizes);
    out.insert(out.end(), s, s + 8);
    out.insert(out.end(), lzf.begin(), lzf.end());
  }
  return out;
}

}  // namespace

TEST_CASE(".pcd in all three encodings; truncated or corrupted files give errors, never crash",
          "[frames][pcd][hostile]") {
  const auto dir = testing::ScratchDir("frames-pcd");
  const core::DepthImage d = PcdTestDepth();
  for (const bool doubles : {false, true})
    for (const std::string enc : {"ascii", "binary", "binary_compressed"}) {
      const auto bytes = MakePcd(d, enc, core::CameraIntrinsics::KinectV1(), 0, doubles);
      const std::string path = (dir / ("c_" + enc + (doubles ? "_f64" : "") + ".pcd")).string();
      REQUIRE(core::WriteFileAtomic(path, bytes).ok());
      auto read = runtime::ReadPcdDepth(path);
      INFO(enc << (doubles ? " float64" : " float32"));
      REQUIRE(read.ok());
      CHECK(read->pixels == d.pixels);
      // Every truncation and some corruptions: an error or a frame, never a crash (ASan builds
      // make any overread fatal).
      int errors = 0;
      for (size_t len = 0; len < bytes.size(); ++len) {
        auto r = runtime::ParsePcdDepth(std::span(bytes.data(), len), path);
        if (!r.ok()) {
          ++errors;
          CHECK_THAT(r.status().message(), Catch::Contains(path));
        }
      }
      CHECK(errors > 0);
      for (size_t i = 0; i < bytes.size(); ++i) {
        auto bad = bytes;
        bad[i] ^= 0xA5;
        (void)runtime::ParsePcdDepth(bad, path);
      }
    }
  fs::remove_all(dir);
}

TEST_CASE(
    ".pcd: hostile headers (field sizes and counts, points the data cannot hold) are refused before any read",
    "[frames][pcd][hostile]") {
  auto parse = [](const std::string& fields, const std::string& size, const std::string& type,
                  const std::string& count, int width, int height, const std::string& data,
                  size_t data_bytes) {
    std::string text = "VERSION 0.7\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " + type + "\nCOUNT " +
                       count + "\nWIDTH " + std::to_string(width) + "\nHEIGHT " + std::to_string(height) +
                       "\nDATA " + data + "\n";
    std::vector<uint8_t> bytes(text.begin(), text.end());
    bytes.resize(bytes.size() + data_bytes, uint8_t('1'));
    return runtime::ParsePcdFrame(bytes, "h.pcd");
  };
  // Sizes that would put z 1 GiB past a 4-byte point, or wrap a field's start (they crashed).
  auto huge = parse("a z b", "1073741824 4 -1073741824", "U F U", "1 1 1", 4, 4, "binary", 64);
  REQUIRE_FALSE(huge.ok());
  CHECK_THAT(huge.status().message(),
             Catch::Contains("h.pcd: PCD field 'a' has SIZE 1073741824 (1, 2, 4 or 8 bytes)"));
  auto wrap = parse("a z b", "-1000 4 1000", "U F U", "1 1 1", 4, 4, "binary_compressed", 64);
  REQUIRE_FALSE(wrap.ok());
  CHECK_THAT(wrap.status().message(), Catch::Contains("PCD field 'a' has SIZE -1000"));
  auto negative = parse("a z", "4 4", "F F", "-3 1", 4, 4, "binary", 64);
  REQUIRE_FALSE(negative.ok());
  CHECK_THAT(negative.status().message(), Catch::Contains("PCD field 'a' has COUNT -3 (1 to 8192)"));
  auto zero = parse("z", "4", "F", "0", 4, 4, "binary", 64);
  REQUIRE_FALSE(zero.ok());
  CHECK_THAT(zero.status().message(), Catch::Contains("has COUNT 0"));
  // A FPFH-like histogram field (COUNT 33) beside z is a valid point of 136 bytes.
  auto histogram = parse("z fpfh", "4 4", "F F", "1 33", 2, 2, "binary", 4 * 136);
  CHECK(histogram.ok());
  // 16384 x 16384 points declared by a header of a few bytes: refused for the missing data
  // before the half-GiB image is allocated, in each encoding.
  for (const std::string data : {"ascii", "binary", "binary_compressed"}) {
    INFO(data);
    auto big = parse("z", "4", "F", "1", 16384, 16384, data, 16);
    REQUIRE_FALSE(big.ok());
    CHECK_THAT(big.status().message(),
               Catch::Contains("h.pcd: PCD " + data +
                               " data holds 16 bytes, too few for 268435456 points of 4 bytes"));
  }
}

TEST_CASE(".pcd: the cloud's own projection is fitted from its points and used as the frame's camera",
          "[frames][pcd]") {
  const auto dir = testing::ScratchDir("frames-pcd-projection");
  const core::DepthImage d = PcdTestDepth();
  core::CameraIntrinsics cam;
  cam.width = 16, cam.height = 12, cam.fx = 525, cam.fy = 530, cam.cx = 7.25, cam.cy = 5.75;
  for (const std::string enc : {"ascii", "binary", "binary_compressed"}) {
    INFO(enc);
    auto frame = runtime::ParsePcdFrame(MakePcd(d, enc, cam), "c.pcd");
    REQUIRE(frame.ok());
    CHECK(frame->depth.pixels == d.pixels);
    REQUIRE(frame->intrinsics.has_value());
    CHECK(frame->intrinsics->fx == Approx(525).margin(0.05));
    CHECK(frame->intrinsics->fy == Approx(530).margin(0.05));
    CHECK(frame->intrinsics->cx == Approx(7.25).margin(0.01));
    CHECK(frame->intrinsics->cy == Approx(5.75).margin(0.01));
    CHECK(frame->intrinsics->width == 16);
    CHECK(frame->fit_rms_px < 0.01);
    // Points moved 0.5 m sideways are no pinhole projection of their pixels: no camera is made up.
    auto moved = runtime::ParsePcdFrame(MakePcd(d, enc, cam, 0.5f), "moved.pcd");
    REQUIRE(moved.ok());
    CHECK_FALSE(moved->intrinsics.has_value());
    CHECK(moved->fit_rms_px > 0.5);
    // x, y and z as float64 (SIZE 8, as PCL writes doubles): the same depth and projection.
    auto doubles = runtime::ParsePcdFrame(MakePcd(d, enc, cam, 0, true), "doubles.pcd");
    REQUIRE(doubles.ok());
    CHECK(doubles->depth.pixels == d.pixels);
    REQUIRE(doubles->intrinsics.has_value());
    CHECK(doubles->intrinsics->fx == Approx(525).margin(0.05));
    CHECK(doubles->intrinsics->cy == Approx(5.75).margin(0.01));
  }
  // Read as a frame source, without camera flags, the frame carries that projection ...
  const std::string path = (dir / "c.pcd").string();
  REQUIRE(core::WriteFileAtomic(path, MakePcd(d, "binary", cam)).ok());
  runtime::FrameSourceOptions o;
  auto src = runtime::OpenFrameSource(path, o);
  REQUIRE(src.ok());
  runtime::Frame f;
  auto r = (*src)->Next(&f);
  REQUIRE(r.ok());
  REQUIRE(*r);
  CHECK(f.camera.name == "pcd-projection");
  CHECK(f.camera.intrinsics.fx == Approx(525).margin(0.05));
  CHECK(f.camera.intrinsics.cx == Approx(7.25).margin(0.01));
  // ... and camera flags still win (the size must then match).
  runtime::FrameSourceOptions given;
  given.camera_given = true;
  given.camera.intrinsics.width = 16, given.camera.intrinsics.height = 12;
  auto src2 = runtime::OpenFrameSource(path, given);
  REQUIRE(src2.ok());
  REQUIRE((*src2)->Next(&f).ok());
  CHECK(f.camera.intrinsics.fx == Approx(575.8));
  // PCL's real person cloud was made at fx = fy = 525 (not the Kinect v1 model's 575.8).
  const fs::path person = testing::DataDir() / "real/pcl_person_pcd/person.pcd";
  REQUIRE(fs::exists(person));
  auto real = runtime::ReadPcdFrame(person.string());
  REQUIRE(real.ok());
  REQUIRE(real->intrinsics.has_value());
  CHECK(real->intrinsics->fx == Approx(525).margin(0.01));
  CHECK(real->intrinsics->fy == Approx(525).margin(0.01));
  CHECK(real->intrinsics->cx == Approx(319.5).margin(0.01));
  CHECK(real->intrinsics->cy == Approx(239.5).margin(0.01));
  fs::remove_all(dir);
}

TEST_CASE(".npy truncated or corrupted at every byte: an error or a frame, never a crash",
          "[frames][npy][hostile]") {
  const auto dir = testing::ScratchDir("frames-npy-hostile");
  const std::string path = (dir / "a.npy").string();
  REQUIRE(runtime::WriteDepthNpy(path, {core::DepthImage(8, 6, 1234), core::DepthImage(8, 6, 2345)}).ok());
  auto bytes = core::ReadFileBytes(path);
  REQUIRE(bytes.ok());
  runtime::FrameSourceOptions o;
  o.camera.intrinsics.width = 8, o.camera.intrinsics.height = 6;
  auto drain = [&](const std::string& p) {
    auto src = runtime::OpenFrameSource(p, o);
    if (!src.ok()) return;
    runtime::Frame f;
    for (int k = 0; k < 10; ++k) {
      auto r = (*src)->Next(&f);
      if (r.ok() && !*r) break;
    }
  };
  for (size_t len = 0; len < bytes->size(); ++len) {
    QuickWrite(path, std::span(bytes->data(), len));
    auto r = runtime::ReadDepthFile(path, o);
    CHECK_FALSE(r.ok());  // one frame of the two is never "all of it"
    drain(path);
  }
  for (size_t i = 0; i < bytes->size(); ++i) {
    auto bad = *bytes;
    bad[i] ^= 0x5A;
    QuickWrite(path, bad);
    drain(path);
  }
  fs::remove_all(dir);
}
