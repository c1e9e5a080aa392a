#include "runtime/classifier_kernels.h"

// The kernels' design: classifier.cpp ("How the classifier is fast").

#include <algorithm>
#include <bit>
#include <cstring>

#if defined(POSEFOREST_CLASSIFIER_AVX512) || defined(POSEFOREST_CLASSIFIER_AVX2)
#include <immintrin.h>
#endif

namespace poseforest::runtime::detail {

using core::Node;

// ---- Portable kernel ------------------------------------------------------------------------

/// Walks one tree for the first `end` pixels of `f` with kLanes traversals interleaved;
/// writes pixel i's leaf index to out[i]. The root must be a split node.
/// Lane state is kept as structure of arrays so that the probe arithmetic of all lanes (the
/// float part of eq. 1) is one loop the compiler vectorizes; the memory part (probe reads,
/// next node) is a scalar loop with branch-free child selection.
template <int kLanes, bool kClamp>
void TraversePortable(const Node* nodes, const FrameView& f, int end, uint32_t* out) {
  float ux[kLanes], uy[kLanes], vx[kLanes], vy[kLanes], thr[kLanes], scale[kLanes];
  int32_t xb[kLanes], yb[kLanes];
  uint32_t child[kLanes], iu[kLanes], iv[kLanes];
  int slot[kLanes];
  bool live[kLanes];
  const unsigned w = unsigned(f.width), h = unsigned(f.height), off_image = w * h;

  auto load_node = [&](int l, const Node& n) {
    ux[l] = float(n.offsets.ux);
    uy[l] = float(n.offsets.uy);
    vx[l] = float(n.offsets.vx);
    vy[l] = float(n.offsets.vy);
    thr[l] = n.threshold;
    child[l] = n.child;
  };
  int next = 0, active = 0;
  for (int l = 0; l < kLanes; ++l) {
    // Lanes without a pixel idle on pixel 0 (stale but valid data: the arithmetic stays safe).
    live[l] = next < end;
    slot[l] = live[l] ? next++ : 0;
    active += live[l];
    xb[l] = f.xb[slot[l]];
    yb[l] = f.yb[slot[l]];
    scale[l] = f.scale[slot[l]];
    load_node(l, nodes[0]);
  }
  while (active > 0) {
    // Probe indices of every lane; off the image they read probe[w * h], a padding entry that
    // holds the background depth, so the loads below need no branch.
    for (int l = 0; l < kLanes; ++l) {
      const float s = scale[l];
      unsigned px = unsigned(xb[l] + int(ux[l] * s + 32768.5f));
      unsigned py = unsigned(yb[l] + int(uy[l] * s + 32768.5f));
      unsigned qx = unsigned(xb[l] + int(vx[l] * s + 32768.5f));
      unsigned qy = unsigned(yb[l] + int(vy[l] * s + 32768.5f));
      if constexpr (kClamp) {  // onto the edge: then every probe lies in the image
        px = unsigned(std::clamp(int(px), 0, int(w) - 1)), py = unsigned(std::clamp(int(py), 0, int(h) - 1));
        qx = unsigned(std::clamp(int(qx), 0, int(w) - 1)), qy = unsigned(std::clamp(int(qy), 0, int(h) - 1));
      }
      iu[l] = (px < w && py < h) ? py * w + px : off_image;
      iv[l] = (qx < w && qy < h) ? qy * w + qx : off_image;
    }
    for (int l = 0; l < kLanes; ++l) {
      if (!live[l]) continue;
      const int32_t response = int32_t(f.probe[iu[l]]) - int32_t(f.probe[iv[l]]);
      // Left if f < threshold, else right (child + 1): "not less" also sends NaN right, as
      // the scalar comparison does.
      const Node& n = nodes[child[l] + uint32_t(!(float(response) < thr[l]))];
      if (!n.is_leaf()) [[likely]] {
        load_node(l, n);
        continue;
      }
      out[slot[l]] = n.leaf_index();
      if (next < end) {
        slot[l] = next;
        xb[l] = f.xb[next];
        yb[l] = f.yb[next];
        scale[l] = f.scale[next];
        ++next;
        load_node(l, nodes[0]);
      } else {
        live[l] = false;
        --active;
      }
    }
  }
}

/// Sums leaf rows over trees and takes the argmax for `count` foreground pixels whose leaf
/// in tree t is leaves[t * leaves_stride + i] and whose linear index is pixel[i]. The sums
/// also go to fg_sums[i * stride...] unless it is null (the compact foreground output).
void CombinePortable(const core::Forest& forest, const uint32_t* leaves, size_t leaves_stride,
                     const uint32_t* pixel, int count, uint16_t* fg_sums, Classification* out) {
  const int stride = forest.leaf_stride();
  const int parts = forest.num_parts;
  const int trees = int(forest.trees.size());
  const bool want = !out->sums.empty();
  uint16_t acc[256];
  for (int i = 0; i < count; ++i) {
    std::fill(acc, acc + stride, uint16_t(0));
    for (int t = 0; t < trees; ++t) {
      const uint8_t* row =
          forest.trees[size_t(t)].leaf(leaves[size_t(t) * leaves_stride + size_t(i)], stride);
      for (int c = 0; c < stride; ++c) acc[c] = uint16_t(acc[c] + row[c]);
    }
    int best = 0;
    for (int c = 1; c < parts; ++c)
      if (acc[c] > acc[best]) best = c;
    const uint32_t p = pixel[i];
    out->labels.pixels[p] = uint8_t(best);
    if (want)
      std::memcpy(out->sums.data() + size_t(p) * size_t(stride), acc, size_t(stride) * sizeof(uint16_t));
    if (fg_sums != nullptr)
      std::memcpy(fg_sums + size_t(i) * size_t(stride), acc, size_t(stride) * sizeof(uint16_t));
  }
}

// ---- AVX-512 kernel -------------------------------------------------------------------------

#ifdef POSEFOREST_CLASSIFIER_AVX512
// GCC 12's shift/convert intrinsics start from _mm512_undefined_*(), which its -Wuninitialized
// wrongly reports when inlined (GCC bug 105593, fixed in 12.3/13).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

/// TraversePortable (end <= kChunk) with kGroups vectors of 16 lanes interleaved.
template <int kGroups, bool kClamp>
void TraverseAvx512(const Node* nodes, const FrameView& f, int end, uint32_t* out) {
  const auto* nb = reinterpret_cast<const char*>(nodes);
  const auto* pb = reinterpret_cast<const char*>(f.probe);
  const __m512i vwidth = _mm512_set1_epi32(f.width), vheight = _mm512_set1_epi32(f.height);
  const __m512i vbg = _mm512_set1_epi32(f.background_mm), low16 = _mm512_set1_epi32(0xFFFF);
  const __m512i one = _mm512_set1_epi32(1);
  const __m512i iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512 bias = _mm512_set1_ps(32768.5f);
  int32_t root_words[4];
  std::memcpy(root_words, &nodes[0], sizeof(root_words));
  const __m512i r_w0 = _mm512_set1_epi32(root_words[0]), r_w1 = _mm512_set1_epi32(root_words[1]);
  const __m512i r_thr = _mm512_set1_epi32(root_words[2]), r_child = _mm512_set1_epi32(root_words[3]);

  // (slot, leaf) pairs of finished lanes, written with register compress + full stores (a
  // compress straight to memory is slow on AMD), scattered to `out` at the end.
  alignas(64) uint32_t done_slot[kChunk + 16], done_leaf[kChunk + 16];
  int num_done = 0;

  // Lane state: the current node's words (offsets u, offsets v, threshold, child), the
  // pixel's biased coordinates, scale and slot. Inactive lanes hold stale values.
  __m512i w0[kGroups], w1[kGroups], thr[kGroups], child[kGroups], xb[kGroups], yb[kGroups], slot[kGroups];
  __m512 scale[kGroups];
  __mmask16 act[kGroups];
  for (int g = 0; g < kGroups; ++g) {
    w0[g] = w1[g] = thr[g] = child[g] = xb[g] = yb[g] = slot[g] = _mm512_setzero_si512();
    scale[g] = _mm512_setzero_ps();
    act[g] = 0;
  }
  int next = 0;
  for (;;) {
    __mmask16 any = 0;
    // Fully unrolled, so that each group's state lives in registers.
#pragma GCC unroll 8
    for (int g = 0; g < kGroups; ++g) {
      // Lanes at a leaf: record, then refill them (and idle lanes) with the next pixels, which
      // start at the root (loaded from registers, not memory).
      const __mmask16 done = act[g] & _mm512_movepi32_mask(child[g]);
      _mm512_storeu_si512(done_slot + num_done, _mm512_maskz_compress_epi32(done, slot[g]));
      _mm512_storeu_si512(
          done_leaf + num_done,
          _mm512_maskz_compress_epi32(done, _mm512_and_si512(child[g], _mm512_set1_epi32(0x7FFFFFFF))));
      num_done += std::popcount(unsigned(done));
      const unsigned free_lanes = unsigned(__mmask16(~act[g] | done));
      const int avail = end - next;
      const unsigned fill = avail >= 16 ? free_lanes : _pdep_u32((1u << avail) - 1u, free_lanes);
      const __mmask16 k = __mmask16(fill);
      xb[g] = _mm512_mask_expand_epi32(xb[g], k, _mm512_loadu_si512(f.xb + next));
      yb[g] = _mm512_mask_expand_epi32(yb[g], k, _mm512_loadu_si512(f.yb + next));
      scale[g] = _mm512_mask_expand_ps(scale[g], k, _mm512_loadu_ps(f.scale + next));
      slot[g] = _mm512_mask_expand_epi32(slot[g], k, _mm512_add_epi32(_mm512_set1_epi32(next), iota));
      w0[g] = _mm512_mask_mov_epi32(w0[g], k, r_w0);
      w1[g] = _mm512_mask_mov_epi32(w1[g], k, r_w1);
      thr[g] = _mm512_mask_mov_epi32(thr[g], k, r_thr);
      child[g] = _mm512_mask_mov_epi32(child[g], k, r_child);
      next += std::popcount(fill);
      act[g] = __mmask16((act[g] & ~done) | k);
      const __mmask16 a = act[g];
      any |= a;

      // Eq. 1 for all lanes (idle ones compute garbage that no memory access sees).
      const __m512i ux = _mm512_srai_epi32(_mm512_slli_epi32(w0[g], 16), 16);
      const __m512i uy = _mm512_srai_epi32(w0[g], 16);
      const __m512i vx = _mm512_srai_epi32(_mm512_slli_epi32(w1[g], 16), 16);
      const __m512i vy = _mm512_srai_epi32(w1[g], 16);
      const __m512 s = scale[g];
      __m512i pux = _mm512_add_epi32(
          xb[g], _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(ux), s), bias)));
      __m512i puy = _mm512_add_epi32(
          yb[g], _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(uy), s), bias)));
      __m512i pvx = _mm512_add_epi32(
          xb[g], _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(vx), s), bias)));
      __m512i pvy = _mm512_add_epi32(
          yb[g], _mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(vy), s), bias)));
      if constexpr (kClamp) {  // onto the edge: then every probe lies in the image
        const __m512i zero = _mm512_setzero_si512(), wm = _mm512_sub_epi32(vwidth, one),
                      hm = _mm512_sub_epi32(vheight, one);
        pux = _mm512_max_epi32(zero, _mm512_min_epi32(pux, wm));
        puy = _mm512_max_epi32(zero, _mm512_min_epi32(puy, hm));
        pvx = _mm512_max_epi32(zero, _mm512_min_epi32(pvx, wm));
        pvy = _mm512_max_epi32(zero, _mm512_min_epi32(pvy, hm));
      }
      const __mmask16 in_u =
          _mm512_mask_cmplt_epu32_mask(_mm512_cmplt_epu32_mask(pux, vwidth) & a, puy, vheight);
      const __mmask16 in_v =
          _mm512_mask_cmplt_epu32_mask(_mm512_cmplt_epu32_mask(pvx, vwidth) & a, pvy, vheight);
      const __m512i iu = _mm512_add_epi32(_mm512_mullo_epi32(puy, vwidth), pux);
      const __m512i iv = _mm512_add_epi32(_mm512_mullo_epi32(pvy, vwidth), pvx);
      const __m512i du = _mm512_and_si512(_mm512_mask_i32gather_epi32(vbg, in_u, iu, pb, 2), low16);
      const __m512i dv = _mm512_and_si512(_mm512_mask_i32gather_epi32(vbg, in_v, iv, pb, 2), low16);
      const __m512 resp = _mm512_cvtepi32_ps(_mm512_sub_epi32(du, dv));
      const __mmask16 right = _mm512_mask_cmp_ps_mask(a, resp, _mm512_castsi512_ps(thr[g]), _CMP_NLT_UQ);
      // Next nodes: 16 plain 16-byte loads and a 4x4 transpose per 128-bit lane, measured
      // 1.5x faster overall than four 16-lane gathers (one per node word) on this Zen.
      // Register q, 128-bit lane j gets the node of lane 4j + q, which the transpose puts
      // back at lane 4j + q of each field vector. Idle lanes load the root (index 0).
      alignas(64) uint32_t ix[16];  // byte offsets of the next nodes
      _mm512_store_si512(
          ix, _mm512_slli_epi32(
                  _mm512_maskz_mov_epi32(a, _mm512_mask_add_epi32(child[g], right, child[g], one)), 4));
      // Keeps the compiler from turning the 16 reloads into vector extracts, which compete
      // with the inserts below for the shuffle unit.
      asm volatile("" : : "m"(ix) : "memory");
      auto node_at = [&](int lane) {
        return _mm_load_si128(reinterpret_cast<const __m128i*>(nb + ix[lane]));
      };
      __m512i v[4];
