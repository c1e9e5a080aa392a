#include "runtime/joint_proposals.h"

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <exception>
#include <limits>
#include <numeric>

#if defined(__AVX2__) || defined(__AVX512F__)
#include <immintrin.h>
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#endif

#include "runtime/mean_shift.h"

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

using detail::MeanShift;
using detail::MeanShiftScratch;
using detail::PointSet;
using detail::ThreadScratch;
using detail::kNone;

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

/// The first pass of ProposeJoints: reprojects the n foreground pixels once into `cloud` (3D
/// point and weight factor d^2 per pixel; 0 depth: unusable, never read; the bounds of the
/// usable ones) and writes P(j | pixel k) at joint_prob[j * n + k], 0 where it does not count
/// (not positive, not finite, no depth). Returns per joint how many pixels are at or above
/// min_p (about the joint's work). pixel_of and probability_row as in Propose.
template <typename PixelOf, typename ProbabilityRow>
std::array<uint32_t, core::kNumJoints> Reproject(const core::DepthImage& depth, size_t n, const PixelOf& pixel_of,
                                                 const ProbabilityRow& probability_row, int pixel_stride,
                                                 const ProposalOptions& options, float min_p, Cloud& cloud,
                                                 float* const joint_prob) {
  const size_t num_pixels = depth.pixels.size();
  const int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();
  const int team = int(std::min<size_t>(size_t(threads), std::max<size_t>(1, n / 4096)));
  std::vector<Eigen::Vector3f> lo(size_t(team), Eigen::Vector3f::Constant(std::numeric_limits<float>::max()));
  std::vector<Eigen::Vector3f> hi(size_t(team), Eigen::Vector3f::Constant(std::numeric_limits<float>::lowest()));
  // A pixel of a subsampled grid stands for pixel_stride^2 pixels (x 1.0f: exact at 1).
  const float area = float(std::max(1, pixel_stride)) * float(std::max(1, pixel_stride));
  // Per thread and joint, the pixels at or above min_probability (about the joint's work).
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
  std::array<uint32_t, core::kNumJoints> total{};
  for (const auto& counts : listed)
    for (int j = 0; j < core::kNumJoints; ++j) total[size_t(j)] += counts[size_t(j)];
  return total;
}

/// Joints with the most pixels first (about the most work), so that the last joint a thread
/// takes is a small one and neither waits long for the other; each joint's result is its
/// own, whatever the order and the thread.
std::array<uint32_t, core::kNumJoints> JointOrder(const std::array<uint32_t, core::kNumJoints>& total) {
  std::array<uint32_t, core::kNumJoints> order{};
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return total[a] > total[b]; });
  return order;
}

/// Appends the proposal of a mode at `surface` (on the body surface; pushed back by the joint's
/// z offset) unless its confidence is not positive or it is not in front of the camera.
inline void Emit(const Eigen::Vector3f& surface, float confidence, const core::JointParams& jp,
                 const core::CameraIntrinsics& camera, std::vector<JointProposal>& proposals) {
  if (!(confidence > 0) || !(surface.z() > 0)) return;
  JointProposal p;
  p.pixel = camera.Project(surface.cast<double>()).cast<float>();
  p.position = surface + Eigen::Vector3f(0, 0, jp.z_offset_m);
  p.confidence = confidence;
  proposals.push_back(p);
}

/// Mean shift's input for one joint into s.voxels (empty on entry): the pixels at or above
/// min_p (P of the joint at pj[k]), summed per voxel of bandwidth * voxel_fraction, or each
/// pixel on its own when that is 0.
void VoxelizeJoint(const float* const pj, size_t n, float min_p, const Cloud& cloud, const core::JointParams& jp,
                   float voxel_fraction, MeanShiftScratch& s) {
  PointSet& v = s.voxels;
  const float voxel = jp.bandwidth_m * voxel_fraction;
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
}

/// The fast clustering method for one joint (P at pj[k]) into `proposals`, most confident first.
void ClusterJoint(const float* const pj, size_t n, const Cloud& cloud, const core::JointParams& jp,
                  const ProposalOptions& options, MeanShiftScratch& s, std::vector<JointProposal>& proposals) {
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
    if (cluster_w > 0) Emit(cluster_sum / cluster_w, cluster_w, jp, options.camera, proposals);
  }
  s.ids.Clear();
  std::stable_sort(proposals.begin(), proposals.end(),
                   [](const JointProposal& a, const JointProposal& b) { return a.confidence > b.confidence; });
}

/// ProposeJoints over n foreground pixels: pixel_of(k) is pixel k's raster index and
/// probability_row(k, float p[kNumJoints]) writes its P(joint | pixel) (any values: those
/// that do not count are zeroed here). Both are called from the OpenMP team and must not throw.
template <typename PixelOf, typename ProbabilityRow>
FrameProposals Propose(const core::DepthImage& depth, size_t n, PixelOf pixel_of,
                       ProbabilityRow probability_row, int pixel_stride, const ProposalOptions& options) {
  FrameProposals out;
  if (n == 0) return out;
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
  // Pixels below the floor (min_p) add (almost) nothing to the density and are never seeds.
  const float min_p = std::max(options.min_probability, std::numeric_limits<float>::min());
  const std::array<uint32_t, core::kNumJoints> total =
      Reproject(depth, n, pixel_of, probability_row, pixel_stride, options, min_p, cloud, joint_prob);
  if (!(cloud.lo.array() <= cloud.hi.array()).all()) return out;  // no usable pixel

  const std::array<uint32_t, core::kNumJoints> order = JointOrder(total);
  // No exception may leave the parallel region: the first is kept and rethrown after it.
  std::exception_ptr error;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
  for (int o = 0; o < core::kNumJoints; ++o) {
    const int j = int(order[size_t(o)]);
    try {
      const core::JointParams& jp = options.params[size_t(j)];
      auto& proposals = out[size_t(j)];
      MeanShiftScratch& s = ThreadScratch();
      const float* const pj = joint_prob + size_t(j) * n;
      s.voxels.clear();
      if (options.method == ProposalMethod::kMeanShift) {
        VoxelizeJoint(pj, n, min_p, cloud, jp, options.voxel_fraction, s);
        for (const Mode& m :
             MeanShift(s.voxels, jp.bandwidth_m, options.max_iterations, options.merge_fraction * jp.bandwidth_m,
                       options.seed_cell_fraction * jp.bandwidth_m, s))
          Emit(m.position, m.confidence, jp, options.camera, proposals);
      } else {
        ClusterJoint(pj, n, cloud, jp, options, s, proposals);
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
