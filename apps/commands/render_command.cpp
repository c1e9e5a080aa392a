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
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "renderer/montage.h"
#include "renderer/scene_assets.h"
#include "renderer/synthetic_source.h"
#include "runtime/camera_model.h"
#include "runtime/core/body_parts.h"
#include "runtime/image_io.h"

#ifndef POSEFOREST_RENDER_DATA_DIR  // set by apps/CMakeLists.txt from the POSEFOREST_DATA_DIR cache value
#define POSEFOREST_RENDER_DATA_DIR "../shared/data"
#endif

namespace poseforest::apps::commands {
namespace {

constexpr const char* kUsage =
    "usage: poseforest render --out DIR [options]\n"
    "\n"
    "Renders synthetic depth frames of people with ground-truth body parts and joints\n"
    "(headless EGL; procedural bodies and poses unless told otherwise). Files in DIR, for\n"
    "i = 0..N-1:\n"
    "  depth_%06d.png   16-bit depth, millimetres (0 = background)\n"
    "  labels_%06d.png  8-bit part id 0..30 (255 = background)\n"
    "  joints_%06d.json 16 joints per person, camera frame (metres) + pixel + visibility\n"
    "  mask_%06d.png    8-bit person id (0 = none, k = person k of the joints file), with\n"
    "                   --clutter, --occluders or --masks\n"
    "  camera.txt       the camera model (name, size, fx fy cx cy in pixels)\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (created)\n"
    "  --count N          frames to render (default 16)\n"
    "  --seed S           stream seed; frame i is a pure function of (S, i) (default 1)\n"
    "  --threads N        rendering threads, one EGL context each (default 1)\n"
    "  --rotation 120|360 person rotation about the vertical: +-120 deg or any (default 120)\n"
    "  --people N         people per frame (default 1)\n"
    "  --no-noise         no Kinect noise model (clean rendered depth)\n"
    "  --camera PRESET    camera model (default kinect-v1): kinect-v1, kinect-v2, azure-nfov,\n"
    "                     azure-nfov-binned, azure-wfov, azure-wfov-unbinned, realsense-d435,\n"
    "                     realsense-d435-640 (docs/runtime/frames.md)\n"
    "  --fx F --fy F --cx C --cy C  intrinsics on top of the preset, pixels (--fx alone sets both);\n"
    "                     the noise model's disparity follows fx\n"
    "  --sensor NAME      depth camera modelled (default kinect-v1): kinect-v2 and azure-nfov\n"
    "                     (NFOV unbinned) are time of flight, rendered at their own size and\n"
    "                     intrinsics unless --camera/--fx is given (renderer/README.md \"Sensor models\")\n"
    "  --flying-pixels P  share of depth-edge pixels read between the two surfaces (default: the\n"
    "                     sensor's; kinect-v1 0)\n"
    "  --range-holes P    hole probability at 4 m, growing as z^2 (default: the sensor's)\n"
    "  --grazing-holes P  hole probability on surfaces seen edge-on (default: the sensor's)\n"
    "  --sitting P        share of people sat down: thighs forward, knees bent (default 0)\n"
    "  --leaning P        share of people leaning the upper body forward, back or sideways\n"
    "                     (default 0; renderer/pose_sampler.h SitDown, LeanTrunk)\n"
  "  --clutter LIST     comma-separated: floor, walls (a back and a side wall), boxes (1-3\n"
    "                     boxes on the floor); a pure function of (seed, frame) like the rest\n"
    "  --occluders N      N boxes per frame between the camera and the people (default 0)\n"
    "  --masks            write mask_%06d.png also without clutter\n"
    "  --realism          render as a training job does by default: a quarter of the frames on the\n"
    "                     upper body (camera 0.6-2 m, aimed between chest and head), half the\n"
    "                     people's arms re-posed toward the camera or near the body, Kinect v1's\n"
    "                     projector shadow and 0.45 m near limit (renderer/README.md, \"Framing,\n"
    "                     arms and the sensor\"); default: the classic renders\n"
    "  --montage FILE.png preview of the first 8 frames: depth grey | part colours, 4x2 grid\n"
    "  --poses FILE.pfposes  draw poses from this mocap pose library (poseforest-poselib build)\n"
    "                     instead of the procedural pose sampler\n"
    "  --clips train|test|all  clips of --poses to use (default all); a clip is a test clip\n"
    "                     when a hash of (clip name, --split-seed) is below --test-fraction\n"
    "  --test-fraction F  share of clips in the test set, 0..1 (default 0.2)\n"
    "  --split-seed S     seed of the clip split (default 0)\n"
    "  --bodies procedural|makehuman|all  body family (default procedural); makehuman = the 18\n"
    "                     MakeHuman presets from DATA/meshes/makehuman_hm08_kit\n"
    "  --sampled-bodies N with makehuman/all: N more MakeHuman bodies sampled over the macro\n"
    "                     targets (gender, age 6-90, weight, muscle, height) after the presets\n"
    "  --clothed F        with makehuman/all: share 0..1 of the MakeHuman bodies dressed (outfit,\n"
    "                     hair, shoes) from DATA/meshes/makehuman_clothes (default 0)\n"
    "  --body-seed S      seed of the sampled bodies and of the outfits (default 1)\n"
    "  --data DIR         shared data folder (default: $POSEFOREST_DATA_DIR, else the build's\n"
    "                     " POSEFOREST_RENDER_DATA_DIR
    ")\n"
    "  --help             this text\n";

std::string FrameName(const std::string& dir, const char* stem, uint64_t i, const char* ext) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s_%06llu.%s", stem, static_cast<unsigned long long>(i), ext);
  return (std::filesystem::path(dir) / buf).string();
}

/// `v` rounded to `decimals` places: the precision the files have always had (0.01 mm, 0.01 px).
double Rounded(double v, double decimals) {
  const double scale = std::pow(10.0, decimals);
  return std::isfinite(v) ? std::round(v * scale) / scale : 0.0;
}

std::string JointsJson(const renderer::RenderedFrame& f, const core::CameraIntrinsics& cam, uint64_t seed,
                       uint64_t index) {
  nlohmann::ordered_json people = nlohmann::ordered_json::array();
  for (size_t p = 0; p < f.joints.size(); ++p) {
    nlohmann::ordered_json joints = nlohmann::ordered_json::array();
    for (int j = 0; j < core::kNumJoints; ++j) {
      const Eigen::Vector3f q = f.joints[p][size_t(j)];
      const Eigen::Vector2d uv = q.z() > 0 ? cam.Project(q.cast<double>()) : Eigen::Vector2d(-1, -1);
      joints.push_back({{"name", std::string(core::JointName(j))},
                        {"x", Rounded(q.x(), 5)},
                        {"y", Rounded(q.y(), 5)},
                        {"z", Rounded(q.z(), 5)},
                        {"u", Rounded(uv.x(), 2)},
                        {"v", Rounded(uv.y(), 2)},
                        {"visible", bool(f.visible[p][size_t(j)])}});
    }
    people.push_back({{"joints", std::move(joints)}});
  }
  const nlohmann::ordered_json doc = {
      {"seed", seed},
      {"index", index},
      {"units", "metres, camera frame: x right, y down, z forward; u, v pixels"},
      {"people", std::move(people)}};
  return doc.dump(2) + "\n";
}

}  // namespace

