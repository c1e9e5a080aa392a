#pragma once
// Preview pictures in the style of the paper's Fig. 2: each frame as a pair of depth (grey, near =
// bright) and body parts (core::PartColour), tiled in a grid.

#include <cstdint>
#include <vector>

#include "renderer/scene.h"

namespace poseforest::renderer {

/// An 8-bit RGB picture, row-major, width*height*3 bytes.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
};

/// Depth as grey: foreground scaled between the frame's nearest (255) and farthest (60) depth;
/// background black. `downsample` >= 1 keeps every n-th pixel.
RgbImage DepthToGrey(const core::DepthImage& depth, int downsample = 1);
/// Labels as part colours (background black).
RgbImage LabelsToColour(const core::LabelImage& labels, int downsample = 1);
/// Frames as [depth | labels] pairs in a cols x rows grid (missing cells stay dark grey);
/// frames with empty images are skipped.
RgbImage MakeMontage(const std::vector<RenderedFrame>& frames, int cols, int rows, int downsample);

}  // namespace poseforest::renderer
