// The histogram builder and what it reads: pixel sampling, the builder against a naive evaluator,
// ranges, ApplySplits, and the sibling histogram by subtraction.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <map>

#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/sample_set.h"
#include "runtime/core/feature.h"

using namespace poseforest;

namespace {

engine::TrainParams SmallParams() {
  engine::TrainParams p;
  p.seed = 11;
  p.images_per_tree = 4;
  p.pixels_per_image = 300;
  p.candidate_features = 40;
  p.thresholds_per_feature = 12;
  p.max_probe_offset_pixel_m = 60;
  p.threshold_reference_pixels = 100;
  p.source.kind = engine::SourceKind::kProcedural;
  p.source.seed = 5;
  p.source.width = 160;
  p.source.height = 120;
  return p;
}

engine::SampleSet MakeSamples(const engine::TrainParams& p, int first, int count) {
  engine::SampleSet set;
  for (int i = first; i < first + count; ++i) {
    engine::LabelledFrame f = engine::MakeProceduralFrame(p.source, uint64_t(i));
    auto px = engine::SamplePixels(f, p.pixels_per_image, 1.0,
                                   core::CounterRng(p.seed, 0, uint64_t(i), engine::kSamplingStream));
    set.AddFrame(uint64_t(i), std::move(f.depth), px, p.constants);
  }
  set.StartTree(0);
  return set;
}

/// The procedural depth frame of sample i, generated afresh (independent of the set's storage).
const core::DepthImage& FrameOf(const engine::TrainParams& p, const engine::SampleSet& set, size_t i) {
  static std::map<std::pair<uint64_t, uint64_t>, core::DepthImage> cache;
  const auto key = std::make_pair(p.source.seed, set.frame_index(i));
  auto it = cache.find(key);
  if (it == cache.end())
    it = cache.emplace(key, engine::MakeProceduralFrame(p.source, key.second).depth).first;
  return it->second;
}

/// Eq. 1 at sample i by core::FeatureResponse on the regenerated frame.
int32_t NaiveResponse(const engine::TrainParams& p, const engine::SampleSet& set, size_t i,
                      const core::FeatureOffsets& f) {
  return core::FeatureResponse(FrameOf(p, set, i), set.x()[i], set.y()[i], f, p.constants);
}

engine::NodePlan PlanFor(const engine::TrainParams& p, const engine::SampleSet& s, uint32_t node) {
  engine::NodePlan plan;
  plan.node = node;
  plan.position = node;  // any key works as long as plan, DrawFeatures and DrawCuts agree
  const engine::NodeRange r = s.RangeOf(node);
  plan.num_samples = r.end - r.begin;
  std::vector<uint64_t> parts(core::kNumParts);
  s.CountParts(r, core::kNumParts, parts.data());
  plan.SetParts(parts);
  plan.features = engine::DrawFeatures(p, 0, node);
  plan.cut_stride = engine::CutStride(p.thresholds_per_feature);
  return plan;
}

}  // namespace

