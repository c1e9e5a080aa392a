#pragma once
// The distributed coordinator: announces a job on a DDS domain, spreads each tree's frames over
// the workers that join (ShardAssignment), and runs the engine's level-wise loop
// (engine/frontier_loop.h) over a remote shard set: per batch of frontier nodes a ranges round
// (pass 1) and a histograms round (pass 2), merged here, FindBestSplit here (the loop's),
// SplitDecisions broadcast as the shard set's ApplySplits. The
// forest is byte-identical to LocalTrainer's for the same job, whatever the worker count and
// whatever workers are lost on the way (docs/distributed/service.md).
//
// Fault tolerance: a worker whose presence liveliness lapses, whose heartbeats stop, or that the
// MessageGate flags is dropped; its frames go to the surviving (and newly joined) workers, which
// replay the tree's split decisions so far to place their samples, and the round is asked again
// under a new epoch. Checkpoints after every level allow a restarted coordinator to resume.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_flags.h"
#include "proto/dds/dds_node.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

/// Reported once per finished level.
struct DistLevelStats {
  int tree = 0;
  int level = 0;
  size_t frontier_nodes = 0;
  size_t split_nodes = 0;
  uint64_t samples = 0;      ///< samples in the frontier
  uint64_t evaluations = 0;  ///< sample x candidate evaluations binned (pass 2 + fused nodes), all workers
  double evaluations_per_s = 0;  ///< evaluations / wall seconds of the ranges + histogram rounds
  int workers_alive = 0;
  int workers_assigned = 0;     ///< of which hold frames of this tree
  uint64_t bytes_received = 0;  ///< reply payload bytes of this level (all rounds)
  uint64_t bytes_sent = 0;      ///< control payload bytes of this level
  double merge_seconds = 0;     ///< decoding + summing histograms + split choice
  double level_seconds = 0;     ///< wall time of the level
  double elapsed_s = 0;         ///< since Train() started
  int retries = 0;              ///< rounds asked again after a worker loss (or subtree tasks handed on)
  size_t subtree_tasks = 0;     ///< nodes of this level handed to one worker whole (SubtreeTask)
  size_t subtree_nodes = 0;     ///< nodes of this level decided by SubtreeResults (tasks' roots included)
  uint64_t subtree_samples = 0;          ///< samples of this level's SubtreeTasks (each time sent)
  uint64_t subtree_samples_busiest = 0;  ///< of which sent to the worker that got the most
  uint64_t subtree_largest_task = 0;     ///< samples of the largest SubtreeTask of this level
  uint64_t subtree_task_messages = 0;    ///< SubtreeTasks messages that carried them (a few per worker)
  double mean_entropy = 0;      ///< bits: part entropy of the frontier nodes, weighted by samples
  double mean_gain = 0;         ///< bits: mean information gain of the splits chosen (0: none)
  // Where the level's wall time went (the per-level table). Per request/reply round the worker
  // whose reply completed it (the largest queued + compute) is the critical one; the round's
  // wall time = its queued + its compute + traffic.
  int rounds = 0;                     ///< request/reply rounds (ranges, histograms, frames)
  double round_seconds = 0;           ///< their wall time
  double round_compute_seconds = 0;   ///< of which the critical worker computed the reply
  double round_queued_seconds = 0;    ///< of which its request waited in its inbox (busy: subtree tasks)
  double round_traffic_seconds = 0;   ///< the rest: on the wire, encoding, decoding, intake
  double subtree_wait_seconds = 0;    ///< after the rounds, waiting for the level's SubtreeResults
  double subtree_busy_seconds = 0;    ///< workers' wall time on the level's subtree tasks (summed over workers)
  double render_seconds = 0;          ///< workers' wall time rendering frames for them (summed over workers)
};

/// Live view of the coordinator for monitoring (coordinator/monitoring/status_model.h,
/// event_log.h). Called on the training thread; implementations must be quick and not throw.
class CoordinatorObserver {
 public:
  virtual ~CoordinatorObserver() = default;
  /// Every StatusEvent the coordinator publishes on the status topic.
  virtual void OnStatus(const v1::StatusEvent&) {}
  /// A level starts: `nodes` frontier nodes holding `samples` samples.
  virtual void OnLevelStart(int /*tree*/, int /*level*/, size_t /*nodes*/, uint64_t /*samples*/) {}
  /// Frontier nodes of the current level whose decision is made (per request batch).
  virtual void OnNodesDecided(size_t /*done*/, size_t /*total*/) {}
  /// The level's figures (also given to CoordinatorOptions::progress).
  virtual void OnLevelDone(const DistLevelStats&) {}
  /// A hello or heartbeat of worker `id` was accepted.
  virtual void OnWorkerSeen(const std::string& /*id*/) {}
  /// Worker `id` was sent a shard of `frames` frames of tree `tree`.
  virtual void OnWorkerAssigned(const std::string& /*id*/, int /*tree*/, uint64_t /*frames*/) {}
  /// A reply of the current round from worker `id` was accepted (`bytes`: its payload).
  virtual void OnWorkerReply(const std::string& /*id*/, uint64_t /*bytes*/, const v1::HistogramReply&) {}
  /// An accepted heartbeat of worker `id` (after OnWorkerSeen): its own throughput figures.
  virtual void OnWorkerHeartbeat(const std::string& /*id*/, const v1::Heartbeat&) {}
  /// Fills the live figures (throughput, ETA, nodes, workers) of a StatusEvent about to be
  /// published, after OnStatus saw it; STATUS_KIND_PROGRESS events only come here.
  virtual void FillStatus(v1::StatusEvent*) {}
};

