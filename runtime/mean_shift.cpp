#include "runtime/mean_shift.h"

#include <algorithm>
#include <bit>
#include <cmath>

#if defined(__AVX2__) || defined(__AVX512F__)
#include <immintrin.h>
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#endif

namespace poseforest::runtime {
namespace detail {
namespace {

/// exp(a) for a <= 0 (a below about -87 gives 0-ish garbage-free small values; callers mask
/// beyond the cut-off anyway): 2^n * 2^f with |f| <= 0.5 and a degree-6 polynomial for 2^f.
/// Relative error ~2e-7. Branch-free so that `omp simd` loops vectorize it.
inline float ExpNonPositive(float a) {
  const float t = std::max(a * 1.44269504f, -120.0f);
  const int n = int(t - 0.5f);  // truncation towards 0 of a negative number: round(t), |t - n| <= 0.5
  const float f = t - float(n);
  float p = 1.5403530e-4f;
  p = p * f + 1.3333558e-3f;
  p = p * f + 9.6181291e-3f;
  p = p * f + 5.5504109e-2f;
  p = p * f + 2.4022651e-1f;
  p = p * f + 6.9314718e-1f;
  p = p * f + 1.0f;
  return p * std::bit_cast<float>(uint32_t(n + 127) << 23);
}

// KernelSums (declared in mean_shift.h; the joint votes use it too): vector kernels for AVX-512,
// AVX2 and 64-bit ARM (NEON), scalar otherwise; they differ only in the order of the float sums
// (NEON's is AVX-512's).
#if defined(__AVX512F__)
// GCC 12's AVX-512 intrinsics start from _mm512_undefined_*(), which its -Wmaybe-uninitialized
// wrongly reports when inlined (GCC bug 105593, fixed in 12.3/13), as in classifier.cpp.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
inline __m512 ExpNonPositive(__m512 a) {
  const __m512 t = _mm512_max_ps(_mm512_mul_ps(a, _mm512_set1_ps(1.44269504f)), _mm512_set1_ps(-120.0f));
  const __m512i n = _mm512_cvttps_epi32(_mm512_sub_ps(t, _mm512_set1_ps(0.5f)));
  const __m512 f = _mm512_sub_ps(t, _mm512_cvtepi32_ps(n));
  __m512 p = _mm512_set1_ps(1.5403530e-4f);
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(1.3333558e-3f));
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(9.6181291e-3f));
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(5.5504109e-2f));
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(2.4022651e-1f));
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(6.9314718e-1f));
  p = _mm512_add_ps(_mm512_mul_ps(p, f), _mm512_set1_ps(1.0f));
  return _mm512_mul_ps(p, _mm512_castsi512_ps(_mm512_slli_epi32(_mm512_add_epi32(n, _mm512_set1_epi32(127)), 23)));
}

