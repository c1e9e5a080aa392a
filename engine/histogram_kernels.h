#pragma once
// The histogram builder's counting kernels: scalar, AVX-512 candidate-major and sample-major,
// their response ranges and the fused bins. Internal to engine/histogram_builder.cpp, the only
// file that includes it: the kernels stay in one translation unit with their callers, so they are
// inlined there as before, and in an unnamed namespace.

#include <omp.h>

#include <algorithm>
#include <exception>

#include "engine/histogram_builder.h"

#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__)
#define POSEFOREST_HIST_AVX512 1
#include <immintrin.h>
// GCC 12's AVX-512 intrinsics (masked gathers, reductions) start from _mm512_undefined_*() and
// warn about it when inlined here; the value is never read.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

namespace poseforest::engine {

namespace {

/// One unit of parallel work: candidates [k0, k1) of plan `plan`.
struct Item {
  uint32_t plan;
  uint32_t k0, k1;
};

/// Candidates per work item: enough samples x candidates per item to amortize scheduling, and
/// for big nodes up to 64 candidates so that the frames a block of samples touches are reused
/// by many candidates while in cache (measured: 16 -> 64 gives +20% at the root with rendered
/// frames) — but at least 4 items per thread.
uint32_t ChunkFor(uint64_t local_samples, uint32_t candidates, int threads) {
  uint64_t chunk;
  if (local_samples >= 4096) {
    chunk = std::clamp<uint64_t>(candidates / (4 * uint64_t(threads)), 16, 64);
  } else {
    chunk = std::max<uint64_t>(16, 65536 / std::max<uint64_t>(1, local_samples));
  }
  return uint32_t(std::min<uint64_t>(chunk, candidates));
}

/// Bin of response f among `stride` (a power of two) ascending cuts: #cuts < f.
inline int BinOf(int32_t f, const int32_t* cuts, int stride) {
  int pos = 0;
  for (int step = stride >> 1; step > 0; step >>= 1) pos += (f > cuts[pos + step - 1]) ? step : 0;
  // The last slot: stride cuts need one more comparison to reach `stride`.
  pos += (f > cuts[pos]) ? 1 : 0;
  return pos;
}

/// Rethrows the first exception caught inside a parallel region, after it (treelite's
/// OMPException pattern).
class OmpErrors {
 public:
  template <typename F>
  void Run(F&& f) {
    try {
      f();
    } catch (...) {
#pragma omp critical(poseforest_worker_omp_errors)
      if (!error_) error_ = std::current_exception();
    }
  }
  void Rethrow() {
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::exception_ptr error_;
};

/// The shard's arrays the kernels read.
struct KernelInput {
  const SampleSet* set;
  const uint16_t* probe;
  const CompactFrame::Row* rows;
  const uint32_t* frame;
  const int16_t *x, *y;
  const float* scale;
  const uint8_t* part;
  int width, height;  ///< every frame's size (uniform_size())
  uint16_t background_mm;
  bool clamp;  ///< probes beyond the edge read the edge (core::ProbeEdge::kClamp)
};

/// Scalar kernel: counts of candidate f over samples [b, e) (SampleSet::Response, the
/// reference for the vector kernels).
void CountScalar(const KernelInput& in, uint64_t b, uint64_t e, const core::FeatureOffsets& f,
                 const int32_t* cuts, int stride, const uint8_t* slot_of, int slots, uint32_t* counts) {
  for (uint64_t i = b; i < e; ++i) {
    const int32_t r = in.set->Response(i, f, in.background_mm);
    ++counts[BinOf(r, cuts, stride) * slots + slot_of[in.part[i]]];
  }
}

#if POSEFOREST_HIST_AVX512
/// Probe values of 16 lanes at (px, py) of the frames whose rows start at `row0` (frame *
/// height in rows()): exactly SampleSet::Probe per lane. A lane off the frame's rows reads
/// background_mm; else its row (one 64-bit gather per 8 lanes: start | lo << 32 | len << 48),
/// then the pixel if px lies in the row's span, else background_mm. Lanes outside `valid`
/// read nothing. With in.clamp, (px, py) are first clamped into the frame.
inline __m512i Probe16(const KernelInput& in, __mmask16 valid, __m512i row0, __m512i px, __m512i py) {
  if (in.clamp) {
    const __m512i zero = _mm512_setzero_si512();
    px = _mm512_max_epi32(zero, _mm512_min_epi32(px, _mm512_set1_epi32(in.width - 1)));
    py = _mm512_max_epi32(zero, _mm512_min_epi32(py, _mm512_set1_epi32(in.height - 1)));
  }
  const __m512i low16 = _mm512_set1_epi32(0xFFFF);
  const __m512i even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
  const __m512i odd = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
  const __mmask16 in_y = valid & _mm512_cmplt_epu32_mask(py, _mm512_set1_epi32(in.height));
  const __m512i r = _mm512_add_epi32(row0, py);
  const __m512i zero = _mm512_setzero_si512();
  const __m512i g0 = _mm512_mask_i32gather_epi64(zero, __mmask8(in_y), _mm512_castsi512_si256(r), in.rows, 8);
  const __m512i g1 =
      _mm512_mask_i32gather_epi64(zero, __mmask8(in_y >> 8), _mm512_extracti64x4_epi64(r, 1), in.rows, 8);
  const __m512i start = _mm512_permutex2var_epi32(g0, even, g1);
  const __m512i span = _mm512_permutex2var_epi32(g0, odd, g1);  // lo | len << 16
  const __m512i rel = _mm512_sub_epi32(px, _mm512_and_si512(span, low16));
  const __mmask16 in_x = in_y & _mm512_cmplt_epu32_mask(rel, _mm512_srli_epi32(span, 16));
  const __m512i bg = _mm512_set1_epi32(in.background_mm);
  return _mm512_and_si512(_mm512_mask_i32gather_epi32(bg, in_x, _mm512_add_epi32(start, rel), in.probe, 2),
                          low16);
}

/// Responses of 16 samples starting at i (lanes beyond `valid` are garbage, never read from
/// memory out of bounds). Exactly SampleSet::Response per lane: float(offset) * scale,
/// + 32768.5f, truncate, - 32768 (no FMA), probe.
inline __m512i Responses16(const KernelInput& in, uint64_t i, __mmask16 valid, __m512 fux, __m512 fuy,
                           __m512 fvx, __m512 fvy) {
  const __m512i x = _mm512_cvtepi16_epi32(_mm256_maskz_loadu_epi16(valid, in.x + i));
  const __m512i y = _mm512_cvtepi16_epi32(_mm256_maskz_loadu_epi16(valid, in.y + i));
  const __m512 s = _mm512_maskz_loadu_ps(valid, in.scale + i);
  const __m512i row0 =
      _mm512_mullo_epi32(_mm512_maskz_loadu_epi32(valid, in.frame + i), _mm512_set1_epi32(in.height));
  const __m512 half = _mm512_set1_ps(32768.5f);
  const __m512i bias = _mm512_set1_epi32(32768);
  auto round_off = [&](__m512 fo) {
    return _mm512_sub_epi32(_mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(fo, s), half)), bias);
  };
  const __m512i ux = _mm512_add_epi32(x, round_off(fux)), uy = _mm512_add_epi32(y, round_off(fuy));
  const __m512i vx = _mm512_add_epi32(x, round_off(fvx)), vy = _mm512_add_epi32(y, round_off(fvy));
  return _mm512_sub_epi32(Probe16(in, valid, row0, ux, uy), Probe16(in, valid, row0, vx, vy));
}

/// Vector kernel: 16 samples at a time; bins by a 7-step branch-free binary search over 64
/// cuts held in 4 registers (permutes, no memory); counts with scalar increments.
void CountAvx512(const KernelInput& in, uint64_t b, uint64_t e, const core::FeatureOffsets& f,
                 const int32_t* cuts, int stride, const int32_t* slot_table32, int slots, uint32_t* counts) {
  alignas(64) int32_t c64[64];
  for (int j = 0; j < 64; ++j) c64[j] = j < stride ? cuts[j] : kNoCut;
  const __m512i c0 = _mm512_load_si512(c64), c1 = _mm512_load_si512(c64 + 16),
                c2 = _mm512_load_si512(c64 + 32), c3 = _mm512_load_si512(c64 + 48);
  const __m512i st_lo = _mm512_loadu_si512(slot_table32), st_hi = _mm512_loadu_si512(slot_table32 + 16);
  const __m512 fux = _mm512_set1_ps(float(f.ux)), fuy = _mm512_set1_ps(float(f.uy)),
               fvx = _mm512_set1_ps(float(f.vx)), fvy = _mm512_set1_ps(float(f.vy));
  const __m512i vslots = _mm512_set1_epi32(slots), k32 = _mm512_set1_epi32(32);
  const bool wide = stride > 32;
  alignas(64) int32_t idx[16];
  for (uint64_t i = b; i < e; i += 16) {
    const __mmask16 valid = e - i >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (e - i)) - 1);
    const __m512i r = Responses16(in, i, valid, fux, fuy, fvx, fvy);
    __m512i pos = _mm512_setzero_si512();
    for (int step = 32; step > 0; step >>= 1) {
      const __m512i probe_at = _mm512_add_epi32(pos, _mm512_set1_epi32(step - 1));
      __m512i val = _mm512_permutex2var_epi32(c0, probe_at, c1);
      if (wide)
        val = _mm512_mask_blend_epi32(_mm512_test_epi32_mask(probe_at, k32), val,
                                      _mm512_permutex2var_epi32(c2, probe_at, c3));
      pos = _mm512_mask_add_epi32(pos, _mm512_cmpgt_epi32_mask(r, val), pos, _mm512_set1_epi32(step));
    }
    {
      __m512i val = _mm512_permutex2var_epi32(c0, pos, c1);
      if (wide)
        val = _mm512_mask_blend_epi32(_mm512_test_epi32_mask(pos, k32), val,
                                      _mm512_permutex2var_epi32(c2, pos, c3));
      // pos == 64 cannot be reached: the 64th slot is always kNoCut for stride <= 64... unless
      // stride == 64 and every cut is real; then the final compare is against c64[63].
      pos = _mm512_mask_add_epi32(pos, _mm512_cmpgt_epi32_mask(r, val), pos, _mm512_set1_epi32(1));
    }
    const __m512i part = _mm512_cvtepu8_epi32(_mm_maskz_loadu_epi8(valid, in.part + i));
    const __m512i slot = _mm512_permutex2var_epi32(st_lo, part, st_hi);
    _mm512_store_si512(idx, _mm512_add_epi32(_mm512_mullo_epi32(pos, vslots), slot));
    const int n = int(std::min<uint64_t>(16, e - i));
    for (int l = 0; l < n; ++l) ++counts[idx[l]];
  }
}

