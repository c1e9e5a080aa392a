#include "coordinator/subtree_scheduler.h"

#include <algorithm>
#include <climits>
#include <cstring>
#include <tuple>

#include "engine/candidates.h"
#include "engine/wire_codec.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;
using proto::dds::Topic;

namespace {
bool FitsInt16(int32_t v) { return v >= INT16_MIN && v <= INT16_MAX; }
}  // namespace

SubtreeScheduler::SubtreeScheduler(Session& session, WorkerRegistry& registry, Rounds& rounds, LevelRecords& records)
    : s_(session), registry_(registry), rounds_(rounds), records_(records) {}

void SubtreeScheduler::Clear() {
  tasks_.clear();
  subtree_load_.clear();
}

void SubtreeScheduler::TakeResults(std::map<uint64_t, engine::SubtreeNode>* delegated) {
  for (auto& [pos, job] : tasks_)
    for (engine::SubtreeNode& n : job.nodes) (*delegated)[n.position] = std::move(n);
  tasks_.clear();
  subtree_load_.clear();
}

void SubtreeScheduler::RejectSubtree(const std::string& sender, const std::string& why) {
  ++subtree_rejected_;
  s_.Log("SubtreeResult from " + sender + " dropped: " + why);
  if (registry_.workers().count(sender)) {
    registry_.Ban(sender);
    registry_.MarkLost(sender, "evicted");
  }
}

void SubtreeScheduler::OnSubtreeResult(const std::string& sender, const v1::SubtreeResult& res) {
  SubtreeJob* job = nullptr;
  for (auto& [pos, t] : tasks_)
    if (t.epoch == res.epoch() && !t.done) job = &t;
  if (!job) {
    // An answer to a task that was handed on (its worker was thought lost) or is done: stale.
    ++s_.stale_count;
    s_.Log("SubtreeResult from " + sender + " of epoch " + std::to_string(res.epoch()) + ": no such task (stale)");
    return;
  }
  if (sender != job->worker) return RejectSubtree(sender, "task " + std::to_string(res.epoch()) + " is not its");
  if (res.tree() != uint32_t(s_.tree) || res.node_id() != job->node)
    return RejectSubtree(sender, "tree/node " + std::to_string(res.tree()) + "/" + std::to_string(res.node_id()) +
                                     ", task is " + std::to_string(s_.tree) + "/" + std::to_string(job->node));
  if (res.position() != job->position)
    return RejectSubtree(sender, "position " + std::to_string(res.position()) + ", task is " +
                                     std::to_string(job->position));
  std::vector<engine::SubtreeNode> nodes;
  for (const v1::SubtreeNode& n : res.subtree_nodes()) {
    if (n.split() && !(FitsInt16(n.ux()) && FitsInt16(n.uy()) && FitsInt16(n.vx()) && FitsInt16(n.vy())))
      return RejectSubtree(sender, "feature offsets outside int16");
    nodes.push_back(FromProto(n));
  }
  core::Tree layout;
  if (Status st = engine::ValidateSubtree(nodes, job->position, job->parts, s_.params, &layout); !st.ok())
    return RejectSubtree(sender, st.message());
  // The forest-format bytes must encode the same subtree.
  if (res.num_nodes() != layout.nodes.size() || res.num_leaves() != layout.num_leaves ||
      res.nodes().size() != layout.nodes.size() * sizeof(core::Node) ||
      std::memcmp(res.nodes().data(), layout.nodes.data(), res.nodes().size()) != 0 ||
      res.leaves() != std::string(reinterpret_cast<const char*>(layout.leaves.data()), layout.leaves.size()))
    return RejectSubtree(sender, "node/leaf bytes do not match its node list");
  job->nodes = std::move(nodes);
  job->done = true;
  ReleaseLoad(*job);
  level_subtree_evaluations_ += res.evaluations();
  s_.level_time.subtree_busy_s += double(res.busy_micros()) * 1e-6;
  s_.level_time.render_s += double(res.render_micros()) * 1e-6;
}

void SubtreeScheduler::ReleaseLoad(const SubtreeJob& job) {
  const auto it = subtree_load_.find(job.worker);
  if (it == subtree_load_.end()) return;
  uint64_t n = 0;
  for (uint64_t c : job.parts) n += c;
  it->second -= std::min(it->second, n);
}

