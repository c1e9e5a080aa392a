#include "apps/commands/frame_options.h"

#include <cmath>
#include <cstdio>

#include "apps/commands/cli.h"

namespace poseforest::apps::commands {

namespace {
/// "WxH" with both sides in 1..32768.
bool ParseSize(const std::string& text, int* w, int* h) {
  return std::sscanf(text.c_str(), "%dx%d", w, h) == 2 && *w > 0 && *h > 0 && *w <= 32768 && *h <= 32768;
}
}  // namespace

void AddCameraOptions(CLI::App& app, CameraFlags* out) {
  const char* group = "camera (docs/runtime/frames.md)";
  app.add_option("--camera", out->camera,
                 "camera model (default kinect-v1): kinect-v1 (640x480), kinect-v2 (512x424), azure-nfov\n"
                 "(640x576), azure-nfov-binned (320x288), azure-wfov (512x512), azure-wfov-unbinned\n"
                 "(1024x1024), realsense-d435 (848x480), realsense-d435-640 (640x480)")
      ->type_name("PRESET")
      ->group(group);
  const auto positive = NumberIn(1e-3, 1e6);
  app.add_option("--fx", out->fx, "focal length in x, pixels, on top of the preset (--fx alone sets both)")
      ->type_name("F")
      ->check(positive)
      ->group(group);
  app.add_option("--fy", out->fy, "focal length in y, pixels")->type_name("F")->check(positive)->group(group);
  app.add_option("--cx", out->cx, "principal point x, pixels")->type_name("C")->check(positive)->group(group);
  app.add_option("--cy", out->cy, "principal point y, pixels")->type_name("C")->check(positive)->group(group);
}

core::Result<runtime::CameraModel> CameraFromFlags(const CameraFlags& flags) {
  auto preset = runtime::CameraPreset(flags.camera.value_or("kinect-v1"));
  if (!preset.ok()) return core::Status(preset.status().code(), "--camera: " + preset.status().message());
  runtime::CameraModel out = *preset;
  auto& k = out.intrinsics;
  if (flags.fx) k.fx = *flags.fx;
  if (flags.fy) k.fy = *flags.fy;
  if (flags.cx) k.cx = *flags.cx;
  if (flags.cy) k.cy = *flags.cy;
  if (flags.fx && !flags.fy) k.fy = k.fx;  // square pixels unless told
  if (flags.fx || flags.fy || flags.cx || flags.cy) out.name += "+custom";
  return out;
}

void AddFrameSourceOptions(CLI::App& app, FrameSourceFlags* out) {
  AddCameraOptions(app, &out->camera);
  const char* group = "camera (docs/runtime/frames.md)";
  app.add_option("--depth-scale", out->depth_scale, "millimetres per raw depth unit (raw, PNG and uint16 .npy)")
      ->type_name("S")
      ->check(NumberIn(1e-6, 1e6))
      ->group(group);
  app.add_option("--raw-size", out->raw_size,
                 "size of raw depth frames (default: the camera's, 640x480); without a camera option\n"
                 "the default model follows it (principal point at the centre)")
      ->type_name("WxH")
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            int w = 0, h = 0;
            return ParseSize(v, &w, &h) ? "" : "must be WxH, e.g. 640x480 (got '" + v + "')";
          },
          ""))
      ->group(group);
  app.add_option("--fps", out->fps, "deliver at most N frames per second (a folder played at camera rate; 0: as\n"
                                    "fast as they come)")
      ->type_name("N")
      ->check(NumberIn(0.0, 100000.0))
      ->group(group);
}

core::Result<runtime::FrameSourceOptions> FrameSourceFromFlags(const FrameSourceFlags& flags) {
  runtime::FrameSourceOptions o;
  auto camera = CameraFromFlags(flags.camera);
  if (!camera.ok()) return camera.status();
  o.camera = *camera;
  o.camera.depth_scale_mm = flags.depth_scale;
  o.camera_given = flags.camera.given();
  if (int w = 0, h = 0; flags.raw_size && ParseSize(*flags.raw_size, &w, &h)) {
    o.raw_width = w, o.raw_height = h;
    // Without a camera flag, --raw-size says the frame size: the default model follows it
    // (principal point at the centre, Kinect v1 focal length).
    auto& k = o.camera.intrinsics;
    if (!o.camera_given) k.width = w, k.height = h, k.cx = (w - 1) / 2.0, k.cy = (h - 1) / 2.0;
  }
  o.fps = flags.fps;
  return o;
}

void AddSegmentationOptions(CLI::App& app, SegmentationFlags* out) {
  const char* group = "segmentation";
  app.add_option("--segment", out->segment,
                 "auto: segment raw frames, pass pre-segmented ones unchanged; on: always segment; off:\n"
                 "every pixel with depth > 0 is foreground")
      ->type_name("auto|on|off")
      ->check(OneOf({"auto", "on", "off"}))
      ->group(group);
  app.add_option("--floor", out->floor, "a known floor plane A*x + B*y + C*z + D = 0 (camera frame, metres)")
      ->type_name("A,B,C,D")
      ->group(group);
  app.add_option("--near", out->near, "depth band in metres: nearest (default 0.4)")
      ->type_name("M")
      ->check(NumberIn(0.0, 60.0))
      ->group(group);
  app.add_option("--far", out->far, "depth band in metres: farthest (default 4.5)")
      ->type_name("M")
      ->check(NumberIn(0.0, 65.0))
      ->group(group);
}

core::Status SegmentationFromFlags(const SegmentationFlags& flags, runtime::SegmentationOptions* out) {
  if (flags.floor) {
    double a, b, c, d;
    if (std::sscanf(flags.floor->c_str(), "%lf,%lf,%lf,%lf", &a, &b, &c, &d) != 4 || std::hypot(a, b, c) < 1e-9)
      return {core::ErrorCode::kInvalidArgument, "--floor must be A,B,C,D with (A,B,C) != 0 (got '" + *flags.floor + "')"};
    const double n = std::hypot(a, b, c);
    out->floor_plane = Eigen::Vector4d(a / n, b / n, c / n, d / n);
  }
  const double near = flags.near.value_or(out->near_m), far = flags.far.value_or(out->far_m);
  if (near >= far) return {core::ErrorCode::kInvalidArgument, "--near must be less than --far"};
  out->near_m = near, out->far_m = far;
  return core::Status::Ok();
}

}  // namespace poseforest::apps::commands
