#include "coordinator/worker_registry.h"

#include <algorithm>
#include <cstdio>

#include "proto/dds/node_config.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Status;
using proto::dds::Topic;

WorkerRegistry::WorkerRegistry(Session& session, const std::vector<v1::SplitDecisions>& tree_decisions)
    : s_(session), tree_decisions_(tree_decisions) {}

int WorkerRegistry::AssignedCount() const {
  int n = 0;
  for (const auto& [id, w] : workers_) n += w.alive && w.assigned;
  return n;
}

int WorkerRegistry::AliveCount() const {
  int n = 0;
  for (const auto& [id, w] : workers_) n += w.alive;
  return n;
}

void WorkerRegistry::OnPresence(const std::string& sender, const v1::Envelope& env, const std::string& writer_guid,
                                const std::string& participant) {
  if (banned_.count(sender)) return;
  if (env.has_hello() && !Admissible(sender, env.hello())) return;
  auto [it, fresh] = workers_.try_emplace(sender);
  WorkerInfo& w = it->second;
  if (fresh || !w.alive) {
    w = WorkerInfo{};
    w.id = sender;
    w.alive = true;
    s_.Log("worker " + w.id + " joined (" + std::to_string(AliveCount()) + " alive)");
    s_.PublishStatus(v1::STATUS_KIND_WORKER_JOINED, "joined", w.id);
  }
  w.alive = true;
  w.last_seen = proto::dds::NowSeconds();
  if (s_.opt.observer) s_.opt.observer->OnWorkerSeen(sender);
  if (env.has_heartbeat()) {
    const v1::Heartbeat& hb = env.heartbeat();
    w.seen_epoch = std::max({w.seen_epoch, hb.shard_epoch(), hb.received_shard_epoch()});
    if (s_.opt.observer) s_.opt.observer->OnWorkerHeartbeat(sender, hb);
  }
  w.presence_writer = writer_guid;
  w.participant = participant;
}

namespace {
/// `s` with control characters (a hostile peer's terminal escapes) replaced by '?'.
std::string Printable(std::string s) {
  for (char& c : s)
    if ((unsigned char)c < 0x20 || c == 0x7f) c = '?';
  return s;
}
}  // namespace

bool WorkerRegistry::Admissible(const std::string& sender, const v1::WorkerHello& hello) {
  std::string why;
  if (!hello.refusal().empty())
    why = "refused the job: " + Printable(hello.refusal());
  else if (hello.build_version() != s_.build_id)
    why = "runs build \"" + Printable(hello.build_version()) + "\", this coordinator \"" + s_.build_id +
          "\": not admitted (a different build may render and split differently, so the forest would depend "
          "on which worker took which frames; run the same build on every host, or set POSEFOREST_BUILD_ID "
          "to the same value on every host to train with builds known to train alike)";
  if (why.empty()) {
    refused_.erase(sender);
    return true;
  }
  const std::string entry =
      Printable(hello.hostname()) + " (pid " + std::to_string(hello.pid()) + "): " + why;
  auto [it, fresh] = refused_.try_emplace(sender, entry);
  if (fresh || it->second != entry) {
    it->second = entry;
    s_.Log("worker " + sender + " on " + entry);
    s_.PublishStatus(v1::STATUS_KIND_WORKER_REFUSED, why, sender);
  }
  // A member that says so now (a hostile peer, or a bug) leaves.
  if (auto w = workers_.find(sender); w != workers_.end() && w->second.alive)
    MarkLost(sender, "not admitted");
  return false;
}

void WorkerRegistry::OnDdsEvent(const proto::dds::DdsEvent& e) {
  if (e.kind == proto::dds::DdsEvent::Kind::kLivelinessLost && e.topic == Topic::kPresence) {
    for (auto& [id, w] : workers_)
      if (w.alive && w.presence_writer == e.peer_guid) MarkLost(id, "liveliness lost");
  } else if (e.kind == proto::dds::DdsEvent::Kind::kParticipantLost) {
    for (auto& [id, w] : workers_)
      if (w.alive && !w.participant.empty() && w.participant == e.peer_participant)
        MarkLost(id, "participant lost");
  }
}

