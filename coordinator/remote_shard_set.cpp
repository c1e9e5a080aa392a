#include "coordinator/remote_shard_set.h"

#include <exception>
#include <string>

#include "engine/candidates.h"
#include "engine/wire_codec.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Status;
using proto::dds::Topic;

namespace {
constexpr int kParts = core::kNumParts;
}  // namespace

RemoteShardSet::RemoteShardSet(Session& session, WorkerRegistry& registry, Rounds& rounds, LevelRecords& records,
                               int merge_threads)
    : s_(session), registry_(registry), rounds_(rounds), records_(records), merge_threads_(merge_threads) {}

Status RemoteShardSet::CountParts(uint32_t node, std::vector<uint64_t>* parts) {
  if (node != 0) return Status(ErrorCode::kInternal, "remote census of a node other than the root");
  auto replies = rounds_.Round(v1::PHASE_COUNTS, {0}, {v1::NodeSpec{}}, 0);
  if (!replies.ok()) return replies.status();
  parts->assign(size_t(kParts), 0);
  for (const Reply& r : *replies)
    for (int p = 0; p < kParts; ++p) (*parts)[size_t(p)] += r.body.ranges(0).part_counts(p);
  return Status::Ok();
}

/// Ranges merged by min/max. A worker that holds every sample of a node whose reference
/// subsample is the whole node builds it in one fused pass and returns its histogram and
/// cuts right away.
Status RemoteShardSet::Ranges(int /*tree*/, int level, engine::Batch* batch, const engine::HistogramSink& sink) {
  const engine::TrainParams& params = s_.params;
  std::vector<engine::NodePlan>& plans = batch->plans;
  const int k = params.candidate_features;
  const int t_count = params.thresholds_per_feature;
  const int cut_stride = engine::CutStride(t_count);
  const proto::dds::HistogramDims dims{uint32_t(k), uint32_t(t_count + 1), uint32_t(kParts)};
  batch->ranges.assign(plans.size(), {});
  batch->fused.assign(plans.size(), 0);
  std::vector<uint32_t> ids;
  std::vector<v1::NodeSpec> specs(plans.size());
  for (size_t p = 0; p < plans.size(); ++p) {
    ids.push_back(plans[p].node);
    specs[p].set_num_samples(plans[p].num_samples);
    specs[p].set_position(plans[p].position);
  }
  const double t_ranges = proto::dds::NowSeconds();
  auto r1 = rounds_.Round(v1::PHASE_RANGES, ids, specs, level);
  if (!r1.ok()) return r1.status();
  hist_s_ += proto::dds::NowSeconds() - t_ranges;
  std::vector<int> fused_by(plans.size(), -1);
  for (size_t p = 0; p < plans.size(); ++p) {
    for (size_t r = 0; r < r1->size(); ++r)
      if ((*r1)[r].body.ranges(int(p)).fused()) {
        if (fused_by[p] >= 0)
          return Status(ErrorCode::kDataLoss, "node " + std::to_string(plans[p].node) +
                                                  ": two workers claim all of its samples");
        fused_by[p] = int(r);
      }
    if (fused_by[p] >= 0) continue;
    std::vector<engine::ResponseRange>& merged = batch->ranges[p];
    merged.resize(size_t(k));
    for (const Reply& r : *r1)
      for (int c = 0; c < k; ++c)
        merged[size_t(c)].Merge({r.body.ranges(int(p)).lo(c), r.body.ranges(int(p)).hi(c)});
  }
  // Fused nodes: cuts and histogram from their one worker.
  const double t_merge = proto::dds::NowSeconds();
  for (size_t p = 0; p < plans.size(); ++p) {
    if (fused_by[p] < 0) continue;
    batch->fused[p] = 1;
    const Reply& r = (*r1)[size_t(fused_by[p])];
    const v1::NodeRanges& nr = r.body.ranges(int(p));
    bool ok = r.body.nodes(int(p)).samples() == plans[p].num_samples &&
              engine::DecodeCuts(nr, k, cut_stride, &plans[p].cuts);
    engine::NodeHistogram hist;
    hist.Reset(plans[p].node, k, t_count + 1, plans[p].num_slots, false);
    if (ok) ok = engine::AddWireRuns(r.body.nodes(int(p)).runs(), dims, plans[p], &hist);
    if (!ok)
      return Status(ErrorCode::kDataLoss, "fused node " + std::to_string(plans[p].node) + " from " +
                                              r.sender + " is inconsistent");
    sink(p, hist);
  }
  merge_s_ += proto::dds::NowSeconds() - t_merge;
  return Status::Ok();
}

