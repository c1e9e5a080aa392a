#include "runtime/core/forest_format.h"

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>

#include <fcntl.h>
#include <unistd.h>

#include "runtime/core/crc32.h"

namespace poseforest::core {
namespace {

// Layout constants; runtime/FORMAT.md is the prose version of this block.
constexpr uint8_t kMagic[8] = {0x89, 'P', 'F', 'F', '\r', '\n', 0x1A, '\n'};
constexpr uint32_t kEndianMarker = 0x0A0B0C0Du;
constexpr uint32_t kHeaderSize = 64;
constexpr uint32_t kTrailerMagic = 0x444E4650u;  // "PFND"
constexpr uint32_t kTrailerSize = 8;
constexpr uint32_t kSectionHeaderSize = 16;
constexpr uint32_t kFlagRequired = 1;
constexpr uint32_t kLeafEncodingU8Sum255 = 1;
constexpr uint32_t kMetaFixedSize = 32;
constexpr uint32_t kTreeFixedSize = 16;

constexpr uint32_t Tag(const char (&s)[5]) {
  return uint32_t(uint8_t(s[0])) | uint32_t(uint8_t(s[1])) << 8 | uint32_t(uint8_t(s[2])) << 16 |
         uint32_t(uint8_t(s[3])) << 24;
}
constexpr uint32_t kTagMeta = Tag("META");
constexpr uint32_t kTagTree = Tag("TREE");
constexpr uint32_t kTagJointParams = Tag("JPAR");      // mean shift (1.1: both methods)
constexpr uint32_t kTagFastJointParams = Tag("JPFC");  // the fast clustering (1.2)
constexpr uint32_t kTagFocal = Tag("FOCL");            // training camera's focal lengths (1.3)
constexpr uint32_t kTagCalibration = Tag("JCAL");      // joint confidence calibration (1.4)
constexpr uint32_t kTagOffsetVotes = Tag("JVOT");      // offset votes (1.5)
constexpr uint32_t kTagTracking = Tag("JTRK");         // learned tracking decision (1.6)
// JTRK: u32 joints, u32 cues, u32 samples, joints x f32 intercept, joints x f32 slope, cues x f32.
// JVOT: u32 trees, u32 joints, f32 max offset, joints x f32 bandwidth, u32 calibration bins.
constexpr uint32_t kVotesHeadSize = 16 + 4 * uint32_t(kNumJoints);
constexpr uint32_t kVoteSize = 8;  // i16 dx, dy, dz (mm), u8 joint, u8 weight

std::string TagName(uint32_t tag) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = char((tag >> (8 * i)) & 0xFF);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  return s;
}

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

// Bounds-checked little-endian reader over one span; every read says whether it fitted.
class Reader {
 public:
  explicit Reader(std::span<const uint8_t> b) : b_(b) {}
  bool Has(size_t n) const { return n <= b_.size() - pos_; }
  size_t pos() const { return pos_; }
  size_t remaining() const { return b_.size() - pos_; }
  void Skip(size_t n) { pos_ += n; }
  uint8_t U8() { return b_[pos_++]; }
  uint16_t U16() { uint16_t v = uint16_t(b_[pos_] | b_[pos_ + 1] << 8); pos_ += 2; return v; }
  uint32_t U32() {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= uint32_t(b_[pos_ + size_t(i)]) << (8 * i);
    pos_ += 4;
    return v;
  }
  uint64_t U64() {
    uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= uint64_t(b_[pos_ + size_t(i)]) << (8 * i);
    pos_ += 8;
    return v;
  }
  int16_t I16() { return int16_t(U16()); }
  float F32() {
    const uint32_t u = U32();
    float f;
    std::memcpy(&f, &u, 4);
    return f;
  }
  const uint8_t* Ptr() const { return b_.data() + pos_; }

