#pragma once
// The distributed worker: joins a training job announced on a DDS domain, renders/loads the
// frames of the shard the coordinator assigns, and answers LevelRequests with ranges (pass 1)
// and histograms (pass 2) of its samples; applies SplitDecisions to move its samples down the
// tree; trains a small node's whole subtree when it gets a SubtreeTask (re-rendering the frames
// of the node that are not in its shard). A library with a thin CLI (`poseforest worker`), so tests run
// workers as threads too.
//
// Threads: Run() receives and computes on the caller's thread; a heartbeat thread publishes
// Hello/Heartbeat on the presence topic (which also asserts its DDS liveliness) while the main
// thread computes. DDS listeners only enqueue (dds::DdsNode).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "proto/dds/dds_node.h"
#include "worker/distributed/dds_flags.h"
#include "runtime/core/result.h"

namespace poseforest::dist {

struct WorkerOptions {
  std::string worker_id;  ///< unique sender id ("worker-<host>-<pid>" when empty)
  uint32_t domain = 0;
  dds::TransportKind transport = dds::TransportKind::kSharedMemoryOnly;
  int threads = 1;             ///< OpenMP threads for frames and histograms
  std::string job_id;          ///< join only this job (empty: any)
  bool exit_when_done = true;  ///< return from Run() when the coordinator reports JOB_DONE
  std::chrono::milliseconds heartbeat_period{250};
  std::chrono::milliseconds lease{1500};        ///< presence liveliness lease
  /// kUdpOnly: initial peers (usually the coordinator's address) and local interfaces to use;
  /// empty = loopback peer, every interface (MakeNodeConfig).
  std::vector<std::string> udp_peers, udp_interfaces;
  /// XML profile, discovery server, DDS-Security (the --dds-xml, --discovery-server, --security flags).
  TransportExtras transport_extras;
  std::function<void(const std::string&)> log;  ///< default: stderr with the worker id
  /// Tests: called when a SubtreeTask arrives; returning true makes the worker drop the task and
  /// stop at once, as if it were killed while holding it.
  std::function<bool()> die_on_subtree_task;
  /// Tests: the next this many SubtreeResults are tampered with after they are built (a root
  /// at the wrong position, then part counts that do not add up), still well-formed for the
  /// gate: a hostile worker.
  int corrupt_subtree_results = 0;
};

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

  struct Impl;

 private:
  WorkerOptions options_;
  std::atomic<bool> stop_{false};
};

}  // namespace poseforest::dist
