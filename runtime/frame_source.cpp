#include "runtime/frame_source.h"

#include <fcntl.h>
#include <glob.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <filesystem>
#include <mutex>
#include <string_view>
#include <thread>

#include "runtime/frame_formats.h"

namespace poseforest::runtime {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using detail::ApplyDepthScale;
using detail::DecodeNpyFrames;
using detail::RawHeight;
using detail::RawWidth;
using detail::ReadAll;
using detail::StartsWith;

class FileListSource : public FrameSource {
 public:
  FileListSource(std::vector<std::string> files, std::string what, FrameSourceOptions options)
      : files_(std::move(files)),
        what_(std::move(what)),
        options_(std::move(options)),
        opened_(Clock::now()) {}

  Result<bool> Next(Frame* frame) override {
    if (pending_.empty()) {
      if (next_file_ >= files_.size()) return false;
      const std::string path = files_[next_file_++];
      pending_path_ = path;
      pending_first_index_ = 0;
      auto st = Load(path);
      if (!st.ok()) {
        ++index_;
        return st;
      }
    }
    Frame& f = *frame;
    f.depth = std::move(pending_.front());
    pending_.pop_front();
    f.camera = options_.camera;
    f.index = index_++;
    const bool multi = pending_count_ > 1;
    f.source = multi ? pending_path_ + "[" + std::to_string(pending_first_index_++) + "]" : pending_path_;
    f.timestamp_s = options_.fps > 0 ? double(f.index) / options_.fps
                                     : std::chrono::duration<double>(Clock::now() - opened_).count();
    if (!options_.camera_given && pcd_) {
      if (pcd_intrinsics_) {
        // An organized cloud's points say the projection they were made with (ParsePcdFrame).
        f.camera.name = "pcd-projection";
        f.camera.intrinsics = *pcd_intrinsics_;
      } else {
        // Only its size: the default model's focal length, centred on it.
        f.camera.intrinsics.width = f.depth.width;
        f.camera.intrinsics.height = f.depth.height;
        f.camera.intrinsics.cx = (f.depth.width - 1) / 2.0;
        f.camera.intrinsics.cy = (f.depth.height - 1) / 2.0;
      }
    }
    POSEFOREST_RETURN_IF_ERROR(CheckFrameSize(f.camera, f.depth.width, f.depth.height, f.source));
    return true;
  }

  std::string Describe() const override { return what_; }

 private:
  Status Load(const std::string& path) {
    pcd_ = false;
    pcd_intrinsics_.reset();
    auto bytes = ReadAll(path);
    if (!bytes.ok()) return bytes.status();
    if (StartsWith(*bytes, "\x93NUMPY")) {
      auto frames = DecodeNpyFrames(*bytes, path, options_.camera.depth_scale_mm);
      if (!frames.ok()) return frames.status();
      pending_count_ = frames->size();
      for (auto& d : *frames) pending_.push_back(std::move(d));
      return Status::Ok();
    }
    if (fs::path(path).extension() == ".pcd") {
      auto d = ReadPcdFrame(path);
      if (!d.ok()) return d.status();
      pcd_ = true;
      pcd_intrinsics_ = d->intrinsics;
      pending_count_ = 1;
      pending_.push_back(std::move(d->depth));
      return Status::Ok();
    }
    auto d = ReadDepthFile(path, options_);
    if (!d.ok()) return d.status();
    pending_count_ = 1;
    pending_.push_back(std::move(*d));
    return Status::Ok();
  }

  std::vector<std::string> files_;
  std::string what_;
  FrameSourceOptions options_;
  Clock::time_point opened_;
  size_t next_file_ = 0;
  int64_t index_ = 0;
  std::deque<core::DepthImage> pending_;
  std::string pending_path_;
  size_t pending_count_ = 0;
  int64_t pending_first_index_ = 0;
  bool pcd_ = false;
  std::optional<core::CameraIntrinsics> pcd_intrinsics_;
};

// Raw uint16 little-endian frames back to back on a file descriptor (stdin): read(2) only, so
// pipes work. A frame cut short by the end of the stream is reported once, then the stream ends.
class RawStreamSource : public FrameSource {
 public:
  RawStreamSource(int fd, std::string name, FrameSourceOptions options)
      : fd_(fd), name_(std::move(name)), options_(std::move(options)), opened_(Clock::now()) {}

