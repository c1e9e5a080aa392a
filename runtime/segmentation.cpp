#include "runtime/segmentation.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include "runtime/core/rng.h"

namespace poseforest::runtime {
namespace {

// A horizontal run of foreground pixels with no depth jump inside: the unit of the components.
struct Run {
  int y, x0, x1;  // inclusive
  uint32_t parent;
};

uint32_t Find(std::vector<Run>& runs, uint32_t i) {
  while (runs[i].parent != i) {
    runs[i].parent = runs[runs[i].parent].parent;
    i = runs[i].parent;
  }
  return i;
}
void Union(std::vector<Run>& runs, uint32_t a, uint32_t b) {
  a = Find(runs, a), b = Find(runs, b);
  if (a == b) return;
  if (a < b) std::swap(a, b);
  runs[a].parent = b;  // the smaller index (earlier run) becomes the root: deterministic
}

inline int JumpLimit(int d, const SegmentationOptions& o) {
  return std::max(o.jump_mm, int(o.jump_fraction * d));
}

// Seeded RANSAC over a grid sample of back-projected points; the best plane that is roughly
// horizontal (normal near the camera's y axis) and below the camera, refitted by least squares
// on its inliers.
std::optional<Eigen::Vector4d> FitFloor(const core::DepthImage& depth, const core::CameraIntrinsics& cam,
                                        const SegmentationOptions& o) {
  // A grid of back-projected points; hypotheses come from three grid neighbours (a local patch),
  // so a floor that fills a fifth of the view is hit by a fifth of the hypotheses, where three
  // independent random points would all lie on it only 1% of the time.
  const int w = depth.width, h = depth.height;
  const int cells = std::max(16, o.ransac_samples);
  const int s = std::max(1, int(std::sqrt(double(w) * h / cells)));
  const int gw = (w - s / 2 + s - 1) / s, gh = (h - s / 2 + s - 1) / s;
  std::vector<Eigen::Vector3d> grid(size_t(gw) * size_t(gh));
  std::vector<uint8_t> valid(grid.size(), 0);
  std::vector<Eigen::Vector3d> pts;
  std::vector<uint32_t> valid_cells;
  for (int gy = 0; gy < gh; ++gy)
    for (int gx = 0; gx < gw; ++gx) {
      const int x = s / 2 + gx * s, y = s / 2 + gy * s;
      const uint16_t d = depth.at(x, y);
      if (d == 0 || d > o.far_m * 1000 * 1.5) continue;
      const size_t c = size_t(gy) * size_t(gw) + size_t(gx);
      grid[c] = cam.PixelToPoint(x, y, d);
      valid[c] = 1;
      pts.push_back(grid[c]);
      valid_cells.push_back(uint32_t(c));
    }
  if (pts.size() < 16) return std::nullopt;
  const double cos_tilt = std::cos(o.floor_max_tilt_deg * std::numbers::pi / 180.0);
  core::RngStream rng(core::CounterRng(o.seed, 0, 0, 0x466c6f6f72ull));  // "Floor"
  int best = 0;
  Eigen::Vector4d best_plane;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const uint32_t c0 = valid_cells[rng.UniformInt(uint32_t(valid_cells.size()))];
    const int gx = int(c0 % uint32_t(gw)), gy = int(c0 / uint32_t(gw));
    const int step = 1 + int(rng.UniformInt(3));
    const int gx1 = gx + step < gw ? gx + step : gx - step, gy2 = gy + step < gh ? gy + step : gy - step;
    if (gx1 < 0 || gy2 < 0) continue;
    const size_t c1 = size_t(gy) * size_t(gw) + size_t(gx1), c2 = size_t(gy2) * size_t(gw) + size_t(gx);
    if (!valid[c1] || !valid[c2]) continue;
    const Eigen::Vector3d& a = grid[c0];
    const Eigen::Vector3d& b = grid[c1];
    const Eigen::Vector3d& c = grid[c2];
    Eigen::Vector3d nrm = (b - a).cross(c - a);
    const double len = nrm.norm();
    if (len < 1e-9) continue;
    nrm /= len;
    if (nrm.y() < 0) nrm = -nrm;  // point "down" (+y): the floor is below the camera
    if (nrm.y() < cos_tilt) continue;
    const double d = -nrm.dot(a);
    if (d >= 0) continue;  // the camera (origin) must be above the plane: n.0 + d < 0
    int inliers = 0, below = 0;
    double zmin = 1e9, zmax = 0, xmin = 1e9, xmax = -1e9;
    for (const auto& p : pts) {
      const double dist = nrm.dot(p) + d;
      if (std::abs(dist) < o.floor_distance_m) {
        ++inliers;
        zmin = std::min(zmin, p.z()), zmax = std::max(zmax, p.z());
        xmin = std::min(xmin, p.x()), xmax = std::max(xmax, p.x());
      } else {
        below += dist > 0;
      }
    }
    // ... and is wide: a person lying on the ground (pre-segmented renders have such poses) is
    // not the floor.
    if (xmax - xmin < o.floor_min_width_m) continue;
    // Nothing is seen through a floor: a plane with many points beyond it is not one.
    if (below > o.floor_max_below_fraction * double(pts.size())) continue;
    // A floor recedes from the camera: its points span a range of depths (a person's shoulders
    // or a table top seen from above do not).
    if (zmax - zmin < o.floor_min_depth_range_m) continue;
    if (inliers > best) best = inliers, best_plane << nrm, d;
  }
  if (best < std::max(16, int(o.min_floor_fraction * double(pts.size())))) return std::nullopt;
  // Least-squares refits on the inliers (smallest eigenvector of their covariance), the band
  // narrowing to a third of the tolerance, so that a hypothesis from a slightly tilted patch
  // settles on the floor itself.
  Eigen::Vector4d plane = best_plane;
  for (int round = 0; round < 3; ++round) {
    const double band = o.floor_distance_m / (1.0 + round);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    int k = 0;
    for (const auto& p : pts)
      if (std::abs(plane.head<3>().dot(p) + plane[3]) < band) mean += p, ++k;
    if (k < 16) break;
    mean /= k;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : pts)
      if (std::abs(plane.head<3>().dot(p) + plane[3]) < band) cov += (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
    Eigen::Vector3d nrm = es.eigenvectors().col(0);
    if (nrm.y() < 0) nrm = -nrm;
    if (nrm.y() < cos_tilt) break;
    plane << nrm, -nrm.dot(mean);
  }
  return plane;
}

/// A frame taken as segmented already: every pixel with depth is person 1.
void PassPresegmented(const core::DepthImage& depth, SegmentationResult* out) {
  const int w = depth.width, h = depth.height;
  out->presegmented = true;
  out->depth.pixels = depth.pixels;
  PersonInfo p;
  p.label = 1;
  p.x0 = w, p.y0 = h, p.x1 = -1, p.y1 = -1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (depth.at(x, y)) {
        out->labels.at(x, y) = 1;
        ++p.pixels;
        p.x0 = std::min(p.x0, x), p.x1 = std::max(p.x1, x), p.y0 = std::min(p.y0, y),
        p.y1 = std::max(p.y1, y);
      }
  if (p.pixels) out->people.push_back(p);
}

/// Steps 1-3: floor, band and runs in one pass over the rows. Appends the runs row by row
/// (row_start[y]: row y's first; row_start[h]: their count) and counts the floor's pixels
/// into out->floor_pixels.
void FindRuns(const core::DepthImage& depth, const core::CameraIntrinsics& cam, const SegmentationOptions& o,
              SegmentationResult* out, std::vector<Run>& runs, std::vector<uint32_t>& row_start) {
  const int w = depth.width, h = depth.height;
  // 1-3: floor, band and runs in one pass over the rows.
  const int near_mm = int(o.near_m * 1000), far_mm = int(o.far_m * 1000);
  std::vector<float> col_term(size_t(w), 0.0f);
  float floor_d = 0, floor_tol = 0;
  const bool has_floor = out->floor.has_value();
  if (has_floor) {
    const Eigen::Vector4d& p = *out->floor;
    for (int x = 0; x < w; ++x) col_term[size_t(x)] = float(p[0] * (x - cam.cx) / cam.fx);
    floor_d = float(p[3] * 1000.0);  // mm
    floor_tol = float(o.floor_distance_m * 1000.0);
  }
  runs.reserve(4096);
  row_start.assign(size_t(h) + 1, 0);
  // Per row: the foreground mask (band, not floor), then the run boundaries (foreground starts
  // or ends, or a depth jump inside it), both in branch-free loops the compiler vectorizes; the
  // boundaries are rare, found 8 bytes at a time.
  std::vector<uint8_t> fg(static_cast<size_t>(w) + 8, 0), edge(static_cast<size_t>(w) + 16, 0);
  const int jump_q16 = int(o.jump_fraction * 65536.0);
  const int jump_mm = o.jump_mm;
  for (int y = 0; y < h; ++y) {
    row_start[size_t(y)] = uint32_t(runs.size());
    const uint16_t* row = depth.data() + size_t(y) * size_t(w);
    uint8_t* f = fg.data();
    if (has_floor) {
      const Eigen::Vector4d& p = *out->floor;
      const float row_term = float(p[1] * (y - cam.cy) / cam.fy + p[2]);
      const float* ct = col_term.data();
      int floor_here = 0;
      for (int x = 0; x < w; ++x) {
        const int d = row[x];
        const bool band = d >= near_mm && d <= far_mm && d != 0;
        // Signed distance (mm) of the pixel's point from the plane: d * (n.ray) + plane d;
        // negative above the floor. Below it (positive beyond the tolerance) is noise.
        const float dist = float(d) * (ct[x] + row_term) + floor_d;
        floor_here += band & (std::abs(dist) < floor_tol);
        f[x] = uint8_t(band & (dist <= -floor_tol));
      }
      out->floor_pixels += floor_here;
    } else {
      for (int x = 0; x < w; ++x) {
        const int d = row[x];
        f[x] = uint8_t(d >= near_mm && d <= far_mm && d != 0);
      }
    }
    uint8_t* e = edge.data();
    e[0] = f[0];
    for (int x = 1; x < w; ++x) {
      const int d = row[x], q = row[x - 1];
      const int limit = std::max(jump_mm, (q * jump_q16) >> 16);
      const int diff = d > q ? d - q : q - d;
      e[x] = uint8_t((f[x] ^ f[x - 1]) | (f[x] & f[x - 1] & (diff > limit)));
    }
    e[w] = f[w - 1];
    int open = -1;
    int x = 0;
    while (x <= w) {
      uint64_t word;
      std::memcpy(&word, e + x, 8);
      if (word == 0) {
        x += 8;
        continue;
      }
      if (!e[x]) {
        ++x;
        continue;
      }
      if (open >= 0) runs.push_back({y, open, x - 1, uint32_t(runs.size())});
      open = (x < w && f[x]) ? x : -1;
      ++x;
    }
  }
  row_start[size_t(h)] = uint32_t(runs.size());
}

/// Joins runs of consecutive rows that overlap where some column's depths are close; returns
/// the pairs that overlap only across a jump (for the small-piece merge).
std::vector<std::pair<uint32_t, uint32_t>> JoinRows(const core::DepthImage& depth, const SegmentationOptions& o,
                                                    std::vector<Run>& runs, const std::vector<uint32_t>& row_start) {
  const int w = depth.width, h = depth.height;
  // Join runs of consecutive rows that overlap where some column's depths are close; remember
  // the pairs that overlap only across a jump (for the small-piece merge).
  std::vector<std::pair<uint32_t, uint32_t>> jump_edges;
  for (int y = 1; y < h; ++y) {
    uint32_t i = row_start[size_t(y - 1)], j = row_start[size_t(y)];
    const uint32_t ie = row_start[size_t(y)], je = row_start[size_t(y) + 1];
    const uint16_t* up = depth.data() + size_t(y - 1) * size_t(w);
    const uint16_t* row = depth.data() + size_t(y) * size_t(w);
    while (i < ie && j < je) {
      const Run &a = runs[i], &b = runs[j];
      const int lo = std::max(a.x0, b.x0), hi = std::min(a.x1, b.x1);
      if (lo <= hi) {
        bool joined = false;
        for (int x = lo; x <= hi; ++x)
          if (std::abs(int(up[x]) - int(row[x])) <= JumpLimit(row[x], o)) {
            joined = true;
            break;
          }
        if (joined)
          Union(runs, i, j);
        else
          jump_edges.emplace_back(i, j);
      }
      if (a.x1 < b.x1)
        ++i;
      else
        ++j;
    }
  }
  return jump_edges;
}

/// A connected component (of runs), and later of components merged into it.
struct Comp {
  double area = 0, sum_d = 0, xmin = 1e9, xmax = -1e9, ymin = 1e9, ymax = -1e9;
  int pixels = 0, x0 = 1 << 30, y0 = 1 << 30, x1 = -1, y1 = -1;
  int dmin = 1 << 30, dmax = 0;  // mm
  int32_t merged_into = -1;
};

/// Component statistics: comp_of[r] gets run r's component.
std::vector<Comp> ComponentStats(const core::DepthImage& depth, const core::CameraIntrinsics& cam,
                                 std::vector<Run>& runs, std::vector<int32_t>& comp_of) {
  const int w = depth.width;
  const uint32_t nr = uint32_t(runs.size());
  comp_of.assign(nr, -1);
  std::vector<Comp> comps;
  const double inv_fx = 1.0 / cam.fx, inv_fy = 1.0 / cam.fy;
  for (uint32_t r = 0; r < nr; ++r) {
    const uint32_t root = Find(runs, r);
    if (comp_of[root] < 0) comp_of[root] = int32_t(comps.size()), comps.emplace_back();
    comp_of[r] = comp_of[root];
    Comp& c = comps[size_t(comp_of[r])];
    const Run& run = runs[r];
    const uint16_t* row = depth.data() + size_t(run.y) * size_t(w);
    uint64_t isd = 0, isd2 = 0;
    int rmin = 65535, rmax = 0;
    for (int x = run.x0; x <= run.x1; ++x) {
      const uint32_t d = row[x];
      isd += d, isd2 += d * d;
      rmin = std::min(rmin, int(d)), rmax = std::max(rmax, int(d));
    }
    c.dmin = std::min(c.dmin, rmin), c.dmax = std::max(c.dmax, rmax);
    const double sd = double(isd), sd2 = double(isd2);
    const int n = run.x1 - run.x0 + 1;
    c.pixels += n;
    c.sum_d += sd;
    c.area += sd2 * 1e-6 * inv_fx * inv_fy;
    const double d0 = row[run.x0] * 1e-3, d1 = row[run.x1] * 1e-3, dm = sd / n * 1e-3;
    c.xmin = std::min(c.xmin, (run.x0 - cam.cx) * d0 * inv_fx);
    c.xmax = std::max(c.xmax, (run.x1 - cam.cx) * d1 * inv_fx);
    const double yv = (run.y - cam.cy) * dm * inv_fy;
    c.ymin = std::min(c.ymin, yv), c.ymax = std::max(c.ymax, yv);
    c.x0 = std::min(c.x0, run.x0), c.x1 = std::max(c.x1, run.x1);
    c.y0 = std::min(c.y0, run.y), c.y1 = std::max(c.y1, run.y);
  }
  return comps;
}

/// The components and their merges (steps (a), (b) and the background test).
struct Components {
  std::vector<Comp>& comps;
  const SegmentationOptions& o;

