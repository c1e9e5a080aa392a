// The engine's frontier loop alone (engine/frontier_loop.h) over in-process shards of
// procedural frames: the hooks its three users rely on. A node taken out of a level and
// decided elsewhere (the coordinator's delegated subtrees) is followed exactly; a hook's error
// ends the loop; the shard count changes no decision.
#include <catch2/catch.hpp>
#include <map>

#include "engine/candidates.h"
#include "engine/frontier_loop.h"
#include "engine/image_source.h"
#include "engine/local_shard_set.h"
#include "engine/sample_set.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/rng.h"

using namespace poseforest;

namespace {

engine::TrainParams Params() {
  engine::TrainParams p;
  p.seed = 17;
  p.max_depth = 8;
  p.images_per_tree = 8;
  p.pixels_per_image = 300;
  p.candidate_features = 40;
  p.thresholds_per_feature = 12;
  p.max_probe_offset_pixel_m = 80;
  p.min_samples_split = 4;
  p.threshold_reference_pixels = 100;
  p.threads = 2;
  p.source.kind = engine::SourceKind::kProcedural;
  p.source.seed = 5;
  p.source.width = 160;
  p.source.height = 120;
  return p;
}

/// Tree 0's frames spread over `num_shards` shards in contiguous blocks (as LocalTrainer does).
std::vector<engine::SampleSet> Shards(const engine::TrainParams& p, int num_shards) {
  auto source = engine::MakeImageSource(p.source);
  REQUIRE(source.ok());
  std::vector<engine::SampleSet> shards(static_cast<size_t>(num_shards));
  for (int i = 0; i < p.images_per_tree; ++i) {
    auto frame = (*source)->Frame(uint64_t(i));
    REQUIRE(frame.ok());
    const auto picked =
        engine::SamplePixels(*frame, p.pixels_per_image, p.part_balance,
                             core::CounterRng(p.seed, 0, uint64_t(i), engine::kSamplingStream));
    if (picked.empty()) continue;
    shards[size_t(i * num_shards / p.images_per_tree)].AddFrame(uint64_t(i), frame->depth, picked,
                                                                p.constants);
  }
  for (auto& s : shards) s.StartTree(0);
  return shards;
}

/// One placed node as the loop reported it.
struct Placed {
  uint64_t position;
  bool split;
  int32_t cut;
  core::FeatureOffsets offsets;
  std::vector<uint64_t> parts;
  bool operator==(const Placed& o) const {
    return position == o.position && split == o.split && cut == o.cut && offsets.ux == o.offsets.ux &&
           offsets.uy == o.offsets.uy && offsets.vx == o.offsets.vx && offsets.vy == o.offsets.vy &&
           parts == o.parts;
  }
};

struct Run {
  std::vector<Placed> placed;  ///< frontier order, level by level
  core::Status status;
  int levels = 0;
};

/// Runs the loop on tree 0 over `num_shards` shards. `decided_elsewhere`: nodes (by position)
/// the before_decide hook takes out of every level and `place` fills in from that map, with
/// the children's part counts from `parts_of`.
Run Grow(int num_shards, const std::map<uint64_t, Placed>* decided_elsewhere = nullptr, int stop_after = -1,
         const std::map<uint64_t, std::vector<uint64_t>>* parts_of = nullptr) {
  const engine::TrainParams p = Params();
  std::vector<engine::SampleSet> shards = Shards(p, num_shards);
  engine::HistogramBuilder builder(p.constants, 2);
  engine::LocalShardSet set(shards, p, builder, 2);
  std::vector<engine::OpenNode> frontier(1);
  frontier[0].position = engine::kRootPosition;
  REQUIRE(set.CountParts(0, &frontier[0].parts).ok());
  Run run;
  uint32_t next_local = 1;
  engine::FrontierLoopHooks hooks;
  hooks.before_decide = [&](int, std::span<const engine::OpenNode> level, std::vector<size_t>* to_split) {
    if (decided_elsewhere)
      std::erase_if(*to_split, [&](size_t i) { return decided_elsewhere->count(level[i].position) > 0; });
    return core::Status::Ok();
  };
  hooks.place = [&](const engine::OpenNode& f, engine::NodeDecision& d) -> core::Result<uint32_t> {
    if (decided_elsewhere) {
      if (auto it = decided_elsewhere->find(f.position); it != decided_elsewhere->end()) {
        REQUIRE_FALSE(d.tried);  // taken out: the loop must not have searched it
        d.split = it->second.split;
        d.offsets = it->second.offsets;
        d.choice.cut = it->second.cut;
        if (d.split) {
          d.choice.left_parts = parts_of->at(engine::LeftChildPosition(f.position));
          d.choice.right_parts = parts_of->at(engine::RightChildPosition(f.position));
        }
      }
    }
    run.placed.push_back({f.position, d.split, d.split ? d.choice.cut : 0,
                          d.split ? d.offsets : core::FeatureOffsets{}, f.parts});
    if (!d.split) return uint32_t(0);
    const uint32_t left = next_local;
    next_local += 2;
    return left;
  };
  hooks.level_done = [&](const engine::LevelDone& done) {
    ++run.levels;
    if (stop_after >= 0 && run.levels >= stop_after)
      return core::Status(core::ErrorCode::kInternal, "stop at level " + std::to_string(done.level));
    return core::Status::Ok();
  };
  run.status = engine::RunFrontierLoop(set, p, 0, 0, std::move(frontier), 1, p.histogram_memory_bytes, hooks);
  return run;
}

}  // namespace

