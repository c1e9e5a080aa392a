#include "coordinator/dist_coordinator.h"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

#include "engine/candidates.h"
#include "engine/frontier_loop.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/split_search.h"
#include "engine/subtree_trainer.h"
#include "engine/tree_assembler.h"
#include "engine/wire_codec.h"
#include "poseforest/v1/checkpoint.pb.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;
using proto::dds::Topic;
using Verdict = proto::dds::MessageGate::Verdict;

namespace {
constexpr int kParts = core::kNumParts;
/// 2: frontier entries, logged decisions and subtree nodes carry heap positions (the random
/// draws are keyed by them since subtree hand-off); format 1 checkpoints cannot resume.
constexpr uint32_t kCheckpointFormat = 2;

struct WorkerInfo {
  std::string id;
  std::string presence_writer, participant;
  double last_seen = 0;
  bool alive = true;
  bool assigned = false;
  std::vector<std::pair<uint32_t, uint32_t>> frames;  ///< tree-local [begin, end) ranges
  uint64_t seen_epoch = 0;                            ///< newest shard epoch its heartbeats report
  uint64_t assign_epoch = 0;                          ///< epoch of its current ShardAssignment
  /// Epoch of the first ShardAssignment with its current frames (a resend repeats them): a
  /// worker whose heartbeats report it or later has them.
  uint64_t frames_epoch = 0;
  int resends = 0;  ///< of the current frames' assignment
  double assign_time = 0;
};

struct Reply {
  std::string sender;
  v1::HistogramReply body;
};

/// A node handed to one worker whole (SubtreeTask), until its SubtreeResult is in.
struct SubtreeJob {
  uint32_t node = 0;  ///< breadth-first id
  uint64_t position = 0;
  std::vector<uint64_t> parts;
  std::vector<uint32_t> frames;  ///< tree-local frames holding its samples
  /// The samples themselves when every holder listed them (FRAMES round): per frame of
  /// `frames`, how many, and their delta-coded pixel indices (SubtreeTask.sample_*).
  std::vector<uint32_t> sample_counts, pixel_deltas;
  std::map<std::string, uint64_t> holders;  ///< worker -> samples of the node in its shard
  std::string worker;                       ///< who has it now
  uint64_t epoch = 0;                       ///< of the task sent to `worker`
  double sent = 0;
  bool done = false;
  std::vector<engine::SubtreeNode> nodes;  ///< the result
};

engine::SubtreeNode FromProto(const v1::SubtreeNode& n) {
  engine::SubtreeNode o;
  o.position = n.position();
  o.split = n.split();
  o.offsets = {int16_t(n.ux()), int16_t(n.uy()), int16_t(n.vx()), int16_t(n.vy())};
  o.cut = n.cut();
  o.gain = n.gain();
  o.parts.assign(n.part_counts().begin(), n.part_counts().end());
  return o;
}

void ToProto(const engine::SubtreeNode& n, v1::SubtreeNode* o) {
  o->set_position(n.position);
  o->set_split(n.split);
  if (n.split) {
    o->set_ux(n.offsets.ux), o->set_uy(n.offsets.uy), o->set_vx(n.offsets.vx), o->set_vy(n.offsets.vy);
    o->set_cut(n.cut);
    o->set_gain(n.gain);
  }
  for (uint64_t c : n.parts) o->add_part_counts(c);
}

bool FitsInt16(int32_t v) { return v >= INT16_MIN && v <= INT16_MAX; }
}  // namespace

struct DistCoordinator::Impl {
  v1::TrainerConfig config;
  v1::Envelope job_announcement;  ///< the job as announced (sent again while workers are missing)
  engine::TrainParams params;
  CoordinatorOptions opt;
  std::string job_id, self_id;
  std::unique_ptr<proto::dds::DdsNode> node;
  std::unique_ptr<proto::dds::MessageGate> gate;
  proto::dds::EnvelopeStamper stamper{"", "", v1::SENDER_KIND_COORDINATOR};
  std::map<std::string, WorkerInfo> workers;
  std::vector<std::pair<uint32_t, uint32_t>> orphan_frames;  ///< of lost workers, current tree
  uint64_t epoch = 0;
  double start = 0;
  int lost_count = 0;
  uint64_t total_bytes_received = 0;
  uint64_t stale_count = 0;  ///< stale messages (the gate's per-sender stats are reset by Forget)

  // Current tree.
  int tree = -1;
  std::vector<v1::SplitDecisions> tree_decisions;  ///< per decided level, for replays
  /// Every split of the current tree by heap position (the paths of SubtreeTasks).
  std::map<uint64_t, std::pair<core::FeatureOffsets, int32_t>> split_of;
  /// Decided nodes of delegated subtrees not placed in the tree yet, by heap position.
  std::map<uint64_t, engine::SubtreeNode> delegated;
  std::map<uint64_t, SubtreeJob> tasks;  ///< outstanding SubtreeTasks of this level, by position
  /// Samples of each worker's unfinished SubtreeTasks of this level (SendTask balances them).
  std::map<std::string, uint64_t> subtree_load;
  std::map<std::string, uint64_t> level_handed;  ///< samples of SubtreeTasks sent this level, per worker
  uint64_t level_largest_task = 0;               ///< samples of the largest SubtreeTask of this level
  /// SubtreeTasks chosen by SendTask, per worker, until FlushTasks sends them.
  std::map<std::string, std::vector<v1::SubtreeTask>> task_outbox;
  uint64_t level_task_messages = 0;  ///< SubtreeTasks messages sent this level
  std::set<std::string> banned;      ///< senders of hostile SubtreeResults: never rejoin
  uint64_t subtree_rejected = 0;
  uint64_t level_subtree_evaluations = 0;
  // Level accounting.
  uint64_t level_bytes_received = 0, level_bytes_sent = 0;
  /// Where the level's time went (DistLevelStats' round_*, subtree_*, render_seconds).
  struct TimeSplit {
    int rounds = 0;
    double round_s = 0, compute_s = 0, queued_s = 0, traffic_s = 0, subtree_wait_s = 0, subtree_busy_s = 0,
           render_s = 0;
  } level_time;
  int level_retries = 0;

  // Checkpoint state.
  v1::Checkpoint ckpt;

  void Log(const std::string& m) { opt.log(m); }

  int AssignedCount() const {
    int n = 0;
    for (const auto& [id, w] : workers) n += w.alive && w.assigned;
    return n;
  }

  int AliveCount() const {
    int n = 0;
    for (const auto& [id, w] : workers) n += w.alive;
    return n;
  }

  Status Send(Topic topic, v1::Envelope& env) {
    const std::string bytes = stamper.Seal(topic, env);
    if (topic == Topic::kControl) level_bytes_sent += bytes.size();
    return node->Publish(topic, bytes);
  }

  void PublishStatus(v1::StatusKind kind, const std::string& message, const std::string& worker = "",
                     int level = 0, double progress = 0) {
    v1::Envelope env;
    auto* s = env.mutable_status();
    s->set_kind(kind);
    s->set_tree(uint32_t(std::max(0, tree)));
    s->set_level(uint32_t(level));
    s->set_epoch(epoch);
    s->set_progress(std::clamp(progress, 0.0, 1.0));
    s->set_worker_id(worker);
    s->set_message(message);
    s->set_active_workers(uint32_t(AliveCount()));
    if (opt.observer) {
      if (kind != v1::STATUS_KIND_PROGRESS) opt.observer->OnStatus(*s);
      opt.observer->FillStatus(s);  // throughput, ETA, workers (monitor --domain)
    }
    last_status_time = proto::dds::NowSeconds();
    (void)Send(Topic::kStatus, env);
  }
  double last_status_time = 0;  ///< of the last StatusEvent: a PROGRESS one 2 s after it
  double last_progress = 0;     ///< of the last LEVEL_DONE / TREE_DONE, for PROGRESS events

