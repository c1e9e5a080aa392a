// bench/live: `poseforest live`'s pipeline on a replayed sequence of cluttered 640x480 frames
// (a floor, walls and boxes; people: the real Kinect frames' people moved back in depth and
// synthetic standing figures, composited by depth test, as bench/segment builds them): people
// segmentation + classification + joint proposals + skeletons (ids, not-tracked rules) + the
// JSON Lines record written to /dev/null + the DDS publish of `live --dds` (builds with Fast DDS),
// one frame at a time with 2 OpenMP threads (--threads).
// Prints frames/s, latency p50 / p99 from frame in to JSON line out, a per-stage table, and what
// else the machine did meanwhile (CPU time stolen by the hypervisor, the load average) and how
// fast the host ran two fixed pieces of reference work (the clock, the memory's latency).
// Last line: `frames/s: N frames/s`.
//
// The forest: --forest F, else scripts/accuracy-recipe.sh's forest (out/accuracy-16000/
// forest_tuned.pff, then forest.pff, then the same in the earlier recipes' out/accuracy-8000/ and
// out/accuracy-4000/); it says which it ran.
//
//   build/bench/live [--forest F] [--threads N] [--frames N] [--seconds S] [--pixel-stride N] [--no-votes]
//                    [--no-tracking-model] [--fit kinematic|greedy] [--checksum] (--help)
//
// --pixel-stride N: classify and propose from every N-th pixel in x and y (`live --pixel-stride`;
// default 2, as `live`'s default; 1: every pixel); the header says which ran.
//
// --checksum: no timing; runs the sequence once through a fresh pipeline and prints checksums of
// the classification (labels, foreground sums), the proposals and the JSON Lines records, so
// that a change meant to be exact can be checked bit-identical against an older build.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bench/bench_cli.h"
#include "runtime/core/forest_format.h"
#include "runtime/core/rng.h"
#include "runtime/frame_source.h"
#include "runtime/skeleton_pipeline.h"
#include "tests/support/scene.h"
#include "tests/support/synthetic.h"
#ifdef POSEFOREST_HAS_SKELETON_DDS
#include "apps/ros2/skeleton_publisher.h"
#endif

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

fs::path DataDir() {
  if (const char* env = std::getenv("POSEFOREST_DATA_DIR"); env && *env) return env;
  return POSEFOREST_DATA_DIR_DEFAULT;
}

double ProcessCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

/// FNV-1a over bytes, chained.
uint64_t Fnv(uint64_t h, const void* data, size_t bytes) {
  const auto* b = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < bytes; ++i) h = (h ^ b[i]) * 1099511628211ull;
  return h;
}

/// The machine's CPU ticks from /proc/stat's first line: all of them, and those the hypervisor
/// stole (time a virtual CPU was ready to run but the host ran something else). Zeros when
/// /proc/stat cannot be read (not Linux).
struct CpuTicks {
  unsigned long long total = 0, steal = 0;
};
CpuTicks ReadCpuTicks() {
  CpuTicks t;
  FILE* f = std::fopen("/proc/stat", "r");
  if (!f) return t;
  unsigned long long v[8] = {};
  if (std::fscanf(f, "cpu %llu %llu %llu %llu %llu %llu %llu %llu", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5],
                  &v[6], &v[7]) == 8) {
    for (unsigned long long x : v) t.total += x;
    t.steal = v[7];
  }
  std::fclose(f);
  return t;
}

/// The 1-minute load average, or -1.
double LoadAverage() {
  double l = -1;
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf", &l) != 1) l = -1;
    std::fclose(f);
  }
  return l;
}