/// Whether every real cut of `cuts[0, n)` lies in [-32767, 32766], so that the 16-bit kernels
/// may bin: a response saturated to int16 then compares with every such cut as the int32 response
/// does (r > 32767 -> 32767 > c; r < -32768 -> -32768 > c is false as r > c is), and the padding
/// kNoCut becomes 32767, which no saturated response exceeds. Responses are depth differences
/// (|r| <= background_mm in practice), so this holds for any real node; the int32 kernels remain
/// for the rest.
inline bool CutsFit16(const int32_t* cuts, size_t n) {
  // Vectorized (a node's 2000 x 64 cut slots are checked per node: scalar it cost ~10% of a
  // deep level): bad = real cut outside [-32767, 32766].
  const __m512i lo = _mm512_set1_epi32(-32767), hi = _mm512_set1_epi32(32766), none = _mm512_set1_epi32(kNoCut);
  __mmask16 bad = 0;
  size_t j = 0;
  for (; j + 16 <= n; j += 16) {
    const __m512i c = _mm512_loadu_si512(cuts + j);
    bad |= _mm512_cmpneq_epi32_mask(c, none) & (_mm512_cmplt_epi32_mask(c, lo) | _mm512_cmpgt_epi32_mask(c, hi));
  }
  if (bad) return false;
  for (; j < n; ++j)
    if (cuts[j] != kNoCut && (cuts[j] < -32767 || cuts[j] > 32766)) return false;
  return true;
}
inline int16_t Cut16(int32_t c) { return c == kNoCut ? int16_t(32767) : int16_t(c); }

