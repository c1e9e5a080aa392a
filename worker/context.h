#pragma once
// What the parts of a worker share (internal to worker/): the options, the DDS node and how a
// message goes out, the job joined, the CPU accounting, the figures its heartbeats report and
// the counters behind DistWorker::Stats(). The parts: intake.h (DDS samples into a queue),
// shard_server.h (the assigned shard and the coordinator's rounds), task_frame_cache.h (the
// frames of subtree tasks), subtree_runner.h (subtree tasks), dist_worker.cpp (the job, the
// heartbeats and the dispatch of every message, on Run()'s thread).

#include <time.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "proto/dds/topics.h"
#include "runtime/core/result.h"
#include "worker/dist_worker.h"

namespace poseforest::worker {

/// CPU seconds of the calling thread.
inline double ThreadCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

/// CPU seconds of the process (all threads).
inline double ProcessCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

/// Adds the calling thread's CPU time from construction to destruction to `*into`.
class CpuTimer {
 public:
  explicit CpuTimer(double* into) : into_(into), t0_(ThreadCpu()) {}
  ~CpuTimer() { *into_ += ThreadCpu() - t0_; }
  CpuTimer(const CpuTimer&) = delete;
  CpuTimer& operator=(const CpuTimer&) = delete;

 private:
  double* into_;
  double t0_;
};

struct DistWorker::Live {
  std::atomic<bool> stopped{false};  ///< Run() returned
  std::atomic<bool> busy{false};     ///< Context::busy
  std::array<std::atomic<uint64_t>, 4> rounds{};
  std::atomic<uint64_t> histograms{0}, subtrees{0}, subtree_nodes{0}, evaluations{0};
  std::atomic<uint64_t> shard_rendered{0}, shard_render_us{0}, shard_hits{0};
  std::atomic<uint64_t> task_rendered{0}, task_render_us{0}, task_hits{0};
  std::atomic<uint64_t> cache_evictions{0}, cache_bytes{0}, cache_capacity{0};
  std::array<std::atomic<uint64_t>, proto::dds::kNumTopics> sent{}, sent_bytes{}, received{};
  std::atomic<uint64_t> rejected{0}, stale{0}, inbox_bytes{0};
  mutable std::mutex mu;  ///< guards the job's ids and `cpu`
  std::string job_id, coordinator_id;
  WorkerCpu cpu;  ///< Context::cpu as of the last message handled
};

struct Context {
  Context(WorkerOptions& o, std::atomic<bool>& s, DistWorker::Live& l)
      : opt(o), stop(s), live(l), stamper("", o.worker_id, v1::SENDER_KIND_WORKER), busy(l.busy) {}

  WorkerOptions& opt;
  std::atomic<bool>& stop;
  DistWorker::Live& live;  ///< what Stats() reads (the /metrics of `worker --http`)
  std::unique_ptr<proto::dds::DdsNode> node;
  /// Set by Run()'s thread when the participant must be replaced (DistWorker::Run): the heartbeat
  /// and intake threads return, Run() creates a new DdsNode and starts them again.
  std::atomic<bool> node_restart{false};
  WorkerCpu cpu;  ///< written by the receiving (Run's) thread only

  std::mutex send_mu;  // guards stamper + job identity used by the heartbeat thread
  proto::dds::EnvelopeStamper stamper;
  /// Why the last job announced was refused (guarded by send_mu; empty: none): while the worker
  /// has no job, its heartbeat thread sends hellos carrying it (WorkerHello.refusal), stamped
  /// with the refused job's id, so that the coordinator reports it.
  std::string refusal;
  std::atomic<bool> has_job{false}, assigned_any{false};
  std::atomic<bool>& busy;  ///< live.busy: heartbeats and Stats() say how many threads are busy
  /// Marks the worker busy (its heartbeats say so) while a subtree task or batch runs.
  struct BusyScope {
    explicit BusyScope(std::atomic<bool>& f) : flag(f) { flag = true; }
    ~BusyScope() { flag = false; }
    std::atomic<bool>& flag;
  };
  std::atomic<uint64_t> newest_epoch{0}, frames_rendered{0}, shard_epoch{0}, received_shard_epoch{0};
  std::atomic<v1::RendererKind> renderer{v1::RENDERER_KIND_PROCEDURAL};
  std::atomic<uint64_t> evaluations{0};  ///< sample x candidate evaluations binned (heartbeats)

  std::string job_id, coordinator_id;
  engine::TrainParams params;  ///< the job's (threads: WorkerOptions::threads)
  /// When the sample being dispatched was taken off DDS (for HistogramReply.queued_micros).
  double dispatch_received_s = 0;

  void Log(const std::string& m) { opt.log(m); }

  /// Copies `cpu` for Stats() (called between messages, when no phase timer is open).
  void SaveCpu() {
    std::lock_guard<std::mutex> lock(live.mu);
    live.cpu = cpu;
  }

  /// Counts a message the gate dropped (Stats()).
  void CountDropped(const proto::dds::MessageGate::Outcome& out) {
    if (out.verdict == proto::dds::MessageGate::Verdict::kRejected)
      ++live.rejected;
    else if (out.verdict == proto::dds::MessageGate::Verdict::kStale)
      ++live.stale;
  }

  /// Seals and writes `env`; `timed`: counted in cpu.publish (the receiving thread's sends).
  core::Status Publish(proto::dds::Topic topic, v1::Envelope& env, bool timed = true);
  /// A reply to the coordinator (Publish on the replies topic), once its reader matched: a
  /// volatile writer drops what it writes before the coordinator's reader matched.
  core::Status Reply(v1::Envelope& env);
};

}  // namespace poseforest::worker
