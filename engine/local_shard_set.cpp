#include "engine/local_shard_set.h"

#include <chrono>
#include <exception>

#include "runtime/core/body_parts.h"

namespace poseforest::engine {

using core::Status;

namespace {
double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

LocalShardSet::LocalShardSet(std::span<SampleSet> shards, const TrainParams& params,
                             HistogramBuilder& builder, int threads)
    : shards_(shards), params_(params), builder_(builder), threads_(threads) {}

Status LocalShardSet::CountParts(uint32_t node, std::vector<uint64_t>* parts) {
  parts->assign(size_t(core::kNumParts), 0);
  std::vector<uint64_t> c(size_t(core::kNumParts));
  for (const SampleSet& s : shards_) {
    const NodeRange range = s.RangeOf(node);
    if (range.end <= range.begin) continue;
    std::fill(c.begin(), c.end(), 0);
    s.CountParts(range, core::kNumParts, c.data());
    for (size_t p = 0; p < c.size(); ++p) (*parts)[p] += c[p];
  }
  return Status::Ok();
}

Status LocalShardSet::Ranges(int tree, int /*level*/, Batch* batch, const HistogramSink& sink) {
  const size_t n = batch->plans.size();
  batch->ranges.assign(n, {});
  batch->fused.assign(n, 0);
  // Which plans one shard builds alone (fused), which go through both passes over all shards.
  std::vector<size_t> normal_at;
  std::vector<NodePlan> normal;
  std::vector<std::vector<size_t>> fused_at(shards_.size());
  std::vector<std::vector<NodePlan>> fused(shards_.size());
  for (size_t p = 0; p < n; ++p) {
    size_t s = 0;
    while (s < shards_.size() && !HistogramBuilder::CanFuse(shards_[s], params_, batch->plans[p])) ++s;
    if (s == shards_.size()) {
      normal_at.push_back(p);
      normal.push_back(std::move(batch->plans[p]));
    } else {
      batch->fused[p] = 1;
      fused_at[s].push_back(p);
      fused[s].push_back(std::move(batch->plans[p]));
    }
  }
  const double t_range = Now();
  if (!normal.empty()) {
    std::vector<std::vector<ResponseRange>> merged, part;
    for (size_t s = 0; s < shards_.size(); ++s) {
      builder_.ComputeRanges(shards_[s], params_, tree, normal, s == 0 ? &merged : &part);
      if (s == 0) continue;
      for (size_t q = 0; q < normal.size(); ++q)
        for (size_t k = 0; k < merged[q].size(); ++k) merged[q][k].Merge(part[q][k]);
    }
    for (size_t q = 0; q < normal.size(); ++q) {
      batch->ranges[normal_at[q]] = std::move(merged[q]);
      batch->plans[normal_at[q]] = std::move(normal[q]);
    }
  }
  range_seconds_ += Now() - t_range;
  for (size_t s = 0; s < shards_.size(); ++s) {
    if (fused[s].empty()) continue;
    const double t_hist = Now();
    std::vector<NodeHistogram> hists;
    builder_.BuildFused(shards_[s], params_, tree, fused[s], &hists);
    histogram_seconds_ += Now() - t_hist;
    for (size_t q = 0; q < fused[s].size(); ++q) batch->plans[fused_at[s][q]] = std::move(fused[s][q]);
    Sink(fused_at[s], hists, sink);
  }
  return Status::Ok();
}

Status LocalShardSet::Histograms(int /*tree*/, int /*level*/, Batch* batch, std::span<const size_t> which,
                                 const HistogramSink& sink) {
  std::vector<NodePlan> plans;
  plans.reserve(which.size());
  for (size_t p : which) plans.push_back(std::move(batch->plans[p]));
  const double t_hist = Now();
  std::vector<NodeHistogram> hists, shard_hists;
  for (size_t s = 0; s < shards_.size(); ++s) {
    builder_.Build(shards_[s], plans, params_.thresholds_per_feature, s == 0 ? &hists : &shard_hists);
    if (s == 0) continue;
    for (size_t q = 0; q < plans.size(); ++q) hists[q].Add(shard_hists[q]);
  }
  histogram_seconds_ += Now() - t_hist;
  for (size_t q = 0; q < which.size(); ++q) batch->plans[which[q]] = std::move(plans[q]);
  Sink(which, hists, sink);
  return Status::Ok();
}

Status LocalShardSet::ApplySplits(std::span<const SampleSet::Split> splits) {
  for (SampleSet& s : shards_) s.ApplySplits(splits, params_.constants, threads_);
  return Status::Ok();
}

void LocalShardSet::Sink(std::span<const size_t> which, std::span<const NodeHistogram> hists,
                         const HistogramSink& sink) const {
  const auto n = int64_t(which.size());
  std::exception_ptr error;  // no exception may leave the OpenMP region: stored, rethrown after it
#pragma omp parallel for num_threads(threads_) schedule(dynamic, 1)
  for (int64_t j = 0; j < n; ++j) {
    try {
      sink(which[size_t(j)], hists[size_t(j)]);
    } catch (...) {
#pragma omp critical(poseforest_local_shard_set_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace poseforest::engine
