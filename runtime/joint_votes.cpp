#include "runtime/joint_votes.h"

#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <numeric>

#include "runtime/core/feature.h"
#include "runtime/mean_shift.h"

namespace poseforest::runtime {

uint32_t LeafOf(const core::Tree& tree, const core::FeatureConstants& constants, const core::DepthImage& depth,
                int x, int y) {
  const float scale = core::PixelScale(depth.at(x, y), constants.offset_unit);
  uint32_t n = 0;
  for (;;) {
    const core::Node& node = tree.nodes[n];
    if (node.is_leaf()) return node.leaf_index();
    const int32_t r = core::FeatureResponse(depth.data(), depth.width, depth.height, x, y, scale,
                                            node.offsets, constants.background_mm, constants.edge);
    // As the classifier: left if f < threshold, else right.
    n = node.child + uint32_t(!(float(r) < node.threshold));
  }
}

namespace {

struct Vote {
  Eigen::Vector3f p;
  float w;  ///< > 0
};

// A joint's votes are ranked heaviest first, ties in cast order: a strict total order, so sorting
// by it is stable_sort by weight. Ranked as one integer per vote: the weight's bits (for floats
// >= 0 their order as unsigned integers is the floats' order) above the complement of the cast
// order, larger first. Integer comparisons are branch-free where the floats' (a.w > b.w ||
// (a.w == b.w && ...)) were not; the order is the same.
uint64_t RankKey(float w, uint32_t order) {
  return uint64_t(std::bit_cast<uint32_t>(w)) << 32 | uint32_t(~order);
}
uint32_t OrderOf(uint64_t key) { return ~uint32_t(key); }

// Weighted mean shift (Gaussian kernel, cut at 3 bandwidths) over the votes, whose positions and
// weights are (x, y, z, w), from the first `seeds` (the heaviest); modes merged within half a
// bandwidth; each mode's score is its kernel-weighted sum of vote weights. The kernel sums are
// the proposals' vector kernel (mean_shift.h).
std::vector<std::pair<Eigen::Vector3f, float>> Modes(const std::vector<float>& x, const std::vector<float>& y,
                                                     const std::vector<float>& z, const std::vector<float>& w,
                                                     float bandwidth, int seeds, int iterations) {
  std::vector<std::pair<Eigen::Vector3f, float>> modes;
  if (w.empty() || !(bandwidth > 0)) return modes;
  const float inv = 1.0f / (bandwidth * bandwidth);
  // Beyond 3 bandwidths the kernel is below 1e-4: those votes are skipped.
  const float cut2 = 9.0f * bandwidth * bandwidth;
  const uint32_t all[1][2] = {{0u, uint32_t(w.size())}};
  auto density = [&](const Eigen::Vector3f& q, Eigen::Vector3f* mean) {
    float s[4];
    const float at[3] = {q.x(), q.y(), q.z()};
    detail::KernelSums(x.data(), y.data(), z.data(), w.data(), all, 1, at, cut2, inv, &s[0], &s[1], &s[2], &s[3]);
    if (mean && s[3] > 0) *mean = Eigen::Vector3f(s[0], s[1], s[2]) / s[3];
    return s[3];
  };
  const int n = std::min<int>(seeds, int(w.size()));
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3f at(x[size_t(i)], y[size_t(i)], z[size_t(i)]);
    for (int it = 0; it < iterations; ++it) {
      Eigen::Vector3f next = at;
      if (!(density(at, &next) > 0)) break;
      const float step = (next - at).norm();
      at = next;
      if (step < 1e-3f) break;
    }
    const float score = density(at, nullptr);
    bool merged = false;
    for (auto& [m, s] : modes)
      if ((m - at).norm() < 0.5f * bandwidth) {
        if (score > s) m = at, s = score;
        merged = true;
        break;
      }
    if (!merged) modes.emplace_back(at, score);
  }
  std::stable_sort(modes.begin(), modes.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
  return modes;
}

}  // namespace

namespace {

// `leaves`, when not null, holds each pixel's leaf per tree (pixels.size() x trees); else the
// trees are walked.
PersonVotes Candidates(const core::Forest& forest, const core::OffsetVotes& table, const core::DepthImage& depth,
                       const std::vector<uint32_t>& pixels, const std::vector<uint32_t>* leaves,
                       const core::CameraIntrinsics& camera, const VoteOptions& options) {
  PersonVotes out;
  if (table.trees.size() != forest.trees.size()) return out;
  const size_t num_trees = forest.trees.size();
  const int num_threads = std::max(1, options.threads > 0 ? options.threads : omp_get_max_threads());
  // Reused across calls on this thread. The loops below run on other threads too, which must
  // use this thread's buffers: through these references, not the thread_locals' names.
  // parts[c][j]: chunk c's votes for joint j in cast order (the chunks in order: the joint's).
  thread_local std::vector<std::array<std::vector<Vote>, core::kNumJoints>> this_threads_parts;
  std::vector<std::array<std::vector<Vote>, core::kNumJoints>>& parts = this_threads_parts;
  parts.resize(size_t(num_threads));
  // Casts the votes of pixels [begin, end) into `into`, in cast order (pixel, then tree).
  auto cast = [&](size_t begin, size_t end, std::array<std::vector<Vote>, core::kNumJoints>& into) {
    for (auto& v : into) v.clear();
    // Each (pixel, tree)'s run of votes in the table first: the table is large (megabytes), so
    // these reads miss the cache, and apart they overlap.
    thread_local std::vector<std::array<uint32_t, 2>> runs;
    runs.assign((end - begin) * num_trees, {0u, 0u});
    for (size_t i = begin; i < end; ++i) {
      const uint32_t idx = pixels[i];
      if (depth.pixels[idx] == 0) continue;
      const int x = int(idx % uint32_t(depth.width)), y = int(idx / uint32_t(depth.width));
      for (size_t t = 0; t < num_trees; ++t) {
        const uint32_t leaf =
            leaves ? (*leaves)[i * num_trees + t] : LeafOf(forest.trees[t], forest.constants, depth, x, y);
        const std::vector<uint32_t>& first = table.trees[t].first;
        runs[(i - begin) * num_trees + t] = {first[leaf], first[leaf + 1]};
      }
    }
    // Then the votes, each run's fetched a few runs ahead.
    constexpr size_t kAhead = 8;
    for (size_t i = begin; i < end; ++i) {
      const uint32_t idx = pixels[i];
      const uint16_t d = depth.pixels[idx];
      if (d == 0) continue;
      const int x = int(idx % uint32_t(depth.width)), y = int(idx / uint32_t(depth.width));
      const Eigen::Vector3f point = camera.Unproject(x, y, d * 1e-3).cast<float>();
      const float area = float(d) * float(d) * 1e-6f;  // the pixel's surface, up to fx fy
      for (size_t t = 0; t < num_trees; ++t) {
        const size_t r = (i - begin) * num_trees + t;
        if (r + kAhead < runs.size())
          __builtin_prefetch(table.trees[(r + kAhead) % num_trees].votes.data() + runs[r + kAhead][0]);
        const core::TreeVotes& tv = table.trees[t];
        for (uint32_t k = runs[r][0]; k < runs[r][1]; ++k) {
          const core::JointVote& v = tv.votes[k];
          into[v.joint].push_back(
              {point + Eigen::Vector3f(float(v.dx_mm), float(v.dy_mm), float(v.dz_mm)) * 1e-3f,
               float(v.weight) * (1.0f / 255.0f) * area});
        }
      }
    }
  };
  // One contiguous chunk of pixels per thread, then the joints, one per thread: the result does
  // not depend on how many threads (the chunks join in pixel order).
#pragma omp parallel num_threads(num_threads)
  {
    const size_t n = pixels.size(), chunks = size_t(num_threads);
#pragma omp for schedule(static, 1)
    for (int c = 0; c < num_threads; ++c) cast(n * size_t(c) / chunks, n * size_t(c + 1) / chunks, parts[size_t(c)]);
#pragma omp for schedule(dynamic, 1)
    for (int j = 0; j < core::kNumJoints; ++j) {
      // The joint's votes in cast order (by pointer) and their rank keys; the total weight in
      // that order. Scratch of the thread running this joint, reused across joints and frames.
      thread_local std::vector<const Vote*> vj;
      thread_local std::vector<uint64_t> keys;
      vj.clear();
      keys.clear();
      float total = 0;
      for (const auto& part : parts)
        for (const Vote& v : part[size_t(j)]) {
          keys.push_back(RankKey(v.w, uint32_t(vj.size())));
          vj.push_back(&v);
          total += v.w;
        }
      if (vj.empty()) continue;
      // Heaviest first (ties: cast order), the lightest dropped past the cap: only the kept ones
      // are sorted.
      const size_t keep = std::min(vj.size(), size_t(std::max(1, options.max_votes_per_joint)));
      if (keep < keys.size())
        std::nth_element(keys.begin(), keys.begin() + std::ptrdiff_t(keep), keys.end(), std::greater<>());
      std::sort(keys.begin(), keys.begin() + std::ptrdiff_t(keep), std::greater<>());
      // As structure of arrays for the vector kernel (thread_local: reused across joints and frames).
      thread_local std::vector<float> x, y, z, w;
      x.resize(keep);
      y.resize(keep);
      z.resize(keep);
      w.resize(keep);
      for (size_t k = 0; k < keep; ++k) {
        const Vote& v = *vj[OrderOf(keys[k])];
        x[k] = v.p.x();
        y[k] = v.p.y();
        z[k] = v.p.z();
        w[k] = v.w;
      }
      const float bandwidth = table.bandwidth_m[size_t(j)] * options.bandwidth_scale;
      for (const auto& [m, score] : Modes(x, y, z, w, bandwidth, options.seeds, options.iterations)) {
        if (int(out[size_t(j)].size()) >= options.max_candidates) break;
        VoteCandidate c;
        c.position = m;
        c.share = total > 0 ? std::clamp(score / total, 0.0f, 1.0f) : 0.0f;
        c.confidence = table.Confidence(j, c.share);
        out[size_t(j)].push_back(c);
      }
      std::stable_sort(out[size_t(j)].begin(), out[size_t(j)].end(),
                       [](const VoteCandidate& a, const VoteCandidate& b) { return a.confidence > b.confidence; });
    }
  }
  return out;
}

}  // namespace

std::vector<PersonVotes> CastVotes(const core::Forest& forest, const core::DepthImage& depth,
                                   const core::LabelImage& masks, int num_people,
                                   const core::CameraIntrinsics& camera, const VoteOptions& options,
                                   const Classification* classification) {
  std::vector<PersonVotes> out(size_t(std::max(0, num_people)));
  if (!forest.offset_votes || num_people <= 0 || masks.width != depth.width || masks.height != depth.height)
    return out;
  const size_t num_trees = forest.trees.size();
  if (classification && classification->width == depth.width && classification->height == depth.height &&
      !classification->foreground_leaves.empty() &&
      classification->foreground_leaves.size() == classification->foreground.size() * num_trees) {
    // The classifier's leaves: each person's foreground pixels, every step-th of them.
    std::vector<std::vector<uint32_t>> of(static_cast<size_t>(num_people));
    for (size_t k = 0; k < classification->foreground.size(); ++k) {
      const uint32_t idx = classification->foreground[k];
      const int l = masks.pixels[idx];
      if (l > 0 && l <= num_people && depth.pixels[idx]) of[size_t(l - 1)].push_back(uint32_t(k));
    }
    for (int p = 0; p < num_people; ++p) {
      const auto& ks = of[size_t(p)];
      if (ks.empty()) continue;
      const size_t step = std::max<size_t>(1, ks.size() / size_t(std::max(1, options.target_pixels)));
      std::vector<uint32_t> pixels;
      std::vector<uint32_t> leaves;
      for (size_t i = step / 2; i < ks.size(); i += step) {
        pixels.push_back(classification->foreground[ks[i]]);
        const uint32_t* l = classification->foreground_leaves.data() + size_t(ks[i]) * num_trees;
        leaves.insert(leaves.end(), l, l + num_trees);
      }
      out[size_t(p)] = Candidates(forest, *forest.offset_votes, depth, pixels, &leaves, camera, options);
    }
    return out;
  }
  std::vector<int> count(size_t(num_people) + 1, 0);
  for (size_t i = 0; i < masks.pixels.size(); ++i) {
    const int l = masks.pixels[i];
    if (l > 0 && l <= num_people && depth.pixels[i]) ++count[size_t(l)];
  }
  for (int label = 1; label <= num_people; ++label) {
    if (count[size_t(label)] == 0) continue;
    // A regular grid of about target_pixels pixels over the person.
    const int step = std::max(
        1, int(std::lround(std::sqrt(double(count[size_t(label)]) / std::max(1, options.target_pixels)))));
    std::vector<uint32_t> pixels;
    for (int y = step / 2; y < depth.height; y += step)
      for (int x = step / 2; x < depth.width; x += step) {
        const size_t i = size_t(y) * size_t(depth.width) + size_t(x);
        if (masks.pixels[i] == label && depth.pixels[i]) pixels.push_back(uint32_t(i));
      }
    out[size_t(label - 1)] = Candidates(forest, *forest.offset_votes, depth, pixels, nullptr, camera, options);
  }
  return out;
}

}  // namespace poseforest::runtime