  void MarkLost(const std::string& id, const std::string& why) {
    auto it = workers.find(id);
    if (it == workers.end() || !it->second.alive) return;
    WorkerInfo& w = it->second;
    w.alive = false;
    ++lost_count;
    if (w.assigned)
      for (auto r : w.frames) orphan_frames.push_back(r);
    w.assigned = false;
    w.frames.clear();
    // A lost worker's id may come back (a restarted process); an evicted one stays flagged.
    if (why != "evicted") gate->Forget(id);
    Log("worker " + id + " lost (" + why + "); " + std::to_string(AliveCount()) + " alive");
    PublishStatus(why == "evicted" ? v1::STATUS_KIND_WORKER_EVICTED : v1::STATUS_KIND_WORKER_LOST, why, id);
  }

  v1::Phase expected_phase = v1::PHASE_UNSPECIFIED;
  int expected_nodes = 0;

  Status CheckShape(const Reply& r, const std::string& sender) const {
    const int k = params.candidate_features;
    auto bad = [&](const std::string& m) {
      return Status(ErrorCode::kInvalidArgument, "reply of " + sender + ": " + m);
    };
    if (r.body.phase() != expected_phase) return bad("wrong phase");
    if (expected_phase == v1::PHASE_RANGES || expected_phase == v1::PHASE_COUNTS) {
      if (r.body.ranges_size() != expected_nodes)
        return bad("ranges of " + std::to_string(r.body.ranges_size()) + " nodes");
      for (const auto& nr : r.body.ranges()) {
        if (expected_phase == v1::PHASE_RANGES && nr.fused()) {
          uint64_t total = 0;
          for (uint32_t c : nr.cut_counts()) {
            if (c > uint32_t(params.thresholds_per_feature)) return bad("cut count");
            total += c;
          }
          if (nr.cut_counts_size() != k || total != uint64_t(nr.cut_deltas_size())) return bad("cut list");
        } else if (expected_phase == v1::PHASE_RANGES && (nr.lo_size() != k || nr.hi_size() != k)) {
          return bad("range count");
        }
        if (expected_phase == v1::PHASE_COUNTS && nr.part_counts_size() != kParts)
          return bad("part count length");
        if (expected_phase == v1::PHASE_FRAMES) {
          for (int j = 0; j < nr.frames_size(); ++j)
            if (nr.frames(j) >= uint32_t(params.images_per_tree) ||
                (j > 0 && nr.frames(j) <= nr.frames(j - 1)))
              return bad("frame list");
          if (nr.num_samples() > 0 && nr.frames_size() == 0) return bad("samples without frames");
        }
      }
    }
    return Status::Ok();
  }

  /// Receives for up to `timeout`, handling presence, replies, events, offenders and timeouts.
  /// Replies of `want_epoch` from pending workers land in `replies`.
  void Pump(std::chrono::milliseconds timeout, uint64_t want_epoch, std::map<std::string, Reply>* replies) {
    while (auto e = node->NextEvent(std::chrono::milliseconds(0))) {
      if (e->kind == proto::dds::DdsEvent::Kind::kLivelinessLost && e->topic == Topic::kPresence) {
        for (auto& [id, w] : workers)
          if (w.alive && w.presence_writer == e->peer_guid) MarkLost(id, "liveliness lost");
      } else if (e->kind == proto::dds::DdsEvent::Kind::kParticipantLost) {
        for (auto& [id, w] : workers)
          if (w.alive && !w.participant.empty() && w.participant == e->peer_participant)
            MarkLost(id, "participant lost");
      }
    }
    // Everything already queued is taken before the heartbeat check below: after a long merge
    // the presence samples that arrived meanwhile wait behind replies, and one sample per call
    // made a busy coordinator take live workers for lost (seen in a 2,000-image run).
    for (auto s = node->Receive(timeout); s; s = node->Receive(std::chrono::milliseconds(0))) {
      auto out = gate->Check(s->topic, s->bytes, s->writer_guid);
      if (out.verdict == Verdict::kStale) ++stale_count;
      if (out.verdict == Verdict::kAccepted) {
        const v1::Envelope& env = out.envelope;
        switch (env.body_case()) {
          case v1::Envelope::kHello:
          case v1::Envelope::kHeartbeat: {
            if (banned.count(out.sender)) break;
            auto [it, fresh] = workers.try_emplace(out.sender);
            WorkerInfo& w = it->second;
            if (fresh || !w.alive) {
              w = WorkerInfo{};
              w.id = out.sender;
              w.alive = true;
              Log("worker " + w.id + " joined (" + std::to_string(AliveCount()) + " alive)");
              PublishStatus(v1::STATUS_KIND_WORKER_JOINED, "joined", w.id);
            }
            w.alive = true;
            w.last_seen = proto::dds::NowSeconds();
            if (opt.observer) opt.observer->OnWorkerSeen(out.sender);
            if (env.has_heartbeat()) {
              const v1::Heartbeat& hb = env.heartbeat();
              w.seen_epoch = std::max({w.seen_epoch, hb.shard_epoch(), hb.received_shard_epoch()});
              if (opt.observer) opt.observer->OnWorkerHeartbeat(out.sender, hb);
            }
            w.presence_writer = s->writer_guid;
            w.participant = s->writer_participant;
            break;
          }
          case v1::Envelope::kHistogram: {
            total_bytes_received += s->bytes.size();
            level_bytes_received += s->bytes.size();
            auto it = workers.find(out.sender);
            if (replies && env.histogram().epoch() == want_epoch && it != workers.end() && it->second.alive &&
                it->second.assigned) {
              Reply r;
              r.sender = out.sender;
              r.body = env.histogram();
              Status st = CheckShape(r, out.sender);
              if (!st.ok()) {
                // Well-formed for the gate but not what we asked: this worker cannot be trusted.
                Log(st.ToString());
                MarkLost(out.sender, "evicted");
              } else {
                if (opt.observer) opt.observer->OnWorkerReply(out.sender, s->bytes.size(), r.body);
                (*replies)[out.sender] = std::move(r);
              }
            }
            break;
          }
          case v1::Envelope::kSubtreeResult:
            total_bytes_received += s->bytes.size();
            level_bytes_received += s->bytes.size();
            OnSubtreeResult(out.sender, env.subtree_result());
            break;
          default:
            break;
        }
      }
    }
    for (const std::string& id : gate->TakeOffenders()) {
      if (workers.count(id))
        MarkLost(id, "evicted");
      else
        Log("sender " + id + " flagged by the gate; its messages are dropped");
    }
    const double now = proto::dds::NowSeconds();
    const double limit = std::chrono::duration<double>(opt.heartbeat_timeout).count();
    for (auto& [id, w] : workers)
      if (w.alive && now - w.last_seen > limit) MarkLost(id, "heartbeat timeout");
    // Live figures for `monitor --domain` between events (a level can take minutes).
    if (opt.observer && now - last_status_time >= 2.0)
      PublishStatus(v1::STATUS_KIND_PROGRESS, "", "", 0, last_progress);
  }

