// `poseforest render`: renders a synthetic labelled depth dataset (16-bit depth PNGs in mm, label
// PNGs, joint JSON) and a preview montage like Fig. 2 of the paper (depth as grey + part colours).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "engine/image_source.h"
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


class RenderCommand final : public Command {
 public:
  RenderCommand();
  int Run() override;

 private:
  /// The scene of the options (camera, sensor, noise, shares, clutter, poses, bodies) into
  /// `config` and `camera`: nullopt to go on, else the exit code.
  std::optional<int> MakeScene(renderer::SceneConfig* config, runtime::CameraModel* camera) const;
  /// --poses and --bodies into `config`: nullopt to go on, else the exit code.
  std::optional<int> LoadPosesAndBodies(renderer::SceneConfig* config) const;
  /// Renders the frames with --threads EGL contexts and writes them, then the montage.
  int RenderFrames(const renderer::SceneConfig& config, const runtime::CameraModel& camera) const;

  std::string out_, clips_ = "all", bodies_ = "procedural", montage_, rotation_ = "120";
  std::optional<std::string> poses_, data_, sensor_, clutter_;
  long count_ = 16;
  int threads_ = 1, people_ = 1, occluders_ = 0, sampled_bodies_ = 0;
  uint64_t seed_ = 1, split_seed_ = 0, body_seed_ = 1;
  double test_fraction_ = 0.2, clothed_ = 0.0, sitting_ = 0.0, leaning_ = 0.0;
  std::optional<double> flying_pixels_, range_holes_, grazing_holes_;  ///< default: the sensor's
  bool no_noise_ = false, masks_ = false, realism_ = false;
  CameraFlags camera_;
};

/// Frame files in `dir` (depth_, labels_, joints_, mask_ NNNNNN) that a render of `count` frames
/// would not write over: "depth_000004.png and 3 more", or empty.
std::string StaleFrameFiles(const std::string& dir, long count, bool writes_masks) {
  static const std::regex kFrameFile(R"((depth|labels|joints|mask)_([0-9]{6,9})\.(png|json))");
  std::vector<std::string> stale;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    std::smatch m;
    if (!std::regex_match(name, m, kFrameFile)) continue;
    if (std::stol(m[2].str()) >= count || (m[1] == "mask" && !writes_masks)) stale.push_back(name);
  }
  if (stale.empty()) return "";
  std::sort(stale.begin(), stale.end());
  return stale.front() + (stale.size() > 1 ? " and " + std::to_string(stale.size() - 1) + " more" : "");
}

