// engine::Shard, what LocalShardSet holds N of and a worker one: the same samples in one shard
// or spread over two give the same census, the same merged ranges, the same histograms (fused
// on one shard or summed over two) and the same routing; frames load the same on any number of
// threads; the wire forms of a fused node's cuts and of a node's frame list.
#include <catch2/catch.hpp>

#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/sample_set.h"
#include "engine/shard.h"
#include "engine/wire_codec.h"
#include "runtime/core/body_parts.h"

using namespace poseforest;

namespace {

engine::TrainParams Params(int reference_pixels) {
  engine::TrainParams p;
  p.seed = 23;
  p.images_per_tree = 6;
  p.pixels_per_image = 200;
  p.candidate_features = 40;
  p.thresholds_per_feature = 12;
  p.max_probe_offset_pixel_m = 60;
  p.threshold_reference_pixels = reference_pixels;
  p.threads = 2;
  p.source.kind = engine::SourceKind::kProcedural;
  p.source.seed = 9;
  p.source.width = 160;
  p.source.height = 120;
  return p;
}

/// Tree 0's frames in `num_shards` sample sets, contiguous blocks of frames (as LocalTrainer).
std::vector<engine::SampleSet> Sets(const engine::TrainParams& p, int num_shards) {
  std::vector<uint64_t> indices;
  for (int i = 0; i < p.images_per_tree; ++i) indices.push_back(uint64_t(i));
  std::vector<engine::ShardFrame> frames;
  REQUIRE(engine::LoadFrames(p, 0, indices, 2, &frames).ok());
  std::vector<engine::SampleSet> sets(static_cast<size_t>(num_shards));
  for (int i = 0; i < p.images_per_tree; ++i) {
    if (frames[size_t(i)].picked.empty()) continue;
    sets[size_t(i * num_shards / p.images_per_tree)].AddFrame(uint64_t(i), frames[size_t(i)].frame,
                                                               frames[size_t(i)].picked, p.constants);
  }
  for (auto& s : sets) s.StartTree(0);
  return sets;
}

std::vector<uint64_t> Census(std::span<const engine::Shard> shards, uint32_t node) {
  std::vector<uint64_t> sum(static_cast<size_t>(core::kNumParts), 0);
  for (const engine::Shard& s : shards) {
    const auto c = s.CountParts(node);
    REQUIRE(c.size() == sum.size());
    for (size_t p = 0; p < c.size(); ++p) sum[p] += c[p];
  }
  return sum;
}

/// The plan of node `node` as the frontier loop makes it.
engine::NodePlan PlanOf(const engine::TrainParams& p, uint32_t node, uint64_t position,
                        const std::vector<uint64_t>& parts) {
  engine::NodePlan plan;
  plan.node = node;
  plan.position = position;
  for (uint64_t c : parts) plan.num_samples += c;
  plan.SetShape(parts, p.thresholds_per_feature);
  plan.features = engine::DrawFeatures(p, 0, position);
  return plan;
}

/// Node `node`'s complete histogram (dense) and cuts through `shards`: pass 1, then pass 2
/// unless a shard built it fused.
std::pair<engine::NodeHistogram, std::vector<int32_t>> Build(const engine::TrainParams& p,
                                                             std::span<const engine::Shard> shards, uint32_t node,
                                                             uint64_t position, bool* fused) {
  std::vector<engine::NodePlan> plans{PlanOf(p, node, position, Census(shards, node))};
  engine::FirstPass pass;
  engine::RunFirstPass(shards, 0, plans, &pass);
  REQUIRE(pass.fused.size() == 1);
  *fused = pass.fused[0] != 0;
  if (*fused) return {pass.hists[0].ToDense(), plans[0].cuts};
  plans[0].cuts = engine::DrawCuts(p, 0, position, pass.ranges[0]);
  std::vector<engine::NodeHistogram> hists;
  engine::SumHistograms(shards, plans, &hists);
  return {hists[0].ToDense(), plans[0].cuts};
}

}  // namespace

TEST_CASE("frames load the same on any number of threads and with one source", "[engine][shard]") {
  const engine::TrainParams p = Params(100);
  const std::vector<uint64_t> indices{0, 3, 4, 5};
  std::vector<engine::ShardFrame> one, three, with;
  REQUIRE(engine::LoadFrames(p, 1, indices, 1, &one).ok());
  REQUIRE(engine::LoadFrames(p, 1, indices, 3, &three).ok());
  auto source = engine::MakeImageSource(p.source);
  REQUIRE(source.ok());
  REQUIRE(engine::LoadFramesWith(**source, p, 1, indices, &with).ok());
  REQUIRE(one.size() == indices.size());
  for (size_t j = 0; j < indices.size(); ++j) {
    for (const auto* other : {&three, &with}) {
      const engine::ShardFrame& f = (*other)[j];
      CHECK(f.frame.pixels == one[j].frame.pixels);
      CHECK(f.frame.width == one[j].frame.width);
      REQUIRE(f.picked.size() == one[j].picked.size());
      for (size_t k = 0; k < f.picked.size(); ++k)
        CHECK((f.picked[k].x == one[j].picked[k].x && f.picked[k].y == one[j].picked[k].y &&
               f.picked[k].part == one[j].picked[k].part));
    }
  }
  CHECK_FALSE(one[0].picked.empty());
}