TEST_CASE("pixel sampling is deterministic, on the body, and balances parts", "[training][sampling]") {
  engine::SourceSpec spec;
  spec.seed = 3;
  spec.width = 320;
  spec.height = 240;
  const engine::LabelledFrame f = engine::MakeProceduralFrame(spec, 7);
  const core::CounterRng rng(1, 0, 7, engine::kSamplingStream);
  const auto a = engine::SamplePixels(f, 620, 1.0, rng), b = engine::SamplePixels(f, 620, 1.0, rng);
  REQUIRE(a.size() == 620);
  REQUIRE(a.size() == b.size());
  std::map<int, int> per_part, pixels_per_part;
  for (size_t i = 0; i < a.size(); ++i) {
    CHECK((a[i].x == b[i].x && a[i].y == b[i].y));
    CHECK(f.depth.at(a[i].x, a[i].y) != 0);
    CHECK(f.labels.at(a[i].x, a[i].y) == a[i].part);
    ++per_part[a[i].part];
  }
  for (size_t i = 0; i < f.labels.pixels.size(); ++i)
    if (f.labels.pixels[i] < core::kNumParts) ++pixels_per_part[f.labels.pixels[i]];
  // Every visible part gets 620 / parts pixels (or all it has), within one.
  const int quota = 620 / int(pixels_per_part.size());
  for (auto [part, n] : pixels_per_part) CHECK(per_part[part] >= std::min(n, quota));
  // No duplicates.
  for (size_t i = 1; i < a.size(); ++i) CHECK((a[i].y * 10000 + a[i].x) > (a[i - 1].y * 10000 + a[i - 1].x));
  // Another key draws other pixels.
  const auto c = engine::SamplePixels(f, 620, 1.0, core::CounterRng(2, 0, 7, engine::kSamplingStream));
  int same = 0;
  for (size_t i = 0; i < c.size(); ++i) same += (c[i].x == a[i].x && c[i].y == a[i].y);
  CHECK(same < int(c.size()));
  // Fewer body pixels than asked: all of them.
  CHECK(engine::SamplePixels(f, 10'000'000, 1.0, rng).size() ==
        size_t(std::count_if(f.labels.pixels.begin(), f.labels.pixels.end(),
                             [](uint8_t l) { return l < core::kNumParts; })));
}

TEST_CASE("pixel_probe_share: that share of the candidates has v = 0, the rest the paper's draw",
          "[training][candidates]") {
  engine::TrainParams p = SmallParams();
  p.candidate_features = 2000;
  const auto paper = engine::DrawFeatures(p, 1, 77);
  size_t zero_v = 0;
  for (const auto& f : paper) zero_v += f.vx == 0 && f.vy == 0;
  CHECK(zero_v == 0);
  for (const double share : {0.25, 0.5, 1.0}) {
    INFO("share " << share);
    p.pixel_probe_share = share;
    const auto drawn = engine::DrawFeatures(p, 1, 77);
    REQUIRE(drawn.size() == paper.size());
    CHECK(drawn == engine::DrawFeatures(p, 1, 77));  // deterministic
    CHECK(drawn != engine::DrawFeatures(p, 1, 78));  // keyed by the node
    size_t pixel = 0, same = 0;
    for (size_t k = 0; k < drawn.size(); ++k) {
      CHECK(drawn[k].ux == paper[k].ux);  // u as the paper's draw
      CHECK(drawn[k].uy == paper[k].uy);
      if (drawn[k].vx == 0 && drawn[k].vy == 0) ++pixel;
      same += drawn[k] == paper[k];
    }
    CHECK(pixel + same == drawn.size());  // each is the paper's feature or its pixel-probe form
    const double expected = share * double(drawn.size());
    CHECK(std::abs(double(pixel) - expected) < 4 * std::sqrt(expected * (1 - share)) + 1);
  }
}

