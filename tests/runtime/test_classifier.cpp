// The optimized classifier against an obviously correct one (one pixel, one tree, one node at
// a time through core::FeatureResponse), on hand-built forests with a known answer and on many
// random forests x random depth images, with every kernel and 1 or 2 threads.

#include <catch2/catch.hpp>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "runtime/classifier.h"
#include "runtime/classifier_internal.h"
#include "runtime/joint_votes.h"
#include "runtime/core/feature.h"
#include "runtime/core/forest.h"
#include "tests/support/synthetic.h"

namespace {

using poseforest::core::DepthImage;
using poseforest::core::FeatureOffsets;
using poseforest::core::Forest;
using poseforest::core::Node;
using poseforest::core::Tree;
using poseforest::runtime::Classification;
using poseforest::runtime::Classifier;
using poseforest::runtime::ClassifyOptions;
using poseforest::runtime::detail::ClassifyWithKernel;
using poseforest::runtime::detail::Kernel;
using poseforest::runtime::detail::KernelAvailable;
namespace core = poseforest::core;
namespace testing = poseforest::testing;

/// The oracle: labels and per-pixel sums, straight from the definitions.
struct Reference {
  core::LabelImage labels;
  std::vector<uint16_t> sums;
};

Reference Classify(const Forest& forest, const DepthImage& depth) {
  const int stride = forest.leaf_stride();
  Reference r;
  r.labels = core::LabelImage(depth.width, depth.height, core::kBackgroundLabel);
  r.sums.assign(size_t(depth.width) * size_t(depth.height) * size_t(stride), 0);
  for (int y = 0; y < depth.height; ++y) {
    for (int x = 0; x < depth.width; ++x) {
      if (depth.at(x, y) == 0) continue;
      uint16_t* sum = r.sums.data() + (size_t(y) * size_t(depth.width) + size_t(x)) * size_t(stride);
      for (const Tree& tree : forest.trees) {
        uint32_t i = 0;
        while (!tree.nodes[i].is_leaf()) {
          const Node& node = tree.nodes[i];
          const int32_t f = core::FeatureResponse(depth, x, y, node.offsets, forest.constants);
          i = f < node.threshold ? node.child : node.child + 1;
        }
        const uint8_t* row = tree.leaf(tree.nodes[i].leaf_index(), stride);
        for (int c = 0; c < stride; ++c) sum[c] = uint16_t(sum[c] + row[c]);
      }
      int best = 0;
      for (int c = 1; c < forest.num_parts; ++c)
        if (sum[c] > sum[best]) best = c;
      r.labels.at(x, y) = uint8_t(best);
    }
  }
  return r;
}

std::vector<Kernel> Kernels() {
  std::vector<Kernel> k{Kernel::kAuto, Kernel::kPortable};
  if (KernelAvailable(Kernel::kAvx512)) k.push_back(Kernel::kAvx512);
  if (KernelAvailable(Kernel::kAvx2)) k.push_back(Kernel::kAvx2);
  return k;
}

/// The oracle's foreground output: raster indices of depth != 0 pixels and their sums.
void ExpectForeground(const Classification& got, const DepthImage& depth, const Reference& want, int stride) {
  std::vector<uint32_t> pixels;
  std::vector<uint16_t> sums;
  for (uint32_t i = 0; i < uint32_t(depth.pixels.size()); ++i) {
    if (depth.pixels[i] == 0) continue;
    pixels.push_back(i);
    sums.insert(sums.end(), want.sums.begin() + std::ptrdiff_t(size_t(i) * size_t(stride)),
                want.sums.begin() + std::ptrdiff_t(size_t(i + 1) * size_t(stride)));
  }
  REQUIRE(got.foreground == pixels);
  REQUIRE(got.foreground_sums == sums);
}

/// Checks every kernel x thread count x want_distributions x want_foreground_distributions
/// against the oracle.
void ExpectMatches(const Forest& forest, const DepthImage& depth, const std::string& what) {
  INFO(what << " (" << depth.width << "x" << depth.height << ", " << forest.trees.size() << " trees, "
            << forest.num_parts << " parts)");
  REQUIRE(core::ValidateForest(forest, what).ok());
  const Reference want = Classify(forest, depth);
  for (Kernel kernel : Kernels()) {
    for (int threads : {1, 2, 3}) {
      for (int mode = 0; mode < 4; ++mode) {
        const bool dist = (mode & 1) != 0, fg = (mode & 2) != 0;
        INFO("kernel " << int(kernel) << ", threads " << threads << ", distributions " << dist << ", foreground "
                       << fg);
        ClassifyOptions options;
        options.num_threads = threads;
        options.want_distributions = dist;
        options.want_foreground_distributions = fg;
        options.want_foreground_leaves = fg && threads != 3;  // the leaves (offset votes), and not
        Classification got;
        ClassifyWithKernel(forest, depth, options, kernel, &got);
        REQUIRE(got.width == depth.width);
        REQUIRE(got.height == depth.height);
        REQUIRE(got.stride == forest.leaf_stride());
        REQUIRE(got.num_trees == int(forest.trees.size()));
        REQUIRE(got.labels.width == depth.width);
        REQUIRE(got.labels.height == depth.height);
        REQUIRE(got.labels.pixels == want.labels.pixels);
        if (dist) {
          REQUIRE(got.sums == want.sums);
        } else {
          REQUIRE(got.sums.empty());
        }
        if (fg) {
          ExpectForeground(got, depth, want, forest.leaf_stride());
          if (options.want_foreground_leaves) {
            // Each foreground pixel's leaf in each tree: the scalar walk's (runtime/joint_votes.h).
            REQUIRE(got.foreground_leaves.size() == got.foreground.size() * forest.trees.size());
            for (size_t k = 0; k < got.foreground.size(); ++k) {
              const int x = int(got.foreground[k] % uint32_t(depth.width)),
                        y = int(got.foreground[k] / uint32_t(depth.width));
              for (size_t t = 0; t < forest.trees.size(); ++t)
                REQUIRE(got.foreground_leaves[k * forest.trees.size() + t] ==
                        poseforest::runtime::LeafOf(forest.trees[t], forest.constants, depth, x, y));
            }
          } else {
            REQUIRE(got.foreground_leaves.empty());
          }
        } else {
          REQUIRE(got.foreground.empty());
          REQUIRE(got.foreground_sums.empty());
        }
      }
    }
  }
  // The public entry point too.
  Classifier classifier(forest);
  Classification got;
  classifier.Classify(depth, ClassifyOptions{0, true}, &got);
  REQUIRE(got.labels.pixels == want.labels.pixels);
  REQUIRE(got.sums == want.sums);
}

Forest EmptyForest(int num_parts) {
  Forest f;
  f.num_parts = num_parts;
  f.part_names = Forest::DefaultPartNames();
  f.part_names.resize(size_t(num_parts));
  for (int i = core::kNumParts; i < num_parts; ++i) f.part_names[size_t(i)] = "p" + std::to_string(i);
  return f;
}

/// Appends a leaf row putting all 255 on `part`.
uint32_t AddLeaf(Tree* tree, int stride, int part) {
  tree->leaves.resize(size_t(tree->num_leaves + 1) * size_t(stride), 0);
  tree->leaves[size_t(tree->num_leaves) * size_t(stride) + size_t(part)] = core::kLeafTotal;
  return tree->num_leaves++;
}

}  // namespace

