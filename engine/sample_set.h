#pragma once
// The training samples held by one shard: which pixel of which frame, its part label, and the
// tree node it currently sits in. Stored structure-of-arrays, ordered by (node, frame) so that
// each frontier node's samples are one contiguous range and, inside it, the samples of one
// frame are adjacent (their probes then hit the same depth image in cache).

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/image_source.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/feature.h"
#include "runtime/core/rng.h"

namespace poseforest::engine {

/// One sampled pixel of a frame.
struct PixelSample {
  int x = 0, y = 0;  ///< pixels
  uint8_t part = 0;  ///< 0..kNumParts-1
};

/// Picks up to `count` body pixels (depth > 0 and a part label) of `frame`. `balance` in 0..1:
/// 0 draws pixels uniformly, 1 gives every present part an equal quota (capped by how many
/// pixels it has; the rest goes to the others), between interpolates quota ~ n_part^(1-balance).
/// Deterministic: every draw comes from `rng`. Output sorted by pixel index (row-major).
std::vector<PixelSample> SamplePixels(const LabelledFrame& frame, int count, double balance,
                                      const core::CounterRng& rng);

/// A depth frame as the feature reads it, keeping only what a probe can tell from background:
/// per row, the span from the first to the last pixel whose probe value (core::ProbeDepth: the
/// depth, or background_mm where it is 0) differs from background_mm. A probe off the frame or
/// off its row's span reads background_mm, which is what ProbeDepth reads there on the full
/// frame, so responses are identical by construction, whatever the frame holds (clutter, noise:
/// a frame without background costs its full size). Labels are not kept: the samples carry
/// their part.
struct CompactFrame {
  /// One row: probe values of pixels [lo, lo + len) lie at pixels[start, start + len).
  /// len == 0: the whole row reads background_mm.
  struct Row {
    uint32_t start = 0;
    uint16_t lo = 0, len = 0;
  };
  int width = 0, height = 0;     ///< pixels, of the frame it was made from
  std::vector<Row> rows;         ///< height entries
  std::vector<uint16_t> pixels;  ///< the rows' spans, concatenated (mm, 0 replaced by background_mm)

  /// Made from `depth` (at most 32767 x 32767 pixels) with background `background_mm`.
  static CompactFrame Of(const core::DepthImage& depth, uint16_t background_mm);
  /// core::ProbeDepth(depth, ..., x, y, background_mm, edge) of the frame it was made from.
  int32_t Probe(int x, int y, uint16_t background_mm, core::ProbeEdge edge) const {
    if (edge == core::ProbeEdge::kClamp && width > 0 && height > 0)
      x = std::clamp(x, 0, width - 1), y = std::clamp(y, 0, height - 1);
    if (unsigned(y) >= unsigned(height)) return background_mm;
    const Row& r = rows[size_t(y)];
    const unsigned rel = unsigned(x) - unsigned(r.lo);
    return rel < r.len ? int32_t(pixels[r.start + rel]) : int32_t(background_mm);
  }
  /// Bytes held (rows + pixels).
  uint64_t Bytes() const { return rows.size() * sizeof(Row) + pixels.size() * sizeof(uint16_t); }
};
static_assert(sizeof(CompactFrame::Row) == 8, "the SIMD kernels gather a row as one 64-bit word");

/// A range of samples sitting in one tree node.
struct NodeRange {
  uint32_t node = 0;   ///< index in the tree's breadth-first node array
  uint64_t begin = 0;  ///< first sample
  uint64_t end = 0;    ///< one past the last sample
};

/// The frames and samples of one shard of one tree.
class SampleSet {
 public:
  /// Adds a frame and its samples; frames must be added in increasing `frame_index`
  /// (the index in the tree's frame sequence, which identifies samples globally). Samples are
  /// body pixels (depth > 0).
  void AddFrame(uint64_t frame_index, const CompactFrame& frame, std::span<const PixelSample> pixels,
                const core::FeatureConstants& c);
  /// The same for a full depth frame (compacted first).
  void AddFrame(uint64_t frame_index, const core::DepthImage& depth, std::span<const PixelSample> pixels,
                const core::FeatureConstants& c);
  /// Adds a frame without samples, in any order (a worker's set of task frames kept across
  /// batches); returns its local id for AddSamples.
  uint32_t AddFrameOnly(uint64_t frame_index, const CompactFrame& frame, const core::FeatureConstants& c);
  uint32_t AddFrameOnly(uint64_t frame_index, const core::DepthImage& depth, const core::FeatureConstants& c);
  /// Adds samples (body pixels: depth > 0) of the frame with local id `local`; each one's own
  /// depth is read from the stored frame (a body pixel's probe value is its depth).
  void AddSamples(uint32_t local, std::span<const PixelSample> pixels, const core::FeatureConstants& c);
  /// The same, checking each pixel against `depth` (that frame, as given to it).
  void AddSamples(uint32_t local, const core::DepthImage& depth, std::span<const PixelSample> pixels,
                  const core::FeatureConstants& c);
  /// Drops every sample and node range; the frames stay (AddSamples, then StartTree, again).
  void ClearSamples();
  /// Pixels of all frames held (their spans in probe()).
  size_t probe_pixels() const { return probe_.size(); }
  /// Room for `frames` more frames of `pixels` span pixels in all and `samples` more samples
  /// (saves the regrowth of a set built many times, as a distributed worker's subtree tasks do,
  /// and the slack of a grown vector).
  void Reserve(size_t frames, size_t pixels, size_t samples, size_t rows = 0);
  /// Puts every sample in node `root` (call once after the last AddFrame).
  void StartTree(uint32_t root = 0);
  /// Puts sample i in node `node_of_sample[i]` (one entry per sample), keeping the (frame,
  /// pixel) order inside each node: several roots in one set (a worker's batch of subtrees).
  void StartTree(std::span<const uint32_t> node_of_sample);

