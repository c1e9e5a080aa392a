#include "engine/wire_codec.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

void EncodeWireRuns(const NodeHistogram& hist, const NodePlan& plan, int num_parts,
                    google::protobuf::RepeatedField<uint64_t>* runs) {
  runs->Clear();
  const int slots = hist.num_slots, bins = hist.num_bins;
  // Slots in ascending part order: the order of their cells inside a wire row.
  std::vector<std::pair<int, int>> order;  // (part, slot)
  for (int p = 0; p < num_parts && p < int(plan.part_slot.size()); ++p)
    if (plan.part_slot[size_t(p)] != 0xFF && plan.part_slot[size_t(p)] < slots)
      order.emplace_back(p, plan.part_slot[size_t(p)]);
  // Same runs as EncodeHistogramRuns over the dense tensor: a literal run goes on over single
  // zeros (the next non-zero cell 2 further) and ends before two or more zeros.
  uint64_t next = 0;   // tensor position after the last cell written
  int len_index = -1;  // index of the open run's length entry, -1 when none is open
  auto emit = [&](uint64_t pos, uint32_t v) {
    if (len_index >= 0 && pos == next + 1) {  // an isolated zero stays inside the run
      runs->Add(0);
    } else if (len_index < 0 || pos != next) {
      if (len_index >= 0) runs->Set(len_index, uint64_t(runs->size() - len_index - 1));
      runs->Add(pos - next);
      len_index = runs->size();
      runs->Add(0);  // length, set when the run ends
    }
    runs->Add(v);
    next = pos + 1;
  };
  std::vector<uint32_t> row(size_t(bins) * size_t(slots));
  for (int k = 0; k < hist.num_candidates; ++k) {
    const uint32_t* c = row.data();
    if (hist.sample_bins)
      hist.CandidateCounts(k, row.data());
    else
      c = hist.counts.data() + size_t(k) * row.size();
    for (int b = 0; b < bins; ++b) {
      const uint64_t base = (uint64_t(k) * uint64_t(bins) + uint64_t(b)) * uint64_t(num_parts);
      for (const auto& [part, slot] : order)
        if (const uint32_t v = c[size_t(b) * size_t(slots) + size_t(slot)]; v != 0)
          emit(base + uint64_t(part), v);
    }
  }
  if (len_index >= 0) runs->Set(len_index, uint64_t(runs->size() - len_index - 1));
}

bool AddWireRuns(const google::protobuf::RepeatedField<uint64_t>& runs, const proto::dds::HistogramDims& dims,
                 const NodePlan& plan, NodeHistogram* hist) {
  const uint64_t cells = dims.cells();
  const uint64_t parts = dims.num_parts, slots = uint64_t(hist->num_slots);
  if (uint64_t(hist->num_candidates) * uint64_t(hist->num_bins) * parts != cells ||
      plan.part_slot.size() < parts)
    return false;
  uint64_t pos = 0;
  const int n = runs.size();
  for (int i = 0; i < n;) {
    pos += runs.Get(i++);
    if (i >= n) break;
    const uint64_t lit = runs.Get(i++);
    if (lit == 0 || lit > uint64_t(n - i) || pos > cells || lit > cells - pos) return false;
    for (uint64_t j = 0; j < lit; ++j, ++pos) {
      const uint64_t v = runs.Get(i++);
      if (v == 0) continue;
      if (v > 0xFFFFFFFFull) return false;
      const uint8_t slot = plan.part_slot[size_t(pos % parts)];
      if (slot == 0xFF) return false;
      hist->counts[size_t((pos / parts) * slots + slot)] += uint32_t(v);
    }
  }
  return pos <= cells;
}

void SetFeatureSplit(const core::FeatureOffsets& f, int32_t cut, uint32_t left_child, uint32_t candidate,
                     v1::FeatureSplit* out) {
  out->set_ux(f.ux);
  out->set_uy(f.uy);
  out->set_vx(f.vx);
  out->set_vy(f.vy);
  out->set_threshold(float(double(cut) + 0.5));
  out->set_candidate_index(candidate);
  out->set_left_child(left_child);
}

Status GetFeatureSplit(const v1::FeatureSplit& s, core::FeatureOffsets* f, int32_t* cut) {
  const double t = double(s.threshold()) - 0.5;
  if (!std::isfinite(t) || std::abs(t) > double(1 << 22) || t != std::floor(t))
    return Status(ErrorCode::kInvalidArgument,
                  "threshold " + std::to_string(s.threshold()) + " is not an integer + 0.5");
  f->ux = int16_t(s.ux());
  f->uy = int16_t(s.uy());
  f->vx = int16_t(s.vx());
  f->vy = int16_t(s.vy());
  *cut = int32_t(t);
  return Status::Ok();
}

void EncodeCuts(const NodePlan& plan, v1::NodeRanges* out) {
  const int k = int(plan.features.size());
  for (int c = 0; c < k; ++c) {
    uint32_t count = 0;
    int32_t prev = 0;
    for (int e = 0; e < plan.cut_stride; ++e) {
      const int32_t cut = plan.cuts[size_t(c) * size_t(plan.cut_stride) + size_t(e)];
      if (cut == kNoCut) break;
      out->add_cut_deltas(count == 0 ? cut : cut - prev);
      prev = cut;
      ++count;
    }
    out->add_cut_counts(count);
  }
}

bool DecodeCuts(const v1::NodeRanges& in, int num_candidates, int cut_stride, std::vector<int32_t>* cuts) {
  cuts->assign(size_t(num_candidates) * size_t(cut_stride), kNoCut);
  if (in.cut_counts_size() != num_candidates) return false;
  int pos = 0;
  for (int c = 0; c < num_candidates; ++c) {
    if (in.cut_counts(c) > uint32_t(cut_stride) || in.cut_counts(c) > uint32_t(in.cut_deltas_size() - pos))
      return false;
    int64_t v = 0;
    for (uint32_t j = 0; j < in.cut_counts(c); ++j) {
      const int32_t d = in.cut_deltas(pos++);
      if (j > 0 && d <= 0) return false;
      v = j == 0 ? int64_t(d) : v + int64_t(d);
      if (v >= int64_t(kNoCut)) return false;
      (*cuts)[size_t(c) * size_t(cut_stride) + j] = int32_t(v);
    }
  }
  return pos == in.cut_deltas_size();
}

void EncodeNodeFrames(const SampleSet& samples, const NodeRange& range, v1::NodeRanges* out) {
  out->set_num_samples(range.end - range.begin);
  uint32_t prev_pixel = 0;
  for (uint64_t j = range.begin; j < range.end; ++j) {
    const uint64_t f = samples.frame_index(j);
    const uint32_t pixel = uint32_t(samples.y()[j]) * uint32_t(samples.frames()[samples.frame()[j]].width) +
                           uint32_t(samples.x()[j]);
    if (out->frames_size() == 0 || out->frames(out->frames_size() - 1) != uint32_t(f)) {
      out->add_frames(uint32_t(f));
      out->add_frame_samples(0);
      prev_pixel = 0;
    }
    out->set_frame_samples(out->frames_size() - 1, out->frame_samples(out->frames_size() - 1) + 1);
    out->add_pixel_deltas(pixel - prev_pixel);
    prev_pixel = pixel;
  }
}

}  // namespace poseforest::engine
