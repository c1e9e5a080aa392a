#include "proto/dds/histogram_codec.h"

#include <limits>
#include <string>

namespace poseforest::proto::dds {

using core::ErrorCode;
using core::Status;

void EncodeHistogramRuns(std::span<const uint32_t> dense, google::protobuf::RepeatedField<uint64_t>* runs) {
  runs->Clear();
  const size_t n = dense.size();
  size_t i = 0;
  while (i < n) {
    size_t zeros = 0;
    while (i + zeros < n && dense[i + zeros] == 0) ++zeros;
    if (i + zeros == n) break;  // trailing zeros are implied
    i += zeros;
    // Literal run: extend over single zeros (one literal 0 costs 1 byte, a new run header 2+).
    size_t end = i;
    while (end < n) {
      if (dense[end] != 0) {
        ++end;
      } else if (end + 1 < n && dense[end + 1] != 0) {
        end += 2;  // an isolated zero stays inside the literal run
      } else {
        break;
      }
    }
    runs->Add(zeros);
    runs->Add(end - i);
    runs->Reserve(runs->size() + static_cast<int>(end - i));
    for (const uint32_t* p = dense.data() + i; p != dense.data() + end; ++p) runs->Add(*p);
    i = end;
  }
}

namespace {

/// Walks `runs` over a tensor of dims.cells() counts, calling literal(position, value) for each
/// literal (zero runs are skipped), with every check of DecodeHistogramRuns.
template <class Literal>
Status WalkHistogramRuns(const google::protobuf::RepeatedField<uint64_t>& runs, const HistogramDims& dims,
                         Literal&& literal) {
  const uint64_t cells = dims.cells();
  if (cells == 0 || cells > kMaxHistogramCells)
    return Status(ErrorCode::kDataLoss, "histogram dimensions " + std::to_string(dims.num_candidates) + "x" +
                                            std::to_string(dims.num_bins) + "x" + std::to_string(dims.num_parts) +
                                            " out of range");
  uint64_t pos = 0;
  int k = 0;
  const int size = runs.size();
  while (k < size) {
    if (k + 2 > size) return Status(ErrorCode::kDataLoss, "histogram runs end inside a run header");
    const uint64_t zeros = runs.Get(k), count = runs.Get(k + 1);
    k += 2;
    if (count == 0) return Status(ErrorCode::kDataLoss, "histogram run of zero literals");
    if (zeros > cells - pos || count > cells - pos - zeros)
      return Status(ErrorCode::kDataLoss, "histogram runs overrun " + std::to_string(cells) + " cells");
    if (count > uint64_t(size - k)) return Status(ErrorCode::kDataLoss, "histogram runs end inside a literal run");
    pos += zeros;
    for (uint64_t j = 0; j < count; ++j) {
      const uint64_t v = runs.Get(k++);
      if (v > std::numeric_limits<uint32_t>::max())
        return Status(ErrorCode::kDataLoss, "histogram count " + std::to_string(v) + " exceeds 32 bits");
      literal(pos++, static_cast<uint32_t>(v));
    }
  }
  return Status::Ok();
}

}  // namespace

core::Result<std::vector<uint32_t>> DecodeHistogramRuns(const google::protobuf::RepeatedField<uint64_t>& runs,
                                                        const HistogramDims& dims) {
  std::vector<uint32_t> dense;
  if (const uint64_t cells = dims.cells(); cells != 0 && cells <= kMaxHistogramCells) dense.assign(cells, 0);
  POSEFOREST_RETURN_IF_ERROR(WalkHistogramRuns(runs, dims, [&](uint64_t pos, uint32_t v) { dense[pos] = v; }));
  return dense;
}

Status ValidateNodeHistogram(const poseforest::v1::NodeHistogram& node, const HistogramDims& dims) {
  // Per-candidate sums straight from the runs: no dense tensor (a node's is often over 1 MB and
  // the coordinator checks every node of every reply).
  const uint64_t per_candidate = uint64_t(dims.num_bins) * dims.num_parts;
  std::vector<uint64_t> sums;
  if (dims.cells() != 0 && dims.cells() <= kMaxHistogramCells) sums.assign(dims.num_candidates, 0);
  if (Status st = WalkHistogramRuns(node.runs(), dims, [&](uint64_t pos, uint32_t v) { sums[pos / per_candidate] += v; });
      !st.ok())
    return Status(st.code(), "node " + std::to_string(node.node_id()) + ": " + st.message());
  for (uint32_t c = 0; c < dims.num_candidates; ++c) {
    if (sums[c] != node.samples())
      return Status(ErrorCode::kDataLoss, "node " + std::to_string(node.node_id()) + " candidate " +
                                              std::to_string(c) + " counts " + std::to_string(sums[c]) +
                                              " samples, node has " + std::to_string(node.samples()));
  }
  if (static_cast<uint32_t>(node.part_counts_size()) != dims.num_parts)
    return Status(ErrorCode::kDataLoss, "node " + std::to_string(node.node_id()) + " has " +
                                            std::to_string(node.part_counts_size()) + " part counts, expected " +
                                            std::to_string(dims.num_parts));
  uint64_t parts = 0;
  for (uint64_t v : node.part_counts()) parts += v;
  if (parts != node.samples())
    return Status(ErrorCode::kDataLoss, "node " + std::to_string(node.node_id()) + " part counts sum to " +
                                            std::to_string(parts) + ", samples " + std::to_string(node.samples()));
  return Status::Ok();
}

}  // namespace poseforest::proto::dds
