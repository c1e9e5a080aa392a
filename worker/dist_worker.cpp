#include "worker/dist_worker.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <deque>
#include <optional>
#include <thread>

#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/build_id.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"
#include "worker/context.h"
#include "worker/intake.h"
#include "worker/shard_server.h"
#include "worker/subtree_runner.h"
#include "worker/task_frame_cache.h"

namespace poseforest::worker {

using core::ErrorCode;
using core::Status;
using proto::dds::Topic;

namespace {
v1::RendererKind RendererOf(const engine::TrainParams& p) {
  switch (p.source.kind) {
    case engine::SourceKind::kRendered:
      return v1::RENDERER_KIND_EGL;
    case engine::SourceKind::kDataset:
      return v1::RENDERER_KIND_DATASET;
    case engine::SourceKind::kProcedural:
      return v1::RENDERER_KIND_PROCEDURAL;
  }
  return v1::RENDERER_KIND_PROCEDURAL;
}
}  // namespace

/// Run()'s state: the parts of the worker (context.h) and the dispatch of every message, on
/// Run()'s thread; the heartbeats on a thread of their own.
struct DistWorker::Impl {
  Context ctx;
  Intake intake{ctx};
  ShardServer shard{ctx};
  TaskFrames task_frames{ctx};
  SubtreeRunner subtrees{ctx, shard, task_frames, [this] { PauseInSubtrees(); }};

  proto::dds::MessageGate job_gate;
  std::unique_ptr<proto::dds::MessageGate> gate;
  /// This build's identity (proto/dds/build_id.h): in hellos, and compared with the job's.
  const std::string build_id = ctx.opt.build_id.empty() ? proto::dds::BuildId() : ctx.opt.build_id;
  std::string last_refused;  ///< job id and reason of the last refusal logged (Refuse)
  /// Decisions and level requests below this epoch belong to a skipped assignment (Dispatch).
  uint64_t skip_below_epoch = 0;
  std::string control_writer;  ///< the coordinator's control writer (GUID), once heard
  std::string coordinator_participant;  ///< the job's coordinator's DDS participant (GUID prefix)
  /// Our participant was replaced since we last joined a coordinator (OnDdsEvent, OnJob).
  bool participant_fresh = false;
  /// When the job's coordinator's participant was lost (0: not waiting for a new one), and when
  /// our participant was last replaced since (RetryParticipant).
  double coordinator_lost_s = 0, replaced_s = 0;

  /// Messages taken off DDS while collecting a batch of SubtreeTasks, handled next (in order).
  struct Pending {
    bool checked = false;  ///< passed the gate: env/sender; else a raw sample for OnSample
    proto::dds::ReceivedSample raw;
    v1::Envelope env;
    std::string sender;
    double received_s = 0;  ///< when `env` was taken off DDS (checked ones)
  };
  std::deque<Pending> pending;

  Impl(WorkerOptions& o, std::atomic<bool>& s, DistWorker::Live& l)
      : ctx(o, s, l), job_gate(proto::dds::GateConfig{o.worker_id, "", 16, o.log}) {}

  void Log(const std::string& m) { ctx.Log(m); }

  v1::WorkerCapacity Capacity() const {
    v1::WorkerCapacity c;
    c.set_threads(uint32_t(std::max(1, ctx.opt.threads)));
    c.set_memory_mb(1024);
    c.set_renderer(ctx.renderer);
    return c;
  }

  v1::WorkerHello* FillHello(v1::WorkerHello* h) {
    *h->mutable_capacity() = Capacity();
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    h->set_hostname(host);
    h->set_pid(uint32_t(::getpid()));
    h->set_build_version(build_id);
    return h;
  }