TEST_CASE("histogram builder equals a naive evaluator, for any thread count", "[training][histogram]") {
  // 12 / 50 thresholds: vector kernels with 16 / 64 cut slots; 100: the scalar path. A large
  // reference size makes the range pass cover whole nodes (sample-major kernel).
  const int thresholds = GENERATE(12, 50, 100);
  const uint64_t reference = GENERATE(100, 100000);
  engine::TrainParams p = SmallParams();
  p.thresholds_per_feature = thresholds;
  p.threshold_reference_pixels = reference;
  p.pixel_probe_share = GENERATE(0.0, 0.5);  // half the candidates against the pixel itself
  const engine::SampleSet set = MakeSamples(p, 0, 4);
  std::vector<engine::NodePlan> plans{PlanFor(p, set, 0)};
  engine::HistogramBuilder b1(p.constants, 1), b2(p.constants, 2);
  std::vector<std::vector<engine::ResponseRange>> r1, r2;
  b1.ComputeRanges(set, p, 0, plans, &r1);
  b2.ComputeRanges(set, p, 0, plans, &r2);
  REQUIRE(r1 == r2);
  // Naive ranges over the reference subsample.
  const engine::ReferenceSelector sel(p, 0, 0, plans[0].num_samples);
  size_t selected = 0;
  for (size_t k = 0; k < plans[0].features.size(); ++k) {
    engine::ResponseRange naive;
    for (size_t i = 0; i < set.num_samples(); ++i) {
      if (!sel.Selected(set.uid(i))) continue;
      selected += k == 0;
      naive.Add(NaiveResponse(p, set, i, plans[0].features[k]));
    }
    CHECK(naive == r1[0][k]);
  }
  // ~threshold_reference_pixels of the node's samples are selected.
  if (reference == 100) {
    CHECK(selected > 50);
    CHECK(selected < 200);
  } else {
    CHECK(selected == set.num_samples());
  }
  plans[0].cuts = engine::DrawCuts(p, 0, 0, r1[0]);
  std::vector<engine::NodeHistogram> h1, h2;
  b1.Build(set, plans, p.thresholds_per_feature, &h1);
  b2.Build(set, plans, p.thresholds_per_feature, &h2);
  REQUIRE(h1 == h2);
  CHECK(b1.evaluations() == set.num_samples() * plans[0].features.size());
  // Naive: linear count of cuts below the response (frames regenerated).
  std::vector<std::vector<int32_t>> responses(set.num_samples());
  for (size_t i = 0; i < set.num_samples(); ++i)
    for (const auto& f : plans[0].features) responses[i].push_back(NaiveResponse(p, set, i, f));
  engine::NodeHistogram naive;
  naive.Reset(0, int(plans[0].features.size()), p.thresholds_per_feature + 1, plans[0].num_slots);
  for (size_t k = 0; k < plans[0].features.size(); ++k) {
    const int32_t* cuts = &plans[0].cuts[k * size_t(plans[0].cut_stride)];
    for (size_t i = 0; i < set.num_samples(); ++i) {
      const int32_t f = responses[i][k];
      int bin = 0;
      for (int j = 0; j < plans[0].cut_stride; ++j) bin += f > cuts[j];
      ++naive.counts[(k * size_t(naive.num_bins) + size_t(bin)) * size_t(naive.num_slots) +
                     plans[0].part_slot[set.part()[i]]];
    }
  }
  CHECK(naive == h1[0]);
  // The per-sample-bins form counts the same.
  std::vector<engine::NodePlan> sparse_plans = plans;
  sparse_plans[0].sample_bins = true;
  std::vector<engine::NodeHistogram> hs1, hs2;
  b1.Build(set, sparse_plans, p.thresholds_per_feature, &hs1);
  b2.Build(set, sparse_plans, p.thresholds_per_feature, &hs2);
  CHECK(hs1 == hs2);
  CHECK(hs1[0].sample_bins);
  CHECK(hs1[0].sample_slot.size() == set.num_samples());
  CHECK(hs1[0].ToDense() == naive);
  // Cuts are sorted, unique, within the range, padded.
  for (size_t k = 0; k < plans[0].features.size(); ++k) {
    const int32_t* cuts = &plans[0].cuts[k * size_t(plans[0].cut_stride)];
    for (int j = 0; j + 1 < plans[0].cut_stride; ++j)
      CHECK((cuts[j] < cuts[j + 1] || cuts[j + 1] == engine::kNoCut));
    if (cuts[0] != engine::kNoCut) {
      CHECK(cuts[0] >= r1[0][k].lo);
      CHECK(cuts[0] < r1[0][k].hi);
    }
  }
}