/// The host's speed in this sitting, on two fixed pieces of work that do not depend on the
/// forest or the build: a chain of dependent integer multiply-adds (the cores' clock) and a chain
/// of dependent loads over 64 MiB (the memory's latency, which other tenants' traffic raises).
/// Nanoseconds per step of each. A sitting whose frame rate is low while these are high ran on
/// a slower host, not a slower build.
std::pair<double, double> ReferenceWork() {
  using clock = std::chrono::steady_clock;
  volatile uint32_t seed = 1;
  uint32_t x = seed;
  const int64_t steps = 100'000'000;
  auto t0 = clock::now();
  for (int64_t i = 0; i < steps; ++i) x = x * 1664525u + 1013904223u;
  const double alu_ns = std::chrono::duration<double, std::nano>(clock::now() - t0).count() / double(steps);
  const size_t n = size_t(16) << 20;  // 16 Mi entries of 4 bytes
  std::vector<uint32_t> next(n);
  for (size_t i = 0; i < n; ++i) next[i] = uint32_t((uint64_t(i) * 2654435761u + x) % n);
  uint32_t k = 0;
  const int64_t loads = 2'000'000;
  t0 = clock::now();
  for (int64_t i = 0; i < loads; ++i) k = next[k];
  const double mem_ns = std::chrono::duration<double, std::nano>(clock::now() - t0).count() / double(loads);
  seed = x + k;  // keeps both chains
  return {alu_ns, mem_ns};
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(q * double(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2, num_frames = 30, pixel_stride = 2;  // pixel stride: `poseforest live`'s default
  double seconds = 5.0;
  bool checksum = false, votes = true, tracking_model = true;
  std::string forest_path;
  std::optional<runtime::SkeletonFit> fit;  // unset: as `live`, the forest's decision's fit
  std::string fit_name;
  CLI::App app(
      "`poseforest live`'s pipeline on a replayed sequence of cluttered 640x480 frames; last line "
      "`frames/s: N frames/s`",
      "bench/live");
  app.add_option("--forest", forest_path,
                 "the forest (default: scripts/accuracy-recipe.sh's, out/accuracy-16000/forest_tuned.pff, "
                 "then its earlier recipes')")
      ->type_name("F")
      ->check(bench::kNonEmptyPath);
  bench::AddFrameLoopOptions(app, &threads, "OpenMP threads", &num_frames, "frames in the replayed sequence",
                             &seconds);
  app.add_option(
         "--pixel-stride", pixel_stride,
         "classify and propose from every N-th pixel in x and y (`live --pixel-stride`; 1: every pixel)")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_flag(
      "--no-votes", [&](int64_t) { votes = false; }, "without the forest's offset votes");
  app.add_flag(
      "--no-tracking-model", [&](int64_t) { tracking_model = false; },
      "the hand-set tracking rules instead of the forest's learned decision");
  app.add_option("--fit", fit_name, "the skeleton fit (default: `live`'s for this forest)")
      ->type_name("kinematic|greedy")
      ->check(CLI::IsMember({"kinematic", "greedy"}));
  app.add_flag(
      "--checksum", checksum,
      "no timing: one pass through a fresh pipeline, then checksums of the classification, proposals and "
      "JSON Lines records");
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  if (!fit_name.empty()) fit = runtime::SkeletonFitFromName(fit_name);
  std::string which = "given with --forest";
  if (forest_path.empty()) {
    // The recipe's default (16,000 images per tree since 30 Nov 2026), then its earlier 8,000
    // (+-60 degrees, 29 Nov 2026) and 4,000.
    for (const char* p : {"out/accuracy-16000/forest_tuned.pff", "out/accuracy-16000/forest.pff",
                          "out/accuracy-8000/forest_tuned.pff", "out/accuracy-8000/forest.pff",
                          "out/accuracy-4000/forest_tuned.pff", "out/accuracy-4000/forest.pff"})
      if (fs::exists(p)) {
        forest_path = p;
        which = std::string("scripts/accuracy-recipe.sh's forest (") + p + ")";
        break;
      }
  }
  if (forest_path.empty()) {
    std::fprintf(
        stderr,
        "bench/live: no forest: run scripts/accuracy-recipe.sh (out/accuracy-16000/forest_tuned.pff) or "
        "give --forest F (e.g. the main job's)\n");
    return 2;
  }
  auto forest = core::LoadForest(forest_path);
  if (!forest.ok()) {
    std::fprintf(stderr, "bench/live: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  std::printf("forest: %s (%s): %zu trees, depth %u\n", forest_path.c_str(), which.c_str(),
              forest->trees.size(), forest->max_depth());

  const auto cam = core::CameraIntrinsics::KinectV1();
  std::vector<core::DepthImage> real_people;
  runtime::FrameSourceOptions fo;
  std::error_code ec;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(DataDir() / "real/skeltrack_kinect_depth", ec))
    if (e.path().filename().string().rfind("depth-data-", 0) == 0) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (const auto& f : files)
    if (auto d = runtime::ReadDepthFile(f.string(), fo); d.ok()) real_people.push_back(*d);
  // A sequence: one clutter, the people walking slowly (a real person and a synthetic one).
  std::vector<runtime::Frame> frames(static_cast<size_t>(num_frames));
  testing::ClutterSpec spec;
  spec.floor_y_m = 1.1;
  spec.back_wall_z_m = 4.6;
  spec.side_wall_x_m = -2.1;
  spec.boxes.push_back({{0.9, 0.85, 3.0}, {1.6, 1.1, 3.5}});
  spec.boxes.push_back({{-1.5, 0.9, 2.6}, {-1.0, 1.1, 3.0}});
  for (int k = 0; k < num_frames; ++k) {
    std::vector<core::DepthImage> people;
    const double t = double(k) / num_frames;
    if (!real_people.empty())
      people.push_back(testing::MovePerson(real_people[size_t(k) % real_people.size()], cam,
                                           900 + int(300 * t), -0.5 + 0.3 * t));
    people.push_back(testing::MakePersonDepth(2.9 - 0.4 * t, 640, 480, 0.7 - 0.2 * t, spec.floor_y_m - 0.98));
    auto& f = frames[size_t(k)];
    f.depth = testing::ComposeScene(cam, spec, people).depth;
    f.timestamp_s = k / 30.0;
    f.index = k;
    f.source = "bench";
  }
  std::printf("sequence: %d cluttered 640x480 frames played back and forth, %s, %d threads\n", num_frames,
              real_people.empty() ? "one synthetic person (no real frames found)"
                                  : "a real Kinect person and a synthetic one",
              threads);
  if (pixel_stride == 1)
    std::printf("pixel stride: 1 (every pixel classified; `live`'s default is 2)\n");
  else
    std::printf("pixel stride: %d (one pixel in %dx%d classified: 1/%d of the pixels; `live`'s default is 2)\n",
                pixel_stride, pixel_stride, pixel_stride, pixel_stride * pixel_stride);

  runtime::SkeletonPipelineOptions options;
  options.num_threads = threads;
  options.pixel_stride = pixel_stride;
  options.votes = votes;
  options.skeleton.use_tracking_model = tracking_model;
  options.skeleton.fit = fit;
  const auto& model = forest->tracking_model;
  std::printf("skeleton fit: %s%s\n",
              std::string(runtime::SkeletonFitName(runtime::ResolveSkeletonFit(
                                                      options.skeleton, model ? &*model : nullptr)))
                  .c_str(),
              fit ? " (--fit)" : " (`live`'s default for this forest)");
  std::printf("tracking decision: %s\n", !forest->tracking_model ? "the hand-set rules (none in the forest)"
                                          : !tracking_model       ? "the hand-set rules (--no-tracking-model)"
                                          : forest->tracking_model->seen
                                              ? "learned (the forest's, format 1.6), tracked when likely seen (1.8)"
                                              : "learned (the forest's, format 1.6)");
  std::printf("offset votes: %s\n", !forest->offset_votes ? "none in the forest"
                                     : votes            ? "on (the forest's, format 1.5)"
                                                        : "off (--no-votes)");
  auto pipeline = runtime::SkeletonPipeline::Create(*forest, options);
  if (!pipeline.ok()) {
    std::fprintf(stderr, "bench/live: %s\n", pipeline.status().ToString().c_str());
    return 1;
  }
  FILE* sink = std::fopen("/dev/null", "w");
#ifdef POSEFOREST_HAS_SKELETON_DDS
  // Published as `live --dds` does, on a domain of its own (nobody subscribes: the cost is
  // serializing and handing the samples to Fast DDS).
  apps::ros2::DdsOptions dds_options;
  dds_options.domain = 231;
  dds_options.topic_prefix = "poseforest_bench";
  auto dds = apps::ros2::SkeletonPublisher::Create(dds_options);
  if (!dds.ok()) {
    std::fprintf(stderr, "bench/live: %s\n", dds.status().ToString().c_str());
    return 1;
  }
#endif
  runtime::SkeletonFrame out;
  if (checksum) {
    uint64_t h_class = 1469598103934665603ull, h_prop = h_class, h_json = h_class;
    size_t fg = 0, proposals = 0;
    for (const auto& f : frames) {
      (*pipeline)->Process(f, &out);
      const auto& c = out.classification;
      h_class = Fnv(h_class, c.labels.pixels.data(), c.labels.pixels.size());
      h_class = Fnv(h_class, c.foreground.data(), c.foreground.size() * sizeof(uint32_t));
      h_class = Fnv(h_class, c.foreground_sums.data(), c.foreground_sums.size() * sizeof(uint16_t));
      fg += c.foreground.size();
      for (const auto& joint : out.proposals)
        for (const auto& p : joint) {
          h_prop = Fnv(h_prop, p.position.data(), 3 * sizeof(float));
          h_prop = Fnv(h_prop, p.pixel.data(), 2 * sizeof(float));
          h_prop = Fnv(h_prop, &p.confidence, sizeof(float));
          ++proposals;
        }
      const std::string line = runtime::SkeletonsJsonLine(f.index, f.timestamp_s, f.source, out.skeletons);
      h_json = Fnv(h_json, line.data(), line.size());
    }
    std::printf("checksum: %d frames, %zu classified pixels, %zu proposals\n", num_frames, fg, proposals);
    std::printf("checksum: classification %016llx proposals %016llx json %016llx\n",
                static_cast<unsigned long long>(h_class), static_cast<unsigned long long>(h_prop),
                static_cast<unsigned long long>(h_json));
    return 0;
  }
  const auto [alu_ns, mem_ns] = ReferenceWork();
  // Warm-up: one pass over the sequence.
  for (const auto& f : frames) (*pipeline)->Process(f, &out);
  std::vector<double> latency;
  runtime::StageTimes sum;
  double json_ms = 0, dds_ms = 0;
  int64_t done = 0, people = 0, tracked = 0;
  const auto start = std::chrono::steady_clock::now();
  const double cpu_start = ProcessCpuSeconds();
  const CpuTicks ticks_start = ReadCpuTicks();
  const double load_start = LoadAverage();
  double elapsed = 0;
  while (elapsed < seconds || done < num_frames) {
    // Played forwards then backwards, so the people never jump (ids stay).
    const int64_t period = std::max<int64_t>(1, 2 * int64_t(num_frames) - 2);
    const int64_t at = done % period;
    runtime::Frame f = frames[size_t(at < num_frames ? at : period - at)];
    f.index = done;
    f.timestamp_s = double(done) / 30.0;
    const auto t0 = std::chrono::steady_clock::now();
    (*pipeline)->Process(f, &out);
    const auto t1 = std::chrono::steady_clock::now();
    const std::string line = runtime::SkeletonsJsonLine(f.index, f.timestamp_s, f.source, out.skeletons);
    std::fputs(line.c_str(), sink);
    std::fputc('\n', sink);
    std::fflush(sink);
#ifdef POSEFOREST_HAS_SKELETON_DDS
    const auto t_dds = std::chrono::steady_clock::now();
    (*dds)->Publish(f.index, f.timestamp_s, f.source, out.skeletons);
    dds_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_dds).count();
#endif
    const auto t2 = std::chrono::steady_clock::now();
    latency.push_back(std::chrono::duration<double, std::milli>(t2 - t0).count());
    json_ms += std::chrono::duration<double, std::milli>(t2 - t1).count();
    sum.segment_ms += out.times.segment_ms, sum.classify_ms += out.times.classify_ms;
    sum.proposals_ms += out.times.proposals_ms, sum.skeletons_ms += out.times.skeletons_ms;
    sum.votes_ms += out.times.votes_ms;
    people += int64_t(out.skeletons.size());
    for (const auto& s : out.skeletons) tracked += s.tracked_joints();
    ++done;
    elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  const double cpu_s = ProcessCpuSeconds() - cpu_start;
  const CpuTicks ticks_end = ReadCpuTicks();
  std::fclose(sink);
  const double n = double(done);
  std::printf("%lld frames in %.2f s; %.2f people per frame (%d ids), %.1f joints tracked per person\n",
              static_cast<long long>(done), elapsed, double(people) / n, (*pipeline)->tracker().people_seen(),
              people ? double(tracked) / double(people) : 0.0);
  std::printf("latency (frame in to skeletons published): p50 %.2f ms, p99 %.2f ms, max %.2f ms\n",
              Percentile(latency, 0.5), Percentile(latency, 0.99),
              *std::max_element(latency.begin(), latency.end()));
  std::printf("%-14s %10s %8s\n", "stage", "ms/frame", "share");
  json_ms -= dds_ms;  // the JSON Lines span above included the publish
  const double total = sum.total() + json_ms + dds_ms;
  for (const auto& [name, ms] : {std::pair<const char*, double>{"segmentation", sum.segment_ms},
                                 {"classify", sum.classify_ms},
                                 {"proposals", sum.proposals_ms},
                                 {"votes", sum.votes_ms},
                                 {"skeletons", sum.skeletons_ms},
                                 {"json lines", json_ms},
                                 {"dds publish", dds_ms}})
    std::printf("%-14s %10.3f %7.1f%%\n", name, ms / n, 100.0 * ms / total);
#ifndef POSEFOREST_HAS_SKELETON_DDS
  std::printf("(DDS publish: not in this build; it comes with -DPOSEFOREST_TRAINING=ON)\n");
#endif
  // CPU time of the whole process over the timed frames (all threads, OpenMP's waiting
  // included): steadier than wall times when other jobs share the machine.
  std::printf("cpu: %.3f ms/frame (all threads)\n", 1000.0 * cpu_s / n);
  // What else the machine did meanwhile: on a virtual machine the host can take the CPUs away
  // ("steal"), and other processes show in the load average (this benchmark alone: about the
  // number of threads). Frame rates of sittings with different figures here do not compare.
  if (ticks_end.total > ticks_start.total)
    std::printf(
        "machine: %.1f%% of the CPUs' time stolen by the hypervisor meanwhile; load average %.2f before, "
        "%.2f after\n",
        100.0 * double(ticks_end.steal - ticks_start.steal) / double(ticks_end.total - ticks_start.total),
        load_start, LoadAverage());
  else
    std::printf("machine: /proc/stat not readable (no steal or load figures)\n");
  std::printf(
      "machine: reference work before the frames: %.3f ns per dependent multiply-add, %.1f ns per "
      "dependent load over 64 MiB\n",
      alu_ns, mem_ns);
  std::printf("frames/s: %.1f frames/s\n", n / elapsed);
  return 0;
}