struct CoordinatorOptions {
  std::string job_id;  ///< empty: "job-<crc32 of the config>"
  uint32_t domain = 0;
  proto::dds::TransportKind transport = proto::dds::TransportKind::kSharedMemoryOnly;
  /// kUdpOnly: initial peers and local interfaces (MakeNodeConfig); empty = loopback, all.
  std::vector<std::string> udp_peers, udp_interfaces;
  /// XML profile, discovery server, DDS-Security (the --dds-xml, --discovery-server, --security flags).
  proto::dds::TransportExtras transport_extras;
  int min_workers = 1;                                ///< workers to wait for before the first tree
  std::chrono::milliseconds worker_wait{60000};       ///< without any live worker this long: error
  std::chrono::milliseconds lease{1500};              ///< liveliness lease (presence, job)
  std::chrono::milliseconds heartbeat_timeout{4000};  ///< no heartbeat this long: worker lost
  /// After JOB_DONE, how long to wait for workers lost during the job to come back and hear it
  /// (WorkerRegistry::AwaitLostWorkers): a worker that replaces its DDS participant (it does on
  /// joining a restarted coordinator) is lost for a moment, and only a live coordinator can tell
  /// it the job is done. 0: leave at once.
  std::chrono::milliseconds done_grace{10000};
  /// An assigned worker that has not answered a round this long is evicted (alive but stuck).
  std::chrono::milliseconds reply_timeout{300000};
  /// Histogram bytes per request batch (also bounded by the job's histogram_memory_bytes): keeps
  /// each reply far below protobuf's 2 GiB message limit. Batching does not change the forest.
  uint64_t max_batch_bytes = uint64_t(64) << 20;
  /// SubtreeTasks list the node's samples (from the FRAMES round) so that the worker takes them
  /// without routing its frames along the path; false (tests): the worker routes. Same forest.
  bool subtree_sample_lists = true;
  /// OpenMP threads for merging histograms and choosing splits; 0: the job's `threads` (0 there:
  /// every core). `--local-workers N` sets the cores the workers leave free (at least 1), so the
  /// coordinator's threads neither take the workers' cores nor spin-wait on them.
  int merge_threads = 0;
  std::string checkpoint_dir;  ///< empty: no checkpoints
  bool resume = false;         ///< continue from checkpoint_dir/checkpoint.pb if present
  /// Tests: before tree t (< size), wait until this many workers are alive (late joiners).
  std::vector<int> min_workers_per_tree;
  int stop_after_levels = -1;  ///< tests: fail with kInternal after this many levels (a "crash")
  /// While this file exists the coordinator holds between levels (workers stay joined and are
  /// watched); removing it lets the job go on. Empty: never.
  std::string pause_file;
  std::function<void(const DistLevelStats&)> progress;
  std::function<void(const std::string&)> log;  ///< default: stderr
  CoordinatorObserver* observer = nullptr;       ///< not owned; may be null
};

class DistCoordinator {
 public:
  /// `config` is announced to the workers; `params` = ParamsFromConfig(config).
  DistCoordinator(v1::TrainerConfig config, engine::TrainParams params, CoordinatorOptions options);
  ~DistCoordinator();

  /// Trains every tree. Errors: participant creation, no workers within worker_wait, a bad
  /// checkpoint, inconsistent worker data that a retry did not fix.
  core::Result<core::Forest> Train();

  const std::string& job_id() const;
  /// Totals over the run.
  uint64_t bytes_received() const;
  /// Messages dropped: by the gate, plus SubtreeResults that did not fit their task.
  uint64_t rejected_messages() const;
  /// Valid messages of an older epoch (e.g. replies of a worker cut off and back), dropped.
  uint64_t stale_messages() const;
  int workers_lost() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace poseforest::coordinator
