#include "apps/devices/openni2_source.h"

#include <OpenNI.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>

#include "runtime/frame_source.h"

namespace poseforest::apps::devices {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;
// The frame source interface these back ends implement (runtime/frame_source.h).
using runtime::CameraModel;
using runtime::CheckFrameSize;
using runtime::Frame;
using runtime::FrameSource;
using runtime::FrameSourceOptions;
using runtime::RegisterFrameBackEnd;

std::mutex g_init_mu;

// OpenNI2 stays initialized for the life of the process: OpenNI::shutdown() with Debian's
// OpenNI2 2.2.0.33 crashes in the Dummy driver's thread after the driver is unloaded (seen under
// test_openni2), and LeakSanitizer reports 240 bytes leaked inside its PS1080/PSLink drivers
// with or without it.

Status InitOpenNi() {
  std::lock_guard lock(g_init_mu);
  if (openni::OpenNI::initialize() != openni::STATUS_OK)
    return {ErrorCode::kIo, std::string("OpenNI2 could not start: ") + openni::OpenNI::getExtendedError()};
  return Status::Ok();
}

// One OpenNI2 depth stream: a device or a .oni recording. readFrame waits at most timeout_s for
// a frame, so a device that stops is reported as lost instead of hanging; a recording ends
// cleanly after its last frame (no repeat).
class OpenNi2Source : public FrameSource {
 public:
  ~OpenNi2Source() override {
    if (stream_.isValid()) {
      stream_.stop();
      stream_.destroy();
    }
    if (device_.isValid()) device_.close();
  }

  static Result<std::unique_ptr<FrameSource>> Open(const std::string& rest,
                                                   const FrameSourceOptions& options) {
    auto src = std::unique_ptr<OpenNi2Source>(new OpenNi2Source());
    POSEFOREST_RETURN_IF_ERROR(src->Init(rest, options));
    return std::unique_ptr<FrameSource>(std::move(src));
  }

  Result<bool> Next(Frame* frame) override {
    if (ended_) return false;
    if (frames_in_file_ > 0 && index_ >= frames_in_file_) {
      ended_ = true;
      return false;
    }
    openni::VideoStream* streams[] = {&stream_};
    int which = -1;
    const int timeout_ms = int(timeout_s_ * 1000);
    if (openni::OpenNI::waitForAnyStream(streams, 1, &which, timeout_ms) != openni::STATUS_OK) {
      ended_ = true;
      if (frames_in_file_ > 0) return false;  // a recording that has nothing more
      return Status(ErrorCode::kIo, name_ + ": device lost: no frame for " + std::to_string(timeout_s_) +
                                        " s after frame " + std::to_string(index_ - 1) + " (" +
                                        openni::OpenNI::getExtendedError() + ")");
    }
    openni::VideoFrameRef ref;
    if (stream_.readFrame(&ref) != openni::STATUS_OK || !ref.isValid()) {
      ended_ = true;
      return Status(ErrorCode::kIo, name_ + ": device lost at frame " + std::to_string(index_) +
                                        " (readFrame: " + openni::OpenNI::getExtendedError() + ")");
    }
    Frame& f = *frame;
    f.source = name_;
    f.index = index_++;
    f.camera = camera_;
    f.timestamp_s = double(ref.getTimestamp()) * 1e-6;
    const int w = ref.getWidth(), h = ref.getHeight();
    if (ref.getDataSize() < w * h * 2)
      return Status(ErrorCode::kDataLoss, f.Name() + ": frame of " + std::to_string(ref.getDataSize()) +
                                              " bytes for " + std::to_string(w) + "x" + std::to_string(h) +
                                              " (truncated)");
    f.depth = core::DepthImage(w, h);
    const auto* src = static_cast<const uint16_t*>(ref.getData());
    for (int y = 0; y < h; ++y)
      std::memcpy(&f.depth.at(0, y), src + size_t(y) * size_t(ref.getStrideInBytes() / 2), size_t(w) * 2);
    if (scale_ != 1.0)
      for (uint16_t& d : f.depth.pixels) d = uint16_t(std::min(65535.0, std::round(d * scale_)));
    POSEFOREST_RETURN_IF_ERROR(CheckFrameSize(f.camera, w, h, f.Name()));
    return true;
  }

