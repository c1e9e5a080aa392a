#include "coordinator/rounds.h"

#include <algorithm>

#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;
using proto::dds::Topic;
using Verdict = proto::dds::MessageGate::Verdict;

namespace {
constexpr int kParts = core::kNumParts;
}  // namespace

Rounds::Rounds(Session& session, WorkerRegistry& registry) : s_(session), registry_(registry) {}

Status Rounds::CheckShape(const Reply& r, const std::string& sender) const {
  const engine::TrainParams& params = s_.params;
  const int k = params.candidate_features;
  auto bad = [&](const std::string& m) {
    return Status(ErrorCode::kInvalidArgument, "reply of " + sender + ": " + m);
  };
  if (r.body.phase() != expected_phase_) return bad("wrong phase");
  if (expected_phase_ == v1::PHASE_RANGES || expected_phase_ == v1::PHASE_COUNTS) {
    if (r.body.ranges_size() != expected_nodes_)
      return bad("ranges of " + std::to_string(r.body.ranges_size()) + " nodes");
    for (const auto& nr : r.body.ranges()) {
      if (expected_phase_ == v1::PHASE_RANGES && nr.fused()) {
        uint64_t total = 0;
        for (uint32_t c : nr.cut_counts()) {
          if (c > uint32_t(params.thresholds_per_feature)) return bad("cut count");
          total += c;
        }
        if (nr.cut_counts_size() != k || total != uint64_t(nr.cut_deltas_size())) return bad("cut list");
      } else if (expected_phase_ == v1::PHASE_RANGES && (nr.lo_size() != k || nr.hi_size() != k)) {
        return bad("range count");
      }
      if (expected_phase_ == v1::PHASE_COUNTS && nr.part_counts_size() != kParts)
        return bad("part count length");
      if (expected_phase_ == v1::PHASE_FRAMES) {
        for (int j = 0; j < nr.frames_size(); ++j)
          if (nr.frames(j) >= uint32_t(params.images_per_tree) || (j > 0 && nr.frames(j) <= nr.frames(j - 1)))
            return bad("frame list");
        if (nr.num_samples() > 0 && nr.frames_size() == 0) return bad("samples without frames");
      }
    }
  }
  return Status::Ok();
}

void Rounds::OnHistogramReply(const std::string& sender, const v1::HistogramReply& body, size_t bytes,
                              uint64_t want_epoch, std::map<std::string, Reply>* replies) {
  auto it = registry_.workers().find(sender);
  if (replies && body.epoch() == want_epoch && it != registry_.workers().end() && it->second.alive &&
      it->second.assigned) {
    Reply r;
    r.sender = sender;
    r.body = body;
    Status st = CheckShape(r, sender);
    if (!st.ok()) {
      // Well-formed for the gate but not what we asked: this worker cannot be trusted.
      s_.Log(st.ToString());
      registry_.MarkLost(sender, "evicted");
    } else {
      if (s_.opt.observer) s_.opt.observer->OnWorkerReply(sender, bytes, r.body);
      (*replies)[sender] = std::move(r);
    }
  }
}

void Rounds::Pump(std::chrono::milliseconds timeout, uint64_t want_epoch, std::map<std::string, Reply>* replies) {
  while (auto e = s_.node->NextEvent(std::chrono::milliseconds(0))) registry_.OnDdsEvent(*e);
  // Everything already queued is taken before the heartbeat check below: after a long merge
  // the presence samples that arrived meanwhile wait behind replies, and one sample per call
  // made a busy coordinator take live workers for lost (seen in a 2,000-image run).
  for (auto s = s_.node->Receive(timeout); s; s = s_.node->Receive(std::chrono::milliseconds(0))) {
    auto out = s_.gate->Check(s->topic, s->bytes, s->writer_guid);
    if (out.verdict == Verdict::kStale) ++s_.stale_count;
    if (out.verdict != Verdict::kAccepted) continue;
    const v1::Envelope& env = out.envelope;
    switch (env.body_case()) {
      case v1::Envelope::kHello:
      case v1::Envelope::kHeartbeat:
        registry_.OnPresence(out.sender, env, s->writer_guid, s->writer_participant);
        break;
      case v1::Envelope::kHistogram:
        s_.total_bytes_received += s->bytes.size();
        s_.level_bytes_received += s->bytes.size();
        OnHistogramReply(out.sender, env.histogram(), s->bytes.size(), want_epoch, replies);
        break;
      case v1::Envelope::kSubtreeResult:
        s_.total_bytes_received += s->bytes.size();
        s_.level_bytes_received += s->bytes.size();
        on_subtree_result(out.sender, env.subtree_result());
        break;
      default:
        break;
    }
  }
  for (const std::string& id : s_.gate->TakeOffenders()) {
    if (registry_.workers().count(id))
      registry_.MarkLost(id, "evicted");
    else
      s_.Log("sender " + id + " flagged by the gate; its messages are dropped");
  }
  const double now = proto::dds::NowSeconds();
  registry_.CheckHeartbeats(now);
  // Live figures for `monitor --domain` between events (a level can take minutes).
  if (s_.opt.observer && now - s_.last_status_time >= 2.0)
    s_.PublishStatus(v1::STATUS_KIND_PROGRESS, "", "", 0, s_.last_progress);
}