  Result<bool> Next(Frame* frame) override {
    if (ended_) return false;
    const int w = RawWidth(options_), h = RawHeight(options_);
    const size_t need = size_t(w) * size_t(h) * 2;
    buf_.resize(need);
    size_t got = 0;
    while (got < need) {
      const ssize_t n = ::read(fd_, buf_.data() + got, need - got);
      if (n < 0) {
        if (errno == EINTR) continue;
        ended_ = true;
        return Status(ErrorCode::kIo,
                      name_ + " frame " + std::to_string(index_) + ": read failed: " + std::strerror(errno));
      }
      if (n == 0) break;
      got += size_t(n);
    }
    if (got == 0) {
      ended_ = true;
      return false;
    }
    if (got < need) {
      ended_ = true;
      return Status(ErrorCode::kDataLoss, name_ + " frame " + std::to_string(index_) +
                                              ": truncated: the stream ended after " + std::to_string(got) +
                                              " of " + std::to_string(need) + " bytes (raw " +
                                              std::to_string(w) + "x" + std::to_string(h) + " uint16)");
    }
    Frame& f = *frame;
    f.depth = core::DepthImage(w, h);
    for (size_t i = 0; i < f.depth.pixels.size(); ++i)
      f.depth.pixels[i] = uint16_t(buf_[2 * i] | buf_[2 * i + 1] << 8);
    ApplyDepthScale(&f.depth, options_.camera.depth_scale_mm);
    f.camera = options_.camera;
    f.source = name_;
    f.index = index_++;
    f.timestamp_s = options_.fps > 0 ? double(f.index) / options_.fps
                                     : std::chrono::duration<double>(Clock::now() - opened_).count();
    POSEFOREST_RETURN_IF_ERROR(CheckFrameSize(f.camera, w, h, f.Name()));
    return true;
  }
  std::string Describe() const override {
    return name_ + ", raw " + std::to_string(RawWidth(options_)) + "x" + std::to_string(RawHeight(options_)) +
           " uint16";
  }

 private:
  int fd_;
  std::string name_;
  FrameSourceOptions options_;
  Clock::time_point opened_;
  std::vector<uint8_t> buf_;
  int64_t index_ = 0;
  bool ended_ = false;
};

// Delivers at most `fps` frames per second: sleeps until each frame's slot.
class PacedSource : public FrameSource {
 public:
  PacedSource(std::unique_ptr<FrameSource> inner, const FrameSourceOptions& options)
      : inner_(std::move(inner)),
        period_(1.0 / options.fps),
        now_(options.pace_now ? options.pace_now : [] { return Clock::now(); }),
        sleep_until_(options.pace_sleep_until ? options.pace_sleep_until
                                              : [](Clock::time_point t) { std::this_thread::sleep_until(t); }) {}
  Result<bool> Next(Frame* frame) override {
    auto r = inner_->Next(frame);
    if (r.ok() && *r) {
      const auto now = now_();
      if (started_) {
        next_ += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_));
        if (next_ > now)
          sleep_until_(next_);
        else
          next_ = now;  // late: no burst to catch up
      } else {
        started_ = true;
        next_ = now;
      }
    }
    return r;
  }
  std::string Describe() const override { return inner_->Describe() + ", paced"; }

 private:
  std::unique_ptr<FrameSource> inner_;
  double period_;
  std::function<Clock::time_point()> now_;
  std::function<void(Clock::time_point)> sleep_until_;
  bool started_ = false;
  Clock::time_point next_;
};

