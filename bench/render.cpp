// Synthetic rendering throughput: images per second per core at 640x480, one thread, including
// pose sampling + skinning matrices, the draw (vertex-shader skinning, rasterization), readback,
// and post-processing (label/depth unpacking, joint visibility, Kinect noise).
//   render [--frames N] [--people N] [--no-noise] (--help)
// The last line is the headline: `images/s/core: <value> images/s/core` (frames per CPU-second
// of this process, so other load on the machine does not count against it).
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bench/bench_cli.h"
#include "renderer/synthetic_source.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {
double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}
}  // namespace

int main(int argc, char** argv) {
  int frames = 400, people = 1;
  bool noise = true;
  CLI::App app(
      "Synthetic 640x480 frames rendered (EGL) on one thread, per CPU second; last line "
      "`images/s/core: N images/s/core`",
      "bench/render");
  app.add_option("--frames", frames, "frames rendered")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000000));
  app.add_option("--people", people, "people per frame")
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 8));
  app.add_flag(
      "--no-noise", [&](int64_t) { noise = false; }, "without the sensor noise model");
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  // llvmpipe rasterizes on the calling thread (no helper threads): a worker runs one renderer per core.
  setenv("LP_NUM_THREADS", "0", 0);
  SceneConfig config;
  config.min_people = config.max_people = people;
  config.noise.enabled = noise;
  const auto c0 = std::chrono::steady_clock::now();
  auto created = SyntheticRenderer::Create(config);
  if (!created.ok()) {
    std::fprintf(stderr, "render: %s\n", created.status().ToString().c_str());
    return 1;
  }
  auto& r = *created;
  const double create_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
  size_t tris = 0;
  for (const auto& b : r->bodies()) tris += b.triangles.size();
  std::printf("renderer: %s\n", r->GlRendererString().c_str());
  std::printf("LP_NUM_THREADS=%s\n", std::getenv("LP_NUM_THREADS"));
  std::printf("bodies: %zu (mean %zu triangles), created in %.2f s\n", r->bodies().size(),
              tris / r->bodies().size(), create_s);
  std::printf("image: %dx%d, people/frame %d, noise %s\n", config.camera.width, config.camera.height, people,
              noise ? "on" : "off");

  // Stage split: glFinish after the draw so rasterization is charged to "draw", not "readback".
  r->set_profile_stages(true);
  for (int i = 0; i < 20; ++i) (void)r->Render(7, uint64_t(i));
  const SyntheticRenderer::StageTimes before = r->stage_times();
  const int profile_frames = std::max(50, frames / 4);
  long fg = 0;
  for (int i = 0; i < profile_frames; ++i) {
    auto f = r->Render(7, uint64_t(1000 + i));
    if (!f.ok()) {
      std::fprintf(stderr, "render: %s\n", f.status().ToString().c_str());
      return 1;
    }
    fg += core::CountForeground(f->depth);
  }
  const auto& after = r->stage_times();
  const double n = double(after.frames - before.frames);
  std::printf("stage ms/frame (profiled, %d frames, glFinish after draw):\n", profile_frames);
  std::printf("  pose + skinning matrices + joints  %.3f ms\n", (after.pose_ms - before.pose_ms) / n);
  std::printf("  draw (vertex skinning + raster)    %.3f ms\n", (after.draw_ms - before.draw_ms) / n);
  std::printf("  readback (glReadPixels + unpack)   %.3f ms\n", (after.readback_ms - before.readback_ms) / n);
  std::printf("  post (visibility + Kinect noise)   %.3f ms\n", (after.post_ms - before.post_ms) / n);
  std::printf("  mean foreground pixels/frame       %.0f\n", double(fg) / profile_frames);

  // Throughput, no profiling sync.
  r->set_profile_stages(false);
  const double cpu0 = CpuSeconds();
  const auto w0 = std::chrono::steady_clock::now();
  for (int i = 0; i < frames; ++i) {
    auto f = r->Render(11, uint64_t(i));
    if (!f.ok()) {
      std::fprintf(stderr, "render: %s\n", f.status().ToString().c_str());
      return 1;
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  const double cpu = CpuSeconds() - cpu0;
  std::printf("frames: %d in %.2f s wall (%.1f images/s), %.2f s CPU\n", frames, wall, frames / wall, cpu);
  std::printf("images/s/core: %.1f images/s/core\n", frames / cpu);
  return 0;
}