/// 32 int16 lanes from two vectors of 16 int32 responses, saturated, in order.
inline __m512i Pack16(__m512i lo, __m512i hi) {
  return _mm512_inserti64x4(_mm512_castsi256_si512(_mm512_cvtsepi32_epi16(lo)), _mm512_cvtsepi32_epi16(hi), 1);
}

inline __mmask32 Mask32(uint64_t n) { return n >= 32 ? ~__mmask32(0) : __mmask32((uint64_t(1) << n) - 1); }

/// CountAvx512 in 16-bit lanes (cuts that CutsFit16): 32 samples at a time; the 64 cut slots
/// fit in two registers, so each of the 7 binary-search steps is one two-table permute, one
/// compare and one masked add for 32 samples (the int32 kernel needs two permutes, a blend, a
/// test, a compare and an add for 16).
void CountAvx512x16(const KernelInput& in, uint64_t b, uint64_t e, const core::FeatureOffsets& f,
                    const int32_t* cuts, int stride, const int16_t* slot_table16, int slots, uint32_t* counts) {
  alignas(64) int16_t c64[64];
  for (int j = 0; j < 64; ++j) c64[j] = j < stride ? Cut16(cuts[j]) : int16_t(32767);
  const __m512i c_lo = _mm512_load_si512(c64), c_hi = _mm512_load_si512(c64 + 32);
  const __m512i st = _mm512_loadu_si512(slot_table16);
  const __m512 fux = _mm512_set1_ps(float(f.ux)), fuy = _mm512_set1_ps(float(f.uy)),
               fvx = _mm512_set1_ps(float(f.vx)), fvy = _mm512_set1_ps(float(f.vy));
  const __m512i vslots = _mm512_set1_epi16(int16_t(slots));
  alignas(64) uint16_t idx[32];
  for (uint64_t i = b; i < e; i += 32) {
    const uint64_t left = e - i;
    const __mmask16 v0 = left >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << left) - 1);
    const __mmask16 v1 = left >= 32 ? __mmask16(0xFFFF) : left > 16 ? __mmask16((1u << (left - 16)) - 1) : 0;
    const __m512i r0 = Responses16(in, i, v0, fux, fuy, fvx, fvy);
    const __m512i r1 = v1 ? Responses16(in, i + 16, v1, fux, fuy, fvx, fvy) : _mm512_setzero_si512();
    const __m512i r = Pack16(r0, r1);
    __m512i pos = _mm512_setzero_si512();
    for (int step = 32; step > 0; step >>= 1) {
      const __m512i val = _mm512_permutex2var_epi16(c_lo, _mm512_add_epi16(pos, _mm512_set1_epi16(int16_t(step - 1))), c_hi);
      pos = _mm512_mask_add_epi16(pos, _mm512_cmpgt_epi16_mask(r, val), pos, _mm512_set1_epi16(int16_t(step)));
    }
    // pos <= 63 here; the last slot needs one more comparison to reach 64.
    pos = _mm512_mask_add_epi16(pos, _mm512_cmpgt_epi16_mask(r, _mm512_permutex2var_epi16(c_lo, pos, c_hi)), pos,
                                _mm512_set1_epi16(1));
    const __m512i part = _mm512_cvtepu8_epi16(_mm256_maskz_loadu_epi8(Mask32(left), in.part + i));
    const __m512i slot = _mm512_permutexvar_epi16(part, st);
    _mm512_store_si512(idx, _mm512_add_epi16(_mm512_mullo_epi16(pos, vslots), slot));
    const int n = int(std::min<uint64_t>(32, left));
    for (int l = 0; l < n; ++l) ++counts[idx[l]];
  }
}

