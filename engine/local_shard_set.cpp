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
    : threads_(threads) {
  shards_.reserve(shards.size());
  for (SampleSet& s : shards) shards_.emplace_back(s, params, builder);
}

Status LocalShardSet::CountParts(uint32_t node, std::vector<uint64_t>* parts) {
  parts->assign(size_t(core::kNumParts), 0);
  for (const Shard& s : shards_) {
    const std::vector<uint64_t> c = s.CountParts(node);
    for (size_t p = 0; p < c.size(); ++p) (*parts)[p] += c[p];
  }
  return Status::Ok();
}

Status LocalShardSet::Ranges(int tree, int /*level*/, Batch* batch, const HistogramSink& sink) {
  FirstPass pass;
  RunFirstPass(shards_, tree, batch->plans, &pass);
  range_seconds_ += pass.range_seconds;
  histogram_seconds_ += pass.fused_seconds;
  batch->ranges = std::move(pass.ranges);
  batch->fused = std::move(pass.fused);
  std::vector<size_t> which;
  std::vector<NodeHistogram> hists;
  for (size_t p = 0; p < batch->fused.size(); ++p) {
    if (!batch->fused[p]) continue;
    which.push_back(p);
    hists.push_back(std::move(pass.hists[p]));
  }
  Sink(which, hists, sink);
  return Status::Ok();
}

Status LocalShardSet::Histograms(int /*tree*/, int /*level*/, Batch* batch, std::span<const size_t> which,
                                 const HistogramSink& sink) {
  std::vector<NodePlan> plans;
  plans.reserve(which.size());
  for (size_t p : which) plans.push_back(std::move(batch->plans[p]));
  const double t_hist = Now();
  std::vector<NodeHistogram> hists;
  SumHistograms(shards_, plans, &hists);
  histogram_seconds_ += Now() - t_hist;
  for (size_t q = 0; q < which.size(); ++q) batch->plans[which[q]] = std::move(plans[q]);
  Sink(which, hists, sink);
  return Status::Ok();
}

Status LocalShardSet::ApplySplits(std::span<const SampleSet::Split> splits) {
  for (const Shard& s : shards_) s.ApplySplits(splits, threads_);
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
