#include "engine/histogram_builder.h"

#include <omp.h>

#include <algorithm>
#include <exception>

#include "engine/histogram_kernels.h"

namespace poseforest::engine {

HistogramBuilder::HistogramBuilder(const core::FeatureConstants& constants, int threads)
    : constants_(constants), threads_(std::max(1, threads)) {}

void HistogramBuilder::ComputeRanges(const SampleSet& samples, const TrainParams& params, int tree,
                                     std::span<const NodePlan> plans,
                                     std::vector<std::vector<ResponseRange>>* out) {
  out->assign(plans.size(), {});
  // Reference samples per plan: either the whole node range (contiguous: vector kernel) or a
  // hash-selected subset (index list: scalar).
  std::vector<std::vector<uint32_t>> refs(plans.size());
  std::vector<uint8_t> whole(plans.size(), 0);
  std::vector<NodeRange> ranges(plans.size());
  std::vector<Item> items;
  for (size_t p = 0; p < plans.size(); ++p) {
    (*out)[p].assign(plans[p].features.size(), ResponseRange{});
    const NodeRange r = ranges[p] = samples.RangeOf(plans[p].node);
    if (r.end == r.begin) continue;
    const ReferenceSelector sel(params, tree, plans[p].position, plans[p].num_samples);
    if (sel.all()) {
      whole[p] = 1;
    } else {
      for (uint64_t i = r.begin; i < r.end; ++i)
        if (sel.Selected(samples.uid(i))) refs[p].push_back(uint32_t(i));
      if (refs[p].empty()) continue;
    }
    const auto k = uint32_t(plans[p].features.size());
    uint32_t chunk = ChunkFor(whole[p] ? r.end - r.begin : refs[p].size(), k, threads_);
    // Sample-major (whole candidate rows per item) for small nodes and for reference subsamples
    // of at most kSampleMajorMax samples (the usual case: threshold_reference_pixels = 500).
    if (SampleMajor(whole[p], r.end - r.begin, samples) || (!whole[p] && SampleMajor(true, refs[p].size(), samples)))
      chunk = k;
    for (uint32_t k0 = 0; k0 < k; k0 += chunk) items.push_back({uint32_t(p), k0, std::min(k, k0 + chunk)});
  }
  const KernelInput in = InputOf(samples, constants_.background_mm);
  [[maybe_unused]] const bool simd = samples.uniform_size();
  OmpErrors errors;
  const auto n_items = int64_t(items.size());
#pragma omp parallel for num_threads(threads_) schedule(dynamic, 1)
  for (int64_t it = 0; it < n_items; ++it) {
    errors.Run([&] {
      const Item item = items[size_t(it)];
      const NodePlan& plan = plans[item.plan];
      ResponseRange* out_ranges = (*out)[item.plan].data();
      const NodeRange range = ranges[item.plan];
#if POSEFOREST_HIST_AVX512
      if (SampleMajor(whole[item.plan], range.end - range.begin, samples)) {
        CandidateSoa soa;
        soa.Set(plan.features, nullptr, 0, 0);
        RangeSampleMajorAvx512(in, range.begin, range.end, nullptr, soa, out_ranges);
        return;
      }
      if (!whole[item.plan] && SampleMajor(true, refs[item.plan].size(), samples)) {
        CandidateSoa soa;
        soa.Set(plan.features, nullptr, 0, 0);
        RangeSampleMajorAvx512(in, 0, refs[item.plan].size(), refs[item.plan].data(), soa, out_ranges);
        return;
      }
#endif
      for (uint32_t k = item.k0; k < item.k1; ++k) {
        const core::FeatureOffsets f = plan.features[k];
        ResponseRange r;
        if (whole[item.plan]) {
#if POSEFOREST_HIST_AVX512
          if (simd) {
            RangeAvx512(in, range.begin, range.end, f, &r);
            out_ranges[k] = r;
            continue;
          }
#endif
          for (uint64_t i = range.begin; i < range.end; ++i) r.Add(samples.Response(i, f, in.background_mm));
        } else {
          for (uint32_t i : refs[item.plan]) r.Add(samples.Response(i, f, in.background_mm));
        }
        out_ranges[k] = r;
      }
    });
  }
  errors.Rethrow();
}

void HistogramBuilder::Build(const SampleSet& samples, std::span<const NodePlan> plans,
                             int thresholds_per_feature, std::vector<NodeHistogram>* out) {
  out->resize(plans.size());
  const int num_bins = thresholds_per_feature + 1;
  std::vector<Item> items;
  std::vector<NodeRange> ranges(plans.size());
  uint64_t evals = 0;
  for (size_t p = 0; p < plans.size(); ++p) {
    const NodePlan& plan = plans[p];
    POSEFOREST_CHECK(plan.cut_stride >= thresholds_per_feature &&
                     plan.cuts.size() == plan.features.size() * size_t(plan.cut_stride));
    NodeHistogram& hist = (*out)[p];
    hist.Reset(plan.node, int(plan.features.size()), num_bins, plan.num_slots, plan.sample_bins);
    ranges[p] = samples.RangeOf(plan.node);
    const uint64_t n = ranges[p].end - ranges[p].begin;
    if (n == 0) continue;
    const auto k = uint32_t(plan.features.size());
    evals += n * k;
    uint32_t chunk = ChunkFor(n, k, threads_);
    if (plan.sample_bins) {
      hist.sample_slot.resize(n);
      for (uint64_t i = 0; i < n; ++i)
        hist.sample_slot[i] = plan.part_slot[samples.part()[ranges[p].begin + i]];
      hist.sample_bin.resize(n * k);
      // Samples are written by row: any candidate split of the item works; keep whole rows
      // together for the vector kernel.
      if (samples.uniform_size()) chunk = k;
    } else if (SampleMajor(true, n, samples) && plan.cut_stride <= 64) {
      chunk = k;
    }
    for (uint32_t k0 = 0; k0 < k; k0 += chunk) items.push_back({uint32_t(p), k0, std::min(k, k0 + chunk)});
  }
  const KernelInput in = InputOf(samples, constants_.background_mm);
  [[maybe_unused]] const bool simd = samples.uniform_size();
  OmpErrors errors;
  const auto n_items = int64_t(items.size());
#pragma omp parallel for num_threads(threads_) schedule(dynamic, 1)
  for (int64_t it = 0; it < n_items; ++it) {
    errors.Run([&] {
      const Item item = items[size_t(it)];
      const NodePlan& plan = plans[item.plan];
      const NodeRange range = ranges[item.plan];
      NodeHistogram& hist = (*out)[item.plan];
      const int slots = hist.num_slots, stride = plan.cut_stride;
      const uint8_t* slot_of = plan.part_slot.data();
      int32_t slot_table32[32] = {};
      [[maybe_unused]] int16_t slot_table16[32] = {};
      for (int c = 0; c < core::kNumParts; ++c) {
        slot_table32[c] = slot_of[c] == 0xFF ? 0 : slot_of[c];
        slot_table16[c] = int16_t(slot_table32[c]);
      }
      if (plan.sample_bins) {
        uint8_t* rows = hist.sample_bin.data();
        const auto kk = size_t(plan.features.size());
#if POSEFOREST_HIST_AVX512
        if (samples.uniform_size()) {
          CandidateSoa soa;
          soa.Set(plan.features, plan.cuts.data(), stride, thresholds_per_feature);
          BinSampleMajorAvx512(in, range.begin, range.end, soa, rows);
          return;
        }
#endif
        for (uint32_t k = item.k0; k < item.k1; ++k) {
          const int32_t* cuts = &plan.cuts[size_t(k) * size_t(stride)];
          for (uint64_t i = range.begin; i < range.end; ++i)
            rows[(i - range.begin) * kk + k] =
                uint8_t(BinOf(samples.Response(i, plan.features[k], in.background_mm), cuts, stride));
        }
        return;
      }
#if POSEFOREST_HIST_AVX512
      if (SampleMajor(true, range.end - range.begin, samples) && stride <= 64) {
        CandidateSoa soa;
        soa.Set(plan.features, plan.cuts.data(), stride, thresholds_per_feature);
        CountSampleMajorAvx512(in, range.begin, range.end, soa, slot_of, num_bins, slots, hist.counts.data());
        return;
      }
#endif
      // Candidates of the item walk the node's samples in blocks, so the frames a block
      // touches stay in cache across the item's candidates (measured at the root, procedural
      // frames: blocks of 1024 samples, half a frame, +5-7% over 4096).
      constexpr uint64_t kBlock = 1024;
      for (uint64_t b0 = range.begin; b0 < range.end; b0 += kBlock) {
        const uint64_t b1 = std::min(range.end, b0 + kBlock);
        for (uint32_t k = item.k0; k < item.k1; ++k) {
          const core::FeatureOffsets f = plan.features[k];
          const int32_t* cuts = &plan.cuts[size_t(k) * size_t(stride)];
          uint32_t* counts = &hist.counts[size_t(k) * size_t(num_bins) * size_t(slots)];
          if (cuts[0] == kNoCut) {
            // No thresholds: every sample lands in bin 0.
            for (uint64_t i = b0; i < b1; ++i) ++counts[slot_of[in.part[i]]];
            continue;
          }
#if POSEFOREST_HIST_AVX512
          if (simd && stride <= 64) {
            if (CutsFit16(cuts, size_t(stride)))
              CountAvx512x16(in, b0, b1, f, cuts, stride, slot_table16, slots, counts);
            else
              CountAvx512(in, b0, b1, f, cuts, stride, slot_table32, slots, counts);
            continue;
          }
#endif
          if (simd) {
            CountScalar(in, b0, b1, f, cuts, stride, slot_of, slots, counts);
          } else {
            for (uint64_t i = b0; i < b1; ++i)
              ++counts[BinOf(samples.Response(i, f, in.background_mm), cuts, stride) * slots +
                       slot_of[in.part[i]]];
          }
        }
      }
    });
  }
  errors.Rethrow();
  evaluations_ += evals;
}

bool HistogramBuilder::CanFuse(const SampleSet& samples, const TrainParams& params, const NodePlan& plan) {
  const NodeRange r = samples.RangeOf(plan.node);
  return plan.num_samples > 0 && r.end - r.begin == plan.num_samples &&
         plan.num_samples <= params.threshold_reference_pixels;
}

namespace {

#if POSEFOREST_HIST_AVX512
/// BuildFused's second pass in 16-bit lanes (soa.fit16): the bins of the node's responses `resp`
/// (rows of `ps` candidates) by a linear count over the transposed cuts, as the sample-major
/// kernel does, tiles of kTile samples.
void FusedBins16(const SampleSet& samples, const NodePlan& plan, const NodeRange& range, const CandidateSoa& soa,
                 const std::vector<int32_t>& resp, size_t ps, int t, NodeHistogram& hist) {
  const uint64_t n = range.end - range.begin;
  const size_t kk = plan.features.size();
  const int num_bins = t + 1, slots = hist.num_slots;
  alignas(64) uint16_t local[32];  // bin * slots + slot per lane
  const size_t cs = size_t(num_bins) * size_t(slots);
  auto tile = [&]<int S>(uint64_t i) {
    __m512i r[S], bin[S];
    for (int k = 0; k < soa.num_candidates; k += 32) {
      for (int s = 0; s < S; ++s) {
        const int32_t* ri = &resp[(i + uint64_t(s)) * ps + size_t(k)];
        r[s] = Pack16(_mm512_loadu_si512(ri), _mm512_loadu_si512(ri + 16));
      }
      BinsTile<S>(r, soa.cuts16.data() + k, size_t(soa.padded), t, bin);
      const int m = std::min(32, soa.num_candidates - k);
      for (int s = 0; s < S; ++s) {
        if (plan.sample_bins) {
          _mm256_mask_storeu_epi8(&hist.sample_bin[(i + uint64_t(s)) * kk + size_t(k)], Mask32(uint64_t(m)),
                                  _mm512_cvtepi16_epi8(bin[s]));
        } else {
          const __m512i slot =
              _mm512_set1_epi16(int16_t(plan.part_slot[samples.part()[range.begin + i + uint64_t(s)]]));
          _mm512_store_si512(
              local, _mm512_add_epi16(_mm512_mullo_epi16(bin[s], _mm512_set1_epi16(int16_t(slots))), slot));
          uint32_t* ck = hist.counts.data() + size_t(k) * cs;
          for (int l = 0; l < m; ++l) ++ck[size_t(l) * cs + local[l]];
        }
      }
    }
  };
  uint64_t i = 0;
  for (; i + kTile <= n; i += kTile) tile.template operator()<kTile>(i);
  for (; i < n; ++i) tile.template operator()<1>(i);
}

/// BuildFused's second pass in 32-bit lanes (cuts that do not fit 16 bits).
void FusedBins32(const SampleSet& samples, const NodePlan& plan, const NodeRange& range, const CandidateSoa& soa,
                 const std::vector<int32_t>& resp, size_t ps, int t, NodeHistogram& hist) {
  const uint64_t n = range.end - range.begin;
  const size_t kk = plan.features.size();
  const int num_bins = t + 1, slots = hist.num_slots;
  alignas(64) int32_t idx[16];
  const __m512i one = _mm512_set1_epi32(1);
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  for (uint64_t i = 0; i < n; ++i) {
    const int slot = plan.part_slot[samples.part()[range.begin + i]];
    for (int k = 0; k < soa.num_candidates; k += 16) {
      const __m512i r = _mm512_loadu_si512(&resp[i * ps + size_t(k)]);
      __m512i bin = _mm512_setzero_si512();
      const int32_t* col = soa.cuts.data() + k;
      for (int j = 0; j < t; ++j)
        bin = _mm512_mask_add_epi32(
            bin, _mm512_cmpgt_epi32_mask(r, _mm512_loadu_si512(col + size_t(j) * size_t(soa.padded))), bin, one);
      const int m = std::min(16, soa.num_candidates - k);
      if (plan.sample_bins) {
        _mm512_mask_cvtepi32_storeu_epi8(&hist.sample_bin[i * kk + size_t(k)], __mmask16((1u << m) - 1), bin);
      } else {
        const __m512i cand = _mm512_add_epi32(_mm512_set1_epi32(k), lane);
        _mm512_store_si512(idx,
                           _mm512_add_epi32(_mm512_mullo_epi32(cand, _mm512_set1_epi32(num_bins * slots)),
                                            _mm512_add_epi32(_mm512_mullo_epi32(bin, _mm512_set1_epi32(slots)),
                                                             _mm512_set1_epi32(slot))));
        for (int l = 0; l < m; ++l) ++hist.counts[size_t(idx[l])];
      }
    }
  }
}
#endif

/// BuildFused of one node: pass 1 computes every response once (rows padded to 32 candidates,
/// in `resp`) and the ranges from them, the cuts are drawn, pass 2 bins the stored responses.
void FusedNode(const KernelInput& in, const SampleSet& samples, const TrainParams& params, int tree,
               NodePlan& plan, NodeHistogram& hist, std::vector<int32_t>& resp) {
  const int t = params.thresholds_per_feature, num_bins = t + 1;
  const NodeRange range = samples.RangeOf(plan.node);
  const uint64_t n = range.end - range.begin;
  const size_t kk = plan.features.size();
  const size_t ps = (kk + 31) / 32 * 32;
  resp.resize(n * ps);
  std::vector<ResponseRange> ranges(kk);
  const int stride = CutStride(t), slots = hist.num_slots;
#if POSEFOREST_HIST_AVX512
  if (samples.uniform_size() && stride <= 64) {
    CandidateSoa soa;
    soa.Set(plan.features, nullptr, 0, 0);
    std::vector<int32_t> lo(ps, INT32_MAX), hi(ps, INT32_MIN);
    for (uint64_t i = 0; i < n; ++i)
      for (int k = 0; k < soa.padded; k += 16) {
        const __m512i r = SampleResponses16(in, range.begin + i, soa, k);
        _mm512_storeu_si512(&resp[i * ps + size_t(k)], r);
        _mm512_storeu_si512(&lo[size_t(k)], _mm512_min_epi32(_mm512_loadu_si512(&lo[size_t(k)]), r));
        _mm512_storeu_si512(&hi[size_t(k)], _mm512_max_epi32(_mm512_loadu_si512(&hi[size_t(k)]), r));
      }
    for (size_t k = 0; k < kk; ++k) ranges[k] = ResponseRange{lo[k], hi[k]};
    plan.cuts = DrawCuts(params, tree, plan.position, ranges);
    plan.cut_stride = stride;
    soa.Set(plan.features, plan.cuts.data(), stride, t);
    if (soa.fit16)
      FusedBins16(samples, plan, range, soa, resp, ps, t, hist);
    else
      FusedBins32(samples, plan, range, soa, resp, ps, t, hist);
    return;
  }
#endif
  for (uint64_t i = 0; i < n; ++i)
    for (size_t k = 0; k < kk; ++k)
      resp[i * ps + k] = samples.Response(range.begin + i, plan.features[k], in.background_mm);
  for (uint64_t i = 0; i < n; ++i)
    for (size_t k = 0; k < kk; ++k) ranges[k].Add(resp[i * ps + k]);
  plan.cuts = DrawCuts(params, tree, plan.position, ranges);
  plan.cut_stride = stride;
  for (uint64_t i = 0; i < n; ++i) {
    const int slot = plan.part_slot[samples.part()[range.begin + i]];
    for (size_t k = 0; k < kk; ++k) {
      const int bin = BinOf(resp[i * ps + k], &plan.cuts[k * size_t(stride)], stride);
      if (plan.sample_bins)
        hist.sample_bin[i * kk + k] = uint8_t(bin);
      else
        ++hist.counts[(k * size_t(num_bins) + size_t(bin)) * size_t(slots) + size_t(slot)];
    }
  }
}

}  // namespace

void HistogramBuilder::BuildFused(const SampleSet& samples, const TrainParams& params, int tree,
                                  std::span<NodePlan> plans, std::vector<NodeHistogram>* out) {
  out->resize(plans.size());
  const int t = params.thresholds_per_feature, num_bins = t + 1;
  uint64_t evals = 0;
  for (size_t p = 0; p < plans.size(); ++p) {
    POSEFOREST_CHECK(CanFuse(samples, params, plans[p]));
    const uint64_t n = plans[p].num_samples;
    evals += n * plans[p].features.size();
    NodeHistogram& hist = (*out)[p];
    hist.Reset(plans[p].node, int(plans[p].features.size()), num_bins, plans[p].num_slots,
               plans[p].sample_bins);
    if (plans[p].sample_bins) {
      const NodeRange r = samples.RangeOf(plans[p].node);
      hist.sample_slot.resize(n);
      for (uint64_t i = 0; i < n; ++i) hist.sample_slot[i] = plans[p].part_slot[samples.part()[r.begin + i]];
      hist.sample_bin.resize(n * plans[p].features.size());
    }
  }
  const KernelInput in = InputOf(samples, constants_.background_mm);
  OmpErrors errors;
  const auto n_plans = int64_t(plans.size());
#pragma omp parallel num_threads(threads_)
  {
    std::vector<int32_t> resp;  // [sample][candidate]
#pragma omp for schedule(dynamic, 1)
    for (int64_t p = 0; p < n_plans; ++p)
      errors.Run([&] { FusedNode(in, samples, params, tree, plans[size_t(p)], (*out)[size_t(p)], resp); });
  }
  errors.Rethrow();
  evaluations_ += evals;
}

}  // namespace poseforest::engine
