#include "runtime/joint_proposals.h"

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <exception>
#include <limits>
#include <numeric>
#include <unordered_map>

#if defined(__AVX2__) || defined(__AVX512F__)
#include <immintrin.h>
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#endif

namespace poseforest::runtime {
namespace {

// How the proposals are fast (figures: bench/pipeline):
//  - The foreground is reprojected once, into structure-of-arrays coordinates.
//  - Per joint, the pixels with P > 0 are summed into voxels of bandwidth * voxel_fraction
//    found through a dense cell array over the frame's bounding box (a hash map only when that
//    box is huge), so no per-pixel hashing.
//  - Mean shift runs over the voxels, bucketed by a counting sort into cells of the kernel's
//    cut-off radius: a query reads 9 contiguous runs (3 x-adjacent cells each) and evaluates
//    the Gaussian with a polynomial exp in an `omp simd` loop (relative error ~2e-7).
//  - Trajectories that come near an earlier end point stop there (basin shortcut).
//  - Joints are spread over the OpenMP team, the most populated first (the reprojection
//    pass counts each joint's pixels; each thread keeps its bounds and counts in registers).

// Integer cell coordinates packed into one key (21 bits each, offset so negatives fit).
uint64_t CellKey(int x, int y, int z) {
  constexpr int kBias = 1 << 20;
  return (uint64_t(uint32_t(x + kBias) & 0x1FFFFF) << 42) | (uint64_t(uint32_t(y + kBias) & 0x1FFFFF) << 21) |
         uint64_t(uint32_t(z + kBias) & 0x1FFFFF);
}

Eigen::Vector3i Cell(const Eigen::Vector3f& p, float inv_size) {
  return {int(std::floor(p.x() * inv_size)), int(std::floor(p.y() * inv_size)), int(std::floor(p.z() * inv_size))};
}

constexpr uint32_t kNone = ~0u;

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

/// Sum over the points k in the runs ranges[r][0] <= k < ranges[r][1] of the Gaussian kernel
/// weight kw = w[k] * exp(-|p_k - q|^2 / b^2), cut at |p_k - q|^2 <= cutoff2: adds sum kw * p_k
/// to (sx, sy, sz) and sum kw to sw. Vector kernels for AVX-512, AVX2 and 64-bit ARM (NEON),
/// scalar otherwise; they differ only in the order of the float sums (NEON's is AVX-512's).
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

void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
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

void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
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

void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
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
void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
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

/// Compact ids for the integer cells of a bounding box: a dense array of ids when the box
/// has at most kMaxDense cells, a hash map otherwise. Ids count from 0 in first-use order.
class CellIds {
 public:
  static constexpr size_t kMaxDense = size_t(1) << 21;

  /// Prepares for cells of `size` metres covering the points within [lo, hi].
  void Reset(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float size) {
    Clear();
    inv_ = 1.0f / size;
    base_ = Cell(lo, inv_);
    const Eigen::Vector3i top = Cell(hi, inv_);
    // One cell of margin on each side, so that neighbour queries need no bounds test.
    base_ -= Eigen::Vector3i::Ones();
    const Eigen::Vector3i dims = top - base_ + 2 * Eigen::Vector3i::Ones();
    const double cells = double(dims.x()) * double(dims.y()) * double(dims.z());
    dense_ = cells <= double(kMaxDense) && dims.minCoeff() > 0;
    if (dense_) {
      nx_ = dims.x();
      nxy_ = size_t(dims.x()) * size_t(dims.y());
      const size_t need = size_t(cells);
      if (cells_.size() < need) cells_.resize(need, kNone);
    }
  }
  float inverse_size() const { return inv_; }
  Eigen::Vector3i CellOf(const Eigen::Vector3f& p) const { return Cell(p, inv_); }
  /// The id of cell c (within the box), adding it if new.
  uint32_t FindOrAdd(const Eigen::Vector3i& c, bool* fresh) {
    if (dense_) {
      uint32_t& id = cells_[Index(c)];
      *fresh = id == kNone;
      if (*fresh) {
        id = uint32_t(used_.size());
        used_.push_back(Index(c));
      }
      return id;
    }
    const auto [it, added] = map_.try_emplace(CellKey(c.x(), c.y(), c.z()), uint32_t(map_.size()));
    *fresh = added;
    return it->second;
  }
  /// The id of cell c (within the box or one cell beside it), or kNone.
  uint32_t Find(const Eigen::Vector3i& c) const {
    if (dense_) return cells_[Index(c)];
    const auto it = map_.find(CellKey(c.x(), c.y(), c.z()));
    return it == map_.end() ? kNone : it->second;
  }
  /// Forgets the ids (only the used entries of the dense array are reset).
  void Clear() {
    for (size_t i : used_) cells_[i] = kNone;
    used_.clear();
    map_.clear();
  }

