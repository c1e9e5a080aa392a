#pragma once
// Mean shift over weighted 3D points, the engine of the joint proposals (joint_proposals.cpp):
// the points as structure of arrays, the compact cell ids that both the proposals' voxels and
// the mean shift's seed cells use, and each thread's reused working memory. Internal to the
// runtime (not a public API).

#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "runtime/joint_proposals.h"

namespace poseforest::runtime::detail {

// Integer cell coordinates packed into one key (21 bits each, offset so negatives fit).
inline uint64_t CellKey(int x, int y, int z) {
  constexpr int kBias = 1 << 20;
  return (uint64_t(uint32_t(x + kBias) & 0x1FFFFF) << 42) | (uint64_t(uint32_t(y + kBias) & 0x1FFFFF) << 21) |
         uint64_t(uint32_t(z + kBias) & 0x1FFFFF);
}

inline Eigen::Vector3i Cell(const Eigen::Vector3f& p, float inv_size) {
  return {int(std::floor(p.x() * inv_size)), int(std::floor(p.y() * inv_size)), int(std::floor(p.z() * inv_size))};
}

constexpr uint32_t kNone = ~0u;

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

/// Sum over the points k in the runs ranges[r][0] <= k < ranges[r][1] of the Gaussian kernel
/// weight kw = w[k] * exp(-|p_k - q|^2 / b^2) (inv_b2 = 1 / b^2), cut at |p_k - q|^2 <= cutoff2:
/// sets (sx, sy, sz) to sum kw * p_k and sw to sum kw. Vector kernels for AVX-512, AVX2 and
/// 64-bit ARM (NEON), scalar otherwise; they differ only in the order of the float sums. exp is
/// a degree-6 polynomial (relative error ~2e-7).
void KernelSums(const float* px, const float* py, const float* pz, const float* pw, const uint32_t (*ranges)[2],
                int num_ranges, const float q[3], float cutoff2, float inv_b2, float* sx, float* sy, float* sz,
                float* sw);

/// This thread's working memory (reused across joints and frames).
MeanShiftScratch& ThreadScratch();

/// Mean shift over `pts` (see MeanShiftModes), seeds in index order; `seed_cell` > 0: one
/// start per cell of that size (ProposalOptions::seed_cell_fraction).
std::vector<Mode> MeanShift(const PointSet& pts, float bandwidth, int max_iterations, float merge_distance,
                            float seed_cell, MeanShiftScratch& s);

}  // namespace poseforest::runtime::detail
