#include "proto/dds/histogram_codec.h"

#include <limits>
#include <string>

namespace poseforest::dds {

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

core::Result<std::vector<uint32_t>> DecodeHistogramRuns(const google::protobuf::RepeatedField<uint64_t>& runs,
                                                        const HistogramDims& dims) {
  const uint64_t cells = dims.cells();
  if (cells == 0 || cells > kMaxHistogramCells)
    return Status(ErrorCode::kDataLoss, "histogram dimensions " + std::to_string(dims.num_candidates) + "x" +
                                            std::to_string(dims.num_bins) + "x" + std::to_string(dims.num_parts) +
                                            " out of range");
  std::vector<uint32_t> dense(cells, 0);
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
      dense[pos++] = static_cast<uint32_t>(v);
    }
  }
  return dense;
}

Status ValidateNodeHistogram(const poseforest::v1::NodeHistogram& node, const HistogramDims& dims) {
  auto dense = DecodeHistogramRuns(node.runs(), dims);
  if (!dense.ok())
    return Status(dense.status().code(), "node " + std::to_string(node.node_id()) + ": " + dense.status().message());
  const uint64_t per_candidate = uint64_t(dims.num_bins) * dims.num_parts;
  for (uint32_t c = 0; c < dims.num_candidates; ++c) {
    uint64_t sum = 0;
    for (uint64_t j = 0; j < per_candidate; ++j) sum += (*dense)[c * per_candidate + j];
    if (sum != node.samples())
      return Status(ErrorCode::kDataLoss, "node " + std::to_string(node.node_id()) + " candidate " +
                                              std::to_string(c) + " counts " + std::to_string(sum) +
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

}  // namespace poseforest::dds