void WorkerRegistry::CheckHeartbeats(double now) {
  const double limit = std::chrono::duration<double>(s_.opt.heartbeat_timeout).count();
  for (auto& [id, w] : workers_)
    if (w.alive && now - w.last_seen > limit) MarkLost(id, "heartbeat timeout");
}

void WorkerRegistry::MarkLost(const std::string& id, const std::string& why) {
  auto it = workers_.find(id);
  if (it == workers_.end() || !it->second.alive) return;
  WorkerInfo& w = it->second;
  w.alive = false;
  if (job_done_) {  // it heard JOB_DONE and left
    s_.Log("worker " + id + " left (job done)");
    return;
  }
  w.evicted = why == "evicted";
  ++lost_count_;
  if (w.assigned)
    for (auto r : w.frames) orphan_frames_.push_back(r);
  w.assigned = false;
  w.frames.clear();
  // A lost worker's id may come back (a restarted process); an evicted one stays flagged.
  if (why != "evicted") s_.gate->Forget(id);
  s_.Log("worker " + id + " lost (" + why + "); " + std::to_string(AliveCount()) + " alive");
  s_.PublishStatus(why == "evicted" ? v1::STATUS_KIND_WORKER_EVICTED : v1::STATUS_KIND_WORKER_LOST, why, id);
}

Status WorkerRegistry::WaitForWorkers(int n) {
  const double deadline = proto::dds::NowSeconds() + std::chrono::duration<double>(s_.opt.worker_wait).count();
  double announced = proto::dds::NowSeconds();
  while (AliveCount() < n) {
    if (proto::dds::NowSeconds() > deadline)
      return Status(ErrorCode::kNotFound,
                    "job " + s_.job_id + ": " + std::to_string(AliveCount()) + " of " + std::to_string(n) +
                        " workers after " + std::to_string(s_.opt.worker_wait.count()) +
                        " ms (DDS: " + std::to_string(s_.node->MatchedReaders(Topic::kJob)) +
                        " readers of the job matched, " +
                        std::to_string(s_.node->MatchedWriters(Topic::kPresence)) +
                        " presence writers; a worker matched but not joined did not get the job, was not "
                        "heard, or refused the job: its own log says why, e.g. a data file of the job "
                        "missing at the same path on its host)" +
                        RefusedSummary());
    // The announcement again every 2 s while workers are missing: the job topic is transient-
    // local, but a worker whose reader missed it (a CI run saw 3 of 5 workers never join)
    // would otherwise wait for ever. A worker that has the job ignores it.
    if (proto::dds::NowSeconds() - announced >= 2.0) {
      announced = proto::dds::NowSeconds();
      v1::Envelope again = s_.job_announcement;
      POSEFOREST_RETURN_IF_ERROR(s_.Send(Topic::kJob, again));
    }
    pump(std::chrono::milliseconds(50));
  }
  // Control messages to a worker whose reader has not matched yet would be lost.
  (void)s_.node->WaitForMatch(Topic::kControl, AliveCount(), std::chrono::milliseconds(5000));
  return Status::Ok();
}

std::string WorkerRegistry::RefusedSummary() const {
  if (refused_.empty()) return "";
  std::string out = "; " + std::to_string(refused_.size()) + " worker(s) not admitted:";
  for (const auto& [id, entry] : refused_) out += " " + id + " on " + entry + ";";
  out.pop_back();
  return out;
}

int WorkerRegistry::AwaitLostWorkers(std::chrono::milliseconds grace, const std::function<void()>& on_back) {
  job_done_ = true;
  std::set<std::string> waiting;  // lost during the job, not yet seen again
  for (const auto& [id, w] : workers_)
    if (!w.alive && !w.evicted && !banned_.count(id)) waiting.insert(id);
  if (waiting.empty() || grace.count() <= 0) return 0;
  const size_t lost = waiting.size();
  std::string names;
  for (const auto& id : waiting) names += (names.empty() ? "" : ", ") + id;
  char secs[32];
  std::snprintf(secs, sizeof secs, "%.1f", double(grace.count()) / 1000.0);
  s_.Log("job done; waiting up to " + std::string(secs) + " s for " + std::to_string(lost) +
         " lost worker(s) to come back and hear it: " + names);
  const double deadline = proto::dds::NowSeconds() + std::chrono::duration<double>(grace).count();
  while (!waiting.empty() && proto::dds::NowSeconds() < deadline) {
    pump(std::chrono::milliseconds(50));
    // Back once seen alive (a worker that then leaves on JOB_DONE is lost again: still back).
    const size_t before = waiting.size();
    std::erase_if(waiting, [&](const std::string& id) { return workers_.at(id).alive; });
    if (waiting.size() < before && on_back) on_back();
  }
  const int back = int(lost - waiting.size());
  s_.Log(std::to_string(back) + " of " + std::to_string(lost) + " lost worker(s) came back");
  return back;
}

