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

}  // namespace poseforest::testing