TEST_CASE("a one-node forest labels every foreground pixel with its leaf", "[classifier]") {
  Forest forest = EmptyForest(core::kNumParts);
  const int stride = forest.leaf_stride();
  Tree tree;
  tree.leaves.assign(size_t(stride), 0);
  tree.leaves[4] = 100;
  tree.leaves[9] = 155;  // argmax 9
  tree.num_leaves = 1;
  tree.nodes.push_back(Node::Leaf(0));
  forest.trees.push_back(tree);
  REQUIRE(core::ValidateForest(forest, "one-node").ok());

  DepthImage depth(5, 3, 1500);
  depth.at(2, 1) = 0;
  for (Kernel kernel : Kernels()) {
    Classification out;
    ClassifyWithKernel(forest, depth, ClassifyOptions{2, true}, kernel, &out);
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 5; ++x) {
        const bool bg = x == 2 && y == 1;
        CHECK(out.labels.at(x, y) == (bg ? core::kBackgroundLabel : 9));
        CHECK(out.Probability(x, y, 9) == Approx(bg ? 0.0 : 155.0 / 255.0));
        CHECK(out.Probability(x, y, 4) == Approx(bg ? 0.0 : 100.0 / 255.0));
      }
  }
  ExpectMatches(forest, depth, "one-node");
}

