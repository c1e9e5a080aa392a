#include "renderer/assets/pose_library.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <set>

#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"
#include "runtime/core/rng.h"

namespace poseforest::renderer::assets {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;
using Signature = std::array<float, 3 * kNumSkelJoints>;

constexpr char kMagic[8] = {'P', 'F', 'P', 'O', 'S', 'E', 'S', '\0'};
constexpr uint32_t kEndianMarker = 0x01020304u;

class Writer {
 public:
  void U32(uint32_t v) { Raw(&v, 4); }
  void F32(float v) { Raw(&v, 4); }
  void F64(double v) { Raw(&v, 8); }
  void Raw(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    out.insert(out.end(), b, b + n);
  }
  std::vector<uint8_t> out;
};

class Reader {
 public:
  Reader(const std::vector<uint8_t>& b, size_t end) : b_(b), end_(end) {}
  bool Raw(void* p, size_t n) {
    if (pos_ + n > end_) return false;
    std::memcpy(p, b_.data() + pos_, n);
    pos_ += n;
    return true;
  }
  bool U32(uint32_t* v) { return Raw(v, 4); }
  bool F32(float* v) { return Raw(v, 4); }
  bool F64(double* v) { return Raw(v, 8); }
  size_t pos() const { return pos_; }
  size_t left() const { return end_ - pos_; }

 private:
  const std::vector<uint8_t>& b_;
  size_t end_;
  size_t pos_ = 0;
};

uint64_t HashString(const std::string& s, uint64_t seed) {
  uint64_t h = 1469598103934665603ull ^ core::Mix64(seed);  // FNV-1a, then mixed
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return core::Mix64(h);
}

}  // namespace

Signature PoseSignature(const Pose& pose, const SkelPositions& rest) {
  const SkelPositions posed = PoseJoints(rest, pose);
  Signature s;
  const Eigen::Vector3d pelvis = posed[size_t(SkelJoint::kPelvis)];
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const Eigen::Vector3d d = posed[size_t(j)] - pelvis;
    for (int k = 0; k < 3; ++k) s[size_t(3 * j + k)] = float(d[k]);
  }
  return s;
}

double PoseDistance(const Signature& a, const Signature& b) {
  double m = 0;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const double dx = a[size_t(3 * j)] - b[size_t(3 * j)];
    const double dy = a[size_t(3 * j + 1)] - b[size_t(3 * j + 1)];
    const double dz = a[size_t(3 * j + 2)] - b[size_t(3 * j + 2)];
    m = std::max(m, dx * dx + dy * dy + dz * dz);
  }
  return std::sqrt(m);
}

std::vector<size_t> SubsamplePoses(const std::vector<Signature>& sig, double min_distance_m) {
  std::vector<size_t> kept;
  if (min_distance_m <= 0) {
    kept.resize(sig.size());
    for (size_t i = 0; i < sig.size(); ++i) kept[i] = i;
    return kept;
  }
  const float t2 = float(min_distance_m * min_distance_m);
  // Kept signatures packed contiguously; checked newest first, because consecutive mocap frames
  // are close and the pose that covers a candidate is usually one kept moments ago.
  std::vector<float> packed;
  for (size_t i = 0; i < sig.size(); ++i) {
    const float* c = sig[i].data();
    bool covered = false;
    for (size_t k = kept.size(); k-- > 0 && !covered;) {
      const float* q = packed.data() + k * 3 * kNumSkelJoints;
      bool near = true;
      for (int j = 0; j < kNumSkelJoints; ++j) {  // early exit: one far joint makes the pair far
        const float dx = c[3 * j] - q[3 * j], dy = c[3 * j + 1] - q[3 * j + 1],
                    dz = c[3 * j + 2] - q[3 * j + 2];
        if (dx * dx + dy * dy + dz * dz >= t2) {
          near = false;
          break;
        }
      }
      covered = near;
    }
    if (!covered) {
      kept.push_back(i);
      packed.insert(packed.end(), c, c + 3 * kNumSkelJoints);
    }
  }
  return kept;
}

std::vector<size_t> SubsamplePoses(const std::vector<Pose>& poses, double min_distance_m) {
  std::vector<Signature> sig;
  sig.reserve(poses.size());
  for (const auto& p : poses) sig.push_back(PoseSignature(p));
  return SubsamplePoses(sig, min_distance_m);
}

