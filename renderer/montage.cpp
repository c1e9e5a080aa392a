#include "renderer/montage.h"

#include <algorithm>

#include "runtime/core/body_parts.h"

namespace poseforest::renderer {

RgbImage DepthToGrey(const core::DepthImage& depth, int ds) {
  ds = std::max(ds, 1);
  RgbImage out;
  out.width = depth.width / ds;
  out.height = depth.height / ds;
  out.rgb.assign(size_t(out.width) * size_t(out.height) * 3, 0);
  int lo = 65535, hi = 0;
  for (uint16_t d : depth.pixels) {
    if (d) lo = std::min(lo, int(d)), hi = std::max(hi, int(d));
  }
  const double span = std::max(1, hi - lo);
  for (int y = 0; y < out.height; ++y) {
    for (int x = 0; x < out.width; ++x) {
      const uint16_t d = depth.at(x * ds, y * ds);
      if (!d) continue;
      const uint8_t g = uint8_t(255.0 - 195.0 * (d - lo) / span);
      uint8_t* p = &out.rgb[(size_t(y) * size_t(out.width) + size_t(x)) * 3];
      p[0] = p[1] = p[2] = g;
    }
  }
  return out;
}

RgbImage LabelsToColour(const core::LabelImage& labels, int ds) {
  ds = std::max(ds, 1);
  RgbImage out;
  out.width = labels.width / ds;
  out.height = labels.height / ds;
  out.rgb.assign(size_t(out.width) * size_t(out.height) * 3, 0);
  for (int y = 0; y < out.height; ++y) {
    for (int x = 0; x < out.width; ++x) {
      const uint8_t l = labels.at(x * ds, y * ds);
      const core::Rgb c = l < core::kNumParts ? core::PartColour(l) : core::kBackgroundColour;
      uint8_t* p = &out.rgb[(size_t(y) * size_t(out.width) + size_t(x)) * 3];
      p[0] = c.r, p[1] = c.g, p[2] = c.b;
    }
  }
  return out;
}

RgbImage MakeMontage(const std::vector<RenderedFrame>& frames, int cols, int rows, int ds) {
  int fw = 0, fh = 0;
  for (const auto& f : frames) {
    if (!f.depth.empty()) fw = f.depth.width / std::max(ds, 1), fh = f.depth.height / std::max(ds, 1);
  }
  const int gap = 4;
  RgbImage out;
  out.width = cols * (2 * fw + gap) + gap;
  out.height = rows * (fh + gap) + gap;
  out.rgb.assign(size_t(out.width) * size_t(out.height) * 3, 40);
  size_t cell = 0;
  for (const auto& f : frames) {
    if (f.depth.empty() || cell >= size_t(cols * rows)) continue;
    const int cx = int(cell % size_t(cols)), cy = int(cell / size_t(cols));
    ++cell;
    const RgbImage pics[2] = {DepthToGrey(f.depth, ds), LabelsToColour(f.labels, ds)};
    for (int k = 0; k < 2; ++k) {
      const int x0 = gap + cx * (2 * fw + gap) + k * fw, y0 = gap + cy * (fh + gap);
      for (int y = 0; y < fh; ++y) {
        std::copy_n(&pics[k].rgb[size_t(y) * size_t(fw) * 3], size_t(fw) * 3,
                    &out.rgb[((size_t(y0 + y) * size_t(out.width)) + size_t(x0)) * 3]);
      }
    }
  }
  return out;
}

}  // namespace poseforest::renderer
