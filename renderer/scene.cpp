#include "renderer/scene.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <numbers>
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

namespace {

/// Probability `p` (clamped to [0, 1]) as a threshold on 16 random bits.
uint32_t Threshold16(double p) { return uint32_t(std::clamp(p, 0.0, 1.0) * 65536.0); }

/// The depth gradient (mm per pixel) at centre `d` from its two neighbours along one axis, on
/// the same surface only: a neighbour within `jump` mm, or both neighbours on one slanted line
/// (their second difference within `jump`: a steep plane steps more than `jump` per pixel).
double SurfaceSlope(int before, int d, int after, int jump) {
  const bool b = before != 0 && std::abs(before - d) <= jump, a = after != 0 && std::abs(after - d) <= jump;
  if ((a && b) || (before != 0 && after != 0 && std::abs((after - d) - (d - before)) <= jump))
    return 0.5 * double(after - before);
  if (a) return double(after - d);
  if (b) return double(d - before);
  return 0.0;
}

}  // namespace

const char* DepthSensorName(DepthSensor sensor) {
  switch (sensor) {
    case DepthSensor::kKinectV2:
      return "kinect-v2";
    case DepthSensor::kAzureKinectNfov:
      return "azure-nfov";
    case DepthSensor::kKinectV1:
      break;
  }
  return "kinect-v1";
}

bool ParseDepthSensor(const std::string& name, DepthSensor* sensor) {
  for (DepthSensor s : {DepthSensor::kKinectV1, DepthSensor::kKinectV2, DepthSensor::kAzureKinectNfov}) {
    if (name == DepthSensorName(s)) {
      *sensor = s;
      return true;
    }
  }
  return false;
}

SensorPreset SensorNoise(DepthSensor sensor) {
  SensorPreset p;  // Kinect v1: CameraIntrinsics::KinectV1() and the classic noise model
  if (sensor == DepthSensor::kKinectV1) return p;
  NoiseConfig& n = p.noise;
  n.principle = DepthPrinciple::kTimeOfFlight;
  n.projector_shadow = false;  // ToF lights the scene from (almost) the camera's own position
  // Axial noise: Fankhauser et al., "Kinect v2 for mobile robot navigation: evaluation and
  // modeling" (ICAR 2015) fit sigma_z = 1.5 - 0.5 z + 0.3 z^2 mm (z in m) on surfaces facing the
  // camera: 1.3 mm at 1 m, 1.7 mm at 2 m, 4.3 mm at 4 m (their angle term is left to
  // grazing_dropout). Used for the Azure Kinect too: Microsoft's depth-camera page bounds its
  // random error by sigma <= 17 mm, and Toelgyessy et al. (Sensors 2021, "Evaluation of the Azure
  // Kinect and its comparison to Kinect v1 and Kinect v2") find it within that and no noisier
  // than the Kinect v2; we know no fitted sigma(z) of its own.
  n.tof_sigma_mm[0] = 1.5, n.tof_sigma_mm[1] = -0.5, n.tof_sigma_mm[2] = 0.3;
  // Flying pixels are the ToF artefact at edges (pmdtec's FAQ "flying pixel": the reading of a
  // pixel on an object's corner lies between object and background; Sarbolandi et al., "Kinect
  // range sensing: structured-light versus time-of-flight Kinect", CVIU 2015, see far more mixed
  // pixels on the Kinect v2 than on the Kinect v1). The shares below are NOT measured: half of
  // the edge pixels mixed, and the edge dropout of structured light (its correlation window
  // loses edges) cut to 0.1, are our guesses for "strong flying pixels, few edge holes".
  n.flying_pixels = 0.5;
  n.edge_dropout = 0.1;
  // Holes: returned light falls as cos(theta) / z^2, so dark and far or edge-on surfaces give
  // no reading. Guesses again (no published per-pixel rates): 2 % at 4 m, and up to 50 % on
  // surfaces seen edge-on, from 60 deg (Nguyen, Izadi and Lovell 2012 and Fankhauser et al.
  // 2015 both find the axial noise flat up to ~60 deg and rising steeply toward 90 deg).
  n.range_dropout = 0.02;
  n.grazing_dropout = 0.5;
  if (sensor == DepthSensor::kKinectV2) {
    // 512x424 depth; f = 365.5 px: factory calibrations read through libfreenect2 / the SDK's
    // coordinate mapper give fx = fy ~ 365.2-365.6 (e.g. 365.456); the nominal 70.6 x 60 deg
    // field of view gives 361.6 x 367.2. Operating range 0.5-4.5 m.
    p.camera = {512, 424, 365.5, 365.5, 255.5, 211.5};
    n.min_range_m = 0.5;
  } else {
    // Azure Kinect NFOV unbinned: 640x576 (k4a_depth_mode_t K4A_DEPTH_MODE_NFOV_UNBINNED). The
    // factory calibration stores the depth camera's focal length normalized by the 1024 px
    // sensor: ~0.492 (Azure-Kinect-Sensor-SDK issue #1488 prints one), 0.492 * 1024 = 504 px in
    // NFOV unbinned (runtime/camera_model's azure-nfov preset is the same 504 px). Operating
    // range 0.5-3.86 m (Microsoft's depth-camera page).
    p.camera = {640, 576, 504.0, 504.0, 319.5, 287.5};
    n.min_range_m = 0.5;
  }
  n.focal_px = p.camera.fx;
  return p;
}