/// Min/max of the responses of samples [b, e).
void RangeAvx512(const KernelInput& in, uint64_t b, uint64_t e, const core::FeatureOffsets& f,
                 ResponseRange* out) {
  const __m512 fux = _mm512_set1_ps(float(f.ux)), fuy = _mm512_set1_ps(float(f.uy)),
               fvx = _mm512_set1_ps(float(f.vx)), fvy = _mm512_set1_ps(float(f.vy));
  __m512i lo = _mm512_set1_epi32(out->lo), hi = _mm512_set1_epi32(out->hi);
  for (uint64_t i = b; i < e; i += 16) {
    const __mmask16 valid = e - i >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (e - i)) - 1);
    const __m512i r = Responses16(in, i, valid, fux, fuy, fvx, fvy);
    lo = _mm512_mask_min_epi32(lo, valid, lo, r);
    hi = _mm512_mask_max_epi32(hi, valid, hi, r);
  }
  out->lo = _mm512_reduce_min_epi32(lo);
  out->hi = _mm512_reduce_max_epi32(hi);
}

/// Nodes with at most this many samples on the shard use the sample-major kernels: one sample
/// at a time against 16 candidates per vector, so its probes (all within the max offset of
/// one pixel) stay in L1, instead of 16 samples of scattered frames per vector.
constexpr uint64_t kSampleMajorMax = 768;

