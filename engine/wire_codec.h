#pragma once
// The conversion between the engine's NodeHistogram (slots) and the wire's run-coded
// counts[candidate][bin][part] tensor, the wire form of a split, of a fused node's cuts and of a
// node's frame list: what a worker sends and the coordinator reads (proto/poseforest/v1/wire.proto).

#include <cstdint>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/sample_set.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/histogram_codec.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// proto::dds::EncodeHistogramRuns of the dense wire tensor (num_candidates x num_bins x num_parts; slot
/// -> part through plan.part_slot), the same runs to the byte, from the histogram's non-zero
/// counts only: no dense num_parts-wide tensor is built or scanned, so the cost follows
/// candidates x bins x parts present (and the samples for per-sample bins).
void EncodeWireRuns(const NodeHistogram& hist, const NodePlan& plan, int num_parts,
                    google::protobuf::RepeatedField<uint64_t>* runs);

/// Adds a run-encoded wire tensor (dds/histogram_codec.h layout, `dims`) into `hist` without
/// expanding it. False when the runs overrun the tensor or count a part absent from the node.
bool AddWireRuns(const google::protobuf::RepeatedField<uint64_t>& runs, const proto::dds::HistogramDims& dims,
                 const NodePlan& plan, NodeHistogram* hist);

/// Sets the 4 offsets + threshold of a wire FeatureSplit; threshold = cut + 0.5 (exact in float
/// for |cut| < 2^22).
void SetFeatureSplit(const core::FeatureOffsets& f, int32_t cut, uint32_t left_child, uint32_t candidate,
                     v1::FeatureSplit* out);
/// Inverse of SetFeatureSplit; InvalidArgument for a threshold that is not k + 0.5.
core::Status GetFeatureSplit(const v1::FeatureSplit& s, core::FeatureOffsets* f, int32_t* cut);

/// The cuts of a fused plan (plan.cuts, plan.cut_stride per candidate, kNoCut padding) into a
/// NodeRanges: cut_counts per candidate, cut_deltas the first cut and then the increments.
void EncodeCuts(const NodePlan& plan, v1::NodeRanges* out);
/// Inverse of EncodeCuts: `*cuts` gets num_candidates * cut_stride cuts padded with kNoCut.
/// False when the lists do not match num_candidates, a count exceeds cut_stride, or the cuts
/// do not ascend strictly below kNoCut.
bool DecodeCuts(const v1::NodeRanges& in, int num_candidates, int cut_stride, std::vector<int32_t>* cuts);

/// The frames holding the samples `range` of `samples` (a node's), in a PHASE_FRAMES NodeRanges:
/// num_samples, the tree-local frames (ascending: samples of a node are ordered by frame, pixel),
/// per frame its sample count, and the samples' pixel indices y * width + x delta-coded per frame
/// (the first absolute), so that a SubtreeTask needs no routing.
void EncodeNodeFrames(const SampleSet& samples, const NodeRange& range, v1::NodeRanges* out);

}  // namespace poseforest::engine
