#pragma once
// MessageGate: everything a node receives passes here before any logic sees it. It parses the
// Envelope, checks job id, protocol version, sender kind and topic, per-sender sequence, epoch
// staleness and the body's dimensions (one validator per body type), and drops what fails with
// a counted, logged reason per sender. A sender whose bad messages exceed a budget is reported
// once by TakeOffenders() (the coordinator evicts it) and everything it sends later is dropped.
//
// Not thread-safe: one gate per receiving thread. No Fast DDS types.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "poseforest/v1/wire.pb.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/topics.h"
#include "runtime/core/result.h"

namespace poseforest::proto::dds {

/// Protocol version this build speaks (major).
inline constexpr poseforest::v1::ProtocolVersion kProtocolVersion = poseforest::v1::PROTOCOL_VERSION_1;

/// Most tasks in one SubtreeTasks message (the gate refuses more).
inline constexpr int kMaxSubtreeTasks = 4096;
/// The coordinator splits a worker's SubtreeTasks of a level into messages of about this many
/// serialized bytes at most (well under the sample limit, so a batch never waits on fragments
/// of one huge sample).
inline constexpr size_t kSubtreeTasksMaxBytes = size_t(4) << 20;

/// Fills the envelope header (job, sender, kind, version, per-topic sequence) and serializes.
/// Not thread-safe: one per sending thread, or guard it.
class EnvelopeStamper {
 public:
  EnvelopeStamper(std::string job_id, std::string sender_id, poseforest::v1::SenderKind kind)
      : job_id_(std::move(job_id)), sender_id_(std::move(sender_id)), kind_(kind) {}
  /// Stamps `env` (its body must be set) for `topic` and returns the bytes to publish.
  std::string Seal(Topic topic, poseforest::v1::Envelope& env);
  /// Seal without the serialization: fills the header only, so a caller that guards the stamper
  /// with a lock serializes a large envelope outside it.
  void Stamp(Topic topic, poseforest::v1::Envelope& env);
  void set_job_id(std::string job_id) { job_id_ = std::move(job_id); }
  const std::string& sender_id() const { return sender_id_; }

 private:
  std::string job_id_, sender_id_;
  poseforest::v1::SenderKind kind_;
  uint64_t sequence_[kNumTopics] = {};
};

/// Which envelope bodies may travel on `topic`, and who may send `body`.
bool BodyAllowedOnTopic(poseforest::v1::Envelope::BodyCase body, Topic topic);
poseforest::v1::SenderKind SenderKindOfBody(poseforest::v1::Envelope::BodyCase body);
const char* BodyName(poseforest::v1::Envelope::BodyCase body);

/// Stateless per-body validators (dimensions, ranges, internal consistency). `num_parts` 0 =
/// not known yet (part-count lengths are then only checked for consistency).
core::Status ValidateJob(const poseforest::v1::JobAnnouncement& m);
core::Status ValidateHello(const poseforest::v1::WorkerHello& m);
core::Status ValidateHeartbeat(const poseforest::v1::Heartbeat& m);
core::Status ValidateShard(const poseforest::v1::ShardAssignment& m);
core::Status ValidateLevelRequest(const poseforest::v1::LevelRequest& m);
core::Status ValidateHistogramReply(const poseforest::v1::HistogramReply& m);
core::Status ValidateDecisions(const poseforest::v1::SplitDecisions& m, uint32_t num_parts);
core::Status ValidateSubtreeTask(const poseforest::v1::SubtreeTask& m);
core::Status ValidateSubtreeResult(const poseforest::v1::SubtreeResult& m);
core::Status ValidateStatus(const poseforest::v1::StatusEvent& m);

struct GateConfig {
  /// Our own sender id: envelopes addressed to another recipient are ignored (not counted bad).
  std::string self_id;
  /// Expected job id; empty (a worker before the job is announced) accepts only JobAnnouncements.
  std::string job_id;
  /// Bad messages a sender may send before it is flagged for eviction.
  uint32_t bad_message_budget = 16;
  /// Where drop reasons go (default: stderr). Rate-limited: the first 5 per sender, then every 1000th.
  std::function<void(const std::string&)> log;
};

class MessageGate {
 public:
  enum class Verdict {
    kAccepted,  ///< valid: `envelope` is ready for use
    kIgnored,   ///< valid but not for us (other recipient, no job yet); not counted as bad
    kStale,     ///< valid but outdated (older epoch/level); counted, not bad
    kRejected,  ///< malformed or not allowed; counted against the sender's budget
  };
  struct Outcome {
    Verdict verdict = Verdict::kRejected;
    poseforest::v1::Envelope envelope;
    std::string sender;  ///< sender id, or "writer:<guid>" when the bytes did not parse
    std::string reason;  ///< short key ("job_id", "dimensions", ...), empty when accepted
    std::string detail;  ///< human-readable explanation
  };
  struct SenderStats {
    uint64_t accepted = 0, ignored = 0, stale = 0, rejected = 0;
    std::map<std::string, uint64_t> reasons;  ///< rejected + stale, by reason key
    bool flagged = false;
  };

  explicit MessageGate(GateConfig config);

  /// Checks one received sample. `writer_guid` is the DDS writer GUID ("prefix|entity") that
  /// identifies the sender when the bytes cannot be parsed, and binds each sender id to one
  /// participant and back (another participant claiming the id, or a participant switching
  /// ids to escape eviction, is rejected until Forget()).
  Outcome Check(Topic topic, std::span<const uint8_t> bytes, std::string_view writer_guid);

  void set_job_id(std::string job_id) { config_.job_id = std::move(job_id); }
  /// Workers: only this sender id may send job/control/status messages.
  void set_coordinator_id(std::string id) { coordinator_id_ = std::move(id); }
  void set_num_parts(uint32_t n) { num_parts_ = n; }
  /// Coordinator: the LevelRequest whose replies it is waiting for. Replies must match its tree,
  /// level, epoch, node ids and dimensions; older epochs are stale, anything else is rejected.
  void ExpectLevel(const poseforest::v1::LevelRequest& request);
  void ClearExpectedLevel() { expected_.reset(); }

  /// Senders that exceeded the budget since the last call (each reported once).
  std::vector<std::string> TakeOffenders();
  /// Drops all state about a sender (after an eviction or a lost liveliness), so a restarted
  /// process may reuse its id.
  void Forget(const std::string& sender);

  const SenderStats* stats(const std::string& sender) const;
  const std::map<std::string, SenderStats>& all_stats() const { return stats_; }
  uint64_t total_rejected() const { return total_rejected_; }

 private:
  Outcome Finish(Outcome out, Verdict verdict, std::string reason, std::string detail);
  core::Status CheckBody(const poseforest::v1::Envelope& env, Verdict* stale_or_ok);

  GateConfig config_;
  std::string coordinator_id_;
  uint32_t num_parts_ = 0;
  std::optional<poseforest::v1::LevelRequest> expected_;
  uint64_t newest_epoch_ = 0;  ///< newest LevelRequest/decisions epoch accepted
  std::map<std::string, SenderStats> stats_;
  std::map<std::pair<std::string, int>, uint64_t> last_sequence_;  ///< (sender, topic)
  std::map<std::string, std::string> participant_of_sender_;       ///< sender id -> GUID prefix
  std::map<std::string, std::string> sender_of_participant_;       ///< GUID prefix -> sender id
  std::map<std::string, std::string> sender_of_writer_;            ///< writer GUID -> sender id
  std::vector<std::string> offenders_;
  uint64_t total_rejected_ = 0;
};

}  // namespace poseforest::proto::dds
