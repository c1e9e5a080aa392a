#include "engine/shard.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <string>
#include <thread>

#include "engine/candidates.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/rng.h"

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double ThreadCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

}  // namespace

Result<ShardFrame> LoadFrame(ImageSource& source, const TrainParams& params, int tree, uint64_t frame) {
  const uint64_t index = uint64_t(tree) * uint64_t(params.images_per_tree) + frame;
  auto labelled = source.Frame(index);
  if (!labelled.ok()) return labelled.status();
  ShardFrame out;
  out.picked = SamplePixels(*labelled, params.pixels_per_image, params.part_balance,
                            core::CounterRng(params.seed, uint64_t(tree), index, kSamplingStream));
  // Compacted (and its labels dropped) as soon as its pixels are sampled, so whole frames never
  // pile up.
  out.frame = CompactFrame::Of(labelled->depth, params.constants.background_mm);
  return out;
}

Status LoadFrames(const TrainParams& params, int tree, std::span<const uint64_t> frames, int threads,
                  std::vector<ShardFrame>* out, double* cpu_seconds) {
  out->assign(frames.size(), ShardFrame{});
  if (frames.empty()) return Status::Ok();
  const int n = std::max(1, std::min<int>(threads, int(frames.size())));
  std::vector<Status> errors(static_cast<size_t>(n));
  std::vector<double> thread_cpu(static_cast<size_t>(n), 0.0);
  std::vector<std::thread> pool;
  for (int tid = 0; tid < n; ++tid) {
    pool.emplace_back([&, tid] {
      const double cpu0 = ThreadCpu();
      try {
        auto source = MakeImageSource(params.source);
        if (!source.ok()) {
          errors[size_t(tid)] = source.status();
        } else {
          for (size_t j = size_t(tid); j < frames.size(); j += size_t(n)) {
            auto frame = LoadFrame(**source, params, tree, frames[j]);
            if (!frame.ok()) {
              errors[size_t(tid)] = frame.status();
              break;
            }
            (*out)[j] = std::move(*frame);
          }
        }
      } catch (const std::exception& e) {
        errors[size_t(tid)] = Status(ErrorCode::kInternal, std::string("loading frames: ") + e.what());
      }
      thread_cpu[size_t(tid)] = ThreadCpu() - cpu0;
    });
  }
  for (auto& t : pool) t.join();
  if (cpu_seconds)
    for (double c : thread_cpu) *cpu_seconds += c;
  for (const Status& e : errors)
    if (!e.ok()) return e;
  return Status::Ok();
}

Status LoadFramesWith(ImageSource& source, const TrainParams& params, int tree, std::span<const uint64_t> frames,
                      std::vector<ShardFrame>* out) {
  out->assign(frames.size(), ShardFrame{});
  try {
    for (size_t j = 0; j < frames.size(); ++j) {
      auto frame = LoadFrame(source, params, tree, frames[j]);
      if (!frame.ok()) return frame.status();
      (*out)[j] = std::move(*frame);
    }
  } catch (const std::exception& e) {
    return Status(ErrorCode::kInternal, std::string("rendering frames: ") + e.what());
  }
  return Status::Ok();
}

std::vector<uint64_t> Shard::CountParts(uint32_t node) const {
  std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
  const NodeRange range = samples_->RangeOf(node);
  if (range.end > range.begin) samples_->CountParts(range, core::kNumParts, parts.data());
  return parts;
}

bool Shard::CanFuse(const NodePlan& plan) const { return HistogramBuilder::CanFuse(*samples_, *params_, plan); }

void Shard::Ranges(int tree, std::span<const NodePlan> plans, std::vector<std::vector<ResponseRange>>* out) const {
  builder_->ComputeRanges(*samples_, *params_, tree, plans, out);
}

void Shard::BuildFused(int tree, std::span<NodePlan> plans, std::vector<NodeHistogram>* out) const {
  builder_->BuildFused(*samples_, *params_, tree, plans, out);
}

void Shard::Histograms(std::span<const NodePlan> plans, std::vector<NodeHistogram>* out) const {
  builder_->Build(*samples_, plans, params_->thresholds_per_feature, out);
}

void Shard::ApplySplits(std::span<const SampleSet::Split> splits, int threads) const {
  samples_->ApplySplits(splits, params_->constants, threads);
}

void RunFirstPass(std::span<const Shard> shards, int tree, std::span<NodePlan> plans, FirstPass* out) {
  const size_t n = plans.size();
  out->fused.assign(n, 0);
  out->ranges.assign(n, {});
  out->hists.assign(n, {});
  // Which plans one shard builds alone (fused), which go through both passes over all shards.
  std::vector<size_t> normal_at;
  std::vector<NodePlan> normal;
  std::vector<std::vector<size_t>> fused_at(shards.size());
  std::vector<std::vector<NodePlan>> fused(shards.size());
  for (size_t p = 0; p < n; ++p) {
    size_t s = 0;
    while (s < shards.size() && !shards[s].CanFuse(plans[p])) ++s;
    if (s == shards.size()) {
      normal_at.push_back(p);
      normal.push_back(std::move(plans[p]));
    } else {
      out->fused[p] = 1;
      fused_at[s].push_back(p);
      fused[s].push_back(std::move(plans[p]));
    }
  }
  const double t_range = Now();
  if (!normal.empty()) {
    std::vector<std::vector<ResponseRange>> merged, part;
    for (size_t s = 0; s < shards.size(); ++s) {
      shards[s].Ranges(tree, normal, s == 0 ? &merged : &part);
      if (s == 0) continue;
      for (size_t q = 0; q < normal.size(); ++q)
        for (size_t k = 0; k < merged[q].size(); ++k) merged[q][k].Merge(part[q][k]);
    }
    for (size_t q = 0; q < normal.size(); ++q) {
      out->ranges[normal_at[q]] = std::move(merged[q]);
      plans[normal_at[q]] = std::move(normal[q]);
    }
  }
  out->range_seconds += Now() - t_range;
  for (size_t s = 0; s < shards.size(); ++s) {
    if (fused[s].empty()) continue;
    const double t_hist = Now();
    std::vector<NodeHistogram> hists;
    shards[s].BuildFused(tree, fused[s], &hists);
    out->fused_seconds += Now() - t_hist;
    for (size_t q = 0; q < fused[s].size(); ++q) {
      plans[fused_at[s][q]] = std::move(fused[s][q]);
      out->hists[fused_at[s][q]] = std::move(hists[q]);
    }
  }
}

void SumHistograms(std::span<const Shard> shards, std::span<const NodePlan> plans,
                   std::vector<NodeHistogram>* out) {
  std::vector<NodeHistogram> shard_hists;
  for (size_t s = 0; s < shards.size(); ++s) {
    shards[s].Histograms(plans, s == 0 ? out : &shard_hists);
    if (s == 0) continue;
    for (size_t q = 0; q < plans.size(); ++q) (*out)[q].Add(shard_hists[q]);
  }
}

}  // namespace poseforest::engine