#pragma GCC unroll 4
      for (int q = 0; q < 4; ++q) {
        __m512i z = _mm512_castsi128_si512(node_at(q));
        z = _mm512_inserti32x4(z, node_at(4 + q), 1);
        z = _mm512_inserti32x4(z, node_at(8 + q), 2);
        v[q] = _mm512_inserti32x4(z, node_at(12 + q), 3);
      }
      const __m512i t0 = _mm512_unpacklo_epi32(v[0], v[1]), t1 = _mm512_unpackhi_epi32(v[0], v[1]);
      const __m512i t2 = _mm512_unpacklo_epi32(v[2], v[3]), t3 = _mm512_unpackhi_epi32(v[2], v[3]);
      w0[g] = _mm512_unpacklo_epi64(t0, t2);
      w1[g] = _mm512_unpackhi_epi64(t0, t2);
      thr[g] = _mm512_unpacklo_epi64(t1, t3);
      child[g] = _mm512_unpackhi_epi64(t1, t3);
    }
    if (any == 0) break;
  }
  for (int i = 0; i < num_done; ++i) out[done_slot[i]] = done_leaf[i];
}
/// CombinePortable for 16 < stride <= 32 (the 31-part taxonomy), AVX-512BW.
void CombineAvx512Stride32(const core::Forest& forest, const uint32_t* leaves, size_t leaves_stride,
                           const uint32_t* pixel, int count, uint16_t* fg_sums, Classification* out) {
  const int trees = int(forest.trees.size());
  const bool want = !out->sums.empty();
  // Only parts < num_parts compete (the padding is zero and the sum over parts is 255 * trees,
  // so it could never win anyway; masked for clarity).
  const __mmask32 part_mask =
      forest.num_parts >= 32 ? ~__mmask32(0) : __mmask32((1u << forest.num_parts) - 1u);
  for (int i = 0; i < count; ++i) {
    __m512i acc = _mm512_setzero_si512();
    for (int t = 0; t < trees; ++t) {
      const uint8_t* row = forest.trees[size_t(t)].leaf(leaves[size_t(t) * leaves_stride + size_t(i)], 32);
      acc = _mm512_add_epi16(acc,
                             _mm512_cvtepu8_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(row))));
    }
    const __m512i cand = _mm512_maskz_mov_epi16(part_mask, acc);
    __m256i m = _mm256_max_epu16(_mm512_castsi512_si256(cand), _mm512_extracti64x4_epi64(cand, 1));
    __m128i m8 = _mm_max_epu16(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
    // minpos on the complement finds the maximum.
    const int maxv = 0xFFFF - _mm_extract_epi16(_mm_minpos_epu16(_mm_xor_si128(m8, _mm_set1_epi16(-1))), 0);
    const __mmask32 eq = _mm512_mask_cmpeq_epi16_mask(part_mask, cand, _mm512_set1_epi16(short(maxv)));
    const uint32_t p = pixel[i];
    out->labels.pixels[p] = uint8_t(std::countr_zero(unsigned(eq)));
    if (want) _mm512_storeu_si512(out->sums.data() + size_t(p) * 32u, acc);
    if (fg_sums != nullptr) _mm512_storeu_si512(fg_sums + size_t(i) * 32u, acc);
  }
}

