#include "worker/subtree_runner.h"

#include <algorithm>
#include <optional>
#include <span>

#include "engine/candidates.h"
#include "engine/wire_codec.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/crc32.h"

namespace poseforest::worker {

using core::ErrorCode;
using core::Status;

Status SelectListedSamples(std::span<const engine::PixelSample> picked, int width, uint64_t frame,
                           std::span<const uint32_t> deltas, std::vector<engine::PixelSample>* out) {
  out->clear();
  uint64_t pixel = 0;
  size_t k = 0;
  auto index = [&](size_t j) { return uint64_t(picked[j].y) * uint64_t(width) + uint64_t(picked[j].x); };
  for (size_t c = 0; c < deltas.size(); ++c) {
    if (c > 0 && deltas[c] == 0)
      return Status(ErrorCode::kInvalidArgument,
                    "frame " + std::to_string(frame) + ": pixel " + std::to_string(pixel) + " listed twice");
    pixel += deltas[c];
    while (k < picked.size() && index(k) < pixel) ++k;
    if (k == picked.size() || index(k) != pixel)
      return Status(ErrorCode::kInvalidArgument, "frame " + std::to_string(frame) + ": pixel " +
                                                     std::to_string(pixel) +
                                                     " is not one of its sampled pixels");
    out->push_back(picked[k]);
  }
  return Status::Ok();
}

void SubtreeRunner::StartJob() {
  builder_ = std::make_unique<engine::HistogramBuilder>(ctx_.params.constants, ctx_.params.threads);
  task_set_ = engine::SampleSet{};
  task_set_tree_ = -1;
  task_set_frames_.clear();
  corrupt_left_ = ctx_.opt.corrupt_subtree_results;
}

void SubtreeRunner::Drop(const v1::SubtreeTask& task, const std::string& sender, const Status& st) const {
  ctx_.Log("dropped SubtreeTask (position " + std::to_string(task.position()) + ") from " + sender + ": " +
           st.ToString());
}

Status SubtreeRunner::Check(const v1::SubtreeTask& task, std::vector<uint64_t>* wanted_out) const {
  const engine::TrainParams& params = ctx_.params;
  const uint64_t ipt = uint64_t(params.images_per_tree);
  const int t = int(task.tree());
  std::vector<uint64_t>& wanted = *wanted_out;
  wanted.clear();
  if (task.tree() >= uint32_t(params.num_trees)) return Status(ErrorCode::kInvalidArgument, "tree out of range");
  if (task.part_counts_size() != core::kNumParts)
    return Status(ErrorCode::kInvalidArgument, "part counts of the wrong length");
  if (task.position() >= (uint64_t(1) << 31) || engine::PositionDepth(task.position()) != int(task.depth()) ||
      int(task.depth()) > params.max_depth)
    return Status(ErrorCode::kInvalidArgument, "position " + std::to_string(task.position()) +
                                                   " is not at depth " + std::to_string(task.depth()));
  for (const auto& r : task.ranges()) {
    if (r.seed() != params.source.seed) return Status(ErrorCode::kInvalidArgument, "image range of another seed");
    for (uint64_t g = r.first_index(); g < r.first_index() + r.count(); ++g) {
      if (g < uint64_t(t) * ipt || g >= uint64_t(t + 1) * ipt)
        return Status(ErrorCode::kInvalidArgument,
                      "frame " + std::to_string(g) + " is not one of tree " + std::to_string(t) + "'s");
      wanted.push_back(g - uint64_t(t) * ipt);
    }
  }
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  // The node's samples listed by the coordinator (then no routing): their frames replace
  // `wanted`, checked here; each pixel is checked against the frame's sampled pixels below.
  if (!Listed(task)) return Status::Ok();
  if (task.sample_counts_size() != task.sample_frames_size())
    return Status(ErrorCode::kInvalidArgument, "sample_counts and sample_frames differ in length");
  uint64_t total = 0;
  for (uint32_t c : task.sample_counts()) total += c;
  if (total != uint64_t(task.sample_pixel_deltas_size()) || total != task.expected_samples())
    return Status(ErrorCode::kInvalidArgument, "the task lists " + std::to_string(task.sample_pixel_deltas_size()) +
                                                   " sample pixels, " + std::to_string(total) + " by its counts, expects " +
                                                   std::to_string(task.expected_samples()));
  wanted.clear();
  for (int e = 0; e < task.sample_frames_size(); ++e) {
    const uint32_t f = task.sample_frames(e);
    if (f >= ipt || (e > 0 && f <= task.sample_frames(e - 1)))
      return Status(ErrorCode::kInvalidArgument, "sample frame " + std::to_string(f) + " out of range or out of order");
    wanted.push_back(f);
  }
  return Status::Ok();
}

Status SubtreeRunner::TaskSamples(const v1::SubtreeTask& task, const std::vector<uint64_t>& wanted,
                                  const std::vector<const engine::ShardFrame*>& src,
                                  engine::SampleSet* set) const {
  const engine::TrainParams& params = ctx_.params;
  const bool listed = Listed(task);
  size_t pixels = 0, picked = 0;
  for (const engine::ShardFrame* f : src) pixels += f->frame.pixels.size(), picked += f->picked.size();
  set->Reserve(wanted.size(), pixels, listed ? size_t(task.expected_samples()) : picked,
               wanted.size() * size_t(std::max(0, params.source.height)));
  size_t delta_at = 0;
  std::vector<engine::PixelSample> chosen;
  for (size_t e = 0; e < wanted.size(); ++e) {
    const uint64_t i = wanted[e];
    const engine::ShardFrame* f = src[e];
    if (!listed) {
      if (!f->picked.empty()) set->AddFrame(i, f->frame, f->picked, params.constants);
      continue;
    }
    const uint32_t count = task.sample_counts(int(e));
    POSEFOREST_RETURN_IF_ERROR(SelectListedSamples(
        f->picked, f->frame.width, i, std::span<const uint32_t>(task.sample_pixel_deltas().data() + delta_at, count),
        &chosen));
    delta_at += count;
    if (!chosen.empty()) set->AddFrame(i, f->frame, chosen, params.constants);
  }
  return Status::Ok();
}

Status SubtreeRunner::Run(const v1::SubtreeTask& task) {
  const engine::TrainParams& params = ctx_.params;
  const int t = int(task.tree());
  std::vector<uint64_t> wanted;
  POSEFOREST_RETURN_IF_ERROR(Check(task, &wanted));
  const bool listed = Listed(task);
  const double t0 = proto::dds::NowSeconds();
  const Context::BusyScope busy_scope(ctx_.busy);
  ++ctx_.cpu.subtree_tasks;
  std::vector<uint64_t> missing;
  std::vector<engine::ShardFrame> loaded;
  std::vector<const engine::ShardFrame*> src;
  POSEFOREST_RETURN_IF_ERROR(frames_.Get(t, wanted, shard_.FramesOf(t), &missing, &loaded, &src));
  std::optional<CpuTimer> route_timer(&ctx_.cpu.subtree_route);
  engine::SampleSet set;
  POSEFOREST_RETURN_IF_ERROR(TaskSamples(task, wanted, src, &set));
  src.clear();
  frames_.Keep(missing, loaded);
  set.StartTree(0);
  // Without a sample list: route along the ancestors' splits; the side not taken is dropped
  // at every step.
  uint32_t at = 0;
  if (!listed)
    for (const auto& step : task.path()) {
      engine::SampleSet::Split sp;
      sp.node = at;
      POSEFOREST_RETURN_IF_ERROR(engine::GetFeatureSplit(step.split(), &sp.offsets, &sp.cut));
      sp.left_child = at + 1;
      set.ApplySplits(std::span<const engine::SampleSet::Split>(&sp, 1), params.constants, params.threads);
      at = step.went_right() ? at + 2 : at + 1;
    }
  std::vector<uint64_t> parts(task.part_counts().begin(), task.part_counts().end());
  const engine::NodeRange routed = set.RangeOf(at);
  route_timer.reset();
  std::optional<CpuTimer> train_timer(&ctx_.cpu.subtree_train);
  served_in_batch_s_ = 0;
  auto out = engine::TrainSubtree(set, at, params, t, task.position(), parts, *builder_, pause_);
  train_timer.reset();
  ctx_.busy = false;
  if (!out.ok()) return out.status();
  return SendResult(task, *out, t0, routed.end - routed.begin, wanted.size(), missing.size());
}

v1::Envelope SubtreeRunner::ResultOf(const v1::SubtreeTask& task, const engine::SubtreeOutput& out) {
  v1::Envelope env;
  v1::SubtreeResult* res = env.mutable_subtree_result();
  res->set_tree(task.tree());
  res->set_node_id(task.node_id());
  res->set_epoch(task.epoch());
  res->set_nodes(
      std::string(reinterpret_cast<const char*>(out.tree.nodes.data()), out.tree.nodes.size() * sizeof(core::Node)));
  res->set_leaves(std::string(reinterpret_cast<const char*>(out.tree.leaves.data()), out.tree.leaves.size()));
  res->set_num_nodes(uint32_t(out.tree.nodes.size()));
  res->set_num_leaves(out.tree.num_leaves);
  res->set_num_parts(uint32_t(core::kNumParts));
  res->set_position(task.position());
  res->set_evaluations(out.evaluations);
  for (const engine::SubtreeNode& n : out.nodes) {
    v1::SubtreeNode* sn = res->add_subtree_nodes();
    sn->set_position(n.position);
    sn->set_split(n.split);
    if (n.split) {
      sn->set_ux(n.offsets.ux), sn->set_uy(n.offsets.uy), sn->set_vx(n.offsets.vx), sn->set_vy(n.offsets.vy);
      sn->set_cut(n.cut);
      sn->set_gain(n.gain);
    }
    for (uint64_t c : n.parts) sn->add_part_counts(c);
  }
  if (corrupt_left_ > 0) {  // tests: a hostile worker
    if (corrupt_left_-- % 2 == 1)
      res->set_position(res->position() + 1), res->mutable_subtree_nodes(0)->set_position(res->position());
    else
      res->mutable_subtree_nodes(0)->set_part_counts(0, res->subtree_nodes(0).part_counts(0) + 1);
  }
  uint32_t crc = core::Crc32(res->nodes().data(), res->nodes().size());
  res->set_crc32(core::Crc32(res->leaves().data(), res->leaves().size(), crc));
  return env;
}

Status SubtreeRunner::SendResult(const v1::SubtreeTask& task, const engine::SubtreeOutput& out, double t0,
                                 uint64_t num_samples, size_t num_frames, size_t rendered) {
  const int t = int(task.tree());
  std::optional<CpuTimer> encode_timer(&ctx_.cpu.subtree_encode);
  v1::Envelope env = ResultOf(task, out);
  v1::SubtreeResult* res = env.mutable_subtree_result();
  ctx_.evaluations += out.evaluations;
  ctx_.live.evaluations += out.evaluations;
  // One line for a tree's first subtree task, then a running total every 100 tasks (a depth-20
  // job hands off hundreds per tree).
  if (t != log_tree_) log_tree_ = t, done_ = 0, nodes_done_ = 0, busy_s_ = 0;
  ++done_;
  nodes_done_ += out.nodes.size();
  // Wall seconds of subtree work: the tasks of a batch share one stretch of time, so each
  // adds only the time since the previous result (or its start), never the batch's whole.
  const double now = proto::dds::NowSeconds();
  // Rounds answered in the middle of the batch (ServeRounds) are not subtree work.
  const double busy_s = std::max(0.0, now - std::max(t0, mark_) - served_in_batch_s_);
  served_in_batch_s_ = 0;
  busy_s_ += busy_s;
  mark_ = now;
  res->set_busy_micros(uint64_t(busy_s * 1e6));
  res->set_render_micros(uint64_t(frames_.TakeRenderSeconds() * 1e6));
  const TaskFrameCache& cache = frames_.cache();
  if (done_ == 1)
    ctx_.Log("tree " + std::to_string(t) + ": subtree at position " + std::to_string(task.position()) + " (" +
             std::to_string(num_samples) + " samples from " + std::to_string(num_frames) + " frames, " +
             std::to_string(rendered) + " rendered) -> " + std::to_string(out.nodes.size()) + " nodes in " +
             std::to_string(proto::dds::NowSeconds() - t0) + " s");
  else if (done_ % 100 == 0)
    ctx_.Log("tree " + std::to_string(t) + ": " + std::to_string(done_) + " subtrees trained so far (" +
             std::to_string(nodes_done_) + " nodes, " + std::to_string(busy_s_) + " s; task frame cache " +
             std::to_string(cache.bytes >> 20) + " of " + std::to_string(cache.cap_bytes >> 20) + " MiB, " +
             std::to_string(cache.evictions) + " evicted; queued rounds answered " +
             std::to_string(ctx_.cpu.rounds_in_batches) + " times in between)");
  encode_timer.reset();
  Status sent = ctx_.Reply(env);
  if (sent.ok()) {
    ++ctx_.live.subtrees;
    ctx_.live.subtree_nodes += out.nodes.size();
  }
  return sent;
}

Status SubtreeRunner::BatchSamples(const std::vector<const v1::SubtreeTask*>& tasks,
                                   const std::vector<uint64_t>& wanted,
                                   const std::vector<const engine::ShardFrame*>& src,
                                   std::map<uint64_t, std::vector<std::pair<size_t, size_t>>>& users) {
  const engine::TrainParams& params = ctx_.params;
  const int t = int(tasks[0]->tree());
  // Where each task's pixel list of each frame starts.
  std::vector<std::vector<size_t>> delta_at(tasks.size());
  for (size_t k = 0; k < tasks.size(); ++k) {
    delta_at[k].resize(size_t(tasks[k]->sample_counts_size()));
    for (size_t e = 0, at = 0; e < delta_at[k].size(); at += tasks[k]->sample_counts(int(e)), ++e)
      delta_at[k][e] = at;
  }
  // The batch's samples go into task_set_, whose frames are copied once per tree (frames it
  // lacks are added here); same samples in the same order as a fresh set, so same subtrees.
  size_t new_pixels = 0;
  for (size_t w = 0; w < wanted.size(); ++w)
    if (!task_set_frames_.count(wanted[w])) new_pixels += src[w]->frame.pixels.size();
  if (task_set_tree_ != t ||
      (task_set_.probe_pixels() + new_pixels) * sizeof(uint16_t) > std::max<uint64_t>(frames_.cache().cap_bytes, 1) ||
      task_set_.probe_pixels() + new_pixels >= (size_t(1) << 30)) {
    task_set_ = engine::SampleSet{};
    task_set_frames_.clear();
    task_set_tree_ = t;
    new_pixels = 0;
    for (const engine::ShardFrame* f : src) new_pixels += f->frame.pixels.size();
  }
  task_set_.ClearSamples();
  engine::SampleSet& set = task_set_;
  std::vector<uint32_t> node_of_sample;
  size_t samples_total = 0;
  for (const v1::SubtreeTask* task : tasks) samples_total += size_t(task->expected_samples());
  set.Reserve(wanted.size(), new_pixels, samples_total);
  for (size_t w = 0; w < wanted.size(); ++w)
    if (!task_set_frames_.count(wanted[w]))
      task_set_frames_[wanted[w]] = set.AddFrameOnly(wanted[w], src[w]->frame, params.constants);
  node_of_sample.reserve(samples_total);
  std::vector<engine::PixelSample> chosen, merged;
  std::vector<std::pair<uint64_t, uint32_t>> order;  // (pixel index, task) of `merged`
  for (size_t w = 0; w < wanted.size(); ++w) {
    const engine::ShardFrame* f = src[w];
    merged.clear();
    order.clear();
    for (const auto& [k, e] : users[wanted[w]]) {
      const uint32_t count = tasks[k]->sample_counts(int(e));
      POSEFOREST_RETURN_IF_ERROR(SelectListedSamples(
          f->picked, f->frame.width, wanted[w],
          std::span<const uint32_t>(tasks[k]->sample_pixel_deltas().data() + delta_at[k][e], count), &chosen));
      for (const engine::PixelSample& p : chosen) {
        order.push_back({uint64_t(p.y) * uint64_t(f->frame.width) + uint64_t(p.x), uint32_t(k)});
        merged.push_back(p);
      }
    }
    // One frame's samples in pixel order (as SamplePixels gives them), each tagged with its task.
    std::vector<size_t> idx(merged.size());
    for (size_t j = 0; j < idx.size(); ++j) idx[j] = j;
    std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return order[a] < order[b]; });
    std::vector<engine::PixelSample> sorted;
    sorted.reserve(merged.size());
    for (size_t j : idx) sorted.push_back(merged[j]), node_of_sample.push_back(order[j].second);
    if (!sorted.empty()) set.AddSamples(task_set_frames_.at(wanted[w]), sorted, params.constants);
  }
  set.StartTree(node_of_sample);
  return Status::Ok();
}