 private:
  size_t Index(const Eigen::Vector3i& c) const {
    return size_t(c.z() - base_.z()) * nxy_ + size_t(c.y() - base_.y()) * size_t(nx_) + size_t(c.x() - base_.x());
  }
  float inv_ = 1;
  bool dense_ = false;
  Eigen::Vector3i base_ = Eigen::Vector3i::Zero();
  int nx_ = 0;
  size_t nxy_ = 0;
  std::vector<uint32_t> cells_;
  std::vector<size_t> used_;
  std::unordered_map<uint64_t, uint32_t> map_;
};

/// Weighted points, structure of arrays: x, y, z (metres), kernel weight, seed weight.
struct PointSet {
  std::vector<float> x, y, z, w, seed;
  size_t size() const { return w.size(); }
  void clear() {
    x.clear();
    y.clear();
    z.clear();
    w.clear();
    seed.clear();
  }
  void push_back(float px, float py, float pz, float pw, float ps) {
    x.push_back(px);
    y.push_back(py);
    z.push_back(pz);
    w.push_back(pw);
    seed.push_back(ps);
  }
};

/// Working memory of one thread, reused across joints and frames.
struct MeanShiftScratch {
  // Points sorted by cut-off cell (counting sort), and where each cell's run starts.
  std::vector<float> sx, sy, sz, sw;
  std::vector<uint32_t> cell_of, start;
  std::vector<Eigen::Vector3f> ends;
  std::vector<std::pair<Eigen::Vector3f, float>> arrivals;
  PointSet voxels, starts;
  CellIds seed_ids;
  std::vector<float> vx, vy, vz;  // weighted position sums per voxel
  CellIds ids;
};

MeanShiftScratch& ThreadScratch() {
  thread_local MeanShiftScratch scratch;
  return scratch;
}

/// Mean shift over `pts` (see MeanShiftModes), seeds in index order.
std::vector<Mode> MeanShift(const PointSet& pts, float bandwidth, int max_iterations, float merge_distance,
                            float seed_cell, MeanShiftScratch& s) {
  std::vector<Mode> modes;
  const size_t n = pts.size();
  if (n == 0 || !(bandwidth > 0)) return modes;
  // The Gaussian is cut at 3 bandwidths (exp(-9) ~ 1e-4 of the peak).
  const float cutoff = 3.0f * bandwidth, cutoff2 = cutoff * cutoff, inv_b2 = 1.0f / (bandwidth * bandwidth);
  // Bucket the points by cells of at least the cut-off radius over their bounding box (plus
  // one empty cell each side, so that a query's 3x3x3 block never leaves the array). Cells
  // grow when the box is huge (far outliers in a real frame), keeping <= ~100^3 of them.
  float lo[3] = {pts.x[0], pts.y[0], pts.z[0]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t i = 1; i < n; ++i) {
    lo[0] = std::min(lo[0], pts.x[i]);
    hi[0] = std::max(hi[0], pts.x[i]);
    lo[1] = std::min(lo[1], pts.y[i]);
    hi[1] = std::max(hi[1], pts.y[i]);
    lo[2] = std::min(lo[2], pts.z[i]);
    hi[2] = std::max(hi[2], pts.z[i]);
  }
  const float extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const float inv_cell = 1.0f / std::max(cutoff, extent / 100.0f);
  int base[3], dims[3];
  double cells = 1;
  for (int a = 0; a < 3; ++a) {
    base[a] = int(std::floor(lo[a] * inv_cell)) - 1;
    dims[a] = int(std::floor(hi[a] * inv_cell)) - base[a] + 2;
    cells *= double(dims[a]);
  }
  const size_t nx = size_t(dims[0]), nxy = size_t(dims[0]) * size_t(dims[1]);
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
  // Starting points: every seed point, or (seed_cell > 0) one per cell of that size, at the
  // seed-weighted mean of the cell's seed points and carrying their summed seed weight.
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
      KernelSums(px, py, pz, pw, ranges, num_ranges, q, cutoff2, inv_b2, &sum_x, &sum_y, &sum_z, &den);
      if (!(den > 0)) break;
      const Eigen::Vector3f next(sum_x / den, sum_y / den, sum_z / den);
      const float step2 = (next - x).squaredNorm();
      x = next;
      if (step2 < converged2) break;
    }
    if (!joined) s.ends.push_back(x);
    s.arrivals.emplace_back(x, starts.seed[i]);
  }
  // Seeds that end within merge_distance of a mode's first arrival belong to that mode; its
  // position is the weight-averaged arrival.
  std::vector<Eigen::Vector3f> anchor, sum;
  for (const auto& [x, w] : s.arrivals) {
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

/// Pixels per block of the proposals' first pass.
constexpr size_t kBlock = 256;
/// Slack after the joint-major probabilities: a joint's scan reads whole vectors of 16.
constexpr size_t kScanPad = 16;

/// Calls f(k) for each k < n with p[k] >= min_p (false for NaN), in increasing k; p[n ..
/// n + 15] must be readable. Vector compares skip the (many) pixels below the floor.
template <typename F>
inline void ForEachAtLeast(const float* p, size_t n, float min_p, F&& f) {
#if defined(__AVX512F__)
  const __m512 floor_v = _mm512_set1_ps(min_p);
  for (size_t k0 = 0; k0 < n; k0 += 16) {
    unsigned mask = _mm512_cmp_ps_mask(_mm512_loadu_ps(p + k0), floor_v, _CMP_GE_OQ);
    if (n - k0 < 16) mask &= (1u << (n - k0)) - 1u;
    for (; mask != 0; mask &= mask - 1) f(k0 + size_t(std::countr_zero(mask)));
  }
#else
  for (size_t k = 0; k < n; ++k)
    if (p[k] >= min_p) f(k);
#endif
}

/// The reprojected foreground, structure of arrays: camera-frame metres and d^2 (m^2).
struct Cloud {
  std::vector<float> x, y, z, d2;
  Eigen::Vector3f lo, hi;
};

}  // namespace

std::vector<Mode> MeanShiftModes(const std::vector<Eigen::Vector3f>& points, const std::vector<float>& weights,
                                 const std::vector<float>& seed_weights, float bandwidth, int max_iterations,
                                 float merge_distance) {
  PointSet pts;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    pts.push_back(points[i].x(), points[i].y(), points[i].z(), weights[i], seed_weights[i]);
  }
  return MeanShift(pts, bandwidth, max_iterations, merge_distance, 0.0f, ThreadScratch());
}