 private:
  std::span<const uint8_t> b_;
  size_t pos_ = 0;
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

}  // namespace

std::vector<uint8_t> SerializeForest(const Forest& forest) {
  Writer w;
  w.Bytes(kMagic, 8);
  w.U16(kFormatMajor);
  w.U16(kFormatMinor);
  w.U32(kEndianMarker);
  w.U64(0);  // file size, patched below
  w.U32(kHeaderSize);
  const uint32_t section_count = 1 + uint32_t(forest.trees.size()) + (forest.proposal_params ? 1 : 0) +
                                 (forest.fast_proposal_params ? 1 : 0) + 1 +
                                 (forest.confidence_calibration ? 1 : 0) + (forest.offset_votes ? 1 : 0) +
                                 (forest.tracking_model ? 1 : 0);
  w.U32(section_count);
  while (w.size() < kHeaderSize) w.U8(0);

  const int stride = forest.leaf_stride();
  size_t at = BeginSection(w, kTagMeta, kFlagRequired);
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

  for (size_t t = 0; t < forest.trees.size(); ++t) {
    const Tree& tree = forest.trees[t];
    at = BeginSection(w, kTagTree, kFlagRequired);
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

  // Optional sections: a 1.0 reader skips both and proposes joints with the paper's means; a
  // 1.1 reader reads JPAR (for both methods, its rule) and skips JPFC.
  for (const bool fast : {false, true}) {
    const auto& params = fast ? forest.fast_proposal_params : forest.proposal_params;
    if (!params) continue;
    at = BeginSection(w, fast ? kTagFastJointParams : kTagJointParams, 0);
    w.U32(uint32_t(kNumJoints));
    for (const JointParams& p : *params) {
      w.F32(p.bandwidth_m);
      w.F32(p.prob_threshold);
      w.F32(p.z_offset_m);
    }
    EndSection(w, at);
  }

  // FOCL (1.3): always written, so a file says which camera it was trained for.
  at = BeginSection(w, kTagFocal, 0);
  w.F32(forest.training_fx);
  w.F32(forest.training_fy);
  EndSection(w, at);

  // JCAL (1.4): the confidence calibration tune-joints measured; older readers skip it.
  if (const auto& cal = forest.confidence_calibration) {
    at = BeginSection(w, kTagCalibration, 0);
    w.U32(uint32_t(cal->method));
    w.U32(uint32_t(kNumJoints));
    w.U32(uint32_t(cal->support_edges_m2.size()));
    w.U32(cal->samples);
    for (float e : cal->support_edges_m2) w.F32(e);
    for (const auto& row : cal->precision)
      for (float v : row) w.F32(v);
    EndSection(w, at);
  }

  // JVOT (1.5): the offset votes learn-votes built; older readers skip it.
  if (const auto& votes = forest.offset_votes) {
    at = BeginSection(w, kTagOffsetVotes, 0);
    w.U32(uint32_t(votes->trees.size()));
    w.U32(uint32_t(kNumJoints));
    w.F32(votes->max_offset_m);
    for (float b : votes->bandwidth_m) w.F32(b);
    w.U32(uint32_t(votes->share_edges.size()));
    for (float e : votes->share_edges) w.F32(e);
    for (float p : votes->precision) w.F32(p);
    for (const TreeVotes& tree : votes->trees) {
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

  // JTRK (1.6): the tracking decision learn-votes fitted; older readers skip it.
  if (const auto& model = forest.tracking_model) {
    at = BeginSection(w, kTagTracking, 0);
    w.U32(uint32_t(kNumJoints));
    w.U32(uint32_t(kNumTrackingFeatures));
    w.U32(model->samples);
    for (float v : model->intercept) w.F32(v);
    for (float v : model->slope) w.F32(v);
    for (float v : model->shared) w.F32(v);
    EndSection(w, at);
  }

  const uint64_t file_size = w.size() + kTrailerSize;
  w.PatchU64(16, file_size);
  const uint32_t crc = Crc32(w.bytes().data(), w.size());
  w.U32(crc);
  w.U32(kTrailerMagic);
  return std::move(w.bytes());
}

Result<Forest> ParseForest(std::span<const uint8_t> bytes, const std::string& source) {
  auto loss = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, source + ": " + what); };
  if (bytes.size() < kHeaderSize + kTrailerSize)
    return loss("file is " + std::to_string(bytes.size()) + " bytes, too short for a forest (truncated?)");
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) return loss("not a poseforest forest file (bad magic bytes)");

  Reader h(bytes);
  h.Skip(8);
  const uint16_t major = h.U16();
  const uint16_t minor = h.U16();
  if (major != kFormatMajor)
    return Status(ErrorCode::kVersionMismatch,
                  source + ": forest format version " + std::to_string(major) + "." + std::to_string(minor) +
                      " cannot be read by this program, which reads format version " +
                      std::to_string(kFormatMajor) + ".x (up to " + std::to_string(kFormatMajor) + "." +
                      std::to_string(kFormatMinor) + ")");
  if (h.U32() != kEndianMarker) return loss("bad endianness marker (not a little-endian v1 file, or corrupt)");
  const uint64_t file_size = h.U64();
  if (file_size != bytes.size())
    return loss("file is " + std::to_string(bytes.size()) + " bytes but its header says " +
                std::to_string(file_size) + (file_size > bytes.size() ? " (truncated)" : " (trailing data or corrupt header)"));
  const uint32_t header_size = h.U32();
  const uint32_t section_count = h.U32();
  if (header_size < kHeaderSize || header_size % 8 != 0 || header_size > bytes.size() - kTrailerSize)
    return loss("bad header size " + std::to_string(header_size));

  Reader trailer(bytes.subspan(bytes.size() - kTrailerSize));
  const uint32_t stored_crc = trailer.U32();
  if (trailer.U32() != kTrailerMagic) return loss("missing end marker (truncated or corrupt)");
  const uint32_t crc = Crc32(bytes.data(), bytes.size() - kTrailerSize);
  if (crc != stored_crc) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "checksum mismatch (stored %08x, computed %08x): the file is corrupt", stored_crc, crc);
    return loss(buf);
  }

  Forest forest;
  forest.part_names.clear();
  bool have_meta = false, have_focal = false, have_calibration = false, have_votes = false,
       have_tracking = false;
  uint32_t tree_count = 0, stride = 0;
  const auto body = bytes.subspan(header_size, bytes.size() - kTrailerSize - header_size);
  Reader r(body);
  for (uint32_t s = 0; s < section_count; ++s) {
    const std::string where = "section " + std::to_string(s) + ": ";
    if (!r.Has(kSectionHeaderSize)) return loss(where + "header runs past the end of the file");
    const uint32_t tag = r.U32();
    const uint32_t flags = r.U32();
    const uint64_t size = r.U64();
    if (size > r.remaining()) return loss(where + "'" + TagName(tag) + "' of " + std::to_string(size) + " bytes runs past the end");
    Reader p(body.subspan(r.pos(), size_t(size)));
    r.Skip(size_t(size));
    // Sections are padded to 8 bytes.
    const size_t pad = (8 - r.pos() % 8) % 8;
    if (!r.Has(pad)) return loss(where + "missing padding");
    r.Skip(pad);

    if (tag == kTagMeta) {
      if (have_meta) return loss(where + "second META section");
      if (s != 0) return loss(where + "META must be the first section");
      if (!p.Has(kMetaFixedSize)) return loss(where + "META section too short");
      tree_count = p.U32();
      p.U32();  // max depth: recomputed and checked against the trees
      const uint32_t num_parts = p.U32();
      stride = p.U32();
      const uint32_t encoding = p.U32();
      const uint32_t background = p.U32();
      forest.constants.offset_unit = p.F32();
      p.U32();
      if (num_parts < 1 || num_parts > 254) return loss(where + "part count " + std::to_string(num_parts) + " outside 1..254");
      forest.num_parts = int(num_parts);
      if (stride != uint32_t(forest.leaf_stride()))
        return loss(where + "leaf stride " + std::to_string(stride) + " does not match " + std::to_string(num_parts) + " parts");
      if (encoding != kLeafEncodingU8Sum255) return loss(where + "unknown leaf encoding " + std::to_string(encoding));
      if (background == 0 || background > 65535) return loss(where + "background depth " + std::to_string(background) + " mm outside 1..65535");
      forest.constants.background_mm = uint16_t(background);
      if (tree_count == 0 || tree_count > 256) return loss(where + "tree count " + std::to_string(tree_count) + " outside 1..256");
      if (section_count < tree_count + 1)
        return loss(where + "tree count " + std::to_string(tree_count) + " but only " + std::to_string(section_count) + " sections");
      for (uint32_t i = 0; i < num_parts; ++i) {
        if (!p.Has(1)) return loss(where + "part table truncated at part " + std::to_string(i));
        const uint8_t len = p.U8();
        if (!p.Has(len)) return loss(where + "part table truncated at part " + std::to_string(i));
        forest.part_names.emplace_back(reinterpret_cast<const char*>(p.Ptr()), len);
        p.Skip(len);
      }
      have_meta = true;
    } else if (tag == kTagTree) {
      if (!have_meta) return loss(where + "TREE before META");
      if (!p.Has(kTreeFixedSize)) return loss(where + "TREE section too short");
      const uint32_t index = p.U32();
      if (index != forest.trees.size())
        return loss(where + "tree index " + std::to_string(index) + ", expected " + std::to_string(forest.trees.size()));
      if (forest.trees.size() >= tree_count) return loss(where + "more trees than the " + std::to_string(tree_count) + " declared");
      const uint32_t node_count = p.U32();
      const uint32_t leaf_count = p.U32();
      Tree tree;
      tree.depth = p.U32();
      tree.num_leaves = leaf_count;
      const uint64_t need = uint64_t(node_count) * sizeof(Node) + uint64_t(leaf_count) * stride;
      if (need != p.remaining())
        return loss(where + "tree " + std::to_string(index) + " declares " + std::to_string(node_count) + " nodes and " +
                    std::to_string(leaf_count) + " leaves (" + std::to_string(need) + " bytes) but holds " +
                    std::to_string(p.remaining()) + " bytes");
      tree.nodes.resize(node_count);
      for (Node& n : tree.nodes) {
        n.offsets.ux = p.I16();
        n.offsets.uy = p.I16();
        n.offsets.vx = p.I16();
        n.offsets.vy = p.I16();
        n.threshold = p.F32();
        n.child = p.U32();
      }
      tree.leaves.assign(p.Ptr(), p.Ptr() + size_t(leaf_count) * stride);
      forest.trees.push_back(std::move(tree));
    } else if (tag == kTagJointParams || tag == kTagFastJointParams) {
      // One set of joint-proposal parameters: JPAR for mean shift, JPFC for the fast clustering.
      const std::string name = TagName(tag);
      auto& slot = tag == kTagJointParams ? forest.proposal_params : forest.fast_proposal_params;
      if (slot) return loss(where + "second " + name + " section");
      if (!p.Has(4))
        return loss(where + name + " section too short (" + std::to_string(p.remaining()) + " bytes)");
      const uint32_t count = p.U32();
      if (count != uint32_t(kNumJoints) || p.remaining() != size_t(count) * 12)
        return loss(where + name + " holds " + std::to_string(p.remaining()) + " bytes for " +
                    std::to_string(count) + " joints, expected " + std::to_string(kNumJoints) + " x 12");
      ProposalParams params;
      for (JointParams& jp : params) {
        jp.bandwidth_m = p.F32();
        jp.prob_threshold = p.F32();
        jp.z_offset_m = p.F32();
      }
      slot = params;
    } else if (tag == kTagFocal) {
      if (have_focal) return loss(where + "second FOCL section");
      if (p.remaining() != 8)
        return loss(where + "FOCL holds " + std::to_string(p.remaining()) + " bytes, expected 8 (fx, fy)");
      forest.training_fx = p.F32();
      forest.training_fy = p.F32();
      have_focal = true;
    } else if (tag == kTagCalibration) {
      if (have_calibration) return loss(where + "second JCAL section");
      if (!p.Has(16))
        return loss(where + "JCAL section too short (" + std::to_string(p.remaining()) + " bytes)");
      ConfidenceCalibration cal;
      cal.method = ConfidenceCalibration::Method(p.U32());
      const uint32_t joints = p.U32();
      const uint32_t bins = p.U32();
      cal.samples = p.U32();
      if (joints != uint32_t(kNumJoints) || bins < 1 || bins > 256 ||
          p.remaining() != size_t(bins) * (1 + size_t(joints)) * 4)
        return loss(where + "JCAL holds " + std::to_string(p.remaining()) + " bytes for " +
                    std::to_string(joints) + " joints x " + std::to_string(bins) + " bins, expected " +
                    std::to_string(kNumJoints) + " joints and (1 + joints) x bins x 4 bytes");
      cal.support_edges_m2.resize(bins);
      for (float& e : cal.support_edges_m2) e = p.F32();
      for (auto& row : cal.precision) {
        row.resize(bins);
        for (float& v : row) v = p.F32();
      }
      forest.confidence_calibration = std::move(cal);
      have_calibration = true;
    } else if (tag == kTagOffsetVotes) {
      // Sizes only here; ValidateForest (below) checks the table against the trees.
      if (have_votes) return loss(where + "second JVOT section");
      if (!have_meta) return loss(where + "JVOT before META");
      if (!p.Has(kVotesHeadSize))
        return loss(where + "JVOT section too short (" + std::to_string(p.remaining()) +
                    " bytes, its head is " + std::to_string(kVotesHeadSize) + ")");
      OffsetVotes votes;
      const uint32_t trees = p.U32();
      const uint32_t joints = p.U32();
      if (joints != uint32_t(kNumJoints))
        return loss(where + "JVOT holds " + std::to_string(joints) + " joints, expected " +
                    std::to_string(kNumJoints));
      if (trees != tree_count)
        return loss(where + "JVOT holds votes for " + std::to_string(trees) + " trees, the forest declares " +
                    std::to_string(tree_count));
      votes.max_offset_m = p.F32();
      for (float& b : votes.bandwidth_m) b = p.F32();
      const uint32_t bins = p.U32();
      if (uint64_t(bins) * 4 * (1 + kNumJoints) > p.remaining())
        return loss(where + "JVOT calibration of " + std::to_string(bins) + " bins needs " +
                    std::to_string(uint64_t(bins) * 4 * (1 + kNumJoints)) + " bytes, the section holds " +
                    std::to_string(p.remaining()) + " more (truncated?)");
      votes.share_edges.resize(bins);
      for (float& e : votes.share_edges) e = p.F32();
      votes.precision.resize(size_t(bins) * kNumJoints);
      for (float& v : votes.precision) v = p.F32();
      votes.trees.resize(trees);
      for (uint32_t t = 0; t < trees; ++t) {
        const std::string tree_name = "JVOT tree " + std::to_string(t);
        if (!p.Has(8))
          return loss(where + tree_name + ": head truncated (" + std::to_string(p.remaining()) + " bytes)");
        const uint32_t leaves = p.U32();
        const uint32_t count = p.U32();
        // At most (2^32) * 4 + (2^32 - 1) * 8 bytes: no overflow in 64 bits.
        const uint64_t need = (uint64_t(leaves) + 1) * 4 + uint64_t(count) * kVoteSize;
        if (need > p.remaining())
          return loss(where + tree_name + ": " + std::to_string(leaves) + " leaves and " +
                      std::to_string(count) + " votes need " + std::to_string(need) +
                      " bytes, the section holds " + std::to_string(p.remaining()) + " more (truncated?)");
        TreeVotes& tv = votes.trees[t];
        tv.first.resize(size_t(leaves) + 1);
        for (uint32_t& f : tv.first) f = p.U32();
        tv.votes.resize(count);
        for (JointVote& v : tv.votes) {
          v.dx_mm = p.I16();
          v.dy_mm = p.I16();
          v.dz_mm = p.I16();
          v.joint = p.U8();
          v.weight = p.U8();
        }
      }
      if (p.remaining() != 0)
        return loss(where + "JVOT has " + std::to_string(p.remaining()) + " bytes after its last tree");
      forest.offset_votes = std::move(votes);
      have_votes = true;
    } else if (tag == kTagTracking) {
      if (have_tracking) return loss(where + "second JTRK section");
      const size_t need = 12 + 4 * (2 * size_t(kNumJoints) + size_t(kNumTrackingFeatures));
      if (p.remaining() != need)
        return loss(where + "JTRK holds " + std::to_string(p.remaining()) + " bytes, expected " +
                    std::to_string(need) + " (" + std::to_string(kNumJoints) + " joints, " +
                    std::to_string(kNumTrackingFeatures) + " cues)");
      const uint32_t joints = p.U32();
      const uint32_t cues = p.U32();
      if (joints != uint32_t(kNumJoints) || cues != uint32_t(kNumTrackingFeatures))
        return loss(where + "JTRK holds " + std::to_string(joints) + " joints and " + std::to_string(cues) +
                    " cues, expected " + std::to_string(kNumJoints) + " and " +
                    std::to_string(kNumTrackingFeatures));
      TrackingModel model;
      model.samples = p.U32();
      for (float& v : model.intercept) v = p.F32();
      for (float& v : model.slope) v = p.F32();
      for (float& v : model.shared) v = p.F32();
      forest.tracking_model = model;
      have_tracking = true;
    } else if (flags & kFlagRequired) {
      return loss(where + "section '" + TagName(tag) + "' is required but unknown to this reader (format " +
                  std::to_string(major) + "." + std::to_string(minor) + "; a newer poseforest can read it)");
    }
    // Unknown optional sections (added by later minor versions) are skipped.
  }
  if (r.remaining() != 0) return loss("unexpected " + std::to_string(r.remaining()) + " bytes after the last section");
  if (!have_meta) return loss("no META section");
  if (forest.trees.size() != tree_count)
    return loss("declares " + std::to_string(tree_count) + " trees but holds " + std::to_string(forest.trees.size()));
  POSEFOREST_RETURN_IF_ERROR(ValidateForest(forest, source));
  return forest;
}

Result<std::vector<uint8_t>> ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    const int err = errno;
    return Status(err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
                  path + (err == ENOENT ? ": no such file" : ": cannot open: " + std::string(std::strerror(err))));
  }
  const std::streamoff size = in.tellg();
  if (size < 0) return Status(ErrorCode::kIo, path + ": cannot determine the file size");
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.seekg(0);
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size))
    return Status(ErrorCode::kIo, path + ": read failed");
  return bytes;
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
