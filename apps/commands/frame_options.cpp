#include "apps/commands/frame_options.h"

#include <cstdio>
#include <cstdlib>
#include <utility>

namespace poseforest::apps::commands {

core::Result<double> GetDouble(const Args& args, const std::string& name, double fallback, double lo,
                               double hi) {
  const auto v = args.Get(name);
  if (!v) return fallback;
  char* end = nullptr;
  const double d = std::strtod(v->c_str(), &end);
  if (end == v->c_str() || *end != '\0' || !(d >= lo && d <= hi))
    return core::Status(core::ErrorCode::kInvalidArgument, "--" + name + " must be a number in [" +
                                                               std::to_string(lo) + ", " +
                                                               std::to_string(hi) + "] (got '" + *v + "')");
  return d;
}

core::Status ParseCameraOptions(const Args& args, runtime::CameraModel* out, bool* given) {
  // Camera model: a preset, then explicit intrinsics on top.
  const bool camera_flags =
      args.Has("camera") || args.Has("fx") || args.Has("fy") || args.Has("cx") || args.Has("cy");
  if (given) *given = camera_flags;
  auto preset = runtime::CameraPreset(args.GetOr("camera", "kinect-v1"));
  if (!preset.ok()) return {preset.status().code(), "--camera: " + preset.status().message()};
  *out = *preset;
  auto& k = out->intrinsics;
  bool custom = false;
  for (const auto& [name, field] :
       {std::pair<const char*, double*>{"fx", &k.fx}, {"fy", &k.fy}, {"cx", &k.cx}, {"cy", &k.cy}}) {
    auto v = GetDouble(args, name, *field, 1e-3, 1e6);
    if (!v.ok()) return v.status();
    custom |= args.Has(name);
    *field = *v;
  }
  if (args.Has("fx") && !args.Has("fy")) k.fy = k.fx;  // square pixels unless told
  if (custom) out->name += "+custom";
  return core::Status::Ok();
}

core::Status ParseFrameSourceOptions(const Args& args, runtime::FrameSourceOptions* out) {
  runtime::FrameSourceOptions& o = *out;
  bool camera_flags = false;
  if (auto st = ParseCameraOptions(args, &o.camera, &camera_flags); !st.ok()) return st;
  auto& k = o.camera.intrinsics;
  auto scale = GetDouble(args, "depth-scale", 1.0, 1e-6, 1e6);
  if (!scale.ok()) return scale.status();
  o.camera.depth_scale_mm = *scale;
  o.camera_given = camera_flags;
  if (auto rs = args.Get("raw-size")) {
    int w = 0, h = 0;
    if (std::sscanf(rs->c_str(), "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0 || w > 32768 || h > 32768)
      return {core::ErrorCode::kInvalidArgument, "--raw-size must be WxH, e.g. 640x480 (got '" + *rs + "')"};
    o.raw_width = w, o.raw_height = h;
    // Without a camera flag, --raw-size says the frame size: the default model follows it
    // (principal point at the centre, Kinect v1 focal length).
    if (!camera_flags) k.width = w, k.height = h, k.cx = (w - 1) / 2.0, k.cy = (h - 1) / 2.0;
  }
  auto fps = GetDouble(args, "fps", 0.0, 0.0, 100000.0);
  if (!fps.ok()) return fps.status();
  o.fps = *fps;
  return core::Status::Ok();
}

}  // namespace poseforest::apps::commands