JointProbabilities ProbabilitiesFromClassification(const core::DepthImage& depth, const Classification& c,
                                                    int num_threads) {
  JointProbabilities out;
  out.width = depth.width;
  out.height = depth.height;
  out.pixel_stride = std::max(1, c.pixel_stride);
  if (c.num_parts != core::kNumParts || c.width != depth.width || c.height != depth.height) return out;
  // Parts pooled per joint: sum over joint_parts[j] of the part sums.
  std::array<std::vector<int>, core::kNumJoints> joint_parts;
  for (int j = 0; j < core::kNumJoints; ++j) joint_parts[size_t(j)] = core::JointParts(j);
  const float norm = 1.0f / float(core::kLeafTotal * c.num_trees);
  auto pool = [&](const uint16_t* s, std::array<float, core::kNumJoints>* p) {
    for (int j = 0; j < core::kNumJoints; ++j) {
      int sum = 0;
      for (int part : joint_parts[size_t(j)]) sum += s[part];
      (*p)[size_t(j)] = float(sum) * norm;
    }
  };
  const size_t stride = size_t(c.stride);
  if (!c.foreground_sums.empty() && c.foreground_sums.size() == c.foreground.size() * stride) {
    // The compact output: one pass over the foreground only.
    const size_t n = c.foreground.size();
    out.pixel = c.foreground;
    out.prob.resize(n);
    const int threads = num_threads > 0 ? num_threads : omp_get_max_threads();
    const int team = int(std::min<size_t>(size_t(threads), std::max<size_t>(1, n / 4096)));
    // Nothing in here allocates or throws.
#pragma omp parallel for num_threads(team) schedule(static)
    for (size_t k = 0; k < n; ++k) pool(c.foreground_sums.data() + k * stride, &out.prob[k]);
    return out;
  }
  if (c.sums.empty()) return out;
  const uint32_t grid = uint32_t(out.pixel_stride), width = uint32_t(depth.width);
  for (uint32_t i = 0; i < uint32_t(depth.pixels.size()); ++i) {
    if (depth.pixels[i] == 0) continue;
    if (grid > 1 && ((i % width) % grid != 0 || (i / width) % grid != 0)) continue;  // not classified
    std::array<float, core::kNumJoints> p{};
    pool(c.sums.data() + size_t(i) * stride, &p);
    out.pixel.push_back(i);
    out.prob.push_back(p);
  }
  return out;
}

