#pragma once
// Depth and label images. Depth is uint16 millimetres with 0 = no reading / background, the
// convention of Kinect v1 drivers (libfreenect, OpenNI) and of our renderer.

#include <cstdint>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::core {

/// A row-major image of T. Pixel (x, y): x = column in [0, width), y = row in [0, height).
template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  std::vector<T> pixels;  ///< width * height values, row-major

  Image() = default;
  Image(int w, int h, T fill = T{}) : width(w), height(h), pixels(size_t(w) * size_t(h), fill) {}

  bool empty() const { return pixels.empty(); }
  bool InBounds(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  T& at(int x, int y) { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
  const T& at(int x, int y) const { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
  T* data() { return pixels.data(); }
  const T* data() const { return pixels.data(); }
};

/// Depth in millimetres; 0 means no reading (background, shadow, out of range).
using DepthImage = Image<uint16_t>;
/// Body-part label per pixel: 0..kNumParts-1, or kBackgroundLabel.
using LabelImage = Image<uint8_t>;

/// Label of pixels that are not on a body.
inline constexpr uint8_t kBackgroundLabel = 255;

/// Number of foreground (non-zero) pixels.
inline int CountForeground(const DepthImage& depth) {
  int n = 0;
  for (uint16_t d : depth.pixels) n += d != 0;
  return n;
}

}  // namespace poseforest::core
