#include "renderer/scene.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "runtime/core/rng.h"

namespace poseforest::renderer {
namespace {
using J = SkelJoint;
const Eigen::Vector3d& At(const SkelPositions& s, J j) { return s[size_t(int(j))]; }
}  // namespace

std::array<Eigen::Vector3d, core::kNumJoints> EvalJoints(const SkelPositions& p) {
  using core::Joint;
  std::array<Eigen::Vector3d, core::kNumJoints> out;
  auto set = [&](Joint j, const Eigen::Vector3d& v) { out[size_t(int(j))] = v; };
  set(Joint::kHead, 0.5 * (At(p, J::kHead) + At(p, J::kHeadTop)));
  set(Joint::kNeck, 0.5 * (At(p, J::kNeck) + At(p, J::kHead)));
  set(Joint::kLShoulder, At(p, J::kLShoulder));
  set(Joint::kRShoulder, At(p, J::kRShoulder));
  set(Joint::kLElbow, At(p, J::kLElbow));
  set(Joint::kRElbow, At(p, J::kRElbow));
  set(Joint::kLWrist, At(p, J::kLWrist));
  set(Joint::kRWrist, At(p, J::kRWrist));
  set(Joint::kLHand, 0.5 * (At(p, J::kLWrist) + At(p, J::kLHandTip)));
  set(Joint::kRHand, 0.5 * (At(p, J::kRWrist) + At(p, J::kRHandTip)));
  set(Joint::kLKnee, At(p, J::kLKnee));
  set(Joint::kRKnee, At(p, J::kRKnee));
  set(Joint::kLAnkle, At(p, J::kLAnkle));
  set(Joint::kRAnkle, At(p, J::kRAnkle));
  set(Joint::kLFoot, 0.5 * (At(p, J::kLAnkle) + At(p, J::kLToe)));
  set(Joint::kRFoot, 0.5 * (At(p, J::kRAnkle) + At(p, J::kRToe)));
  return out;
}

uint16_t QuantizeDepthMm(const NoiseConfig& noise, double depth_mm) {
  if (depth_mm <= 0) return 0;
  const double fb = noise.focal_px * noise.baseline_m;  // pixel-metres
  const double steps = noise.subpixel_steps;
  const double disparity = fb / (depth_mm * 1e-3);  // pixels
  const double dq = std::max(1.0, std::round(disparity * steps)) / steps;
  return uint16_t(std::clamp(std::round(fb / dq * 1e3), 0.0, 65535.0));
}

void ApplyProjectorShadow(const NoiseConfig& noise, core::DepthImage* depth, core::LabelImage* labels) {
  const int w = depth->width, h = depth->height;
  // The projector at x = side * b sees camera pixel u of depth z at its own column
  // u_p = u - side * f * b / z (pixels). Along a row, a lit surface has u_p rising with u (side
  // +1); a pixel whose u_p falls behind one already seen nearer the projector's side is hidden
  // from the projector by that nearer surface. Scan from the projector's side inward.
  const double fb_px_mm = noise.focal_px * noise.baseline_m * 1e3;  // pixels * mm
  constexpr double kSlackPx = 0.5;  // depth is whole millimetres: keep sub-pixel rounding lit
  const int side = noise.projector_side;
  for (int y = 0; y < h; ++y) {
    uint16_t* d = depth->data() + size_t(y) * size_t(w);
    uint8_t* l = labels->data() + size_t(y) * size_t(w);
    double edge = side > 0 ? 1e30 : -1e30;  // the lowest (side +1) / highest u_p seen so far
    for (int k = 0; k < w; ++k) {
      const int x = side > 0 ? w - 1 - k : k;
      if (d[x] == 0) continue;
      const double up = double(x) - double(side) * fb_px_mm / double(d[x]);
      if (side > 0 ? up > edge + kSlackPx : up < edge - kSlackPx) {
        d[x] = 0;
        l[x] = core::kBackgroundLabel;
      } else {
        edge = side > 0 ? std::min(edge, up) : std::max(edge, up);
      }
    }
  }
}

void ApplyKinectNoise(const NoiseConfig& noise, uint64_t key, core::DepthImage* depth,
                      core::LabelImage* labels) {
  if (!noise.enabled) return;
  const int w = depth->width, h = depth->height;
  if (noise.min_range_m > 0) {
    const uint16_t near = uint16_t(std::min(65535.0, noise.min_range_m * 1e3));
    for (size_t i = 0; i < depth->pixels.size(); ++i)
      if (depth->pixels[i] != 0 && depth->pixels[i] < near) {
        depth->pixels[i] = 0;
        labels->pixels[i] = core::kBackgroundLabel;
      }
  }
  if (noise.projector_shadow) ApplyProjectorShadow(noise, depth, labels);
  // Only the rows holding foreground (plus one either side, for the neighbour test) are touched.
  int y_lo = h, y_hi = -1;
  for (int y = 0; y < h; ++y) {
    const uint16_t* row = depth->data() + size_t(y) * size_t(w);
    if (std::any_of(row, row + w, [](uint16_t d) { return d != 0; })) y_lo = std::min(y_lo, y), y_hi = y;
  }
  if (y_hi < 0) return;
  // A copy of the clean rows with a one-pixel border, so the 4-neighbour test needs no bounds
  // checks. Inside the image the rows above y_lo and below y_hi are background (zeros); outside
  // it, the border repeats the edge pixels, so the frame edge itself is not a discontinuity.
  const int copy_lo = y_lo - 1, stride = w + 2;
  std::vector<uint16_t> clean(size_t(stride) * size_t(y_hi - y_lo + 3), 0);
  auto fill_row = [&](int dst_row, int src_y) {
    uint16_t* r = &clean[size_t(dst_row) * size_t(stride)];
    std::copy_n(depth->data() + size_t(src_y) * size_t(w), size_t(w), r + 1);
    r[0] = r[1];
    r[w + 1] = r[w];
  };
  for (int y = y_lo; y <= y_hi; ++y) fill_row(y - copy_lo, y);
  if (y_lo == 0) fill_row(0, 0);
  if (y_hi == h - 1) fill_row(y_hi - copy_lo + 1, h - 1);
  const core::CounterRng rng(key, 0x4E015E, 0, 1);
  // Disparity in steps of 1/subpixel_steps pixel: D = steps * f * b / z.
  const double fb_steps_mm = noise.focal_px * noise.baseline_m * noise.subpixel_steps * 1e3;  // steps * mm
  const double sigma_steps = noise.disparity_sigma_px * noise.subpixel_steps;
  const int jump = int(std::lround(noise.discontinuity_mm));
  // Dropout thresholds on 16 random bits.
  const uint32_t edge_drop = uint32_t(std::clamp(noise.edge_dropout, 0.0, 1.0) * 65536.0);
  const uint32_t speckle_drop = uint32_t(std::clamp(noise.speckle_dropout, 0.0, 1.0) * 65536.0);
  for (int y = y_lo; y <= y_hi; ++y) {
    const uint16_t* c = &clean[size_t(y - copy_lo) * size_t(stride) + 1];
    uint16_t* out_d = depth->data() + size_t(y) * size_t(w);
    uint8_t* out_l = labels->data() + size_t(y) * size_t(w);
    for (int x = 0; x < w; ++x) {
      const int d = c[x];
      if (d == 0) continue;
      const int n[4] = {c[x - 1], c[x + 1], c[x - stride], c[x + stride]};
      bool edge = false;
      for (int k = 0; k < 4; ++k) edge |= n[k] == 0 || std::abs(n[k] - d) > jump;
      // One 64-bit draw per pixel: 16 bits decide the dropout, 48 bits make the noise.
      const uint64_t bits = rng.Bits(uint64_t(y) * uint64_t(w) + uint64_t(x));
      if (uint32_t(bits >> 48) < (edge ? edge_drop : speckle_drop)) {
        out_d[x] = 0;
        out_l[x] = core::kBackgroundLabel;
        continue;
      }
      // Approximately normal: Irwin-Hall of three 16-bit uniforms (mean 1.5, variance 1/4).
      const double sum =
          double(bits & 0xFFFF) + double((bits >> 16) & 0xFFFF) + double((bits >> 32) & 0xFFFF);
      const double gauss = (sum * (1.0 / 65536.0) - 1.5) * 2.0;
      const double disparity = fb_steps_mm / double(d) + sigma_steps * gauss;  // in steps
      const double level = std::max(1.0, std::floor(disparity + 0.5));
      out_d[x] = uint16_t(std::min(65535.0, std::floor(fb_steps_mm / level + 0.5)));
    }
  }
}

void RayCastClutter(const SceneClutter& clutter, const Eigen::Isometry3d& camera_from_world, bool mirrored,
                    const core::CameraIntrinsics& cam, core::DepthImage* depth) {
  const int w = cam.width, h = cam.height;
  if (depth->width != w || depth->height != h) *depth = core::DepthImage(w, h);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Rendered camera coordinates are flip * camera_from_world * world, so the ray of pixel (x, y)
  // at depth t is world_from_camera * flip * t (dx, dy, 1): t is the depth z.
  const Eigen::Isometry3d world_from_camera = camera_from_world.inverse();
  Eigen::Matrix3d m = world_from_camera.linear();
  if (mirrored) m.col(0) = -m.col(0);
  const Eigen::Vector3d o = world_from_camera.translation();
  for (int y = 0; y < h; ++y) {
    uint16_t* row = depth->data() + size_t(y) * size_t(w);
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d r = m * Eigen::Vector3d((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
      double t = kInf;
      if (clutter.floor && r.y() < -1e-12 && o.y() > 0) t = std::min(t, -o.y() / r.y());
      if (clutter.back_wall_z < 0 && r.z() < -1e-12) t = std::min(t, (clutter.back_wall_z - o.z()) / r.z());
      if (clutter.side_wall_x != 0 && (clutter.side_wall_x - o.x()) * r.x() > 1e-12)
        t = std::min(t, (clutter.side_wall_x - o.x()) / r.x());
      for (const ClutterBox& b : clutter.boxes) {
        double t0 = 0, t1 = kInf;  // slab test
        bool hit = true;
        for (int a = 0; a < 3 && hit; ++a) {
          if (std::abs(r[a]) < 1e-12) {
            hit = o[a] >= b.min[a] && o[a] <= b.max[a];
            continue;
          }
          double ta = (b.min[a] - o[a]) / r[a], tb = (b.max[a] - o[a]) / r[a];
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta), t1 = std::min(t1, tb);
          hit = t0 <= t1;
        }
        if (hit && t0 > 0) t = std::min(t, t0);
      }
      row[x] = t <= clutter.max_depth_m ? uint16_t(std::lround(t * 1000.0)) : uint16_t(0);
    }
  }
}

}  // namespace poseforest::renderer