/// Histograms summed, per node in parallel (independent, deterministic per node). A reply
/// that counts a part absent from a node comes from a worker that disagrees with the
/// coordinator: it is evicted and the round asked again without it.
Status RemoteShardSet::Histograms(int /*tree*/, int level, engine::Batch* batch, std::span<const size_t> which,
                                  const engine::HistogramSink& sink) {
  const engine::TrainParams& params = s_.params;
  const std::vector<engine::NodePlan>& plans = batch->plans;
  const int k = params.candidate_features;
  const int t_count = params.thresholds_per_feature;
  const proto::dds::HistogramDims dims{uint32_t(k), uint32_t(t_count + 1), uint32_t(kParts)};
  std::vector<uint32_t> ids2;
  std::vector<v1::NodeSpec> specs2(which.size());
  for (size_t q = 0; q < which.size(); ++q) {
    const size_t p = which[q];
    ids2.push_back(plans[p].node);
    specs2[q].set_num_samples(plans[p].num_samples);
    specs2[q].set_position(plans[p].position);
    for (uint64_t c : batch->parts[p]) specs2[q].add_part_counts(c);
    for (const auto& m : batch->ranges[p]) {
      specs2[q].add_range_lo(m.lo);
      specs2[q].add_range_hi(m.hi);
    }
  }
  for (int attempt = 0;; ++attempt) {
    const double t_hist = proto::dds::NowSeconds();
    auto r2 = rounds_.Round(v1::PHASE_HISTOGRAMS, ids2, specs2, level);
    if (!r2.ok()) return r2.status();
    hist_s_ += proto::dds::NowSeconds() - t_hist;
    const double t_merge = proto::dds::NowSeconds();
    const auto nq = int64_t(which.size());
    std::vector<std::string> bad(which.size());
    std::vector<uint64_t> got(which.size(), 0);
    std::exception_ptr merge_error;
#pragma omp parallel for num_threads(merge_threads_) schedule(dynamic, 1)
    for (int64_t qi = 0; qi < nq; ++qi) {
      try {  // no exception may leave the OpenMP region: stored, rethrown after it
        const auto q = size_t(qi);
        const size_t p = which[q];
        engine::NodeHistogram hist;
        hist.Reset(plans[p].node, k, t_count + 1, plans[p].num_slots, false);
        for (const Reply& r : *r2) {
          const auto& nh = r.body.nodes(int(q));
          if (!engine::AddWireRuns(nh.runs(), dims, plans[p], &hist)) {
            bad[q] = r.sender;
            break;
          }
          got[q] += nh.samples();
        }
        if (!bad[q].empty() || got[q] != plans[p].num_samples) continue;
        sink(p, hist);
      } catch (...) {
#pragma omp critical(poseforest_dist_merge_error)
        if (!merge_error) merge_error = std::current_exception();
      }
    }
    if (merge_error) std::rethrow_exception(merge_error);
    merge_s_ += proto::dds::NowSeconds() - t_merge;
    std::string culprit;
    for (const std::string& b : bad)
      if (!b.empty()) culprit = b;
    if (!culprit.empty() && attempt < 3) {
      s_.Log("histogram from " + culprit + " counts parts absent from a node");
      registry_.MarkLost(culprit, "evicted");
      continue;
    }
    for (size_t q = 0; q < which.size(); ++q)
      if (!bad[q].empty() || got[q] != plans[which[q]].num_samples)
        return Status(ErrorCode::kDataLoss, "node " + std::to_string(plans[which[q]].node) +
                                                ": the workers' histograms hold " +
                                                std::to_string(got[q]) + " samples, expected " +
                                                std::to_string(plans[which[q]].num_samples));
    return Status::Ok();
  }
}

/// The level's decisions (leaves, splits, delegated nodes) to every worker: each routes its
/// own samples.
Status RemoteShardSet::ApplySplits(std::span<const engine::SampleSet::Split> /*splits*/) {
  if (!decisions) return Status(ErrorCode::kInternal, "no decisions to send");
  v1::SplitDecisions* dec = decisions->mutable_decisions();
  dec->set_epoch(++s_.epoch);
  records_.AddSent(*dec);
  return s_.Send(Topic::kControl, *decisions);
}

}  // namespace poseforest::coordinator