/// A node's candidates transposed for the sample-major kernels (blocks of 16 and 32 lanes).
struct CandidateSoa {
  int num_candidates = 0, padded = 0, thresholds = 0;
  std::vector<float> ux, uy, vx, vy;  ///< padded entries are 0 (probe the pixel itself)
  /// Cut j of candidate k at [j * padded + k] (padding: kNoCut / 32767), in int16 when every
  /// cut CutsFit16 (cuts16, half the memory and twice the lanes), else in int32 (cuts).
  bool fit16 = false;
  std::vector<int32_t> cuts;
  std::vector<int16_t> cuts16;

  void Set(const std::vector<core::FeatureOffsets>& f, const int32_t* cut_rows, int stride, int t) {
    num_candidates = int(f.size());
    padded = (num_candidates + 31) / 32 * 32;
    thresholds = t;
    ux.assign(size_t(padded), 0.f);
    uy.assign(size_t(padded), 0.f);
    vx.assign(size_t(padded), 0.f);
    vy.assign(size_t(padded), 0.f);
    for (int k = 0; k < num_candidates; ++k) {
      ux[size_t(k)] = float(f[size_t(k)].ux);
      uy[size_t(k)] = float(f[size_t(k)].uy);
      vx[size_t(k)] = float(f[size_t(k)].vx);
      vy[size_t(k)] = float(f[size_t(k)].vy);
    }
    if (!cut_rows) return;
    fit16 = CutsFit16(cut_rows, size_t(num_candidates) * size_t(stride));
    if (fit16) {
      // Transposed 16 candidates at a time: one gather of cut j of 16 candidates, saturated to
      // int16 (= Cut16 here: the real cuts fit and kNoCut = INT32_MAX saturates to 32767;
      // candidates past the end read as kNoCut). A scalar transpose cost ~20% of a deep level.
      cuts16.resize(size_t(t) * size_t(padded));
      const __m512i lane_offset = _mm512_mullo_epi32(
          _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15), _mm512_set1_epi32(stride));
      const __m512i none = _mm512_set1_epi32(kNoCut);
      for (int k0 = 0; k0 < padded; k0 += 16) {
        const int m = std::clamp(num_candidates - k0, 0, 16);
        const __mmask16 valid = m >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << m) - 1);
        const int32_t* base = cut_rows + size_t(std::min(k0, num_candidates > 0 ? num_candidates - 1 : 0)) * size_t(stride);
        for (int j = 0; j < t; ++j) {
          const __m512i c = _mm512_mask_i32gather_epi32(none, valid, lane_offset, base + j, 4);
          _mm256_storeu_si256(reinterpret_cast<__m256i*>(&cuts16[size_t(j) * size_t(padded) + size_t(k0)]),
                             _mm512_cvtsepi32_epi16(c));
        }
      }
    } else {
      cuts.assign(size_t(t) * size_t(padded), kNoCut);
      for (int k = 0; k < num_candidates; ++k)
        for (int j = 0; j < t; ++j)
          cuts[size_t(j) * size_t(padded) + size_t(k)] = cut_rows[size_t(k) * size_t(stride) + size_t(j)];
    }
  }
};

/// Bins of S samples' saturated responses to the same 32 candidates (r[s]: 32 int16 lanes)
/// against the candidates' transposed int16 cuts (col[j * pitch + lane], rows 0..t-1): a linear
/// count. Each cut row is loaded once for the S samples: the node's cuts (t rows x candidates,
/// 200 KB for 2000 x 50) stream from L2 once per S samples instead of once per sample, which
/// bounded the sample-major kernels; the S accumulators are independent dependency chains.
template <int S>
inline void BinsTile(const __m512i* r, const int16_t* col, size_t pitch, int t, __m512i* bins) {
  const __m512i one = _mm512_set1_epi16(1);
  for (int s = 0; s < S; ++s) bins[s] = _mm512_setzero_si512();
  for (int j = 0; j < t; ++j) {
    const __m512i row = _mm512_loadu_si512(col + size_t(j) * pitch);
    for (int s = 0; s < S; ++s) bins[s] = _mm512_mask_add_epi16(bins[s], _mm512_cmpgt_epi16_mask(r[s], row), bins[s], one);
  }
}

/// Samples per tile in the 16-bit sample-major kernels.
constexpr int kTile = 8;