TEST_CASE("a three-node forest splits on its feature as eq. 1 says", "[classifier]") {
  // Root: f = d(x + u/d(x)) - d(x) with u = 2 pixel*m to the right: at 2 m that is the next
  // column. Left (f < 100 mm) -> part 3, right -> part 7.
  Forest forest = EmptyForest(core::kNumParts);
  const int stride = forest.leaf_stride();
  Tree tree;
  FeatureOffsets u;
  u.ux = int16_t(2.0f / forest.constants.offset_unit);
  tree.nodes.push_back(Node::Split(u, 100.0f, 1));
  tree.nodes.push_back(Node::Leaf(AddLeaf(&tree, stride, 3)));
  tree.nodes.push_back(Node::Leaf(AddLeaf(&tree, stride, 7)));
  tree.depth = 1;
  forest.trees.push_back(tree);
  REQUIRE(core::ValidateForest(forest, "three-node").ok());

  const int w = 9, h = 4;
  DepthImage depth(w, h, 2000);
  for (int y = 0; y < h; ++y) depth.at(5, y) = 0;  // a background column
  depth.at(1, 2) = 2050;                           // small step: f = 50 < 100 for x = 0
  depth.at(7, 3) = 2200;                           // big step: f = 200 for x = 6
  for (Kernel kernel : Kernels()) {
    for (int threads : {1, 2}) {
      Classification out;
      ClassifyWithKernel(forest, depth, ClassifyOptions{threads, false}, kernel, &out);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          INFO("x " << x << " y " << y << " kernel " << int(kernel));
          int want = 3;
          if (x == 5) want = core::kBackgroundLabel;
          if (x == 4 || x == w - 1) want = 7;  // next column is background / off the image
          if (x == 6 && y == 3) want = 7;      // 2200 - 2000 >= 100
          if (x == 7 && y == 3) want = 3;      // 2000 - 2200 < 100
          CHECK(int(out.labels.at(x, y)) == want);
        }
    }
  }
  ExpectMatches(forest, depth, "three-node");
}

TEST_CASE("ties go to the lowest part index", "[classifier]") {
  Forest forest = EmptyForest(5);
  const int stride = forest.leaf_stride();
  for (int t = 0; t < 2; ++t) {
    Tree tree;
    tree.leaves.assign(size_t(stride), 0);
    // Tree 0 puts 255 on part 4, tree 1 on part 2: parts 2 and 4 tie at 255.
    tree.leaves[t == 0 ? 4 : 2] = 255;
    tree.num_leaves = 1;
    tree.nodes.push_back(Node::Leaf(0));
    forest.trees.push_back(tree);
  }
  DepthImage depth(3, 2, 800);
  Classification out;
  for (Kernel kernel : Kernels()) {
    ClassifyWithKernel(forest, depth, ClassifyOptions{1, true}, kernel, &out);
    for (uint8_t l : out.labels.pixels) CHECK(int(l) == 2);
    CHECK(out.Probability(1, 1, 2) == Approx(0.5));
  }
  ExpectMatches(forest, depth, "ties");
}

TEST_CASE("optimized classifier equals the reference on random forests and images", "[classifier]") {
  struct Case {
    testing::RandomForestSpec spec;
    const char* name;
  };
  std::vector<Case> cases;
  auto add = [&](uint64_t seed, int trees, int depth, int nodes, int parts, int max_offset,
                 const char* name) {
    testing::RandomForestSpec s;
    s.seed = seed;
    s.num_trees = trees;
    s.max_depth = depth;
    s.nodes_per_tree = nodes;
    s.num_parts = parts;
    s.max_offset = max_offset;
    cases.push_back({s, name});
  };
  add(11, 3, 4, 20, 31, 129, "small 31 parts");
  add(12, 1, 1, 3, 2, 40, "stump, 2 parts");
  add(13, 2, 8, 300, 16, 60, "16 parts (stride 16)");
  add(14, 4, 12, 3000, 31, 200, "mid, 4 trees");
  add(15, 3, 10, 1500, 40, 129, "40 parts (stride 48)");
  add(16, 3, 16, 20000, 31, 129, "deep");
  add(17, 5, 9, 800, 7, 1000, "long offsets");
  add(18, 2, 10, 1000, 32, 5, "32 parts, short offsets");

  struct Size {
    int w, h;
  };
  const std::vector<Size> sizes = {{1, 1}, {1, 9}, {9, 1}, {2, 3}, {17, 13}, {64, 48}, {33, 201}, {160, 120}};
  uint64_t image_seed = 100;
  // Both probe edges: the kernels' clamp (template) paths against the reference's ProbeDepth.
  const core::ProbeEdge edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);
  INFO("probe edge " << core::ProbeEdgeName(edge));
  for (const Case& c : cases) {
    Forest forest = testing::MakeRandomForest(c.spec);
    forest.constants.edge = edge;
    for (const Size& s : sizes) {
      ++image_seed;
      ExpectMatches(forest, testing::MakeRandomDepth(image_seed, s.w, s.h), c.name);
    }
    // Tiny depths make offsets huge (far off the image); far depths make them sub-pixel.
    ExpectMatches(forest, testing::MakeRandomDepth(++image_seed, 40, 30, 1, 40),
                  std::string(c.name) + ", near");
    ExpectMatches(forest, testing::MakeRandomDepth(++image_seed, 40, 30, 9000, 65535),
                  std::string(c.name) + ", far");
    // A person at the edge of a frame: probes fall off the image and on background.
    ExpectMatches(forest, testing::MakePersonDepth(1.2, 96, 72, 0.5),
                  std::string(c.name) + ", person at edge");
  }
}

