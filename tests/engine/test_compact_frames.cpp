// Compact frames (memory per training image): a SampleSet keeps per row only the span
// of pixels that do not read background_mm. Every response, through SampleSet::Response and
// through the histogram builder's vector kernels, must equal core::FeatureResponse on the full
// frame: probes off the frame, off a row's span, on empty rows, on frames without background.
#include <algorithm>
#include <catch2/catch.hpp>
#include <map>
#include <random>

#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/sample_set.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/feature.h"

using namespace poseforest;

namespace {

constexpr int kW = 64, kH = 48;

/// Frames of every shape the span logic has to get right. `kind`:
/// 0 noise everywhere (depths, zeros and background_mm values mixed: no background to drop),
/// 1 a blob in the middle (empty rows above and below, spans inside rows),
/// 2 spans at the edges: single pixels at x = 0 and x = W-1, rows of background_mm (not 0),
///   rows whose ends are 0 or background_mm just inside a span, full rows,
/// 3 only background (0 and background_mm),
/// 4 a blob touching the corners of the frame.
core::DepthImage MakeFrame(int kind, std::mt19937& rng, uint16_t bg, int w = kW, int h = kH) {
  core::DepthImage d(w, h, 0);
  std::uniform_int_distribution<int> depth(400, 9000);
  auto body = [&] { return uint16_t(depth(rng)); };
  switch (kind) {
    case 0:
      for (auto& p : d.pixels) {
        const int r = int(rng() % 10);
        p = r == 0 ? 0 : r == 1 ? bg : r == 2 ? uint16_t(1 + rng() % 65535) : body();
      }
      break;
    case 1: {
      const int cx = w / 2 + int(rng() % 9) - 4, cy = h / 2 + int(rng() % 9) - 4;
      const int rx = 3 + int(rng() % uint32_t(w / 3)), ry = 3 + int(rng() % uint32_t(h / 3));
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const double u = double(x - cx) / rx, v = double(y - cy) / ry;
          if (u * u + v * v <= 1.0 && rng() % 8 != 0) d.at(x, y) = body();  // holes inside spans
        }
      break;
    }
    case 2:
      for (int y = 0; y < h; ++y) {
        switch (y % 8) {
          case 0:
            d.at(0, y) = body();
            break;
          case 1:
            d.at(w - 1, y) = body();
            break;
          case 2:
            for (int x = 0; x < w; ++x) d.at(x, y) = bg;
            break;
          case 3:
            for (int x = 0; x < w; ++x) d.at(x, y) = body();
            break;
          case 4:
            d.at(0, y) = body(), d.at(w - 1, y) = body();
            break;
          case 5:
            for (int x = 5; x < w - 5; ++x) d.at(x, y) = body();
            d.at(5, y) = bg, d.at(w - 6, y) = 0;  // the span's ends read background
            break;
          case 6:
            d.at(int(rng() % uint32_t(w)), y) = body();
            break;
          default:
            break;  // an empty row
        }
      }
      break;
    case 3:
      for (auto& p : d.pixels) p = rng() % 2 ? bg : 0;
      break;
    default:
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (x + y < 6 || (w - 1 - x) + (h - 1 - y) < 6 || (x < 3 && h - 1 - y < 3)) d.at(x, y) = body();
      break;
  }
  return d;
}

/// Up to `n` body pixels (depth > 0) of `d`, row-major, random parts.
std::vector<engine::PixelSample> Pick(const core::DepthImage& d, int n, std::mt19937& rng) {
  std::vector<uint32_t> body;
  for (uint32_t i = 0; i < d.pixels.size(); ++i)
    if (d.pixels[i] != 0) body.push_back(i);
  std::shuffle(body.begin(), body.end(), rng);
  body.resize(std::min(body.size(), size_t(n)));
  std::sort(body.begin(), body.end());
  std::vector<engine::PixelSample> out;
  for (uint32_t i : body)
    out.push_back({int(i % uint32_t(d.width)), int(i / uint32_t(d.width)), uint8_t(rng() % core::kNumParts)});
  return out;
}

/// Random features: offsets up to `reach` units (1/32 pixel*m), a few at the int16 limits.
std::vector<core::FeatureOffsets> Features(int n, int reach, std::mt19937& rng) {
  std::uniform_int_distribution<int> off(-reach, reach);
  std::vector<core::FeatureOffsets> f;
  f.resize(size_t(n));
  for (auto& o : f) o = {int16_t(off(rng)), int16_t(off(rng)), int16_t(off(rng)), int16_t(off(rng))};
  // Every fourth probes against the pixel itself (v = 0), as job.proto's pixel_probe_share draws.
  for (size_t i = 3; i < f.size(); i += 4) f[i].vx = f[i].vy = 0;
  f[0] = {0, 0, 0, 0};
  if (n > 2) f[1] = {32767, -32768, -32768, 32767};
  return f;
}

