#include "runtime/core/forest_format.h"

#include <cstdio>
#include <cstring>
#include <optional>

#include "runtime/core/crc32.h"
#include "runtime/core/forest_layout.h"

// The reader of the forest format; forest_format.cpp writes it (SerializeForest).

namespace poseforest::core {
namespace {

using namespace detail;  // the layout constants

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

/// A DataLoss error naming the file.
struct Loss {
  const std::string& source;
  Status operator()(const std::string& what) const { return Status(ErrorCode::kDataLoss, source + ": " + what); }
};

/// What the header says.
struct Header {
  uint16_t major = 0, minor = 0;
  uint32_t header_size = 0, section_count = 0;
};

/// The header read and checked, and the trailer (end marker, checksum).
Result<Header> ParseHeader(std::span<const uint8_t> bytes, const std::string& source) {
  const Loss loss{source};
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
  return Header{major, minor, header_size, section_count};
}

/// What ParseForest's section loop has read so far.
struct ParseState {
  Forest& forest;
  const Loss& loss;
  uint32_t section_count = 0;
  bool have_meta = false, have_focal = false, have_calibration = false, have_votes = false, have_tracking = false;
  bool have_edge = false;
  std::optional<TrackingFit> tracking_fit;  ///< JTFT, applied to the JTRK model after the loop
  std::optional<TrackingWeights> tracking_seen;  ///< JSEE, the JTRK model's seen decision after the loop
  uint32_t tree_count = 0, stride = 0;
};

/// META, section s.
Status ParseMeta(Reader& p, const std::string& where, uint32_t s, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
  const uint32_t section_count = st.section_count;
  uint32_t& tree_count = st.tree_count;
  uint32_t& stride = st.stride;
  bool& have_meta = st.have_meta;
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
  return Status::Ok();
}

Status ParseTree(Reader& p, const std::string& where, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
  const uint32_t tree_count = st.tree_count, stride = st.stride;
  const bool have_meta = st.have_meta;
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
  return Status::Ok();
}

/// One set of joint-proposal parameters: JPAR for mean shift, JPFC for the fast clustering.
Status ParseJointParams(Reader& p, const std::string& where, uint32_t tag, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
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
  return Status::Ok();
}

Status ParseFocal(Reader& p, const std::string& where, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
  bool& have_focal = st.have_focal;
  if (have_focal) return loss(where + "second FOCL section");
  if (p.remaining() != 8)
    return loss(where + "FOCL holds " + std::to_string(p.remaining()) + " bytes, expected 8 (fx, fy)");
  forest.training_fx = p.F32();
  forest.training_fy = p.F32();
  have_focal = true;
  return Status::Ok();
}

Status ParseCalibration(Reader& p, const std::string& where, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
  bool& have_calibration = st.have_calibration;
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
  return Status::Ok();
}

/// Tree t's votes of a JVOT section.
Status ParseTreeVotes(Reader& p, const std::string& where, uint32_t t, const Loss& loss, TreeVotes& tv) {
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
  return Status::Ok();
}

/// JVOT: sizes only here; ValidateForest (below) checks the table against the trees.
Status ParseOffsetVotes(Reader& p, const std::string& where, ParseState& st) {
  Forest& forest = st.forest;
  const Loss& loss = st.loss;
  const uint32_t tree_count = st.tree_count;
  const bool have_meta = st.have_meta;
  bool& have_votes = st.have_votes;
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
  for (uint32_t t = 0; t < trees; ++t)
    POSEFOREST_RETURN_IF_ERROR(ParseTreeVotes(p, where, t, loss, votes.trees[t]));
  if (p.remaining() != 0)
    return loss(where + "JVOT has " + std::to_string(p.remaining()) + " bytes after its last tree");
  forest.offset_votes = std::move(votes);
  have_votes = true;
  return Status::Ok();
}

/// A JTRK or JSEE payload: u32 joints, u32 cues, JTRK's u32 samples (when `samples` is given),
/// then the weights; its size exact and its counts this reader's.
Status ParseWeights(Reader& p, const std::string& where, const Loss& loss, const std::string& tag,
                    TrackingWeights& weights, uint32_t* samples) {
  const size_t need = (samples ? 12 : 8) + 4 * (2 * size_t(kNumJoints) + size_t(kNumTrackingFeatures));
  if (p.remaining() != need)
    return loss(where + tag + " holds " + std::to_string(p.remaining()) + " bytes, expected " +
                std::to_string(need) + " (" + std::to_string(kNumJoints) + " joints, " +
                std::to_string(kNumTrackingFeatures) + " cues)");
  const uint32_t joints = p.U32();
  const uint32_t cues = p.U32();
  if (joints != uint32_t(kNumJoints) || cues != uint32_t(kNumTrackingFeatures))
    return loss(where + tag + " holds " + std::to_string(joints) + " joints and " + std::to_string(cues) +
                " cues, expected " + std::to_string(kNumJoints) + " and " +
                std::to_string(kNumTrackingFeatures));
  if (samples) *samples = p.U32();
  for (float& v : weights.intercept) v = p.F32();
  for (float& v : weights.slope) v = p.F32();
  for (float& v : weights.shared) v = p.F32();
  return Status::Ok();
}

Status ParseTracking(Reader& p, const std::string& where, ParseState& st) {
  if (st.have_tracking) return st.loss(where + "second JTRK section");
  TrackingModel model;
  POSEFOREST_RETURN_IF_ERROR(ParseWeights(p, where, st.loss, "JTRK", model, &model.samples));
  st.forest.tracking_model = model;
  st.have_tracking = true;
  return Status::Ok();
}

/// JSEE (1.8): the seen decision of the JTRK model.
Status ParseTrackingSeen(Reader& p, const std::string& where, ParseState& st) {
  if (st.tracking_seen) return st.loss(where + "second JSEE section");
  TrackingWeights seen;
  POSEFOREST_RETURN_IF_ERROR(ParseWeights(p, where, st.loss, "JSEE", seen, nullptr));
  st.tracking_seen = seen;
  return Status::Ok();
}

/// JTFT (1.7): the skeleton fit the JTRK model was fitted on.
Status ParseTrackingFit(Reader& p, const std::string& where, ParseState& st) {
  const Loss& loss = st.loss;
  if (st.tracking_fit) return loss(where + "second JTFT section");
  if (p.remaining() != kTrackingFitSize)
    return loss(where + "JTFT holds " + std::to_string(p.remaining()) + " bytes, expected " +
                std::to_string(kTrackingFitSize));
  const uint32_t fit = p.U32();
  const uint32_t reserved = p.U32();
  if (fit != uint32_t(TrackingFit::kGreedy) && fit != uint32_t(TrackingFit::kKinematic))
    return loss(where + "JTFT names skeleton fit " + std::to_string(fit) + ", expected 0 (greedy) or 1 (kinematic)");
  if (reserved != 0) return loss(where + "JTFT's reserved word is " + std::to_string(reserved) + ", expected 0");
  st.tracking_fit = TrackingFit(fit);
  return Status::Ok();
}

/// PEDG (1.9): what a probe beyond the image's edge reads.
Status ParseProbeEdge(Reader& p, const std::string& where, ParseState& st) {
  const Loss& loss = st.loss;
  if (st.have_edge) return loss(where + "second PEDG section");
  if (!st.have_meta) return loss(where + "PEDG before META");
  if (p.remaining() != kProbeEdgeSize)
    return loss(where + "PEDG holds " + std::to_string(p.remaining()) + " bytes, expected " +
                std::to_string(kProbeEdgeSize));
  const uint32_t edge = p.U32();
  const uint32_t reserved = p.U32();
  if (edge != uint32_t(ProbeEdge::kBackground) && edge != uint32_t(ProbeEdge::kClamp))
    return loss(where + "PEDG names probe edge " + std::to_string(edge) +
                ", expected 0 (background) or 1 (clamp)");
  if (reserved != 0)
    return loss(where + "PEDG's reserved word is " + std::to_string(reserved) + ", expected 0");
  st.forest.constants.edge = ProbeEdge(edge);
  st.have_edge = true;
  return Status::Ok();
}

}  // namespace

Result<Forest> ParseForest(std::span<const uint8_t> bytes, const std::string& source) {
  const Loss loss{source};
  auto header = ParseHeader(bytes, source);
  if (!header.ok()) return header.status();
  const uint16_t major = header->major, minor = header->minor;
  const uint32_t header_size = header->header_size, section_count = header->section_count;

  Forest forest;
  forest.part_names.clear();
  ParseState st{forest, loss, section_count};
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
      POSEFOREST_RETURN_IF_ERROR(ParseMeta(p, where, s, st));
    } else if (tag == kTagTree) {
      POSEFOREST_RETURN_IF_ERROR(ParseTree(p, where, st));
    } else if (tag == kTagJointParams || tag == kTagFastJointParams) {
      POSEFOREST_RETURN_IF_ERROR(ParseJointParams(p, where, tag, st));
    } else if (tag == kTagFocal) {
      POSEFOREST_RETURN_IF_ERROR(ParseFocal(p, where, st));
    } else if (tag == kTagCalibration) {
      POSEFOREST_RETURN_IF_ERROR(ParseCalibration(p, where, st));
    } else if (tag == kTagOffsetVotes) {
      POSEFOREST_RETURN_IF_ERROR(ParseOffsetVotes(p, where, st));
    } else if (tag == kTagTracking) {
      POSEFOREST_RETURN_IF_ERROR(ParseTracking(p, where, st));
    } else if (tag == kTagTrackingFit) {
      POSEFOREST_RETURN_IF_ERROR(ParseTrackingFit(p, where, st));
    } else if (tag == kTagTrackingSeen) {
      POSEFOREST_RETURN_IF_ERROR(ParseTrackingSeen(p, where, st));
    } else if (tag == kTagProbeEdge) {
      POSEFOREST_RETURN_IF_ERROR(ParseProbeEdge(p, where, st));
    } else if (flags & kFlagRequired) {
      return loss(where + "section '" + TagName(tag) + "' is required but unknown to this reader (format " +
                  std::to_string(major) + "." + std::to_string(minor) + "; a newer poseforest can read it)");
    }
    // Unknown optional sections (added by later minor versions) are skipped.
  }
  if (r.remaining() != 0) return loss("unexpected " + std::to_string(r.remaining()) + " bytes after the last section");
  if (!st.have_meta) return loss("no META section");
  if (st.tracking_fit) {
    if (!forest.tracking_model) return loss("a JTFT section without the JTRK section it describes");
    forest.tracking_model->fit = *st.tracking_fit;
  }
  if (st.tracking_seen) {
    if (!forest.tracking_model) return loss("a JSEE section without the JTRK section it belongs to");
    forest.tracking_model->seen = *st.tracking_seen;
  }
  if (forest.trees.size() != st.tree_count)
    return loss("declares " + std::to_string(st.tree_count) + " trees but holds " + std::to_string(forest.trees.size()));
  POSEFOREST_RETURN_IF_ERROR(ValidateForest(forest, source));
  return forest;
}

}  // namespace poseforest::core