  bool IsSmall(const Comp& c) const { return c.area < o.min_area_m2 || (c.ymax - c.ymin) < o.min_height_m; }
  static double MeanM(const Comp& c) { return c.sum_d / c.pixels * 1e-3; }
  int32_t Root(int32_t c) const {
    while (comps[size_t(c)].merged_into >= 0) c = comps[size_t(c)].merged_into;
    return c;
  }
  void Absorb(int32_t into, int32_t from) {
    Comp &t = comps[size_t(into)], &c = comps[size_t(from)];
    t.area += c.area, t.sum_d += c.sum_d, t.pixels += c.pixels;
    t.xmin = std::min(t.xmin, c.xmin), t.xmax = std::max(t.xmax, c.xmax);
    t.ymin = std::min(t.ymin, c.ymin), t.ymax = std::max(t.ymax, c.ymax);
    t.x0 = std::min(t.x0, c.x0), t.x1 = std::max(t.x1, c.x1), t.y0 = std::min(t.y0, c.y0),
    t.y1 = std::max(t.y1, c.y1);
    t.dmin = std::min(t.dmin, c.dmin), t.dmax = std::max(t.dmax, c.dmax);
    c.merged_into = into;
  }

  /// (a) Small pieces (an arm in front of the body, split off by its depth jump) rejoin the
  /// neighbouring big component nearest in depth, if within merge_distance_m.
  void MergeSmallPieces(const std::vector<std::pair<int32_t, int32_t>>& pairs) {
    std::vector<int32_t> target(comps.size(), -1);
    std::vector<double> target_gap(comps.size(), 1e9);
    for (const auto& [a, b] : pairs) {
      const double gap = std::abs(MeanM(comps[size_t(a)]) - MeanM(comps[size_t(b)]));
      if (gap > o.merge_distance_m) continue;
      for (const auto& [sm, lg] : {std::pair{a, b}, std::pair{b, a}}) {
        if (!IsSmall(comps[size_t(sm)]) || IsSmall(comps[size_t(lg)])) continue;
        if (gap < target_gap[size_t(sm)]) target_gap[size_t(sm)] = gap, target[size_t(sm)] = lg;
      }
    }
    for (size_t sm = 0; sm < comps.size(); ++sm)
      if (target[sm] >= 0) Absorb(target[sm], int32_t(sm));
  }

