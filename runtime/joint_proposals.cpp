#include "runtime/joint_proposals.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_map>

namespace poseforest::runtime {
namespace {

// Integer cell coordinates packed into one key (21 bits each, offset so negatives fit).
uint64_t CellKey(int x, int y, int z) {
  constexpr int kBias = 1 << 20;
  return (uint64_t(uint32_t(x + kBias) & 0x1FFFFF) << 42) | (uint64_t(uint32_t(y + kBias) & 0x1FFFFF) << 21) |
         uint64_t(uint32_t(z + kBias) & 0x1FFFFF);
}

Eigen::Vector3i Cell(const Eigen::Vector3f& p, float inv_size) {
  return {int(std::floor(p.x() * inv_size)), int(std::floor(p.y() * inv_size)), int(std::floor(p.z() * inv_size))};
}

// Points bucketed in cubic cells of `size`, for radius queries.
class Grid {
 public:
  Grid(const std::vector<Eigen::Vector3f>& points, float size) : inv_(1.0f / size), order_(points.size()) {
    std::vector<uint64_t> keys(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3i c = Cell(points[i], inv_);
      keys[i] = CellKey(c.x(), c.y(), c.z());
    }
    std::iota(order_.begin(), order_.end(), 0u);
    std::sort(order_.begin(), order_.end(), [&](uint32_t a, uint32_t b) { return keys[a] < keys[b]; });
    for (size_t k = 0; k < order_.size();) {
      size_t e = k;
      while (e < order_.size() && keys[order_[e]] == keys[order_[k]]) ++e;
      ranges_[keys[order_[k]]] = {uint32_t(k), uint32_t(e)};
      k = e;
    }
  }
  // Calls f(index) for the points in the 27 cells around p.
  template <typename F>
  void ForNeighbours(const Eigen::Vector3f& p, F&& f) const {
    const Eigen::Vector3i c = Cell(p, inv_);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = ranges_.find(CellKey(c.x() + dx, c.y() + dy, c.z() + dz));
          if (it == ranges_.end()) continue;
          for (uint32_t k = it->second.first; k < it->second.second; ++k) f(order_[k]);
        }
  }

 private:
  float inv_;
  std::vector<uint32_t> order_;
  std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> ranges_;
};

struct Voxelized {
  std::vector<Eigen::Vector3f> points;
  std::vector<float> weights, seed_weights;
};

}  // namespace