std::vector<Reply> Rounds::CloseRound(std::map<std::string, Reply>& replies, double t_round) {
  std::vector<Reply> out;
  for (auto& [id, w] : registry_.workers())
    if (w.assigned && w.alive) out.push_back(std::move(replies[id]));
  if (out.empty()) return out;
  // The critical worker: the largest queued + compute (the reply that completed the round).
  TimeSplit& time = s_.level_time;
  double crit = 0, crit_queued = 0, crit_compute = 0;
  for (const Reply& r : out) {
    const double q = double(r.body.queued_micros()) * 1e-6, c = double(r.body.compute_micros()) * 1e-6;
    if (q + c >= crit) crit = q + c, crit_queued = q, crit_compute = c;
    time.render_s += double(r.body.render_micros()) * 1e-6;
  }
  const double wall = proto::dds::NowSeconds() - t_round;
  ++time.rounds;
  time.round_s += wall;
  time.queued_s += std::min(crit_queued, wall);
  time.compute_s += std::min(crit_compute, std::max(0.0, wall - crit_queued));
  time.traffic_s += std::max(0.0, wall - crit);
  return out;
}

Result<std::vector<Reply>> Rounds::Round(v1::Phase phase, const std::vector<uint32_t>& node_ids,
                                         const std::vector<v1::NodeSpec>& specs, int level) {
  const engine::TrainParams& params = s_.params;
  const double t_round = proto::dds::NowSeconds();
  for (;;) {
    if (registry_.HasOrphans()) {
      FrameRanges frames = registry_.TakeOrphans();
      ++s_.level_retries;
      POSEFOREST_RETURN_IF_ERROR(registry_.Distribute(std::move(frames)));
    }
    v1::Envelope env;
    v1::LevelRequest* req = env.mutable_level_request();
    req->set_tree(uint32_t(s_.tree));
    req->set_level(uint32_t(level));
    req->set_epoch(++s_.epoch);
    for (uint32_t id : node_ids) {
      req->add_node_ids(id);
      req->add_candidate_seeds(params.seed);
    }
    req->set_job_seed(params.seed);
    req->set_num_candidates(uint32_t(params.candidate_features));
    req->set_num_thresholds(uint32_t(params.thresholds_per_feature + 1));
    req->set_num_parts(uint32_t(kParts));
    s_.gate->ExpectLevel(*req);
    req->set_phase(phase);
    for (const v1::NodeSpec& s : specs) *req->add_nodes() = s;
    const uint64_t want = req->epoch();
    expected_phase_ = phase;
    expected_nodes_ = int(node_ids.size());
    POSEFOREST_RETURN_IF_ERROR(s_.Send(Topic::kControl, env));
    std::map<std::string, Reply> replies;
    const double deadline = proto::dds::NowSeconds() + std::chrono::duration<double>(s_.opt.reply_timeout).count();
    for (;;) {
      if (proto::dds::NowSeconds() > deadline)
        for (auto& [id, w] : registry_.workers())
          if (w.assigned && w.alive && !replies.count(id)) registry_.MarkLost(id, "no reply");
      if (registry_.HasOrphans()) break;  // someone was lost: redistribute and ask again
      // A worker whose heartbeats show none of the assignments of its current frames missed
      // them (its control reader matched after we wrote): send it again, after 3 s, then 6,
      // 12, .. at most 30 s apart, and ask the round again. One that got any of them has its
      // frames: it is loading them or busy, and is waited for (resending to a busy worker
      // every 3 s, each with a new epoch, made it load each in turn: a livelock once seen in a
      // 12,000-image run; the worker also skips to the newest one queued).
      bool resent = false;
      for (auto& [id, w] : registry_.workers())
        if (w.assigned && w.alive && !replies.count(id) && w.seen_epoch < w.frames_epoch &&
            proto::dds::NowSeconds() - w.assign_time > std::min(30.0, 3.0 * double(1 << std::min(w.resends, 4)))) {
          s_.Log("worker " + id + " has not seen its assignment: sending it again");
          POSEFOREST_RETURN_IF_ERROR(registry_.SendAssignment(w, 0, 1, /*again=*/true));
          resent = true;
        }
      if (resent) break;
      bool all = true;
      for (const auto& [id, w] : registry_.workers())
        if (w.assigned && w.alive && !replies.count(id)) all = false;
      if (all) {
        std::vector<Reply> out = CloseRound(replies, t_round);
        if (out.empty()) break;
        return out;
      }
      Pump(std::chrono::milliseconds(20), want, &replies);
    }
    if (!registry_.HasOrphans() && registry_.AssignedCount() == 0) {
      // Nobody assigned (every worker lost before any answered): start over with the tree's frames.
      registry_.AddOrphans({0, uint32_t(params.images_per_tree)});
    }
  }
}

}  // namespace poseforest::coordinator