  /// (b) One body cut in two by something in front of it (another person's arm): two
  /// components at about the same depth that both touch the same nearer component become one.
  void MergeOccludedHalves(const std::vector<std::pair<int32_t, int32_t>>& pairs) {
    std::vector<std::vector<int32_t>> behind(comps.size());  // nearer component -> those behind it
    for (const auto& [a0, b0] : pairs) {
      const int32_t a = Root(a0), b = Root(b0);
      if (a == b) continue;
      const bool a_near = MeanM(comps[size_t(a)]) < MeanM(comps[size_t(b)]);
      behind[size_t(a_near ? a : b)].push_back(a_near ? b : a);
    }
    for (auto& list : behind) {
      for (size_t i = 0; i < list.size(); ++i)
        for (size_t j = i + 1; j < list.size(); ++j) {
          const int32_t a = Root(list[i]), b = Root(list[j]);
          if (a == b) continue;
          const Comp &ca = comps[size_t(a)], &cb = comps[size_t(b)];
          if (std::abs(MeanM(ca) - MeanM(cb)) > o.merge_distance_m) continue;
          // Close in space too: their metric boxes overlap or nearly touch.
          const double gx = std::max(ca.xmin, cb.xmin) - std::min(ca.xmax, cb.xmax);
          const double gy = std::max(ca.ymin, cb.ymin) - std::min(ca.ymax, cb.ymax);
          if (gx > o.occlusion_gap_m || gy > o.occlusion_gap_m) continue;
          Absorb(std::min(a, b), std::max(a, b));
        }
    }
  }

