#pragma once
// The coordinator's event log: one JSON object per line (JSON Lines), appended and flushed as
// things happen, so a crashed or killed coordinator leaves every event up to its end. Lines:
// JOB_STARTED, LEVEL_DONE (with the level's figures), TREE_DONE, JOB_DONE, WORKER_JOINED,
// WORKER_LOST, WORKER_EVICTED, WORKER_ASSIGNED, ERROR, and from the command FOREST_WRITTEN /
// JOB_FAILED. Schema: JobEvent in proto/poseforest/v1/status.proto (docs/distributed/monitoring.md).

#include <cstdio>
#include <memory>
#include <mutex>
#include <string>

#include "coordinator/dist_coordinator.h"
#include "poseforest/v1/status.pb.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator::monitoring {

class EventLog : public CoordinatorObserver {
 public:
  /// Opens `path` for appending (a resumed job continues the same file). Errors name the path.
  static core::Result<std::unique_ptr<EventLog>> Open(const std::string& path, const std::string& job_id);
  ~EventLog() override;

  void OnStatus(const v1::StatusEvent& e) override;
  void OnLevelDone(const DistLevelStats& s) override;
  void OnWorkerAssigned(const std::string& id, int tree, uint64_t frames) override;

  /// Writes `e` as one line, with its time, unix and job set here (only the fields set are written).
  void Write(v1::JobEvent e);

 private:
  EventLog() = default;
  std::mutex mu_;
  std::FILE* file_ = nullptr;
  std::string path_, job_id_;
  bool have_level_ = false;
  DistLevelStats last_level_;
};

}  // namespace poseforest::coordinator::monitoring
