#include "tests/support/synthetic.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "runtime/core/camera.h"
#include "runtime/core/rng.h"

namespace poseforest::testing {

using core::CounterRng;
using core::Forest;
using core::Node;
using core::RngStream;

core::OffsetVotes MakeRandomOffsetVotes(const core::Forest& forest, uint64_t seed, double votes_per_leaf) {
  core::OffsetVotes votes;
  votes.max_offset_m = 0.6f;
  for (int j = 0; j < core::kNumJoints; ++j) votes.bandwidth_m[size_t(j)] = 0.05f + 0.002f * float(j);
  votes.share_edges = {0.0f, 0.1f, 0.3f};
  for (int j = 0; j < core::kNumJoints; ++j) votes.precision.insert(votes.precision.end(), {0.2f, 0.5f, 0.9f});
  const double p_vote = std::clamp(votes_per_leaf / core::kNumJoints, 0.0, 1.0);
  const int max_mm = int(votes.max_offset_m * 1000);
  for (size_t t = 0; t < forest.trees.size(); ++t) {
    RngStream rng(CounterRng(seed, uint64_t(t), 0, 0xF1));
    core::TreeVotes tree;
    tree.first.push_back(0);
    for (uint32_t l = 0; l < forest.trees[t].num_leaves; ++l) {
      for (int j = 0; j < core::kNumJoints; ++j) {
        if (rng.Uniform01() >= p_vote) continue;
        core::JointVote v;
        v.dx_mm = int16_t(rng.UniformIntIn(-max_mm, max_mm));
        v.dy_mm = int16_t(rng.UniformIntIn(-max_mm, max_mm));
        v.dz_mm = int16_t(rng.UniformIntIn(-max_mm, max_mm));
        v.joint = uint8_t(j);
        v.weight = uint8_t(rng.UniformIntIn(1, 255));
        tree.votes.push_back(v);
      }
      tree.first.push_back(uint32_t(tree.votes.size()));
    }
    votes.trees.push_back(std::move(tree));
  }
  return votes;
}

core::Forest MakeRandomForest(const RandomForestSpec& spec) {
  Forest forest;
  forest.num_parts = spec.num_parts;
  forest.part_names = Forest::DefaultPartNames();
  forest.part_names.resize(size_t(spec.num_parts));
  for (int i = core::kNumParts; i < spec.num_parts; ++i) forest.part_names[size_t(i)] = "part" + std::to_string(i);
  const int stride = forest.leaf_stride();
  const int max_off = int(std::lround(spec.max_offset / forest.constants.offset_unit));

  for (int t = 0; t < spec.num_trees; ++t) {
    RngStream rng(CounterRng(spec.seed, uint64_t(t), 0, 0xF0));
    core::Tree tree;
    // Breadth-first: `frontier` holds indices of nodes at the current depth, still undecided.
    tree.nodes.emplace_back();
    std::vector<uint32_t> frontier{0};
    long budget = spec.nodes_per_tree - 1;
    std::vector<float> probs(size_t(spec.num_parts));
    for (int depth = 0; !frontier.empty(); ++depth) {
      const int levels_left = spec.max_depth - depth;
      double p_split = 0;
      if (levels_left > 0) {
        const double per_level = double(std::max(0L, budget)) / levels_left;
        p_split = std::clamp(per_level / (2.0 * double(frontier.size())), 0.0, 1.0);
      }
      std::vector<uint32_t> next;
      bool any_split = false;
      for (size_t k = 0; k < frontier.size(); ++k) {
        const uint32_t i = frontier[k];
        // Force at least one split per level so every tree reaches max_depth.
        const bool last = k + 1 == frontier.size();
        const bool split = levels_left > 0 && (rng.Uniform01() < p_split || (last && !any_split));
        if (split) {
          any_split = true;
          core::FeatureOffsets f;
          f.ux = int16_t(rng.UniformIntIn(-max_off, max_off));
          f.uy = int16_t(rng.UniformIntIn(-max_off, max_off));
          // Half of the features compare against the pixel itself (v = 0), as trained trees do.
          if (rng.Uniform01() < 0.5) {
            f.vx = int16_t(rng.UniformIntIn(-max_off, max_off));
            f.vy = int16_t(rng.UniformIntIn(-max_off, max_off));
          }
          const float tau = float(rng.UniformIn(-400.0, 400.0));
          const auto left = uint32_t(tree.nodes.size());
          tree.nodes[i] = Node::Split(f, tau, left);
          tree.nodes.emplace_back();
          tree.nodes.emplace_back();
          next.push_back(left);
          next.push_back(left + 1);
          budget -= 2;
        } else {
          std::fill(probs.begin(), probs.end(), 0.0f);
          const int k_parts = 1 + int(rng.UniformInt(uint32_t(spec.max_parts_per_leaf)));
          for (int m = 0; m < k_parts; ++m) probs[rng.UniformInt(uint32_t(spec.num_parts))] += float(rng.Uniform01() + 0.05);
          const uint32_t leaf = tree.num_leaves++;
          tree.leaves.resize(size_t(tree.num_leaves) * size_t(stride), 0);
          core::QuantizeDistribution(probs.data(), spec.num_parts, tree.leaves.data() + size_t(leaf) * size_t(stride));
          tree.nodes[i] = Node::Leaf(leaf);
        }
      }
      if (any_split) tree.depth = uint32_t(depth + 1);
      frontier.swap(next);
    }
    forest.trees.push_back(std::move(tree));
  }
  return forest;
}

namespace {

// Distance from p to segment ab.
double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  if (ab.squaredNorm() == 0) return (p - a).norm();  // a sphere
  const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (p - (a + t * ab)).norm();
}

}  // namespace

