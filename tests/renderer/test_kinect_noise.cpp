// The Kinect-like noise model: quantization steps, noise statistics, dropout, determinism.
#include <catch2/catch.hpp>
#include <cmath>
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