  /// Background seen through a gap (the wall between a person's arm and body, or between two
  /// people): a component behind every component it touches across a depth jump, at the depth
  /// of something too big to be a person (the wall it is part of). A person behind another
  /// person, with the wall beyond the depth band, touches only nearer things too, but no wall
  /// is there. Per component: 1 if it is such a background piece.
  std::vector<uint8_t> SeenThroughGaps(const std::vector<std::pair<int32_t, int32_t>>& pairs) const {
    auto oversize = [&](const Comp& k) {
      return k.area > o.max_area_m2 || k.xmax - k.xmin > o.max_width_m || k.ymax - k.ymin > o.max_height_m;
    };
    std::vector<std::pair<int, int>> background_depths;  // mm ranges of oversize components
    for (const Comp& k : comps)
      if (k.merged_into < 0 && oversize(k)) background_depths.emplace_back(k.dmin - 100, k.dmax + 100);
    auto at_background_depth = [&](const Comp& k) {
      const double d = k.sum_d / k.pixels;
      for (const auto& [lo, hi] : background_depths)
        if (d >= lo && d <= hi) return true;
      return false;
    };
    std::vector<uint8_t> has_nearer(comps.size(), 0), has_farther(comps.size(), 0);
    for (const auto& [a0, b0] : pairs) {
      const int32_t ca = Root(a0), cb = Root(b0);
      if (ca == cb) continue;
      const bool a_far = MeanM(comps[size_t(ca)]) > MeanM(comps[size_t(cb)]);
      has_nearer[size_t(a_far ? ca : cb)] = 1;
      has_farther[size_t(a_far ? cb : ca)] = 1;
    }
    std::vector<uint8_t> background(comps.size(), 0);
    for (size_t c = 0; c < comps.size(); ++c) {
      const Comp& k = comps[c];
      if (k.merged_into >= 0) continue;
      background[c] = uint8_t(has_nearer[c] && !has_farther[c] && at_background_depth(k));
    }
    return background;
  }
};

/// Component pairs that touch across a depth jump, sorted, each once.
std::vector<std::pair<int32_t, int32_t>> JumpPairs(const std::vector<std::pair<uint32_t, uint32_t>>& jump_edges,
                                                   const std::vector<int32_t>& comp_of) {
  std::vector<std::pair<int32_t, int32_t>> pairs;
  for (const auto& [a, b] : jump_edges) {
    const int32_t ca = comp_of[a], cb = comp_of[b];
    if (ca != cb) pairs.emplace_back(std::min(ca, cb), std::max(ca, cb));
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

/// Step 4: the components within the size limits and fill ratio (not background) become people,
/// largest first (at most 254), into out->people. Returns each component's person label (0:
/// none; a merged component takes its root's).
std::vector<int32_t> SelectPeople(const Components& cs, const std::vector<uint8_t>& background,
                                  SegmentationResult* out) {
  const std::vector<Comp>& comps = cs.comps;
  const SegmentationOptions& o = cs.o;
  std::vector<int32_t> person_of(comps.size(), 0);
  std::vector<size_t> order;
  for (size_t c = 0; c < comps.size(); ++c) {
    const Comp& k = comps[c];
    if (k.merged_into >= 0) continue;
    const double height = k.ymax - k.ymin, width = k.xmax - k.xmin;
    const double fill = double(k.pixels) / (double(k.x1 - k.x0 + 1) * double(k.y1 - k.y0 + 1));
    if (k.area < o.min_area_m2 || k.area > o.max_area_m2) continue;
    if (height < o.min_height_m || height > o.max_height_m || width < o.min_width_m || width > o.max_width_m)
      continue;
    if (fill > o.max_fill) continue;
    if (background[c]) continue;
    order.push_back(c);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return comps[a].pixels > comps[b].pixels; });
  if (order.size() > 254) order.resize(254);
  for (size_t i = 0; i < order.size(); ++i) {
    person_of[order[i]] = int32_t(i + 1);
    const Comp& k = comps[order[i]];
    PersonInfo p;
    p.label = int(i + 1);
    p.pixels = k.pixels;
    p.x0 = k.x0, p.y0 = k.y0, p.x1 = k.x1, p.y1 = k.y1;
    p.height_m = k.ymax - k.ymin, p.width_m = k.xmax - k.xmin, p.area_m2 = k.area;
    p.mean_depth_m = k.sum_d / k.pixels * 1e-3;
    out->people.push_back(p);
  }
  for (size_t c = 0; c < comps.size(); ++c)
    if (comps[c].merged_into >= 0) person_of[c] = person_of[size_t(cs.Root(int32_t(c)))];
  return person_of;
}

/// The people's runs into out->depth and out->labels.
void PaintPeople(const core::DepthImage& depth, const std::vector<Run>& runs, const std::vector<int32_t>& comp_of,
                 const std::vector<int32_t>& person_of, SegmentationResult* out) {
  const int w = depth.width, h = depth.height;
  const uint32_t nr = uint32_t(runs.size());
  out->depth.pixels.assign(size_t(w) * size_t(h), 0);
  for (uint32_t r = 0; r < nr; ++r) {
    const int32_t label = person_of[size_t(comp_of[r])];
    if (!label) continue;
    const Run& run = runs[r];
    const size_t base = size_t(run.y) * size_t(w);
    std::copy(depth.pixels.begin() + ptrdiff_t(base + size_t(run.x0)),
              depth.pixels.begin() + ptrdiff_t(base + size_t(run.x1) + 1),
              out->depth.pixels.begin() + ptrdiff_t(base + size_t(run.x0)));
    std::fill(out->labels.pixels.begin() + ptrdiff_t(base + size_t(run.x0)),
              out->labels.pixels.begin() + ptrdiff_t(base + size_t(run.x1) + 1), uint8_t(label));
  }
}

}  // namespace

void SegmentPeople(const core::DepthImage& depth, const core::CameraIntrinsics& cam,
                   const SegmentationOptions& o, SegmentationResult* out) {
  const int w = depth.width, h = depth.height;
  out->people.clear();
  out->floor.reset();
  out->floor_pixels = 0;
  out->components = 0;
  out->presegmented = false;
  out->labels.width = w, out->labels.height = h;
  out->depth.width = w, out->depth.height = h;
  out->labels.pixels.assign(size_t(w) * size_t(h), 0);
  const size_t zeros = size_t(std::count(depth.pixels.begin(), depth.pixels.end(), uint16_t(0)));

  // Floor first: with a floor in view the frame is raw whatever its zeros.
  if (o.floor_plane)
    out->floor = o.floor_plane;
  else if (o.find_floor && o.presegmented != std::optional<bool>(true))
    out->floor = FitFloor(depth, cam, o);

  bool pass =
      o.presegmented.value_or(!out->floor && double(zeros) >= o.presegmented_zero_fraction * double(w) * h);
  if (pass) {
    PassPresegmented(depth, out);
    return;
  }

  std::vector<Run> runs;
  std::vector<uint32_t> row_start;
  FindRuns(depth, cam, o, out, runs, row_start);
  const std::vector<std::pair<uint32_t, uint32_t>> jump_edges = JoinRows(depth, o, runs, row_start);
  std::vector<int32_t> comp_of;
  std::vector<Comp> comps = ComponentStats(depth, cam, runs, comp_of);
  out->components = int(comps.size());
  const std::vector<std::pair<int32_t, int32_t>> pairs = JumpPairs(jump_edges, comp_of);
  Components cs{comps, o};
  cs.MergeSmallPieces(pairs);
  cs.MergeOccludedHalves(pairs);
  const std::vector<uint8_t> background = cs.SeenThroughGaps(pairs);
  const std::vector<int32_t> person_of = SelectPeople(cs, background, out);
  PaintPeople(depth, runs, comp_of, person_of, out);
}

core::DepthImage PersonDepth(const SegmentationResult& seg, int label) {
  core::DepthImage d(seg.depth.width, seg.depth.height);
  for (size_t i = 0; i < d.pixels.size(); ++i)
    if (seg.labels.pixels[i] == label) d.pixels[i] = seg.depth.pixels[i];
  return d;
}

double MaskIoU(const core::LabelImage& a, int a_label, const core::LabelImage& b, int b_label) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < a.pixels.size() && i < b.pixels.size(); ++i) {
    const bool x = a.pixels[i] == a_label, y = b.pixels[i] == b_label;
    inter += x && y;
    uni += x || y;
  }
  return uni ? double(inter) / double(uni) : 1.0;
}

}  // namespace poseforest::runtime