void SubtreeRunner::RunBatch(const std::vector<v1::Envelope>& batch, const std::string& sender) {
  std::vector<const v1::SubtreeTask*> tasks;
  std::vector<std::vector<uint64_t>> wanted_of;
  for (const v1::Envelope& env : batch) {
    std::vector<uint64_t> w;
    if (Status st = Check(env.subtree_task(), &w); !st.ok()) {
      Drop(env.subtree_task(), sender, st);
      continue;
    }
    tasks.push_back(&env.subtree_task());
    wanted_of.push_back(std::move(w));
  }
  if (tasks.empty()) return;
  const int t = int(tasks[0]->tree());
  const double t0 = proto::dds::NowSeconds();
  const Context::BusyScope busy_scope(ctx_.busy);
  ctx_.cpu.subtree_tasks += tasks.size();
  ++ctx_.cpu.subtree_batches;
  // The union of the tasks' frames; per frame, which tasks list samples there and where.
  std::map<uint64_t, std::vector<std::pair<size_t, size_t>>> users;  // frame -> (task, entry)
  for (size_t k = 0; k < tasks.size(); ++k)
    for (size_t e = 0; e < wanted_of[k].size(); ++e) users[wanted_of[k][e]].push_back({k, e});
  std::vector<uint64_t> wanted;
  for (const auto& [frame, u] : users) wanted.push_back(frame);
  std::vector<uint64_t> missing;
  std::vector<engine::ShardFrame> loaded;
  std::vector<const engine::ShardFrame*> src;
  auto one_by_one = [&](const Status& why) {
    ctx_.Log("a batch of " + std::to_string(tasks.size()) + " subtree tasks failed (" + why.ToString() +
             "): one by one");
    ctx_.cpu.subtree_tasks -= tasks.size();
    --ctx_.cpu.subtree_batches;
    for (const v1::SubtreeTask* task : tasks)
      if (Status st = Run(*task); !st.ok()) Drop(*task, sender, st);
  };
  if (Status st = frames_.Get(t, wanted, shard_.FramesOf(t), &missing, &loaded, &src); !st.ok())
    return one_by_one(st);
  std::optional<CpuTimer> route_timer(&ctx_.cpu.subtree_route);
  const Status built = BatchSamples(tasks, wanted, src, users);
  src.clear();
  frames_.Keep(missing, loaded);
  if (!built.ok()) {
    route_timer.reset();
    return one_by_one(built);
  }
  std::vector<engine::SubtreeRoot> roots(tasks.size());
  for (size_t k = 0; k < tasks.size(); ++k) {
    roots[k].sample_node = uint32_t(k);
    roots[k].position = tasks[k]->position();
    roots[k].parts.assign(tasks[k]->part_counts().begin(), tasks[k]->part_counts().end());
  }
  route_timer.reset();
  std::optional<CpuTimer> train_timer(&ctx_.cpu.subtree_train);
  served_in_batch_s_ = 0;
  auto out = engine::TrainSubtrees(task_set_, roots, ctx_.params, t, *builder_, pause_);
  train_timer.reset();
  if (!out.ok()) return one_by_one(out.status());
  ctx_.busy = false;
  for (size_t k = 0; k < tasks.size(); ++k) {
    uint64_t n = 0;
    for (uint64_t c : roots[k].parts) n += c;
    if (Status st = SendResult(*tasks[k], (*out)[k], t0, n, wanted_of[k].size(), missing.size()); !st.ok())
      Drop(*tasks[k], sender, st);
  }
}

}  // namespace poseforest::worker
