#pragma once
// DDS intake: a thread of its own takes every sample off the DDS readers as it arrives and
// queues it here, whatever the training thread is doing. A worker deep in a long batch of
// subtree tasks thus never leaves the coordinator's keep-all control history full (which made
// the coordinator's writes fail). Bounded in bytes against a flood: past kMaxBytes the intake
// pauses and DDS flow control applies again.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>

#include "proto/dds/dds_node.h"
#include "worker/context.h"

namespace poseforest::worker {

class Intake {
 public:
  static constexpr uint64_t kMaxBytes = uint64_t(1) << 30;

  explicit Intake(Context& ctx) : ctx_(ctx) {}

  /// The intake thread's body: until ctx.stop (or ctx.node_restart), samples off ctx.node into
  /// the queue.
  void Loop();
  /// The next sample the intake thread queued, waiting up to `timeout`.
  std::optional<proto::dds::ReceivedSample> Take(std::chrono::milliseconds timeout);
  /// Wakes the threads waiting on the queue (Run() stopping).
  void Wake() { cv_.notify_all(); }
  /// The newest epoch above `epoch` of a ShardAssignment for this worker waiting in the queue,
  /// written by the coordinator's control writer `control_writer` (the gate checked that
  /// writer's earlier messages; these are only looked at, and pass the gate when their turn
  /// comes); 0: none.
  uint64_t NewerQueuedShard(const std::string& control_writer, uint64_t epoch);
  /// The intake thread's CPU seconds (complete once Loop() returned).
  double cpu_seconds() const { return cpu_; }

 private:
  Context& ctx_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<proto::dds::ReceivedSample> queue_;
  uint64_t bytes_ = 0;
  double cpu_ = 0;
};

}  // namespace poseforest::worker
