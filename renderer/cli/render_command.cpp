// `poseforest render`: renders a synthetic labelled depth dataset (16-bit depth PNGs in mm, label
// PNGs, joint JSON) and a preview montage like Fig. 2 of the paper (depth as grey + part colours).
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "renderer/montage.h"
#include "renderer/synthetic_source.h"
#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"
#include "runtime/core/body_parts.h"
#include "runtime/image_io.h"

namespace poseforest::cli {
namespace {

constexpr const char* kUsage =
    "usage: poseforest render --out DIR [options]\n"
    "\n"
    "Renders synthetic depth frames of people with ground-truth body parts and joints\n"
    "(procedural bodies and poses, headless EGL). Files in DIR, for i = 0..N-1:\n"
    "  depth_%06d.png   16-bit depth, millimetres (0 = background)\n"
    "  labels_%06d.png  8-bit part id 0..30 (255 = background)\n"
    "  joints_%06d.json 16 joints per person, camera frame (metres) + pixel + visibility\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (created)\n"
    "  --count N          frames to render (default 16)\n"
    "  --seed S           stream seed; frame i is a pure function of (S, i) (default 1)\n"
    "  --threads N        rendering threads, one EGL context each (default 1)\n"
    "  --rotation 120|360 person rotation about the vertical: +-120 deg or any (default 120)\n"
    "  --people N         people per frame (default 1)\n"
    "  --no-noise         no Kinect noise model (clean rendered depth)\n"
    "  --montage FILE.png preview of the first 8 frames: depth grey | part colours, 4x2 grid\n"
    "  --help             this text\n";

std::string FrameName(const std::string& dir, const char* stem, uint64_t i, const char* ext) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s_%06llu.%s", stem, static_cast<unsigned long long>(i), ext);
  return (std::filesystem::path(dir) / buf).string();
}

std::string JointsJson(const renderer::RenderedFrame& f, const core::CameraIntrinsics& cam, uint64_t seed,
                       uint64_t index) {
  std::string s =
      "{\n  \"seed\": " + std::to_string(seed) + ",\n  \"index\": " + std::to_string(index) +
      ",\n  \"units\": \"metres, camera frame: x right, y down, z forward; u, v pixels\",\n  \"people\": [";
  char buf[256];
  for (size_t p = 0; p < f.joints.size(); ++p) {
    s += p ? ",\n    {\"joints\": [" : "\n    {\"joints\": [";
    for (int j = 0; j < core::kNumJoints; ++j) {
      const Eigen::Vector3f q = f.joints[p][size_t(j)];
      const Eigen::Vector2d uv = q.z() > 0 ? cam.Project(q.cast<double>()) : Eigen::Vector2d(-1, -1);
      std::snprintf(
          buf, sizeof buf,
          "%s\n      {\"name\": \"%s\", \"x\": %.5f, \"y\": %.5f, \"z\": %.5f, \"u\": %.2f, \"v\": %.2f, "
          "\"visible\": %s}",
          j ? "," : "", std::string(core::JointName(j)).c_str(), q.x(), q.y(), q.z(), uv.x(), uv.y(),
          f.visible[p][size_t(j)] ? "true" : "false");
      s += buf;
    }
    s += "\n    ]}";
  }
  s += "\n  ]\n}\n";
  return s;
}

}  // namespace