TEST_CASE("one shard or two: the same census, ranges, histograms and routing", "[engine][shard]") {
  // 100 reference pixels: the root's ranges come from a subsample (merged over shards); a
  // million: the root fuses on the one shard and goes through both passes on two.
  for (const int reference_pixels : {100, 1000000}) {
    const engine::TrainParams p = Params(reference_pixels);
    std::vector<engine::SampleSet> one_set = Sets(p, 1), two_sets = Sets(p, 2);
    engine::HistogramBuilder b1(p.constants, 2), b2(p.constants, 2);
    const std::vector<engine::Shard> one{engine::Shard(one_set[0], p, b1)};
    const std::vector<engine::Shard> two{engine::Shard(two_sets[0], p, b2), engine::Shard(two_sets[1], p, b2)};
    REQUIRE(two_sets[0].num_samples() > 0);
    REQUIRE(two_sets[1].num_samples() > 0);
    const auto census = Census(one, 0);
    CHECK(census == Census(two, 0));

    bool fused1 = false, fused2 = false;
    const auto [h1, cuts1] = Build(p, one, 0, engine::kRootPosition, &fused1);
    const auto [h2, cuts2] = Build(p, two, 0, engine::kRootPosition, &fused2);
    CHECK(fused1 == (reference_pixels > 1000));
    CHECK_FALSE(fused2);  // the root's samples sit on both shards
    CHECK(cuts1 == cuts2);
    CHECK(h1.counts == h2.counts);
    CHECK(b1.evaluations() == b2.evaluations());

    // A split of the root routes the same samples to the same children.
    std::vector<engine::NodePlan> plans{PlanOf(p, 0, engine::kRootPosition, census)};
    const engine::SampleSet::Split split{0, plans[0].features[3], cuts1[size_t(3 * engine::CutStride(p.thresholds_per_feature))], 1};
    for (const auto& s : one) s.ApplySplits(std::span(&split, 1), 2);
    for (const auto& s : two) s.ApplySplits(std::span(&split, 1), 2);
    for (uint32_t child : {1u, 2u}) CHECK(Census(one, child) == Census(two, child));
    const auto left = Census(one, 1), right = Census(one, 2);
    for (size_t c = 0; c < census.size(); ++c) CHECK(left[c] + right[c] == census[c]);
  }
}

TEST_CASE("a fused node's cuts and a node's frame list in their wire form", "[engine][shard][wire]") {
  const engine::TrainParams p = Params(1000000);
  std::vector<engine::SampleSet> sets = Sets(p, 1);
  engine::HistogramBuilder builder(p.constants, 2);
  const engine::Shard shard(sets[0], p, builder);
  std::vector<engine::NodePlan> plans{PlanOf(p, 0, engine::kRootPosition, shard.CountParts(0))};
  REQUIRE(shard.CanFuse(plans[0]));
  std::vector<engine::NodeHistogram> hists;
  shard.BuildFused(0, plans, &hists);
  v1::NodeRanges ranges;
  engine::EncodeCuts(plans[0], &ranges);
  std::vector<int32_t> cuts;
  REQUIRE(engine::DecodeCuts(ranges, int(plans[0].features.size()), plans[0].cut_stride, &cuts));
  CHECK(cuts == plans[0].cuts);
  ranges.add_cut_deltas(1);  // one delta too many
  CHECK_FALSE(engine::DecodeCuts(ranges, int(plans[0].features.size()), plans[0].cut_stride, &cuts));

  v1::NodeRanges frames;
  const engine::SampleSet& s = sets[0];
  engine::EncodeNodeFrames(s, s.RangeOf(0), &frames);
  CHECK(frames.num_samples() == s.num_samples());
  REQUIRE(frames.pixel_deltas_size() == int(s.num_samples()));
  size_t i = 0;
  for (int e = 0; e < frames.frames_size(); ++e) {
    uint32_t pixel = 0;
    for (uint32_t j = 0; j < frames.frame_samples(e); ++j, ++i) {
      pixel += frames.pixel_deltas(int(i));
      CHECK(s.frame_index(i) == frames.frames(e));
      CHECK(pixel == uint32_t(s.y()[i]) * uint32_t(p.source.width) + uint32_t(s.x()[i]));
    }
  }
  CHECK(i == s.num_samples());
}