/// Responses of one sample to candidates [k, k+16) (exactly SampleSet::Response per lane).
inline __m512i SampleResponses16(const KernelInput& in, uint64_t i, const CandidateSoa& c, int k) {
  const __m512 s = _mm512_set1_ps(in.scale[i]);
  const __m512i x = _mm512_set1_epi32(in.x[i]), y = _mm512_set1_epi32(in.y[i]);
  const __m512i row0 = _mm512_set1_epi32(int32_t(in.frame[i] * uint32_t(in.height)));
  const __m512 half = _mm512_set1_ps(32768.5f);
  const __m512i bias = _mm512_set1_epi32(32768);
  auto round_off = [&](const float* fo) {
    return _mm512_sub_epi32(
        _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(_mm512_loadu_ps(fo + k), s), half)), bias);
  };
  const __m512i ux = _mm512_add_epi32(x, round_off(c.ux.data())),
                uy = _mm512_add_epi32(y, round_off(c.uy.data()));
  const __m512i vx = _mm512_add_epi32(x, round_off(c.vx.data())),
                vy = _mm512_add_epi32(y, round_off(c.vy.data()));
  const __mmask16 all = 0xFFFF;
  return _mm512_sub_epi32(Probe16(in, all, row0, ux, uy), Probe16(in, all, row0, vx, vy));
}

/// Sample-major histogram kernel for a small node: counts of every candidate over [b, e).
void CountSampleMajorAvx512(const KernelInput& in, uint64_t b, uint64_t e, const CandidateSoa& c,
                            const uint8_t* slot_of, int bins, int slots, uint32_t* counts) {
  alignas(64) int32_t idx[16];
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512i cand_stride = _mm512_set1_epi32(bins * slots), vslots = _mm512_set1_epi32(slots);
  const __m512i one = _mm512_set1_epi32(1);
  if (c.fit16) {
    alignas(64) uint16_t local[32];  // bin * slots + slot per lane
    const size_t cs = size_t(bins) * size_t(slots);
    const __m512i vslots16 = _mm512_set1_epi16(int16_t(slots));
    auto tile = [&]<int S>(uint64_t i) {
      __m512i slot[S], r[S], bin[S];
      for (int s = 0; s < S; ++s) slot[s] = _mm512_set1_epi16(int16_t(slot_of[in.part[i + uint64_t(s)]]));
      for (int k = 0; k < c.num_candidates; k += 32) {
        for (int s = 0; s < S; ++s)
          r[s] = Pack16(SampleResponses16(in, i + uint64_t(s), c, k), SampleResponses16(in, i + uint64_t(s), c, k + 16));
        BinsTile<S>(r, c.cuts16.data() + k, size_t(c.padded), c.thresholds, bin);
        uint32_t* ck = counts + size_t(k) * cs;
        const int n = std::min(32, c.num_candidates - k);
        for (int s = 0; s < S; ++s) {
          _mm512_store_si512(local, _mm512_add_epi16(_mm512_mullo_epi16(bin[s], vslots16), slot[s]));
          for (int l = 0; l < n; ++l) ++ck[size_t(l) * cs + local[l]];
        }
      }
    };
    uint64_t i = b;
    for (; i + kTile <= e; i += kTile) tile.template operator()<kTile>(i);
    for (; i < e; ++i) tile.template operator()<1>(i);
    return;
  }
  for (uint64_t i = b; i < e; ++i) {
    const __m512i slot = _mm512_set1_epi32(slot_of[in.part[i]]);
    for (int k = 0; k < c.num_candidates; k += 16) {
      const __m512i r = SampleResponses16(in, i, c, k);
      // Bin = number of cuts below r: a linear count over the transposed cuts.
      __m512i bin = _mm512_setzero_si512();
      const int32_t* col = c.cuts.data() + k;
      for (int j = 0; j < c.thresholds; ++j)
        bin = _mm512_mask_add_epi32(
            bin, _mm512_cmpgt_epi32_mask(r, _mm512_loadu_si512(col + size_t(j) * size_t(c.padded))), bin,
            one);
      const __m512i cand = _mm512_add_epi32(_mm512_set1_epi32(k), lane);
      _mm512_store_si512(idx, _mm512_add_epi32(_mm512_mullo_epi32(cand, cand_stride),
                                               _mm512_add_epi32(_mm512_mullo_epi32(bin, vslots), slot)));
      const int n = std::min(16, c.num_candidates - k);
      for (int l = 0; l < n; ++l) ++counts[idx[l]];
    }
  }
}