#pragma GCC diagnostic pop
#endif  // POSEFOREST_CLASSIFIER_AVX512

// ---- AVX2 kernel ----------------------------------------------------------------------------

#ifdef POSEFOREST_CLASSIFIER_AVX2
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

namespace {

/// For each 8-bit lane mask m: the permutation that moves elements 0, 1, 2... to the set
/// lanes of m in order (AVX2 has no vpexpandd).
struct ExpandTable {
  alignas(32) uint32_t index[256][8];
  constexpr ExpandTable() : index{} {
    for (int m = 0; m < 256; ++m) {
      int k = 0;
      for (int lane = 0; lane < 8; ++lane) index[m][lane] = (m >> lane) & 1 ? uint32_t(k++) : 0u;
    }
  }
};
constexpr ExpandTable kExpand;

/// The lanes of `m` as a vector mask (all ones / zero per 32-bit lane).
inline __m256i LaneMask(unsigned m) {
  const __m256i bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  return _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(m)), bits), bits);
}

/// x < bound as unsigned, for bound <= INT32_MAX: min(x, bound - 1) == x.
inline __m256i LessU32(__m256i x, __m256i bound_minus_1) {
  return _mm256_cmpeq_epi32(_mm256_min_epu32(x, bound_minus_1), x);
}

}  // namespace