RenderCommand::RenderCommand()
    : Command("render",
              "Renders synthetic depth frames of people with ground-truth body parts and joints\n"
              "(headless EGL; procedural bodies and poses unless told otherwise). Files in DIR, for\n"
              "i = 0..N-1:\n"
              "  depth_%06d.png   16-bit depth, millimetres (0 = background)\n"
              "  labels_%06d.png  8-bit part id 0..30 (255 = background)\n"
              "  joints_%06d.json 16 joints per person, camera frame (metres) + pixel + visibility\n"
              "  mask_%06d.png    8-bit person id (0 = none, k = person k of the joints file), with\n"
              "                   --clutter, --occluders or --masks\n"
              "  camera.txt       the camera model (name, size, fx fy cx cy in pixels)\n"
              "A folder that holds frames of an earlier render which this one would not replace (more\n"
              "frames, or masks) is refused: they would mix with the new ones.") {
  app_.add_option("--out", out_, "output folder (created)")->type_name("DIR")->required();
  app_.add_option("--count", count_, "frames to render")->type_name("N")->check(IntIn(1, 100000000));
  app_.add_option("--seed", seed_, "stream seed; frame i is a pure function of (S, i)")
      ->type_name("S")
      ->check(NonNegativeInt());
  app_.add_option("--threads", threads_, "rendering threads, one EGL context each")
      ->type_name("N")
      ->check(IntIn(1, 256));
  app_.add_option("--rotation", rotation_, "person rotation about the vertical: +-120 deg or any")
      ->type_name("120|360")
      ->check(OneOf({"120", "360"}));
  app_.add_option("--people", people_, "people per frame")->type_name("N")->check(IntIn(1, 8));
  app_.add_flag("--no-noise", no_noise_, "no Kinect noise model (clean rendered depth)");
  AddCameraOptions(app_, &camera_);
  app_.add_option("--sensor", sensor_,
                  "depth camera modelled (default kinect-v1): kinect-v2 and azure-nfov (NFOV unbinned)\n"
                  "are time of flight, rendered at their own size and intrinsics unless --camera/--fx\n"
                  "is given (renderer/README.md \"Sensor models\"); the noise model's disparity follows fx")
      ->type_name("NAME")
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            renderer::DepthSensor sensor;
            return renderer::ParseDepthSensor(v, &sensor) ? ""
                                                          : "must be kinect-v1, kinect-v2 or azure-nfov, not '" + v + "'";
          },
          ""));
  const auto share = NumberIn(0.0, 1.0);
  app_.add_option("--flying-pixels", flying_pixels_,
                  "share of depth-edge pixels read between the two surfaces (default: the sensor's;\n"
                  "kinect-v1 0)")
      ->type_name("P")
      ->check(share);
  app_.add_option("--range-holes", range_holes_, "hole probability at 4 m, growing as z^2 (default: the sensor's)")
      ->type_name("P")
      ->check(share);
  app_.add_option("--grazing-holes", grazing_holes_, "hole probability on surfaces seen edge-on (default: the sensor's)")
      ->type_name("P")
      ->check(share);
  app_.add_option("--sitting", sitting_, "share of people sat down: thighs forward, knees bent")
      ->type_name("P")
      ->check(share);
  app_.add_option("--leaning", leaning_,
                  "share of people leaning the upper body forward, back or sideways\n"
                  "(renderer/pose_sampler.h SitDown, LeanTrunk)")
      ->type_name("P")
      ->check(share);
  app_.add_option("--clutter", clutter_,
                  "comma-separated: floor, walls (a back and a side wall), boxes (1-3 boxes on the\n"
                  "floor); a pure function of (seed, frame) like the rest")
      ->type_name("LIST");
  app_.add_option("--occluders", occluders_, "N boxes per frame between the camera and the people")
      ->type_name("N")
      ->check(IntIn(0, 16));
  app_.add_flag("--masks", masks_, "write mask_%06d.png also without clutter");
  app_.add_flag("--realism", realism_,
                "render as a training job does by default: a quarter of the frames on the upper body\n"
                "(camera 0.6-2 m, aimed between chest and head), half the people's arms re-posed\n"
                "toward the camera or near the body, Kinect v1's projector shadow and 0.45 m near limit\n"
                "(renderer/README.md, \"Framing, arms and the sensor\"); default: the classic renders");
  app_.add_option("--montage", montage_, "preview of the first 8 frames: depth grey | part colours, 4x2 grid")
      ->type_name("FILE.png");
  app_.add_option("--poses", poses_,
                  "draw poses from this mocap pose library (poseforest-poselib build) instead of the\n"
                  "procedural pose sampler")
      ->type_name("FILE.pfposes");
  app_.add_option("--clips", clips_,
                  "clips of --poses to use; a clip is a test clip when a hash of (clip name,\n"
                  "--split-seed) is below --test-fraction")
      ->type_name("train|test|all")
      ->check(OneOf({"train", "test", "all"}));
  app_.add_option("--test-fraction", test_fraction_, "share of clips in the test set, 0..1")
      ->type_name("F")
      ->check(share);
  app_.add_option("--split-seed", split_seed_, "seed of the clip split")->type_name("S")->check(NonNegativeInt());
  app_.add_option("--bodies", bodies_,
                  "body family; makehuman = the 18 MakeHuman presets from\n"
                  "DATA/meshes/makehuman_hm08_kit")
      ->type_name("procedural|makehuman|all")
      ->check(OneOf({"procedural", "makehuman", "all"}));
  app_.add_option("--sampled-bodies", sampled_bodies_,
                  "with makehuman/all: N more MakeHuman bodies sampled over the macro targets (gender,\n"
                  "age 6-90, weight, muscle, height) after the presets")
      ->type_name("N")
      ->check(IntIn(0, 2000));
  app_.add_option("--clothed", clothed_,
                  "with makehuman/all: share 0..1 of the MakeHuman bodies dressed (outfit, hair,\n"
                  "shoes) from DATA/meshes/makehuman_clothes")
      ->type_name("F")
      ->check(share);
  app_.add_option("--body-seed", body_seed_, "seed of the sampled bodies and of the outfits")
      ->type_name("S")
      ->check(NonNegativeInt());
  app_.add_option("--data", data_,
                  "shared data folder (default: $POSEFOREST_DATA_DIR, else the build's\n" POSEFOREST_RENDER_DATA_DIR ")")
      ->type_name("DIR");
}

