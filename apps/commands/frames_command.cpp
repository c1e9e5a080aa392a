// poseforest frames: read any frame source, say what it holds, and convert it (16-bit PNGs, a
// .npy, a fakenect recording). The way to check a camera or a recording before inference.
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "apps/devices/fakenect_recording.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"

namespace poseforest::apps::commands {
namespace {

namespace fs = std::filesystem;

class FramesCommand final : public Command {
 public:
  FramesCommand()
      : Command("frames",
                "Reads depth frames from any source `poseforest infer` reads (files, folders, globs, - for raw\n"
                "frames on stdin, .npy, .pcd, freenect:N, openni2:URI; see docs/runtime/frames.md), prints one\n"
                "line per frame (size, valid pixels, depth range, timestamp) and optionally writes them out.\n"
                "Bad frames are reported naming the source and frame, skipped and counted (exit status 1 if\n"
                "any). `poseforest frames --list-devices`: the device back ends built in and the devices they\n"
                "see.") {
    app_.add_option("SOURCE", sources_, "depth frames (required unless --list-devices)");
    app_.add_option("--out-dir", out_dir_,
                    "write each frame as a 16-bit PNG in millimetres (DIR/frame-NNNNNN.png, numbered from 0\n"
                    "in the order written, over all sources)")
        ->type_name("DIR");
    app_.add_option("--npy", npy_, "write all frames as one uint16 .npy [N, H, W] (mm)")->type_name("FILE");
    app_.add_option("--fakenect", fakenect_,
                    "write the frames as a fakenect recording (640x480 only): replay it through libfreenect\n"
                    "with LD_LIBRARY_PATH=/usr/lib/<arch>/fakenect FAKENECT_PATH=DIR")
        ->type_name("DIR");
    app_.add_option("--record-fps", record_fps_, "frame rate of the fakenect recording")
        ->type_name("N")
        ->check(NumberIn(0.001, 10000.0));
    app_.add_option("--max-frames", max_frames_, "stop after N good frames (a camera streams until stopped)")
        ->type_name("N")
        ->check(IntIn(1, 1LL << 40));
    app_.add_flag("--list-devices", list_devices_, "the device back ends built in and the devices they see");
    app_.add_flag("--quiet", quiet_, "print only errors and the summary");
    AddFrameSourceOptions(app_, &frames_);
  }
  int Run() override;

 private:
  std::vector<std::string> sources_;
  std::optional<std::string> out_dir_, npy_, fakenect_;
  double record_fps_ = 30.0;
  std::optional<int64_t> max_frames_;
  bool list_devices_ = false, quiet_ = false;
  FrameSourceFlags frames_;
};

int FramesCommand::Run() {
  if (list_devices_) {
    const auto back_ends = runtime::FrameBackEnds();
    if (back_ends.empty())
      std::printf("no device back ends in this build (libfreenect, OpenNI2: found at configure time)\n");
    for (const auto& b : back_ends)
      std::printf("%s: %s: %s\n", b.scheme.c_str(), b.describe.c_str(), b.list_devices().c_str());
    return 0;
  }
  if (sources_.empty()) return UsageError("no source given");
  auto options = FrameSourceFromFlags(frames_);
  if (!options.ok()) return UsageError(options.status().message());
  const int64_t max_frames = max_frames_.value_or(-1);
  const bool quiet = quiet_;
  const auto& out_dir = out_dir_;
  if (out_dir) {
    std::error_code ec;
    fs::create_directories(*out_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest frames: %s: cannot create folder: %s\n", out_dir->c_str(),
                   ec.message().c_str());
      return 1;
    }
  }
  auto source = runtime::OpenFrameSources(sources_, *options);
  if (!source.ok()) {
    std::fprintf(stderr, "poseforest frames: %s\n", source.status().ToString().c_str());
    return 1;
  }
  std::vector<core::DepthImage> kept;  // for --npy / --fakenect
  const bool keep = npy_ || fakenect_;
  int good = 0, bad = 0, write_errors = 0, bad_in_a_row = 0;
  runtime::Frame f;
  while (max_frames < 0 || good < max_frames) {
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
      // Numbered by this run, not by the frame's index in its source: two sources both start at 0.
      std::snprintf(stem, sizeof stem, "frame-%06d.png", good - 1);
      const auto st = runtime::WriteDepthPng((fs::path(*out_dir) / stem).string(), f.depth);
      if (!st.ok()) std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
    }
    if (keep) kept.push_back(f.depth);
  }
  if (const auto& npy = npy_; npy && !kept.empty()) {
    const auto st = runtime::WriteDepthNpy(*npy, kept);
    if (!st.ok()) std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
  }
  if (const auto& dir = fakenect_; dir && !kept.empty()) {
    const auto st = apps::devices::WriteFakenectRecording(*dir, kept, record_fps_);
    if (!st.ok())
      std::fprintf(stderr, "poseforest frames: %s\n", st.ToString().c_str()), ++write_errors;
    else if (!quiet)
      std::printf("wrote a fakenect recording of %zu frames to %s\n", kept.size(), dir->c_str());
  }
  std::printf("%s: %d frame(s), %d bad frame(s) skipped\n", (*source)->Describe().c_str(), good, bad);
  return bad == 0 && write_errors == 0 ? 0 : 1;
}

}  // namespace

std::unique_ptr<Command> MakeFramesCommand() { return std::make_unique<FramesCommand>(); }

}  // namespace poseforest::apps::commands
