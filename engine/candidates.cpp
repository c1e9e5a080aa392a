#include "engine/candidates.h"

#include <algorithm>
#include <cmath>

#include "runtime/core/rng.h"

namespace poseforest::engine {

namespace {
__extension__ typedef unsigned __int128 U128;  // GCC/Clang; exact products of 64-bit values
}  // namespace

int CutStride(int thresholds_per_feature) {
  int s = 1;
  while (s < thresholds_per_feature) s *= 2;
  return s;
}

std::vector<core::FeatureOffsets> DrawFeatures(const TrainParams& params, int tree, uint64_t position) {
  const core::CounterRng rng(params.seed, uint64_t(tree), position, kFeatureStream);
  const int m = params.max_offset_units();
  std::vector<core::FeatureOffsets> out(static_cast<size_t>(params.candidate_features));
  for (size_t k = 0; k < out.size(); ++k) {
    const uint64_t i = 4 * k;
    out[k].ux = int16_t(rng.UniformIntIn(i + 0, -m, m));
    out[k].uy = int16_t(rng.UniformIntIn(i + 1, -m, m));
    out[k].vx = int16_t(rng.UniformIntIn(i + 2, -m, m));
    out[k].vy = int16_t(rng.UniformIntIn(i + 3, -m, m));
  }
  // Which features probe against the pixel itself: draws of their own, after the offsets' 4n
  // (a counter RNG: the offsets' draws stay where they were).
  if (params.pixel_probe_share > 0) {
    const uint64_t first = 4 * uint64_t(out.size());
    for (size_t k = 0; k < out.size(); ++k)
      if (rng.Uniform01(first + k) < params.pixel_probe_share) out[k].vx = out[k].vy = 0;
  }
  return out;
}

ReferenceSelector::ReferenceSelector(const TrainParams& params, int tree, uint64_t position,
                                     uint64_t node_samples)
    : rng_(params.seed, uint64_t(tree), position, kReferenceStream) {
  if (node_samples <= params.threshold_reference_pixels) {
    all_ = true;
  } else {
    // limit = p * 2^64 with p = R / n, computed exactly in integers.
    limit_ = uint64_t((U128(params.threshold_reference_pixels) << 64) / node_samples);
  }
}

std::vector<int32_t> DrawCuts(const TrainParams& params, int tree, uint64_t position,
                              std::span<const ResponseRange> ranges) {
  const int t = params.thresholds_per_feature, stride = CutStride(t);
  const core::CounterRng rng(params.seed, uint64_t(tree), position, kThresholdStream);
  std::vector<int32_t> cuts(ranges.size() * size_t(stride), kNoCut);
  for (size_t k = 0; k < ranges.size(); ++k) {
    const ResponseRange& r = ranges[k];
    if (r.lo >= r.hi) continue;  // empty or constant: no threshold separates anything
    int32_t* c = &cuts[k * size_t(stride)];
    // Stratified: cut j is uniform within the j-th of t equal strata of [lo, hi - 1], so the
    // cuts come out sorted (no sort: at deep levels the thresholds of a node cost as much as
    // its evaluations) and spread over the whole range. Integer arithmetic only, so every
    // machine derives the same cuts.
    const auto span = uint64_t(int64_t(r.hi) - int64_t(r.lo));  // >= 1, < 2^18
    // Stratum width in 32.32 fixed point; cut j = lo + floor(j * w + u_j * w) / 2^32 < lo + span,
    // u_j a 16-bit fraction (four per 64 random bits: the draws are a visible cost at deep
    // levels, and 1/65536 of a stratum is far below the 1 mm resolution of the responses).
    const uint64_t w = (span << 32) / uint64_t(t);
    for (int j = 0; j < t; j += 4) {
      const uint64_t bits = rng.Bits(k * uint64_t(t) + uint64_t(j));
      for (int q = 0; q < 4 && j + q < t; ++q) {
        const uint64_t frac = (bits >> (16 * q)) & 0xFFFFu;
        const uint64_t pos = uint64_t(j + q) * w + uint64_t((U128(frac) * w) >> 16);
        c[j + q] = r.lo + int32_t(pos >> 32);
      }
    }
    int32_t* end = std::unique(c, c + t);
    std::fill(end, c + stride, kNoCut);
  }
  return cuts;
}

}  // namespace poseforest::engine
