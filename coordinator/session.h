#pragma once
// What every part of the coordinator shares: the job (its config, parameters, options and
// ids), the DDS node and the message gate, the one epoch counter every request, assignment
// and task is numbered by, the tree being grown, and the traffic and time figures of the
// current level and of the run. Send stamps and publishes; PublishStatus tells the status
// topic (and the observer) what happens.

#include <cstdint>
#include <memory>
#include <string>

#include "coordinator/dist_coordinator.h"
#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

class WorkerRegistry;

/// Where a level's wall time went (DistLevelStats' round_*, subtree_*, render_seconds).
struct TimeSplit {
  int rounds = 0;
  double round_s = 0, compute_s = 0, queued_s = 0, traffic_s = 0, subtree_wait_s = 0, subtree_busy_s = 0,
         render_s = 0;
};

struct Session {
  v1::TrainerConfig config;
  v1::Envelope job_announcement;  ///< the job as announced (sent again while workers are missing)
  engine::TrainParams params;
  CoordinatorOptions opt;
  std::string job_id, self_id;
  /// This build's identity (proto/dds/build_id.h): announced with the job; workers of another
  /// build are not admitted (WorkerRegistry::OnPresence).
  std::string build_id;
  std::unique_ptr<proto::dds::DdsNode> node;
  std::unique_ptr<proto::dds::MessageGate> gate;
  proto::dds::EnvelopeStamper stamper{"", "", v1::SENDER_KIND_COORDINATOR};
  /// The workers (not owned): PublishStatus reports how many are alive.
  const WorkerRegistry* registry = nullptr;
  uint64_t epoch = 0;
  double start = 0;
  uint64_t total_bytes_received = 0;
  uint64_t stale_count = 0;  ///< stale messages (the gate's per-sender stats are reset by Forget)

  int tree = -1;  ///< the tree being grown

  // Level accounting.
  uint64_t level_bytes_received = 0, level_bytes_sent = 0;
  TimeSplit level_time;
  int level_retries = 0;

  double last_status_time = 0;  ///< of the last StatusEvent: a PROGRESS one 2 s after it
  double last_progress = 0;     ///< of the last LEVEL_DONE / TREE_DONE, for PROGRESS events

  void Log(const std::string& m) { opt.log(m); }

  /// Stamps and publishes `env`; control traffic counts towards the level's bytes sent.
  core::Status Send(proto::dds::Topic topic, v1::Envelope& env);

  void PublishStatus(v1::StatusKind kind, const std::string& message, const std::string& worker = "",
                     int level = 0, double progress = 0);

  /// The job id (default: from the config), a fresh sender id, the stamper and the gate.
  void StartSender();

  /// Creates the DDS participant and announces the job.
  core::Status Announce();
};

}  // namespace poseforest::coordinator
