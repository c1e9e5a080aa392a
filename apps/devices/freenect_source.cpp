#include "apps/devices/freenect_source.h"

#include <libfreenect.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <thread>

#include "apps/devices/fakenect_recording.h"
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
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr int kW = 640, kH = 480;
constexpr size_t kMaxQueued = 32;

struct Queued {
  core::DepthImage depth;
  double host_s;
};

// One Kinect v1 through libfreenect. A pump thread runs freenect_process_events; the depth
// callback converts each frame to millimetres and queues it; Next() waits for one with a
// timeout, so a device that stops sending is reported as lost instead of hanging.
//
// Under fakenect (FAKENECT_PATH set: libfreenect's replay library), the recording's index is
// checked first, because fakenect exits the process on a missing frame file and reads past the
// end of a short one: bad entries are reported in sequence (named, skipped, counted) and replay
// runs on a filtered index; the recording's end is a clean end of stream.
class FreenectSource : public FrameSource {
 public:
  ~FreenectSource() override { Close(); }

  static Result<std::unique_ptr<FrameSource>> Open(const std::string& rest,
                                                   const FrameSourceOptions& options) {
    auto src = std::unique_ptr<FreenectSource>(new FreenectSource());
    POSEFOREST_RETURN_IF_ERROR(src->Init(rest, options));
    return std::unique_ptr<FrameSource>(std::move(src));
  }

  Result<bool> Next(Frame* frame) override {
    if (ended_) return false;
    if (plan_) {
      if (plan_pos_ >= plan_->size()) {
        ended_ = true;  // the recording ended: a clean end of stream
        return false;
      }
      const FakenectEntry& e = (*plan_)[plan_pos_];
      if (!e.ok) {
        ++plan_pos_;
        const int64_t k = index_++;
        return Status(ErrorCode::kDataLoss, name_ + " frame " + std::to_string(k) + " (fakenect recording " +
                                                recording_ + ", file " + e.file + "): " + e.problem +
                                                "; skipped");
      }
    }
    std::unique_lock lock(mu_);
    const bool got = cv_.wait_for(lock, std::chrono::duration<double>(timeout_s_),
                                  [&] { return !queue_.empty() || pump_error_ != 0; });
    if (!queue_.empty()) {
      Queued q = std::move(queue_.front());
      queue_.pop_front();
      lock.unlock();
      space_.notify_one();
      if (plan_) ++plan_pos_;
      Frame& f = *frame;
      f.depth = std::move(q.depth);
      f.timestamp_s = q.host_s;
      f.camera = camera_;
      f.source = name_;
      f.index = index_++;
      return true;
    }
    ended_ = true;
    if (pump_error_ != 0)
      return Status(ErrorCode::kIo, name_ + ": device lost after frame " + std::to_string(index_ - 1) +
                                        " (libfreenect's event loop returned " + std::to_string(pump_error_) +
                                        ")");
    (void)got;
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.1f", timeout_s_);
    return Status(ErrorCode::kIo, name_ + ": device lost: no frame for " + buf + " s after frame " +
                                      std::to_string(index_ - 1) +
                                      " (timeout=S in the source sets the wait)");
  }

  std::string Describe() const override {
    return name_ + (plan_ ? " (fakenect recording " + recording_ + ")" : std::string(" (libfreenect)")) +
           (mm_mode_ ? ", depth in mm by libfreenect" : ", 11-bit disparity converted to mm");
  }

 private:
  FreenectSource() = default;

