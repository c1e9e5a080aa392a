#include "runtime/core/forest_format.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>

#include "runtime/core/crc32.h"
#include "runtime/core/forest_layout.h"

namespace poseforest::core {
namespace {

using namespace detail;  // the layout constants

// Little-endian writer.
class Writer {
 public:
  void U8(uint8_t v) { out_.push_back(v); }
  void U16(uint16_t v) { for (int i = 0; i < 2; ++i) out_.push_back(uint8_t(v >> (8 * i))); }
  void U32(uint32_t v) { for (int i = 0; i < 4; ++i) out_.push_back(uint8_t(v >> (8 * i))); }
  void U64(uint64_t v) { for (int i = 0; i < 8; ++i) out_.push_back(uint8_t(v >> (8 * i))); }
  void I16(int16_t v) { U16(uint16_t(v)); }
  void F32(float v) {
    uint32_t u;
    std::memcpy(&u, &v, 4);
    U32(u);
  }
  void Bytes(const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    out_.insert(out_.end(), b, b + n);
  }
  void PadTo(size_t align) { while (out_.size() % align) out_.push_back(0); }
  void PatchU32(size_t at, uint32_t v) { for (int i = 0; i < 4; ++i) out_[at + size_t(i)] = uint8_t(v >> (8 * i)); }
  void PatchU64(size_t at, uint64_t v) { for (int i = 0; i < 8; ++i) out_[at + size_t(i)] = uint8_t(v >> (8 * i)); }
  size_t size() const { return out_.size(); }
  std::vector<uint8_t>& bytes() { return out_; }