namespace {

// Readings nearer than the sensor's minimum range are lost.
void ClearBelowMinRange(const NoiseConfig& noise, core::DepthImage* depth, core::LabelImage* labels) {
  const uint16_t near = uint16_t(std::min(65535.0, noise.min_range_m * 1e3));
  for (size_t i = 0; i < depth->pixels.size(); ++i)
    if (depth->pixels[i] != 0 && depth->pixels[i] < near) {
      depth->pixels[i] = 0;
      labels->pixels[i] = core::kBackgroundLabel;
    }
}

// A copy of the clean rows r_lo-1 .. r_hi+1 with a one-pixel border, so the 4-neighbour test
// needs no bounds checks. Inside the image the rows outside y_lo..y_hi are background (zeros);
// outside it, the border repeats the edge pixels, so the frame edge itself is not a
// discontinuity. Labels (and people) are copied too when mixed pixels may take a neighbour's.
struct CleanRows {
  int copy_lo = 0, stride = 0;
  std::vector<uint16_t> depth;
  std::vector<uint8_t> labels, people;
};

CleanRows CopyCleanRows(const core::DepthImage& depth, const core::LabelImage& labels,
                        const core::LabelImage* people, int y_lo, int y_hi, int r_lo, int r_hi, bool flying) {
  const int w = depth.width, h = depth.height;
  CleanRows cr;
  cr.copy_lo = r_lo - 1;
  cr.stride = w + 2;
  const int copy_rows = r_hi - r_lo + 3;
  cr.depth.assign(size_t(cr.stride) * size_t(copy_rows), 0);
  cr.labels.assign(flying ? cr.depth.size() : 0, core::kBackgroundLabel);
  cr.people.assign(flying && people ? cr.depth.size() : 0, 0);
  for (int row = 0; row < copy_rows; ++row) {
    const int src_y = std::clamp(cr.copy_lo + row, 0, h - 1);
    if (src_y < y_lo || src_y > y_hi) continue;
    const size_t dst = size_t(row) * size_t(cr.stride), src = size_t(src_y) * size_t(w);
    auto fill = [&](auto* out, const auto* in) {
      std::copy_n(in + src, size_t(w), out + dst + 1);
      out[dst] = out[dst + 1];
      out[dst + size_t(w) + 1] = out[dst + size_t(w)];
    };
    fill(cr.depth.data(), depth.data());
    if (flying) fill(cr.labels.data(), labels.data());
    if (!cr.people.empty()) fill(cr.people.data(), people->data());
  }
  return cr;
}

// The sensor's noise model for one frame: its random streams and constants.
struct NoiseModel {
  NoiseModel(const NoiseConfig& noise_config, uint64_t key, int w, int h)
      : noise(noise_config),
        tof(noise.principle == DepthPrinciple::kTimeOfFlight),
        flying(noise.flying_pixels > 0),
        holes(noise.range_dropout > 0 || noise.grazing_dropout > 0),
        rng(key, 0x4E015E, 0, 1),
        // The optional effects draw from streams of their own: off, they change nothing.
        hole_rng(key, 0x4013E5, 0, 2),
        fly_rng(key, 0xF1E5, 0, 3),
        // Disparity in steps of 1/subpixel_steps pixel: D = steps * f * b / z.
        fb_steps_mm(noise.focal_px * noise.baseline_m * noise.subpixel_steps * 1e3),  // steps * mm
        sigma_steps(noise.disparity_sigma_px * noise.subpixel_steps),
        jump(int(std::lround(noise.discontinuity_mm))),
        // Dropout thresholds on 16 random bits.
        edge_drop(Threshold16(noise.edge_dropout)),
        speckle_drop(Threshold16(noise.speckle_dropout)),
        fly_share(Threshold16(noise.flying_pixels)),
        f(noise.focal_px),
        cx(0.5 * (w - 1)),
        cy(0.5 * (h - 1)),
        graze_lo(noise.grazing_start_deg * std::numbers::pi / 180.0),
        graze_span(std::max(1e-9, 0.5 * std::numbers::pi - graze_lo)),
        range_k(noise.range_dropout / std::max(1e-9, noise.range_dropout_ref_m * noise.range_dropout_ref_m)) {
  }