TEST_CASE("frontier loop: the shard count changes no decision", "[engine][unit]") {
  const Run one = Grow(1);
  REQUIRE(one.status.ok());
  REQUIRE(one.placed.size() > 20);
  size_t splits = 0;
  for (const Placed& n : one.placed) splits += n.split;
  CHECK(splits > 5);
  const Run three = Grow(3);
  REQUIRE(three.status.ok());
  CHECK(three.placed == one.placed);
}

TEST_CASE("frontier loop: nodes decided elsewhere are followed, their samples routed", "[engine][unit]") {
  const Run full = Grow(2);
  REQUIRE(full.status.ok());
  std::map<uint64_t, std::vector<uint64_t>> parts_of;
  std::map<uint64_t, Placed> all;
  for (const Placed& n : full.placed) parts_of[n.position] = n.parts, all[n.position] = n;
  // The root's left child (position 1) and its right grandchild (position 4) decided
  // "elsewhere", as the loop decided them: the run must come out the same, which needs their
  // splits applied to the shards (the loop searches their children over the routed samples).
  REQUIRE(all.at(1).split);
  REQUIRE(all.at(4).split);
  const std::map<uint64_t, Placed> elsewhere{{1, all.at(1)}, {4, all.at(4)}};
  const Run followed = Grow(2, &elsewhere, -1, &parts_of);
  REQUIRE(followed.status.ok());
  CHECK(followed.placed == full.placed);
  // A different decision made elsewhere is followed too: the root's left child a leaf.
  std::map<uint64_t, Placed> leaf{{1, all.at(1)}};
  leaf.at(1).split = false;
  const Run cut = Grow(2, &leaf, -1, &parts_of);
  REQUIRE(cut.status.ok());
  CHECK(cut.placed.size() < full.placed.size());
  for (const Placed& n : cut.placed) {
    uint64_t q = n.position;
    while (q > 1) q = (q - 1) / 2;
    CHECK((q != 1 || n.position == 1));  // nothing below the leaf
  }
}

TEST_CASE("frontier loop: a hook's error ends the loop with it", "[engine][unit]") {
  const Run run = Grow(1, nullptr, 2);
  CHECK(run.status.code() == core::ErrorCode::kInternal);
  CHECK(run.status.message() == "stop at level 1");
  CHECK(run.levels == 2);
  CHECK(run.placed.size() == 3);  // the root, then its two children
}