/// A set of frames of every kind (with their full depth kept aside) and its samples.
struct Fixture {
  core::FeatureConstants c;
  std::vector<core::DepthImage> full;  ///< per local frame
  engine::SampleSet set;
  explicit Fixture(uint32_t seed, int frames, int pixels, bool mixed_sizes = false,
                   core::ProbeEdge edge = core::ProbeEdge::kBackground) {
    c.edge = edge;
    std::mt19937 rng(seed);
    for (int i = 0; i < frames; ++i) {
      const int w = mixed_sizes && i % 2 ? kW + 13 : kW, h = mixed_sizes && i % 3 ? kH - 7 : kH;
      full.push_back(MakeFrame(i % 5, rng, c.background_mm, w, h));
      // Half through the full frame, half through a CompactFrame made first.
      if (i % 2)
        set.AddFrame(uint64_t(i), full.back(), Pick(full.back(), pixels, rng), c);
      else
        set.AddFrame(uint64_t(i), engine::CompactFrame::Of(full.back(), c.background_mm),
                     Pick(full.back(), pixels, rng), c);
    }
    set.StartTree(0);
  }
  int32_t Naive(size_t i, const core::FeatureOffsets& f) const {
    return core::FeatureResponse(full[set.frame()[i]], set.x()[i], set.y()[i], f, c);
  }
};

}  // namespace

TEST_CASE("a compact frame reads as the full frame everywhere, off the frame too", "[training][compact]") {
  std::mt19937 rng(7);
  const uint16_t bg = GENERATE(uint16_t(10000), uint16_t(3000));
  const core::ProbeEdge edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);
  INFO("probe edge " << core::ProbeEdgeName(edge));
  for (int kind = 0; kind < 5; ++kind) {
    for (int rep = 0; rep < 4; ++rep) {
      const core::DepthImage d = MakeFrame(kind, rng, bg);
      const engine::CompactFrame cf = engine::CompactFrame::Of(d, bg);
      REQUIRE(cf.rows.size() == size_t(kH));
      for (int y = -3; y < kH + 3; ++y)
        for (int x = -3; x < kW + 3; ++x)
          REQUIRE(cf.Probe(x, y, bg, edge) == core::ProbeDepth(d.data(), kW, kH, x, y, bg, edge));
      // Far off the frame: the background, or the row's pixel on that edge.
      for (int x : {-100000, -32768, 32767, 100000}) {
        const int edge_x = x < 0 ? 0 : kW - 1;
        CHECK(cf.Probe(x, kH / 2, bg, edge) ==
              (edge == core::ProbeEdge::kClamp ? core::ProbeDepth(d.data(), kW, kH, edge_x, kH / 2, bg, edge)
                                               : int32_t(bg)));
      }
      // Spans are tight: their first and last pixels differ from background.
      for (const auto& r : cf.rows) {
        if (r.len == 0) continue;
        CHECK(cf.pixels[r.start] != bg);
        CHECK(cf.pixels[r.start + r.len - 1u] != bg);
      }
      if (kind == 3) CHECK(cf.pixels.empty());
    }
  }
}

TEST_CASE("compact responses equal core::FeatureResponse on the full frames", "[training][compact]") {
  const bool mixed = GENERATE(false, true);
  const core::ProbeEdge edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);
  INFO("probe edge " << core::ProbeEdgeName(edge));
  const Fixture fx(11, 15, 120, mixed, edge);
  REQUIRE(fx.set.edge() == edge);
  REQUIRE(fx.set.uniform_size() == !mixed);
  REQUIRE(fx.set.num_samples() > 1000);
  std::mt19937 rng(3);
  for (int reach : {40, 800, 6000, 32767}) {
    const auto features = Features(200, reach, rng);
    size_t mismatches = 0;
    for (const auto& f : features)
      for (size_t i = 0; i < fx.set.num_samples(); ++i)
        mismatches += fx.set.Response(i, f, fx.c.background_mm) != fx.Naive(i, f);
    CHECK(mismatches == 0);
  }
  // Fewer bytes than the full frames they stand for.
  CHECK(fx.set.probe_pixels() < 15u * kW * kH);
}

