#include "engine/histogram_builder.h"

// Node plans and node histograms: their shapes, sums and differences (the counting kernels that
// fill them are in histogram_kernels.h, the builder in histogram_builder.cpp).

namespace poseforest::engine {

void NodePlan::SetParts(std::span<const uint64_t> part_counts) {
  part_slot.assign(core::kNumParts, 0xFF);
  num_slots = 0;
  for (size_t c = 0; c < part_counts.size() && c < size_t(core::kNumParts); ++c)
    if (part_counts[c] > 0) part_slot[c] = uint8_t(num_slots++);
}

void NodePlan::SetShape(std::span<const uint64_t> part_counts, int thresholds_per_feature) {
  SetParts(part_counts);
  sample_bins = UseSampleBins(num_samples, thresholds_per_feature, num_slots);
  cut_stride = CutStride(thresholds_per_feature);
}

bool UseSampleBins(uint64_t node_samples, int thresholds_per_feature, int slots) {
  // Per sample K + 1 bytes vs K * bins * slots * 4 bytes per node; independent of K.
  return node_samples < uint64_t(4) * uint64_t(thresholds_per_feature + 1) * uint64_t(slots);
}

void NodeHistogram::Reset(uint32_t node_id, int candidates, int bins, int slots, bool per_sample) {
  node = node_id;
  num_candidates = candidates;
  num_bins = bins;
  num_slots = slots;
  sample_bins = per_sample;
  sample_slot.clear();
  sample_bin.clear();
  if (per_sample) {
    POSEFOREST_CHECK(bins <= 256);
    counts.clear();
  } else {
    counts.assign(size_t(candidates) * size_t(bins) * size_t(slots), 0);
  }
}

void NodeHistogram::Add(const NodeHistogram& other) {
  POSEFOREST_CHECK(node == other.node && num_candidates == other.num_candidates &&
                   num_bins == other.num_bins && num_slots == other.num_slots &&
                   sample_bins == other.sample_bins);
  if (sample_bins) {
    sample_slot.insert(sample_slot.end(), other.sample_slot.begin(), other.sample_slot.end());
    sample_bin.insert(sample_bin.end(), other.sample_bin.begin(), other.sample_bin.end());
    return;
  }
  for (size_t i = 0; i < counts.size(); ++i) counts[i] += other.counts[i];
}

void NodeHistogram::CandidateCounts(int k, uint32_t* out) const {
  const size_t n = size_t(num_bins) * size_t(num_slots);
  if (!sample_bins) {
    std::copy_n(counts.data() + size_t(k) * n, n, out);
    return;
  }
  std::fill(out, out + n, 0u);
  const size_t stride = size_t(num_candidates);
  for (size_t i = 0; i < sample_slot.size(); ++i)
    ++out[size_t(sample_bin[i * stride + size_t(k)]) * size_t(num_slots) + sample_slot[i]];
}

NodeHistogram NodeHistogram::ToDense() const {
  NodeHistogram d;
  d.Reset(node, num_candidates, num_bins, num_slots, false);
  for (int k = 0; k < num_candidates; ++k)
    CandidateCounts(k, d.counts.data() + size_t(k) * size_t(num_bins) * size_t(num_slots));
  return d;
}

void NodeHistogram::SetDifference(const NodeHistogram& parent, const NodeHistogram& other) {
  POSEFOREST_CHECK(parent.num_candidates == other.num_candidates && parent.num_bins == other.num_bins &&
                   parent.num_slots == other.num_slots);
  num_candidates = parent.num_candidates;
  num_bins = parent.num_bins;
  num_slots = parent.num_slots;
  counts.resize(parent.counts.size());
  for (size_t i = 0; i < counts.size(); ++i) {
    POSEFOREST_CHECK(parent.counts[i] >= other.counts[i]);
    counts[i] = parent.counts[i] - other.counts[i];
  }
}

uint64_t HistogramBytes(int candidates, int thresholds_per_feature, int slots) {
  return uint64_t(candidates) * uint64_t(thresholds_per_feature + 1) * uint64_t(slots) * sizeof(uint32_t);
}

uint64_t PlanHistogramBytes(const NodePlan& plan, int thresholds_per_feature) {
  if (plan.sample_bins) return plan.num_samples * (plan.features.size() + 1);
  return HistogramBytes(int(plan.features.size()), thresholds_per_feature, plan.num_slots);
}

}  // namespace poseforest::engine