JointProbabilities ProbabilitiesFromLabels(const core::DepthImage& depth, const core::LabelImage& labels) {
  JointProbabilities out;
  out.width = depth.width;
  out.height = depth.height;
  if (labels.width != depth.width || labels.height != depth.height) return out;
  std::array<int, 256> joint_of{};
  joint_of.fill(-1);
  for (int j = 0; j < core::kNumJoints; ++j)
    for (int part : core::JointParts(j)) joint_of[size_t(part)] = j;
  for (uint32_t i = 0; i < uint32_t(depth.pixels.size()); ++i) {
    if (depth.pixels[i] == 0 || labels.pixels[i] == core::kBackgroundLabel) continue;
    std::array<float, core::kNumJoints> p{};
    if (const int j = joint_of[labels.pixels[i]]; j >= 0) p[size_t(j)] = 1.0f;
    out.pixel.push_back(i);
    out.prob.push_back(p);
  }
  return out;
}

namespace {

/// ProposeJoints over n foreground pixels: pixel_of(k) is pixel k's raster index and
/// probability_row(k, float p[kNumJoints]) writes its P(joint | pixel) (any values: those
/// that do not count are zeroed here). Both are called from the OpenMP team and must not throw.
template <typename PixelOf, typename ProbabilityRow>
FrameProposals Propose(const core::DepthImage& depth, size_t n, PixelOf pixel_of,
                       ProbabilityRow probability_row, int pixel_stride, const ProposalOptions& options) {
  FrameProposals out;
  if (n == 0) return out;
  const size_t num_pixels = depth.pixels.size();
  const int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();
  // Reproject once: 3D point and weight factor d^2 per pixel (0 depth: unusable, never read).
  // Reused across calls on the same thread (a plain reference, so that the OpenMP team
  // shares the caller's): no allocation and no clearing per frame.
  thread_local Cloud cloud_storage;
  Cloud& cloud = cloud_storage;
  cloud.x.resize(n);
  cloud.y.resize(n);
  cloud.z.resize(n);
  cloud.d2.resize(n);
  // P(j | pixel k) at joint_prob[j * n + k], joint-major so that each joint's pass reads one
  // contiguous array; 0 where it does not count (not positive, not finite, no depth). Reused
  // across calls on the same thread; kScanPad entries of slack for the joints' vector scans.
  thread_local std::vector<float> joint_prob_storage;
  joint_prob_storage.resize(n * size_t(core::kNumJoints) + kScanPad);
  float* const joint_prob = joint_prob_storage.data();
  const int team = int(std::min<size_t>(size_t(threads), std::max<size_t>(1, n / 4096)));
  std::vector<Eigen::Vector3f> lo(size_t(team), Eigen::Vector3f::Constant(std::numeric_limits<float>::max()));
  std::vector<Eigen::Vector3f> hi(size_t(team), Eigen::Vector3f::Constant(std::numeric_limits<float>::lowest()));
  // Per thread and joint, the pixels at or above min_probability (about the joint's work).
  const float min_p = std::max(options.min_probability, std::numeric_limits<float>::min());
  // A pixel of a subsampled grid stands for pixel_stride^2 pixels (x 1.0f: exact at 1).
  const float area = float(std::max(1, pixel_stride)) * float(std::max(1, pixel_stride));
  std::vector<std::array<uint32_t, core::kNumJoints>> listed(static_cast<size_t>(team));
  const core::CameraIntrinsics& cam = options.camera;
  const uint32_t width = uint32_t(std::max(1, depth.width));
  const double inv_width = 1.0 / double(width);
  const size_t num_blocks = (n + kBlock - 1) / kBlock;
  // Nothing in here allocates or throws.
#pragma omp parallel num_threads(team)
  {
    // Bounds and counts in registers, stored once at the end: the threads' entries share a
    // cache line, and updating them there per pixel made two threads slower than one.
    Eigen::Vector3f my_lo = lo[0], my_hi = hi[0];
    std::array<uint32_t, core::kNumJoints> my_listed{};
    uint16_t dk[kBlock];
#pragma omp for schedule(static) nowait
    for (size_t b = 0; b < num_blocks; ++b) {
      const size_t k0 = b * kBlock, m = std::min(n - k0, kBlock);
      // Geometry of the block, branch-free so that it vectorizes: the same double arithmetic
      // as core::CameraIntrinsics::PixelToPoint (then cast to float); y = i / width through
      // (i + 0.5) / width in double, exact for any 32-bit i (never within 0.5 / width of an
      // integer). Pixels without depth get the point (0, 0, 0), never read.
      for (size_t l = 0; l < m; ++l) {
        const uint32_t i = pixel_of(k0 + l);
        const uint16_t d = i < num_pixels ? depth.pixels[i] : 0;
        dk[l] = d;
        const uint32_t y = uint32_t((double(i) + 0.5) * inv_width), x = i - y * width;
        const double z_m = double(d) * 1e-3;
        cloud.x[k0 + l] = float((double(x) - cam.cx) * z_m / cam.fx);
        cloud.y[k0 + l] = float((double(y) - cam.cy) * z_m / cam.fy);
        cloud.z[k0 + l] = float(z_m);
        cloud.d2[k0 + l] = float(d) * float(d) * 1e-6f * area;
      }
      for (size_t l = 0; l < m; ++l) {
        if (dk[l] == 0) continue;
        const Eigen::Vector3f p(cloud.x[k0 + l], cloud.y[k0 + l], cloud.z[k0 + l]);
        my_lo = my_lo.cwiseMin(p);
        my_hi = my_hi.cwiseMax(p);
      }
      for (size_t l = 0; l < m; ++l) {
        const size_t k = k0 + l;
        const bool usable = dk[l] != 0;
        float row[core::kNumJoints];
        probability_row(k, row);
        for (int j = 0; j < core::kNumJoints; ++j) {
          const float p = row[size_t(j)];
          const float kept = usable && p > 0 && std::isfinite(p) ? p : 0.0f;
          joint_prob[size_t(j) * n + k] = kept;
          my_listed[size_t(j)] += uint32_t(kept >= min_p);
        }
      }
    }
    const size_t t = size_t(omp_get_thread_num());
    lo[t] = my_lo;
    hi[t] = my_hi;
    listed[t] = my_listed;
  }
  cloud.lo = lo[0];
  cloud.hi = hi[0];
  for (int t = 1; t < team; ++t) {
    cloud.lo = cloud.lo.cwiseMin(lo[size_t(t)]);
    cloud.hi = cloud.hi.cwiseMax(hi[size_t(t)]);
  }
  if (!(cloud.lo.array() <= cloud.hi.array()).all()) return out;  // no usable pixel

  // Joints with the most pixels first (about the most work), so that the last joint a thread
  // takes is a small one and neither waits long for the other; each joint's result is its
  // own, whatever the order and the thread.
  std::array<uint32_t, core::kNumJoints> total{}, order{};
  for (const auto& counts : listed)
    for (int j = 0; j < core::kNumJoints; ++j) total[size_t(j)] += counts[size_t(j)];
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return total[a] > total[b]; });
  // No exception may leave the parallel region: the first is kept and rethrown after it.
  std::exception_ptr error;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
  for (int o = 0; o < core::kNumJoints; ++o) {
    const int j = int(order[size_t(o)]);
    try {
      const core::JointParams& jp = options.params[size_t(j)];
      auto& proposals = out[size_t(j)];
      MeanShiftScratch& s = ThreadScratch();
      auto emit = [&](const Eigen::Vector3f& surface, float confidence) {
        if (!(confidence > 0) || !(surface.z() > 0)) return;
        JointProposal p;
        p.pixel = options.camera.Project(surface.cast<double>()).cast<float>();
        p.position = surface + Eigen::Vector3f(0, 0, jp.z_offset_m);
        p.confidence = confidence;
        proposals.push_back(p);
      };
      const float* const pj = joint_prob + size_t(j) * n;
      PointSet& v = s.voxels;
      // Pixels below the floor (min_p) add (almost) nothing to the density and are never seeds.
      v.clear();
      if (options.method == ProposalMethod::kMeanShift) {
        const float voxel = jp.bandwidth_m * options.voxel_fraction;
        if (voxel > 0) {
          // Voxels in order of first use (the seeds' order), as a hash map would number them.
          s.ids.Reset(cloud.lo, cloud.hi, voxel);
          s.vx.clear();
          s.vy.clear();
          s.vz.clear();
          ForEachAtLeast(pj, n, min_p, [&](size_t k) {
            const float p = pj[k];
            const float w = p * cloud.d2[k];
            const Eigen::Vector3f pt(cloud.x[k], cloud.y[k], cloud.z[k]);
            bool fresh = false;
            const uint32_t id = s.ids.FindOrAdd(s.ids.CellOf(pt), &fresh);
            if (fresh) {
              v.push_back(0, 0, 0, 0, 0);
              s.vx.push_back(0);
              s.vy.push_back(0);
              s.vz.push_back(0);
            }
            v.w[id] += w;
            // Same association as Eigen's w * point: (w*x, w*y, w*z) added per coordinate.
            s.vx[id] += w * pt.x();
            s.vy[id] += w * pt.y();
            s.vz[id] += w * pt.z();
            if (p > jp.prob_threshold) v.seed[id] += w;
          });
          s.ids.Clear();
          for (size_t i = 0; i < v.size(); ++i) {
            v.x[i] = s.vx[i] / v.w[i];
            v.y[i] = s.vy[i] / v.w[i];
            v.z[i] = s.vz[i] / v.w[i];
          }
        } else {
          for (size_t k = 0; k < n; ++k) {
            const float p = pj[k];
            if (!(p >= min_p)) continue;
            const float w = p * cloud.d2[k];
            v.push_back(cloud.x[k], cloud.y[k], cloud.z[k], w, p > jp.prob_threshold ? w : 0.0f);
          }
        }
        for (const Mode& m :
             MeanShift(v, jp.bandwidth_m, options.max_iterations, options.merge_fraction * jp.bandwidth_m,
                       options.seed_cell_fraction * jp.bandwidth_m, s))
          emit(m.position, m.confidence);
      } else {
        // Bottom-up clustering: the above-threshold pixels are binned into cubic cells of the
        // joint's bandwidth; face- or corner-adjacent occupied cells form one cluster (so depth
        // jumps at a silhouette's rim do not split a part), whose weighted centroid is the
        // proposal. One pass over the pixels plus one over the occupied cells.
        s.ids.Reset(cloud.lo, cloud.hi, jp.bandwidth_m * options.cluster_cell_fraction);
        std::vector<Eigen::Vector3i> cells;
        std::vector<Eigen::Vector3f> wsum;
        std::vector<float> wtot;
        for (size_t k = 0; k < n; ++k) {
          const float p = pj[k];
          if (!(p > jp.prob_threshold)) continue;
          const Eigen::Vector3f pt(cloud.x[k], cloud.y[k], cloud.z[k]);
          const Eigen::Vector3i c = s.ids.CellOf(pt);
          bool fresh = false;
          const uint32_t id = s.ids.FindOrAdd(c, &fresh);
          if (fresh) {
            cells.push_back(c);
            wsum.push_back(Eigen::Vector3f::Zero());
            wtot.push_back(0);
          }
          const float w = p * cloud.d2[k];
          wsum[id] += w * pt;
          wtot[id] += w;
        }
        std::vector<uint8_t> done(cells.size(), 0);
        std::vector<uint32_t> stack;
        for (uint32_t c0 = 0; c0 < cells.size(); ++c0) {
          if (done[c0]) continue;
          Eigen::Vector3f cluster_sum = Eigen::Vector3f::Zero();
          float cluster_w = 0;
          stack.assign(1, c0);
          done[c0] = 1;
          while (!stack.empty()) {
            const uint32_t c = stack.back();
            stack.pop_back();
            cluster_sum += wsum[c];
            cluster_w += wtot[c];
            for (int dz = -1; dz <= 1; ++dz)
              for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                  const uint32_t id = s.ids.Find(cells[c] + Eigen::Vector3i(dx, dy, dz));
                  if (id == kNone || done[id]) continue;
                  done[id] = 1;
                  stack.push_back(id);
                }
          }
          if (cluster_w > 0) emit(cluster_sum / cluster_w, cluster_w);
        }
        s.ids.Clear();
        std::stable_sort(proposals.begin(), proposals.end(),
                         [](const JointProposal& a, const JointProposal& b) { return a.confidence > b.confidence; });
      }
    } catch (...) {
#pragma omp critical(poseforest_propose_joints_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
  return out;
}

}  // namespace