/// Sample-major bins of every candidate over [b, e): row i - b of `rows` (num_candidates bytes).
void BinSampleMajorAvx512(const KernelInput& in, uint64_t b, uint64_t e, const CandidateSoa& c,
                          uint8_t* rows) {
  const __m512i one = _mm512_set1_epi32(1);
  if (c.fit16) {
    auto tile = [&]<int S>(uint64_t i) {
      __m512i r[S], bin[S];
      for (int k = 0; k < c.num_candidates; k += 32) {
        for (int s = 0; s < S; ++s)
          r[s] = Pack16(SampleResponses16(in, i + uint64_t(s), c, k), SampleResponses16(in, i + uint64_t(s), c, k + 16));
        BinsTile<S>(r, c.cuts16.data() + k, size_t(c.padded), c.thresholds, bin);
        for (int s = 0; s < S; ++s)
          _mm256_mask_storeu_epi8(rows + (i + uint64_t(s) - b) * size_t(c.num_candidates) + k,
                                  Mask32(uint64_t(c.num_candidates - k)), _mm512_cvtepi16_epi8(bin[s]));
      }
    };
    uint64_t i = b;
    for (; i + kTile <= e; i += kTile) tile.template operator()<kTile>(i);
    for (; i < e; ++i) tile.template operator()<1>(i);
    return;
  }
  for (uint64_t i = b; i < e; ++i) {
    uint8_t* row = rows + (i - b) * size_t(c.num_candidates);
    for (int k = 0; k < c.num_candidates; k += 16) {
      const __m512i r = SampleResponses16(in, i, c, k);
      __m512i bin = _mm512_setzero_si512();
      const int32_t* col = c.cuts.data() + k;
      for (int j = 0; j < c.thresholds; ++j)
        bin = _mm512_mask_add_epi32(
            bin, _mm512_cmpgt_epi32_mask(r, _mm512_loadu_si512(col + size_t(j) * size_t(c.padded))), bin,
            one);
      const int n = std::min(16, c.num_candidates - k);
      _mm512_mask_cvtepi32_storeu_epi8(row + k, __mmask16((1u << n) - 1), bin);
    }
  }
}

/// Sample-major min/max of every candidate over samples [b, e), or over index[b..e) when
/// `index` is given (a node's reference subsample): one sample at a time against all
/// candidates (its probes stay in L1), running minima/maxima in `out`.
void RangeSampleMajorAvx512(const KernelInput& in, uint64_t b, uint64_t e, const uint32_t* index,
                            const CandidateSoa& c, ResponseRange* out) {
  std::vector<int32_t> lo(size_t(c.padded), INT32_MAX), hi(size_t(c.padded), INT32_MIN);
  for (uint64_t j = b; j < e; ++j) {
    const uint64_t i = index ? index[j] : j;
    for (int k = 0; k < c.num_candidates; k += 16) {
      const __m512i r = SampleResponses16(in, i, c, k);
      _mm512_storeu_si512(lo.data() + k, _mm512_min_epi32(_mm512_loadu_si512(lo.data() + k), r));
      _mm512_storeu_si512(hi.data() + k, _mm512_max_epi32(_mm512_loadu_si512(hi.data() + k), r));
    }
  }
  for (int k = 0; k < c.num_candidates; ++k) {
    out[k].lo = lo[size_t(k)];
    out[k].hi = hi[size_t(k)];
  }
}
#endif

/// Whether a node range is processed by the sample-major kernels.
bool SampleMajor([[maybe_unused]] bool whole, [[maybe_unused]] uint64_t n,
                 [[maybe_unused]] const SampleSet& s) {
#if POSEFOREST_HIST_AVX512
  return whole && n <= kSampleMajorMax && s.uniform_size();
#else
  return false;
#endif
}

KernelInput InputOf(const SampleSet& s, uint16_t background_mm) {
  KernelInput in{&s,    s.probe(), s.rows(),      s.frame(),
                 s.x(), s.y(),     s.scale(),     s.part(),
                 0,     0,         background_mm, s.edge() == core::ProbeEdge::kClamp};
  if (!s.frames().empty()) {
    in.width = s.frames()[0].width;
    in.height = s.frames()[0].height;
  }
  return in;
}

}  // namespace

}  // namespace poseforest::engine
