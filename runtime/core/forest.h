#pragma once
// The decision forest in memory: per tree, one contiguous 64-byte-aligned array of 16-byte
// nodes and one table of quantized leaf distributions. The same layout is written to disk
// (see runtime/FORMAT.md) and walked by the classifier with no further checks, so every
// invariant below is established once, by ValidateForest (which the loader runs).

#include <cstddef>
#include <cstdint>
#include <new>
#include <optional>
#include <string>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/confidence_calibration.h"
#include "runtime/core/feature.h"
#include "runtime/core/offset_votes.h"
#include "runtime/core/tracking_model.h"
#include "runtime/core/proposal_params.h"
#include "runtime/core/result.h"

namespace poseforest::core {

/// Focal length of the Kinect v1 depth camera in pixels at 640x480 (CameraIntrinsics::KinectV1),
/// the camera every forest before format 1.3 was trained for.
inline constexpr double kKinectV1FocalPx = 575.8;

/// Minimal allocator giving cache-line-aligned storage for the hot arrays.
template <typename T, size_t kAlign = 64>
struct AlignedAllocator {
  using value_type = T;
  AlignedAllocator() = default;
  template <typename U>
  AlignedAllocator(const AlignedAllocator<U, kAlign>&) {}  // NOLINT
  template <typename U>
  struct rebind {
    using other = AlignedAllocator<U, kAlign>;
  };
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(kAlign))); }
  void deallocate(T* p, size_t) { ::operator delete(p, std::align_val_t(kAlign)); }
  template <typename U>
  bool operator==(const AlignedAllocator<U, kAlign>&) const { return true; }
};
template <typename T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

/// Set in Node::child to mark a leaf; the low 31 bits are then the leaf index.
inline constexpr uint32_t kLeafBit = 0x80000000u;

/// One tree node, 16 bytes, 4 per cache line.
/// Split node: go to `child` (left) if f_theta(I, x) < threshold (eq. 3), else `child + 1`.
/// Leaf: child == kLeafBit | leaf index; offsets and threshold are zero.
struct Node {
  FeatureOffsets offsets;  ///< theta = (u, v), in FeatureConstants::offset_unit
  float threshold = 0;     ///< tau, millimetres of depth difference
  uint32_t child = 0;      ///< index of the left child in this tree (> own index), or leaf

  bool is_leaf() const { return (child & kLeafBit) != 0; }
  uint32_t leaf_index() const { return child & ~kLeafBit; }
  static Node Leaf(uint32_t leaf_index) {
    Node n;
    n.child = kLeafBit | leaf_index;
    return n;
  }
  static Node Split(FeatureOffsets offsets, float threshold, uint32_t left_child) {
    Node n;
    n.offsets = offsets;
    n.threshold = threshold;
    n.child = left_child;
    return n;
  }
};
static_assert(sizeof(Node) == 16, "Node must stay 16 bytes (on-disk layout)");

/// Leaf distributions are uint8 numerators over kLeafTotal: each leaf's entries sum to exactly
/// 255, so the average of T trees (eq. 2) is an exact integer sum.
inline constexpr int kLeafTotal = 255;
/// Bytes per leaf row: number of parts rounded up to a multiple of 16 (SIMD-friendly); padding
/// entries are zero.
inline constexpr int LeafStride(int num_parts) { return (num_parts + 15) / 16 * 16; }

struct Tree {
  AlignedVector<Node> nodes;       ///< nodes[0] is the root; children after parents
  AlignedVector<uint8_t> leaves;   ///< num_leaves rows of LeafStride(num_parts) bytes
  uint32_t num_leaves = 0;
  uint32_t depth = 0;              ///< longest root-to-leaf path in edges (root alone = 0)

  const uint8_t* leaf(uint32_t i, int stride) const { return leaves.data() + size_t(i) * size_t(stride); }
};

