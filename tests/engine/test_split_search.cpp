// Information gain and the binned split search against hand computation and brute force.
#include <catch2/catch.hpp>
#include <cmath>

#include "engine/split_search.h"
#include "runtime/core/rng.h"

using namespace poseforest;

TEST_CASE("entropy and information gain match hand-computed values", "[training][gain]") {
  const std::vector<uint64_t> uniform2{5, 5};
  CHECK(engine::Entropy(uniform2) == Approx(1.0));
  const std::vector<uint64_t> pure{7, 0, 0};
  CHECK(engine::Entropy(pure) == 0.0);
  // Q = {3 of A, 1 of B}: H = -(3/4 log2 3/4 + 1/4 log2 1/4) = 0.8112781245.
  // Q_l = {2 A}, Q_r = {1 A, 1 B}: G = 0.8112781245 - 2/4 * 0 - 2/4 * 1 = 0.3112781245.
  const std::vector<uint64_t> l{2, 0}, r{1, 1};
  CHECK(engine::InformationGain(l, r) == Approx(0.3112781245).epsilon(1e-9));
  // A perfect split of two equal classes gains one bit.
  const std::vector<uint64_t> l2{4, 0}, r2{0, 4};
  CHECK(engine::InformationGain(l2, r2) == Approx(1.0));
  // A split that keeps the proportions gains nothing.
  const std::vector<uint64_t> l3{2, 6}, r3{1, 3};
  CHECK(std::abs(engine::InformationGain(l3, r3)) < 1e-12);
}

namespace {

/// A node with random candidates, random (sometimes duplicated / missing) cuts and a random
/// histogram.
void RandomNode(uint64_t seed, int candidates, int thresholds, int slots, engine::NodePlan* plan,
                engine::NodeHistogram* hist, std::vector<uint64_t>* parts) {
  core::RngStream rng(core::CounterRng(seed, 0, 0, 99));
  std::vector<uint64_t> counts(core::kNumParts, 0);
  for (int s = 0; s < slots; ++s) counts[size_t(s * 2)] = 1;  // parts 0, 2, 4, ... present
  plan->SetParts(counts);
  REQUIRE(plan->num_slots == slots);
  plan->features.resize(size_t(candidates));
  plan->cut_stride = engine::CutStride(thresholds);
  plan->cuts.assign(size_t(candidates) * size_t(plan->cut_stride), engine::kNoCut);
  for (int k = 0; k < candidates; ++k) {
    const int real = k % 7 == 3 ? 0 : 1 + int(rng.UniformInt(uint32_t(thresholds)));
    int32_t c = rng.UniformIntIn(-500, 0);
    for (int j = 0; j < real; ++j) {
      plan->cuts[size_t(k) * size_t(plan->cut_stride) + size_t(j)] = c;
      c += 1 + int32_t(rng.UniformInt(40));
    }
  }
  hist->Reset(0, candidates, thresholds + 1, slots);
  // Every candidate sees the same samples: generate sample (bin, slot) per candidate from a
  // fixed multiset of labels, so totals per slot agree across candidates as in real data.
  std::vector<int> labels(200);
  for (auto& l : labels) l = int(rng.UniformInt(uint32_t(slots)));
  for (int k = 0; k < candidates; ++k) {
    const int32_t* cuts = &plan->cuts[size_t(k) * size_t(plan->cut_stride)];
    int real = 0;
    while (real < plan->cut_stride && cuts[real] != engine::kNoCut) ++real;
    for (int l : labels) {
      // Correlate the bin with the label for some candidates, so gains differ.
      const int bin =
          real == 0
              ? 0
              : int((rng.UniformInt(uint32_t(real + 1)) + uint32_t(k % 3 == 0 ? l : 0)) % uint32_t(real + 1));
      ++hist->counts[(size_t(k) * size_t(thresholds + 1) + size_t(bin)) * size_t(slots) + size_t(l)];
    }
  }
  parts->assign(core::kNumParts, 0);
  for (int l : labels) ++(*parts)[size_t(l * 2)];
}

}  // namespace