Status WorkerRegistry::SendAssignment(WorkerInfo& w, uint32_t index, uint32_t count, bool again) {
  const engine::TrainParams& params = s_.params;
  v1::Envelope env;
  env.set_recipient_id(w.id);
  auto* s = env.mutable_shard();
  s->set_tree(uint32_t(s_.tree));
  s->set_epoch(++s_.epoch);
  s->set_pixels_per_image(uint32_t(params.pixels_per_image));
  s->set_shard_index(index);
  s->set_shard_count(count);
  const uint64_t base = uint64_t(s_.tree) * uint64_t(params.images_per_tree);
  for (auto [b, e] : w.frames) {
    auto* r = s->add_ranges();
    r->set_seed(params.source.seed);
    r->set_first_index(base + b);
    r->set_count(e - b);
  }
  POSEFOREST_RETURN_IF_ERROR(s_.Send(Topic::kControl, env));
  for (const v1::SplitDecisions& d : tree_decisions_) {
    v1::Envelope denv;
    denv.set_recipient_id(w.id);
    *denv.mutable_decisions() = d;
    denv.mutable_decisions()->set_epoch(++s_.epoch);
    POSEFOREST_RETURN_IF_ERROR(s_.Send(Topic::kControl, denv));
  }
  w.assigned = true;
  w.assign_epoch = s->epoch();
  w.assign_time = proto::dds::NowSeconds();
  if (again) {
    ++w.resends;
  } else {
    w.frames_epoch = s->epoch();
    w.resends = 0;
  }
  if (s_.opt.observer) {
    uint64_t frames = 0;
    for (auto [b, e] : w.frames) frames += e - b;
    s_.opt.observer->OnWorkerAssigned(w.id, s_.tree, frames);
  }
  return Status::Ok();
}

Status WorkerRegistry::Distribute(FrameRanges frames) {
  for (;;) {
    POSEFOREST_RETURN_IF_ERROR(WaitForWorkers(1));
    std::vector<WorkerInfo*> live;
    for (auto& [id, w] : workers_)
      if (w.alive) live.push_back(&w);
    std::vector<uint32_t> list;
    for (auto [b, e] : frames)
      for (uint32_t i = b; i < e; ++i) list.push_back(i);
    std::sort(list.begin(), list.end());
    const size_t n = live.size();
    std::vector<WorkerInfo*> changed;
    for (size_t k = 0; k < n; ++k) {
      const size_t b = list.size() * k / n, e = list.size() * (k + 1) / n;
      if (b == e) continue;
      for (size_t i = b; i < e;) {
        size_t j = i + 1;
        while (j < e && list[j] == list[j - 1] + 1) ++j;
        live[k]->frames.push_back({list[i], list[j - 1] + 1});
        i = j;
      }
      changed.push_back(live[k]);
    }
    for (WorkerInfo* w : changed) {
      std::sort(w->frames.begin(), w->frames.end());
      POSEFOREST_RETURN_IF_ERROR(SendAssignment(*w, 0, 1));
    }
    // A worker lost while we were sending: hand its frames on too.
    bool ok = true;
    for (WorkerInfo* w : changed) ok = ok && w->alive;
    if (ok) return Status::Ok();
    frames.swap(orphan_frames_);
    orphan_frames_.clear();
  }
}

void WorkerRegistry::ClearAssignments() {
  for (auto& [id, w] : workers_) w.assigned = false, w.frames.clear();
  orphan_frames_.clear();
}

FrameRanges WorkerRegistry::TakeOrphans() {
  FrameRanges frames = std::move(orphan_frames_);
  orphan_frames_.clear();
  return frames;
}

}  // namespace poseforest::coordinator