  /// Refuses the job of `env` (not for this worker's build or host): logs why and sends it to
  /// the coordinator in hellos until a job is taken (HeartbeatLoop).
  void Refuse(const v1::Envelope& env, const std::string& why) {
    // The coordinator announces a job every 2 s while it waits for workers: said once.
    if (last_refused != env.job_id() + "\n" + why) Log("job " + env.job_id() + " refused: " + why);
    last_refused = env.job_id() + "\n" + why;
    if (ctx.has_job) return;  // busy with another job: its envelopes keep that job's id
    std::lock_guard<std::mutex> lock(ctx.send_mu);
    // At most 2,000 bytes (the gate takes 2,048), cut on a UTF-8 character boundary: the wire's
    // string must stay valid UTF-8 (a path may hold any character).
    size_t end = std::min<size_t>(why.size(), 2000);
    while (end < why.size() && end > 0 && (static_cast<unsigned char>(why[end]) & 0xC0) == 0x80) --end;
    ctx.refusal = why.substr(0, end);
    ctx.stamper.set_job_id(env.job_id());
  }

  void HeartbeatLoop() {
    // (time, evaluations): the rate over the last ~10 s, from the start (work done before the
    // first heartbeat counts).
    std::deque<std::pair<double, uint64_t>> recent{{proto::dds::NowSeconds(), ctx.evaluations.load()}};
    while (!ctx.stop && !ctx.node_restart) {
      if (!ctx.has_job) {
        // A refused job: hellos that say why, for the coordinator to report.
        v1::Envelope env;
        {
          std::lock_guard<std::mutex> lock(ctx.send_mu);
          if (!ctx.refusal.empty()) FillHello(env.mutable_hello())->set_refusal(ctx.refusal);
        }
        if (env.has_hello()) (void)ctx.Publish(Topic::kPresence, env, /*timed=*/false);
      } else {
        v1::Envelope env;
        if (!ctx.assigned_any) {
          FillHello(env.mutable_hello());
        } else {
          auto* h = env.mutable_heartbeat();
          *h->mutable_capacity() = Capacity();
          h->set_busy_threads(ctx.busy ? uint32_t(std::max(1, ctx.opt.threads)) : 0);
          h->set_epoch(ctx.newest_epoch);
          h->set_frames_rendered(ctx.frames_rendered);
          h->set_shard_epoch(ctx.shard_epoch);
          h->set_received_shard_epoch(ctx.received_shard_epoch);
          const double now = proto::dds::NowSeconds();
          const uint64_t e = ctx.evaluations;
          recent.emplace_back(now, e);
          while (recent.size() > 2 && now - recent[1].first >= 10) recent.pop_front();
          const double span = now - recent.front().first;
          h->set_evaluations(e);
          h->set_evaluations_per_s(span > 0 ? double(e - recent.front().second) / span : 0);
          h->set_task_tree(task_frames.tree);
          h->set_task_frames_rendered(task_frames.tree_rendered);
          h->set_task_frames_cached(task_frames.tree_cached);
          h->set_task_cache_evictions(task_frames.tree_evictions);
        }
        (void)ctx.Publish(Topic::kPresence, env, /*timed=*/false);
      }
      std::this_thread::sleep_for(ctx.opt.heartbeat_period);
    }
  }