/// Sends `job` to a live worker: the one with the least subtree work of this level
/// outstanding (samples of its unfinished tasks) less the samples of `job` it holds (its frames
/// need no rendering); ties: most samples held, then an assigned worker, then the smallest id.
/// A worker trains its tasks before it answers the level's histogram request, so balancing
/// the samples handed to each keeps one worker from holding up the level (which worker trains
/// a subtree never changes it).
Status SubtreeScheduler::SendTask(SubtreeJob& job) {
  const engine::TrainParams& params = s_.params;
  const WorkerInfo* best = nullptr;
  int64_t best_score = 0;
  uint64_t best_n = 0;
  for (const auto& [id, w] : registry_.workers()) {
    if (!w.alive) continue;
    const auto it = job.holders.find(id);
    const uint64_t n = it == job.holders.end() ? 0 : it->second;
    const auto load = subtree_load_.find(id);
    const int64_t score = int64_t(load == subtree_load_.end() ? 0 : load->second) - int64_t(n);
    if (!best || score < best_score || (score == best_score && n > best_n) ||
        (score == best_score && n == best_n && w.assigned && !best->assigned))
      best = &w, best_score = score, best_n = n;
  }
  if (!best) {
    POSEFOREST_RETURN_IF_ERROR(registry_.WaitForWorkers(1));
    return SendTask(job);
  }
  v1::SubtreeTask* t = &task_outbox_[best->id].emplace_back();
  t->set_tree(uint32_t(s_.tree));
  t->set_node_id(job.node);
  const int depth = engine::PositionDepth(job.position);
  t->set_depth(uint32_t(depth));
  t->set_epoch(++s_.epoch);
  std::vector<uint64_t> chain;  // root .. the node
  for (uint64_t p = job.position;; p = engine::ParentPosition(p)) {
    chain.push_back(p);
    if (p == engine::kRootPosition) break;
  }
  std::reverse(chain.begin(), chain.end());
  for (size_t i = 0; i + 1 < chain.size(); ++i) {
    const LevelRecords::SplitAt* split = records_.SplitAtPosition(chain[i]);
    if (!split) return Status(ErrorCode::kInternal, "no split known at position " + std::to_string(chain[i]));
    auto* step = t->add_path();
    engine::SetFeatureSplit(split->first, split->second, 1, 0, step->mutable_split());
    step->set_went_right(chain[i + 1] == engine::RightChildPosition(chain[i]));
  }
  const uint64_t base = uint64_t(s_.tree) * uint64_t(params.images_per_tree);
  for (size_t i = 0; i < job.frames.size();) {
    size_t j = i + 1;
    while (j < job.frames.size() && job.frames[j] == job.frames[j - 1] + 1) ++j;
    auto* r = t->add_ranges();
    r->set_seed(params.source.seed);
    r->set_first_index(base + job.frames[i]);
    r->set_count(uint32_t(j - i));
    i = j;
  }
  uint64_t total = 0;
  for (uint64_t c : job.parts) total += c;
  t->set_expected_samples(total);
  t->set_position(job.position);
  for (uint64_t c : job.parts) t->add_part_counts(c);
  if (!job.sample_counts.empty() && s_.opt.subtree_sample_lists) {
    t->mutable_sample_frames()->Add(job.frames.begin(), job.frames.end());
    t->mutable_sample_counts()->Add(job.sample_counts.begin(), job.sample_counts.end());
    t->mutable_sample_pixel_deltas()->Add(job.pixel_deltas.begin(), job.pixel_deltas.end());
  }
  job.worker = best->id;
  job.epoch = t->epoch();
  job.sent = proto::dds::NowSeconds();
  subtree_load_[job.worker] += total;
  level_handed_[job.worker] += total;
  level_largest_task_ = std::max(level_largest_task_, total);
  return Status::Ok();
}