TEST_CASE("shards' histograms sum to the whole set's", "[training][histogram]") {
  const engine::TrainParams p = SmallParams();
  const engine::SampleSet all = MakeSamples(p, 0, 4), s0 = MakeSamples(p, 0, 1), s1 = MakeSamples(p, 1, 3);
  std::vector<engine::NodePlan> plans{PlanFor(p, all, 0)};
  engine::HistogramBuilder b(p.constants, 2);
  std::vector<std::vector<engine::ResponseRange>> ra, r0, r1;
  b.ComputeRanges(all, p, 0, plans, &ra);
  b.ComputeRanges(s0, p, 0, plans, &r0);
  b.ComputeRanges(s1, p, 0, plans, &r1);
  for (size_t k = 0; k < ra[0].size(); ++k) {
    r0[0][k].Merge(r1[0][k]);
    CHECK(r0[0][k] == ra[0][k]);
  }
  plans[0].cuts = engine::DrawCuts(p, 0, 0, ra[0]);
  std::vector<engine::NodeHistogram> ha, h0, h1;
  b.Build(all, plans, p.thresholds_per_feature, &ha);
  b.Build(s0, plans, p.thresholds_per_feature, &h0);
  b.Build(s1, plans, p.thresholds_per_feature, &h1);
  h0[0].Add(h1[0]);
  CHECK(h0[0] == ha[0]);
}

TEST_CASE(
    "ApplySplits moves samples by the split and the sibling histogram by subtraction equals a direct build",
    "[training][histogram]") {
  const engine::TrainParams p = SmallParams();
  engine::SampleSet set = MakeSamples(p, 0, 4);
  const size_t n = set.num_samples();
  std::vector<engine::NodePlan> plans{PlanFor(p, set, 0)};
  engine::HistogramBuilder b(p.constants, 2);
  std::vector<std::vector<engine::ResponseRange>> r;
  b.ComputeRanges(set, p, 0, plans, &r);
  plans[0].cuts = engine::DrawCuts(p, 0, 0, r[0]);
  std::vector<engine::NodeHistogram> parent;
  b.Build(set, plans, p.thresholds_per_feature, &parent);
  // Split the root by candidate 0 at its middle cut; count the expected left side directly.
  const core::FeatureOffsets f = plans[0].features[0];
  const int32_t cut = plans[0].cuts[3];
  REQUIRE(cut != engine::kNoCut);
  std::vector<uint64_t> uid_left, uid_right;
  for (size_t i = 0; i < n; ++i) {
    (NaiveResponse(p, set, i, f) < float(cut) + 0.5f ? uid_left : uid_right).push_back(set.uid(i));
  }
  REQUIRE(!uid_left.empty());
  REQUIRE(!uid_right.empty());
  const engine::SampleSet::Split split{0, f, cut, 1};
  set.ApplySplits(std::span(&split, 1), p.constants, 2);
  REQUIRE(set.ranges().size() == 2);
  CHECK(set.ranges()[0].node == 1);
  CHECK(set.ranges()[1].node == 2);
  std::vector<uint64_t> got_left, got_right;
  for (uint64_t i = set.ranges()[0].begin; i < set.ranges()[0].end; ++i) got_left.push_back(set.uid(i));
  for (uint64_t i = set.ranges()[1].begin; i < set.ranges()[1].end; ++i) got_right.push_back(set.uid(i));
  CHECK(got_left == uid_left);  // order kept: (frame, pixel)
  CHECK(got_right == uid_right);
  // Children with the parent's candidates and cuts: right = parent - left.
  engine::NodePlan left_plan = plans[0], right_plan = plans[0];
  left_plan.node = 1;
  right_plan.node = 2;
  std::vector<engine::NodeHistogram> left, right;
  b.Build(set, std::span(&left_plan, 1), p.thresholds_per_feature, &left);
  b.Build(set, std::span(&right_plan, 1), p.thresholds_per_feature, &right);
  engine::NodeHistogram by_subtraction;
  by_subtraction.node = 2;
  by_subtraction.SetDifference(parent[0], left[0]);
  CHECK(by_subtraction == right[0]);
  // A leaf drops its samples.
  const engine::SampleSet::Split only_left{1, f, cut, 3};
  set.ApplySplits(std::span(&only_left, 1), p.constants, 1);
  uint64_t kept = 0;
  for (const auto& rg : set.ranges()) kept += rg.end - rg.begin;
  CHECK(kept == uid_left.size());
  CHECK(set.num_samples() == uid_left.size());
}

