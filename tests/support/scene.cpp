#include "tests/support/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poseforest::testing {

ClutteredFrame ComposeScene(const core::CameraIntrinsics& cam, const ClutterSpec& spec,
                            const std::vector<core::DepthImage>& people, const std::vector<int>& shift_mm) {
  const int w = cam.width, h = cam.height;
  ClutteredFrame out{core::DepthImage(w, h, 0), core::LabelImage(w, h, 0)};
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // Ray t * (dx, dy, 1): t is the depth z.
      const double dx = (x - cam.cx) / cam.fx, dy = (y - cam.cy) / cam.fy;
      double z = kInf;
      if (spec.floor_y_m > 0 && dy > 1e-9) z = std::min(z, spec.floor_y_m / dy);
      if (spec.back_wall_z_m > 0) z = std::min(z, spec.back_wall_z_m);
      if (spec.side_wall_x_m != 0 && dx * spec.side_wall_x_m > 1e-9) z = std::min(z, spec.side_wall_x_m / dx);
      for (const Box& b : spec.boxes) {
        // Slab test along the ray (direction (dx, dy, 1)).
        double t0 = 0, t1 = kInf;
        const double dir[3] = {dx, dy, 1.0};
        bool hit = true;
        for (int a = 0; a < 3 && hit; ++a) {
          if (std::abs(dir[a]) < 1e-12) {
            if (0 < b.min[a] || 0 > b.max[a]) hit = false;
            continue;
          }
          double ta = b.min[a] / dir[a], tb = b.max[a] / dir[a];
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta), t1 = std::min(t1, tb);
          if (t0 > t1) hit = false;
        }
        if (hit && t0 > 0) z = std::min(z, t0);
      }
      if (std::isfinite(z) && z < 65.0) out.depth.at(x, y) = uint16_t(std::lround(z * 1000.0));
      for (size_t k = 0; k < people.size(); ++k) {
        const uint16_t pd = people[k].at(x, y);
        if (!pd) continue;
        const int d = int(pd) + (k < shift_mm.size() ? shift_mm[k] : 0);
        if (d <= 0 || d > 65535) continue;
        if (out.depth.at(x, y) == 0 || d < out.depth.at(x, y) ||
            (out.truth.at(x, y) == 0 && d <= out.depth.at(x, y))) {
          out.depth.at(x, y) = uint16_t(d);
          out.truth.at(x, y) = uint8_t(k + 1);
        }
      }
    }
  return out;
}

core::DepthImage MovePerson(const core::DepthImage& person, const core::CameraIntrinsics& cam, int dz_mm,
                            double dx_m) {
  core::DepthImage out(person.width, person.height, 0);
  for (int y = 0; y < person.height; ++y)
    for (int x = 0; x < person.width; ++x) {
      const uint16_t d = person.at(x, y);
      if (!d) continue;
      const double z = d * 1e-3, z2 = z + dz_mm * 1e-3;
      // Same 3D point shape, further away: project (X + dx, Y, Z + dz).
      const double X = (x - cam.cx) * z / cam.fx + dx_m, Y = (y - cam.cy) * z / cam.fy;
      const int u = int(std::lround(cam.cx + cam.fx * X / z2)),
                v = int(std::lround(cam.cy + cam.fy * Y / z2));
      if (!out.InBounds(u, v)) continue;
      const uint16_t nd = uint16_t(std::lround(z2 * 1000));
      if (!out.at(u, v) || nd < out.at(u, v)) out.at(u, v) = nd;
    }
  // Fill the pinholes that moving away leaves (a 3x3 closing on the silhouette).
  core::DepthImage filled = out;
  for (int y = 1; y + 1 < out.height; ++y)
    for (int x = 1; x + 1 < out.width; ++x) {
      if (out.at(x, y)) continue;
      int n = 0, sum = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (const uint16_t d = out.at(x + dx, y + dy)) ++n, sum += d;
      if (n >= 5) filled.at(x, y) = uint16_t(sum / n);
    }
  return filled;
}

}  // namespace poseforest::testing
