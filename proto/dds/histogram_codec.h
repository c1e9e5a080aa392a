#pragma once
// Sparse encoding of per-node split histograms for HistogramReply (wire.proto, NodeHistogram):
// the dense counts[candidate][bin][part] tensor as runs of zeros and literal counts in packed
// varints. Most cells are zero deep in a tree (few parts reach a node), so this is compact.

#include <cstdint>
#include <span>
#include <vector>

#include "poseforest/v1/wire.pb.h"
#include "runtime/core/result.h"

namespace poseforest::proto::dds {

/// Dimensions of one node's histogram tensor.
struct HistogramDims {
  uint32_t num_candidates = 0;
  uint32_t num_bins = 0;
  uint32_t num_parts = 0;
  uint64_t cells() const { return uint64_t(num_candidates) * num_bins * num_parts; }
};

/// Largest tensor a receiver accepts per node (cells): 4096 candidates x 256 bins x 64 parts.
inline constexpr uint64_t kMaxHistogramCells = uint64_t(4096) * 256 * 64;

/// Appends the run encoding of `dense` to `runs` (which is cleared first).
/// Layout: repeatedly [zeros, n, v_1 .. v_n]; trailing zeros implied; n >= 1.
void EncodeHistogramRuns(std::span<const uint32_t> dense, google::protobuf::RepeatedField<uint64_t>* runs);

/// Decodes `runs` into exactly dims.cells() counts. DataLoss when the runs overrun the tensor,
/// have a zero-length literal run, a count above 2^32-1, or end inside a literal run.
core::Result<std::vector<uint32_t>> DecodeHistogramRuns(const google::protobuf::RepeatedField<uint64_t>& runs,
                                                        const HistogramDims& dims);

/// Full check of one NodeHistogram against its dimensions: decodes, and verifies that every
/// candidate's counts sum to `samples` and part_counts (num_parts entries) sum to `samples`.
core::Status ValidateNodeHistogram(const poseforest::v1::NodeHistogram& node, const HistogramDims& dims);

}  // namespace poseforest::proto::dds