  Status WaitForWorkers(int n) {
    const double deadline = proto::dds::NowSeconds() + std::chrono::duration<double>(opt.worker_wait).count();
    double announced = proto::dds::NowSeconds();
    while (AliveCount() < n) {
      if (proto::dds::NowSeconds() > deadline)
        return Status(ErrorCode::kNotFound,
                      "job " + job_id + ": " + std::to_string(AliveCount()) + " of " + std::to_string(n) +
                          " workers after " + std::to_string(opt.worker_wait.count()) + " ms (DDS: " +
                          std::to_string(node->MatchedReaders(Topic::kJob)) + " readers of the job matched, " +
                          std::to_string(node->MatchedWriters(Topic::kPresence)) +
                          " presence writers; a worker matched but not joined did not get the job or was "
                          "not heard)");
      // The announcement again every 2 s while workers are missing: the job topic is transient-
      // local, but a worker whose reader missed it (a CI run saw 3 of 5 workers never join)
      // would otherwise wait for ever. A worker that has the job ignores it.
      if (proto::dds::NowSeconds() - announced >= 2.0) {
        announced = proto::dds::NowSeconds();
        v1::Envelope again = job_announcement;
        POSEFOREST_RETURN_IF_ERROR(Send(Topic::kJob, again));
      }
      Pump(std::chrono::milliseconds(50), 0, nullptr);
    }
    // Control messages to a worker whose reader has not matched yet would be lost.
    (void)node->WaitForMatch(Topic::kControl, AliveCount(), std::chrono::milliseconds(5000));
    return Status::Ok();
  }

