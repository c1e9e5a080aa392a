#include "engine/split_search.h"

#include <cmath>
#include <limits>

namespace poseforest::engine {

namespace {

/// n * log2(n), with 0 log 0 = 0. A table for small n keeps the hot scoring loop cheap and
/// gives the same bits as the direct formula (it is filled with it).
class NLogN {
 public:
  static constexpr uint64_t kTable = 1 << 16;
  NLogN() {
    table_.resize(kTable);
    for (uint64_t n = 0; n < kTable; ++n) table_[n] = Direct(n);
  }
  double operator()(uint64_t n) const { return n < kTable ? table_[n] : Direct(n); }
  static double Direct(uint64_t n) { return n == 0 ? 0.0 : double(n) * std::log2(double(n)); }

 private:
  std::vector<double> table_;
};

const NLogN& Table() {
  static const NLogN table;
  return table;
}

}  // namespace

double Entropy(std::span<const uint64_t> counts) {
  uint64_t n = 0;
  double s = 0;
  for (uint64_t c : counts) {
    n += c;
    s += NLogN::Direct(c);
  }
  if (n == 0) return 0;
  return std::log2(double(n)) - s / double(n);
}

double InformationGain(std::span<const uint64_t> left, std::span<const uint64_t> right) {
  POSEFOREST_CHECK(left.size() == right.size());
  std::vector<uint64_t> all(left.size());
  uint64_t nl = 0, nr = 0;
  for (size_t c = 0; c < left.size(); ++c) {
    all[c] = left[c] + right[c];
    nl += left[c];
    nr += right[c];
  }
  const double n = double(nl + nr);
  if (n == 0) return 0;
  return Entropy(all) - double(nl) / n * Entropy(left) - double(nr) / n * Entropy(right);
}

SplitChoice FindBestSplit(const NodeHistogram& hist, const NodePlan& plan,
                          std::span<const uint64_t> parent_parts) {
  const NLogN& nlogn = Table();
  const int slots = hist.num_slots, bins = hist.num_bins, stride = plan.cut_stride;
  POSEFOREST_CHECK(slots == plan.num_slots && size_t(hist.num_candidates) == plan.features.size());
  // Parent totals per slot, from the histogram itself (candidate 0: every sample lands in
  // exactly one bin of every candidate).
  std::vector<uint64_t> total(static_cast<size_t>(slots), 0);
  std::vector<uint32_t> scratch(static_cast<size_t>(bins) * size_t(slots));
  uint64_t n = 0;
  if (hist.num_candidates > 0) {
    hist.CandidateCounts(0, scratch.data());
    for (int b = 0; b < bins; ++b)
      for (int s = 0; s < slots; ++s) total[size_t(s)] += scratch[size_t(b * slots + s)];
  }
  for (uint64_t t : total) n += t;
  SplitChoice best;
  if (n == 0) return best;
  double sum_total = 0;
  for (uint64_t t : total) sum_total += nlogn(t);
  // G * n = n log n - sum nlogn(c) - [L log L - sum nlogn(l_c)] - [R log R - sum nlogn(r_c)];
  // maximise score = sum nlogn(l_c) + sum nlogn(r_c) - nlogn(L) - nlogn(R).
  double best_score = -std::numeric_limits<double>::infinity();
  std::vector<uint64_t> left(static_cast<size_t>(slots));
  for (int k = 0; k < hist.num_candidates; ++k) {
    const int32_t* cuts = &plan.cuts[size_t(k) * size_t(stride)];
    hist.CandidateCounts(k, scratch.data());
    const uint32_t* h = scratch.data();
    std::fill(left.begin(), left.end(), 0);
    uint64_t nl = 0;
    for (int j = 0; j + 1 < bins && cuts[j] != kNoCut; ++j) {
      // Threshold j sends bins 0..j left.
      for (int s = 0; s < slots; ++s) {
        left[size_t(s)] += h[j * slots + s];
        nl += h[j * slots + s];
      }
      if (nl == 0) continue;
      if (nl == n) break;
      double score = -nlogn(nl) - nlogn(n - nl);
      for (int s = 0; s < slots; ++s)
        score += nlogn(left[size_t(s)]) + nlogn(total[size_t(s)] - left[size_t(s)]);
      if (score > best_score) {  // strict: ties keep the earlier (candidate, threshold)
        best_score = score;
        best.valid = true;
        best.candidate = k;
        best.threshold = j;
        best.cut = cuts[j];
        best.num_left = nl;
        best.num_right = n - nl;
      }
    }
  }
  if (!best.valid) return best;
  best.gain = (nlogn(n) - sum_total + best_score) / double(n);
  // Part counts of the children, mapped back from slots to parts.
  best.left_parts.assign(parent_parts.size(), 0);
  best.right_parts.assign(parent_parts.begin(), parent_parts.end());
  hist.CandidateCounts(best.candidate, scratch.data());
  const uint32_t* h = scratch.data();
  for (size_t c = 0; c < parent_parts.size(); ++c) {
    const uint8_t s = plan.part_slot[c];
    if (s == 0xFF) continue;
    uint64_t l = 0;
    for (int b = 0; b <= best.threshold; ++b) l += h[b * slots + s];
    best.left_parts[c] = l;
    best.right_parts[c] -= l;
  }
  return best;
}

std::vector<double> BruteForceGains(const NodeHistogram& hist, const NodePlan& plan, int k) {
  const int slots = hist.num_slots, bins = hist.num_bins;
  const int32_t* cuts = &plan.cuts[size_t(k) * size_t(plan.cut_stride)];
  std::vector<uint32_t> scratch(static_cast<size_t>(bins) * size_t(slots));
  hist.CandidateCounts(k, scratch.data());
  const uint32_t* h = scratch.data();
  std::vector<double> gains;
  for (int j = 0; j + 1 < bins; ++j) {
    if (cuts[j] == kNoCut) {
      gains.push_back(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    std::vector<uint64_t> left(static_cast<size_t>(slots), 0), right(size_t(slots), 0);
    uint64_t nl = 0, nr = 0;
    for (int b = 0; b < bins; ++b)
      for (int s = 0; s < slots; ++s) {
        // Samples of bin b have cuts[b-1] < f <= cuts[b]: left of threshold j iff b <= j.
        if (b <= j) {
          left[size_t(s)] += h[b * slots + s];
          nl += h[b * slots + s];
        } else {
          right[size_t(s)] += h[b * slots + s];
          nr += h[b * slots + s];
        }
      }
    gains.push_back(nl == 0 || nr == 0 ? std::numeric_limits<double>::quiet_NaN()
                                       : InformationGain(left, right));
  }
  return gains;
}

}  // namespace poseforest::engine
