#include "worker/task_frame_cache.h"

#include <unistd.h>

#include <algorithm>
#include <exception>
#include <string>

namespace poseforest::worker {

using core::ErrorCode;
using core::Status;

void TaskFrameCache::Clear(int new_tree) {
  tree = new_tree;
  frames_.clear();
  lru_.clear();
  bytes = 0;
}

const engine::ShardFrame* TaskFrameCache::Find(uint64_t i) {
  auto it = frames_.find(i);
  if (it == frames_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second.second);
  return &it->second.first;
}

void TaskFrameCache::Put(uint64_t i, engine::ShardFrame f) {
  if (Has(i)) return;
  const uint64_t b = f.Bytes();
  if (b > cap_bytes) {
    ++evictions;
    return;
  }
  while (bytes + b > cap_bytes && !lru_.empty()) {
    auto it = frames_.find(lru_.back());
    bytes -= it->second.first.Bytes();
    frames_.erase(it);
    lru_.pop_back();
    ++evictions;
  }
  lru_.push_front(i);
  frames_.emplace(i, std::make_pair(std::move(f), lru_.begin()));
  bytes += b;
  peak_bytes = std::max(peak_bytes, bytes);
}

uint64_t TaskCacheBytesFor(const engine::TrainParams& params, uint64_t physical_bytes) {
  const uint64_t frame = uint64_t(std::max(0, params.source.width)) *
                             uint64_t(std::max(0, params.source.height)) * sizeof(uint16_t) +
                         uint64_t(std::max(0, params.pixels_per_image)) * sizeof(engine::PixelSample);
  const uint64_t tree = frame * uint64_t(std::max(0, params.images_per_tree));
  const uint64_t floor = uint64_t(256) << 20;
  return std::max(floor, std::min(tree, physical_bytes / 8));
}

void TaskFrames::StartJob() {
  cache_.Clear(-1);
  cache_.cap_bytes = ctx_.opt.task_cache_bytes > 0
                         ? ctx_.opt.task_cache_bytes
                         : TaskCacheBytesFor(ctx_.params, uint64_t(::sysconf(_SC_PHYS_PAGES)) *
                                                              uint64_t(::sysconf(_SC_PAGE_SIZE)));
  ctx_.Log("task frame cache: " + std::to_string(cache_.cap_bytes >> 20) + " MiB" +
           (ctx_.opt.task_cache_bytes > 0 ? "" : " (auto: a tree's frames; --task-cache-mb to set)"));
  source_.reset();
}

Status TaskFrames::Render(int t, const std::vector<uint64_t>& missing, std::vector<engine::ShardFrame>* loaded) {
  const engine::TrainParams& params = ctx_.params;
  if (missing.size() >= 4 * size_t(params.threads) && params.threads > 1)
    return engine::LoadFrames(params, t, missing, params.threads, loaded, &ctx_.cpu.subtree_render);
  loaded->assign(missing.size(), engine::ShardFrame{});
  if (missing.empty()) return Status::Ok();
  if (!source_) {
    try {
      auto source = engine::MakeImageSource(params.source);
      if (!source.ok()) return source.status();
      source_ = std::move(*source);
    } catch (const std::exception& e) {
      return Status(ErrorCode::kInternal, std::string("rendering frames: ") + e.what());
    }
  }
  return engine::LoadFramesWith(*source_, params, t, missing, loaded);
}

Status TaskFrames::Get(int t, const std::vector<uint64_t>& wanted, const std::map<uint64_t, engine::ShardFrame>* own,
                       std::vector<uint64_t>* missing, std::vector<engine::ShardFrame>* loaded,
                       std::vector<const engine::ShardFrame*>* src) {
  if (cache_.tree != t) {
    if (cache_.tree >= 0 && (tree_rendered > 0 || tree_cached > 0))
      ctx_.Log("tree " + std::to_string(cache_.tree) + " subtree frames: " + std::to_string(tree_rendered) +
               " rendered again, " + std::to_string(tree_cached) + " from the shard or the task cache, " +
               std::to_string(cache_.evictions - evictions_at_tree_start_) + " evicted (cache " +
               std::to_string(cache_.cap_bytes >> 20) + " MiB)");
    cache_.Clear(t);
    ctx_.live.cache_bytes = 0;
    tree = uint32_t(t);
    tree_rendered = 0;
    tree_cached = 0;
    evictions_at_tree_start_ = cache_.evictions;
    tree_evictions = 0;
  }
  missing->clear();
  for (uint64_t i : wanted)
    if (!(own && own->count(i)) && !cache_.Has(i)) missing->push_back(i);
  WorkerCpu& cpu = ctx_.cpu;
  cpu.task_frames += missing->size();
  cpu.task_frames_cached += wanted.size() - missing->size();
  tree_rendered += missing->size();
  tree_cached += wanted.size() - missing->size();
  ctx_.live.task_hits += wanted.size() - missing->size();
  {
    CpuTimer timer(&cpu.subtree_render);
    const double t_render = proto::dds::NowSeconds();
    struct Mark {  // the wall time, however it ends
      double t0;
      double* sum;
      std::atomic<uint64_t>* micros;
      ~Mark() {
        const double s = proto::dds::NowSeconds() - t0;
        *sum += s;
        *micros += uint64_t(s * 1e6);
      }
    } mark{t_render, &render_unreported_s_, &ctx_.live.task_render_us};
    POSEFOREST_RETURN_IF_ERROR(Render(t, *missing, loaded));
    ctx_.frames_rendered += missing->size();
    ctx_.live.task_rendered += missing->size();
  }
  src->assign(wanted.size(), nullptr);
  for (size_t e = 0, next_loaded = 0; e < wanted.size(); ++e) {
    const uint64_t i = wanted[e];
    if (next_loaded < missing->size() && (*missing)[next_loaded] == i)
      (*src)[e] = &(*loaded)[next_loaded++];
    else
      (*src)[e] = own && own->count(i) ? &own->at(i) : cache_.Find(i);
  }
  return Status::Ok();
}

void TaskFrames::Keep(const std::vector<uint64_t>& missing, std::vector<engine::ShardFrame>& loaded) {
  for (size_t j = 0; j < missing.size(); ++j) cache_.Put(missing[j], std::move(loaded[j]));
  WorkerCpu& cpu = ctx_.cpu;
  cpu.task_cache_peak_bytes = std::max(cpu.task_cache_peak_bytes, cache_.peak_bytes);
  cpu.task_cache_evictions = cache_.evictions;
  tree_evictions = cache_.evictions - evictions_at_tree_start_;
  ctx_.live.cache_evictions += cache_.evictions - evictions_counted_;
  evictions_counted_ = cache_.evictions;
  ctx_.live.cache_bytes = cache_.bytes;
}

}  // namespace poseforest::worker
