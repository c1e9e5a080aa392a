#pragma once
// The job's workers: who joined (hellos and heartbeats), who is still alive (presence
// liveliness, heartbeats, the gate's verdicts, evictions), and which frames of the current tree
// each one holds (its ShardAssignment). A lost worker's frames wait as orphans until
// Distribute hands them to the live workers, which replay the tree's decisions so far.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "coordinator/session.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_node.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

struct WorkerInfo {
  std::string id;
  std::string presence_writer, participant;
  double last_seen = 0;
  bool alive = true;
  bool evicted = false;  ///< lost for misbehaving: not waited for (AwaitLostWorkers)
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

using FrameRanges = std::vector<std::pair<uint32_t, uint32_t>>;

class WorkerRegistry {
 public:
  /// `tree_decisions`: the current tree's SplitDecisions so far (LevelRecords'), which every
  /// assignment is followed by.
  WorkerRegistry(Session& session, const std::vector<v1::SplitDecisions>& tree_decisions);

  /// Takes in messages for up to the given time (the coordinator's Pump, no round open); set
  /// before WaitForWorkers is called.
  std::function<void(std::chrono::milliseconds)> pump;

  std::map<std::string, WorkerInfo>& workers() { return workers_; }
  int AssignedCount() const;
  int AliveCount() const;
  int lost_count() const { return lost_count_; }

  /// A hello or heartbeat from `sender` (written by `writer_guid` of `participant`): a new or
  /// returning worker joins; a known one is seen.
  void OnPresence(const std::string& sender, const v1::Envelope& env, const std::string& writer_guid,
                  const std::string& participant);
  /// Whether a worker's hello admits it: false (reported once, as STATUS_KIND_WORKER_REFUSED)
  /// when it refuses the job or runs another build than the coordinator's.
  bool Admissible(const std::string& sender, const v1::WorkerHello& hello);
  /// "; N worker(s) not admitted: ID on HOST (pid P): why; ..." ("" when none).
  std::string RefusedSummary() const;
  /// Presence liveliness lost, or a participant gone: its workers are lost.
  void OnDdsEvent(const proto::dds::DdsEvent& e);
  /// Workers not heard from for heartbeat_timeout before `now` (NowSeconds) are lost.
  void CheckHeartbeats(double now);
  /// Drops worker `id` (why "evicted": for misbehaving, its id stays flagged at the gate); its
  /// frames become orphans.
  void MarkLost(const std::string& id, const std::string& why);
  /// `id` never rejoins (a sender of hostile SubtreeResults).
  void Ban(const std::string& id) { banned_.insert(id); }

  /// Waits (announcing the job again every 2 s) until `n` workers are alive.
  core::Status WaitForWorkers(int n);

  /// After JOB_DONE: waits up to `grace` for the workers lost during the job (not evicted or
  /// banned) to come back. A worker replacing its DDS participant is lost for a moment and
  /// waits for JOB_DONE, which the status topic (transient-local) gives it once it matches a
  /// live coordinator; `on_back` runs each time some came back (the caller says JOB_DONE again:
  /// a worker that joined after the replay missed it). Returns how many came back.
  int AwaitLostWorkers(std::chrono::milliseconds grace, const std::function<void()>& on_back);

  /// Sends `w` its ShardAssignment, then the tree's decisions so far (the worker replays them).
  /// `again`: the same frames once more (the worker's heartbeats do not show it got them).
  core::Status SendAssignment(WorkerInfo& w, uint32_t index, uint32_t count, bool again = false);

  /// Spreads `frames` (tree-local ranges) over every live worker in contiguous blocks and
  /// (re)sends the assignments of the workers that got some.
  core::Status Distribute(FrameRanges frames);

  /// A new tree: nobody holds frames.
  void ClearAssignments();
  bool HasOrphans() const { return !orphan_frames_.empty(); }
  /// The frames of lost workers, handed over to the caller (to Distribute).
  FrameRanges TakeOrphans();
  void AddOrphans(std::pair<uint32_t, uint32_t> range) { orphan_frames_.push_back(range); }

 private:
  Session& s_;
  const std::vector<v1::SplitDecisions>& tree_decisions_;
  std::map<std::string, WorkerInfo> workers_;
  FrameRanges orphan_frames_;  ///< of lost workers, current tree
  std::set<std::string> banned_;  ///< senders of hostile SubtreeResults: never rejoin
  /// Workers not admitted (sender -> "host: why"): they refused the job or run another build.
  /// Reported once each, and in WaitForWorkers' error; a later admissible hello clears it.
  std::map<std::string, std::string> refused_;
  int lost_count_ = 0;
  /// Set by AwaitLostWorkers: workers leave on JOB_DONE now; leaving is not being lost.
  bool job_done_ = false;
};

}  // namespace poseforest::coordinator
