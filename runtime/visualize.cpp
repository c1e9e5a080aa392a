#include "runtime/visualize.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace poseforest::runtime {
namespace {

core::Rgb JointColour(int joint) { return core::PartColour(core::JointParts(joint).front()); }

void Ring(RgbImage& img, float cx, float cy, float r, core::Rgb c) {
  const int x0 = int(std::floor(cx - r - 1)), x1 = int(std::ceil(cx + r + 1));
  const int y0 = int(std::floor(cy - r - 1)), y1 = int(std::ceil(cy + r + 1));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const float d = std::hypot(float(x) - cx, float(y) - cy);
      if (d <= r + 0.5f && d >= r - 1.5f)
        img.Set(x, y, {255, 255, 255});
      else if (d < r - 1.5f)
        img.Set(x, y, c);
    }
}

// A hollow circle: only the rim (2 pixels wide) in `c`; what lies inside stays visible.
void Circle(RgbImage& img, float cx, float cy, float r, core::Rgb c) {
  const int x0 = int(std::floor(cx - r - 1)), x1 = int(std::ceil(cx + r + 1));
  const int y0 = int(std::floor(cy - r - 1)), y1 = int(std::ceil(cy + r + 1));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const float d = std::hypot(float(x) - cx, float(y) - cy);
      if (d <= r + 0.5f && d >= r - 1.5f) img.Set(x, y, c);
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

// The 5x7 font: 7 rows per glyph, bit 4 = leftmost column.
struct Glyph {
  char c;
  uint8_t rows[7];
};
constexpr Glyph kFont[] = {
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}}, {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}}, {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}}, {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}}, {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}}, {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'A', {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}}, {'B', {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}},
    {'C', {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}}, {'D', {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}},
    {'E', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F}}, {'F', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}},
    {'G', {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}}, {'H', {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'I', {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}}, {'J', {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},
    {'K', {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}}, {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}},
    {'M', {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11}}, {'N', {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}},
    {'O', {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}}, {'P', {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}},
    {'Q', {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D}}, {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}},
    {'S', {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}}, {'T', {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'U', {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}}, {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}}, {'X', {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}},
    {'Y', {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04}}, {'Z', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}}, {',', {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08}},
    {'-', {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}}, {'_', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F}},
    {':', {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00}}, {'/', {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00}},
    {'(', {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}}, {')', {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}},
    {'=', {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00}}, {'%', {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}},
    {'+', {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00}},
};

const Glyph* FindGlyph(char c) {
  if (c >= 'a' && c <= 'z') c = char(c - 'a' + 'A');
  for (const Glyph& g : kFont)
    if (g.c == c) return &g;
  return nullptr;
}

void FillRect(RgbImage& img, int x0, int y0, int w, int h, core::Rgb c) {
  for (int y = y0; y < y0 + h; ++y)
    for (int x = x0; x < x0 + w; ++x) img.Set(x, y, c);
}

// A line `thick` pixels wide (square pen), clipped by RgbImage::Set.
void Line(RgbImage& img, float x0, float y0, float x1, float y1, core::Rgb c, int thick) {
  const int steps = std::max(1, int(std::ceil(std::max(std::abs(x1 - x0), std::abs(y1 - y0)))));
  for (int i = 0; i <= steps; ++i) {
    const float t = float(i) / float(steps);
    const int x = int(std::lround(x0 + (x1 - x0) * t)), y = int(std::lround(y0 + (y1 - y0) * t));
    FillRect(img, x - thick / 2, y - thick / 2, thick, thick, c);
  }
}

}  // namespace

void DrawLine(RgbImage& picture, float x0, float y0, float x1, float y1, core::Rgb colour, int thick) {
  Line(picture, x0, y0, x1, y1, colour, thick);
}

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
      Ring(picture, list[k].pixel.x() * scale, list[k].pixel.y() * scale, k == 0 ? 5.0f : 3.0f,
           JointColour(j));
    }
  }
}