  size_t num_samples() const { return x_.size(); }
  size_t num_frames() const { return frames_.size(); }
  /// Frontier ranges in increasing node order; nodes without samples here are absent.
  const std::vector<NodeRange>& ranges() const { return ranges_; }
  /// Range of `node`, or an empty one.
  NodeRange RangeOf(uint32_t node) const;

  /// Global identity of sample i: (frame index << 24) | pixel index. Never changes, so hashes
  /// of it select the same samples however frames are spread over shards.
  uint64_t uid(size_t i) const;

  /// Per-part sample counts of a node range (num_parts entries).
  void CountParts(const NodeRange& r, int num_parts, uint64_t* counts) const;

  /// Moves samples to children. `decision(node)` returns the split for a node: nullptr -> the
  /// node became a leaf (its samples are dropped); else go left (to left_child) if the
  /// response < cut + 0.5, i.e. response <= cut, else right (left_child + 1). Order inside each
  /// child stays (frame, pixel). `threads` = OpenMP threads.
  struct Split {
    uint32_t node = 0;
    core::FeatureOffsets offsets;
    int32_t cut = 0;  ///< integer cut: threshold tau = cut + 0.5 mm
    uint32_t left_child = 0;
  };
  void ApplySplits(std::span<const Split> splits, const core::FeatureConstants& c, int threads);

  /// Bytes held (frames + per-sample arrays).
  uint64_t MemoryBytes() const;

  /// Probe value at (x, y) of local frame `local`: core::ProbeDepth on the frame as given, with
  /// the set's probe edge (edge()).
  int32_t Probe(uint32_t local, int x, int y, uint16_t background_mm) const {
    const FrameInfo& fr = frames_[local];
    if (edge_ == core::ProbeEdge::kClamp && fr.width > 0 && fr.height > 0)
      x = std::clamp(x, 0, fr.width - 1), y = std::clamp(y, 0, fr.height - 1);
    if (unsigned(y) >= unsigned(fr.height)) return background_mm;
    const CompactFrame::Row& r = rows_[fr.row_begin + uint32_t(y)];
    const unsigned rel = unsigned(x) - unsigned(r.lo);
    return rel < r.len ? int32_t(probe_[r.start + rel]) : int32_t(background_mm);
  }
  /// Eq. 1 for sample i: core::FeatureResponse on its frame, bit-identical to the runtime (the
  /// same offsets and rounding; the probes read the compact frame, which reads as the full one).
  int32_t Response(size_t i, const core::FeatureOffsets& f, uint16_t background_mm) const {
    const float s = scale_[i];
    const int x = x_[i], y = y_[i];
    const int ux = x + core::RoundOffset(float(f.ux) * s), uy = y + core::RoundOffset(float(f.uy) * s);
    const int vx = x + core::RoundOffset(float(f.vx) * s), vy = y + core::RoundOffset(float(f.vy) * s);
    return Probe(frame_[i], ux, uy, background_mm) - Probe(frame_[i], vx, vy, background_mm);
  }
  /// Global frame index of sample i (its index in the tree's frame sequence).
  uint64_t frame_index(size_t i) const { return frames_[frame_[i]].index; }

  /// Where a frame lies in the row table.
  struct FrameInfo {
    uint64_t index = 0;      ///< global frame index
    uint32_t row_begin = 0;  ///< its first row in rows()
    int width = 0, height = 0;
  };

  // Hot-loop access (read-only views).
  /// Every frame's row spans, concatenated, with 0 replaced by background_mm, and 32 entries of
  /// padding so a 32-bit gather at the last pixel stays inside.
  const uint16_t* probe() const { return probe_.data(); }
  /// Every frame's rows (CompactFrame::Row, start in probe()), frame after frame: with
  /// uniform_size(), frame f's row y is rows()[f * height + y].
  const CompactFrame::Row* rows() const { return rows_.data(); }
  const std::vector<FrameInfo>& frames() const { return frames_; }
  /// True if every frame has the same size (the SIMD kernel's precondition).
  bool uniform_size() const { return uniform_size_; }
  /// What a probe beyond a frame's edge reads (FeatureConstants::edge of the frames added).
  core::ProbeEdge edge() const { return edge_; }
  const uint32_t* frame() const { return frame_.data(); }
  const int16_t* x() const { return x_.data(); }
  const int16_t* y() const { return y_.data(); }
  const float* scale() const { return scale_.data(); }
  const uint8_t* part() const { return part_.data(); }

 private:
  std::vector<uint16_t> probe_;  ///< frames' spans (see probe())
  std::vector<CompactFrame::Row> rows_;
  std::vector<FrameInfo> frames_;
  bool uniform_size_ = true;
  uint16_t background_mm_ = 0;
  core::ProbeEdge edge_ = core::ProbeEdge::kBackground;
  std::vector<uint32_t> frame_;  ///< local frame per sample
  std::vector<int16_t> x_, y_;   ///< pixels
  std::vector<float> scale_;     ///< PixelScale(d(x)) per sample: pixels per offset unit
  std::vector<uint8_t> part_;
  std::vector<NodeRange> ranges_;
};

}  // namespace poseforest::engine