int RenderMain(int argc, char** argv) {
  Args args(
      {"out",           "count",      "seed",   "threads", "rotation", "people", "montage", "poses", "clips",
       "test-fraction", "split-seed", "bodies", "data",    "camera",   "fx",     "fy",      "cx",    "cy",
       "clutter",       "occluders", "sampled-bodies", "clothed", "body-seed",
       "sensor",        "flying-pixels", "range-holes", "grazing-holes", "sitting", "leaning"},
      {"no-noise", "masks", "help", "realism"});
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
  auto occluders = args.GetInt("occluders", 0, 0, 16);
  for (const auto* r : {&count, &threads, &rotation, &people, &occluders}) {
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
  // Poses and bodies: checked before anything is written.
  const std::string clips = args.GetOr("clips", "all"), bodies = args.GetOr("bodies", "procedural");
  if (clips != "all" && clips != "train" && clips != "test") {
    std::fprintf(stderr, "poseforest render: --clips must be train, test or all, not '%s'\n", clips.c_str());
    return 2;
  }
  if (bodies != "procedural" && bodies != "makehuman" && bodies != "all") {
    std::fprintf(stderr, "poseforest render: --bodies must be procedural, makehuman or all, not '%s'\n",
                 bodies.c_str());
    return 2;
  }
  if (bodies == "procedural") {
    for (const char* o : {"sampled-bodies", "clothed", "body-seed"}) {
      if (args.Has(o)) {
        std::fprintf(stderr, "poseforest render: --%s needs MakeHuman bodies (--bodies makehuman or all)\n", o);
        return 2;
      }
    }
  }
  renderer::MakeHumanBodyOptions mh_options;
  {
    auto sampled = args.GetInt("sampled-bodies", 0, 0, 2000);
    if (!sampled.ok()) {
      std::fprintf(stderr, "poseforest render: %s\n", sampled.status().message().c_str());
      return 2;
    }
    mh_options.sampled_bodies = int(*sampled);
    if (auto f = args.Get("clothed")) {
      char* end = nullptr;
      mh_options.clothed_share = std::strtod(f->c_str(), &end);
      if (f->empty() || *end != '\0' || !(mh_options.clothed_share >= 0 && mh_options.clothed_share <= 1)) {
        std::fprintf(stderr, "poseforest render: --clothed must be a number in [0, 1], not '%s'\n", f->c_str());
        return 2;
      }
    }
    if (auto s = args.Get("body-seed")) {
      char* end = nullptr;
      mh_options.seed = std::strtoull(s->c_str(), &end, 10);
      if (s->empty() || *end != '\0' || (*s)[0] == '-') {
        std::fprintf(stderr, "poseforest render: --body-seed must be a non-negative integer, not '%s'\n",
                     s->c_str());
        return 2;
      }
    }
  }
  if (!args.Has("poses")) {
    for (const char* o : {"clips", "test-fraction", "split-seed"}) {
      if (args.Has(o)) {
        std::fprintf(stderr, "poseforest render: --%s needs --poses FILE.pfposes\n", o);
        return 2;
      }
    }
  }
  double test_fraction = 0.2;
  if (auto f = args.Get("test-fraction")) {
    char* end = nullptr;
    test_fraction = std::strtod(f->c_str(), &end);
    if (f->empty() || *end != '\0' || !(test_fraction >= 0 && test_fraction <= 1)) {
      std::fprintf(stderr, "poseforest render: --test-fraction must be a number in [0, 1], not '%s'\n",
                   f->c_str());
      return 2;
    }
  }
  uint64_t split_seed = 0;
  if (auto s = args.Get("split-seed")) {
    char* end = nullptr;
    split_seed = std::strtoull(s->c_str(), &end, 10);
    if (s->empty() || *end != '\0' || (*s)[0] == '-') {
      std::fprintf(stderr, "poseforest render: --split-seed must be a non-negative integer, not '%s'\n",
                   s->c_str());
      return 2;
    }
  }

  renderer::SceneConfig config;
  runtime::CameraModel camera;
  bool camera_given = false;
  if (core::Status st = ParseCameraOptions(args, &camera, &camera_given); !st.ok()) {
    std::fprintf(stderr, "poseforest render: %s\n", st.message().c_str());
    return 2;
  }
  // The sensor's noise model and, unless a camera is given, its size and intrinsics.
  renderer::DepthSensor sensor = renderer::DepthSensor::kKinectV1;
  if (auto name = args.Get("sensor"); name && !renderer::ParseDepthSensor(*name, &sensor)) {
    std::fprintf(stderr, "poseforest render: --sensor takes kinect-v1, kinect-v2 or azure-nfov, not '%s'\n",
                 name->c_str());
    return 2;
  }
  const renderer::SensorPreset preset = renderer::SensorNoise(sensor);
  if (!camera_given && sensor != renderer::DepthSensor::kKinectV1) {
    camera.name = renderer::DepthSensorName(sensor);
    camera.intrinsics = preset.camera;
  }
  config.camera = camera.intrinsics;
  config.noise = preset.noise;
  config.noise.focal_px = camera.intrinsics.fx;  // disparity and surface normals at this focal length
  {
    struct Share {
      const char* option;
      double* value;
    };
    for (const Share& share : {Share{"flying-pixels", &config.noise.flying_pixels},
                               Share{"range-holes", &config.noise.range_dropout},
                               Share{"grazing-holes", &config.noise.grazing_dropout},
                               Share{"sitting", &config.sit_share}, Share{"leaning", &config.lean_share}}) {
      auto v = GetDouble(args, share.option, *share.value, 0.0, 1.0);
      if (!v.ok()) {
        std::fprintf(stderr, "poseforest render: %s\n", v.status().message().c_str());
        return 2;
      }
      *share.value = *v;
    }
  }
  if (auto list = args.Get("clutter")) {
    size_t start = 0;
    while (start <= list->size()) {
      const size_t comma = std::min(list->find(',', start), list->size());
      const std::string item = list->substr(start, comma - start);
      if (item == "floor") {
        config.clutter.floor = true;
      } else if (item == "walls") {
        config.clutter.walls = true;
      } else if (item == "boxes") {
        config.clutter.boxes = true;
      } else {
        std::fprintf(
            stderr, "poseforest render: --clutter takes floor, walls and boxes (comma-separated), not '%s'\n",
            item.c_str());
        return 2;
      }
      start = comma + 1;
    }
  }
  config.clutter.occluders = int(*occluders);
  const bool write_masks = config.clutter.enabled() || args.Has("masks");
  if (auto poses = args.Get("poses")) {
    renderer::PoseSelection sel;
    sel.library = *poses;
    sel.clips = clips == "train"  ? renderer::ClipSet::kTrain
                : clips == "test" ? renderer::ClipSet::kTest
                                  : renderer::ClipSet::kAll;
    sel.test_fraction = test_fraction;
    sel.split_seed = split_seed;
    auto lib = renderer::LoadPoseSelection(sel);
    if (!lib.ok()) {
      std::fprintf(stderr, "poseforest render: --poses %s\n", lib.status().ToString().c_str());
      return 1;
    }
    config.shared_poses = *lib;  // one copy shared by every thread's renderer
    std::printf("poses: %zu from the %s clips of %s\n", (*lib)->size(), clips.c_str(), poses->c_str());
  }
  config.use_procedural_bodies = bodies != "makehuman";
  if (bodies != "procedural") {
    std::filesystem::path data = POSEFOREST_RENDER_DATA_DIR;
    if (const char* env = std::getenv("POSEFOREST_DATA_DIR"); env && *env) data = env;
    if (auto d = args.Get("data")) data = *d;
    const std::filesystem::path kit = data / "meshes" / "makehuman_hm08_kit";
    std::error_code dir_ec;
    if (!std::filesystem::is_directory(kit, dir_ec)) {
      std::fprintf(stderr,
                   "poseforest render: --bodies %s: %s: MakeHuman kit folder not found (set --data DIR or "
                   "POSEFOREST_DATA_DIR to the shared data folder)\n",
                   bodies.c_str(), kit.string().c_str());
      return 1;
    }
    mh_options.clothes_dir = data / "meshes" / "makehuman_clothes";
    auto made = renderer::MakeHumanBodies(kit, mh_options);
    if (!made.ok()) {
      std::fprintf(stderr, "poseforest render: --bodies %s: %s\n", bodies.c_str(),
                   made.status().ToString().c_str());
      return 1;
    }
    config.bodies = std::move(made).value();
    std::printf("bodies: %zu MakeHuman (18 presets + %d sampled, clothed share %g) from %s%s\n",
                config.bodies.size(), mh_options.sampled_bodies, mh_options.clothed_share, kit.string().c_str(),
                bodies == "all" ? " + the procedural family" : "");
  }

  std::error_code ec;
  std::filesystem::create_directories(*out, ec);
  if (ec) {
    std::fprintf(stderr, "poseforest render: cannot create %s: %s\n", out->c_str(), ec.message().c_str());
    return 1;
  }

  config.rotation_range_deg = *rotation == 360 ? 180.0 : 120.0;
  config.min_people = config.max_people = int(*people);
  config.noise.enabled = !args.Has("no-noise");
  if (args.Has("realism")) {  // the job defaults (engine/job_spec.h SourceSpec)
    config.framing.upper_body_share = 0.25;
    config.arm_pose_share = 0.5;
    config.noise.projector_shadow = true;
    config.noise.min_range_m = 0.45;
  }

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
      if (st.ok() && write_masks) st = runtime::WriteLabelPng(FrameName(*out, "mask", i, "png"), f->people);
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
  if (core::Status st =
          runtime::WriteCameraModelFile((std::filesystem::path(*out) / "camera.txt").string(), camera);
      !st.ok()) {
    std::fprintf(stderr, "poseforest render: %s\n", st.ToString().c_str());
    return 1;
  }
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
  std::printf("camera: %s\n", camera.Describe().c_str());
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

}  // namespace poseforest::apps::commands