  const NoiseConfig& noise;
  const bool tof, flying, holes;
  const core::CounterRng rng, hole_rng, fly_rng;
  const double fb_steps_mm, sigma_steps;
  const int jump;
  const uint32_t edge_drop, speckle_drop, fly_share;
  const double f, cx, cy, graze_lo, graze_span, range_k;

  // The reading of a pixel whose true depth is `z` mm (> 0), from the noise bits of its draw.
  uint16_t Measure(double z, uint64_t bits) const {
    // Approximately normal: Irwin-Hall of three 16-bit uniforms (mean 1.5, variance 1/4).
    const double sum = double(bits & 0xFFFF) + double((bits >> 16) & 0xFFFF) + double((bits >> 32) & 0xFFFF);
    const double gauss = (sum * (1.0 / 65536.0) - 1.5) * 2.0;
    if (tof) {
      const double zm = z * 1e-3;
      const double sigma =
          std::max(0.0, noise.tof_sigma_mm[0] + noise.tof_sigma_mm[1] * zm + noise.tof_sigma_mm[2] * zm * zm);
      return uint16_t(std::clamp(std::floor(z + sigma * gauss + 0.5), 1.0, 65535.0));
    }
    const double disparity = fb_steps_mm / z + sigma_steps * gauss;  // in steps
    const double level = std::max(1.0, std::floor(disparity + 0.5));
    return uint16_t(std::min(65535.0, std::floor(fb_steps_mm / level + 0.5)));
  }
};

// One row being noised: the clean row `c` (bordered), its outputs, and the neighbour offsets.
struct NoiseRow {
  const CleanRows& cr;
  size_t row;  ///< index of the row's first pixel in cr
  const uint16_t* c;
  uint16_t* out_d;
  uint8_t* out_l;
  uint8_t* out_p;  ///< null without person ids
  ptrdiff_t off[4];
};

// A background pixel beside a surface sees a little of it: its own (virtual) surface is
// flying_void_mm behind the nearest neighbour's.
void FlyIntoBackground(const NoiseModel& m, const NoiseRow& r, int x, uint64_t index) {
  const uint16_t* c = r.c;
  int near = 0;
  for (ptrdiff_t o : r.off)
    if (c[x + o] != 0 && (near == 0 || c[x + o] < near)) near = c[x + o];
  if (near == 0) return;
  const uint64_t fly = m.fly_rng.Bits(index);
  if (uint32_t(fly & 0xFFFF) >= m.fly_share) return;
  const uint64_t bits = m.rng.Bits(index);
  if (uint32_t(bits >> 48) < m.edge_drop) return;  // an edge reading, dropped as such
  const double a = double((fly >> 16) & 0xFFFF) * (0.5 / 65536.0);
  const double own = near + m.noise.flying_void_mm;
  const double mixed = own + a * (near - own);
  uint8_t label = core::kBackgroundLabel, person = 0;
  if (mixed - near <= m.noise.flying_label_mm) {
    for (ptrdiff_t o : r.off)
      if (c[x + o] == near) {
        label = r.cr.labels[r.row + size_t(x + o)];
        person = r.cr.people.empty() ? 0 : r.cr.people[r.row + size_t(x + o)];
        break;
      }
  }
  r.out_d[x] = m.Measure(mixed, bits);
  r.out_l[x] = label;
  if (r.out_p) r.out_p[x] = person;
}

// The chance that a surface pixel of clean depth `d` reads nothing: far range, and grazing
// angles.
double HoleProbability(const NoiseModel& m, const NoiseRow& r, int x, int y, int d) {
  const uint16_t* c = r.c;
  const int stride = r.cr.stride;
  const double f = m.f;
  double p = m.range_k * (d * 1e-3) * (d * 1e-3);
  if (m.noise.grazing_dropout > 0) {
    // Normal from the clean depth (mm per pixel): with P = z r, r = ((x-cx)/f, (y-cy)/f, 1),
    // n ~ (-f z_x, -f z_y, f (z_x r_x + z_y r_y) + z) and n.r = z, so cos(theta) = z / (|n| |r|).
    const double zx = SurfaceSlope(c[x - 1], d, c[x + 1], m.jump);
    const double zy = SurfaceSlope(c[x - stride], d, c[x + stride], m.jump);
    const double rx = (x - m.cx) / f, ry = (y - m.cy) / f;
    const Eigen::Vector3d n(-f * zx, -f * zy, f * (zx * rx + zy * ry) + d);
    const double cos_theta = double(d) / (n.norm() * std::sqrt(rx * rx + ry * ry + 1.0));
    const double theta = std::acos(std::clamp(cos_theta, 0.0, 1.0));
    const double g = m.noise.grazing_dropout * std::clamp((theta - m.graze_lo) / m.graze_span, 0.0, 1.0);
    p = 1.0 - (1.0 - std::min(1.0, p)) * (1.0 - g);
  }
  return p;
}

// The depth an edge pixel of clean depth `d` reads when it is a flying pixel (a mix with the
// surface across the edge), its label and person id updated; `d` itself otherwise.
double FlyingEdgeDepth(const NoiseModel& m, const NoiseRow& r, int x, uint64_t index, int d) {
  const uint16_t* c = r.c;
  double z = d;
  const uint64_t fly = m.fly_rng.Bits(index);
  if (uint32_t(fly & 0xFFFF) < m.fly_share) {
    // The other surface: the neighbour across the largest jump (no reading: flying_void_mm
    // behind this pixel).
    int other = 0;
    double other_z = d, best = -1;
    for (int k = 0; k < 4; ++k) {
      const int n = c[x + r.off[k]];
      if (n != 0 && std::abs(n - d) <= m.jump) continue;
      const double nz = n == 0 ? d + m.noise.flying_void_mm : double(n);
      if (std::abs(nz - d) > best) best = std::abs(nz - d), other = k, other_z = nz;
    }
    const double a = double((fly >> 16) & 0xFFFF) * (0.5 / 65536.0);
    z = d + a * (other_z - d);
    // The label of the surface the reading lies within flying_label_mm of, the nearer
    // surface first; else background. A neighbour with no reading has no label.
    const int n_other = c[x + r.off[other]];
    const bool other_near = n_other != 0 && n_other < d;
    const bool near_own = std::abs(z - d) <= m.noise.flying_label_mm;
    const bool near_other = n_other != 0 && std::abs(z - n_other) <= m.noise.flying_label_mm;
    if (near_other && (other_near || !near_own)) {
      r.out_l[x] = r.cr.labels[r.row + size_t(x + r.off[other])];
      if (r.out_p) r.out_p[x] = r.cr.people.empty() ? 0 : r.cr.people[r.row + size_t(x + r.off[other])];
    } else if (!near_own) {
      r.out_l[x] = core::kBackgroundLabel;
      if (r.out_p) r.out_p[x] = 0;
    }
  }
  return z;
}

// A pixel on a surface: dropped (at edges, as speckle, as a hole), or read with noise.
void NoiseSurfacePixel(const NoiseModel& m, const NoiseRow& r, int x, int y, uint64_t index) {
  const uint16_t* c = r.c;
  const int d = c[x];
  bool edge = false;
  for (ptrdiff_t o : r.off) edge |= c[x + o] == 0 || std::abs(c[x + o] - d) > m.jump;
  // One 64-bit draw per pixel: 16 bits decide the dropout, 48 bits make the noise.
  const uint64_t bits = m.rng.Bits(index);
  if (uint32_t(bits >> 48) < (edge ? m.edge_drop : m.speckle_drop)) {
    r.out_d[x] = 0;
    r.out_l[x] = core::kBackgroundLabel;
    return;
  }
  if (m.holes && uint32_t(m.hole_rng.Bits(index) & 0xFFFF) < Threshold16(HoleProbability(m, r, x, y, d))) {
    r.out_d[x] = 0;
    r.out_l[x] = core::kBackgroundLabel;
    if (r.out_p) r.out_p[x] = 0;
    return;
  }
  const double z = m.flying && edge ? FlyingEdgeDepth(m, r, x, index, d) : double(d);
  r.out_d[x] = m.Measure(z, bits);
}

}  // namespace