void KernelSumsImpl(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw) {
  const __m512 qx = _mm512_set1_ps(q[0]), qy = _mm512_set1_ps(q[1]), qz = _mm512_set1_ps(q[2]);
  const __m512 cut = _mm512_set1_ps(cutoff2), neg_inv = _mm512_set1_ps(-inv_b2);
  __m512 ax = _mm512_setzero_ps(), ay = ax, az = ax, aw = ax;
  for (int r = 0; r < num_ranges; ++r) {
    const uint32_t e = ranges[r][1];
    for (uint32_t k = ranges[r][0]; k < e; k += 16) {
      const __mmask16 in = e - k >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (e - k)) - 1u);
      const __m512 x = _mm512_maskz_loadu_ps(in, px + k), y = _mm512_maskz_loadu_ps(in, py + k);
      const __m512 z = _mm512_maskz_loadu_ps(in, pz + k), w = _mm512_maskz_loadu_ps(in, pw + k);
      const __m512 ex = _mm512_sub_ps(x, qx), ey = _mm512_sub_ps(y, qy), ez = _mm512_sub_ps(z, qz);
      const __m512 d2 =
          _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(ex, ex), _mm512_mul_ps(ey, ey)), _mm512_mul_ps(ez, ez));
      const __mmask16 near = _mm512_mask_cmp_ps_mask(in, d2, cut, _CMP_LE_OQ);
      const __m512 kw = _mm512_maskz_mul_ps(near, w, ExpNonPositive(_mm512_mul_ps(d2, neg_inv)));
      ax = _mm512_add_ps(ax, _mm512_mul_ps(kw, x));
      ay = _mm512_add_ps(ay, _mm512_mul_ps(kw, y));
      az = _mm512_add_ps(az, _mm512_mul_ps(kw, z));
      aw = _mm512_add_ps(aw, kw);
    }
  }
  *sx = _mm512_reduce_add_ps(ax);
  *sy = _mm512_reduce_add_ps(ay);
  *sz = _mm512_reduce_add_ps(az);
  *sw = _mm512_reduce_add_ps(aw);
}
#pragma GCC diagnostic pop
#elif defined(__AVX2__)
inline __m256 ExpNonPositive(__m256 a) {
  const __m256 t = _mm256_max_ps(_mm256_mul_ps(a, _mm256_set1_ps(1.44269504f)), _mm256_set1_ps(-120.0f));
  const __m256i n = _mm256_cvttps_epi32(_mm256_sub_ps(t, _mm256_set1_ps(0.5f)));
  const __m256 f = _mm256_sub_ps(t, _mm256_cvtepi32_ps(n));
  __m256 p = _mm256_set1_ps(1.5403530e-4f);
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(1.3333558e-3f));
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(9.6181291e-3f));
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(5.5504109e-2f));
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(2.4022651e-1f));
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(6.9314718e-1f));
  p = _mm256_add_ps(_mm256_mul_ps(p, f), _mm256_set1_ps(1.0f));
  return _mm256_mul_ps(p, _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(n, _mm256_set1_epi32(127)), 23)));
}

inline float HorizontalSum(__m256 v) {
  __m128 s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  s = _mm_add_ps(s, _mm_movehl_ps(s, s));
  s = _mm_add_ss(s, _mm_movehdup_ps(s));
  return _mm_cvtss_f32(s);
}

void KernelSumsImpl(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw) {
  const __m256 qx = _mm256_set1_ps(q[0]), qy = _mm256_set1_ps(q[1]), qz = _mm256_set1_ps(q[2]);
  const __m256 cut = _mm256_set1_ps(cutoff2), neg_inv = _mm256_set1_ps(-inv_b2);
  const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  __m256 ax = _mm256_setzero_ps(), ay = ax, az = ax, aw = ax;
  for (int r = 0; r < num_ranges; ++r) {
    const uint32_t e = ranges[r][1];
    for (uint32_t k = ranges[r][0]; k < e; k += 8) {
      const __m256i in = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(std::min(e - k, 8u))), iota);
      const __m256 x = _mm256_maskload_ps(px + k, in), y = _mm256_maskload_ps(py + k, in);
      const __m256 z = _mm256_maskload_ps(pz + k, in), w = _mm256_maskload_ps(pw + k, in);
      const __m256 ex = _mm256_sub_ps(x, qx), ey = _mm256_sub_ps(y, qy), ez = _mm256_sub_ps(z, qz);
      const __m256 d2 =
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ex, ex), _mm256_mul_ps(ey, ey)), _mm256_mul_ps(ez, ez));
      const __m256 near = _mm256_and_ps(_mm256_cmp_ps(d2, cut, _CMP_LE_OQ), _mm256_castsi256_ps(in));
      const __m256 kw = _mm256_and_ps(near, _mm256_mul_ps(w, ExpNonPositive(_mm256_mul_ps(d2, neg_inv))));
      ax = _mm256_add_ps(ax, _mm256_mul_ps(kw, x));
      ay = _mm256_add_ps(ay, _mm256_mul_ps(kw, y));
      az = _mm256_add_ps(az, _mm256_mul_ps(kw, z));
      aw = _mm256_add_ps(aw, kw);
    }
  }
  *sx = HorizontalSum(ax);
  *sy = HorizontalSum(ay);
  *sz = HorizontalSum(az);
  *sw = HorizontalSum(aw);
}
#elif defined(__ARM_NEON) && defined(__aarch64__)
// 64-bit ARM (Raspberry Pi 4/5, Jetson, Rockchip): NEON, 4 floats per register. The kernel
// keeps the AVX-512 kernel's 16 lanes (four registers per sum) and adds them up in the order
// _mm512_reduce_add_ps does, so an aarch64 board's sums, hence its joints, are bit-identical
// to an AVX-512 machine's. Multiplies and adds stay separate (vmulq + vaddq, never vfmaq), as
// everywhere in the project (-ffp-contract=off).
inline float32x4_t ExpNonPositive(float32x4_t a) {
  const float32x4_t t = vmaxq_f32(vmulq_f32(a, vdupq_n_f32(1.44269504f)), vdupq_n_f32(-120.0f));
  const int32x4_t n = vcvtq_s32_f32(vsubq_f32(t, vdupq_n_f32(0.5f)));  // truncates, as cvttps
  const float32x4_t f = vsubq_f32(t, vcvtq_f32_s32(n));
  float32x4_t p = vdupq_n_f32(1.5403530e-4f);
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(1.3333558e-3f));
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(9.6181291e-3f));
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(5.5504109e-2f));
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(2.4022651e-1f));
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(6.9314718e-1f));
  p = vaddq_f32(vmulq_f32(p, f), vdupq_n_f32(1.0f));
  return vmulq_f32(p, vreinterpretq_f32_s32(vshlq_n_s32(vaddq_s32(n, vdupq_n_s32(127)), 23)));
}

