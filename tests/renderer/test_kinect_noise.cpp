// The Kinect-like noise model: quantization steps, noise statistics, dropout, determinism.
#include <catch2/catch.hpp>
#include <cmath>
#include <algorithm>
#include <set>

#include "renderer/scene.h"

using namespace poseforest;
using namespace poseforest::renderer;

TEST_CASE("depth quantization steps grow with the square of the distance", "[noise]") {
  NoiseConfig noise;
  const double fb = noise.focal_px * noise.baseline_m;
  for (double z_m : {1.0, 2.0, 3.0, 4.0}) {
    std::set<uint16_t> levels;
    for (int d = int(z_m * 1000) - 200; d <= int(z_m * 1000) + 200; ++d)
      levels.insert(QuantizeDepthMm(noise, d));
    // Mean spacing of the levels over the window vs the model z^2 / (f b 8).
    const double spacing = (double(*levels.rbegin()) - double(*levels.begin())) / double(levels.size() - 1);
    const double expected = z_m * z_m / (fb * noise.subpixel_steps) * 1000.0;
    INFO("z " << z_m << " m: spacing " << spacing << " mm, expected " << expected);
    CHECK(spacing == Approx(expected).epsilon(0.12));
    for (uint16_t q : levels) CHECK(QuantizeDepthMm(noise, q) == q);  // levels are fixed points
  }
  CHECK(QuantizeDepthMm(noise, 2000.0) == Approx(2000).margin(6));
  CHECK(QuantizeDepthMm(noise, 0.0) == 0);
}

TEST_CASE("noise statistics, edge dropout and determinism", "[noise]") {
  NoiseConfig noise;
  const int w = 200, h = 200;
  core::DepthImage depth(w, h, 0);
  core::LabelImage labels(w, h, core::kBackgroundLabel);
  for (int y = 50; y < 150; ++y) {
    for (int x = 50; x < 150; ++x) depth.at(x, y) = 2500, labels.at(x, y) = 7;
  }
  core::DepthImage d1 = depth, d2 = depth, d3 = depth;
  core::LabelImage l1 = labels, l2 = labels, l3 = labels;
  ApplyKinectNoise(noise, 42, &d1, &l1);
  ApplyKinectNoise(noise, 42, &d2, &l2);
  ApplyKinectNoise(noise, 43, &d3, &l3);
  CHECK(d1.pixels == d2.pixels);
  CHECK(l1.pixels == l2.pixels);
  CHECK(d1.pixels != d3.pixels);

  int edge = 0, edge_dropped = 0, inner = 0, inner_dropped = 0;
  double sum = 0, sum2 = 0;
  int n = 0;
  for (int y = 50; y < 150; ++y) {
    for (int x = 50; x < 150; ++x) {
      const bool on_edge = x == 50 || x == 149 || y == 50 || y == 149;
      const bool dropped = d1.at(x, y) == 0;
      REQUIRE(dropped == (l1.at(x, y) == core::kBackgroundLabel));
      if (on_edge) {
        ++edge, edge_dropped += dropped;
      } else {
        ++inner, inner_dropped += dropped;
      }
      if (!dropped && !on_edge) {
        const double e = double(d1.at(x, y)) - 2500.0;
        sum += e, sum2 += e * e, ++n;
        REQUIRE(QuantizeDepthMm(noise, d1.at(x, y)) == d1.at(x, y));  // on a quantization level
      }
    }
  }
  // Background stays background.
  for (int x = 0; x < w; ++x) REQUIRE(d1.at(x, 0) == 0);
  CHECK(double(edge_dropped) / edge == Approx(noise.edge_dropout).margin(0.08));
  CHECK(double(inner_dropped) / inner < 0.01);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  const double step =
      2.5 * 2.5 / (noise.focal_px * noise.baseline_m * noise.subpixel_steps) * 1000.0;  // ~18 mm
  INFO("mean " << mean << " mm, sd " << sd << " mm, step " << step << " mm");
  CHECK(std::abs(mean) < 0.5 * step);
  CHECK(sd > 0.1 * step);  // the disparity noise dithers across levels
  CHECK(sd < 1.0 * step);

  NoiseConfig off = noise;
  off.enabled = false;
  core::DepthImage d4 = depth;
  core::LabelImage l4 = labels;
  ApplyKinectNoise(off, 42, &d4, &l4);
  CHECK(d4.pixels == depth.pixels);
}