// Several sources one after the other; indices continue across them.
class ChainSource : public FrameSource {
 public:
  explicit ChainSource(std::vector<std::unique_ptr<FrameSource>> parts) : parts_(std::move(parts)) {}
  Result<bool> Next(Frame* frame) override {
    while (current_ < parts_.size()) {
      auto r = parts_[current_]->Next(frame);
      if (!r.ok()) return r;
      if (*r) return true;
      ++current_;
    }
    return false;
  }
  std::string Describe() const override {
    std::string s;
    for (const auto& p : parts_) s += (s.empty() ? "" : " + ") + p->Describe();
    return s;
  }

 private:
  std::vector<std::unique_ptr<FrameSource>> parts_;
  size_t current_ = 0;
};

struct Registry {
  std::mutex mu;
  std::vector<std::pair<BackEndInfo, FrameSourceFactory>> back_ends;
};
Registry& GetRegistry() {
  static Registry r;
  return r;
}

bool HasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

}  // namespace

std::string Frame::Name() const {
  const bool file_like = source.find(':') == std::string::npos && source != "stdin";
  return file_like ? source : source + " frame " + std::to_string(index);
}

bool RegisterFrameBackEnd(const BackEndInfo& info, FrameSourceFactory factory) {
  Registry& r = GetRegistry();
  std::lock_guard lock(r.mu);
  for (const auto& [i, f] : r.back_ends)
    if (i.scheme == info.scheme) return false;
  r.back_ends.emplace_back(info, std::move(factory));
  return true;
}

std::vector<BackEndInfo> FrameBackEnds() {
  Registry& r = GetRegistry();
  std::lock_guard lock(r.mu);
  std::vector<BackEndInfo> out;
  for (const auto& [i, f] : r.back_ends) out.push_back(i);
  return out;
}

bool IsNotAFrameFile(const std::string& name) {
  auto ends = [&](std::string_view suffix) { return name.ends_with(suffix); };
  // poseforest's own outputs beside frames: infer's (<name>.parts.png, ...) and render's.
  for (std::string_view s : {".parts.png", ".labels.png", ".mask.png", ".pose.png", ".probs.npy"})
    if (ends(s)) return true;
  if (name == "camera.txt" || name == "montage.png") return true;
  for (std::string_view prefix : {"labels_", "joints_"})
    if (name.starts_with(prefix)) {
      const size_t dot = name.find('.');
      const std::string digits = name.substr(prefix.size(), dot - prefix.size());
      if (!digits.empty() &&
          std::all_of(digits.begin(), digits.end(), [](unsigned char c) { return std::isdigit(c) != 0; }))
        return true;
    }
  // Text, documents, archives and forests: a depth frame (PNG, .npy, .pcd, raw of any name) never
  // has these extensions.
  std::string ext = fs::path(name).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  for (std::string_view e :
       {".txt",       ".md",  ".json", ".jsonl", ".csv", ".yaml", ".yml", ".xml", ".html", ".pdf",
        ".textproto", ".pff", ".log",  ".gz",    ".bz2", ".xz",   ".zip", ".tar", ".sh",   ".py"})
    if (ext == e) return true;
  // A licence or readme without an extension (COPYING, LICENSE, README, AUTHORS): capitals only.
  if (ext.empty() && name.size() >= 4 &&
      std::all_of(name.begin(), name.end(), [](unsigned char c) { return std::isupper(c) != 0 || c == '_'; }))
    return true;
  return false;
}

