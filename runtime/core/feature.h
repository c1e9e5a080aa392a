#pragma once
// The depth-comparison feature of eq. 1:
//   f(I, x) = d(x + u / d(x)) - d(x + v / d(x))
// u, v are offsets in pixel*metres; dividing by the depth at x (metres) gives pixels, so the same
// world-space offset results whatever the person's distance (depth invariance). A probe on
// background (depth 0) reads the large constant `background_mm`; a probe beyond the image's edge
// reads it too (the paper's rule, ProbeEdge::kBackground), or, in a forest trained so
// (ProbeEdge::kClamp), the pixel on the edge nearest to it.
//
// This header is the single definition used by the trainer, the worker and the runtime: the
// rounding below is part of the model, so all of them must compute bit-identical responses.

#include <algorithm>
#include <cstdint>

#include "runtime/core/depth_image.h"

namespace poseforest::core {

/// What a probe beyond the image's edge reads. A forest is trained with one and must run with
/// the same (FeatureConstants::edge; the forest file's PEDG section, format 1.9).
enum class ProbeEdge : uint8_t {
  /// background_mm, as a probe on background (section 3.1 of the paper). A person cut by the
  /// frame then looks to the trees as if their body ended at the edge: a shin cut by the bottom
  /// edge reads like the end of a leg.
  kBackground = 0,
  /// The nearest pixel on the edge (its depth, or background_mm where it has none): the body
  /// goes on past the frame as it meets it. On the main job's renders and the real frames it
  /// places more hidden joints and tracks more real ones (docs/training/probe-edge.md).
  kClamp = 1,
};

/// "background" or "clamp".
inline const char* ProbeEdgeName(ProbeEdge edge) {
  return edge == ProbeEdge::kClamp ? "clamp" : "background";
}

/// Constants of the feature that a forest is trained with (stored in the forest header).
struct FeatureConstants {
  /// Depth read by a probe off the image or on background, millimetres (10 m: beyond any
  /// Kinect reading, so "background" is far behind every body pixel).
  uint16_t background_mm = 10000;
  /// Pixel*metres per stored offset unit. Offsets are int16, so 1/32 gives a range of
  /// +-1024 pixel*m at a resolution far below one pixel.
  float offset_unit = 1.0f / 32.0f;
  /// What a probe beyond the image's edge reads.
  ProbeEdge edge = ProbeEdge::kBackground;
};

/// Stored offsets of one feature theta = (u, v), in units of FeatureConstants::offset_unit.
struct FeatureOffsets {
  int16_t ux = 0, uy = 0, vx = 0, vy = 0;
  bool operator==(const FeatureOffsets&) const = default;
};

/// Pixels per stored offset unit at a pixel of depth `depth_mm` (> 0): offset_unit / d(x)[m].
inline float PixelScale(uint16_t depth_mm, float offset_unit) {
  return offset_unit * 1000.0f / float(depth_mm);
}

/// Rounds an offset in pixels to the nearest integer (halves up), branch-free and bit-exact
/// on every machine (no FMA: the project builds with -ffp-contract=off). Exact rounding for
/// v > -32768.5; further left (only reachable at absurd depths of a few mm) it may be off by
/// one, still deterministically and still far off any image. Defined for |v| < 2^31 - 2^15,
/// which any int16 offset times PixelScale satisfies.
inline int RoundOffset(float v) { return int(v + 32768.5f) - 32768; }

/// Depth read by a probe at (x, y) of a width x height image (both > 0): the stored depth, or
/// background_mm on 0; off the image, background_mm (kBackground) or what the nearest pixel on
/// the edge reads (kClamp).
inline int32_t ProbeDepth(const uint16_t* depth, int width, int height, int x, int y, uint16_t background_mm,
                          ProbeEdge edge) {
  if (edge == ProbeEdge::kClamp && width > 0 && height > 0)
    x = std::clamp(x, 0, width - 1), y = std::clamp(y, 0, height - 1);
  if (unsigned(x) >= unsigned(width) || unsigned(y) >= unsigned(height)) return background_mm;
  const uint16_t d = depth[y * width + x];
  return d != 0 ? int32_t(d) : int32_t(background_mm);
}

/// Eq. 1 at pixel (x, y) whose own depth gives `scale` = PixelScale(d(x), offset_unit).
/// Returns a depth difference in millimetres.
inline int32_t FeatureResponse(const uint16_t* depth, int width, int height, int x, int y, float scale,
                               const FeatureOffsets& f, uint16_t background_mm, ProbeEdge edge) {
  const int ux = x + RoundOffset(float(f.ux) * scale), uy = y + RoundOffset(float(f.uy) * scale);
  const int vx = x + RoundOffset(float(f.vx) * scale), vy = y + RoundOffset(float(f.vy) * scale);
  return ProbeDepth(depth, width, height, ux, uy, background_mm, edge) -
         ProbeDepth(depth, width, height, vx, vy, background_mm, edge);
}

/// Convenience: eq. 1 at a foreground pixel (x, y) of `image` (its depth must be non-zero).
inline int32_t FeatureResponse(const DepthImage& image, int x, int y, const FeatureOffsets& f,
                               const FeatureConstants& c) {
  const float scale = PixelScale(image.at(x, y), c.offset_unit);
  return FeatureResponse(image.data(), image.width, image.height, x, y, scale, f, c.background_mm, c.edge);
}

}  // namespace poseforest::core