TEST_CASE("binned split search equals brute force over all thresholds", "[training][gain]") {
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    engine::NodePlan plan;
    engine::NodeHistogram hist;
    std::vector<uint64_t> parts;
    const int slots = 2 + int(seed % 5), thresholds = 3 + int(seed % 9);
    RandomNode(seed, 25, thresholds, slots, &plan, &hist, &parts);
    const engine::SplitChoice best = engine::FindBestSplit(hist, plan, parts);
    // The same counts as per-sample bins choose the same split.
    {
      engine::NodeHistogram per_sample;
      per_sample.Reset(0, hist.num_candidates, hist.num_bins, hist.num_slots, true);
      // Rebuild samples: candidate 0's (bin, slot) pairs fix each sample's slot; every other
      // candidate's counts are then dealt to the samples of each slot in order.
      const int nb = hist.num_bins, ns = hist.num_slots, nk = hist.num_candidates;
      std::vector<std::vector<int>> of_slot(static_cast<size_t>(ns));
      for (int b = 0; b < nb; ++b)
        for (int s = 0; s < ns; ++s)
          for (uint32_t c = 0; c < hist.counts[size_t(b * ns + s)]; ++c) {
            of_slot[size_t(s)].push_back(int(per_sample.sample_slot.size()));
            per_sample.sample_slot.push_back(uint8_t(s));
          }
      per_sample.sample_bin.assign(per_sample.sample_slot.size() * size_t(nk), 0);
      for (int k = 0; k < nk; ++k)
        for (int s = 0; s < ns; ++s) {
          size_t next = 0;
          for (int b = 0; b < nb; ++b)
            for (uint32_t c = 0;
                 c < hist.counts[(size_t(k) * size_t(nb) + size_t(b)) * size_t(ns) + size_t(s)]; ++c)
              per_sample.sample_bin[size_t(of_slot[size_t(s)][next++]) * size_t(nk) + size_t(k)] = uint8_t(b);
        }
      REQUIRE(per_sample.ToDense() == hist);
      const engine::SplitChoice again = engine::FindBestSplit(per_sample, plan, parts);
      CHECK(again.valid == best.valid);
      CHECK(again.candidate == best.candidate);
      CHECK(again.threshold == best.threshold);
      CHECK(again.gain == best.gain);
    }
    // Brute force: scan every (candidate, threshold), keep the first maximum.
    double bf_gain = -1;
    int bf_k = -1, bf_j = -1;
    for (int k = 0; k < hist.num_candidates; ++k) {
      const std::vector<double> gains = engine::BruteForceGains(hist, plan, k);
      for (size_t j = 0; j < gains.size(); ++j) {
        if (std::isnan(gains[j])) continue;
        if (gains[j] > bf_gain + 1e-12) {
          bf_gain = gains[j];
          bf_k = k;
          bf_j = int(j);
        }
      }
    }
    INFO("seed " << seed);
    REQUIRE(best.valid == (bf_k >= 0));
    if (!best.valid) continue;
    CHECK(best.gain == Approx(bf_gain).margin(1e-9));
    CHECK(best.candidate == bf_k);
    CHECK(best.threshold == bf_j);
    CHECK(best.cut == plan.cuts[size_t(bf_k) * size_t(plan.cut_stride) + size_t(bf_j)]);
    // Children part counts add up to the parent's.
    uint64_t nl = 0;
    for (size_t c = 0; c < parts.size(); ++c) {
      CHECK(best.left_parts[c] + best.right_parts[c] == parts[c]);
      nl += best.left_parts[c];
    }
    CHECK(nl == best.num_left);
  }
}

TEST_CASE("ties break by candidate index, then threshold index", "[training][gain]") {
  engine::NodePlan plan;
  std::vector<uint64_t> parts(core::kNumParts, 0);
  parts[0] = 2;
  parts[1] = 2;
  plan.SetParts(parts);
  plan.features.resize(3);
  plan.cut_stride = 2;
  plan.cuts = {0, 10, 0, 10, 0, 10};
  engine::NodeHistogram hist;
  hist.Reset(0, 3, 3, 2);
  // Candidate 0: useless (all in bin 1). Candidates 1 and 2: the same perfect split at
  // threshold 0 and again at threshold 1 (bin 1 empty): four equal best choices.
  auto at = [&](int k, int b, int s) -> uint32_t& { return hist.counts[size_t((k * 3 + b) * 2 + s)]; };
  at(0, 1, 0) = 2;
  at(0, 1, 1) = 2;
  for (int k = 1; k <= 2; ++k) {
    at(k, 0, 0) = 2;
    at(k, 2, 1) = 2;
  }
  const auto best = engine::FindBestSplit(hist, plan, parts);
  REQUIRE(best.valid);
  CHECK(best.candidate == 1);
  CHECK(best.threshold == 0);
  CHECK(best.gain == Approx(1.0));
}
