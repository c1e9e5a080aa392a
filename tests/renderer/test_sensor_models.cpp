// Sensor models beyond the classic Kinect v1 noise: mixed / flying pixels at depth
// edges, holes growing with depth and on grazing surfaces, time-of-flight presets; and that the
// classic model, with all of them off, is byte for byte what it was.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <numbers>
#include <set>

#include "renderer/scene.h"
#include "runtime/core/rng.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

// The noise model as it was before the sensor models (renderer/scene.cpp at that time), verbatim: the
// reference the classic path must still match byte for byte.
void ClassicNoise(const NoiseConfig& noise, uint64_t key, core::DepthImage* depth, core::LabelImage* labels) {
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

/// A synthetic scene: a far plane (clutter: background label, or no reading) with boxes before it
/// at several depths, labelled by box.
struct Scene {
  core::DepthImage depth;
  core::LabelImage labels, people;
};
Scene Boxes(int w, int h, uint16_t back_mm, uint64_t seed) {
  Scene s{core::DepthImage(w, h, back_mm), core::LabelImage(w, h, core::kBackgroundLabel),
          core::LabelImage(w, h, 0)};
  core::RngStream rng(core::CounterRng(seed, 1, 2, 3));
  for (int b = 0; b < 6; ++b) {
    const int x0 = rng.UniformIntIn(0, w - 20), y0 = rng.UniformIntIn(0, h - 20);
    const int x1 = x0 + rng.UniformIntIn(5, w / 2), y1 = y0 + rng.UniformIntIn(5, h / 2);
    const uint16_t z = uint16_t(rng.UniformIntIn(600, 4200));
    const double slope = rng.UniformIn(-8, 8);  // mm per pixel: some boxes are slanted
    for (int y = y0; y < std::min(h, y1); ++y)
      for (int x = x0; x < std::min(w, x1); ++x) {
        const uint16_t d = uint16_t(z + slope * (x - x0));
        if (s.depth.at(x, y) == 0 || d < s.depth.at(x, y)) {
          s.depth.at(x, y) = d;
          s.labels.at(x, y) = uint8_t(b);
          s.people.at(x, y) = uint8_t(1 + b % 2);
        }
      }
  }
  return s;
}

/// Depth of a plane through (0, 0, z0_mm) turned by `angle_deg` about the camera's vertical axis,
/// at every pixel of a w x h image with focal length f (principal point at the centre).
core::DepthImage SlantedPlane(int w, int h, double f, double z0_mm, double angle_deg) {
  core::DepthImage d(w, h, 0);
  const double a = angle_deg * std::numbers::pi / 180.0;
  const Eigen::Vector3d n(std::sin(a), 0, -std::cos(a));  // plane n.P = n.(0, 0, z0)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d r((x - 0.5 * (w - 1)) / f, (y - 0.5 * (h - 1)) / f, 1.0);
      const double t = n.dot(Eigen::Vector3d(0, 0, z0_mm)) / n.dot(r);  // depth z = t
      if (t > 0 && t < 20000) d.at(x, y) = uint16_t(std::lround(t));
    }
  return d;
}

/// A noise model with only the effect under test: no dropout, no random depth noise (ToF with
/// sigma 0 leaves depths exact).
NoiseConfig Quiet() {
  NoiseConfig n;
  n.principle = DepthPrinciple::kTimeOfFlight;
  n.tof_sigma_mm[0] = n.tof_sigma_mm[1] = n.tof_sigma_mm[2] = 0;
  n.edge_dropout = n.speckle_dropout = 0;
  return n;
}

}  // namespace

TEST_CASE("with the new effects off the classic model is byte for byte what it was", "[noise]") {
  for (uint64_t seed = 0; seed < 12; ++seed) {
    NoiseConfig noise;
    noise.projector_shadow = seed % 2 == 1;
    noise.min_range_m = seed % 3 == 0 ? 0.8 : 0.0;
    noise.flying_pixels = noise.range_dropout = noise.grazing_dropout = 0;  // explicitly off
    // With and without a back wall (a person against nothing, or clutter behind).
    Scene s = Boxes(160, 120, seed % 4 < 2 ? 0 : 4500, seed);
    core::DepthImage d_ref = s.depth, d_new = s.depth;
    core::LabelImage l_ref = s.labels, l_new = s.labels, p_new = s.people;
    ClassicNoise(noise, seed * 77 + 1, &d_ref, &l_ref);
    ApplyKinectNoise(noise, seed * 77 + 1, &d_new, &l_new, &p_new);
    INFO("scene " << seed);
    CHECK(d_new.pixels == d_ref.pixels);
    CHECK(l_new.pixels == l_ref.pixels);
    CHECK(p_new.pixels == s.people.pixels);  // only mixed pixels ever touch the person masks
    core::DepthImage d_old_api = s.depth;
    core::LabelImage l_old_api = s.labels;
    ApplyKinectNoise(noise, seed * 77 + 1, &d_old_api, &l_old_api);  // without person masks
    CHECK(d_old_api.pixels == d_ref.pixels);
  }
  // The Kinect v1 preset is the classic model.
  const SensorPreset v1 = SensorNoise(DepthSensor::kKinectV1);
  CHECK(v1.camera.width == 640);
  CHECK(v1.camera.fx == 575.8);
  CHECK(v1.noise.principle == DepthPrinciple::kStructuredLight);
  CHECK(v1.noise.flying_pixels == 0);
  CHECK(v1.noise.range_dropout == 0);
  CHECK(v1.noise.grazing_dropout == 0);
}

