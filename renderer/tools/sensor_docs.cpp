// Writes docs/renderer/sensor_models.png: one scene (a person before a wall, an arm re-posed toward
// the camera) as four depth cameras see it: Kinect v1 as jobs render it by default (projector
// shadow, near limit), the same with flying pixels and holes growing with depth and obliquity
// switched on, the Kinect v2 preset and the Azure Kinect NFOV unbinned preset (time of flight,
// at their own size and intrinsics). Each: depth (grey, near = bright) | parts, cropped around
// the person at native resolution.
//   sensor_docs OUT.png [SEED INDEX]
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "renderer/montage.h"
#include "renderer/synthetic_source.h"
#include "runtime/core/command_line.h"
#include "runtime/image_io.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

/// `src` magnified `k` times (nearest neighbour).
RgbImage Zoom(const RgbImage& src, int k) {
  RgbImage out;
  out.width = src.width * k, out.height = src.height * k;
  out.rgb.resize(size_t(out.width) * size_t(out.height) * 3);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < 3; ++c)
        out.rgb[(size_t(y) * size_t(out.width) + size_t(x)) * 3 + size_t(c)] =
            src.rgb[(size_t(y / k) * size_t(src.width) + size_t(x / k)) * 3 + size_t(c)];
  return out;
}

/// The window of `src` (w x h) centred on (cx, cy), black outside the picture.
RgbImage Crop(const RgbImage& src, int cx, int cy, int w, int h) {
  RgbImage out;
  out.width = w, out.height = h;
  out.rgb.assign(size_t(w) * size_t(h) * 3, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int sx = cx - w / 2 + x, sy = cy - h / 2 + y;
      if (sx < 0 || sy < 0 || sx >= src.width || sy >= src.height) continue;
      for (int c = 0; c < 3; ++c)
        out.rgb[(size_t(y) * size_t(w) + size_t(x)) * 3 + size_t(c)] =
            src.rgb[(size_t(sy) * size_t(src.width) + size_t(sx)) * 3 + size_t(c)];
    }
  return out;
}

void Blit(const RgbImage& src, RgbImage* dst, int x0, int y0) {
  for (int y = 0; y < src.height; ++y)
    for (int x = 0; x < src.width; ++x)
      for (int c = 0; c < 3; ++c)
        dst->rgb[(size_t(y0 + y) * size_t(dst->width) + size_t(x0 + x)) * 3 + size_t(c)] =
            src.rgb[(size_t(y) * size_t(src.width) + size_t(x)) * 3 + size_t(c)];
}

int Fail(const core::Status& st) {
  std::fprintf(stderr, "sensor_docs: %s\n", st.ToString().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  // The command line on CLI11, as poseforest-poselib's: a seed or index that is not a number is
  // refused (exit 2), where strtoull read "abc" as 0.
  std::string out_png;
  uint64_t seed = 3, index = 0;
  CLI::App app("sensor_docs: the sensor models side by side (docs/renderer/sensor_models.png)",
               "sensor_docs");
  app.add_option("OUT.png", out_png, "the picture to write")->required()->check([](const std::string& v) {
    return v.empty() ? std::string("must be a file name, not empty") : std::string();
  });
  app.add_option("SEED", seed, "the scene's seed")->capture_default_str();
  app.add_option("INDEX", index, "the frame of that seed")->capture_default_str()->needs("SEED");
  try {
    std::vector<std::string> args = core::ArgumentsForCli11(argc, argv);
    app.parse(args);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "sensor_docs: %s (see --help)\n", e.what());
    return 2;
  }
  setenv("LP_NUM_THREADS", "0", 0);
  SceneConfig base;
  base.variants_per_shape = 1;
  base.min_distance_m = base.max_distance_m = 2.6;
  base.lateral_fraction = 0.0;
  base.mirror_probability = 0.0;
  base.rotation_range_deg = 20.0;
  base.arm_pose_share = 1.0;
  base.clutter.walls = true;
  base.noise.projector_shadow = true;  // Kinect v1 as jobs render it by default
  base.noise.min_range_m = 0.45;

  SceneConfig edges = base;  // + the new edge and hole effects (strong, to be seen at this size)
  edges.noise.flying_pixels = 0.5;
  edges.noise.range_dropout = 0.1;
  edges.noise.grazing_dropout = 0.6;
  std::vector<SceneConfig> configs = {base, edges};
  for (DepthSensor s : {DepthSensor::kKinectV2, DepthSensor::kAzureKinectNfov}) {
    SceneConfig c = base;
    const SensorPreset p = SensorNoise(s);
    c.camera = p.camera;
    c.noise = p.noise;
    configs.push_back(c);
  }
  // One scene for all: sampled once (Kinect v1), then drawn by every camera.
  auto first = SyntheticRenderer::Create(base);
  if (!first.ok()) return Fail(first.status());
  const SceneSample scene = (*first)->Sample(seed, index);

  const int cell_w = 200, cell_h = 400;
  RgbImage grid;
  grid.width = 4 * cell_w;
  grid.height = 2 * cell_h + cell_w;  // + a row of 4x close-ups of the silhouette
  grid.rgb.assign(size_t(grid.width) * size_t(grid.height) * 3, 40);
  for (size_t k = 0; k < configs.size(); ++k) {
    auto r = k == 0 ? std::move(first) : SyntheticRenderer::Create(configs[k]);
    if (!r.ok()) return Fail(r.status());
    auto f = (*r)->RenderScene(scene);
    if (!f.ok()) return Fail(f.status());
    // Centre on the person's pixels (their label bounding box).
    int x_lo = f->labels.width, x_hi = 0, y_lo = f->labels.height, y_hi = 0;
    for (int y = 0; y < f->labels.height; ++y)
      for (int x = 0; x < f->labels.width; ++x)
        if (f->labels.at(x, y) != core::kBackgroundLabel)
          x_lo = std::min(x_lo, x), x_hi = std::max(x_hi, x), y_lo = std::min(y_lo, y),
          y_hi = std::max(y_hi, y);
    const int cx = (x_lo + x_hi) / 2, cy = (y_lo + y_hi) / 2;
    const int gx = int(k % 2) * 2 * cell_w, gy = int(k / 2) * cell_h;
    Blit(Crop(DepthToGrey(f->depth), cx, cy, cell_w, cell_h), &grid, gx, gy);
    Blit(Crop(LabelsToColour(f->labels), cx, cy, cell_w, cell_h), &grid, gx + cell_w, gy);
    // Close-up: 50 x 50 px of depth at the person's left silhouette, 3/8 of the way down.
    const int zy = y_lo + (y_hi - y_lo) * 3 / 8;
    int zx = x_lo;
    while (zx < x_hi && f->labels.at(zx, zy) == core::kBackgroundLabel) ++zx;
    Blit(Zoom(Crop(DepthToGrey(f->depth), zx, zy, cell_w / 4, cell_w / 4), 4), &grid, int(k) * cell_w,
         2 * cell_h);
    std::printf("%zu: %dx%d fx %.1f, person %dx%d px\n", k, configs[k].camera.width, configs[k].camera.height,
                configs[k].camera.fx, x_hi - x_lo + 1, y_hi - y_lo + 1);
  }
  if (auto st = runtime::WriteRgbPng(out_png, grid.width, grid.height, grid.rgb); !st.ok()) return Fail(st);
  std::printf("wrote %s\n", out_png.c_str());
  return 0;
}
