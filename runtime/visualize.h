#pragma once
// Pictures of results for people: depth as grey, parts in their colours, joint proposals as
// markers, and front/side/top views of the point cloud with the joints, like Fig. 5 of the paper;
// precision-recall curves (Fig. 7's metric) with axis labels in a tiny built-in 5x7 bitmap font,
// so the runtime needs no font library.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"
#include "runtime/joint_metrics.h"
#include "runtime/joint_proposals.h"
#include "runtime/skeleton.h"

namespace poseforest::runtime {

/// An 8-bit RGB picture, row-major, 3 bytes per pixel.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;
  RgbImage() = default;
  RgbImage(int w, int h, uint8_t grey = 0) : width(w), height(h), rgb(size_t(w) * size_t(h) * 3, grey) {}
  void Set(int x, int y, core::Rgb c) {
    if (x < 0 || y < 0 || x >= width || y >= height) return;
    uint8_t* p = &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3];
    p[0] = c.r, p[1] = c.g, p[2] = c.b;
  }
};

/// Depth as grey (near = bright; background black), scaled over the frame's depth range.
RgbImage DepthPicture(const core::DepthImage& depth);
/// Part colours (core::PartColour), background black.
RgbImage PartsPicture(const core::LabelImage& labels);
/// Draws each joint's proposals with confidence >= min_confidence as a ring in the joint's
/// colour (the colour of its first part); the most confident one larger.
void DrawProposals(RgbImage& picture, const FrameProposals& proposals, float min_confidence,
                   float scale = 1.0f);

/// The paper's Fig. 5 layout, 2 x 3 panels of the frame's size / 2: depth, parts, parts with
/// joints; front, side (from the right) and top views of the foreground point cloud coloured by
/// part, with the most confident proposal of each joint (confidence >= min_confidence).
RgbImage PoseFigure(const core::DepthImage& depth, const core::LabelImage& labels,
                    const FrameProposals& proposals, const core::CameraIntrinsics& camera,
                    float min_confidence);

/// A colour per person id (8 distinct ones, then repeating); the same in pictures and markers.
core::Rgb PersonColour(int id);
/// Skeletons drawn on a picture of the frame (pixel coordinates x `scale`, then + (ox, oy)):
/// bones (SkeletonBones) between tracked joints as lines in the person's colour, tracked joints
/// as discs in the joint's colour ringed white, inferred joints (JointState::kInferred) as hollow
/// circles of the same size in the joint's colour with no bones to them, other joints found but
/// not tracked as small grey discs ringed white, and "ID n" above the person's highest tracked
/// joint. With a frame size (frame_width > 0), joints placed beyond the frame
/// (SkeletonOptions::votes_beyond_frame) are not drawn: they would land on a neighbouring panel.
void DrawSkeletons(RgbImage& picture, const std::vector<Skeleton>& skeletons, float scale = 1.0f, int ox = 0,
                   int oy = 0, int frame_width = 0, int frame_height = 0);
/// `live`'s picture: depth | parts | depth with the skeletons, side by side, each panel the
/// frame's size divided by `factor` (1 = full size).
RgbImage SkeletonFigure(const core::DepthImage& depth, const core::LabelImage& labels,
                        const std::vector<Skeleton>& skeletons, int factor = 1);

/// A line `thick` pixels wide (square pen), clipped to the picture.
void DrawLine(RgbImage& picture, float x0, float y0, float x1, float y1, core::Rgb colour, int thick = 1);
/// Writes `text` with the built-in 5x7 font (6 x 8 pixels per character at scale 1), top-left
/// corner at (x, y). Letters are drawn upper case; characters outside A-Z 0-9 . , - _ : / ( ) = %
/// + are drawn as blanks.
void DrawText(RgbImage& picture, int x, int y, std::string_view text, core::Rgb colour, int scale = 1);
/// Width in pixels of `text` drawn at `scale`.
int TextWidth(std::string_view text, int scale = 1);

/// One precision-recall curve of a plot.
struct PrSeries {
  std::string name;  ///< legend text
  core::Rgb colour;
  std::vector<PrPoint> curve;  ///< recall rising (as JointApEvaluator::Curve returns it)
  double ap = 0;               ///< printed in the panel
};

/// One plot: a title (e.g. the joint's name) and its curves.
struct PrPanel {
  std::string title;
  std::vector<PrSeries> series;
};

/// Precision (vertical) against recall (horizontal), both 0..1 with a 0.2 grid, one panel per
/// entry in `columns` columns, each panel_w x panel_h pixels, with a legend of the first
/// panel's series names on top. Each panel lists its series' AP.
RgbImage PrCurvesFigure(const std::vector<PrPanel>& panels, int columns, int panel_w = 260, int panel_h = 230,
                        int scale = 1);

}  // namespace poseforest::runtime