  void OnJob(const v1::Envelope& env) {
    const WorkerOptions& opt = ctx.opt;
    const auto& job = env.job();
    if (!opt.job_id.empty() && env.job_id() != opt.job_id) return;
    if (ctx.has_job && env.job_id() == ctx.job_id && job.coordinator_id() == ctx.coordinator_id) return;
    if (!job.build_id().empty() && job.build_id() != build_id) {
      Refuse(env, "the coordinator runs build \"" + job.build_id() + "\", this worker \"" + build_id +
                      "\": run the same build on every host (a different build may render and split "
                      "differently, so the forest would depend on which worker took which frames), or set "
                      "POSEFOREST_BUILD_ID to the same value on every host to train with builds known to "
                      "train alike");
      return;
    }
    auto p = engine::ParamsFromConfig(job.config(), "job " + env.job_id());
    if (!p.ok()) {
      Refuse(env, p.status().ToString());
      return;
    }
    if (job.num_parts() != uint32_t(core::kNumParts)) {
      Refuse(env,
             std::to_string(job.num_parts()) + " parts, this build has " + std::to_string(core::kNumParts));
      return;
    }
    // A restarted coordinator: joined, and our participant replaced right after (see
    // OnDdsEvent), unless that was done when the old one's lease ran out.
    const bool replace =
        ctx.has_job && job.coordinator_id() != ctx.coordinator_id && !participant_fresh && SharedMemory();
    // A new job, or a restarted coordinator: start from scratch.
    ctx.params = std::move(*p);
    ctx.params.threads = std::max(1, opt.threads);
    ctx.job_id = env.job_id();
    ctx.coordinator_id = job.coordinator_id();
    gate = std::make_unique<proto::dds::MessageGate>(proto::dds::GateConfig{opt.worker_id, ctx.job_id, 16, opt.log});
    gate->set_coordinator_id(ctx.coordinator_id);
    gate->set_num_parts(uint32_t(core::kNumParts));
    shard.StartJob();
    task_frames.StartJob();
    subtrees.StartJob();
    ctx.renderer = RendererOf(ctx.params);
    {
      std::lock_guard<std::mutex> lock(ctx.send_mu);
      ctx.stamper.set_job_id(ctx.job_id);
      ctx.refusal.clear();
    }
    {
      std::lock_guard<std::mutex> lock(ctx.live.mu);
      ctx.live.job_id = ctx.job_id;
      ctx.live.coordinator_id = ctx.coordinator_id;
    }
    ctx.live.cache_capacity = task_frames.cache().cap_bytes;
    ctx.live.cache_bytes = 0;
    ctx.assigned_any = false;
    ctx.shard_epoch = 0;
    ctx.received_shard_epoch = 0;
    skip_below_epoch = 0;
    control_writer.clear();
    ctx.has_job = true;
    participant_fresh = false;
    coordinator_lost_s = 0;  // a coordinator heard
    Log("joined job " + ctx.job_id + " of " + ctx.coordinator_id + ": " + engine::DescribeParams(ctx.params));
    if (replace) {
      Log("the job's coordinator was restarted: starting a new DDS participant (fresh shared-memory ports)");
      ReplaceParticipant();
    }
  }

  /// Called by a subtree batch between its histogram batches and levels: answers the level
  /// requests (and applies the decisions) of this worker's shard that are queued at the front,
  /// so the coordinator's rounds do not wait for the whole batch (in a 2,000-image run,
  /// rounds waited 883 of 1,917 s for workers busy in subtree batches). Only those: the
  /// first other message (an assignment, a task, a job) stops it and waits its turn in `pending`.
  /// The batch uses its own sample set and histogram builder, so answering from the shard's set
  /// with the shard's builder is safe here; the answers and the subtrees are what they would be
  /// in order.
  void PauseInSubtrees() {
    if (ctx.opt.in_subtree_batch) ctx.opt.in_subtree_batch();
    ServeRounds();
  }

  /// Whether `env` is a round of the shard held now (ServeRounds answers those in a batch).
  bool IsRound(const v1::Envelope& env) const {
    if (!shard.have_shard()) return false;
    if (env.body_case() == v1::Envelope::kLevelRequest)
      return int(env.level_request().tree()) == shard.tree() && env.level_request().epoch() >= skip_below_epoch;
    if (env.body_case() == v1::Envelope::kDecisions)
      return int(env.decisions().tree()) == shard.tree() && env.decisions().epoch() >= skip_below_epoch;
    return false;
  }

  void ServeRounds() {
    const double t_serve = proto::dds::NowSeconds(), cpu_serve = ThreadCpu();
    const bool was_busy = ctx.busy;
    int served = 0;
    for (;;) {
      if (!pending.empty()) {
        if (!pending.front().checked || !IsRound(pending.front().env)) break;
        Pending p = std::move(pending.front());
        pending.pop_front();
        ctx.dispatch_received_s = p.received_s;
        Dispatch(p.env, p.sender);
        ++served;
        continue;
      }
      std::optional<proto::dds::ReceivedSample> s = intake.Take(std::chrono::milliseconds(0));
      if (!s) break;
      if (s->topic == Topic::kJob || !gate) {
        pending.push_back({false, std::move(*s), {}, {}, 0});
        break;
      }
      auto out = gate->Check(s->topic, s->bytes, s->writer_guid);
      ctx.CountDropped(out);
      if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) continue;
      if (!IsRound(out.envelope)) {
        pending.push_back({true, {}, std::move(out.envelope), std::move(out.sender), s->received_s});
        break;
      }
      ctx.dispatch_received_s = s->received_s;
      Dispatch(out.envelope, out.sender);
      ++served;
    }
    ctx.busy = was_busy;
    if (served == 0) return;
    ++ctx.cpu.rounds_in_batches;
    subtrees.AddServedSeconds(proto::dds::NowSeconds() - t_serve);
    // The subtree_train timer around the batch counts this thread's CPU; the answers counted
    // theirs in their own phases.
    ctx.cpu.subtree_train -= ThreadCpu() - cpu_serve;
  }