std::vector<Mode> MeanShiftModes(const std::vector<Eigen::Vector3f>& points, const std::vector<float>& weights,
                                 const std::vector<float>& seed_weights, float bandwidth, int max_iterations,
                                 float merge_distance) {
  std::vector<Mode> modes;
  if (points.empty() || !(bandwidth > 0)) return modes;
  // The Gaussian is cut at 3 bandwidths (exp(-9) ~ 1e-4 of the peak).
  const float cutoff = 3.0f * bandwidth, cutoff2 = cutoff * cutoff, inv_b2 = 1.0f / (bandwidth * bandwidth);
  const Grid grid(points, cutoff);
  std::vector<std::pair<Eigen::Vector3f, float>> arrivals;
  // Where earlier seeds converged: a later trajectory that comes within a quarter of the merge
  // distance of one of them would end there too, so it stops and takes that end point (the
  // usual basin-of-attraction shortcut; it changes no mode, only the work).
  std::vector<Eigen::Vector3f> ends;
  const float join2 = 0.0625f * merge_distance * merge_distance;
  for (size_t s = 0; s < points.size(); ++s) {
    if (!(seed_weights[s] > 0)) continue;
    Eigen::Vector3f x = points[s];
    bool joined = false;
    for (int it = 0; it < max_iterations && !joined; ++it) {
      for (const Eigen::Vector3f& e : ends)
        if ((e - x).squaredNorm() < join2) {
          x = e;
          joined = true;
          break;
        }
      if (joined) break;
      Eigen::Vector3f num = Eigen::Vector3f::Zero();
      float den = 0;
      grid.ForNeighbours(x, [&](uint32_t i) {
        const float d2 = (points[i] - x).squaredNorm();
        if (d2 > cutoff2) return;
        const float k = weights[i] * std::exp(-d2 * inv_b2);
        num += k * points[i];
        den += k;
      });
      if (!(den > 0)) break;
      const Eigen::Vector3f next = num / den;
      const float step2 = (next - x).squaredNorm();
      x = next;
      if (step2 < 1e-6f * bandwidth * bandwidth) break;
    }
    if (!joined) ends.push_back(x);
    arrivals.emplace_back(x, seed_weights[s]);
  }
  // Seeds that end within merge_distance of a mode's first arrival belong to that mode; its
  // position is the weight-averaged arrival.
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

JointProbabilities ProbabilitiesFromClassification(const core::DepthImage& depth, const Classification& c) {
  JointProbabilities out;
  out.width = depth.width;
  out.height = depth.height;
  if (c.num_parts != core::kNumParts || c.sums.empty() || c.width != depth.width || c.height != depth.height) return out;
  const float norm = 1.0f / float(core::kLeafTotal * c.num_trees);
  for (uint32_t i = 0; i < uint32_t(depth.pixels.size()); ++i) {
    if (depth.pixels[i] == 0) continue;
    const uint16_t* s = c.sums.data() + size_t(i) * size_t(c.stride);
    std::array<float, core::kNumJoints> p{};
    for (int j = 0; j < core::kNumJoints; ++j) {
      int sum = 0;
      for (int part : core::JointParts(j)) sum += s[part];
      p[size_t(j)] = float(sum) * norm;
    }
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

FrameProposals ProposeJoints(const core::DepthImage& depth, const JointProbabilities& probs,
                             const ProposalOptions& options) {
  FrameProposals out;
  const size_t n = probs.pixel.size();
  if (n == 0 || probs.prob.size() != n || depth.width != probs.width || depth.height != probs.height) return out;
  // Reproject once: 3D point and weight factor d^2 per pixel.
  std::vector<Eigen::Vector3f> points(n);
  std::vector<float> d2(n);
  for (size_t k = 0; k < n; ++k) {
    const uint32_t i = probs.pixel[k];
    const int x = int(i % uint32_t(depth.width)), y = int(i / uint32_t(depth.width));
    const uint16_t d = depth.pixels[i];
    points[k] = options.camera.PixelToPoint(x, y, d).cast<float>();
    d2[k] = float(d) * float(d) * 1e-6f;
  }
  const int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();

#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
  for (int j = 0; j < core::kNumJoints; ++j) {
    const core::JointParams& jp = options.params[size_t(j)];
    auto& proposals = out[size_t(j)];
    auto emit = [&](const Eigen::Vector3f& surface, float confidence) {
      if (!(confidence > 0) || !(surface.z() > 0)) return;
      JointProposal p;
      p.pixel = options.camera.Project(surface.cast<double>()).cast<float>();
      p.position = surface + Eigen::Vector3f(0, 0, jp.z_offset_m);
      p.confidence = confidence;
      proposals.push_back(p);
    };
    if (options.method == ProposalMethod::kMeanShift) {
      Voxelized v;
      const float voxel = jp.bandwidth_m * options.voxel_fraction;
      if (voxel > 0) {
        std::unordered_map<uint64_t, uint32_t> slot;
        std::vector<Eigen::Vector3f> wsum;
        for (size_t k = 0; k < n; ++k) {
          const float p = probs.prob[k][size_t(j)];
          if (!(p > 0) || !std::isfinite(p)) continue;
          const float w = p * d2[k];
          const Eigen::Vector3i c = Cell(points[k], 1.0f / voxel);
          const auto [it, fresh] = slot.try_emplace(CellKey(c.x(), c.y(), c.z()), uint32_t(v.weights.size()));
          if (fresh) {
            v.weights.push_back(0);
            v.seed_weights.push_back(0);
            wsum.push_back(Eigen::Vector3f::Zero());
          }
          v.weights[it->second] += w;
          wsum[it->second] += w * points[k];
          if (p > jp.prob_threshold) v.seed_weights[it->second] += w;
        }
        v.points.resize(wsum.size());
        for (size_t s = 0; s < wsum.size(); ++s) v.points[s] = wsum[s] / v.weights[s];
      } else {
        for (size_t k = 0; k < n; ++k) {
          const float p = probs.prob[k][size_t(j)];
          if (!(p > 0) || !std::isfinite(p)) continue;
          v.points.push_back(points[k]);
          v.weights.push_back(p * d2[k]);
          v.seed_weights.push_back(p > jp.prob_threshold ? p * d2[k] : 0.0f);
        }
      }
      for (const Mode& m : MeanShiftModes(v.points, v.weights, v.seed_weights, jp.bandwidth_m, options.max_iterations,
                                          options.merge_fraction * jp.bandwidth_m))
        emit(m.position, m.confidence);
    } else {
      // Bottom-up clustering: the above-threshold pixels are binned into cubic cells of the
      // joint's bandwidth; face- or corner-adjacent occupied cells form one cluster (so depth
      // jumps at a silhouette's rim do not split a part), whose weighted centroid is the
      // proposal. One pass over the pixels plus one over the occupied cells.
      const float inv_cell = 1.0f / (jp.bandwidth_m * options.cluster_cell_fraction);
      std::unordered_map<uint64_t, uint32_t> slot;
      std::vector<Eigen::Vector3i> cells;
      std::vector<Eigen::Vector3f> wsum;
      std::vector<float> wtot;
      for (size_t k = 0; k < n; ++k) {
        const float p = probs.prob[k][size_t(j)];
        if (!(p > jp.prob_threshold) || !std::isfinite(p)) continue;
        const Eigen::Vector3i c = Cell(points[k], inv_cell);
        const auto [it, fresh] = slot.try_emplace(CellKey(c.x(), c.y(), c.z()), uint32_t(cells.size()));
        if (fresh) {
          cells.push_back(c);
          wsum.push_back(Eigen::Vector3f::Zero());
          wtot.push_back(0);
        }
        const float w = p * d2[k];
        wsum[it->second] += w * points[k];
        wtot[it->second] += w;
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
                const auto it = slot.find(CellKey(cells[c].x() + dx, cells[c].y() + dy, cells[c].z() + dz));
                if (it == slot.end() || done[it->second]) continue;
                done[it->second] = 1;
                stack.push_back(it->second);
              }
        }
        if (cluster_w > 0) emit(cluster_sum / cluster_w, cluster_w);
      }
      std::stable_sort(proposals.begin(), proposals.end(),
                       [](const JointProposal& a, const JointProposal& b) { return a.confidence > b.confidence; });
    }
  }
  return out;
}

}  // namespace poseforest::runtime
