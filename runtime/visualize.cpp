#include "runtime/visualize.h"

#include <algorithm>
#include <cmath>

namespace poseforest::runtime {
namespace {

core::Rgb JointColour(int joint) { return core::PartColour(core::JointParts(joint).front()); }

void Ring(RgbImage& img, float cx, float cy, float r, core::Rgb c) {
  const int x0 = int(std::floor(cx - r - 1)), x1 = int(std::ceil(cx + r + 1));
  const int y0 = int(std::floor(cy - r - 1)), y1 = int(std::ceil(cy + r + 1));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const float d = std::hypot(float(x) - cx, float(y) - cy);
      if (d <= r + 0.5f && d >= r - 1.5f) img.Set(x, y, {255, 255, 255});
      else if (d < r - 1.5f) img.Set(x, y, c);
    }
}

// Copies `src` into `dst` at (ox, oy), shrunk by an integer factor (nearest).
void Blit(RgbImage& dst, const RgbImage& src, int ox, int oy, int factor) {
  for (int y = 0; y < src.height / factor; ++y)
    for (int x = 0; x < src.width / factor; ++x) {
      const uint8_t* p = &src.rgb[(size_t(y * factor) * size_t(src.width) + size_t(x * factor)) * 3];
      dst.Set(ox + x, oy + y, {p[0], p[1], p[2]});
    }
}

}  // namespace

RgbImage DepthPicture(const core::DepthImage& depth) {
  RgbImage img(depth.width, depth.height);
  uint16_t lo = 65535, hi = 0;
  for (uint16_t d : depth.pixels)
    if (d) lo = std::min(lo, d), hi = std::max(hi, d);
  const float span = hi > lo ? float(hi - lo) : 1.0f;
  for (int y = 0; y < depth.height; ++y)
    for (int x = 0; x < depth.width; ++x)
      if (const uint16_t d = depth.at(x, y)) {
        const auto g = uint8_t(255 - int(175.0f * float(d - lo) / span));
        img.Set(x, y, {g, g, g});
      }
  return img;
}

RgbImage PartsPicture(const core::LabelImage& labels) {
  RgbImage img(labels.width, labels.height);
  for (int y = 0; y < labels.height; ++y)
    for (int x = 0; x < labels.width; ++x)
      if (const uint8_t l = labels.at(x, y); l < core::kNumParts) img.Set(x, y, core::PartColour(l));
  return img;
}

void DrawProposals(RgbImage& picture, const FrameProposals& proposals, float min_confidence, float scale) {
  for (int j = 0; j < core::kNumJoints; ++j) {
    const auto& list = proposals[size_t(j)];
    for (size_t k = list.size(); k-- > 0;) {  // most confident drawn last, on top
      if (list[k].confidence < min_confidence) continue;
      Ring(picture, list[k].pixel.x() * scale, list[k].pixel.y() * scale, k == 0 ? 5.0f : 3.0f, JointColour(j));
    }
  }
}

RgbImage PoseFigure(const core::DepthImage& depth, const core::LabelImage& labels, const FrameProposals& proposals,
                    const core::CameraIntrinsics& camera, float min_confidence) {
  const int pw = depth.width / 2, ph = depth.height / 2;
  RgbImage fig(3 * pw, 2 * ph, 24);
  Blit(fig, DepthPicture(depth), 0, 0, 2);
  const RgbImage parts = PartsPicture(labels);
  Blit(fig, parts, pw, 0, 2);
  RgbImage overlay = DepthPicture(depth);
  DrawProposals(overlay, proposals, min_confidence);
  Blit(fig, overlay, 2 * pw, 0, 2);

  // Point cloud views: orthographic, a common scale fitted to the cloud's extent.
  std::vector<Eigen::Vector3f> pts;
  std::vector<core::Rgb> cols;
  for (int y = 0; y < depth.height; y += 2)
    for (int x = 0; x < depth.width; x += 2)
      if (const uint16_t d = depth.at(x, y)) {
        pts.push_back(camera.PixelToPoint(x, y, d).cast<float>());
        const uint8_t l = labels.at(x, y);
        cols.push_back(l < core::kNumParts ? core::PartColour(l) : core::Rgb{128, 128, 128});
      }
  if (pts.empty()) return fig;
  Eigen::Vector3f lo = pts[0], hi = pts[0];
  for (const auto& p : pts) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Eigen::Vector3f centre = (lo + hi) / 2;
  const float extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z(), 0.5f}) * 1.15f;
  const float s = float(std::min(pw, ph)) / extent;
  // Each view maps a point to panel (u, v): front = (x, y), side from the right = (-z, y),
  // top = (x, z) with the camera at the bottom.
  auto view = [&](int panel, const Eigen::Vector3f& p) -> Eigen::Vector2f {
    const Eigen::Vector3f q = p - centre;
    Eigen::Vector2f uv;
    if (panel == 0) uv = {q.x(), q.y()};
    else if (panel == 1) uv = {-q.z(), q.y()};
    else uv = {q.x(), -q.z()};
    return {float(panel * pw) + pw / 2.0f + uv.x() * s, float(ph) + ph / 2.0f + uv.y() * s};
  };
  for (int panel = 0; panel < 3; ++panel) {
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector2f uv = view(panel, pts[i]);
      const int u = int(uv.x()), v = int(uv.y());
      if (u >= panel * pw && u < (panel + 1) * pw && v >= ph && v < 2 * ph) fig.Set(u, v, cols[i]);
    }
    for (int j = 0; j < core::kNumJoints; ++j) {
      const auto& list = proposals[size_t(j)];
      if (list.empty() || list[0].confidence < min_confidence) continue;
      const Eigen::Vector2f uv = view(panel, list[0].position);
      Ring(fig, uv.x(), uv.y(), 4.0f, JointColour(j));
    }
  }
  return fig;
}

}  // namespace poseforest::runtime