  /// Shared memory among our transports (the profiles shm and default).
  bool SharedMemory() const {
    const auto t = ctx.opt.transport;
    return t == proto::dds::TransportKind::kSharedMemoryOnly || t == proto::dds::TransportKind::kDefault;
  }

  /// Asks Run() for a new DDS participant (between messages).
  void ReplaceParticipant() {
    ctx.node_restart = true;
    participant_fresh = true;
  }

  /// The job's coordinator's participant gone (it exited, or its lease ran out: killed) on a
  /// transport with shared memory: the participant is replaced. Fast DDS 2.9 keeps the
  /// shared-memory port it opened to a peer after the peer is gone. A coordinator restarted on
  /// this host may take the dead one's participant id, and so its port numbers, and open a new
  /// segment under that name (the old one failed its health check): our messages would still go
  /// into the old segment, and the restarted coordinator would wait for workers it never hears
  /// ("0 of N workers", seen in CI after `coordinator --resume`). A new participant opens every
  /// port afresh. (A coordinator restarted before the lease runs out: OnJob.)
  void OnDdsEvent(const proto::dds::DdsEvent& e) {
    if (e.kind != proto::dds::DdsEvent::Kind::kParticipantLost || coordinator_participant.empty() ||
        e.peer_participant != coordinator_participant || !SharedMemory())
      return;
    coordinator_participant.clear();
    Log("the coordinator's DDS participant is gone: starting a new participant (fresh shared-memory ports)");
    ReplaceParticipant();
    coordinator_lost_s = replaced_s = proto::dds::NowSeconds();
  }

  /// Still no coordinator kRetryS after the replacement above: another new participant, every
  /// kRetryS until a coordinator's job arrives. A participant made while the dead coordinator's
  /// ports were still on the host opens those stale segments; a coordinator restarted on this
  /// host then replaces them under the same names and never hears us (CI, 28 Nov 2026: "0 of 2
  /// workers after 60000 ms" with the coordinator restarted after both workers had replaced
  /// their participants). The next participant opens the restarted coordinator's segments.
  void RetryParticipant() {
    static constexpr double kRetryS = 15.0;
    if (coordinator_lost_s == 0 || ctx.node_restart || !SharedMemory()) return;
    const double now = proto::dds::NowSeconds();
    if (now - replaced_s < kRetryS) return;
    char waited[32];
    std::snprintf(waited, sizeof waited, "%.0f", now - coordinator_lost_s);
    Log(std::string("no coordinator heard ") + waited +
        " s after its participant was lost: starting a new DDS participant again");
    ReplaceParticipant();
    replaced_s = now;
  }