/// TraverseAvx512 for AVX2 machines: kGroups vectors of 8 lanes, refill through a
/// permutation table instead of expand, finished lanes recorded by a scalar loop.
template <int kGroups, bool kClamp>
void TraverseAvx2(const Node* nodes, const FrameView& f, int end, uint32_t* out) {
  const auto* nb = reinterpret_cast<const char*>(nodes);
  const auto* pb = reinterpret_cast<const int*>(f.probe);
  const __m256i vwidth = _mm256_set1_epi32(f.width);
  const __m256i wm1 = _mm256_set1_epi32(f.width - 1), hm1 = _mm256_set1_epi32(f.height - 1);
  const __m256i vbg = _mm256_set1_epi32(f.background_mm), low16 = _mm256_set1_epi32(0xFFFF);
  const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256 bias = _mm256_set1_ps(32768.5f);
  int32_t root_words[4];
  std::memcpy(root_words, &nodes[0], sizeof(root_words));
  const __m256i r_w0 = _mm256_set1_epi32(root_words[0]), r_w1 = _mm256_set1_epi32(root_words[1]);
  const __m256i r_thr = _mm256_set1_epi32(root_words[2]), r_child = _mm256_set1_epi32(root_words[3]);

  __m256i w0[kGroups], w1[kGroups], thr[kGroups], child[kGroups], xb[kGroups], yb[kGroups], slot[kGroups];
  __m256 scale[kGroups];
  unsigned act[kGroups];
  for (int g = 0; g < kGroups; ++g) {
    w0[g] = w1[g] = thr[g] = child[g] = xb[g] = yb[g] = slot[g] = _mm256_setzero_si256();
    scale[g] = _mm256_setzero_ps();
    act[g] = 0;
  }
  int next = 0;
  for (;;) {
    unsigned any = 0;
#pragma GCC unroll 8
    for (int g = 0; g < kGroups; ++g) {
      const unsigned done = act[g] & unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(child[g])));
      if (done != 0) {
        alignas(32) uint32_t slots[8], leaves[8];
        _mm256_store_si256(reinterpret_cast<__m256i*>(slots), slot[g]);
        _mm256_store_si256(reinterpret_cast<__m256i*>(leaves), child[g]);
        for (unsigned m = done; m != 0; m &= m - 1) {
          const int lane = std::countr_zero(m);
          out[slots[lane]] = leaves[lane] & ~core::kLeafBit;
        }
      }
      const unsigned free_lanes = (~act[g] | done) & 0xFFu;
      const int avail = end - next;
      const unsigned fill = avail >= 8 ? free_lanes : _pdep_u32((1u << avail) - 1u, free_lanes);
      const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kExpand.index[fill]));
      const __m256i k = LaneMask(fill);
      auto expand = [&](__m256i old, __m256i packed) {
        return _mm256_blendv_epi8(old, _mm256_permutevar8x32_epi32(packed, perm), k);
      };
      xb[g] = expand(xb[g], _mm256_loadu_si256(reinterpret_cast<const __m256i*>(f.xb + next)));
      yb[g] = expand(yb[g], _mm256_loadu_si256(reinterpret_cast<const __m256i*>(f.yb + next)));
      scale[g] =
          _mm256_castsi256_ps(expand(_mm256_castps_si256(scale[g]),
                                     _mm256_loadu_si256(reinterpret_cast<const __m256i*>(f.scale + next))));
      slot[g] = expand(slot[g], _mm256_add_epi32(_mm256_set1_epi32(next), iota));
      w0[g] = _mm256_blendv_epi8(w0[g], r_w0, k);
      w1[g] = _mm256_blendv_epi8(w1[g], r_w1, k);
      thr[g] = _mm256_blendv_epi8(thr[g], r_thr, k);
      child[g] = _mm256_blendv_epi8(child[g], r_child, k);
      next += std::popcount(fill);
      act[g] = (act[g] & ~done) | fill;
      any |= act[g];
      const __m256i a = LaneMask(act[g]);

      const __m256i ux = _mm256_srai_epi32(_mm256_slli_epi32(w0[g], 16), 16);
      const __m256i uy = _mm256_srai_epi32(w0[g], 16);
      const __m256i vx = _mm256_srai_epi32(_mm256_slli_epi32(w1[g], 16), 16);
      const __m256i vy = _mm256_srai_epi32(w1[g], 16);
      const __m256 s = scale[g];
      auto probe = [&](__m256i base, __m256i offset) {
        return _mm256_add_epi32(
            base, _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(offset), s), bias)));
      };
      __m256i pux = probe(xb[g], ux), puy = probe(yb[g], uy);
      __m256i pvx = probe(xb[g], vx), pvy = probe(yb[g], vy);
      if constexpr (kClamp) {  // onto the edge: then every probe lies in the image
        const __m256i zero = _mm256_setzero_si256(), wm = _mm256_set1_epi32(f.width - 1),
                      hm = _mm256_set1_epi32(f.height - 1);
        pux = _mm256_max_epi32(zero, _mm256_min_epi32(pux, wm));
        puy = _mm256_max_epi32(zero, _mm256_min_epi32(puy, hm));
        pvx = _mm256_max_epi32(zero, _mm256_min_epi32(pvx, wm));
        pvy = _mm256_max_epi32(zero, _mm256_min_epi32(pvy, hm));
      }
      const __m256i in_u = _mm256_and_si256(_mm256_and_si256(LessU32(pux, wm1), LessU32(puy, hm1)), a);
      const __m256i in_v = _mm256_and_si256(_mm256_and_si256(LessU32(pvx, wm1), LessU32(pvy, hm1)), a);
      const __m256i iu = _mm256_add_epi32(_mm256_mullo_epi32(puy, vwidth), pux);
      const __m256i iv = _mm256_add_epi32(_mm256_mullo_epi32(pvy, vwidth), pvx);
      const __m256i du = _mm256_and_si256(_mm256_mask_i32gather_epi32(vbg, pb, iu, in_u, 2), low16);
      const __m256i dv = _mm256_and_si256(_mm256_mask_i32gather_epi32(vbg, pb, iv, in_v, 2), low16);
      const __m256 resp = _mm256_cvtepi32_ps(_mm256_sub_epi32(du, dv));
      // right: all ones where !(f < threshold) (NaN goes right), and child - (-1) = child + 1.
      const __m256i right =
          _mm256_castps_si256(_mm256_cmp_ps(resp, _mm256_castsi256_ps(thr[g]), _CMP_NLT_UQ));
      alignas(32) uint32_t ix[8];  // byte offsets of the next nodes; idle lanes load the root
      _mm256_store_si256(reinterpret_cast<__m256i*>(ix),
                         _mm256_slli_epi32(_mm256_and_si256(_mm256_sub_epi32(child[g], right), a), 4));
      asm volatile("" : : "m"(ix) : "memory");
      auto node_at = [&](int lane) {
        return _mm_load_si128(reinterpret_cast<const __m128i*>(nb + ix[lane]));
      };
      __m256i v[4];