/// The sum of 16 lanes a[0..3] (lanes 0-3, 4-7, 8-11, 12-15) in _mm512_reduce_add_ps's order:
/// halves (8 + 8), quarters (4 + 4), then lanes (0 + 2, 1 + 3), then the last two.
inline float ReduceAdd16(const float32x4_t a[4]) {
  const float32x4_t q = vaddq_f32(vaddq_f32(a[3], a[1]), vaddq_f32(a[2], a[0]));
  return (vgetq_lane_f32(q, 0) + vgetq_lane_f32(q, 2)) + (vgetq_lane_f32(q, 1) + vgetq_lane_f32(q, 3));
}

void KernelSumsImpl(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw) {
  const float32x4_t qx = vdupq_n_f32(q[0]), qy = vdupq_n_f32(q[1]), qz = vdupq_n_f32(q[2]);
  const float32x4_t cut = vdupq_n_f32(cutoff2), neg_inv = vdupq_n_f32(-inv_b2);
  float32x4_t ax[4], ay[4], az[4], aw[4];
  for (int g = 0; g < 4; ++g) ax[g] = ay[g] = az[g] = aw[g] = vdupq_n_f32(0.0f);
  // The last (partial) block of a run is copied into zero-filled buffers: the loads stay within
  // the arrays, and the lanes past the end add kw = 0, as the AVX-512 kernel's masked lanes do.
  alignas(16) float tail[4][16];
  for (int r = 0; r < num_ranges; ++r) {
    const uint32_t e = ranges[r][1];
    for (uint32_t k = ranges[r][0]; k < e; k += 16) {
      const float *x16 = px + k, *y16 = py + k, *z16 = pz + k, *w16 = pw + k;
      if (e - k < 16) {
        const uint32_t m = e - k;
        for (uint32_t i = 0; i < 16; ++i) {
          tail[0][i] = i < m ? px[k + i] : 0.0f;
          tail[1][i] = i < m ? py[k + i] : 0.0f;
          tail[2][i] = i < m ? pz[k + i] : 0.0f;
          tail[3][i] = i < m ? pw[k + i] : 0.0f;
        }
        x16 = tail[0], y16 = tail[1], z16 = tail[2], w16 = tail[3];
      }
      const uint32_t valid = std::min(e - k, 16u);
      for (int g = 0; g < 4; ++g) {
        const float32x4_t x = vld1q_f32(x16 + 4 * g), y = vld1q_f32(y16 + 4 * g);
        const float32x4_t z = vld1q_f32(z16 + 4 * g), w = vld1q_f32(w16 + 4 * g);
        const float32x4_t ex = vsubq_f32(x, qx), ey = vsubq_f32(y, qy), ez = vsubq_f32(z, qz);
        const float32x4_t d2 = vaddq_f32(vaddq_f32(vmulq_f32(ex, ex), vmulq_f32(ey, ey)), vmulq_f32(ez, ez));
        const uint32x4_t lane = vaddq_u32(vdupq_n_u32(uint32_t(4 * g)), uint32x4_t{0, 1, 2, 3});
        const uint32x4_t near = vandq_u32(vcleq_f32(d2, cut), vcltq_u32(lane, vdupq_n_u32(valid)));
        const float32x4_t kw = vreinterpretq_f32_u32(
            vandq_u32(near, vreinterpretq_u32_f32(vmulq_f32(w, ExpNonPositive(vmulq_f32(d2, neg_inv))))));
        ax[g] = vaddq_f32(ax[g], vmulq_f32(kw, x));
        ay[g] = vaddq_f32(ay[g], vmulq_f32(kw, y));
        az[g] = vaddq_f32(az[g], vmulq_f32(kw, z));
        aw[g] = vaddq_f32(aw[g], kw);
      }
    }
  }
  *sx = ReduceAdd16(ax);
  *sy = ReduceAdd16(ay);
  *sz = ReduceAdd16(az);
  *sw = ReduceAdd16(aw);
}
#else
void KernelSumsImpl(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw) {
  float ax = 0, ay = 0, az = 0, aw = 0;
  for (int r = 0; r < num_ranges; ++r)
    for (uint32_t k = ranges[r][0]; k < ranges[r][1]; ++k) {
      const float ex = px[k] - q[0], ey = py[k] - q[1], ez = pz[k] - q[2];
      const float d2 = ex * ex + ey * ey + ez * ez;
      if (!(d2 <= cutoff2)) continue;
      const float kw = pw[k] * ExpNonPositive(-d2 * inv_b2);
      ax += kw * px[k];
      ay += kw * py[k];
      az += kw * pz[k];
      aw += kw;
    }
  *sx = ax;
  *sy = ay;
  *sz = az;
  *sw = aw;
}
#endif

}  // namespace