  Status Init(const std::string& rest, const FrameSourceOptions& options) {
    // rest: "N" or "N,timeout=S"
    int device = 0;
    std::string spec = rest;
    if (const size_t comma = spec.find(','); comma != std::string::npos) {
      const std::string opt = spec.substr(comma + 1);
      spec = spec.substr(0, comma);
      if (opt.rfind("timeout=", 0) != 0 || !(std::atof(opt.c_str() + 8) > 0))
        return {ErrorCode::kInvalidArgument, "freenect:" + rest + ": options are timeout=SECONDS"};
      timeout_s_ = std::atof(opt.c_str() + 8);
    }
    char* end = nullptr;
    device = spec.empty() ? 0 : int(std::strtol(spec.c_str(), &end, 10));
    if (!spec.empty() && (*end != '\0' || device < 0))
      return {ErrorCode::kInvalidArgument, "freenect:" + rest + ": the device is a number (freenect:0)"};
    name_ = "freenect:" + std::to_string(device);
    camera_ = options.camera;
    if (options.camera_given) {
      POSEFOREST_RETURN_IF_ERROR(CheckFrameSize(camera_, kW, kH, name_ + " (a Kinect v1 sends 640x480)"));
    }

    if (const char* rec = std::getenv("FAKENECT_PATH"); rec && *rec) {
      recording_ = rec;
      auto plan = CheckFakenectRecording(recording_);
      if (!plan.ok()) return {plan.status().code(), name_ + ": " + plan.status().message()};
      plan_ = std::move(*plan);
      size_t good = 0;
      for (const auto& e : *plan_) good += e.ok;
      expected_good_ = good;
      if (good != plan_->size()) {
        // Replay the good entries only, through a filtered index of links.
        char tmpl[] = "/tmp/poseforest-fakenect-XXXXXX";
        if (!::mkdtemp(tmpl)) return {ErrorCode::kIo, name_ + ": cannot create a temporary folder"};
        filtered_dir_ = tmpl;
        std::ofstream index(fs::path(filtered_dir_) / "INDEX.txt");
        for (const auto& e : *plan_) {
          if (!e.ok) continue;
          std::error_code ec;
          fs::create_symlink(fs::absolute(fs::path(recording_) / e.file), fs::path(filtered_dir_) / e.file,
                             ec);
          if (ec) return {ErrorCode::kIo, name_ + ": cannot link " + e.file + ": " + ec.message()};
          index << e.file << '\n';
        }
        ::setenv("FAKENECT_PATH", filtered_dir_.c_str(), 1);  // fakenect reads it in freenect_init
      }
    }

    if (freenect_init(&ctx_, nullptr) < 0)
      return {ErrorCode::kIo, name_ + ": libfreenect could not start (freenect_init)"};
    freenect_set_log_level(ctx_, FREENECT_LOG_FATAL);
    freenect_select_subdevices(ctx_, FREENECT_DEVICE_CAMERA);
    const int n = freenect_num_devices(ctx_);
    if (n <= device)
      return {ErrorCode::kNotFound, name_ + ": no Kinect v1 found (libfreenect sees " +
                                        std::to_string(std::max(n, 0)) + " device(s))"};
    if (freenect_open_device(ctx_, &dev_, device) < 0) {
      dev_ = nullptr;
      return {ErrorCode::kIo, name_ + ": cannot open the device (in use, or no permission on its USB node)"};
    }
    // Millimetres from libfreenect itself where it offers them (a real device); else the
    // 11-bit disparity (all that fakenect replays), converted here.
    freenect_frame_mode mode{};
    const int modes = freenect_get_depth_mode_count();
    for (int i = 0; i < modes; ++i) {
      const freenect_frame_mode m = freenect_get_depth_mode(i);
      if (!m.is_valid || m.resolution != FREENECT_RESOLUTION_MEDIUM) continue;
      if (m.depth_format == FREENECT_DEPTH_MM) mode = m, mm_mode_ = true;
      if (m.depth_format == FREENECT_DEPTH_11BIT && !mm_mode_) mode = m;
    }
    if (!mode.is_valid)
      return {ErrorCode::kUnimplemented, name_ + ": the device offers no 640x480 depth mode in mm or 11-bit"};
    if (freenect_set_depth_mode(dev_, mode) < 0)
      return {ErrorCode::kIo, name_ + ": cannot set the depth mode"};
    freenect_set_user(dev_, this);
    freenect_set_depth_callback(dev_, &FreenectSource::DepthCallback);
    if (freenect_start_depth(dev_) < 0) return {ErrorCode::kIo, name_ + ": cannot start the depth stream"};
    started_ = true;
    opened_ = Clock::now();
    pump_ = std::thread([this] { Pump(); });
    return Status::Ok();
  }