#pragma GCC unroll 4
      for (int q = 0; q < 4; ++q)
        v[q] = _mm256_inserti128_si256(_mm256_castsi128_si256(node_at(q)), node_at(4 + q), 1);
      const __m256i t0 = _mm256_unpacklo_epi32(v[0], v[1]), t1 = _mm256_unpackhi_epi32(v[0], v[1]);
      const __m256i t2 = _mm256_unpacklo_epi32(v[2], v[3]), t3 = _mm256_unpackhi_epi32(v[2], v[3]);
      w0[g] = _mm256_unpacklo_epi64(t0, t2);
      w1[g] = _mm256_unpackhi_epi64(t0, t2);
      thr[g] = _mm256_unpacklo_epi64(t1, t3);
      child[g] = _mm256_unpackhi_epi64(t1, t3);
    }
    if (any == 0) break;
  }
}

#pragma GCC diagnostic pop
#endif  // POSEFOREST_CLASSIFIER_AVX2

template void TraversePortable<kPortableLanes, false>(const Node* nodes, const FrameView& f, int end,
                                                      uint32_t* out);
template void TraversePortable<kPortableLanes, true>(const Node* nodes, const FrameView& f, int end,
                                                     uint32_t* out);
#ifdef POSEFOREST_CLASSIFIER_AVX512
template void TraverseAvx512<kAvx512Groups, false>(const Node* nodes, const FrameView& f, int end,
                                                   uint32_t* out);
template void TraverseAvx512<kAvx512Groups, true>(const Node* nodes, const FrameView& f, int end,
                                                  uint32_t* out);
#endif
#ifdef POSEFOREST_CLASSIFIER_AVX2
template void TraverseAvx2<kAvx2Groups, false>(const Node* nodes, const FrameView& f, int end, uint32_t* out);
template void TraverseAvx2<kAvx2Groups, true>(const Node* nodes, const FrameView& f, int end, uint32_t* out);
#endif

}  // namespace poseforest::runtime::detail