TEST_CASE("flying pixels: only at depth edges, reading between the two surfaces, labelled by rule",
          "[noise]") {
  NoiseConfig noise = Quiet();
  noise.flying_pixels = 1.0;
  for (const uint16_t back : {uint16_t(0), uint16_t(4500)}) {
    for (uint64_t seed = 0; seed < 6; ++seed) {
      const Scene s = Boxes(160, 120, back, seed);
      core::DepthImage d = s.depth;
      core::LabelImage l = s.labels, p = s.people;
      ApplyKinectNoise(noise, seed, &d, &l, &p);
      const int jump = int(noise.discontinuity_mm);
      int edge_pixels = 0, mixed = 0;
      for (int y = 0; y < 120; ++y) {
        for (int x = 0; x < 160; ++x) {
          const int c = s.depth.at(x, y);
          // The clean depths of the pixel and its 4-neighbours (inside the image).
          int lo = c == 0 ? 1 << 30 : c, hi = c;
          bool edge = false, beside_surface = false, zero_beside = false;
          for (auto [dx, dy] : {std::pair{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
            if (!s.depth.InBounds(x + dx, y + dy)) continue;
            const int n = s.depth.at(x + dx, y + dy);
            edge |= c != 0 && (n == 0 || std::abs(n - c) > jump);
            beside_surface |= c == 0 && n != 0;
            if (n != 0) lo = std::min(lo, n), hi = std::max(hi, n);
            zero_beside |= n == 0;
          }
          // Where one side has no reading, the far surface is flying_void_mm behind the near one.
          if (c == 0 || zero_beside) hi = std::max(hi, (c == 0 ? lo : c) + int(noise.flying_void_mm));
          INFO("back " << back << " scene " << seed << " pixel " << x << "," << y << " clean " << c << " now "
                       << d.at(x, y) << " label " << int(l.at(x, y)));
          if (!edge && !beside_surface) {
            REQUIRE(d.at(x, y) == c);  // away from edges nothing changes
            REQUIRE(l.at(x, y) == s.labels.at(x, y));
            continue;
          }
          ++edge_pixels;
          if (d.at(x, y) == c && l.at(x, y) == s.labels.at(x, y)) continue;
          ++mixed;
          REQUIRE(d.at(x, y) >= lo);  // between the surfaces around it
          REQUIRE(d.at(x, y) <= hi);
          if (l.at(x, y) == core::kBackgroundLabel) {
            REQUIRE(p.at(x, y) == 0);
            continue;
          }
          // A body label only within flying_label_mm of a surface carrying that label.
          bool supported = false;
          for (auto [dx, dy] : {std::pair{0, 0}, {-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
            if (!s.depth.InBounds(x + dx, y + dy) || s.depth.at(x + dx, y + dy) == 0) continue;
            supported |=
                s.labels.at(x + dx, y + dy) == l.at(x, y) &&
                std::abs(int(s.depth.at(x + dx, y + dy)) - int(d.at(x, y))) <= noise.flying_label_mm &&
                s.people.at(x + dx, y + dy) == p.at(x, y);
          }
          REQUIRE(supported);
        }
      }
      INFO("edge pixels " << edge_pixels << ", mixed " << mixed);
      CHECK(edge_pixels > 100);
      CHECK(mixed > edge_pixels * 9 / 10);  // share 1: all of them, bar a fraction a ~ 0
    }
  }
  // A person against nothing: the pixels beside the silhouette read behind the person and are
  // background; a share of 0.3 mixes about 30 % of the edge pixels.
  noise.flying_pixels = 0.3;
  core::DepthImage d(200, 200, 0);
  core::LabelImage l(200, 200, core::kBackgroundLabel);
  for (int y = 50; y < 150; ++y)
    for (int x = 50; x < 150; ++x) d.at(x, y) = 2000, l.at(x, y) = 4;
  const core::DepthImage clean = d;
  ApplyKinectNoise(noise, 3, &d, &l);
  int outside = 0, outside_read = 0, rim = 0, rim_moved = 0;
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 200; ++x) {
      const bool in = x >= 50 && x < 150 && y >= 50 && y < 150;
      const bool ring_out = !in && x >= 49 && x <= 150 && y >= 49 && y <= 150 &&
                            !((x == 49 || x == 150) && (y == 49 || y == 150));  // 4-adjacent to the square
      const bool ring_in = in && (x == 50 || x == 149 || y == 50 || y == 149);
      if (ring_out) {
        ++outside, outside_read += d.at(x, y) != 0;
        if (d.at(x, y) != 0) {
          CHECK(d.at(x, y) >= 2000 + noise.flying_void_mm * 0.5);
          CHECK(l.at(x, y) == core::kBackgroundLabel);
        }
      } else if (ring_in) {
        ++rim, rim_moved += d.at(x, y) != 2000;
        CHECK(d.at(x, y) >= 2000);
        CHECK(d.at(x, y) <= 2000 + noise.flying_void_mm * 0.5);
        // (the label is decided before the reading is rounded to whole millimetres)
        if (std::abs(d.at(x, y) - (2000 + noise.flying_label_mm)) > 1)
          CHECK((l.at(x, y) == 4) == (d.at(x, y) <= 2000 + noise.flying_label_mm));
      } else if (!in) {
        CHECK(d.at(x, y) == 0);
      } else {
        CHECK(d.at(x, y) == 2000);
      }
    }
  INFO("outside " << outside_read << "/" << outside << ", rim " << rim_moved << "/" << rim);
  CHECK(double(outside_read) / outside == Approx(0.3).margin(0.07));
  CHECK(double(rim_moved) / rim == Approx(0.3).margin(0.07));
}

TEST_CASE("holes grow with distance", "[noise]") {
  NoiseConfig noise = Quiet();
  noise.range_dropout = 0.3;
  double last = -1;
  for (const double z_m : {1.0, 2.0, 3.0, 4.0}) {
    core::DepthImage d(200, 200, uint16_t(z_m * 1000));
    core::LabelImage l(200, 200, 1);
    ApplyKinectNoise(noise, 11, &d, &l);
    const double rate =
        double(std::count(d.pixels.begin(), d.pixels.end(), uint16_t(0))) / double(d.pixels.size());
    const double expected = 0.3 * (z_m / 4.0) * (z_m / 4.0);
    INFO("z " << z_m << " m: hole rate " << rate << ", model " << expected);
    CHECK(rate == Approx(expected).margin(0.01));
    CHECK(rate > last);
    last = rate;
    for (size_t i = 0; i < d.pixels.size(); ++i)
      REQUIRE((d.pixels[i] == 0) == (l.pixels[i] == core::kBackgroundLabel));
  }
}

TEST_CASE("holes grow on grazing surfaces, from the clean depth's normals", "[noise]") {
  NoiseConfig noise = Quiet();
  noise.grazing_dropout = 0.6;
  const int w = 160, h = 120;
  double last = -1;
  for (const double angle : {0.0, 30.0, 55.0, 70.0, 80.0, 85.0}) {
    const core::DepthImage plane = SlantedPlane(w, h, noise.focal_px, 2000, angle);
    core::DepthImage d = plane;
    core::LabelImage l(w, h, 2);
    ApplyKinectNoise(noise, 5, &d, &l);
    // The middle of the image, where the view ray is (nearly) the optical axis: theta = angle.
    int n = 0, holes = 0;
    for (int y = h / 2 - 30; y < h / 2 + 30; ++y)
      for (int x = w / 2 - 10; x < w / 2 + 10; ++x) ++n, holes += d.at(x, y) == 0;
    const double rate = double(holes) / n;
    // At pixel (x, y) the ray is off-axis by up to ~2 deg here, so the model's rate is approximate.
    const double expected = 0.6 * std::clamp((angle - 60.0) / 30.0, 0.0, 1.0);
    INFO("plane at " << angle << " deg: hole rate " << rate << ", model " << expected);
    CHECK(rate == Approx(expected).margin(0.08));
    CHECK(rate >= last);
    last = rate;
  }
  // Fronto-parallel planes lose nothing, however far (grazing alone).
  core::DepthImage flat(w, h, 3500);
  core::LabelImage flat_l(w, h, 1);
  ApplyKinectNoise(noise, 5, &flat, &flat_l);
  CHECK(std::count(flat.pixels.begin(), flat.pixels.end(), uint16_t(0)) == 0);
}

TEST_CASE("time-of-flight presets: sizes, intrinsics, no shadow, no quantization", "[noise]") {
  const SensorPreset v2 = SensorNoise(DepthSensor::kKinectV2);
  CHECK(v2.camera.width == 512);
  CHECK(v2.camera.height == 424);
  CHECK(v2.camera.fx == Approx(365.5).margin(1));
  CHECK(v2.camera.fy == Approx(365.5).margin(1));
  CHECK(v2.noise.focal_px == v2.camera.fx);
  const SensorPreset az = SensorNoise(DepthSensor::kAzureKinectNfov);
  CHECK(az.camera.width == 640);
  CHECK(az.camera.height == 576);
  CHECK(az.camera.fx == Approx(504).margin(2));
  CHECK(az.camera.cx == Approx(319.5));
  CHECK(az.camera.cy == Approx(287.5));
  for (const SensorPreset* p : {&v2, &az}) {
    CHECK(p->noise.principle == DepthPrinciple::kTimeOfFlight);
    CHECK(!p->noise.projector_shadow);
    CHECK(p->noise.flying_pixels > 0);
    CHECK(p->noise.min_range_m == Approx(0.5));
  }
  for (DepthSensor s : {DepthSensor::kKinectV1, DepthSensor::kKinectV2, DepthSensor::kAzureKinectNfov}) {
    DepthSensor back = DepthSensor::kKinectV1;
    CHECK(ParseDepthSensor(DepthSensorName(s), &back));
    CHECK(back == s);
  }
  DepthSensor unused;
  CHECK(!ParseDepthSensor("kinect-v9", &unused));

  // Noise: unquantized, centred, sd = sigma(z) (1.5 - 0.5 z + 0.3 z^2 mm: 2.1 mm at 2.5 m).
  NoiseConfig tof = v2.noise;
  tof.flying_pixels = tof.range_dropout = tof.grazing_dropout = tof.speckle_dropout = 0;
  core::DepthImage d(200, 200, 2500);
  core::LabelImage l(200, 200, 1);
  ApplyKinectNoise(tof, 9, &d, &l);
  double sum = 0, sum2 = 0;
  std::set<uint16_t> levels;
  for (int y = 1; y < 199; ++y)
    for (int x = 1; x < 199; ++x) {
      const double e = double(d.at(x, y)) - 2500.0;
      sum += e, sum2 += e * e, levels.insert(d.at(x, y));
    }
  const double n = 198.0 * 198.0, mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  INFO("mean " << mean << " mm, sd " << sd << " mm, " << levels.size() << " distinct readings");
  CHECK(std::abs(mean) < 0.1);
  CHECK(sd == Approx(1.5 - 0.5 * 2.5 + 0.3 * 2.5 * 2.5).epsilon(0.1));
  CHECK(levels.size() >= 8);  // Kinect v1 at 2.5 m: levels 18 mm apart, 1-2 readings here
  // No projector shadow even when asked for: a hand before a chest leaves no band.
  tof.projector_shadow = true;
  tof.tof_sigma_mm[0] = tof.tof_sigma_mm[1] = tof.tof_sigma_mm[2] = 0;
  tof.edge_dropout = 0;
  tof.min_range_m = 0;
  core::DepthImage hand(300, 20, 1300);
  core::LabelImage hand_l(300, 20, 3);
  for (int y = 0; y < 20; ++y)
    for (int x = 120; x < 180; ++x) hand.at(x, y) = 900;
  ApplyKinectNoise(tof, 1, &hand, &hand_l);
  CHECK(std::count(hand.pixels.begin(), hand.pixels.end(), uint16_t(0)) == 0);
}

TEST_CASE("every effect is deterministic in the noise key", "[noise]") {
  for (DepthSensor sensor : {DepthSensor::kKinectV1, DepthSensor::kKinectV2, DepthSensor::kAzureKinectNfov}) {
    NoiseConfig noise = SensorNoise(sensor).noise;
    noise.flying_pixels = 0.5, noise.range_dropout = 0.2, noise.grazing_dropout = 0.5;
    noise.projector_shadow = sensor == DepthSensor::kKinectV1;
    const Scene s = Boxes(160, 120, 0, 4);
    Scene a = s, b = s, c = s;
    ApplyKinectNoise(noise, 21, &a.depth, &a.labels, &a.people);
    ApplyKinectNoise(noise, 21, &b.depth, &b.labels, &b.people);
    ApplyKinectNoise(noise, 22, &c.depth, &c.labels, &c.people);
    INFO(DepthSensorName(sensor));
    CHECK(a.depth.pixels == b.depth.pixels);
    CHECK(a.labels.pixels == b.labels.pixels);
    CHECK(a.people.pixels == b.people.pixels);
    CHECK(a.depth.pixels != c.depth.pixels);
  }
}