void ApplyKinectNoise(const NoiseConfig& noise, uint64_t key, core::DepthImage* depth,
                      core::LabelImage* labels, core::LabelImage* people) {
  if (!noise.enabled) return;
  const int w = depth->width, h = depth->height;
  const bool tof = noise.principle == DepthPrinciple::kTimeOfFlight;
  if (people && (people->width != w || people->height != h)) people = nullptr;
  if (noise.min_range_m > 0) ClearBelowMinRange(noise, depth, labels);
  if (noise.projector_shadow && !tof) ApplyProjectorShadow(noise, depth, labels);
  // Only the rows holding foreground (plus one either side, for the neighbour test) are touched.
  int y_lo = h, y_hi = -1;
  for (int y = 0; y < h; ++y) {
    const uint16_t* row = depth->data() + size_t(y) * size_t(w);
    if (std::any_of(row, row + w, [](uint16_t d) { return d != 0; })) y_lo = std::min(y_lo, y), y_hi = y;
  }
  if (y_hi < 0) return;
  const NoiseModel m(noise, key, w, h);
  // Rows visited: the foreground rows, and with flying pixels the background row either side
  // (its pixels may straddle the silhouette).
  const int r_lo = m.flying ? std::max(0, y_lo - 1) : y_lo,
            r_hi = m.flying ? std::min(h - 1, y_hi + 1) : y_hi;
  const CleanRows cr = CopyCleanRows(*depth, *labels, people, y_lo, y_hi, r_lo, r_hi, m.flying);
  const ptrdiff_t stride = cr.stride;
  for (int y = r_lo; y <= r_hi; ++y) {
    const size_t row = size_t(y - cr.copy_lo) * size_t(stride) + 1;
    const NoiseRow r{cr,
                     row,
                     &cr.depth[row],
                     depth->data() + size_t(y) * size_t(w),
                     labels->data() + size_t(y) * size_t(w),
                     people ? people->data() + size_t(y) * size_t(w) : nullptr,
                     {-1, 1, -stride, stride}};
    for (int x = 0; x < w; ++x) {
      const uint64_t index = uint64_t(y) * uint64_t(w) + uint64_t(x);
      if (r.c[x] == 0) {
        if (m.flying) FlyIntoBackground(m, r, x, index);
        continue;
      }
      NoiseSurfacePixel(m, r, x, y, index);
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