  static void DepthCallback(freenect_device* dev, void* data, uint32_t /*timestamp*/) {
    static_cast<FreenectSource*>(freenect_get_user(dev))->OnDepth(data);
  }

  void OnDepth(const void* data) {
    Queued q{core::DepthImage(kW, kH), std::chrono::duration<double>(Clock::now() - opened_).count()};
    // Copied bytewise first: the buffer need not be 2-byte aligned (fakenect 0.5.3 passes its
    // file buffer just past the odd-length PGM header line; UBSan caught the unaligned loads).
    std::memcpy(q.depth.pixels.data(), data, size_t(kW) * kH * 2);
    if (!mm_mode_)
      for (uint16_t& v : q.depth.pixels) v = KinectDisparityToMm(v);
    std::unique_lock lock(mu_);
    space_.wait(lock, [&] { return queue_.size() < kMaxQueued || stop_; });
    if (stop_) return;
    queue_.push_back(std::move(q));
    ++delivered_;
    cv_.notify_one();
  }

  void Pump() {
    while (true) {
      {
        std::lock_guard lock(mu_);
        if (stop_) return;
        // A recording: stop pumping once every good frame came (fakenect would only warn
        // about the end of its index from here on).
        if (plan_ && delivered_ >= expected_good_) return;
      }
      timeval tv{0, 100000};
      const int r = freenect_process_events_timeout(ctx_, &tv);
      if (r < 0) {
        std::lock_guard lock(mu_);
        pump_error_ = r;
        cv_.notify_all();
        return;
      }
    }
  }

  void Close() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    space_.notify_all();
    if (pump_.joinable()) pump_.join();
    if (dev_) {
      if (started_) freenect_stop_depth(dev_);
      freenect_close_device(dev_);
    }
    if (ctx_) freenect_shutdown(ctx_);
    if (!filtered_dir_.empty()) {
      std::error_code ec;
      fs::remove_all(filtered_dir_, ec);
      ::setenv("FAKENECT_PATH", recording_.c_str(), 1);
    }
  }

  freenect_context* ctx_ = nullptr;
  freenect_device* dev_ = nullptr;
  bool started_ = false, mm_mode_ = false, ended_ = false;
  std::string name_, recording_, filtered_dir_;
  CameraModel camera_;
  double timeout_s_ = 2.0;
  std::optional<std::vector<FakenectEntry>> plan_;
  size_t plan_pos_ = 0, expected_good_ = 0;
  int64_t index_ = 0;
  Clock::time_point opened_;

  std::mutex mu_;
  std::condition_variable cv_, space_;
  std::deque<Queued> queue_;
  size_t delivered_ = 0;
  int pump_error_ = 0;
  bool stop_ = false;
  std::thread pump_;
};

}  // namespace

std::string ListFreenectDevices() {
  freenect_context* ctx = nullptr;
  if (freenect_init(&ctx, nullptr) < 0) return "libfreenect could not start";
  freenect_set_log_level(ctx, FREENECT_LOG_FATAL);
  const int n = freenect_num_devices(ctx);
  freenect_shutdown(ctx);
  if (n <= 0) return "no Kinect v1 connected";
  return std::to_string(n) + " Kinect v1 device(s): freenect:0" +
         (n > 1 ? " .. freenect:" + std::to_string(n - 1) : "");
}

void RegisterFreenectBackEnd() {
  RegisterFrameBackEnd({"freenect", "libfreenect (Kinect v1; freenect:N[,timeout=S])", &ListFreenectDevices},
                       &FreenectSource::Open);
}

}  // namespace poseforest::apps::devices