struct Forest {
  FeatureConstants constants;
  int num_parts = kNumParts;
  std::vector<std::string> part_names;  ///< num_parts names (the taxonomy's, by default)
  std::vector<Tree> trees;
  /// Joint-proposal parameters learned for this forest, if any: for mean shift (format >= 1.1,
  /// section JPAR; a 1.1 file's one set, which served both methods, loads here) ...
  std::optional<ProposalParams> proposal_params;
  /// ... and for the fast clustering (format >= 1.2, section JPFC).
  std::optional<ProposalParams> fast_proposal_params;
  /// Focal lengths (pixels) of the camera the forest was trained for (format >= 1.3, section
  /// FOCL). Offsets are pixel*metres at this focal length: a camera with focal length f sees the
  /// same metres at f / training_fx times the pixels (runtime/camera_model.h rescales). Files
  /// older than 1.3 were all trained for the Kinect v1, which is the default.
  float training_fx = float(kKinectV1FocalPx);
  float training_fy = float(kKinectV1FocalPx);
  /// Joint confidence calibration measured by `tune-joints` (format >= 1.4, section JCAL):
  /// proposal support (m^2) -> precision on validation renders. Absent: FallbackConfidence.
  std::optional<ConfidenceCalibration> confidence_calibration;
  /// Offset votes learned by `learn-votes` (format >= 1.5, section JVOT): per leaf, offsets to
  /// the joints (runtime/joint_votes.h casts them). Absent: the skeleton uses part proposals only.
  std::optional<OffsetVotes> offset_votes;
  /// The learned tracking decision (format >= 1.6, section JTRK), fitted by `learn-votes` on
  /// validation renders. Absent: the skeleton's hand-set tracking rules.
  std::optional<TrackingModel> tracking_model;

  int leaf_stride() const { return LeafStride(num_parts); }
  /// Maximum depth over trees.
  uint32_t max_depth() const;
  /// Total nodes over trees.
  size_t total_nodes() const;
  /// The parameters a proposal method runs with: its own learned set; for the fast clustering
  /// without one, the mean-shift set (format 1.1's rule); else the paper's means.
  ProposalParamsChoice ProposalParamsFor(bool fast_clustering) const {
    if (fast_clustering && fast_proposal_params)
      return {*fast_proposal_params, ProposalParamsSource::kLearned};
    if (proposal_params)
      return {*proposal_params,
              fast_clustering ? ProposalParamsSource::kMeanShiftSet : ProposalParamsSource::kLearned};
    return {DefaultProposalParams(), ProposalParamsSource::kPaperMeans};
  }
  /// The confidence calibration, if it was measured for this proposal method; else null (the
  /// skeleton then uses FallbackConfidence).
  const ConfidenceCalibration* CalibrationFor(bool fast_clustering) const {
    const auto wanted =
        fast_clustering ? ConfidenceCalibration::Method::kFastClustering : ConfidenceCalibration::Method::kMeanShift;
    return confidence_calibration && confidence_calibration->method == wanted ? &*confidence_calibration : nullptr;
  }
  /// Part names of the paper's 31-part taxonomy.
  static std::vector<std::string> DefaultPartNames();
  /// How this forest's parts differ from the paper's 31-part taxonomy, which joints need: empty
  /// when they do not; "this one has 5 parts"; "its part 3 is 'X', the paper's 'RU_head'".
  std::string TaxonomyDifference() const;
};

/// Quantizes a probability vector (non-negative, any positive sum) to uint8 numerators summing
/// to exactly kLeafTotal by largest remainder; ties go to the lower part index. `out` receives
/// `n` values. An all-zero input becomes a uniform-as-possible distribution.
void QuantizeDistribution(const float* p, int n, uint8_t* out);

/// Checks every invariant the classifier relies on: children in range and after their parent,
/// right child in range, finite thresholds, leaf indices in range, each leaf row sums to 255
/// with zero padding, recorded depth equal to the real depth, part names present. `source`
/// names the file or message in errors.
Status ValidateForest(const Forest& forest, const std::string& source);

}  // namespace poseforest::core