  void OnSample(const proto::dds::ReceivedSample& s) {
    if (s.topic == Topic::kJob) {
      auto out = job_gate.Check(s.topic, s.bytes, s.writer_guid);
      ctx.CountDropped(out);
      if (out.verdict == proto::dds::MessageGate::Verdict::kAccepted) {
        OnJob(out.envelope);
        if (ctx.has_job && out.envelope.job().coordinator_id() == ctx.coordinator_id)
          coordinator_participant = s.writer_participant;
      }
      return;
    }
    if (!gate) return;
    std::optional<CpuTimer> gate_timer(&ctx.cpu.receive);
    auto out = gate->Check(s.topic, s.bytes, s.writer_guid);
    gate_timer.reset();
    ctx.CountDropped(out);
    if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) return;
    if (s.topic == Topic::kControl && out.sender == ctx.coordinator_id) control_writer = s.writer_guid;
    if (out.sender == ctx.coordinator_id) {
      coordinator_participant = s.writer_participant;
      coordinator_lost_s = 0;  // it is back (a partition that healed)
    }
    ctx.dispatch_received_s = s.received_s;
    Dispatch(out.envelope, out.sender);
  }

  /// After a SubtreeTask with a sample list: the tasks queued right behind it (the coordinator
  /// sends a level's tasks in one burst) of the same tree, also listed, join `batch`; the first
  /// other message is kept in `pending`. False: the test hook says die.
  bool DrainTasks(std::vector<v1::Envelope>* batch) {
    const WorkerOptions& opt = ctx.opt;
    for (;;) {
      std::optional<proto::dds::ReceivedSample> more;
      {
        CpuTimer timer(&ctx.cpu.receive);
        more = intake.Take(std::chrono::milliseconds(0));
      }
      if (!more) return true;
      if (more->topic == Topic::kJob) {
        pending.push_back({false, std::move(*more), {}, {}, 0});
        return true;
      }
      std::optional<CpuTimer> gate_timer(&ctx.cpu.receive);
      auto out = gate->Check(more->topic, more->bytes, more->writer_guid);
      gate_timer.reset();
      ctx.CountDropped(out);
      if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) continue;
      if (out.envelope.body_case() == v1::Envelope::kSubtreeTask &&
          out.envelope.subtree_task().tree() == batch->front().subtree_task().tree() &&
          SubtreeRunner::Listed(out.envelope.subtree_task())) {
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) return false;
        batch->push_back(std::move(out.envelope));
        continue;
      }
      if (out.envelope.body_case() == v1::Envelope::kSubtreeTasks &&
          out.envelope.subtree_tasks().tasks(0).tree() == batch->front().subtree_task().tree() &&
          std::all_of(out.envelope.subtree_tasks().tasks().begin(), out.envelope.subtree_tasks().tasks().end(),
                      SubtreeRunner::Listed)) {
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) return false;
        for (const v1::SubtreeTask& task : out.envelope.subtree_tasks().tasks())
          *batch->emplace_back().mutable_subtree_task() = task;
        continue;
      }
      pending.push_back({true, {}, std::move(out.envelope), std::move(out.sender), more->received_s});
      return true;
    }
  }

  /// A ShardAssignment: loaded, unless a newer one for this worker is already queued.
  Status OnShard(const v1::ShardAssignment& s) {
    if (ctx.opt.hold_before_shard) ctx.opt.hold_before_shard();
    const uint64_t e = s.epoch();
    ctx.newest_epoch = std::max<uint64_t>(ctx.newest_epoch, e);
    ctx.received_shard_epoch = std::max<uint64_t>(ctx.received_shard_epoch, e);
    ctx.assigned_any = true;  // heartbeats (with the epochs) from now on, also while it loads
    // A newer assignment for us already queued (the coordinator sent it again while we were
    // busy): load that one only. Loading each in turn, slower than the coordinator re-sent
    // them, livelocked a 2,000-image run. The decisions replayed and the
    // level requests between the two are obsolete: the newer one is followed by its own.
    if (const uint64_t newer = intake.NewerQueuedShard(control_writer, e); newer > 0) {
      skip_below_epoch = std::max(skip_below_epoch, newer);
      ++ctx.cpu.shards_skipped;
      Log("assignment of epoch " + std::to_string(e) + " skipped: epoch " + std::to_string(newer) + " is queued");
      return Status::Ok();
    }
    Status st = shard.Load(s);
    if (st.ok()) ctx.shard_epoch = e;
    return st;
  }

  /// SubtreeTask(s) in `env`: those with sample lists train together (one SampleSet), with any
  /// listed tasks queued right behind; a task without a list (the coordinator routes none today)
  /// alone. False: the test hook says die.
  bool OnSubtreeTasks(const v1::Envelope& env, const std::string& sender, Status* st) {
    if (ctx.opt.die_on_subtree_task && ctx.opt.die_on_subtree_task()) {
      Log(env.body_case() == v1::Envelope::kSubtreeTask ? "test hook: dying with a subtree task"
                                                         : "test hook: dying with subtree tasks");
      return false;
    }
    if (ctx.opt.hold_on_subtree_task) ctx.opt.hold_on_subtree_task();
    std::vector<v1::Envelope> batch;
    if (env.body_case() == v1::Envelope::kSubtreeTask) {
      if (!SubtreeRunner::Listed(env.subtree_task())) {
        *st = subtrees.Run(env.subtree_task());
        return true;
      }
      batch.push_back(env);
    } else {
      for (const v1::SubtreeTask& task : env.subtree_tasks().tasks()) {
        if (SubtreeRunner::Listed(task)) {
          *batch.emplace_back().mutable_subtree_task() = task;
        } else if (Status one = subtrees.Run(task); !one.ok()) {
          Log("dropped SubtreeTask (position " + std::to_string(task.position()) + ") from " + sender + ": " +
              one.ToString());
        }
      }
      if (batch.empty()) return true;
    }
    if (!DrainTasks(&batch)) {
      Log("test hook: dying with subtree tasks");
      return false;
    }
    if (batch.size() > 1)
      subtrees.RunBatch(batch, sender);
    else
      *st = subtrees.Run(batch.front().subtree_task());
    return true;
  }

  void Dispatch(const v1::Envelope& env, const std::string& sender) {
    Status st;
    switch (env.body_case()) {
      case v1::Envelope::kShard:
        st = OnShard(env.shard());
        break;
      case v1::Envelope::kDecisions:
        if (env.decisions().epoch() < skip_below_epoch) break;  // replayed for a skipped assignment
        if (shard.have_shard() && int(env.decisions().tree()) == shard.tree()) st = shard.Apply(env.decisions());
        break;
      case v1::Envelope::kLevelRequest:
        ctx.newest_epoch = std::max<uint64_t>(ctx.newest_epoch, env.level_request().epoch());
        if (env.level_request().epoch() < skip_below_epoch) break;  // asked again after the newer one
        if (shard.have_shard() && int(env.level_request().tree()) == shard.tree())
          st = shard.Answer(env.level_request());
        break;
      case v1::Envelope::kSubtreeTask:
      case v1::Envelope::kSubtreeTasks:
        if (!OnSubtreeTasks(env, sender, &st)) {
          ctx.stop = true;
          return;
        }
        break;
      case v1::Envelope::kStatus:
        if (env.status().kind() == v1::STATUS_KIND_JOB_DONE && ctx.opt.exit_when_done) {
          Log("job " + ctx.job_id + " done");
          ctx.stop = true;
        }
        break;
      default:
        break;
    }
    if (!st.ok())
      Log(std::string("dropped ") + proto::dds::BodyName(env.body_case()) + " from " + sender + ": " +
          st.ToString());
  }
};