  std::string Describe() const override {
    return name_ + " (OpenNI2" + (frames_in_file_ > 0 ? ", recording)" : ")");
  }

 private:
  Status Init(const std::string& rest, const FrameSourceOptions& options) {
    name_ = "openni2:" + rest;
    POSEFOREST_RETURN_IF_ERROR(InitOpenNi());
    const char* uri = openni::ANY_DEVICE;
    if (!rest.empty()) uri = rest.c_str();
    if (rest.empty()) {
      openni::Array<openni::DeviceInfo> list;
      openni::OpenNI::enumerateDevices(&list);
      if (list.getSize() == 0)
        return {ErrorCode::kNotFound, name_ + ": no OpenNI2 device found (" + ListOpenNi2Devices() + ")"};
    }
    if (device_.open(uri) != openni::STATUS_OK)
      return {ErrorCode::kNotFound, name_ + ": cannot open: " + openni::OpenNI::getExtendedError()};
    if (device_.isFile()) {
      if (auto* pc = device_.getPlaybackControl()) {
        pc->setRepeatEnabled(false);
        pc->setSpeed(options.fps > 0 ? 1.0f : -1.0f);  // as fast as read unless paced
      }
    }
    if (stream_.create(device_, openni::SENSOR_DEPTH) != openni::STATUS_OK)
      return {ErrorCode::kIo, name_ + ": no depth stream: " + openni::OpenNI::getExtendedError()};
    const openni::VideoMode mode = stream_.getVideoMode();
    if (mode.getPixelFormat() == openni::PIXEL_FORMAT_DEPTH_100_UM)
      scale_ = 0.1;
    else if (mode.getPixelFormat() != openni::PIXEL_FORMAT_DEPTH_1_MM)
      return {ErrorCode::kUnimplemented, name_ + ": depth pixel format " +
                                             std::to_string(int(mode.getPixelFormat())) +
                                             " is not millimetres or 100 um"};
    if (device_.isFile())
      if (auto* pc = device_.getPlaybackControl()) frames_in_file_ = pc->getNumberOfFrames(stream_);
    // The device's own intrinsics (from its field of view) unless a camera was given.
    camera_ = options.camera;
    if (!options.camera_given) {
      const int w = mode.getResolutionX(), h = mode.getResolutionY();
      auto& k = camera_.intrinsics;
      k.width = w, k.height = h, k.cx = (w - 1) / 2.0, k.cy = (h - 1) / 2.0;
      const float hfov = stream_.getHorizontalFieldOfView(), vfov = stream_.getVerticalFieldOfView();
      if (hfov > 0.1f && vfov > 0.1f)
        k.fx = w / 2.0 / std::tan(hfov / 2.0), k.fy = h / 2.0 / std::tan(vfov / 2.0);
      camera_.name = "openni2";
    }
    // A device whose frames contradict the camera model never fixes itself: refuse it up front.
    POSEFOREST_RETURN_IF_ERROR(
        CheckFrameSize(camera_, mode.getResolutionX(), mode.getResolutionY(), name_ + "'s depth stream"));
    if (stream_.start() != openni::STATUS_OK)
      return {ErrorCode::kIo, name_ + ": cannot start the depth stream"};
    return Status::Ok();
  }

  openni::Device device_;
  openni::VideoStream stream_;
  std::string name_;
  CameraModel camera_;
  double scale_ = 1.0, timeout_s_ = 2.0;
  int64_t index_ = 0, frames_in_file_ = 0;
  bool ended_ = false;
};

}  // namespace

std::string ListOpenNi2Devices() {
  if (auto st = InitOpenNi(); !st.ok()) return st.message();
  openni::Array<openni::DeviceInfo> list;
  openni::OpenNI::enumerateDevices(&list);
  if (list.getSize() == 0) return "no OpenNI2 device connected";
  std::string out = std::to_string(list.getSize()) + " device(s):";
  for (int i = 0; i < list.getSize(); ++i)
    out += std::string(" openni2:") + list[i].getUri() + " (" + list[i].getVendor() + " " +
           list[i].getName() + ")";
  return out;
}

void RegisterOpenNi2BackEnd() {
  RegisterFrameBackEnd({"openni2", "OpenNI2 (openni2:[URI], openni2:FILE.oni)", &ListOpenNi2Devices},
                       &OpenNi2Source::Open);
}

}  // namespace poseforest::apps::devices