/// Sends the SubtreeTasks that SendTask queued: one SubtreeTasks message per worker, split
/// only to stay under kSubtreeTasksMaxBytes, so a level's hand-off costs a few samples per
/// worker however many nodes it hands off (one sample per node filled a busy worker's control history).
Status SubtreeScheduler::FlushTasks() {
  std::map<std::string, std::vector<v1::SubtreeTask>> out;
  out.swap(task_outbox_);
  for (auto& [id, list] : out) {
    for (size_t i = 0; i < list.size();) {
      v1::Envelope env;
      env.set_recipient_id(id);
      v1::SubtreeTasks* batch = env.mutable_subtree_tasks();
      size_t bytes = 0;
      while (i < list.size() && batch->tasks_size() < proto::dds::kMaxSubtreeTasks &&
             (batch->tasks_size() == 0 || bytes + list[i].ByteSizeLong() <= proto::dds::kSubtreeTasksMaxBytes)) {
        bytes += list[i].ByteSizeLong();
        *batch->add_tasks() = std::move(list[i]);
        ++i;
      }
      ++level_task_messages_;
      POSEFOREST_RETURN_IF_ERROR(s_.Send(Topic::kControl, env));
    }
  }
  return Status::Ok();
}

Status SubtreeScheduler::WaitSubtrees() {
  const double limit = std::chrono::duration<double>(s_.opt.reply_timeout).count();
  for (;;) {
    bool all = true;
    for (auto& [pos, job] : tasks_) {
      if (job.done) continue;
      all = false;
      auto it = registry_.workers().find(job.worker);
      if (it != registry_.workers().end() && it->second.alive && proto::dds::NowSeconds() - job.sent > limit)
        registry_.MarkLost(job.worker, "no subtree result");
      if (it == registry_.workers().end() || !it->second.alive) {
        s_.Log("subtree at position " + std::to_string(pos) + ": " + job.worker + " is gone, handing it on");
        ++s_.level_retries;
        ReleaseLoad(job);
        POSEFOREST_RETURN_IF_ERROR(SendTask(job));
        POSEFOREST_RETURN_IF_ERROR(FlushTasks());
      }
    }
    if (all) return Status::Ok();
    rounds_.Pump(std::chrono::milliseconds(20));
  }
}

// Small nodes go to one worker each, whole (SubtreeTask): ask the workers which frames
// hold their samples, send the tasks, and let them train while the histogram rounds of
// the other nodes run. Never the root: one worker would train the whole tree. Small: at
// most subtree_max_samples samples, or (the frame rule) samples in at most
// subtree_max_frames frames, up to 16 x subtree_max_samples samples and a quarter of the
// tree's samples per live worker (a level of few large tasks would leave workers idle).
// Returns how many nodes were handed off; they leave *to_split.
Result<size_t> SubtreeScheduler::HandOff(int level, std::span<const engine::OpenNode> frontier,
                                         uint64_t level_samples, std::vector<size_t>* to_split) {
  const engine::TrainParams& params = s_.params;
  level_handed_.clear();
  level_largest_task_ = 0;
  level_task_messages_ = 0;
  if (params.subtree_max_samples > 0 && level > 0) {
    const uint64_t by_samples = params.subtree_max_samples;
    const uint64_t by_frames =
        params.subtree_max_frames > 0
            ? std::min(16 * by_samples, level_samples / (4 * uint64_t(std::max(1, registry_.AliveCount()))))
            : 0;
    std::vector<size_t> keep, ask;
    for (size_t i : *to_split) (frontier[i].total() <= std::max(by_samples, by_frames) ? ask : keep).push_back(i);
    if (!ask.empty()) {
      std::vector<uint32_t> ids;
      std::vector<v1::NodeSpec> specs(ask.size());
      for (size_t q = 0; q < ask.size(); ++q) {
        ids.push_back(frontier[ask[q]].node);
        specs[q].set_num_samples(frontier[ask[q]].total());
        specs[q].set_position(frontier[ask[q]].position);
      }
      auto rf = rounds_.Round(v1::PHASE_FRAMES, ids, specs, level);
      if (!rf.ok()) return rf.status();
      auto handed = MakeTasks(frontier, ask, *rf, by_samples, &keep);
      if (!handed.ok()) return handed.status();
      std::sort(keep.begin(), keep.end());  // frontier order, as before
      to_split->swap(keep);
      return *handed;
    }
  }
  return size_t(0);
}