TEST_CASE("the image border is not a depth discontinuity", "[noise]") {
  NoiseConfig noise;
  noise.edge_dropout = 1.0;  // every discontinuity pixel drops
  noise.speckle_dropout = 0.0;
  core::DepthImage depth(64, 48, 0);
  core::LabelImage labels(64, 48, core::kBackgroundLabel);
  // A flat body cropped by the top-left corner of the frame: x < 20, y < 30.
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < 20; ++x) depth.at(x, y) = 2000, labels.at(x, y) = 3;
  }
  ApplyKinectNoise(noise, 5, &depth, &labels);
  for (int y = 0; y < 30; ++y) {
    for (int x = 0; x < 20; ++x) {
      const bool silhouette = x == 19 || y == 29;
      INFO("pixel " << x << ", " << y);
      REQUIRE((depth.at(x, y) == 0) == silhouette);
    }
  }
}

TEST_CASE("projector shadow: a band beside a near object, on the side away from the projector", "[noise]") {
  NoiseConfig noise;
  noise.projector_shadow = true;
  const int w = 300, h = 20;
  const double z_near = 0.9, z_far = 1.3;  // a hand before the chest
  core::DepthImage depth(w, h, uint16_t(z_far * 1000));
  core::LabelImage labels(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 120; x < 180; ++x) depth.at(x, y) = uint16_t(z_near * 1000), labels.at(x, y) = 9;
  const double band = noise.focal_px * noise.baseline_m * (1 / z_near - 1 / z_far);  // ~14.8 px
  for (int side : {+1, -1}) {
    noise.projector_side = side;
    core::DepthImage d = depth;
    core::LabelImage l = labels;
    ApplyProjectorShadow(noise, &d, &l);
    for (int y = 0; y < h; ++y) {
      int left = 0, right = 0, near_lost = 0;
      for (int x = 0; x < 120; ++x) left += d.at(x, y) == 0;
      for (int x = 180; x < w; ++x) right += d.at(x, y) == 0;
      for (int x = 120; x < 180; ++x) near_lost += d.at(x, y) == 0;
      INFO("side " << side << " row " << y << ": shadow left " << left << " right " << right << ", band " << band);
      CHECK(near_lost == 0);  // the near surface is lit
      const int shadowed = side > 0 ? left : right, lit = side > 0 ? right : left;
      CHECK(std::abs(shadowed - band) <= 1.0);
      CHECK(lit == 0);
      // The band is contiguous and touches the near object; shadowed pixels are background.
      for (int k = 1; k <= shadowed; ++k) {
        const int x = side > 0 ? 120 - k : 179 + k;
        CHECK(d.at(x, y) == 0);
        CHECK(l.at(x, y) == core::kBackgroundLabel);
      }
    }
  }
  // A plane facing the camera, however far, casts nothing on itself.
  core::DepthImage flat(w, h, 1500);
  core::LabelImage flat_l(w, h, 1);
  ApplyProjectorShadow(noise, &flat, &flat_l);
  CHECK(std::count(flat.pixels.begin(), flat.pixels.end(), uint16_t(0)) == 0);
}

TEST_CASE("min range: surfaces nearer than the sensor's limit give no reading", "[noise]") {
  NoiseConfig noise;
  noise.min_range_m = 0.45;
  core::DepthImage depth(40, 10, 1000);
  core::LabelImage labels(40, 10, 2);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 10; ++x) depth.at(x, y) = 400;
  ApplyKinectNoise(noise, 7, &depth, &labels);
  for (int y = 0; y < 10; ++y) {
    for (int x = 0; x < 10; ++x) CHECK((depth.at(x, y) == 0 && labels.at(x, y) == core::kBackgroundLabel));
    CHECK(depth.at(30, y) != 0);
  }
}
