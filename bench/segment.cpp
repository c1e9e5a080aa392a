// bench/segment: people segmentation of cluttered 640x480 frames (runtime/segmentation.h).
// Frames are built here: a floor, a back wall and a side wall at varying distances, boxes on the
// floor, and people - synthetic standing figures and, when the shared data is there, the real
// Kinect frames' people (already segmented) moved back in depth - composited by depth test, with
// the ground-truth person masks. Prints the segmentation's IoU per person against the truth and
// its speed with N threads (default 2), one frame per thread at a time. Last line:
// `frames/s: N frames/s`.
//
//   build/bench/segment [--threads N] [--frames N] [--seconds S] [--dump DIR] [--pictures DIR] (--help)
#include <omp.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_cli.h"
#include "runtime/core/rng.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "runtime/segmentation.h"
#include "tests/support/scene.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

fs::path DataDir() {
  if (const char* env = std::getenv("POSEFOREST_DATA_DIR"); env && *env) return env;
  return POSEFOREST_DATA_DIR_DEFAULT;
}

// Depth as grey (near = bright), then person labels as colours over a dimmed depth.
void DrawPanel(const core::DepthImage& depth, const core::LabelImage* labels, std::vector<uint8_t>& rgb,
               int panel, int panels) {
  static const uint8_t kColours[6][3] = {{230, 60, 50},  {50, 140, 230}, {60, 200, 80},
                                         {240, 200, 40}, {200, 80, 220}, {40, 220, 220}};
  const int w = depth.width, h = depth.height;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const uint16_t d = depth.at(x, y);
      const int g = d ? std::clamp(255 - (int(d) - 500) * 200 / 5500, 40, 255) : 0;
      uint8_t* px = &rgb[(size_t(y) * size_t(w * panels) + size_t(panel * w + x)) * 3];
      px[0] = px[1] = px[2] = uint8_t(g);
      if (labels) {
        const int l = labels->at(x, y);
        px[0] = px[1] = px[2] = uint8_t(g / 3);
        if (l > 0) {
          const uint8_t* c = kColours[(l - 1) % 6];
          for (int k = 0; k < 3; ++k) px[k] = uint8_t(c[k] * (0.5 + 0.5 * g / 255.0));
        }
      }
    }
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2, num_frames = 24;
  double seconds = 3.0;
  std::string dump;      // --dump DIR: a picture per frame (depth | truth | segmentation)
  std::string pictures;  // --pictures DIR: the pictures of docs/runtime/frames.md
  CLI::App app(
      "People segmentation of cluttered 640x480 frames: IoU per person against the truth, and speed; "
      "last line `frames/s: N frames/s`",
      "bench/segment");
  bench::AddFrameLoopOptions(app, &threads, "threads, one frame each at a time", &num_frames, "frames built",
                             &seconds);
  app.add_option("--dump", dump, "a picture per frame (depth | truth | segmentation) into this folder")
      ->type_name("DIR")
      ->check(bench::kNonEmptyPath);
  app.add_option("--pictures", pictures, "the pictures of docs/runtime/frames.md into this folder")
      ->type_name("DIR")
      ->check(bench::kNonEmptyPath);
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  const auto cam = core::CameraIntrinsics::KinectV1();

  // People: synthetic standing figures, and the real frames' people if the data is there.
  std::vector<core::DepthImage> real_people;
  runtime::FrameSourceOptions fo;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(DataDir() / "real/skeltrack_kinect_depth", ec))
    if (e.path().filename().string().rfind("depth-data-", 0) == 0)
      if (auto d = runtime::ReadDepthFile(e.path().string(), fo); d.ok()) real_people.push_back(*d);
  std::printf("building %d cluttered 640x480 frames (%zu real Kinect people available)...\n", num_frames,
              real_people.size());

  struct Item {
    testing::ClutteredFrame frame;
    int people = 0;
  };
  std::vector<Item> items(static_cast<size_t>(num_frames));
  core::RngStream rng(core::CounterRng(14, 0, 0, 0x5E6));
  for (int k = 0; k < num_frames; ++k) {
    testing::ClutterSpec spec;
    spec.floor_y_m = rng.UniformIn(0.8, 1.3);  // camera height above the floor
    spec.back_wall_z_m = rng.UniformIn(3.8, 5.5);
    spec.side_wall_x_m = (rng.UniformInt(2) ? 1 : -1) * rng.UniformIn(1.6, 2.6);
    const int boxes = 1 + int(rng.UniformInt(3));
    for (int b = 0; b < boxes; ++b) {
      const double x = rng.UniformIn(-1.5, 1.2), z = rng.UniformIn(2.4, 3.6), w = rng.UniformIn(0.3, 0.9);
      const double h = rng.UniformIn(0.15, 0.32), dz = rng.UniformIn(0.3, 0.6);
      spec.boxes.push_back({{x, spec.floor_y_m - h, z}, {x + w, spec.floor_y_m, z + dz}});
    }
    std::vector<core::DepthImage> people;
    const int n = 1 + int(rng.UniformInt(2));
    for (int p = 0; p < n; ++p) {
      const bool real = !real_people.empty() && rng.UniformInt(3) == 0;
      if (real) {
        const auto& src = real_people[rng.UniformInt(uint32_t(real_people.size()))];
        people.push_back(
            testing::MovePerson(src, cam, int(rng.UniformIn(300, 1200)), rng.UniformIn(-0.4, 0.4)));
      } else {
        // Standing on the floor: the figure's feet are 0.98 m below its pelvis.
        const double z = rng.UniformIn(1.8, 3.3);
        people.push_back(
            testing::MakePersonDepth(z, 640, 480, rng.UniformIn(-0.8, 0.8), spec.floor_y_m - 0.98));
      }
    }
    items[size_t(k)].frame = testing::ComposeScene(cam, spec, people);
    items[size_t(k)].people = n;
  }

  // Quality: per true person, the IoU of the best-matching segmented person.
  runtime::SegmentationOptions options;
  double iou_sum = 0;
  int persons = 0, count_right = 0, presegmented = 0;
  for (const Item& it : items) {
    runtime::SegmentationResult seg;
    runtime::SegmentPeople(it.frame.depth, cam, options, &seg);
    presegmented += seg.presegmented;
    int visible = 0;
    for (int p = 1; p <= it.people; ++p) {
      const auto& t = it.frame.truth.pixels;
      if (std::count(t.begin(), t.end(), uint8_t(p)) < 500) continue;  // hidden behind another
      ++visible;
      double best = 0;
      for (const auto& person : seg.people)
        best = std::max(best, runtime::MaskIoU(seg.labels, person.label, it.frame.truth, p));
      iou_sum += best;
      ++persons;
    }
    count_right += int(seg.people.size()) == visible;
    if (!dump.empty()) {
      fs::create_directories(dump);
      std::vector<uint8_t> rgb(size_t(640 * 3) * 480 * 3);
      DrawPanel(it.frame.depth, nullptr, rgb, 0, 3);
      DrawPanel(it.frame.depth, &it.frame.truth, rgb, 1, 3);
      DrawPanel(it.frame.depth, &seg.labels, rgb, 2, 3);
      char name[64];
      std::snprintf(name, sizeof name, "/frame-%02td.png", &it - items.data());
      (void)runtime::WriteRgbPng(dump + name, 640 * 3, 480, rgb);
    }
    if (std::getenv("SEGMENT_VERBOSE")) {
      std::printf("frame %td: %d visible, %zu found, floor %s, components %d:", &it - items.data(), visible,
                  seg.people.size(), seg.floor ? "yes" : "no", seg.components);
      for (int p = 1; p <= it.people; ++p) {
        double best = 0;
        for (const auto& person : seg.people)
          best = std::max(best, runtime::MaskIoU(seg.labels, person.label, it.frame.truth, p));
        std::printf(" IoU %.2f", best);
      }
      for (const auto& q : seg.people)
        std::printf(" [%d px h %.2f w %.2f a %.2f z %.2f]", q.pixels, q.height_m, q.width_m, q.area_m2,
                    q.mean_depth_m);
      std::printf("\n");
    }
  }

  if (!pictures.empty()) {
    // person.pcd (a real Kinect cloud of a person in a room): depth | segmentation.
    fs::create_directories(pictures);
    if (auto pcd = runtime::ReadPcdDepth((DataDir() / "real/pcl_person_pcd/person.pcd").string()); pcd.ok()) {
      runtime::SegmentationResult seg;
      runtime::SegmentPeople(*pcd, cam, options, &seg);
      std::vector<uint8_t> rgb(size_t(640 * 2) * 480 * 3);
      DrawPanel(*pcd, nullptr, rgb, 0, 2);
      DrawPanel(*pcd, &seg.labels, rgb, 1, 2);
      (void)runtime::WriteRgbPng(pictures + "/segmentation_person_pcd.png", 640 * 2, 480, rgb);
      std::printf("person.pcd: %zu person(s), floor %s\n", seg.people.size(), seg.floor ? "found" : "none");
    }
    // A cluttered frame with two people touching at different depths: depth | truth | result.
    for (int k : {14, 3}) {
      if (k >= num_frames) continue;
      runtime::SegmentationResult seg;
      runtime::SegmentPeople(items[size_t(k)].frame.depth, cam, options, &seg);
      std::vector<uint8_t> rgb(size_t(640 * 3) * 480 * 3);
      DrawPanel(items[size_t(k)].frame.depth, nullptr, rgb, 0, 3);
      DrawPanel(items[size_t(k)].frame.depth, &items[size_t(k)].frame.truth, rgb, 1, 3);
      DrawPanel(items[size_t(k)].frame.depth, &seg.labels, rgb, 2, 3);
      (void)runtime::WriteRgbPng(pictures + "/segmentation_cluttered_" + std::to_string(k) + ".png", 640 * 3,
                                 480, rgb);
    }
  }

  // Speed: every thread segments frames round robin for about `seconds`.
  omp_set_dynamic(0);
  long done = 0;
  const auto t0 = std::chrono::steady_clock::now();
  double elapsed = 0;
  int rounds = 0;
  while (elapsed < seconds || rounds == 0) {
#pragma omp parallel num_threads(threads) reduction(+ : done)
    {
      runtime::SegmentationResult seg;  // per thread, storage reused
#pragma omp for schedule(static)
      for (int k = 0; k < num_frames * 8; ++k) {
        runtime::SegmentPeople(items[size_t(k % num_frames)].frame.depth, cam, options, &seg);
        ++done;
      }
    }
    ++rounds;
    elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const double fps = double(done) / elapsed;
  std::printf(
      "frames: %d distinct cluttered frames (floor, 2 walls, 1-3 boxes, 1-2 people), %ld segmented in %.2f "
      "s\n",
      num_frames, done, elapsed);
  std::printf(
      "people: %d visible, mean IoU %.3f; frames with the right person count %d/%d; taken as pre-segmented "
      "%d\n",
      persons, persons ? iou_sum / persons : 0.0, count_right, num_frames, presegmented);
  std::printf("threads: %d, %.3f ms per frame per thread\n", threads,
              1000.0 * elapsed * threads / double(done));
  std::printf("frames/s: %.0f frames/s\n", fps);
  return 0;
}