TEST_CASE("small nodes: sample-major kernels and per-sample bins equal the naive evaluator",
          "[training][histogram]") {
  engine::TrainParams p = SmallParams();
  p.thresholds_per_feature = GENERATE(8, 50, 100);  // 100: the scalar paths
  p.threshold_reference_pixels = 1000000;
  engine::SampleSet set = MakeSamples(p, 0, 4);
  // Four levels of splits at each node's middle response: 16 nodes of ~75 samples.
  for (int level = 0; level < 4; ++level) {
    std::vector<engine::SampleSet::Split> splits;
    uint32_t next = uint32_t(set.ranges().back().node) + 1;
    for (const auto& r : set.ranges()) {
      const auto f = engine::DrawFeatures(p, 0, r.node)[0];
      std::vector<int32_t> resp;
      for (uint64_t i = r.begin; i < r.end; ++i)
        resp.push_back(set.Response(i, f, p.constants.background_mm));
      std::nth_element(resp.begin(), resp.begin() + long(resp.size() / 2), resp.end());
      splits.push_back({r.node, f, resp[resp.size() / 2], next});
      next += 2;
    }
    set.ApplySplits(splits, p.constants, 2);
  }
  REQUIRE(set.ranges().size() >= 8);
  std::vector<engine::NodePlan> plans;
  for (const auto& r : set.ranges()) plans.push_back(PlanFor(p, set, r.node));
  engine::HistogramBuilder b(p.constants, 2);
  std::vector<std::vector<engine::ResponseRange>> rr;
  b.ComputeRanges(set, p, 0, plans, &rr);
  for (size_t q = 0; q < plans.size(); ++q) plans[q].cuts = engine::DrawCuts(p, 0, plans[q].node, rr[q]);
  std::vector<engine::NodeHistogram> dense, sparse;
  b.Build(set, plans, p.thresholds_per_feature, &dense);
  // The fused single-shard pass derives the same cuts and counts.
  std::vector<engine::NodePlan> fused_plans = plans;
  for (auto& plan : fused_plans) {
    REQUIRE(engine::HistogramBuilder::CanFuse(set, p, plan));
    plan.cuts.clear();
  }
  std::vector<engine::NodeHistogram> fused;
  b.BuildFused(set, p, 0, fused_plans, &fused);
  for (size_t q = 0; q < plans.size(); ++q) {
    CHECK(fused_plans[q].cuts == plans[q].cuts);
    CHECK(fused[q] == dense[q]);
  }
  for (auto& plan : plans) plan.sample_bins = true;
  b.Build(set, plans, p.thresholds_per_feature, &sparse);
  fused_plans = plans;
  std::vector<engine::NodeHistogram> fused_sparse;
  b.BuildFused(set, p, 0, fused_plans, &fused_sparse);
  for (size_t q = 0; q < plans.size(); ++q) CHECK(fused_sparse[q] == sparse[q]);
  for (size_t q = 0; q < plans.size(); ++q) {
    const engine::NodeRange r = set.RangeOf(plans[q].node);
    engine::NodeHistogram naive;
    naive.Reset(plans[q].node, int(plans[q].features.size()), p.thresholds_per_feature + 1,
                plans[q].num_slots);
    for (uint64_t i = r.begin; i < r.end; ++i) {
      for (size_t k = 0; k < plans[q].features.size(); ++k) {
        const int32_t f = NaiveResponse(p, set, i, plans[q].features[k]);
        CHECK(f >= rr[q][k].lo);
        CHECK(f <= rr[q][k].hi);
        int bin = 0;
        for (int j = 0; j < plans[q].cut_stride; ++j)
          bin += f > plans[q].cuts[k * size_t(plans[q].cut_stride) + size_t(j)];
        ++naive.counts[(k * size_t(naive.num_bins) + size_t(bin)) * size_t(naive.num_slots) +
                       plans[q].part_slot[set.part()[i]]];
      }
    }
    CHECK(dense[q] == naive);
    CHECK(sparse[q].ToDense() == naive);
  }
}