DistWorker::DistWorker(WorkerOptions options)
    : options_(std::move(options)), live_(std::make_unique<Live>()) {
  if (options_.worker_id.empty()) options_.worker_id = proto::dds::DefaultWorkerId();
  if (!options_.log) {
    const std::string id = options_.worker_id;
    options_.log = [id](const std::string& m) { std::fprintf(stderr, "[%s] %s\n", id.c_str(), m.c_str()); };
  }
  options_.threads = std::max(1, options_.threads);
}

DistWorker::~DistWorker() = default;

Status DistWorker::Run() {
  const double process0 = ProcessCpu();
  live_->busy = false;
  live_->stopped = false;
  struct Stopped {
    std::atomic<bool>& stopped;
    ~Stopped() { stopped = true; }
  } stopped_at_return{live_->stopped};
  Impl impl(options_, stop_, *live_);
  impl.ctx.cpu.process_at_start = process0;
  std::optional<CpuTimer> participant_timer(&impl.ctx.cpu.participant);
  proto::dds::NodeConfig node_config = proto::dds::MakeNodeConfig(
      options_.domain, options_.transport, false, options_.worker_id, options_.lease, options_.udp_peers,
      options_.udp_interfaces, options_.transport_extras);
  node_config.log = options_.log;
  auto node = proto::dds::DdsNode::Create(node_config);
  if (!node.ok()) return node.status();
  impl.ctx.node = std::move(*node);
  participant_timer.reset();
  std::thread heartbeat([&] { impl.HeartbeatLoop(); });
  std::thread intake([&] { impl.intake.Loop(); });
  while (!stop_) {
    while (auto e = impl.ctx.node->NextEvent(std::chrono::milliseconds(0))) impl.OnDdsEvent(*e);
    impl.RetryParticipant();
    if (impl.ctx.node_restart) {  // between messages: no phase is running on this thread
      heartbeat.join();
      intake.join();
      {
        CpuTimer timer(&impl.ctx.cpu.participant);
        impl.ctx.node.reset();
        auto fresh = proto::dds::DdsNode::Create(node_config);
        if (!fresh.ok()) {
          stop_ = true;
          impl.intake.Wake();
          return Status(fresh.status().code(), "new DDS participant: " + fresh.status().message());
        }
        impl.ctx.node = std::move(*fresh);
      }
      impl.ctx.node_restart = false;
      heartbeat = std::thread([&] { impl.HeartbeatLoop(); });
      intake = std::thread([&] { impl.intake.Loop(); });
    }
    if (!impl.pending.empty()) {  // taken off DDS while a batch of subtree tasks was collected
      Impl::Pending p = std::move(impl.pending.front());
      impl.pending.pop_front();
      if (p.checked) {
        impl.ctx.dispatch_received_s = p.received_s;
        impl.Dispatch(p.env, p.sender);
      }
      else
        impl.OnSample(p.raw);
      continue;
    }
    std::optional<proto::dds::ReceivedSample> s;
    {
      CpuTimer timer(&impl.ctx.cpu.receive);
      s = impl.intake.Take(std::chrono::milliseconds(50));
    }
    if (s) impl.OnSample(*s);
    impl.ctx.SaveCpu();
  }
  heartbeat.join();
  impl.intake.Wake();
  intake.join();
  impl.ctx.cpu.receive += impl.intake.cpu_seconds();
  // Let the last replies reach the coordinator before the participant goes away.
  {
    CpuTimer timer(&impl.ctx.cpu.publish);
    (void)impl.ctx.node->WaitForAcknowledgments(Topic::kReplies, std::chrono::milliseconds(500));
  }
  impl.ctx.cpu.run_total = ProcessCpu() - process0;
  cpu_ = impl.ctx.cpu;
  impl.ctx.SaveCpu();
  return Status::Ok();
}