Result<std::vector<std::filesystem::path>> CollectBvhFiles(const std::vector<std::filesystem::path>& inputs) {
  std::vector<std::filesystem::path> files;
  for (const auto& in : inputs) {
    std::error_code ec;
    if (std::filesystem::is_directory(in, ec)) {
      std::vector<std::filesystem::path> found;
      // Linked folders are followed (a data set assembled from links is common); a folder
      // that is its own ancestor (a link back up the tree) is not entered again, so nothing
      // loops. Folders on the current path, real (canonical) paths: ancestors[d] holds depth d.
      std::vector<std::filesystem::path> ancestors{std::filesystem::canonical(in, ec)};
      if (ec) return Status(ErrorCode::kIo, in.string() + ": cannot list folder: " + ec.message());
      for (auto it = std::filesystem::recursive_directory_iterator(
               in, std::filesystem::directory_options::follow_directory_symlink, ec);
           !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
        std::error_code entry_ec;
        if (it->is_directory(entry_ec)) {
          ancestors.resize(size_t(it.depth()) + 1);
          std::filesystem::path real = std::filesystem::canonical(it->path(), entry_ec);
          if (entry_ec || std::find(ancestors.begin(), ancestors.end(), real) != ancestors.end())
            it.disable_recursion_pending();
          else
            ancestors.push_back(std::move(real));
          continue;
        }
        if (!it->is_regular_file(entry_ec)) continue;
        std::string ext = it->path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(),
                       [](unsigned char c) { return char(std::tolower(c)); });
        if (ext == ".bvh") found.push_back(it->path());
      }
      if (ec) return Status(ErrorCode::kIo, in.string() + ": cannot list folder: " + ec.message());
      if (found.empty())
        return Status(ErrorCode::kNotFound, in.string() + ": no .bvh clips in this folder or below");
      // A clip reached by two paths (a folder linked twice) counts once, under its first path in
      // sorted order, whatever order the folders were listed in.
      std::sort(found.begin(), found.end());
      std::set<std::filesystem::path> seen;
      std::erase_if(found, [&](const std::filesystem::path& f) {
        std::error_code real_ec;
        const std::filesystem::path real = std::filesystem::canonical(f, real_ec);
        return !real_ec && !seen.insert(real).second;
      });
      files.insert(files.end(), found.begin(), found.end());
    } else if (std::filesystem::exists(in, ec)) {
      files.push_back(in);
    } else {
      return Status(ErrorCode::kNotFound, in.string() + ": no such file or folder");
    }
  }
  return files;
}

bool IsTestClip(const std::string& clip_name, double test_fraction, uint64_t seed) {
  if (test_fraction <= 0) return false;
  if (test_fraction >= 1) return true;
  const double u = double(HashString(clip_name, seed) >> 11) * 0x1.0p-53;
  return u < test_fraction;
}

ClipSplit SplitClips(const std::vector<std::filesystem::path>& files, double test_fraction, uint64_t seed) {
  ClipSplit split;
  for (const auto& f : files)
    (IsTestClip(f.stem().string(), test_fraction, seed) ? split.test : split.train).push_back(f);
  return split;
}

Result<PoseLibrary> BuildPoseLibrary(const std::vector<std::filesystem::path>& files,
                                     const BuildOptions& options) {
  PoseLibrary lib;
  lib.min_distance_m = std::max(0.0, options.min_distance_m);
  const SkelPositions& rest = ReferenceRestJoints();
  std::vector<Pose> all;
  std::vector<PoseSource> all_src;
  for (size_t c = 0; c < files.size(); ++c) {
    BvhOptions bo;
    bo.max_frames = options.max_frames_per_clip;
    auto clip = LoadBvh(files[c], bo);
    if (!clip.ok()) return clip.status();
    auto poses = RetargetClip(*clip, rest, options.retarget);
    if (!poses.ok()) return poses.status();
    lib.clips.push_back(files[c].stem().string());
    for (size_t f = 0; f < poses->size(); ++f) {
      all.push_back((*poses)[f]);
      all_src.push_back({uint32_t(c), uint32_t(f)});
    }
    if (options.progress) options.progress(c, files.size(), files[c], poses->size(), all.size());
  }
  const auto kept = SubsamplePoses(all, lib.min_distance_m);
  lib.poses.reserve(kept.size());
  lib.sources.reserve(kept.size());
  for (size_t i : kept) {
    lib.poses.push_back(all[i]);
    lib.sources.push_back(all_src[i]);
  }
  return lib;
}

std::vector<uint8_t> SerializePoseLibrary(const PoseLibrary& lib) {
  POSEFOREST_CHECK(lib.poses.size() == lib.sources.size());
  Writer w;
  w.Raw(kMagic, 8);
  w.U32(kPoseLibraryMajor);
  w.U32(kPoseLibraryMinor);
  w.U32(kEndianMarker);
  w.U32(uint32_t(lib.clips.size()));
  w.U32(uint32_t(lib.poses.size()));
  w.F64(lib.min_distance_m);
  for (const auto& name : lib.clips) {
    w.U32(uint32_t(name.size()));
    w.Raw(name.data(), name.size());
  }
  for (size_t i = 0; i < lib.poses.size(); ++i) {
    w.U32(lib.sources[i].clip);
    w.U32(lib.sources[i].frame);
    const Pose& p = lib.poses[i];
    for (int k = 0; k < 3; ++k) w.F32(float(p.root_translation[k]));
    for (const auto& q : p.rotation) {
      w.F32(float(q.w()));
      w.F32(float(q.x()));
      w.F32(float(q.y()));
      w.F32(float(q.z()));
    }
  }
  const uint32_t crc = core::Crc32(w.out.data(), w.out.size());
  w.U32(crc);
  return std::move(w.out);
}

