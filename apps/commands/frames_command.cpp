// poseforest frames: read any frame source, say what it holds, and convert it (16-bit PNGs, a
// .npy, a fakenect recording). The way to check a camera or a recording before inference.
#include <cstdio>
#include <filesystem>
#include <set>
#include <vector>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "apps/devices/fakenect_recording.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"

namespace poseforest::apps::commands {
namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage = R"(usage: poseforest frames [options] SOURCE [SOURCE...]
       poseforest frames --list-devices

Reads depth frames from any source `poseforest infer` reads (files, folders, globs, - for raw
frames on stdin, .npy, .pcd, freenect:N, openni2:URI; see docs/runtime/frames.md), prints one line
per frame (size, valid pixels, depth range, timestamp) and optionally writes them out. Bad frames
are reported naming the source and frame, skipped and counted (exit status 1 if any).

options:
  --out-dir DIR        write each frame as a 16-bit PNG in millimetres (DIR/<name>.png)
  --npy FILE           write all frames as one uint16 .npy [N, H, W] (mm)
  --fakenect DIR       write the frames as a fakenect recording (640x480 only): replay it through
                       libfreenect with LD_LIBRARY_PATH=/usr/lib/<arch>/fakenect FAKENECT_PATH=DIR
  --record-fps N       frame rate of the fakenect recording (default 30)
  --max-frames N       stop after N good frames (a camera streams until stopped)
  --camera PRESET, --fx --fy --cx --cy, --depth-scale S, --raw-size WxH, --fps N: as for infer
  --list-devices       the device back ends built in and the devices they see
  --quiet              print only errors and the summary
  --help               this text
)";

}  // namespace

int FramesMain(int argc, char** argv) {
  std::set<std::string> value_options = {"out-dir", "npy", "fakenect", "record-fps", "max-frames"};
  for (const char* o : kFrameSourceValueOptions) value_options.insert(o);
  Args args(value_options, {"help", "quiet", "list-devices"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (args.Has("list-devices")) {
    const auto back_ends = runtime::FrameBackEnds();
    if (back_ends.empty())
      std::printf("no device back ends in this build (libfreenect, OpenNI2: found at configure time)\n");
    for (const auto& b : back_ends)
      std::printf("%s: %s: %s\n", b.scheme.c_str(), b.describe.c_str(), b.list_devices().c_str());
    return 0;
  }
  if (args.positional().empty()) {
    std::fprintf(stderr, "poseforest frames: no source given\n\n%s", kUsage);
    return 2;
  }
  runtime::FrameSourceOptions options;
  if (auto st = ParseFrameSourceOptions(args, &options); !st.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n", st.message().c_str());
    return 2;
  }
  auto record_fps = GetDouble(args, "record-fps", 30.0, 0.001, 10000.0);
  if (!record_fps.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n", record_fps.status().message().c_str());
    return 2;
  }
  auto max_frames = args.GetInt("max-frames", -1, 1, 1L << 40);
  if (!max_frames.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n", max_frames.status().message().c_str());
    return 2;
  }
  const bool quiet = args.Has("quiet");
  const auto out_dir = args.Get("out-dir");
  if (out_dir) {
    std::error_code ec;
    fs::create_directories(*out_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest frames: %s: cannot create folder: %s\n", out_dir->c_str(),
                   ec.message().c_str());
      return 1;
    }
  }
  auto source = runtime::OpenFrameSources(args.positional(), options);
  if (!source.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n", source.status().ToString().c_str());
    return 1;
  }
  std::vector<core::DepthImage> kept;  // for --npy / --fakenect
  const bool keep = args.Has("npy") || args.Has("fakenect");
  int good = 0, bad = 0, write_errors = 0, bad_in_a_row = 0;
  runtime::Frame f;
  while (*max_frames < 0 || good < *max_frames) {
    auto r = (*source)->Next(&f);
    if (!r.ok()) {
      std::fprintf(stderr, "poseforest frames: %s\n", r.status().ToString().c_str());
      ++bad;
      if (++bad_in_a_row >= runtime::kMaxConsecutiveBadFrames) {
        std::fprintf(stderr, "poseforest frames: %s: giving up after %d bad frames in a row\n",
                     (*source)->Describe().c_str(), bad_in_a_row);
        break;
      }
      continue;
    }
    bad_in_a_row = 0;
    if (!*r) break;
    ++good;
    int valid = 0, lo = 65535, hi = 0;
    for (uint16_t d : f.depth.pixels)
      if (d) ++valid, lo = std::min<int>(lo, d), hi = std::max<int>(hi, d);
    if (!quiet)
      std::printf("%s: %dx%d, %d valid pixels, %d..%d mm, t %.3f s, camera %s\n", f.Name().c_str(),
                  f.depth.width, f.depth.height, valid, valid ? lo : 0, hi, f.timestamp_s,
                  f.camera.Describe().c_str());
    if (out_dir) {
      char stem[32];
      std::snprintf(stem, sizeof stem, "frame-%06lld.png", static_cast<long long>(f.index));
      const auto st = runtime::WriteDepthPng((fs::path(*out_dir) / stem).string(), f.depth);
      if (!st.ok()) std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
    }
    if (keep) kept.push_back(f.depth);
  }
  if (auto npy = args.Get("npy"); npy && !kept.empty()) {
    const auto st = runtime::WriteDepthNpy(*npy, kept);
    if (!st.ok()) std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
  }
  if (auto dir = args.Get("fakenect"); dir && !kept.empty()) {
    const auto st = apps::devices::WriteFakenectRecording(*dir, kept, *record_fps);
    if (!st.ok())
      std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
    else if (!quiet)
      std::printf("wrote a fakenect recording of %zu frames to %s\n", kept.size(), dir->c_str());
  }
  std::printf("%s: %d frame(s), %d bad frame(s) skipped\n", (*source)->Describe().c_str(), good, bad);
  return bad == 0 && write_errors == 0 ? 0 : 1;
}

}  // namespace poseforest::apps::commands