WorkerStats DistWorker::Stats() const {
  const Live& l = *live_;
  WorkerStats s;
  s.worker_id = options_.worker_id;
  s.stopped = l.stopped;
  s.threads = options_.threads;
  s.busy_threads = l.busy ? options_.threads : 0;
  for (size_t i = 0; i < s.rounds.size(); ++i) s.rounds[i] = l.rounds[i];
  s.histograms = l.histograms;
  s.subtrees = l.subtrees;
  s.subtree_nodes = l.subtree_nodes;
  s.evaluations = l.evaluations;
  s.shard_frames = {l.shard_rendered, double(l.shard_render_us) * 1e-6, l.shard_hits};
  s.task_frames = {l.task_rendered, double(l.task_render_us) * 1e-6, l.task_hits};
  s.frame_cache_evictions = l.cache_evictions;
  s.frame_cache_bytes = l.cache_bytes;
  s.frame_cache_capacity_bytes = l.cache_capacity;
  for (size_t t = 0; t < size_t(proto::dds::kNumTopics); ++t) {
    s.messages_sent[t] = l.sent[t];
    s.bytes_sent[t] = l.sent_bytes[t];
    s.messages_received[t] = l.received[t];
  }
  s.messages_rejected = l.rejected;
  s.messages_stale = l.stale;
  s.inbox_bytes = l.inbox_bytes;
  std::lock_guard<std::mutex> lock(l.mu);
  s.job_id = l.job_id;
  s.coordinator_id = l.coordinator_id;
  s.cpu = l.cpu;
  return s;
}

}  // namespace poseforest::worker