TEST_CASE("the histogram builder's kernels on compact frames equal the naive evaluator",
          "[training][compact][histogram]") {
  const int thresholds = GENERATE(12, 50);
  const int reach = GENERATE(200, 3000, 32767);
  const core::ProbeEdge edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);
  INFO("probe edge " << core::ProbeEdgeName(edge));
  Fixture fx(23, 20, 100, false, edge);
  engine::TrainParams p;
  p.seed = 5;
  p.thresholds_per_feature = thresholds;
  p.threshold_reference_pixels = 1000000;  // ranges over whole nodes (vector kernels)
  p.constants = fx.c;
  std::mt19937 rng(uint32_t(reach + thresholds));
  engine::HistogramBuilder builder(p.constants, 2);

  // Checks every kernel on the set's current nodes: ranges, dense and per-sample histograms,
  // and the fused pass where it applies, against core::FeatureResponse on the full frames.
  auto check_level = [&](int level) {
    std::vector<engine::NodePlan> plans;
    for (const auto& r : fx.set.ranges()) {
      engine::NodePlan plan;
      plan.node = r.node;
      plan.position = r.node;
      plan.num_samples = r.end - r.begin;
      std::vector<uint64_t> parts(core::kNumParts);
      fx.set.CountParts(r, core::kNumParts, parts.data());
      plan.SetParts(parts);
      plan.features = Features(70, reach, rng);
      plan.cut_stride = engine::CutStride(thresholds);
      plans.push_back(std::move(plan));
    }
    std::vector<std::vector<engine::ResponseRange>> ranges;
    builder.ComputeRanges(fx.set, p, 0, plans, &ranges);
    for (size_t q = 0; q < plans.size(); ++q) {
      const auto& pl = plans[q];
      const engine::NodeRange r = fx.set.RangeOf(pl.node);
      std::vector<engine::ResponseRange> naive(pl.features.size());
      for (size_t k = 0; k < pl.features.size(); ++k)
        for (uint64_t i = r.begin; i < r.end; ++i) naive[k].Add(fx.Naive(i, pl.features[k]));
      INFO("level " << level << " node " << pl.node << " samples " << pl.num_samples);
      CHECK(naive == ranges[q]);
      plans[q].cuts = engine::DrawCuts(p, 0, pl.position, ranges[q]);
    }
    std::vector<engine::NodeHistogram> dense, sparse;
    builder.Build(fx.set, plans, thresholds, &dense);
    std::vector<engine::NodePlan> sparse_plans = plans;
    for (auto& pl : sparse_plans) pl.sample_bins = true;
    builder.Build(fx.set, sparse_plans, thresholds, &sparse);
    for (size_t q = 0; q < plans.size(); ++q) {
      const auto& pl = plans[q];
      const engine::NodeRange r = fx.set.RangeOf(pl.node);
      engine::NodeHistogram naive;
      naive.Reset(pl.node, int(pl.features.size()), thresholds + 1, pl.num_slots);
      for (size_t k = 0; k < pl.features.size(); ++k) {
        const int32_t* cuts = &pl.cuts[k * size_t(pl.cut_stride)];
        for (uint64_t i = r.begin; i < r.end; ++i) {
          const int32_t f = fx.Naive(i, pl.features[k]);
          int bin = 0;
          for (int j = 0; j < pl.cut_stride; ++j) bin += f > cuts[j];
          ++naive.counts[(k * size_t(naive.num_bins) + size_t(bin)) * size_t(naive.num_slots) +
                         pl.part_slot[fx.set.part()[i]]];
        }
      }
      INFO("level " << level << " node " << pl.node << " samples " << pl.num_samples);
      CHECK(naive == dense[q]);
      CHECK(naive == sparse[q].ToDense());
    }
    // The fused single-shard pass (small nodes).
    std::vector<engine::NodePlan> fusable;
    for (auto pl : plans) {
      pl.cuts.clear();
      if (engine::HistogramBuilder::CanFuse(fx.set, p, pl)) fusable.push_back(std::move(pl));
    }
    if (!fusable.empty()) {
      std::vector<engine::NodeHistogram> fused;
      builder.BuildFused(fx.set, p, 0, fusable, &fused);
      for (size_t q = 0; q < fusable.size(); ++q) {
        const auto it = std::find_if(plans.begin(), plans.end(),
                                     [&](const engine::NodePlan& pl) { return pl.node == fusable[q].node; });
        CHECK(fusable[q].cuts == it->cuts);
        CHECK(fused[q] == dense[size_t(it - plans.begin())]);
      }
    }
  };

  // Level 0: one node of ~2000 samples (node-major kernels); then splits down to nodes of a
  // few hundred and a few dozen samples (sample-major kernels, fused pass), checking the
  // partition of ApplySplits against the naive responses on the way.
  for (int level = 0; level < 4; ++level) {
    check_level(level);
    std::vector<engine::SampleSet::Split> splits;
    std::vector<std::pair<uint64_t, bool>> expect;  // (uid, goes left) per sample
    uint32_t next = 1u << (level + 1);
    for (const auto& r : fx.set.ranges()) {
      const auto f = Features(3, reach, rng)[2];
      const int32_t cut = fx.Naive(r.begin + (r.end - r.begin) / 2, f);
      splits.push_back({r.node, f, cut, next});
      for (uint64_t i = r.begin; i < r.end; ++i) expect.push_back({fx.set.uid(i), fx.Naive(i, f) <= cut});
      next += 2;
    }
    // Naive partition: uid -> child.
    std::map<uint64_t, uint32_t> child;
    {
      size_t e = 0;
      for (size_t s = 0; s < splits.size(); ++s) {
        const auto r = fx.set.ranges()[s];
        for (uint64_t i = r.begin; i < r.end; ++i, ++e)
          child[expect[e].first] = expect[e].second ? splits[s].left_child : splits[s].left_child + 1;
      }
    }
    fx.set.ApplySplits(splits, p.constants, 2);
    size_t placed = 0;
    for (const auto& r : fx.set.ranges())
      for (uint64_t i = r.begin; i < r.end; ++i, ++placed) CHECK(child.at(fx.set.uid(i)) == r.node);
    CHECK(placed == child.size());
  }
}