void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw) {
  KernelSumsImpl(px, py, pz, pw, ranges, num_ranges, q, cutoff2, inv_b2, sx, sy, sz, sw);
}

namespace {

/// The cells of at least the kernel's cut-off radius that the points are bucketed by, over
/// their bounding box plus one empty cell each side (so that a query's 3x3x3 block never leaves
/// the array).
struct CutoffGrid {
  float inv_cell = 0;
  int base[3] = {0, 0, 0}, dims[3] = {0, 0, 0};
  size_t nx = 0, nxy = 0;
};

/// The bounding box of the n > 0 points.
void Bounds(const PointSet& pts, float lo[3], float hi[3]) {
  const size_t n = pts.size();
  lo[0] = pts.x[0];
  lo[1] = pts.y[0];
  lo[2] = pts.z[0];
  hi[0] = lo[0];
  hi[1] = lo[1];
  hi[2] = lo[2];
  for (size_t i = 1; i < n; ++i) {
    lo[0] = std::min(lo[0], pts.x[i]);
    hi[0] = std::max(hi[0], pts.x[i]);
    lo[1] = std::min(lo[1], pts.y[i]);
    hi[1] = std::max(hi[1], pts.y[i]);
    lo[2] = std::min(lo[2], pts.z[i]);
    hi[2] = std::max(hi[2], pts.z[i]);
  }
}

/// Buckets the points by cells of at least `cutoff` (counting sort into s.sx .. s.sw, each
/// cell's run starting at s.start[cell]). Cells grow when the box is huge (far outliers in a
/// real frame), keeping <= ~100^3 of them.
CutoffGrid BucketPoints(const PointSet& pts, float cutoff, const float lo[3], const float hi[3],
                        MeanShiftScratch& s) {
  const size_t n = pts.size();
  CutoffGrid g;
  const float extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  g.inv_cell = 1.0f / std::max(cutoff, extent / 100.0f);
  const float inv_cell = g.inv_cell;
  double cells = 1;
  for (int a = 0; a < 3; ++a) {
    g.base[a] = int(std::floor(lo[a] * inv_cell)) - 1;
    g.dims[a] = int(std::floor(hi[a] * inv_cell)) - g.base[a] + 2;
    cells *= double(g.dims[a]);
  }
  g.nx = size_t(g.dims[0]);
  g.nxy = size_t(g.dims[0]) * size_t(g.dims[1]);
  const int* base = g.base;
  const size_t nx = g.nx, nxy = g.nxy;
  s.cell_of.resize(n);
  s.start.assign(size_t(cells) + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    const size_t c = size_t(int(std::floor(pts.z[i] * inv_cell)) - base[2]) * nxy +
                     size_t(int(std::floor(pts.y[i] * inv_cell)) - base[1]) * nx +
                     size_t(int(std::floor(pts.x[i] * inv_cell)) - base[0]);
    s.cell_of[i] = uint32_t(c);
    ++s.start[c + 1];
  }
  for (size_t c = 1; c < s.start.size(); ++c) s.start[c] += s.start[c - 1];
  s.sx.resize(n);
  s.sy.resize(n);
  s.sz.resize(n);
  s.sw.resize(n);
  {
    std::vector<uint32_t>& fill = s.start;  // advanced while filling, shifted back below
    for (size_t i = 0; i < n; ++i) {
      const uint32_t k = fill[s.cell_of[i]]++;
      s.sx[k] = pts.x[i];
      s.sy[k] = pts.y[i];
      s.sz[k] = pts.z[i];
      s.sw[k] = pts.w[i];
    }
    for (size_t c = s.start.size() - 1; c > 0; --c) s.start[c] = s.start[c - 1];
    s.start[0] = 0;
  }
  return g;
}

/// The starting points into s.starts: every seed point, or (seed_cell > 0) one per cell of that
/// size, at the seed-weighted mean of the cell's seed points and carrying their summed seed
/// weight.
void GatherStarts(const PointSet& pts, float seed_cell, const float lo[3], const float hi[3],
                  MeanShiftScratch& s) {
  const size_t n = pts.size();
  PointSet& starts = s.starts;
  starts.clear();
  if (seed_cell > 0) {
    Eigen::Vector3f lo_v(lo[0], lo[1], lo[2]), hi_v(hi[0], hi[1], hi[2]);
    s.seed_ids.Reset(lo_v, hi_v, seed_cell);
    for (size_t i = 0; i < n; ++i) {
      const float sw = pts.seed[i];
      if (!(sw > 0)) continue;
      const Eigen::Vector3f p(pts.x[i], pts.y[i], pts.z[i]);
      bool fresh = false;
      const uint32_t id = s.seed_ids.FindOrAdd(s.seed_ids.CellOf(p), &fresh);
      if (fresh) starts.push_back(0, 0, 0, 0, 0);
      starts.x[id] += sw * p.x();
      starts.y[id] += sw * p.y();
      starts.z[id] += sw * p.z();
      starts.seed[id] += sw;
    }
    s.seed_ids.Clear();
    for (size_t g = 0; g < starts.size(); ++g) {
      starts.x[g] /= starts.seed[g];
      starts.y[g] /= starts.seed[g];
      starts.z[g] /= starts.seed[g];
    }
  } else {
    for (size_t i = 0; i < n; ++i)
      if (pts.seed[i] > 0) starts.push_back(pts.x[i], pts.y[i], pts.z[i], 0, pts.seed[i]);
  }
}

/// Runs a trajectory from each of s.starts over the bucketed points, into s.arrivals (end point,
/// seed weight).
void Climb(const CutoffGrid& g, float bandwidth, int max_iterations, float merge_distance, MeanShiftScratch& s) {
  // The Gaussian is cut at 3 bandwidths (exp(-9) ~ 1e-4 of the peak).
  const float cutoff = 3.0f * bandwidth, cutoff2 = cutoff * cutoff, inv_b2 = 1.0f / (bandwidth * bandwidth);
  const float inv_cell = g.inv_cell;
  const int* base = g.base;
  const int* dims = g.dims;
  const size_t nx = g.nx, nxy = g.nxy;
  const float* px = s.sx.data();
  const float* py = s.sy.data();
  const float* pz = s.sz.data();
  const float* pw = s.sw.data();

  s.arrivals.clear();
  // Where earlier seeds converged: a later trajectory that comes within a quarter of the merge
  // distance of one of them would end there too, so it stops and takes that end point (the
  // usual basin-of-attraction shortcut; it changes no mode, only the work).
  s.ends.clear();
  const float join2 = 0.0625f * merge_distance * merge_distance;
  const float converged2 = 1e-6f * bandwidth * bandwidth;
  const PointSet& starts = s.starts;
  for (size_t i = 0; i < starts.size(); ++i) {
    Eigen::Vector3f x(starts.x[i], starts.y[i], starts.z[i]);
    bool joined = false;
    for (int it = 0; it < max_iterations && !joined; ++it) {
      for (const Eigen::Vector3f& e : s.ends)
        if ((e - x).squaredNorm() < join2) {
          x = e;
          joined = true;
          break;
        }
      if (joined) break;
      // The query's cell, clamped into the box (a mean of points stays inside it, up to
      // rounding).
      int c[3];
      const float q[3] = {x.x(), x.y(), x.z()};
      for (int a = 0; a < 3; ++a) c[a] = std::clamp(int(std::floor(q[a] * inv_cell)) - base[a], 1, dims[a] - 2);
      uint32_t ranges[9][2];
      int num_ranges = 0;
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy) {
          const size_t row = size_t(c[2] + dz) * nxy + size_t(c[1] + dy) * nx + size_t(c[0]);
          ranges[num_ranges][0] = s.start[row - 1];
          ranges[num_ranges][1] = s.start[row + 2];
          num_ranges += ranges[num_ranges][1] > ranges[num_ranges][0];
        }
      float sum_x = 0, sum_y = 0, sum_z = 0, den = 0;
      KernelSumsImpl(px, py, pz, pw, ranges, num_ranges, q, cutoff2, inv_b2, &sum_x, &sum_y, &sum_z, &den);
      if (!(den > 0)) break;
      const Eigen::Vector3f next(sum_x / den, sum_y / den, sum_z / den);
      const float step2 = (next - x).squaredNorm();
      x = next;
      if (step2 < converged2) break;
    }
    if (!joined) s.ends.push_back(x);
    s.arrivals.emplace_back(x, starts.seed[i]);
  }
}