TEST_CASE("a big frame with more foreground than one block, 2 threads", "[classifier]") {
  testing::RandomForestSpec spec;
  spec.seed = 21;
  spec.num_trees = 3;
  spec.max_depth = 18;
  spec.nodes_per_tree = 30000;
  Forest forest = testing::MakeRandomForest(spec);
  forest.constants.edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);
  ExpectMatches(forest, testing::MakePersonDepth(2.5, 320, 240), "person 320x240");
  ExpectMatches(forest, testing::MakeRandomDepth(77, 320, 240), "random 320x240");
}

TEST_CASE("outputs are reused across frames of different sizes", "[classifier]") {
  testing::RandomForestSpec spec;
  spec.seed = 31;
  spec.nodes_per_tree = 2000;
  spec.max_depth = 11;
  const Forest forest = testing::MakeRandomForest(spec);
  Classifier classifier(forest);
  Classification out;
  const DepthImage a = testing::MakeRandomDepth(1, 50, 40), b = testing::MakeRandomDepth(2, 23, 7);
  const DepthImage empty;
  classifier.Classify(a, ClassifyOptions{2, true}, &out);
  REQUIRE(out.labels.pixels == Classify(forest, a).labels.pixels);
  classifier.Classify(b, ClassifyOptions{1, false}, &out);
  REQUIRE(out.labels.pixels == Classify(forest, b).labels.pixels);
  REQUIRE(out.sums.empty());
  classifier.Classify(a, ClassifyOptions{2, true}, &out);
  REQUIRE(out.sums == Classify(forest, a).sums);
  classifier.Classify(empty, ClassifyOptions{2, true}, &out);
  REQUIRE(out.width == 0);
  REQUIRE(out.labels.pixels.empty());
  REQUIRE(out.sums.empty());
  // All background.
  const DepthImage zeros(31, 5, 0);
  classifier.Classify(zeros, ClassifyOptions{2, true}, &out);
  for (uint8_t l : out.labels.pixels) REQUIRE(l == core::kBackgroundLabel);
  for (uint16_t v : out.sums) REQUIRE(v == 0);
  // The compact foreground output is reused too: a frame, then one with no foreground.
  classifier.Classify(a, ClassifyOptions{2, false, true}, &out);
  const Reference ra = Classify(forest, a);
  ExpectForeground(out, a, ra, forest.leaf_stride());
  classifier.Classify(zeros, ClassifyOptions{2, false, true}, &out);
  REQUIRE(out.foreground.empty());
  REQUIRE(out.foreground_sums.empty());
  classifier.Classify(b, ClassifyOptions{1, false, false}, &out);
  REQUIRE(out.foreground.empty());
}

TEST_CASE("Classify runs concurrently on different outputs", "[classifier]") {
  testing::RandomForestSpec spec;
  spec.seed = 41;
  spec.nodes_per_tree = 5000;
  spec.max_depth = 14;
  const Forest forest = testing::MakeRandomForest(spec);
  const Classifier classifier(forest);
  const DepthImage frames[2] = {testing::MakePersonDepth(2.0, 160, 120), testing::MakeRandomDepth(5, 97, 61)};
  const Reference want[2] = {Classify(forest, frames[0]), Classify(forest, frames[1])};
  bool ok[2] = {true, true};
  std::vector<std::thread> workers;
  for (int k = 0; k < 2; ++k) {
    workers.emplace_back([&, k] {
      Classification out;
      for (int rep = 0; rep < 5; ++rep) {
        classifier.Classify(frames[k], ClassifyOptions{2, true}, &out);
        ok[k] = ok[k] && out.labels.pixels == want[k].labels.pixels && out.sums == want[k].sums;
      }
    });
  }
  for (std::thread& t : workers) t.join();
  CHECK(ok[0]);
  CHECK(ok[1]);
}