Result<size_t> SubtreeScheduler::MakeTasks(std::span<const engine::OpenNode> frontier, const std::vector<size_t>& ask,
                                           const std::vector<Reply>& replies, uint64_t by_samples,
                                           std::vector<size_t>* keep) {
  const engine::TrainParams& params = s_.params;
  size_t hand = 0;
  tasks_.clear();
  subtree_load_.clear();
  for (size_t q = 0; q < ask.size(); ++q) {
    const engine::OpenNode& f = frontier[ask[q]];
    SubtreeJob job;
    job.node = f.node;
    job.position = f.position;
    job.parts = f.parts;
    uint64_t held = 0;
    // (frame, reply, first delta, count) of the listed samples; any holder without a
    // consistent list: the task goes without (the worker routes the frames' samples).
    std::vector<std::tuple<uint32_t, const v1::NodeRanges*, int, uint32_t>> listed;
    bool all_listed = true;
    for (const Reply& r : replies) {
      const v1::NodeRanges& nr = r.body.ranges(int(q));
      if (nr.num_samples() > 0) job.holders[r.sender] = nr.num_samples();
      held += nr.num_samples();
      job.frames.insert(job.frames.end(), nr.frames().begin(), nr.frames().end());
      uint64_t sum = 0;
      for (uint32_t c : nr.frame_samples()) sum += c;
      if (nr.frame_samples_size() != nr.frames_size() || sum != nr.num_samples() ||
          uint64_t(nr.pixel_deltas_size()) != sum) {
        if (nr.frame_samples_size() > 0 || nr.pixel_deltas_size() > 0)
          s_.Log("FRAMES reply from " + r.sender + ", node " + std::to_string(f.node) + ": " +
                 std::to_string(nr.pixel_deltas_size()) + " sample pixels, " + std::to_string(sum) +
                 " by its counts, " + std::to_string(nr.num_samples()) +
                 " samples: the task goes without sample lists (the worker routes)");
        all_listed = all_listed && nr.num_samples() == 0;
        continue;
      }
      for (int e = 0, at = 0; e < nr.frames_size(); at += int(nr.frame_samples(e)), ++e)
        listed.emplace_back(nr.frames(e), &nr, at, nr.frame_samples(e));
    }
    if (held != f.total())
      return Status(ErrorCode::kDataLoss, "node " + std::to_string(f.node) + ": the workers hold " +
                                              std::to_string(held) + " of its samples, expected " +
                                              std::to_string(f.total()));
    std::sort(job.frames.begin(), job.frames.end());
    job.frames.erase(std::unique(job.frames.begin(), job.frames.end()), job.frames.end());
    if (f.total() > by_samples && job.frames.size() > params.subtree_max_frames) {
      keep->push_back(ask[q]);  // too many frames to hand over: histogram rounds
      continue;
    }
    ++hand;
    std::sort(listed.begin(), listed.end(),
              [](const auto& a, const auto& b) { return std::get<0>(a) < std::get<0>(b); });
    if (all_listed && listed.size() == job.frames.size()) {  // no frame listed twice
      job.pixel_deltas.reserve(f.total());
      for (const auto& [frame, nr, at, count] : listed) {
        job.sample_counts.push_back(count);
        job.pixel_deltas.insert(job.pixel_deltas.end(), nr->pixel_deltas().begin() + at,
                                nr->pixel_deltas().begin() + at + int(count));
      }
    }
    tasks_[f.position] = std::move(job);
  }
  // Largest first, each to the least loaded worker (SendTask): the level's subtree work
  // splits evenly however unequal the nodes are.
  std::vector<SubtreeJob*> order;
  for (auto& [pos, job] : tasks_) order.push_back(&job);
  std::stable_sort(order.begin(), order.end(), [](const SubtreeJob* a, const SubtreeJob* b) {
    uint64_t na = 0, nb = 0;
    for (uint64_t c : a->parts) na += c;
    for (uint64_t c : b->parts) nb += c;
    return na > nb;
  });
  for (SubtreeJob* job : order) POSEFOREST_RETURN_IF_ERROR(SendTask(*job));
  POSEFOREST_RETURN_IF_ERROR(FlushTasks());
  return hand;
}

}  // namespace poseforest::coordinator