core::DepthImage MakePersonDepth(double distance_m, int width, int height, double lateral_m, double vertical_m) {
  core::CameraIntrinsics cam;
  cam.width = width;
  cam.height = height;
  cam.cx = (width - 1) / 2.0;
  cam.cy = (height - 1) / 2.0;
  core::DepthImage img(width, height, 0);
  // Capsules in the body plane (metres, x right, y down, centred on the pelvis), with radius.
  struct Capsule {
    Eigen::Vector2d a, b;
    double r;
  };
  const std::vector<Capsule> body = {
      {{0, -0.62}, {0, -0.62}, 0.11},          // head
      {{0, -0.50}, {0, -0.44}, 0.06},          // neck
      {{0, -0.35}, {0, 0.0}, 0.17},            // torso
      {{-0.2, -0.38}, {-0.55, -0.30}, 0.055},  // arms, slightly raised
      {{0.2, -0.38}, {0.55, -0.30}, 0.055},
      {{-0.55, -0.30}, {-0.78, -0.10}, 0.045},
      {{0.55, -0.30}, {0.78, -0.10}, 0.045},
      {{-0.1, 0.05}, {-0.13, 0.50}, 0.08},     // legs
      {{0.1, 0.05}, {0.13, 0.50}, 0.08},
      {{-0.13, 0.50}, {-0.14, 0.92}, 0.06},
      {{0.13, 0.50}, {0.14, 0.92}, 0.06},
  };
  // The body is a height field over the plane z = distance: surface z = distance - bulge(X, Y),
  // bulge = max over capsules of sqrt(r^2 - dist^2). Each pixel's ray t * (dx, dy, 1) meets it
  // where z = distance - bulge(z dx, z dy): a fixed point that a few iterations reach, so the
  // depth and the pixel position agree (a physically consistent surface at any distance).
  auto bulge = [&](double bx, double by) {
    const Eigen::Vector2d p(bx - lateral_m, by - vertical_m);
    double best = 0;
    for (const Capsule& c : body) {
      const double d = SegmentDistance(p, c.a, c.b);
      if (d < c.r) best = std::max(best, std::sqrt(c.r * c.r - d * d));
    }
    return best;
  };
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector3d dir = cam.Unproject(x, y, 1.0);
      double z = distance_m;
      if (bulge(z * dir.x(), z * dir.y()) <= 0) continue;
      for (int it = 0; it < 8; ++it) z = distance_m - bulge(z * dir.x(), z * dir.y());
      if (z < distance_m) img.at(x, y) = uint16_t(std::lround(z * 1000.0));
    }
  }
  return img;
}

core::DepthImage MakeRandomDepth(uint64_t seed, int width, int height, uint16_t min_mm, uint16_t max_mm) {
  RngStream rng(CounterRng(seed, 0, 0, 0xD0));
  core::DepthImage img(width, height, 0);
  const int blobs = 1 + int(rng.UniformInt(8));
  for (int b = 0; b < blobs; ++b) {
    const double cx = rng.UniformIn(0, width), cy = rng.UniformIn(0, height);
    const double rx = rng.UniformIn(2, width / 2.0 + 2), ry = rng.UniformIn(2, height / 2.0 + 2);
    const double base = rng.UniformIn(min_mm, max_mm);
    const double slope = rng.UniformIn(-5, 5);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const double u = (x - cx) / rx, v = (y - cy) / ry;
        if (u * u + v * v <= 1.0) {
          const double d = std::clamp(base + slope * (x - cx), double(min_mm), double(max_mm));
          img.at(x, y) = uint16_t(d);
        }
      }
  }
  // Holes: isolated missing pixels, as at depth discontinuities in Kinect frames.
  const int holes = int(rng.UniformInt(uint32_t(width * height / 20 + 1)));
  for (int h = 0; h < holes; ++h) img.at(int(rng.UniformInt(uint32_t(width))), int(rng.UniformInt(uint32_t(height)))) = 0;
  return img;
}

}  // namespace poseforest::testing