 private:
  std::vector<uint8_t> out_;
};

size_t BeginSection(Writer& w, uint32_t tag, uint32_t flags) {
  w.U32(tag);
  w.U32(flags);
  const size_t size_at = w.size();
  w.U64(0);
  return size_at;
}

void EndSection(Writer& w, size_t size_at) {
  w.PatchU64(size_at, uint64_t(w.size() - (size_at + 8)));
  w.PadTo(8);
}

/// The header (file size 0: patched at the end), for `section_count` sections.
void WriteHeader(Writer& w, uint32_t section_count) {
  w.Bytes(kMagic, 8);
  w.U16(kFormatMajor);
  w.U16(kFormatMinor);
  w.U32(kEndianMarker);
  w.U64(0);  // file size, patched below
  w.U32(kHeaderSize);
  w.U32(section_count);
  while (w.size() < kHeaderSize) w.U8(0);
}

void WriteMeta(Writer& w, const Forest& forest) {
  const int stride = forest.leaf_stride();
  const size_t at = BeginSection(w, kTagMeta, kFlagRequired);
  w.U32(uint32_t(forest.trees.size()));
  w.U32(forest.max_depth());
  w.U32(uint32_t(forest.num_parts));
  w.U32(uint32_t(stride));
  w.U32(kLeafEncodingU8Sum255);
  w.U32(forest.constants.background_mm);
  w.F32(forest.constants.offset_unit);
  w.U32(0);
  for (const std::string& name : forest.part_names) {
    w.U8(uint8_t(name.size()));
    w.Bytes(name.data(), name.size());
  }
  EndSection(w, at);
}

void WriteTree(Writer& w, const Tree& tree, size_t t) {
  const size_t at = BeginSection(w, kTagTree, kFlagRequired);
  w.U32(uint32_t(t));
  w.U32(uint32_t(tree.nodes.size()));
  w.U32(tree.num_leaves);
  w.U32(tree.depth);
  for (const Node& n : tree.nodes) {
    w.I16(n.offsets.ux);
    w.I16(n.offsets.uy);
    w.I16(n.offsets.vx);
    w.I16(n.offsets.vy);
    w.F32(n.threshold);
    w.U32(n.child);
  }
  w.Bytes(tree.leaves.data(), tree.leaves.size());
  EndSection(w, at);
}

/// JPAR (mean shift) or, `fast`, JPFC (the fast clustering).
void WriteJointParams(Writer& w, const ProposalParams& params, bool fast) {
  const size_t at = BeginSection(w, fast ? kTagFastJointParams : kTagJointParams, 0);
  w.U32(uint32_t(kNumJoints));
  for (const JointParams& p : params) {
    w.F32(p.bandwidth_m);
    w.F32(p.prob_threshold);
    w.F32(p.z_offset_m);
  }
  EndSection(w, at);
}

void WriteCalibration(Writer& w, const ConfidenceCalibration& cal) {
  const size_t at = BeginSection(w, kTagCalibration, 0);
  w.U32(uint32_t(cal.method));
  w.U32(uint32_t(kNumJoints));
  w.U32(uint32_t(cal.support_edges_m2.size()));
  w.U32(cal.samples);
  for (float e : cal.support_edges_m2) w.F32(e);
  for (const auto& row : cal.precision)
    for (float v : row) w.F32(v);
  EndSection(w, at);
}

void WriteOffsetVotes(Writer& w, const OffsetVotes& votes) {
  const size_t at = BeginSection(w, kTagOffsetVotes, 0);
  w.U32(uint32_t(votes.trees.size()));
  w.U32(uint32_t(kNumJoints));
  w.F32(votes.max_offset_m);
  for (float b : votes.bandwidth_m) w.F32(b);
  w.U32(uint32_t(votes.share_edges.size()));
  for (float e : votes.share_edges) w.F32(e);
  for (float p : votes.precision) w.F32(p);
  for (const TreeVotes& tree : votes.trees) {
    w.U32(tree.first.empty() ? 0 : uint32_t(tree.first.size() - 1));  // valid: num_leaves
    w.U32(uint32_t(tree.votes.size()));
    for (uint32_t f : tree.first) w.U32(f);
    for (const JointVote& v : tree.votes) {
      w.I16(v.dx_mm);
      w.I16(v.dy_mm);
      w.I16(v.dz_mm);
      w.U8(v.joint);
      w.U8(v.weight);
    }
  }
  EndSection(w, at);
}

void WriteWeights(Writer& w, const TrackingWeights& weights) {
  for (float v : weights.intercept) w.F32(v);
  for (float v : weights.slope) w.F32(v);
  for (float v : weights.shared) w.F32(v);
}

void WriteTracking(Writer& w, const TrackingModel& model) {
  const size_t at = BeginSection(w, kTagTracking, 0);
  w.U32(uint32_t(kNumJoints));
  w.U32(uint32_t(kNumTrackingFeatures));
  w.U32(model.samples);
  WriteWeights(w, model);
  EndSection(w, at);
  // JTFT (1.7): only for a model of the kinematic fit's choices; without it, the greedy fit's.
  if (model.fit != TrackingFit::kGreedy) {
    const size_t fit_at = BeginSection(w, kTagTrackingFit, 0);
    w.U32(uint32_t(model.fit));
    w.U32(0);
    EndSection(w, fit_at);
  }
  // JSEE (1.8): the seen decision, when learn-votes fitted one.
  if (const auto& seen = model.seen) {
    const size_t seen_at = BeginSection(w, kTagTrackingSeen, 0);
    w.U32(uint32_t(kNumJoints));
    w.U32(uint32_t(kNumTrackingFeatures));
    WriteWeights(w, *seen);
    EndSection(w, seen_at);
  }
}
}  // namespace

std::vector<uint8_t> SerializeForest(const Forest& forest) {
  Writer w;
  const uint32_t section_count =
      1 + uint32_t(forest.trees.size()) + (forest.proposal_params ? 1 : 0) +
      (forest.fast_proposal_params ? 1 : 0) + 1 + (forest.confidence_calibration ? 1 : 0) +
      (forest.offset_votes ? 1 : 0) + (forest.tracking_model ? 1 : 0) +
      (forest.tracking_model && forest.tracking_model->fit != TrackingFit::kGreedy ? 1 : 0) +
      (forest.tracking_model && forest.tracking_model->seen ? 1 : 0) +
      (forest.constants.edge != ProbeEdge::kBackground ? 1 : 0);
  WriteHeader(w, section_count);
  WriteMeta(w, forest);
  for (size_t t = 0; t < forest.trees.size(); ++t) WriteTree(w, forest.trees[t], t);
  // PEDG (1.9, required): the trees were trained with probes past the edge reading the edge; a
  // reader that does not know it must refuse the file rather than evaluate the trees the paper's
  // way. Not written for the paper's rule, so such files stay readable by 1.0-1.8 readers.
  if (forest.constants.edge != ProbeEdge::kBackground) {
    const size_t edge_at = BeginSection(w, kTagProbeEdge, kFlagRequired);
    w.U32(uint32_t(forest.constants.edge));
    w.U32(0);
    EndSection(w, edge_at);
  }

  // Optional sections: a 1.0 reader skips both and proposes joints with the paper's means; a
  // 1.1 reader reads JPAR (for both methods, its rule) and skips JPFC.
  for (const bool fast : {false, true}) {
    const auto& params = fast ? forest.fast_proposal_params : forest.proposal_params;
    if (!params) continue;
    WriteJointParams(w, *params, fast);
  }

  // FOCL (1.3): always written, so a file says which camera it was trained for.
  const size_t at = BeginSection(w, kTagFocal, 0);
  w.F32(forest.training_fx);
  w.F32(forest.training_fy);
  EndSection(w, at);

  // JCAL (1.4): the confidence calibration tune-joints measured; older readers skip it.
  if (const auto& cal = forest.confidence_calibration) WriteCalibration(w, *cal);
  // JVOT (1.5): the offset votes learn-votes built; older readers skip it.
  if (const auto& votes = forest.offset_votes) WriteOffsetVotes(w, *votes);
  // JTRK (1.6), JTFT (1.7) and JSEE (1.8): the tracking decision learn-votes fitted; older
  // readers skip them.
  if (const auto& model = forest.tracking_model) WriteTracking(w, *model);

  const uint64_t file_size = w.size() + kTrailerSize;
  w.PatchU64(16, file_size);
  const uint32_t crc = Crc32(w.bytes().data(), w.size());
  w.U32(crc);
  w.U32(kTrailerMagic);
  return std::move(w.bytes());
}

Status CheckReadableFile(const std::string& path) {
  // A folder opens as a stream on Linux, and its size reads as huge: refuse it first.
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
    return Status(ErrorCode::kInvalidArgument, path + ": is a folder, not a file");
  if (::access(path.c_str(), R_OK) != 0) {
    const int err = errno;
    return Status(err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                  path + (err == ENOENT ? ": no such file" : ": cannot open: " + std::string(std::strerror(err))));
  }
  return Status::Ok();
}

Result<std::vector<uint8_t>> ReadFileBytes(const std::string& path) {
  if (Status readable = CheckReadableFile(path); !readable.ok()) return readable;
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return Status(ErrorCode::kIo, path + ": cannot open: " + std::string(std::strerror(errno)));
  const std::streamoff size = in.tellg();
  if (size < 0) return Status(ErrorCode::kIo, path + ": cannot determine the file size");
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.seekg(0);
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size))
    return Status(ErrorCode::kIo, path + ": read failed");
  return bytes;
}

Result<std::string> ReadFileText(const std::string& path) {
  auto bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return std::string(bytes->begin(), bytes->end());
}

Status WriteFileAtomic(const std::string& path, std::span<const uint8_t> bytes) {
  // Unique per process and call, so concurrent writers of one path never share a temporary.
  static std::atomic<uint64_t> counter{0};
  const std::string tmp = path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Status(ErrorCode::kIo, path + ": cannot create " + tmp + ": " + std::strerror(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string err = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      return Status(ErrorCode::kIo, path + ": write failed: " + err);
    }
    done += size_t(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    return Status(ErrorCode::kIo, path + ": flush failed: " + err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    return Status(ErrorCode::kIo, path + ": cannot rename " + tmp + " into place: " + err);
  }
  return Status::Ok();
}

Result<Forest> LoadForest(const std::string& path) {
  auto bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParseForest(*bytes, path);
}

Status SaveForest(const Forest& forest, const std::string& path) {
  POSEFOREST_RETURN_IF_ERROR(ValidateForest(forest, path + " (in memory)"));
  const std::vector<uint8_t> bytes = SerializeForest(forest);
  return WriteFileAtomic(path, bytes);
}

}  // namespace poseforest::core