TEST_CASE("the feature is depth invariant in world units", "[classifier][feature]") {
  // A flat wall at depth D with a 300 mm step starting 64 pixel*m / D to the right of x = 10:
  // the offset u = 64 pixel*m reaches the step from x = 10 (and not from x = 9) at every D,
  // because eq. 1 divides the offset by the depth of x.
  core::FeatureConstants c;
  FeatureOffsets f;
  f.ux = int16_t(64.0f / c.offset_unit);
  for (int d_mm : {1000, 2000, 4000}) {
    const int px_offset = 64 * 1000 / d_mm;  // 64, 32, 16 pixels
    DepthImage img(200, 3, uint16_t(d_mm));
    for (int x = 10 + px_offset; x < 200; ++x) img.at(x, 1) = uint16_t(d_mm + 300);
    INFO("depth " << d_mm);
    CHECK(core::FeatureResponse(img, 10, 1, f, c) == 300);
    CHECK(core::FeatureResponse(img, 9, 1, f, c) == 0);
  }
}

TEST_CASE("pixel_stride classifies the grid pixels exactly; the others take their grid pixel's part",
          "[classifier]") {
  testing::RandomForestSpec spec;
  spec.seed = 51;
  spec.num_trees = 3;
  spec.max_depth = 14;
  spec.nodes_per_tree = 5000;
  const Forest forest = testing::MakeRandomForest(spec);
  const int stride = forest.leaf_stride();
  for (const DepthImage& depth :
       {testing::MakePersonDepth(2.5, 160, 120), testing::MakeRandomDepth(61, 67, 45),
        testing::MakePersonDepth(1.2, 97, 71, 0.1)}) {
    const Reference want = Classify(forest, depth);
    const int w = depth.width, h = depth.height;
    for (int s : {2, 3}) {
      // What the grid gives: the reference at grid pixels; off the grid, the grid pixel's
      // label where both are foreground.
      std::vector<uint32_t> fg;
      std::vector<uint16_t> fg_sums, dense(want.sums.size(), 0);
      core::LabelImage labels(w, h, core::kBackgroundLabel);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const size_t i = size_t(y) * size_t(w) + size_t(x);
          const int gx = x - x % s, gy = y - y % s;
          if (depth.pixels[i] == 0 || depth.at(gx, gy) == 0) continue;
          labels.pixels[i] = want.labels.at(gx, gy);
          if (gx != x || gy != y) continue;
          fg.push_back(uint32_t(i));
          const auto row = want.sums.begin() + std::ptrdiff_t(i * size_t(stride));
          fg_sums.insert(fg_sums.end(), row, row + stride);
          std::copy(row, row + stride, dense.begin() + std::ptrdiff_t(i * size_t(stride)));
        }
      REQUIRE(fg.size() > 0);
      REQUIRE(fg.size() * size_t(s * s) < size_t(core::CountForeground(depth)) * 2);  // about 1/s^2
      for (Kernel kernel : Kernels())
        for (int threads : {1, 2}) {
          INFO("stride " << s << ", kernel " << int(kernel) << ", threads " << threads << ", " << w << "x"
                         << h);
          ClassifyOptions options;
          options.num_threads = threads;
          options.want_distributions = true;
          options.want_foreground_distributions = true;
          options.pixel_stride = s;
          Classification got;
          ClassifyWithKernel(forest, depth, options, kernel, &got);
          REQUIRE(got.pixel_stride == s);
          REQUIRE(got.labels.pixels == labels.pixels);
          REQUIRE(got.foreground == fg);
          REQUIRE(got.foreground_sums == fg_sums);
          REQUIRE(got.sums == dense);
          // And back to every pixel with the same output object.
          options.pixel_stride = 1;
          ClassifyWithKernel(forest, depth, options, kernel, &got);
          REQUIRE(got.pixel_stride == 1);
          REQUIRE(got.labels.pixels == want.labels.pixels);
          REQUIRE(got.sums == want.sums);
        }
    }
  }
}
