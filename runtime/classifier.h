#pragma once
// Per-pixel body-part classification (eq. 2): every foreground pixel walks every tree, the
// quantized leaf distributions are summed over trees (an exact integer average), and the most
// likely part is taken. OpenMP across pixels.

#include <cstdint>
#include <vector>

#include "runtime/core/depth_image.h"
#include "runtime/core/forest.h"

namespace poseforest::runtime {

struct ClassifyOptions {
  int num_threads = 0;             ///< OpenMP threads; 0 = all available
  bool want_distributions = false; ///< also fill Classification::sums (dense, W*H*stride)
  /// Also fill Classification::foreground and foreground_sums: the same sums for the
  /// foreground pixels only (what the joint proposals need; ~10x less memory traffic than
  /// the dense array on a VGA frame with one person).
  bool want_foreground_distributions = false;
  /// With want_foreground_distributions: also fill Classification::foreground_leaves (each
  /// foreground pixel's leaf in every tree: what the offset votes read, runtime/joint_votes.h).
  bool want_foreground_leaves = false;
  /// Classify only the pixels of a subsampled grid: x % pixel_stride == 0 and
  /// y % pixel_stride == 0 (2: a quarter of the pixels, as Kinect's tracker ran at 320x240 from a
  /// 640x480 sensor). The features still probe the full-resolution depth, so a grid pixel gets
  /// exactly the result it gets at 1. Every other foreground pixel takes the label of its grid
  /// pixel (x - x % s, y - y % s) when that one is foreground, else core::kBackgroundLabel;
  /// the sums (dense and foreground) exist for the grid pixels only (the dense ones are zero
  /// elsewhere). 1 (default) = every pixel; values below 1 count as 1.
  int pixel_stride = 1;
};

/// Result for one depth image.
struct Classification {
  int width = 0, height = 0;
  int num_parts = 0;
  int num_trees = 0;
  int stride = 0;  ///< entries per pixel in `sums` (Forest::leaf_stride())
  /// ClassifyOptions::pixel_stride it was made with: each classified pixel stands for
  /// pixel_stride^2 pixels (the joint proposals weight it so).
  int pixel_stride = 1;
  /// Most likely part per pixel (ties: lowest part index); core::kBackgroundLabel where the
  /// depth is 0.
  core::LabelImage labels;
  /// If requested: per pixel, `stride` sums of leaf numerators over trees; P(c|I,x) =
  /// sums[pixel*stride + c] / (255 * num_trees). Zero for background pixels.
  std::vector<uint16_t> sums;
  /// If requested (want_foreground_distributions): raster indices y*width+x of the foreground
  /// (depth != 0) pixels in raster order (only the grid's when pixel_stride > 1), and per
  /// foreground pixel k, `stride` sums at foreground_sums[k*stride + c], equal to the dense sums
  /// of that pixel. Empty otherwise.
  std::vector<uint32_t> foreground;
  std::vector<uint16_t> foreground_sums;
  /// If requested (want_foreground_leaves): per foreground pixel k, its leaf index in tree t at
  /// foreground_leaves[k * num_trees + t]. Empty otherwise.
  std::vector<uint32_t> foreground_leaves;

  float Probability(int x, int y, int part) const {
    return float(sums[(size_t(y) * size_t(width) + size_t(x)) * size_t(stride) + size_t(part)]) /
           float(core::kLeafTotal * num_trees);
  }
};

/// Classifies depth images with one validated forest. The forest must outlive the classifier
/// and must have passed core::ValidateForest (the loader guarantees it): the hot loop does no
/// checks. Thread-safe: Classify may run concurrently on different outputs.
class Classifier {
 public:
  explicit Classifier(const core::Forest& forest);

  /// Classifies every foreground pixel of `depth` (any size) into `out` (reusing its storage).
  void Classify(const core::DepthImage& depth, const ClassifyOptions& options, Classification* out) const;

  const core::Forest& forest() const { return forest_; }

 private:
  const core::Forest& forest_;
};

}  // namespace poseforest::runtime