RgbImage PoseFigure(const core::DepthImage& depth, const core::LabelImage& labels,
                    const FrameProposals& proposals, const core::CameraIntrinsics& camera,
                    float min_confidence) {
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
    if (panel == 0)
      uv = {q.x(), q.y()};
    else if (panel == 1)
      uv = {-q.z(), q.y()};
    else
      uv = {q.x(), -q.z()};
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

void DrawText(RgbImage& picture, int x, int y, std::string_view text, core::Rgb colour, int scale) {
  for (size_t i = 0; i < text.size(); ++i) {
    const Glyph* g = FindGlyph(text[i]);
    if (!g) continue;
    const int ox = x + int(i) * 6 * scale;
    for (int r = 0; r < 7; ++r)
      for (int col = 0; col < 5; ++col)
        if (g->rows[r] & (0x10 >> col))
          FillRect(picture, ox + col * scale, y + r * scale, scale, scale, colour);
  }
}

int TextWidth(std::string_view text, int scale) {
  return text.empty() ? 0 : (int(text.size()) * 6 - 1) * scale;
}

RgbImage PrCurvesFigure(const std::vector<PrPanel>& panels, int columns, int panel_w, int panel_h,
                        int scale) {
  columns = std::max(1, columns);
  const int rows = std::max(1, int((panels.size() + size_t(columns) - 1) / size_t(columns)));
  const int legend_h = 14 * scale;
  RgbImage fig(columns * panel_w, legend_h + rows * panel_h, 255);
  const core::Rgb black{0, 0, 0}, grid{215, 215, 215}, dark{90, 90, 90};
  // Legend: the first panel's series.
  if (!panels.empty()) {
    int x = 8 * scale;
    for (const PrSeries& s : panels[0].series) {
      FillRect(fig, x, 3 * scale, 12 * scale, 7 * scale, s.colour);
      x += 16 * scale;
      DrawText(fig, x, 3 * scale, s.name, black, scale);
      x += TextWidth(s.name, scale) + 14 * scale;
    }
  }
  const int left = 30 * scale, right = 10 * scale, top = 26 * scale, bottom = 24 * scale;
  for (size_t k = 0; k < panels.size(); ++k) {
    const PrPanel& panel = panels[k];
    const int ox = int(k % size_t(columns)) * panel_w, oy = legend_h + int(k / size_t(columns)) * panel_h;
    const int pw = panel_w - left - right, ph = panel_h - top - bottom;
    const int x0 = ox + left, y0 = oy + top;  // the plot area's top-left; recall 0, precision 1
    auto px = [&](double recall) { return float(x0) + float(recall) * float(pw); };
    auto py = [&](double precision) { return float(y0 + ph) - float(precision) * float(ph); };
    for (int i = 0; i <= 5; ++i) {
      Line(fig, px(i * 0.2), py(0), px(i * 0.2), py(1), grid, 1);
      Line(fig, px(0), py(i * 0.2), px(1), py(i * 0.2), grid, 1);
    }
    Line(fig, px(0), py(0), px(1), py(0), black, 1);
    Line(fig, px(0), py(0), px(0), py(1), black, 1);
    for (const char* t : {"0", "0.5", "1"}) {
      const double v = std::atof(t);
      DrawText(fig, int(px(v)) - TextWidth(t, scale) / 2, y0 + ph + 4 * scale, t, dark, scale);
      DrawText(fig, x0 - TextWidth(t, scale) - 4 * scale, int(py(v)) - 3 * scale, t, dark, scale);
    }
    DrawText(fig, x0 + pw / 2 - TextWidth("RECALL", scale) / 2, y0 + ph + 14 * scale, "RECALL", dark, scale);
    DrawText(fig, ox + 3 * scale, y0 - 11 * scale, "P", dark, scale);
    DrawText(fig, x0, oy + 3 * scale, panel.title, black, scale);
    // Each series' AP in its colour, right of the title.
    std::string aps;
    int tx = ox + panel_w - right;
    for (size_t s = panel.series.size(); s-- > 0;) {
      char buf[16];
      std::snprintf(buf, sizeof buf, " %.3f", panel.series[s].ap);
      tx -= TextWidth(buf, scale) + scale;
      DrawText(fig, tx, oy + 14 * scale, buf, panel.series[s].colour, scale);
    }
    DrawText(fig, x0, oy + 14 * scale, "AP", dark, scale);
    for (const PrSeries& s : panel.series) {
      // Start at the first point's precision on the recall-0 axis, then point to point.
      float lx = -1, ly = -1;
      for (const PrPoint& p : s.curve) {
        const float x = px(std::clamp(p.recall, 0.0, 1.0)), y = py(std::clamp(p.precision, 0.0, 1.0));
        if (lx < 0) lx = px(0), ly = y;
        Line(fig, lx, ly, x, y, s.colour, 2 * scale);
        lx = x, ly = y;
      }
    }
  }
  return fig;
}

core::Rgb PersonColour(int id) {
  static constexpr core::Rgb kColours[] = {{255, 64, 64},  {64, 160, 255}, {64, 220, 64}, {255, 200, 0},
                                           {220, 64, 255}, {0, 220, 220},  {255, 128, 0}, {255, 255, 255}};
  return kColours[size_t((id % 8 + 8) % 8)];
}

void DrawSkeletons(RgbImage& picture, const std::vector<Skeleton>& skeletons, float scale, int ox, int oy,
                   int frame_width, int frame_height) {
  const int thick = std::max(2, int(std::lround(4 * scale)));
  for (const Skeleton& s : skeletons) {
    auto at = [&](int j) {
      const auto& p = s.joints[size_t(j)].pixel;
      return Eigen::Vector2f(p.x() * scale + float(ox), p.y() * scale + float(oy));
    };
    for (const auto& [a, b] : SkeletonBones()) {
      if (!s.joints[size_t(a)].tracked || !s.joints[size_t(b)].tracked) continue;
      const auto pa = at(a), pb = at(b);
      Line(picture, pa.x(), pa.y(), pb.x(), pb.y(), PersonColour(s.id), thick);
    }
    float top_y = 1e9f, top_x = 0;
    for (int j = 0; j < core::kNumJoints; ++j) {
      const SkeletonJoint& joint = s.joints[size_t(j)];
      if (!joint.found) continue;
      if (frame_width > 0 && !PixelInImage(joint.pixel, frame_width, frame_height)) continue;
      const auto p = at(j);
      switch (StateOf(joint)) {
        case JointState::kTracked:
          Ring(picture, p.x(), p.y(), std::max(2.5f, 5.0f * scale), JointColour(j));
          if (p.y() < top_y) top_y = p.y(), top_x = p.x();
          break;
        case JointState::kInferred:  // hidden, placed by the votes: hollow, no bones
          Circle(picture, p.x(), p.y(), std::max(2.5f, 5.0f * scale), JointColour(j));
          break;
        case JointState::kNotTracked:
          Ring(picture, p.x(), p.y(), std::max(1.5f, 3.0f * scale), {110, 110, 110});
          break;
      }
    }
    if (top_y < 1e9f) {
      const std::string label = "ID " + std::to_string(s.id);
      DrawText(picture, int(top_x) - TextWidth(label, 2) / 2, int(top_y) - 28, label, PersonColour(s.id), 2);
    }
  }
}

RgbImage SkeletonFigure(const core::DepthImage& depth, const core::LabelImage& labels,
                        const std::vector<Skeleton>& skeletons, int factor) {
  factor = std::max(1, factor);
  const int pw = depth.width / factor, ph = depth.height / factor;
  RgbImage fig(3 * pw, ph, 0);
  const RgbImage grey = DepthPicture(depth);
  Blit(fig, grey, 0, 0, factor);
  if (labels.width == depth.width && labels.height == depth.height)
    Blit(fig, PartsPicture(labels), pw, 0, factor);
  Blit(fig, grey, 2 * pw, 0, factor);
  DrawSkeletons(fig, skeletons, 1.0f / float(factor), 2 * pw, 0, depth.width, depth.height);
  for (int y = 0; y < ph; ++y)  // panel separators
    for (int k = 1; k < 3; ++k) fig.Set(k * pw, y, {60, 60, 60});
  return fig;
}

}  // namespace poseforest::runtime