std::optional<int> RenderCommand::MakeScene(renderer::SceneConfig* config, runtime::CameraModel* camera) const {
  auto model = CameraFromFlags(camera_);
  if (!model.ok()) return UsageError(model.status().message());
  *camera = *model;
  // The sensor's noise model and, unless a camera is given, its size and intrinsics.
  renderer::DepthSensor sensor = renderer::DepthSensor::kKinectV1;
  if (sensor_) renderer::ParseDepthSensor(*sensor_, &sensor);  // checked by the declaration
  const renderer::SensorPreset preset = renderer::SensorNoise(sensor);
  if (!camera_.given() && sensor != renderer::DepthSensor::kKinectV1) {
    camera->name = renderer::DepthSensorName(sensor);
    camera->intrinsics = preset.camera;
  }
  config->camera = camera->intrinsics;
  config->noise = preset.noise;
  config->noise.focal_px = camera->intrinsics.fx;  // disparity and surface normals at this focal length
  if (flying_pixels_) config->noise.flying_pixels = *flying_pixels_;
  if (range_holes_) config->noise.range_dropout = *range_holes_;
  if (grazing_holes_) config->noise.grazing_dropout = *grazing_holes_;
  config->sit_share = sitting_;
  config->lean_share = leaning_;
  if (clutter_) {
    const std::string& list = *clutter_;
    size_t start = 0;
    while (start <= list.size()) {
      const size_t comma = std::min(list.find(',', start), list.size());
      const std::string item = list.substr(start, comma - start);
      if (item == "floor") {
        config->clutter.floor = true;
      } else if (item == "walls") {
        config->clutter.walls = true;
      } else if (item == "boxes") {
        config->clutter.boxes = true;
      } else {
        return UsageError("--clutter takes floor, walls and boxes (comma-separated), not '" + item + "'");
      }
      start = comma + 1;
    }
  }
  config->clutter.occluders = occluders_;
  return LoadPosesAndBodies(config);
}

std::optional<int> RenderCommand::LoadPosesAndBodies(renderer::SceneConfig* config) const {
  if (poses_) {
    renderer::PoseSelection sel;
    sel.library = *poses_;
    sel.clips = clips_ == "train"  ? renderer::ClipSet::kTrain
                : clips_ == "test" ? renderer::ClipSet::kTest
                                   : renderer::ClipSet::kAll;
    sel.test_fraction = test_fraction_;
    sel.split_seed = split_seed_;
    auto lib = renderer::LoadPoseSelection(sel);
    if (!lib.ok()) {
      std::fprintf(stderr, "poseforest render: --poses %s\n", lib.status().ToString().c_str());
      return 1;
    }
    config->shared_poses = *lib;  // one copy shared by every thread's renderer
    std::printf("poses: %zu from %s clips of %s\n", (*lib)->size(),
                clips_ == "all" ? "all the" : ("the " + clips_).c_str(), poses_->c_str());
  }
  config->use_procedural_bodies = bodies_ != "makehuman";
  if (bodies_ == "procedural") return std::nullopt;
  renderer::MakeHumanBodyOptions mh_options;
  mh_options.sampled_bodies = sampled_bodies_;
  mh_options.clothed_share = clothed_;
  mh_options.seed = body_seed_;
  std::filesystem::path data = POSEFOREST_RENDER_DATA_DIR;
  if (const char* env = std::getenv("POSEFOREST_DATA_DIR"); env && *env) data = env;
  if (data_) data = *data_;
  const std::filesystem::path kit = data / "meshes" / "makehuman_hm08_kit";
  std::error_code dir_ec;
  if (!std::filesystem::is_directory(kit, dir_ec)) {
    std::fprintf(stderr,
                 "poseforest render: --bodies %s: %s: MakeHuman kit folder not found (set --data DIR or "
                 "POSEFOREST_DATA_DIR to the shared data folder)\n",
                 bodies_.c_str(), kit.string().c_str());
    return 1;
  }
  mh_options.clothes_dir = data / "meshes" / "makehuman_clothes";
  auto made = renderer::MakeHumanBodies(kit, mh_options);
  if (!made.ok()) {
    std::fprintf(stderr, "poseforest render: --bodies %s: %s\n", bodies_.c_str(), made.status().ToString().c_str());
    return 1;
  }
  config->bodies = std::move(made).value();
  std::printf("bodies: %zu MakeHuman (18 presets + %d sampled, clothed share %g) from %s%s\n", config->bodies.size(),
              mh_options.sampled_bodies, mh_options.clothed_share, kit.string().c_str(),
              bodies_ == "all" ? " + the procedural family" : "");
  return std::nullopt;
}