Result<std::vector<std::string>> ExpandFrameFiles(const std::string& spec,
                                                  std::vector<std::string>* not_frames) {
  std::vector<std::string> files;
  std::error_code ec;
  if (not_frames) not_frames->clear();
  if (fs::is_directory(spec, ec)) {
    std::vector<std::string> skipped;
    for (const auto& e : fs::directory_iterator(spec, ec)) {
      const std::string name = e.path().filename().string();
      if (name.empty() || name[0] == '.') continue;
      if (!e.is_regular_file(ec)) continue;
      if (IsNotAFrameFile(name)) {
        skipped.push_back(name);
        continue;
      }
      files.push_back(e.path().string());
    }
    if (ec) return Status(ErrorCode::kIo, spec + ": cannot list the folder: " + ec.message());
    std::sort(skipped.begin(), skipped.end());
    if (files.empty())
      return Status(ErrorCode::kNotFound,
                    spec + (skipped.empty() ? ": the folder holds no files"
                                            : ": the folder holds no frame files (only " +
                                                  std::to_string(skipped.size()) + " others, such as " +
                                                  skipped.front() + ")"));
    if (not_frames) *not_frames = std::move(skipped);
  } else if (HasGlobChars(spec) && !fs::exists(spec, ec)) {
    glob_t g{};
    const int rc = ::glob(spec.c_str(), GLOB_NOSORT, nullptr, &g);
    if (rc == 0)
      for (size_t i = 0; i < g.gl_pathc; ++i)
        if (fs::is_regular_file(g.gl_pathv[i], ec)) files.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    if (files.empty()) return Status(ErrorCode::kNotFound, spec + ": no file matches the pattern");
  } else {
    if (!fs::exists(spec, ec)) return Status(ErrorCode::kNotFound, spec + ": no such file");
    files.push_back(spec);
  }
  std::sort(files.begin(), files.end());
  return files;
}

Result<std::unique_ptr<FrameSource>> OpenFrameSource(const std::string& spec,
                                                     const FrameSourceOptions& options) {
  if (options.fps < 0 || !std::isfinite(options.fps))
    return Status(ErrorCode::kInvalidArgument, "--fps must be a positive number");
  std::unique_ptr<FrameSource> src;
  if (spec == "-") {
    src = std::make_unique<RawStreamSource>(STDIN_FILENO, "stdin", options);
  } else if (const size_t colon = spec.find(':');
             colon != std::string::npos && colon > 1 && spec.find('/') > colon && !fs::exists(spec)) {
    // scheme:rest (a one-letter "scheme" would be a Windows drive; a path with ':' that exists is a file).
    const std::string scheme = spec.substr(0, colon), rest = spec.substr(colon + 1);
    FrameSourceFactory factory;
    std::string known;
    {
      Registry& r = GetRegistry();
      std::lock_guard lock(r.mu);
      for (const auto& [info, f] : r.back_ends) {
        known += (known.empty() ? "" : ", ") + info.scheme;
        if (info.scheme == scheme) factory = f;
      }
    }
    if (!factory)
      return Status(ErrorCode::kUnimplemented,
                    spec + ": no '" + scheme + "' back end in this build (built in: " +
                        (known.empty() ? std::string("none") : known) +
                        "; `poseforest --version` lists them; device back ends are found at configure time)");
    auto r = factory(rest, options);
    if (!r.ok()) return r.status();
    src = std::move(*r);
  } else {
    std::vector<std::string> not_frames;
    auto files = ExpandFrameFiles(spec, &not_frames);
    if (!files.ok()) return files.status();
    std::string what = files->size() == 1 && not_frames.empty()
                           ? spec
                           : spec + " (" + std::to_string(files->size()) + " files";
    if (!not_frames.empty()) {
      what += "; " + std::to_string(not_frames.size()) + " not frames, left out: " + not_frames[0];
      for (size_t i = 1; i < not_frames.size() && i < 3; ++i) what += ", " + not_frames[i];
      if (not_frames.size() > 3) what += ", ...";
    }
    if (what != spec) what += ")";
    src = std::make_unique<FileListSource>(std::move(*files), what, options);
  }
  if (options.fps > 0) src = std::make_unique<PacedSource>(std::move(src), options);
  return src;
}

Result<std::unique_ptr<FrameSource>> OpenFrameSources(const std::vector<std::string>& specs,
                                                      const FrameSourceOptions& options) {
  if (specs.empty()) return Status(ErrorCode::kInvalidArgument, "no frame source given");
  if (specs.size() == 1) return OpenFrameSource(specs[0], options);
  std::vector<std::unique_ptr<FrameSource>> parts;
  for (const auto& s : specs) {
    auto r = OpenFrameSource(s, options);
    if (!r.ok()) return r.status();
    parts.push_back(std::move(*r));
  }
  return std::unique_ptr<FrameSource>(std::make_unique<ChainSource>(std::move(parts)));
}

}  // namespace poseforest::runtime