  /// Sends `w` its ShardAssignment, then the tree's decisions so far (the worker replays them).
  /// `again`: the same frames once more (the worker's heartbeats do not show it got them).
  Status SendAssignment(WorkerInfo& w, uint32_t index, uint32_t count, bool again = false) {
    v1::Envelope env;
    env.set_recipient_id(w.id);
    auto* s = env.mutable_shard();
    s->set_tree(uint32_t(tree));
    s->set_epoch(++epoch);
    s->set_pixels_per_image(uint32_t(params.pixels_per_image));
    s->set_shard_index(index);
    s->set_shard_count(count);
    const uint64_t base = uint64_t(tree) * uint64_t(params.images_per_tree);
    for (auto [b, e] : w.frames) {
      auto* r = s->add_ranges();
      r->set_seed(params.source.seed);
      r->set_first_index(base + b);
      r->set_count(e - b);
    }
    POSEFOREST_RETURN_IF_ERROR(Send(Topic::kControl, env));
    for (const v1::SplitDecisions& d : tree_decisions) {
      v1::Envelope denv;
      denv.set_recipient_id(w.id);
      *denv.mutable_decisions() = d;
      denv.mutable_decisions()->set_epoch(++epoch);
      POSEFOREST_RETURN_IF_ERROR(Send(Topic::kControl, denv));
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
    if (opt.observer) {
      uint64_t frames = 0;
      for (auto [b, e] : w.frames) frames += e - b;
      opt.observer->OnWorkerAssigned(w.id, tree, frames);
    }
    return Status::Ok();
  }

  /// Spreads `frames` (tree-local ranges) over every live worker in contiguous blocks and
  /// (re)sends the assignments of the workers that got some.
  Status Distribute(std::vector<std::pair<uint32_t, uint32_t>> frames) {
    for (;;) {
      POSEFOREST_RETURN_IF_ERROR(WaitForWorkers(1));
      std::vector<WorkerInfo*> live;
      for (auto& [id, w] : workers)
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
      frames.swap(orphan_frames);
      orphan_frames.clear();
    }
  }

  /// One request/reply round over the assigned workers, repeated under a new epoch (after
  /// handing lost workers' frames on) until every assigned worker has answered.
  Result<std::vector<Reply>> Round(v1::Phase phase, const std::vector<uint32_t>& node_ids,
                                   const std::vector<v1::NodeSpec>& specs, int level) {
    const double t_round = proto::dds::NowSeconds();
    for (;;) {
      if (!orphan_frames.empty()) {
        auto frames = std::move(orphan_frames);
        orphan_frames.clear();
        ++level_retries;
        POSEFOREST_RETURN_IF_ERROR(Distribute(std::move(frames)));
      }
      v1::Envelope env;
      v1::LevelRequest* req = env.mutable_level_request();
      req->set_tree(uint32_t(tree));
      req->set_level(uint32_t(level));
      req->set_epoch(++epoch);
      for (uint32_t id : node_ids) {
        req->add_node_ids(id);
        req->add_candidate_seeds(params.seed);
      }
      req->set_job_seed(params.seed);
      req->set_num_candidates(uint32_t(params.candidate_features));
      req->set_num_thresholds(uint32_t(params.thresholds_per_feature + 1));
      req->set_num_parts(uint32_t(kParts));
      gate->ExpectLevel(*req);
      req->set_phase(phase);
      for (const v1::NodeSpec& s : specs) *req->add_nodes() = s;
      const uint64_t want = req->epoch();
      expected_phase = phase;
      expected_nodes = int(node_ids.size());
      POSEFOREST_RETURN_IF_ERROR(Send(Topic::kControl, env));
      std::map<std::string, Reply> replies;
      const double deadline =
          proto::dds::NowSeconds() + std::chrono::duration<double>(opt.reply_timeout).count();
      for (;;) {
        if (proto::dds::NowSeconds() > deadline)
          for (auto& [id, w] : workers)
            if (w.assigned && w.alive && !replies.count(id)) MarkLost(id, "no reply");
        if (!orphan_frames.empty()) break;  // someone was lost: redistribute and ask again
        // A worker whose heartbeats show none of the assignments of its current frames missed
        // them (its control reader matched after we wrote): send it again, after 3 s, then 6,
        // 12, .. at most 30 s apart, and ask the round again. One that got any of them has its
        // frames: it is loading them or busy, and is waited for (resending to a busy worker
        // every 3 s, each with a new epoch, made it load each in turn: the livelock of issue
        // 13's run of record; the worker also skips to the newest one queued).
        bool resent = false;
        for (auto& [id, w] : workers)
          if (w.assigned && w.alive && !replies.count(id) && w.seen_epoch < w.frames_epoch &&
              proto::dds::NowSeconds() - w.assign_time >
                  std::min(30.0, 3.0 * double(1 << std::min(w.resends, 4)))) {
            Log("worker " + id + " has not seen its assignment: sending it again");
            POSEFOREST_RETURN_IF_ERROR(SendAssignment(w, 0, 1, /*again=*/true));
            resent = true;
          }
        if (resent) break;
        bool all = true;
        for (const auto& [id, w] : workers)
          if (w.assigned && w.alive && !replies.count(id)) all = false;
        if (all) {
          std::vector<Reply> out;
          for (auto& [id, w] : workers)
            if (w.assigned && w.alive) out.push_back(std::move(replies[id]));
          if (out.empty()) break;
          // The critical worker: the largest queued + compute (the reply that completed the round).
          double crit = 0, crit_queued = 0, crit_compute = 0;
          for (const Reply& r : out) {
            const double q = double(r.body.queued_micros()) * 1e-6, c = double(r.body.compute_micros()) * 1e-6;
            if (q + c >= crit) crit = q + c, crit_queued = q, crit_compute = c;
            level_time.render_s += double(r.body.render_micros()) * 1e-6;
          }
          const double wall = proto::dds::NowSeconds() - t_round;
          ++level_time.rounds;
          level_time.round_s += wall;
          level_time.queued_s += std::min(crit_queued, wall);
          level_time.compute_s += std::min(crit_compute, std::max(0.0, wall - crit_queued));
          level_time.traffic_s += std::max(0.0, wall - crit);
          return out;
        }
        Pump(std::chrono::milliseconds(20), want, &replies);
      }
      if (orphan_frames.empty() && AssignedCount() == 0) {
        // Nobody assigned (every worker lost before any answered): start over with the tree's frames.
        orphan_frames.push_back({0, uint32_t(params.images_per_tree)});
      }
    }
  }

  /// A SubtreeResult that does not fit its task: dropped, counted, and its sender (if it is one
  /// of our workers) evicted for good; its task goes to another worker.
  void RejectSubtree(const std::string& sender, const std::string& why) {
    ++subtree_rejected;
    Log("SubtreeResult from " + sender + " dropped: " + why);
    if (workers.count(sender)) {
      banned.insert(sender);
      MarkLost(sender, "evicted");
    }
  }

  void OnSubtreeResult(const std::string& sender, const v1::SubtreeResult& res) {
    SubtreeJob* job = nullptr;
    for (auto& [pos, t] : tasks)
      if (t.epoch == res.epoch() && !t.done) job = &t;
    if (!job) {
      // An answer to a task that was handed on (its worker was thought lost) or is done: stale.
      ++stale_count;
      Log("SubtreeResult from " + sender + " of epoch " + std::to_string(res.epoch()) +
          ": no such task (stale)");
      return;
    }
    if (sender != job->worker)
      return RejectSubtree(sender, "task " + std::to_string(res.epoch()) + " is not its");
    if (res.tree() != uint32_t(tree) || res.node_id() != job->node)
      return RejectSubtree(sender, "tree/node " + std::to_string(res.tree()) + "/" +
                                       std::to_string(res.node_id()) + ", task is " + std::to_string(tree) +
                                       "/" + std::to_string(job->node));
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
    if (Status st = engine::ValidateSubtree(nodes, job->position, job->parts, params, &layout); !st.ok())
      return RejectSubtree(sender, st.message());
    // The forest-format bytes must encode the same subtree.
    if (res.num_nodes() != layout.nodes.size() || res.num_leaves() != layout.num_leaves ||
        res.nodes().size() != layout.nodes.size() * sizeof(core::Node) ||
        std::memcmp(res.nodes().data(), layout.nodes.data(), res.nodes().size()) != 0 ||
        res.leaves() !=
            std::string(reinterpret_cast<const char*>(layout.leaves.data()), layout.leaves.size()))
      return RejectSubtree(sender, "node/leaf bytes do not match its node list");
    job->nodes = std::move(nodes);
    job->done = true;
    ReleaseLoad(*job);
    level_subtree_evaluations += res.evaluations();
    level_time.subtree_busy_s += double(res.busy_micros()) * 1e-6;
    level_time.render_s += double(res.render_micros()) * 1e-6;
  }

  /// Takes `job`'s samples off its worker's outstanding subtree load (done or handed on).
  void ReleaseLoad(const SubtreeJob& job) {
    const auto it = subtree_load.find(job.worker);
    if (it == subtree_load.end()) return;
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
  Status SendTask(SubtreeJob& job) {
    const WorkerInfo* best = nullptr;
    int64_t best_score = 0;
    uint64_t best_n = 0;
    for (const auto& [id, w] : workers) {
      if (!w.alive) continue;
      const auto it = job.holders.find(id);
      const uint64_t n = it == job.holders.end() ? 0 : it->second;
      const auto load = subtree_load.find(id);
      const int64_t score = int64_t(load == subtree_load.end() ? 0 : load->second) - int64_t(n);
      if (!best || score < best_score || (score == best_score && n > best_n) ||
          (score == best_score && n == best_n && w.assigned && !best->assigned))
        best = &w, best_score = score, best_n = n;
    }
    if (!best) {
      POSEFOREST_RETURN_IF_ERROR(WaitForWorkers(1));
      return SendTask(job);
    }
    v1::SubtreeTask* t = &task_outbox[best->id].emplace_back();
    t->set_tree(uint32_t(tree));
    t->set_node_id(job.node);
    const int depth = engine::PositionDepth(job.position);
    t->set_depth(uint32_t(depth));
    t->set_epoch(++epoch);
    std::vector<uint64_t> chain;  // root .. the node
    for (uint64_t p = job.position;; p = engine::ParentPosition(p)) {
      chain.push_back(p);
      if (p == engine::kRootPosition) break;
    }
    std::reverse(chain.begin(), chain.end());
    for (size_t i = 0; i + 1 < chain.size(); ++i) {
      const auto it = split_of.find(chain[i]);
      if (it == split_of.end())
        return Status(ErrorCode::kInternal, "no split known at position " + std::to_string(chain[i]));
      auto* step = t->add_path();
      engine::SetFeatureSplit(it->second.first, it->second.second, 1, 0, step->mutable_split());
      step->set_went_right(chain[i + 1] == engine::RightChildPosition(chain[i]));
    }
    const uint64_t base = uint64_t(tree) * uint64_t(params.images_per_tree);
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
    if (!job.sample_counts.empty() && opt.subtree_sample_lists) {
      t->mutable_sample_frames()->Add(job.frames.begin(), job.frames.end());
      t->mutable_sample_counts()->Add(job.sample_counts.begin(), job.sample_counts.end());
      t->mutable_sample_pixel_deltas()->Add(job.pixel_deltas.begin(), job.pixel_deltas.end());
    }
    job.worker = best->id;
    job.epoch = t->epoch();
    job.sent = proto::dds::NowSeconds();
    subtree_load[job.worker] += total;
    level_handed[job.worker] += total;
    level_largest_task = std::max(level_largest_task, total);
    return Status::Ok();
  }

  /// Sends the SubtreeTasks that SendTask queued: one SubtreeTasks message per worker, split
  /// only to stay under kSubtreeTasksMaxBytes, so a level's hand-off costs a few samples per
  /// worker however many nodes it hands off (one sample per node filled a busy worker's control history).
  Status FlushTasks() {
    std::map<std::string, std::vector<v1::SubtreeTask>> out;
    out.swap(task_outbox);
    for (auto& [id, list] : out) {
      for (size_t i = 0; i < list.size();) {
        v1::Envelope env;
        env.set_recipient_id(id);
        v1::SubtreeTasks* batch = env.mutable_subtree_tasks();
        size_t bytes = 0;
        while (i < list.size() && batch->tasks_size() < proto::dds::kMaxSubtreeTasks &&
               (batch->tasks_size() == 0 ||
                bytes + list[i].ByteSizeLong() <= proto::dds::kSubtreeTasksMaxBytes)) {
          bytes += list[i].ByteSizeLong();
          *batch->add_tasks() = std::move(list[i]);
          ++i;
        }
        ++level_task_messages;
        POSEFOREST_RETURN_IF_ERROR(Send(Topic::kControl, env));
      }
    }
    return Status::Ok();
  }

  /// Waits for every outstanding SubtreeTask's result, handing the task of a worker that is
  /// lost (or evicted, or silent past reply_timeout) to another one: same result, since the
  /// subtree depends on the node's samples alone.
  Status WaitSubtrees() {
    const double limit = std::chrono::duration<double>(opt.reply_timeout).count();
    for (;;) {
      bool all = true;
      for (auto& [pos, job] : tasks) {
        if (job.done) continue;
        all = false;
        auto it = workers.find(job.worker);
        if (it != workers.end() && it->second.alive && proto::dds::NowSeconds() - job.sent > limit)
          MarkLost(job.worker, "no subtree result");
        if (it == workers.end() || !it->second.alive) {
          Log("subtree at position " + std::to_string(pos) + ": " + job.worker + " is gone, handing it on");
          ++level_retries;
          ReleaseLoad(job);
          POSEFOREST_RETURN_IF_ERROR(SendTask(job));
          POSEFOREST_RETURN_IF_ERROR(FlushTasks());
        }
      }
      if (all) return Status::Ok();
      Pump(std::chrono::milliseconds(20), 0, nullptr);
    }
  }

  Status SaveCheckpoint() {
    if (opt.checkpoint_dir.empty()) return Status::Ok();
    ckpt.set_epoch(epoch);
    const std::string bytes = ckpt.SerializeAsString();
    std::error_code ec;
    std::filesystem::create_directories(opt.checkpoint_dir, ec);
    return core::WriteFileAtomic(
        (std::filesystem::path(opt.checkpoint_dir) / "checkpoint.pb").string(),
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()));
  }

  /// Replays a logged tree's levels into `assembler`; errors if the log is inconsistent.
  static Status Replay(const v1::LoggedTree& log, engine::TreeAssembler* assembler) {
    for (const v1::LoggedLevel& level : log.levels())
      for (const v1::LoggedDecision& d : level.decisions()) {
        if (d.split()) {
          core::FeatureOffsets f{int16_t(d.ux()), int16_t(d.uy()), int16_t(d.vx()), int16_t(d.vy())};
          if (assembler->MakeSplit(d.node(), f, d.cut()) != d.left_child())
            return Status(ErrorCode::kDataLoss, "checkpoint: node layout does not replay");
        } else {
          if (d.part_counts_size() != kParts)
            return Status(ErrorCode::kDataLoss, "checkpoint: leaf part counts");
          std::vector<uint64_t> parts(d.part_counts().begin(), d.part_counts().end());
          assembler->MakeLeaf(d.node(), parts);
        }
      }
    return Status::Ok();
  }

  // Small nodes go to one worker each, whole (SubtreeTask): ask the workers which frames
  // hold their samples, send the tasks, and let them train while the histogram rounds of
  // the other nodes run. Never the root: one worker would train the whole tree. Small: at
  // most subtree_max_samples samples, or (the frame rule) samples in at most
  // subtree_max_frames frames, up to 16 x subtree_max_samples samples and a quarter of the
  // tree's samples per live worker (a level of few large tasks would leave workers idle).
  // Returns how many nodes were handed off; they leave *to_split.
  Result<size_t> HandOff(int level, std::span<const engine::OpenNode> frontier, uint64_t level_samples,
                         std::vector<size_t>* to_split) {
    level_handed.clear();
    level_largest_task = 0;
    level_task_messages = 0;
    if (params.subtree_max_samples > 0 && level > 0) {
      const uint64_t by_samples = params.subtree_max_samples;
      const uint64_t by_frames =
          params.subtree_max_frames > 0
              ? std::min(16 * by_samples, level_samples / (4 * uint64_t(std::max(1, AliveCount()))))
              : 0;
      std::vector<size_t> keep, ask, hand;
      for (size_t i : *to_split)
        (frontier[i].total() <= std::max(by_samples, by_frames) ? ask : keep).push_back(i);
      if (!ask.empty()) {
        std::vector<uint32_t> ids;
        std::vector<v1::NodeSpec> specs(ask.size());
        for (size_t q = 0; q < ask.size(); ++q) {
          ids.push_back(frontier[ask[q]].node);
          specs[q].set_num_samples(frontier[ask[q]].total());
          specs[q].set_position(frontier[ask[q]].position);
        }
        auto rf = Round(v1::PHASE_FRAMES, ids, specs, level);
        if (!rf.ok()) return rf.status();
        tasks.clear();
        subtree_load.clear();
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
          for (const Reply& r : *rf) {
            const v1::NodeRanges& nr = r.body.ranges(int(q));
            if (nr.num_samples() > 0) job.holders[r.sender] = nr.num_samples();
            held += nr.num_samples();
            job.frames.insert(job.frames.end(), nr.frames().begin(), nr.frames().end());
            uint64_t sum = 0;
            for (uint32_t c : nr.frame_samples()) sum += c;
            if (nr.frame_samples_size() != nr.frames_size() || sum != nr.num_samples() ||
                uint64_t(nr.pixel_deltas_size()) != sum) {
              if (nr.frame_samples_size() > 0 || nr.pixel_deltas_size() > 0)
                Log("FRAMES reply from " + r.sender + ", node " + std::to_string(f.node) + ": " +
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
            keep.push_back(ask[q]);  // too many frames to hand over: histogram rounds
            continue;
          }
          hand.push_back(ask[q]);
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
          tasks[f.position] = std::move(job);
        }
        // Largest first, each to the least loaded worker (SendTask): the level's subtree work
        // splits evenly however unequal the nodes are.
        std::vector<SubtreeJob*> order;
        for (auto& [pos, job] : tasks) order.push_back(&job);
        std::stable_sort(order.begin(), order.end(), [](const SubtreeJob* a, const SubtreeJob* b) {
          uint64_t na = 0, nb = 0;
          for (uint64_t c : a->parts) na += c;
          for (uint64_t c : b->parts) nb += c;
          return na > nb;
        });
        for (SubtreeJob* job : order) POSEFOREST_RETURN_IF_ERROR(SendTask(*job));
        POSEFOREST_RETURN_IF_ERROR(FlushTasks());
        std::sort(keep.begin(), keep.end());  // frontier order, as before
        to_split->swap(keep);
        return hand.size();
      }
    }
    return size_t(0);
  }

  /// The workers' shards as the frontier loop sees them: each pass is one request/reply Round
  /// over the assigned workers (lost workers' frames handed on, the round asked again), the
  /// replies merged here. Nothing is decided here: the loop (engine/frontier_loop.h) does that.
  struct RemoteShards final : engine::ShardSet {
    Impl& impl;
    int merge_threads;
    double hist_s = 0, merge_s = 0;  ///< of the current level: rounds, merging
    /// Set by the coordinator while it places a level's nodes: the decisions ApplySplits sends.
    v1::Envelope* decisions = nullptr;

    RemoteShards(Impl& i, int threads) : impl(i), merge_threads(threads) {}

    Status CountParts(uint32_t node, std::vector<uint64_t>* parts) override {
      if (node != 0) return Status(ErrorCode::kInternal, "remote census of a node other than the root");
      auto replies = impl.Round(v1::PHASE_COUNTS, {0}, {v1::NodeSpec{}}, 0);
      if (!replies.ok()) return replies.status();
      parts->assign(size_t(kParts), 0);
      for (const Reply& r : *replies)
        for (int p = 0; p < kParts; ++p) (*parts)[size_t(p)] += r.body.ranges(0).part_counts(p);
      return Status::Ok();
    }

    /// Ranges merged by min/max. A worker that holds every sample of a node whose reference
    /// subsample is the whole node builds it in one fused pass and returns its histogram and
    /// cuts right away.
    Status Ranges(int /*tree*/, int level, engine::Batch* batch, const engine::HistogramSink& sink) override {
      const engine::TrainParams& params = impl.params;
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
      auto r1 = impl.Round(v1::PHASE_RANGES, ids, specs, level);
      if (!r1.ok()) return r1.status();
      hist_s += proto::dds::NowSeconds() - t_ranges;
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
        plans[p].cuts.assign(size_t(k) * size_t(cut_stride), engine::kNoCut);
        int pos = 0;
        bool ok = r.body.nodes(int(p)).samples() == plans[p].num_samples;
        for (int c = 0; c < k && ok; ++c) {
          int64_t v = 0;
          for (uint32_t j = 0; j < nr.cut_counts(c); ++j) {
            const int32_t d = nr.cut_deltas(pos++);
            if (j > 0 && d <= 0) ok = false;
            v = j == 0 ? int64_t(d) : v + int64_t(d);
            if (v >= int64_t(engine::kNoCut)) ok = false;
            plans[p].cuts[size_t(c) * size_t(cut_stride) + j] = int32_t(v);
          }
        }
        engine::NodeHistogram hist;
        hist.Reset(plans[p].node, k, t_count + 1, plans[p].num_slots, false);
        if (ok) ok = engine::AddWireRuns(r.body.nodes(int(p)).runs(), dims, plans[p], &hist);
        if (!ok)
          return Status(ErrorCode::kDataLoss, "fused node " + std::to_string(plans[p].node) + " from " +
                                                  r.sender + " is inconsistent");
        sink(p, hist);
      }
      merge_s += proto::dds::NowSeconds() - t_merge;
      return Status::Ok();
    }

    /// Histograms summed, per node in parallel (independent, deterministic per node). A reply
    /// that counts a part absent from a node comes from a worker that disagrees with the
    /// coordinator: it is evicted and the round asked again without it.
    Status Histograms(int /*tree*/, int level, engine::Batch* batch, std::span<const size_t> which,
                      const engine::HistogramSink& sink) override {
      const engine::TrainParams& params = impl.params;
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
        auto r2 = impl.Round(v1::PHASE_HISTOGRAMS, ids2, specs2, level);
        if (!r2.ok()) return r2.status();
        hist_s += proto::dds::NowSeconds() - t_hist;
        const double t_merge = proto::dds::NowSeconds();
        const auto nq = int64_t(which.size());
        std::vector<std::string> bad(which.size());
        std::vector<uint64_t> got(which.size(), 0);
        std::exception_ptr merge_error;
#pragma omp parallel for num_threads(merge_threads) schedule(dynamic, 1)
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
        merge_s += proto::dds::NowSeconds() - t_merge;
        std::string culprit;
        for (const std::string& b : bad)
          if (!b.empty()) culprit = b;
        if (!culprit.empty() && attempt < 3) {
          impl.Log("histogram from " + culprit + " counts parts absent from a node");
          impl.MarkLost(culprit, "evicted");
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
    Status ApplySplits(std::span<const engine::SampleSet::Split> /*splits*/) override {
      if (!decisions) return Status(ErrorCode::kInternal, "no decisions to send");
      v1::SplitDecisions* dec = decisions->mutable_decisions();
      dec->set_epoch(++impl.epoch);
      impl.tree_decisions.push_back(*dec);
      return impl.Send(Topic::kControl, *decisions);
    }
  };

  Result<core::Tree> TrainTree(std::vector<engine::OpenNode> frontier, int first_level, int* levels_done) {
    engine::TreeAssembler assembler(kParts);
    POSEFOREST_RETURN_IF_ERROR(Replay(ckpt.current(), &assembler));
    split_of.clear();
    delegated.clear();
    tasks.clear();
    subtree_load.clear();
    for (const v1::LoggedLevel& lv : ckpt.current().levels())
      for (const v1::LoggedDecision& d : lv.decisions())
        if (d.split())
          split_of[d.position()] = {{int16_t(d.ux()), int16_t(d.uy()), int16_t(d.vx()), int16_t(d.vy())},
                                    d.cut()};
    for (const v1::SubtreeNode& n : ckpt.subtree_nodes()) delegated[n.position()] = FromProto(n);
    // Resumed after its last level, before the tree was filed as finished: nothing left to do.
    if (first_level > 0 && frontier.empty()) return assembler.Finish();
    // Shards: every frame of the tree over the live workers; replays of resumed levels included.
    for (auto& [id, w] : workers) w.assigned = false, w.frames.clear();
    orphan_frames.clear();
    POSEFOREST_RETURN_IF_ERROR(Distribute({{0, uint32_t(params.images_per_tree)}}));
    const int merge_threads = opt.merge_threads > 0 ? opt.merge_threads
                              : params.threads > 0  ? params.threads
                                                    : omp_get_max_threads();
    RemoteShards shards(*this, merge_threads);
    if (frontier.empty()) {
      // Census of the root.
      engine::OpenNode root;
      root.position = engine::kRootPosition;
      level_time = {};
      POSEFOREST_RETURN_IF_ERROR(shards.CountParts(0, &root.parts));
      // The census waits for every worker's shard: its frames rendered (summed over workers).
      char line[160];
      std::snprintf(line, sizeof line, "tree %d: shards ready in %.2f s (workers rendered %.2f s in all)", tree,
                    level_time.round_s, level_time.render_s);
      Log(line);
      if (root.total() == 0)
        return Status(ErrorCode::kInvalidArgument, "tree " + std::to_string(tree) +
                                                       ": no body pixels in any of its " +
                                                       std::to_string(params.images_per_tree) + " frames");
      frontier.push_back(std::move(root));
    }
    // Per level: what the hooks below share.
    double t_level = 0;
    uint64_t evaluations = 0, level_samples = 0;
    size_t handed_off = 0, from_subtrees = 0, frontier_size = 0, histogram_nodes = 0;
    double entropy_sum = 0, gain_sum = 0;  // for DistLevelStats
    v1::Envelope env;
    v1::LoggedLevel* logged = nullptr;
    engine::FrontierLoopHooks hooks;
    hooks.before_decide = [&](int level, std::span<const engine::OpenNode> level_nodes,
                              std::vector<size_t>* to_split) -> Status {
      if (!opt.pause_file.empty() && std::filesystem::exists(opt.pause_file)) {
        Log("paused (next: tree " + std::to_string(tree) + ", level " + std::to_string(level) + "); remove " +
            opt.pause_file + " to go on");
        while (std::filesystem::exists(opt.pause_file)) Pump(std::chrono::milliseconds(50), 0, nullptr);
        Log("resumed");
      }
      t_level = proto::dds::NowSeconds();
      level_bytes_received = level_bytes_sent = 0;
      level_retries = 0;
      level_subtree_evaluations = 0;
      level_time = {};
      shards.hist_s = shards.merge_s = 0;
      evaluations = level_samples = 0;
      from_subtrees = 0;
      entropy_sum = gain_sum = 0;
      frontier_size = level_nodes.size();
      for (const engine::OpenNode& f : level_nodes) level_samples += f.total();
      // Nodes of delegated subtrees are decided by their SubtreeResult.
      std::erase_if(*to_split, [&](size_t i) { return delegated.count(level_nodes[i].position) > 0; });
      if (opt.observer) {
        opt.observer->OnLevelStart(tree, level, level_nodes.size(), level_samples);
        opt.observer->OnNodesDecided(level_nodes.size() - to_split->size(), level_nodes.size());
      }
      handed_off = 0;
      auto handed = HandOff(level, level_nodes, level_samples, to_split);
      if (!handed.ok()) return handed.status();
      handed_off = *handed;
      histogram_nodes = to_split->size();
      return Status::Ok();
    };
    hooks.after_batch = [&](size_t decided, uint64_t /*batch_bytes*/) {
      if (opt.observer)
        opt.observer->OnNodesDecided(frontier_size - histogram_nodes - handed_off + decided, frontier_size);
    };
    hooks.after_decide = [&](int level) -> Status {
      if (!tasks.empty()) {
        const double t_wait = proto::dds::NowSeconds();
        POSEFOREST_RETURN_IF_ERROR(WaitSubtrees());
        shards.hist_s += proto::dds::NowSeconds() - t_wait;
        level_time.subtree_wait_s += proto::dds::NowSeconds() - t_wait;
        for (auto& [pos, job] : tasks)
          for (engine::SubtreeNode& n : job.nodes) delegated[n.position] = std::move(n);
        tasks.clear();
        subtree_load.clear();
        evaluations += level_subtree_evaluations;
        if (opt.observer) opt.observer->OnNodesDecided(frontier_size, frontier_size);
      }
      // Children in node order (breadth-first layout), decisions to the workers, the log.
      env.Clear();
      v1::SplitDecisions* dec = env.mutable_decisions();
      dec->set_tree(uint32_t(tree));
      dec->set_level(uint32_t(level));
      logged = ckpt.mutable_current()->add_levels();
      shards.decisions = &env;
      return Status::Ok();
    };
    hooks.place = [&](const engine::OpenNode& f, engine::NodeDecision& d) -> Result<uint32_t> {
      // One tree: a node's sample-node id is its breadth-first index, the assembler's.
      POSEFOREST_CHECK(f.node == f.local);
      if (d.tried) evaluations += d.evaluations;
      entropy_sum += engine::Entropy(f.parts) * double(f.total());
      auto* nd = env.mutable_decisions()->add_nodes();
      nd->set_node_id(f.node);
      v1::LoggedDecision* ld = logged->add_decisions();
      ld->set_node(f.node);
      ld->set_position(f.position);
      if (auto it = delegated.find(f.position); it != delegated.end()) {
        ld->set_delegated(true);
        // Decided by a worker that holds the whole subtree; the other workers drop their
        // samples of it (a delegated decision routes nothing).
        ++from_subtrees;
        nd->set_delegated(true);
        const engine::SubtreeNode s = std::move(it->second);
        delegated.erase(it);
        if (!std::equal(s.parts.begin(), s.parts.end(), f.parts.begin(), f.parts.end()))
          return Status(ErrorCode::kInternal, "subtree node " + std::to_string(f.position) + ": part counts");
        if (!s.split) {
          assembler.MakeLeaf(f.node, f.parts);
          for (uint64_t c : f.parts) ld->add_part_counts(c);
          return uint32_t(0);
        }
        gain_sum += s.gain;
        const uint32_t left = assembler.MakeSplit(f.node, s.offsets, s.cut);
        ld->set_split(true);
        ld->set_ux(s.offsets.ux), ld->set_uy(s.offsets.uy), ld->set_vx(s.offsets.vx),
            ld->set_vy(s.offsets.vy);
        ld->set_cut(s.cut);
        ld->set_left_child(left);
        split_of[f.position] = {s.offsets, s.cut};
        // The loop follows the worker's decision: children with the subtree's counts.
        d.split = true;
        d.offsets = s.offsets;
        d.choice.cut = s.cut;
        d.choice.left_parts = delegated.at(engine::LeftChildPosition(f.position)).parts;
        d.choice.right_parts = delegated.at(engine::RightChildPosition(f.position)).parts;
        return left;
      }
      if (!d.split) {
        assembler.MakeLeaf(f.node, f.parts);
        for (uint64_t c : f.parts) {
          nd->mutable_leaf()->add_part_counts(c);
          ld->add_part_counts(c);
        }
        return uint32_t(0);
      }
      const engine::SplitChoice& c = d.choice;
      gain_sum += c.gain;
      const uint32_t left = assembler.MakeSplit(f.node, d.offsets, c.cut);
      engine::SetFeatureSplit(d.offsets, c.cut, left, uint32_t(c.candidate), nd->mutable_split());
      ld->set_split(true);
      ld->set_ux(d.offsets.ux), ld->set_uy(d.offsets.uy), ld->set_vx(d.offsets.vx), ld->set_vy(d.offsets.vy);
      ld->set_cut(c.cut);
      ld->set_left_child(left);
      split_of[f.position] = {d.offsets, c.cut};
      return left;
    };
    hooks.level_done = [&](const engine::LevelDone& done) -> Status {
      shards.decisions = nullptr;
      ckpt.clear_frontier();
      for (const engine::OpenNode& f : done.next) {
        auto* fe = ckpt.add_frontier();
        fe->set_node(f.node);
        fe->set_position(f.position);
        for (uint64_t c : f.parts) fe->add_part_counts(c);
      }
      // Every task of this level is in, so the subtrees' remaining decisions are all known.
      ckpt.clear_subtree_nodes();
      for (const auto& [pos, n] : delegated) ToProto(n, ckpt.add_subtree_nodes());
      POSEFOREST_RETURN_IF_ERROR(SaveCheckpoint());
      DistLevelStats st;
      st.tree = tree;
      st.level = done.level;
      st.frontier_nodes = done.frontier_nodes;
      st.split_nodes = done.split_nodes;
      st.samples = done.samples;
      st.evaluations = evaluations;
      st.evaluations_per_s = shards.hist_s > 0 ? double(evaluations) / shards.hist_s : 0;
      st.workers_alive = AliveCount();
      for (const auto& [id, w] : workers) st.workers_assigned += w.alive && w.assigned;
      st.bytes_received = level_bytes_received;
      st.bytes_sent = level_bytes_sent;
      st.merge_seconds = shards.merge_s;
      st.level_seconds = proto::dds::NowSeconds() - t_level;
      st.elapsed_s = proto::dds::NowSeconds() - start;
      st.retries = level_retries;
      st.subtree_tasks = handed_off;
      st.subtree_nodes = from_subtrees;
      for (const auto& [id, n] : level_handed)
        st.subtree_samples += n, st.subtree_samples_busiest = std::max(st.subtree_samples_busiest, n);
      st.subtree_largest_task = level_largest_task;
      st.subtree_task_messages = level_task_messages;
      st.mean_entropy = done.samples > 0 ? entropy_sum / double(done.samples) : 0;
      st.mean_gain = done.split_nodes > 0 ? gain_sum / double(done.split_nodes) : 0;
      st.rounds = level_time.rounds;
      st.round_seconds = level_time.round_s;
      st.round_compute_seconds = level_time.compute_s;
      st.round_queued_seconds = level_time.queued_s;
      st.round_traffic_seconds = level_time.traffic_s;
      st.subtree_wait_seconds = level_time.subtree_wait_s;
      st.subtree_busy_seconds = level_time.subtree_busy_s;
      st.render_seconds = level_time.render_s;
      if (opt.progress) opt.progress(st);
      if (opt.observer) opt.observer->OnLevelDone(st);
      const double progress =
          (double(tree) + std::min(1.0, double(done.level + 1) / double(params.max_depth + 1))) /
          double(params.num_trees);
      PublishStatus(v1::STATUS_KIND_LEVEL_DONE, "level done", "", done.level, progress);
      last_progress = progress;
      ++*levels_done;
      if (opt.stop_after_levels >= 0 && *levels_done >= opt.stop_after_levels)
        return Status(ErrorCode::kInternal,
                      "stopped after " + std::to_string(*levels_done) + " levels (test hook)");
      return Status::Ok();
    };
    POSEFOREST_RETURN_IF_ERROR(engine::RunFrontierLoop(
        shards, params, tree, first_level, std::move(frontier), uint32_t(assembler.num_nodes()),
        std::min(params.histogram_memory_bytes, opt.max_batch_bytes), hooks));
    return assembler.Finish();
  }

  Result<core::Forest> Train() {
    start = proto::dds::NowSeconds();
    std::string config_bytes;
    config.SerializeToString(&config_bytes);
    if (job_id.empty()) job_id = engine::DefaultJobId(config);
    // A fresh sender id per run: a restarted coordinator is a new sender (sequence numbers
    // restart), and workers take its announcement as "start over".
    char host[128] = {};
    ::gethostname(host, sizeof host - 1);
    self_id = "coordinator-" + std::string(host) + "-" + std::to_string(::getpid()) + "-" +
              std::to_string(uint64_t(proto::dds::NowSeconds() * 1e6) & 0xFFFFFF);
    stamper = proto::dds::EnvelopeStamper(job_id, self_id, v1::SENDER_KIND_COORDINATOR);
    gate = std::make_unique<proto::dds::MessageGate>(proto::dds::GateConfig{self_id, job_id, 16, opt.log});
    gate->set_num_parts(uint32_t(kParts));

    // The forest's header (constants, parts, training focal length), recorded in the checkpoint
    // so `poseforest export` writes the same one on a machine without the job's files.
    auto shell = engine::EmptyForest(params);
    if (!shell.ok()) return shell.status();
    // Resume.
    std::vector<core::Tree> trees;
    std::vector<engine::OpenNode> frontier;
    int first_level = 0;
    ckpt.Clear();
    ckpt.set_format(kCheckpointFormat);
    ckpt.set_job_id(job_id);
    ckpt.set_config(config_bytes);
    ckpt.set_training_fx(shell->training_fx);
    ckpt.set_training_fy(shell->training_fy);
    const std::string ckpt_path =
        opt.checkpoint_dir.empty() ? ""
                                   : (std::filesystem::path(opt.checkpoint_dir) / "checkpoint.pb").string();
    if (opt.resume && !ckpt_path.empty() && std::filesystem::exists(ckpt_path)) {
      std::ifstream in(ckpt_path, std::ios::binary);
      std::stringstream ss;
      ss << in.rdbuf();
      v1::Checkpoint saved;
      if (!saved.ParseFromString(ss.str()) || saved.format() == 0)
        return Status(ErrorCode::kDataLoss, ckpt_path + ": not a checkpoint");
      if (saved.format() != kCheckpointFormat)
        return Status(ErrorCode::kVersionMismatch,
                      ckpt_path + ": checkpoint format " + std::to_string(saved.format()) +
                          ", this coordinator reads " + std::to_string(kCheckpointFormat));
      if (saved.config() != config_bytes || saved.job_id() != job_id)
        return Status(ErrorCode::kInvalidArgument, ckpt_path + ": checkpoint of another job");
      for (const v1::LoggedTree& lt : saved.finished()) {
        engine::TreeAssembler a(kParts);
        POSEFOREST_RETURN_IF_ERROR(Replay(lt, &a));
        trees.push_back(a.Finish());
      }
      for (const v1::FrontierEntry& fe : saved.frontier()) {
        if (fe.part_counts_size() != kParts) return Status(ErrorCode::kDataLoss, ckpt_path + ": frontier");
        // Every frontier node sits at depth first_level; node ids are breadth-first indices.
        frontier.push_back({fe.node(), fe.position(), engine::PositionDepth(fe.position()),
                            std::vector<uint64_t>(fe.part_counts().begin(), fe.part_counts().end()), 0,
                            fe.node()});
      }
      first_level = saved.current().levels_size();
      epoch = saved.epoch();
      ckpt = saved;
      if (ckpt.training_fx() == 0) ckpt.set_training_fx(shell->training_fx), ckpt.set_training_fy(shell->training_fy);
      Log("resuming " + job_id + " at tree " + std::to_string(trees.size()) + " level " +
          std::to_string(first_level));
    }

    proto::dds::NodeConfig node_config =
        proto::dds::MakeNodeConfig(opt.domain, opt.transport, true, self_id, opt.lease, opt.udp_peers,
                                   opt.udp_interfaces, opt.transport_extras);
    node_config.log = opt.log;
    auto n = proto::dds::DdsNode::Create(node_config);
    if (!n.ok()) return n.status();
    node = std::move(*n);
    v1::Envelope job_env;
    auto* job = job_env.mutable_job();
    *job->mutable_config() = config;
    job->set_coordinator_id(self_id);
    job->set_num_parts(uint32_t(kParts));
    job->set_thresholds_per_feature(uint32_t(params.thresholds_per_feature + 1));
    job_announcement = job_env;
    POSEFOREST_RETURN_IF_ERROR(Send(Topic::kJob, job_env));
    Log("announced " + job_id + " as " + self_id + " on domain " + std::to_string(opt.domain) + ": " +
        engine::DescribeParams(params));
    PublishStatus(v1::STATUS_KIND_JOB_STARTED, engine::DescribeParams(params));
    POSEFOREST_RETURN_IF_ERROR(WaitForWorkers(std::max(1, opt.min_workers)));

    int levels_done = 0;
    for (int t = int(trees.size()); t < params.num_trees; ++t) {
      tree = t;
      tree_decisions.clear();
      if (size_t(t) < opt.min_workers_per_tree.size())
        POSEFOREST_RETURN_IF_ERROR(WaitForWorkers(opt.min_workers_per_tree[size_t(t)]));
      // Replays of a resumed tree's levels: rebuild the decisions from the log.
      for (const v1::LoggedLevel& lv : ckpt.current().levels()) {
        v1::SplitDecisions d;
        d.set_tree(uint32_t(t));
        d.set_level(uint32_t(tree_decisions.size()));
        for (const v1::LoggedDecision& ld : lv.decisions()) {
          auto* nd = d.add_nodes();
          nd->set_node_id(ld.node());
          if (ld.delegated())
            nd->set_delegated(true);
          else if (ld.split())
            engine::SetFeatureSplit({int16_t(ld.ux()), int16_t(ld.uy()), int16_t(ld.vx()), int16_t(ld.vy())},
                                    ld.cut(), ld.left_child(), 0, nd->mutable_split());
          else
            for (uint64_t c : ld.part_counts()) nd->mutable_leaf()->add_part_counts(c);
        }
        tree_decisions.push_back(std::move(d));
      }
      auto tr = TrainTree(std::move(frontier), first_level, &levels_done);
      if (!tr.ok()) {
        PublishStatus(v1::STATUS_KIND_ERROR, tr.status().ToString());
        return tr.status();
      }
      trees.push_back(std::move(*tr));
      frontier.clear();
      first_level = 0;
      *ckpt.add_finished() = ckpt.current();
      ckpt.clear_current();
      ckpt.clear_subtree_nodes();
      ckpt.clear_frontier();
      ckpt.set_tree(uint32_t(t + 1));
      POSEFOREST_RETURN_IF_ERROR(SaveCheckpoint());
      last_progress = double(t + 1) / params.num_trees;
      PublishStatus(v1::STATUS_KIND_TREE_DONE, "tree done", "", 0, last_progress);
    }
    core::Forest forest = *shell;
    forest.trees = std::move(trees);
    POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(forest, "trained forest"));
    PublishStatus(v1::STATUS_KIND_JOB_DONE, "job done", "", 0, 1.0);
    (void)node->WaitForAcknowledgments(Topic::kStatus, std::chrono::milliseconds(2000));
    return forest;
  }
};

DistCoordinator::DistCoordinator(v1::TrainerConfig config, engine::TrainParams params,
                                 CoordinatorOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->config = std::move(config);
  impl_->params = std::move(params);
  impl_->opt = std::move(options);
  impl_->job_id = impl_->opt.job_id;
  if (!impl_->opt.log)
    impl_->opt.log = [](const std::string& m) { std::fprintf(stderr, "[coordinator] %s\n", m.c_str()); };
}

DistCoordinator::~DistCoordinator() = default;

Result<core::Forest> DistCoordinator::Train() { return impl_->Train(); }
const std::string& DistCoordinator::job_id() const { return impl_->job_id; }
uint64_t DistCoordinator::bytes_received() const { return impl_->total_bytes_received; }
uint64_t DistCoordinator::rejected_messages() const {
  return (impl_->gate ? impl_->gate->total_rejected() : 0) + impl_->subtree_rejected;
}
int DistCoordinator::workers_lost() const { return impl_->lost_count; }
uint64_t DistCoordinator::stale_messages() const { return impl_->stale_count; }

}  // namespace poseforest::coordinator
