#include "apps/devices/fakenect_recording.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "runtime/core/forest_format.h"

namespace poseforest::apps::devices {
namespace {
namespace fs = std::filesystem;
constexpr double kA = -0.0030711016, kB = 3.3309495161;
constexpr int kW = 640, kH = 480;
}  // namespace

uint16_t KinectDisparityToMm(uint16_t raw) {
  if (raw >= 1084) return 0;  // 2047 = no reading; beyond 1083 the fit leaves its range
  const double m = 1.0 / (double(raw) * kA + kB);
  const double mm = std::round(m * 1000.0);
  return mm > 0 && mm < 65535 ? uint16_t(mm) : 0;
}

uint16_t MmToKinectDisparity(uint16_t mm) {
  if (mm == 0) return kKinectNoDisparity;
  const double raw = (1000.0 / double(mm) - kB) / kA;
  int r = int(std::lround(raw));
  r = std::clamp(r, 0, 1083);
  // The neighbour whose depth is nearest (the fit is not linear).
  int best = r;
  for (int c = std::max(0, r - 1); c <= std::min(1083, r + 1); ++c)
    if (std::abs(int(KinectDisparityToMm(uint16_t(c))) - int(mm)) <
        std::abs(int(KinectDisparityToMm(uint16_t(best))) - int(mm)))
      best = c;
  return uint16_t(best);
}

core::Status WriteFakenectRecording(const std::string& dir, const std::vector<core::DepthImage>& frames,
                                    double fps, double start_time_s) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return {core::ErrorCode::kIo, dir + ": cannot create folder: " + ec.message()};
  const fs::path index = fs::path(dir) / "INDEX.txt";
  if (fs::exists(index))
    return {core::ErrorCode::kInvalidArgument,
            index.string() + ": already exists (a recording is not overwritten)"};
  if (!(fps > 0)) return {core::ErrorCode::kInvalidArgument, "fakenect recording: fps must be positive"};
  std::string lines;
  for (size_t k = 0; k < frames.size(); ++k) {
    const core::DepthImage& f = frames[k];
    if (f.width != kW || f.height != kH)
      return {core::ErrorCode::kInvalidArgument,
              "fakenect recording frame " + std::to_string(k) + " is " + std::to_string(f.width) + "x" +
                  std::to_string(f.height) + "; fakenect replays 640x480 Kinect v1 frames only"};
    char name[96];
    std::snprintf(name, sizeof name, "d-%f-%u.pgm", start_time_s + double(k) / fps,
                  unsigned(1000000 + uint64_t(double(k) * 60e6 / fps)));
    std::vector<uint8_t> bytes;
    const std::string header = "P5 640 480 65535\n";
    bytes.assign(header.begin(), header.end());
    bytes.reserve(header.size() + f.pixels.size() * 2);
    for (uint16_t mm : f.pixels) {
      const uint16_t raw = MmToKinectDisparity(mm);
      bytes.push_back(uint8_t(raw & 0xFF));  // native (little-endian) order, as record.c fwrites it
      bytes.push_back(uint8_t(raw >> 8));
    }
    POSEFOREST_RETURN_IF_ERROR(core::WriteFileAtomic((fs::path(dir) / name).string(), bytes));
    lines += name;
    lines += '\n';
  }
  return core::WriteFileAtomic(index.string(),
                               std::span(reinterpret_cast<const uint8_t*>(lines.data()), lines.size()));
}

core::Result<std::vector<FakenectEntry>> CheckFakenectRecording(const std::string& dir) {
  const fs::path index = fs::path(dir) / "INDEX.txt";
  std::ifstream in(index);
  if (!in)
    return core::Status(core::ErrorCode::kNotFound, index.string() + ": cannot read the recording's index");
  std::vector<FakenectEntry> out;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] != 'd') continue;  // video ('r') and accelerometer ('a') entries
    FakenectEntry e;
    e.file = line;
    const fs::path p = fs::path(dir) / line;
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) {
      e.problem = "missing (fakenect would exit the process on it)";
    } else {
      std::ifstream f(p, std::ios::binary);
      std::string header;
      std::getline(f, header);
      const uint64_t size = fs::file_size(p, ec);
      const uint64_t want = header.size() + 1 + uint64_t(kW) * kH * 2;
      if (header.rfind("P5", 0) != 0)
        e.problem = "not a PGM depth frame (header '" + header.substr(0, 20) + "')";
      else if (size < want)
        e.problem = "truncated: " + std::to_string(size) + " of " + std::to_string(want) + " bytes";
      else
        e.ok = true;
    }
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace poseforest::apps::devices