int RenderCommand::Run() {
  // Poses and bodies: checked before anything is written.
  if (bodies_ == "procedural")
    for (const char* o : {"sampled-bodies", "clothed", "body-seed"})
      if (Given(o)) return UsageError(std::string("--") + o + " needs MakeHuman bodies (--bodies makehuman or all)");
  if (!poses_)
    for (const char* o : {"clips", "test-fraction", "split-seed"})
      if (Given(o)) return UsageError(std::string("--") + o + " needs --poses FILE.pfposes");
  renderer::SceneConfig config;
  runtime::CameraModel camera;
  if (auto rc = MakeScene(&config, &camera)) return *rc;

  std::error_code ec;
  std::filesystem::create_directories(out_, ec);
  if (ec) {
    std::fprintf(stderr, "poseforest render: cannot create %s: %s\n", out_.c_str(), ec.message().c_str());
    return 1;
  }
  // Files of an earlier render that this one would not write over (frames past --count, masks
  // when it writes none) would mix with it: `eval` reads every frame of the folder.
  if (const std::string stale = StaleFrameFiles(out_, count_, config.clutter.enabled() || masks_);
      !stale.empty())
    return UsageError(out_ + " holds files of an earlier render that this one would not replace (" + stale +
                      "); they would mix with its frames: remove them or give another folder");
  config.rotation_range_deg = rotation_ == "360" ? 180.0 : 120.0;
  config.min_people = config.max_people = people_;
  config.noise.enabled = !no_noise_;
  if (realism_) {  // the job defaults (engine/job_spec.h SourceSpec)
    config.framing.upper_body_share = 0.25;
    config.arm_pose_share = 0.5;
    config.noise.projector_shadow = true;
    config.noise.min_range_m = 0.45;
  }
  // llvmpipe: rasterize on each worker thread itself (no helper threads), since we run one
  // context per worker thread. An LP_NUM_THREADS already set by the user wins.
  setenv("LP_NUM_THREADS", "0", 0);
  return RenderFrames(config, camera);
}

int RenderCommand::RenderFrames(const renderer::SceneConfig& config, const runtime::CameraModel& camera) const {
  const bool write_masks = config.clutter.enabled() || masks_;
  const uint64_t seed = seed_;
  const std::string* out = &out_;
  const int n_threads = int(std::min<long>(threads_, std::max<long>(1, count_)));
  const uint64_t n = uint64_t(count_);
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
      if (st.ok()) st = runtime::WriteDepthPng(engine::DatasetFramePath(*out, "depth", i, "png"), f->depth);
      if (st.ok()) st = runtime::WriteLabelPng(engine::DatasetFramePath(*out, "labels", i, "png"), f->labels);
      if (st.ok() && write_masks) st = runtime::WriteLabelPng(engine::DatasetFramePath(*out, "mask", i, "png"), f->people);
      if (st.ok()) {
        const std::string path = engine::DatasetFramePath(*out, "joints", i, "json");
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
  if (const std::string& montage = montage_; Given("montage") && n_montage > 0) {
    const renderer::RgbImage m = renderer::MakeMontage(montage_frames, 4, 2, 2);
    if (core::Status st = runtime::WriteRgbPng(montage, m.width, m.height, m.rgb); !st.ok()) {
      std::fprintf(stderr, "poseforest render: %s\n", st.ToString().c_str());
      return 1;
    }
    std::printf("montage: %s (%dx%d)\n", montage.c_str(), m.width, m.height);
  }
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeRenderCommand() { return std::make_unique<RenderCommand>(); }

}  // namespace poseforest::apps::commands