TEST_CASE("16-bit binning: saturated responses and cuts at the int16 limits equal the naive evaluator",
          "[training][histogram]") {
  // A far background (60000 mm) makes responses reach +-6e4, beyond int16: candidates whose cuts
  // all lie in [-32767, 32766] are binned in 16-bit lanes on saturated responses, the others by
  // the int32 kernels. 1 frame (300 samples): the sample-major kernels; 4 frames: candidate-major.
  engine::TrainParams p = SmallParams();
  p.constants.background_mm = 60000;
  p.thresholds_per_feature = GENERATE(8, 50);
  const int frames = GENERATE(1, 4);
  const engine::SampleSet set = MakeSamples(p, 0, frames);
  engine::NodePlan plan = PlanFor(p, set, 0);
  const int stride = plan.cut_stride, t = p.thresholds_per_feature;
  // Hand-made cuts per candidate (ascending, unique, padded): at the int16 limits [-32767, 32766]
  // (16-bit kernels on saturated responses) or one past them (int32 kernels). mixed == 0: every
  // candidate at the limits (every kernel takes its 16-bit form); mixed == 1: k % 3 == 0 at the
  // limits, k % 3 == 1 past them, k % 3 == 2 drawn from the ranges (which reach beyond int16).
  const int mixed = GENERATE(0, 1);
  engine::HistogramBuilder b(p.constants, 2);
  std::vector<std::vector<engine::ResponseRange>> rr;
  b.ComputeRanges(set, p, 0, std::span(&plan, 1), &rr);
  plan.cuts = engine::DrawCuts(p, 0, 0, rr[0]);
  size_t saturated = 0;
  for (size_t k = 0; k < plan.features.size(); ++k) {
    if (mixed && k % 3 == 2) continue;
    const bool past = mixed && k % 3 == 1;
    std::vector<int32_t> cuts{past ? -32768 : -32767, -20000, -500, 0, 500, 20000, past ? 32767 : 32766};
    cuts.resize(std::min<size_t>(cuts.size(), size_t(t)));
    int32_t* c = &plan.cuts[k * size_t(stride)];
    std::fill(c, c + stride, engine::kNoCut);
    std::copy(cuts.begin(), cuts.end(), c);
  }
  std::vector<engine::NodeHistogram> dense, sparse;
  b.Build(set, std::span(&plan, 1), t, &dense);
  engine::NodePlan sparse_plan = plan;
  sparse_plan.sample_bins = true;
  b.Build(set, std::span(&sparse_plan, 1), t, &sparse);
  engine::NodeHistogram naive;
  naive.Reset(0, int(plan.features.size()), t + 1, plan.num_slots);
  for (size_t i = 0; i < set.num_samples(); ++i) {
    for (size_t k = 0; k < plan.features.size(); ++k) {
      const int32_t f = NaiveResponse(p, set, i, plan.features[k]);
      saturated += f > 32767 || f < -32768;
      int bin = 0;
      for (int j = 0; j < stride; ++j) bin += f > plan.cuts[k * size_t(stride) + size_t(j)];
      ++naive.counts[(k * size_t(naive.num_bins) + size_t(bin)) * size_t(naive.num_slots) +
                     plan.part_slot[set.part()[i]]];
    }
  }
  CHECK(saturated > 100);  // the test reaches responses beyond int16
  CHECK(dense[0] == naive);
  CHECK(sparse[0].ToDense() == naive);
  // The fused pass (cuts from the ranges, which here reach beyond int16) agrees with the
  // two-phase build on the same node.
  if (frames == 1) {
    p.threshold_reference_pixels = 1000000;
    engine::NodePlan two = PlanFor(p, set, 0), fused = two;
    b.ComputeRanges(set, p, 0, std::span(&two, 1), &rr);
    two.cuts = engine::DrawCuts(p, 0, 0, rr[0]);
    std::vector<engine::NodeHistogram> h2, hf;
    b.Build(set, std::span(&two, 1), t, &h2);
    REQUIRE(engine::HistogramBuilder::CanFuse(set, p, fused));
    b.BuildFused(set, p, 0, std::span(&fused, 1), &hf);
    CHECK(fused.cuts == two.cuts);
    CHECK(hf[0] == h2[0]);
  }
}