Result<PoseLibrary> ParsePoseLibrary(const std::vector<uint8_t>& bytes, const std::string& source) {
  auto loss = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, source + ": " + what); };
  constexpr size_t kHeader = 8 + 4 * 5 + 8;
  if (bytes.size() < kHeader + 4)
    return loss("too short for a pose library (" + std::to_string(bytes.size()) + " bytes)");
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) return loss("not a pose library (bad magic)");
  Reader r(bytes, bytes.size() - 4);
  char magic[8];
  uint32_t major = 0, minor = 0, endian = 0, clip_count = 0, pose_count = 0;
  double min_distance = 0;
  (void)r.Raw(magic, 8);
  (void)r.U32(&major);
  (void)r.U32(&minor);
  (void)r.U32(&endian);
  if (endian != kEndianMarker)
    return loss("byte order marker mismatch (file written on another endianness?)");
  if (major != kPoseLibraryMajor)
    return Status(ErrorCode::kVersionMismatch, source + ": pose library format " + std::to_string(major) +
                                                   "." + std::to_string(minor) + ", this build reads " +
                                                   std::to_string(kPoseLibraryMajor) + ".x");
  uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  const uint32_t crc = core::Crc32(bytes.data(), bytes.size() - 4);
  if (crc != stored_crc) return loss("checksum mismatch (file corrupt or truncated)");
  (void)r.U32(&clip_count);
  (void)r.U32(&pose_count);
  (void)r.F64(&min_distance);
  if (!std::isfinite(min_distance) || min_distance < 0) return loss("bad min_distance");
  constexpr size_t kPoseBytes = 8 + 4 * (3 + 4 * kNumSkelJoints);
  if (uint64_t(clip_count) * 4 > r.left() || uint64_t(pose_count) * kPoseBytes > r.left())
    return loss("counts (" + std::to_string(clip_count) + " clips, " + std::to_string(pose_count) +
                " poses) exceed the file size");
  PoseLibrary lib;
  lib.min_distance_m = min_distance;
  for (uint32_t c = 0; c < clip_count; ++c) {
    uint32_t len = 0;
    if (!r.U32(&len) || len > r.left()) return loss("clip name " + std::to_string(c) + " runs past the end");
    std::string name(len, '\0');
    (void)r.Raw(name.data(), len);
    lib.clips.push_back(std::move(name));
  }
  if (uint64_t(pose_count) * kPoseBytes != r.left())
    return loss("pose data is " + std::to_string(r.left()) + " bytes, expected " +
                std::to_string(uint64_t(pose_count) * kPoseBytes));
  lib.poses.resize(pose_count);
  lib.sources.resize(pose_count);
  for (uint32_t i = 0; i < pose_count; ++i) {
    PoseSource& s = lib.sources[i];
    (void)r.U32(&s.clip);
    (void)r.U32(&s.frame);
    if (s.clip >= clip_count)
      return loss("pose " + std::to_string(i) + " names clip " + std::to_string(s.clip) + " of " +
                  std::to_string(clip_count));
    float v[3 + 4 * kNumSkelJoints];
    (void)r.Raw(v, sizeof(v));
    Pose& p = lib.poses[i];
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(v[k])) return loss("pose " + std::to_string(i) + ": non-finite root translation");
      p.root_translation[k] = v[k];
    }
    for (int j = 0; j < kNumSkelJoints; ++j) {
      const float* q = v + 3 + 4 * j;
      Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
      const double n = quat.norm();
      if (!std::isfinite(n) || std::abs(n - 1.0) > 1e-3)
        return loss("pose " + std::to_string(i) + " joint " + std::to_string(j) + ": not a unit quaternion");
      p.rotation[size_t(j)] = quat.normalized();
    }
  }
  return lib;
}

core::Status SavePoseLibrary(const PoseLibrary& library, const std::filesystem::path& path) {
  const auto bytes = SerializePoseLibrary(library);
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Status(ErrorCode::kIo, path.string() + ": cannot open for writing");
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    if (!out) return Status(ErrorCode::kIo, path.string() + ": write failed");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return Status(ErrorCode::kIo, path.string() + ": rename failed: " + ec.message());
  return Status::Ok();
}

Result<PoseLibrary> LoadPoseLibrary(const std::filesystem::path& path) {
  auto bytes = core::ReadFileBytes(path.string());
  if (!bytes.ok()) return bytes.status();
  return ParsePoseLibrary(*bytes, path.string());
}

}  // namespace poseforest::renderer::assets