FrameProposals ProposeJoints(const core::DepthImage& depth, const JointProbabilities& probs,
                             const ProposalOptions& options) {
  if (probs.prob.size() != probs.pixel.size() || depth.width != probs.width || depth.height != probs.height) return {};
  return Propose(
      depth, probs.pixel.size(), [&](size_t k) { return probs.pixel[k]; },
      [&](size_t k, float* row) { std::copy(probs.prob[k].begin(), probs.prob[k].end(), row); },
      probs.pixel_stride, options);
}

FrameProposals ProposeJointsFromClassification(const core::DepthImage& depth, const Classification& c,
                                                const ProposalOptions& options) {
  const size_t stride = size_t(c.stride);
  if (c.foreground_sums.empty() || c.foreground_sums.size() != c.foreground.size() * stride)
    return ProposeJoints(depth, ProbabilitiesFromClassification(depth, c, options.num_threads), options);
  if (c.num_parts != core::kNumParts || c.width != depth.width || c.height != depth.height) return {};
  // The parts of each joint (disjoint sets), and the same arithmetic as
  // ProbabilitiesFromClassification, so that both paths give identical probabilities.
  // As fixed tables: each joint's first part, then the further parts (the head's three
  // others); the sums are integers, so any order gives the same value.
  std::array<int, core::kNumJoints> first_part{};
  std::vector<std::pair<int, int>> more;  // (joint, part)
  for (int j = 0; j < core::kNumJoints; ++j) {
    const std::vector<int>& parts = core::JointParts(j);
    POSEFOREST_CHECK(!parts.empty());
    first_part[size_t(j)] = parts[0];
    for (size_t q = 1; q < parts.size(); ++q) more.emplace_back(j, parts[q]);
  }
  const float norm = 1.0f / float(core::kLeafTotal * c.num_trees);
  return Propose(
      depth, c.foreground.size(), [&](size_t k) { return c.foreground[k]; },
      [&](size_t k, float* row) {
        const uint16_t* sums = c.foreground_sums.data() + k * stride;
        int sum[core::kNumJoints];
        for (int j = 0; j < core::kNumJoints; ++j) sum[j] = sums[first_part[size_t(j)]];
        for (const auto& [j, part] : more) sum[j] += sums[part];
        for (int j = 0; j < core::kNumJoints; ++j) row[j] = float(sum[j]) * norm;
      },
      c.pixel_stride, options);
}

}  // namespace poseforest::runtime