/// Seeds that end within merge_distance of a mode's first arrival belong to that mode; its
/// position is the weight-averaged arrival. Most confident first.
std::vector<Mode> MergeArrivals(const std::vector<std::pair<Eigen::Vector3f, float>>& arrivals,
                                float merge_distance) {
  std::vector<Mode> modes;
  std::vector<Eigen::Vector3f> anchor, sum;
  for (const auto& [x, w] : arrivals) {
    size_t m = 0;
    while (m < anchor.size() && (anchor[m] - x).norm() > merge_distance) ++m;
    if (m == anchor.size()) {
      anchor.push_back(x);
      sum.push_back(Eigen::Vector3f::Zero());
      modes.push_back({x, 0.0f});
    }
    sum[m] += w * x;
    modes[m].confidence += w;
  }
  for (size_t m = 0; m < modes.size(); ++m)
    if (modes[m].confidence > 0) modes[m].position = sum[m] / modes[m].confidence;
  std::stable_sort(modes.begin(), modes.end(), [](const Mode& a, const Mode& b) { return a.confidence > b.confidence; });
  return modes;
}

}  // namespace

MeanShiftScratch& ThreadScratch() {
  thread_local MeanShiftScratch scratch;
  return scratch;
}

std::vector<Mode> MeanShift(const PointSet& pts, float bandwidth, int max_iterations, float merge_distance,
                            float seed_cell, MeanShiftScratch& s) {
  const size_t n = pts.size();
  if (n == 0 || !(bandwidth > 0)) return {};
  float lo[3], hi[3];
  Bounds(pts, lo, hi);
  const CutoffGrid g = BucketPoints(pts, 3.0f * bandwidth, lo, hi, s);
  GatherStarts(pts, seed_cell, lo, hi, s);
  Climb(g, bandwidth, max_iterations, merge_distance, s);
  return MergeArrivals(s.arrivals, merge_distance);
}

}  // namespace detail

std::vector<Mode> MeanShiftModes(const std::vector<Eigen::Vector3f>& points, const std::vector<float>& weights,
                                 const std::vector<float>& seed_weights, float bandwidth, int max_iterations,
                                 float merge_distance) {
  detail::PointSet pts;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    pts.push_back(points[i].x(), points[i].y(), points[i].z(), weights[i], seed_weights[i]);
  }
  return detail::MeanShift(pts, bandwidth, max_iterations, merge_distance, 0.0f, detail::ThreadScratch());
}

}  // namespace poseforest::runtime