int RenderMain(int argc, char** argv) {
  Args args({"out", "count", "seed", "threads", "rotation", "people", "montage"}, {"no-noise", "help"});
  if (core::Status st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest render: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  const auto out = args.Get("out");
  if (!out) {
    std::fprintf(stderr, "poseforest render: --out DIR is required\n\n%s", kUsage);
    return 2;
  }
  auto count = args.GetInt("count", 16, 0, 100000000);
  auto threads = args.GetInt("threads", 1, 1, 256);
  auto rotation = args.GetInt("rotation", 120, 0, 360);
  auto people = args.GetInt("people", 1, 1, 8);
  for (const auto* r : {&count, &threads, &rotation, &people}) {
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest render: %s\n", r->status().message().c_str());
      return 2;
    }
  }
  if (*rotation != 120 && *rotation != 360) {
    std::fprintf(stderr, "poseforest render: --rotation must be 120 or 360, not %ld\n", *rotation);
    return 2;
  }
  uint64_t seed = 1;
  if (auto s = args.Get("seed")) {
    char* end = nullptr;
    seed = std::strtoull(s->c_str(), &end, 10);
    if (s->empty() || *end != '\0') {
      std::fprintf(stderr, "poseforest render: --seed must be a non-negative integer, not '%s'\n",
                   s->c_str());
      return 2;
    }
  }
  std::error_code ec;
  std::filesystem::create_directories(*out, ec);
  if (ec) {
    std::fprintf(stderr, "poseforest render: cannot create %s: %s\n", out->c_str(), ec.message().c_str());
    return 1;
  }

  renderer::SceneConfig config;
  config.rotation_range_deg = *rotation == 360 ? 180.0 : 120.0;
  config.min_people = config.max_people = int(*people);
  config.noise.enabled = !args.Has("no-noise");

  // llvmpipe: rasterize on each worker thread itself (no helper threads), since we run one
  // context per worker thread. An LP_NUM_THREADS already set by the user wins.
  setenv("LP_NUM_THREADS", "0", 0);

  const int n_threads = int(std::min<long>(*threads, std::max<long>(1, *count)));
  const uint64_t n = uint64_t(*count);
  const uint64_t n_montage = std::min<uint64_t>(8, n);
  std::vector<renderer::RenderedFrame> montage_frames(n_montage);
  std::atomic<uint64_t> next{0}, done{0};
  std::atomic<bool> failed{false};
  std::mutex mu;
  std::string error;
  std::string gl_name;
  const auto t0 = std::chrono::steady_clock::now();
  auto worker = [&] {
    auto r = renderer::SyntheticRenderer::Create(config);
    if (!r.ok()) {
      std::lock_guard<std::mutex> lock(mu);
      failed = true;
      error = r.status().ToString();
      return;
    }
    {
      std::lock_guard<std::mutex> lock(mu);
      if (gl_name.empty()) gl_name = (*r)->GlRendererString();
    }
    for (uint64_t i = next++; i < n && !failed; i = next++) {
      auto f = (*r)->Render(seed, i);
      core::Status st = f.ok() ? core::Status::Ok() : f.status();
      if (st.ok()) st = runtime::WriteDepthPng(FrameName(*out, "depth", i, "png"), f->depth);
      if (st.ok()) st = runtime::WriteLabelPng(FrameName(*out, "labels", i, "png"), f->labels);
      if (st.ok()) {
        const std::string path = FrameName(*out, "joints", i, "json");
        std::ofstream js(path);
        js << JointsJson(*f, config.camera, seed, i);
        if (!js) st = core::Status(core::ErrorCode::kIo, path + ": write failed");
      }
      if (!st.ok()) {
        std::lock_guard<std::mutex> lock(mu);
        failed = true;
        error = st.ToString();
        return;
      }
      if (i < n_montage) montage_frames[i] = std::move(f).value();
      const uint64_t d = ++done;
      if (d % 16 == 0 || d == n) {
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::lock_guard<std::mutex> lock(mu);
        std::fprintf(stderr, "\rrender: %llu/%llu frames, %.1f frames/s", static_cast<unsigned long long>(d),
                     static_cast<unsigned long long>(n), double(d) / std::max(s, 1e-9));
        std::fflush(stderr);
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < n_threads; ++t) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  std::fprintf(stderr, "\n");
  if (failed) {
    std::fprintf(stderr, "poseforest render: %s\n", error.c_str());
    return 1;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("rendered %llu frames to %s in %.2f s with %d thread(s) on %s\n",
              static_cast<unsigned long long>(n), out->c_str(), secs, n_threads, gl_name.c_str());
  if (auto montage = args.Get("montage"); montage && n_montage > 0) {
    const renderer::RgbImage m = renderer::MakeMontage(montage_frames, 4, 2, 2);
    if (core::Status st = runtime::WriteRgbPng(*montage, m.width, m.height, m.rgb); !st.ok()) {
      std::fprintf(stderr, "poseforest render: %s\n", st.ToString().c_str());
      return 1;
    }
    std::printf("montage: %s (%dx%d)\n", montage->c_str(), m.width, m.height);
  }
  return 0;
}

}  // namespace poseforest::cli
