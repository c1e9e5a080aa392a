#pragma once
// The distributed worker: joins a training job announced on a DDS domain, renders/loads the
// frames of the shard the coordinator assigns, and answers LevelRequests with ranges (pass 1)
// and histograms (pass 2) of its samples; applies SplitDecisions to move its samples down the
// tree; trains a small node's whole subtree when it gets a SubtreeTask (re-rendering the frames
// of the node that are not in its shard). A library with a thin CLI (`poseforest worker`), so tests run
// workers as threads too.
//
// Threads: Run() computes on the caller's thread; an intake thread takes every sample off DDS as
// it arrives and queues it for Run() (so a worker busy training never leaves the coordinator's
// control history full); a heartbeat thread publishes Hello/Heartbeat on the presence topic
// (which also asserts its DDS liveliness) while the main thread computes. DDS listeners only
// enqueue (proto::dds::DdsNode).

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "proto/dds/dds_flags.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/topics.h"
#include "runtime/core/result.h"

namespace poseforest::worker {

struct WorkerOptions {
  std::string worker_id;  ///< unique sender id (DefaultWorkerId() when empty)
  uint32_t domain = 0;
  proto::dds::TransportKind transport = proto::dds::TransportKind::kSharedMemoryOnly;
  int threads = 1;             ///< OpenMP threads for frames and histograms
  std::string job_id;          ///< join only this job (empty: any)
  /// The build identity it reports and compares with the job's (empty: proto::dds::BuildId(),
  /// this build's, or POSEFOREST_BUILD_ID).
  std::string build_id;
  bool exit_when_done = true;  ///< return from Run() when the coordinator reports JOB_DONE
  std::chrono::milliseconds heartbeat_period{250};
  std::chrono::milliseconds lease{1500};        ///< presence liveliness lease
  /// kUdpOnly: initial peers (usually the coordinator's address) and local interfaces to use;
  /// empty = loopback peer, every interface (MakeNodeConfig).
  std::vector<std::string> udp_peers, udp_interfaces;
  /// XML profile, discovery server, DDS-Security (the --dds-xml, --discovery-server, --security flags).
  proto::dds::TransportExtras transport_extras;
  /// Most bytes of frames of other shards kept between SubtreeTasks of a tree (rendered for one
  /// task, reused by the next ones); least recently used dropped first. Never changes a result.
  /// 0 (default): sized from the job (TaskCacheBytesFor), so that a tree's frames rendered for
  /// tasks are rendered once: at 256 MiB a 2,000-image tree rendered frames again and again
  /// (13,029 evictions).
  uint64_t task_cache_bytes = 0;
  std::function<void(const std::string&)> log;  ///< default: stderr with the worker id
  /// Tests: called when a SubtreeTask arrives; returning true makes the worker drop the task and
  /// stop at once, as if it were killed while holding it.
  std::function<bool()> die_on_subtree_task;
  /// Tests: called on the training thread when subtree tasks arrive, before they are trained
  /// (a test sleeps in it: a worker busy in a long batch while the coordinator goes on sending).
  std::function<void()> hold_on_subtree_task;
  /// Test hook: called at every pause of a subtree task or batch (between its histogram
  /// batches and levels, where the worker answers queued rounds).
  std::function<void()> in_subtree_batch;
  /// Tests: called on the training thread when a ShardAssignment is taken off the queue, before
  /// it counts as received (a test sleeps in it: a worker busy elsewhere while assignments queue).
  std::function<void()> hold_before_shard;
  /// Tests: called when a ShardAssignment is loaded, before its frames are rendered (a test
  /// sleeps in it: a slow load, as at 2,000 images per tree).
  std::function<void()> hold_in_shard_load;
  /// Tests: the next this many SubtreeResults are tampered with after they are built (a root
  /// at the wrong position, then part counts that do not add up), still well-formed for the
  /// gate: a hostile worker.
  int corrupt_subtree_results = 0;
};

/// Where a worker's CPU time goes (DistWorker::cpu(), bench/distributed's breakdown): CPU
/// seconds by phase, each measured on the thread doing the work (CLOCK_THREAD_CPUTIME_ID, plus
/// the frame-loading threads it starts).
struct WorkerCpu {
  double process_at_start = 0;  ///< process CPU when Run() began (exec, libraries, static init)
  double participant = 0;       ///< creating the DDS participant, readers and writers
  double receive = 0;           ///< taking samples off DDS, the gate (decode + checks), idle polling
  double shard = 0;             ///< ShardAssignment: rendering the own frames, sampling, SampleSet
  double decisions = 0;         ///< SplitDecisions: routing the samples
  double level_compute = 0;     ///< LevelRequests: ranges, histograms, fused nodes, census, frame lists
  double level_encode = 0;      ///< LevelRequests: part counts and histogram runs into the reply
  double subtree_render = 0;    ///< SubtreeTasks: rendering the frames not held
  double subtree_route = 0;     ///< SubtreeTasks: the frames' SampleSet, routing along the path
  double subtree_train = 0;     ///< SubtreeTasks: TrainSubtree
  double subtree_encode = 0;    ///< SubtreeTasks: the SubtreeResult message
  double publish = 0;           ///< serializing envelopes and writing them (DDS), waits for a match
  double run_total = 0;         ///< process CPU spent from Run()'s start to its end (all threads)
  uint64_t shard_frames = 0;    ///< frames rendered/loaded for shards
  uint64_t shard_loads = 0;     ///< ShardAssignments loaded
  uint64_t shards_skipped = 0;  ///< ShardAssignments skipped: a newer one for this worker was queued
  uint64_t task_frames = 0;     ///< frames rendered for SubtreeTasks
  uint64_t task_frames_cached = 0;  ///< task frames found in the shard or the task cache
  uint64_t subtree_tasks = 0;
  uint64_t subtree_batches = 0;     ///< sets of several tasks trained together (one SampleSet)
  uint64_t rounds_in_batches = 0;   ///< times a subtree task or batch stopped to answer queued rounds
  uint64_t task_cache_peak_bytes = 0;  ///< most bytes the task-frame cache held
  uint64_t task_cache_evictions = 0;   ///< frames dropped from it to stay under its cap
  /// The main thread's phases above (not process_at_start / run_total), named, in order: what the
  /// bench's stats file and the worker's /metrics list.
  std::array<std::pair<const char*, double>, 11> NamedPhases() const {
    return {{{"participant", participant},
             {"receive", receive},
             {"shard", shard},
             {"decisions", decisions},
             {"level_compute", level_compute},
             {"level_encode", level_encode},
             {"subtree_render", subtree_render},
             {"subtree_route", subtree_route},
             {"subtree_train", subtree_train},
             {"subtree_encode", subtree_encode},
             {"publish", publish}}};
  }
  /// Their sum.
  double Phases() const {
    double sum = 0;
    for (const auto& [name, seconds] : NamedPhases()) sum += seconds;
    return sum;
  }
};

/// What a worker has done, for its /metrics (`worker --http`, worker/worker_metrics.h): counters
/// since the DistWorker was made, over every Run() and every job of a --stay worker (they only
/// grow), and the figures of now. A copy taken by DistWorker::Stats(), from any thread at any time.
struct WorkerStats {
  std::string worker_id;
  /// Run() returned (the worker stopped: Stop(), a signal, or the job done); false before it
  /// starts, so that a metrics server started ahead of Run() says "up".
  bool stopped = false;
  std::string job_id, coordinator_id;  ///< the job joined last (empty: none yet)
  int threads = 1;                     ///< WorkerOptions::threads
  int busy_threads = 0;                ///< in a round or a subtree task now: 0 or `threads`
  /// LevelRequests answered, by phase: ranges (pass 1), histograms (pass 2), counts (census),
  /// frames (the frame lists before a hand-off); kRoundPhases names them.
  std::array<uint64_t, 4> rounds{};
  static constexpr std::array<const char*, 4> kRoundPhases = {"ranges", "histograms", "counts", "frames"};
  uint64_t histograms = 0;     ///< node histograms sent (fused ones of pass 1, and pass 2's)
  uint64_t subtrees = 0;       ///< subtrees trained and sent (SubtreeResults)
  uint64_t subtree_nodes = 0;  ///< nodes of those subtrees
  uint64_t evaluations = 0;    ///< sample x candidate evaluations binned, rounds and subtrees
  /// Frames of the own shard (ShardAssignments) and of other shards (SubtreeTasks).
  struct Frames {
    uint64_t rendered = 0;      ///< rendered or loaded
    double render_seconds = 0;  ///< wall seconds spent rendering/loading them (all threads at once)
    uint64_t cache_hits = 0;    ///< needed but already held (shard: kept from the tree's last
                                ///< assignment; subtree: in the shard or the task-frame cache)
  } shard_frames, task_frames;
  uint64_t frame_cache_evictions = 0;       ///< frames dropped from the task-frame cache (its cap)
  uint64_t frame_cache_bytes = 0;           ///< bytes the task-frame cache holds now
  uint64_t frame_cache_capacity_bytes = 0;  ///< its cap (WorkerOptions::task_cache_bytes, or auto)
  /// Envelopes written and their serialized bytes, and samples taken off DDS, by proto::dds::Topic.
  std::array<uint64_t, proto::dds::kNumTopics> messages_sent{}, bytes_sent{}, messages_received{};
  uint64_t messages_rejected = 0;  ///< dropped by the message gate: malformed or not allowed
  uint64_t messages_stale = 0;     ///< dropped by the message gate: outdated (older epoch or level)
  uint64_t inbox_bytes = 0;        ///< taken off DDS, queued for the training thread now
  /// CPU seconds by phase so far (updated between messages: a phase's time counts once it ends).
  WorkerCpu cpu;
};

/// The samples of one frame that a SubtreeTask lists (SubtreeTask.sample_pixel_deltas): `deltas`
/// are pixel indices y * width + x, ascending and delta-coded (the first absolute), each one of
/// `picked`, the frame's sampled pixels (ascending, as SamplePixels returns them); `*out` gets
/// those samples. InvalidArgument naming the frame and the pixel otherwise.
core::Status SelectListedSamples(std::span<const engine::PixelSample> picked, int width, uint64_t frame,
                                 std::span<const uint32_t> deltas, std::vector<engine::PixelSample>* out);

/// The automatic task-frame cache of a job: every frame of one tree (depth + sampled pixels,
/// as the cache keeps them), at most an eighth of `physical_bytes`, at least 256 MiB.
uint64_t TaskCacheBytesFor(const engine::TrainParams& params, uint64_t physical_bytes);

class DistWorker {
 public:
  explicit DistWorker(WorkerOptions options);
  ~DistWorker();

  /// Runs until Stop(), or until the job is done when exit_when_done. Errors: the participant
  /// could not be created. Bad messages are dropped and counted (never an error).
  core::Status Run();
  /// Asks Run() to return (thread-safe).
  void Stop() { stop_ = true; }
  const std::string& id() const { return options_.worker_id; }
  /// Where the CPU went in the last Run() (complete once Run() returned).
  const WorkerCpu& cpu() const { return cpu_; }
  /// What the worker has done so far (WorkerStats): thread-safe, also while Run() runs.
  WorkerStats Stats() const;

  struct Impl;
  struct Live;  ///< the counters behind Stats(), written by Run()'s threads (context.h)

 private:
  WorkerOptions options_;
  std::atomic<bool> stop_{false};
  WorkerCpu cpu_;
  std::unique_ptr<Live> live_;
};

}  // namespace poseforest::worker
