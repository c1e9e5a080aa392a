#include "proto/dds/message_gate.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <set>

#include "proto/dds/build_id.h"
#include "runtime/core/crc32.h"

namespace poseforest::proto::dds {

namespace v1 = poseforest::v1;
using core::ErrorCode;
using core::Status;
using Body = v1::Envelope::BodyCase;

namespace {
Status Bad(std::string msg) { return Status(ErrorCode::kInvalidArgument, std::move(msg)); }
std::string S(uint64_t v) { return std::to_string(v); }
constexpr uint32_t kMaxNodesPerLevel = 1u << 20;
constexpr uint32_t kMaxCandidates = 4096;
constexpr uint32_t kMaxBins = 256;
constexpr uint32_t kMaxParts = 255;
constexpr uint32_t kMaxDepth = 64;
constexpr size_t kMaxHostname = 256;  // HOST_NAME_MAX is 64 on Linux
constexpr size_t kMaxRefusal = 2048;  // WorkerHello.refusal

Status ValidateRanges(const google::protobuf::RepeatedPtrField<v1::ImageRange>& ranges) {
  if (ranges.empty()) return Bad("no image ranges");
  for (const auto& r : ranges) {
    if (r.count() == 0) return Bad("empty image range");
    if (r.first_index() > std::numeric_limits<uint64_t>::max() - r.count()) return Bad("image range overflows");
  }
  return Status::Ok();
}

Status ValidateSplit(const v1::FeatureSplit& s) {
  for (int32_t o : {s.ux(), s.uy(), s.vx(), s.vy()})
    if (o < std::numeric_limits<int16_t>::min() || o > std::numeric_limits<int16_t>::max())
      return Bad("feature offset " + std::to_string(o) + " outside int16");
  if (!std::isfinite(s.threshold())) return Bad("non-finite threshold");
  return Status::Ok();
}

Status ValidateCapacity(const v1::WorkerCapacity& c) {
  if (c.threads() == 0 || c.threads() > 4096) return Bad("capacity threads " + S(c.threads()) + " out of 1..4096");
  if (c.renderer() == v1::RENDERER_KIND_UNSPECIFIED) return Bad("renderer kind unspecified");
  return Status::Ok();
}
}  // namespace

void EnvelopeStamper::Stamp(Topic topic, v1::Envelope& env) {
  env.set_job_id(job_id_);
  env.set_sender_id(sender_id_);
  env.set_sender_kind(kind_);
  env.set_protocol_version(kProtocolVersion);
  env.set_sequence(++sequence_[static_cast<int>(topic)]);
}

std::string EnvelopeStamper::Seal(Topic topic, v1::Envelope& env) {
  Stamp(topic, env);
  return env.SerializeAsString();
}

bool BodyAllowedOnTopic(Body body, Topic topic) {
  switch (body) {
    case v1::Envelope::kJob: return topic == Topic::kJob;
    case v1::Envelope::kHello:
    case v1::Envelope::kHeartbeat: return topic == Topic::kPresence;
    case v1::Envelope::kShard:
    case v1::Envelope::kLevelRequest:
    case v1::Envelope::kDecisions:
    case v1::Envelope::kSubtreeTask:
    case v1::Envelope::kSubtreeTasks: return topic == Topic::kControl;
    case v1::Envelope::kHistogram:
    case v1::Envelope::kSubtreeResult: return topic == Topic::kReplies;
    case v1::Envelope::kStatus: return topic == Topic::kStatus;
    case v1::Envelope::BODY_NOT_SET: return false;
  }
  return false;
}

v1::SenderKind SenderKindOfBody(Body body) {
  switch (body) {
    case v1::Envelope::kHello:
    case v1::Envelope::kHeartbeat:
    case v1::Envelope::kHistogram:
    case v1::Envelope::kSubtreeResult: return v1::SENDER_KIND_WORKER;
    case v1::Envelope::BODY_NOT_SET: return v1::SENDER_KIND_UNSPECIFIED;
    default: return v1::SENDER_KIND_COORDINATOR;
  }
}

const char* BodyName(Body body) {
  switch (body) {
    case v1::Envelope::kJob: return "JobAnnouncement";
    case v1::Envelope::kHello: return "WorkerHello";
    case v1::Envelope::kHeartbeat: return "Heartbeat";
    case v1::Envelope::kShard: return "ShardAssignment";
    case v1::Envelope::kLevelRequest: return "LevelRequest";
    case v1::Envelope::kHistogram: return "HistogramReply";
    case v1::Envelope::kDecisions: return "SplitDecisions";
    case v1::Envelope::kSubtreeTask: return "SubtreeTask";
    case v1::Envelope::kSubtreeTasks: return "SubtreeTasks";
    case v1::Envelope::kSubtreeResult: return "SubtreeResult";
    case v1::Envelope::kStatus: return "StatusEvent";
    case v1::Envelope::BODY_NOT_SET: return "none";
  }
  return "?";
}

Status ValidateJob(const v1::JobAnnouncement& m) {
  if (!m.has_config()) return Bad("job without config");
  if (m.coordinator_id().empty()) return Bad("job without coordinator id");
  if (m.num_parts() < 2 || m.num_parts() > kMaxParts) return Bad("num_parts " + S(m.num_parts()) + " out of 2..255");
  if (m.build_id().size() > kMaxBuildIdBytes) return Bad("build id of " + S(m.build_id().size()) + " bytes");
  if (m.thresholds_per_feature() < 1 || m.thresholds_per_feature() > kMaxBins)
    return Bad("thresholds_per_feature " + S(m.thresholds_per_feature()) + " out of 1..256");
  return Status::Ok();
}

namespace {
// Throughput figures of heartbeats and status events (monitoring): finite, >= 0, bounded.
constexpr double kMaxRate = 1e13;    // per second: ~10^4 of today's fastest workers
constexpr double kMaxSeconds = 1e9;  // ~32 years
constexpr uint64_t kMaxCount = uint64_t(1) << 62;
constexpr int kMaxStatusWorkers = 4096;
constexpr size_t kMaxWorkerId = 256;
constexpr int kMaxStatusLevels = 256;  // StatusEvent.levels (the coordinator sends at most 64)
constexpr double kMaxBits = 64;        // entropy and gain of a level row

Status ValidateFigure(const char* name, double v, double max) {
  if (!std::isfinite(v) || v < 0 || v > max) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", v);
    return Bad(std::string(name) + " " + buf + " outside 0.." + S(uint64_t(max)));
  }
  return Status::Ok();
}
}  // namespace

Status ValidateHello(const v1::WorkerHello& m) {
  POSEFOREST_RETURN_IF_ERROR(ValidateCapacity(m.capacity()));
  if (m.hostname().size() > kMaxHostname) return Bad("hostname of " + S(m.hostname().size()) + " bytes");
  if (m.build_version().size() > kMaxBuildIdBytes)
    return Bad("build version of " + S(m.build_version().size()) + " bytes");
  if (m.refusal().size() > kMaxRefusal) return Bad("refusal of " + S(m.refusal().size()) + " bytes");
  return Status::Ok();
}
Status ValidateHeartbeat(const v1::Heartbeat& m) {
  POSEFOREST_RETURN_IF_ERROR(ValidateCapacity(m.capacity()));
  if (m.busy_threads() > m.capacity().threads()) return Bad("busy threads above capacity");
  POSEFOREST_RETURN_IF_ERROR(ValidateFigure("evaluations_per_s", m.evaluations_per_s(), kMaxRate));
  if (m.evaluations() > kMaxCount) return Bad("evaluations " + S(m.evaluations()) + " above 2^62");
  return Status::Ok();
}

Status ValidateShard(const v1::ShardAssignment& m) {
  POSEFOREST_RETURN_IF_ERROR(ValidateRanges(m.ranges()));
  if (m.shard_count() == 0 || m.shard_index() >= m.shard_count())
    return Bad("shard " + S(m.shard_index()) + " of " + S(m.shard_count()));
  if (m.epoch() == 0) return Bad("epoch 0");
  return Status::Ok();
}

Status ValidateLevelRequest(const v1::LevelRequest& m) {
  if (m.epoch() == 0) return Bad("epoch 0");
  if (m.level() > kMaxDepth) return Bad("level " + S(m.level()) + " too deep");
  if (m.node_ids().empty() || static_cast<uint32_t>(m.node_ids_size()) > kMaxNodesPerLevel)
    return Bad(S(m.node_ids_size()) + " frontier nodes");
  if (m.candidate_seeds_size() != m.node_ids_size())
    return Bad(S(m.candidate_seeds_size()) + " candidate seeds for " + S(m.node_ids_size()) + " nodes");
  if (m.num_candidates() == 0 || m.num_candidates() > kMaxCandidates) return Bad("num_candidates " + S(m.num_candidates()));
  if (m.num_thresholds() == 0 || m.num_thresholds() > kMaxBins) return Bad("num_thresholds " + S(m.num_thresholds()));
  if (m.num_parts() < 2 || m.num_parts() > kMaxParts) return Bad("num_parts " + S(m.num_parts()));
  std::set<uint32_t> ids(m.node_ids().begin(), m.node_ids().end());
  if (ids.size() != static_cast<size_t>(m.node_ids_size())) return Bad("duplicate frontier node ids");
  return Status::Ok();
}

Status ValidateHistogramReply(const v1::HistogramReply& m) {
  const HistogramDims dims{m.num_candidates(), m.num_bins(), m.num_parts()};
  if (dims.num_candidates == 0 || dims.num_candidates > kMaxCandidates || dims.num_bins == 0 ||
      dims.num_bins > kMaxBins || dims.num_parts < 2 || dims.num_parts > kMaxParts)
    return Bad("histogram dimensions " + S(dims.num_candidates) + "x" + S(dims.num_bins) + "x" + S(dims.num_parts) +
               " out of range");
  if (m.nodes().empty()) return Bad("histogram reply without nodes");
  for (const auto& node : m.nodes()) POSEFOREST_RETURN_IF_ERROR(ValidateNodeHistogram(node, dims));
  return Status::Ok();
}

Status ValidateDecisions(const v1::SplitDecisions& m, uint32_t num_parts) {
  if (m.epoch() == 0) return Bad("epoch 0");
  if (m.nodes().empty()) return Bad("no decisions");
  std::set<uint32_t> ids;
  for (const auto& d : m.nodes()) {
    if (!ids.insert(d.node_id()).second) return Bad("duplicate decision for node " + S(d.node_id()));
    switch (d.kind_case()) {
      case v1::NodeDecision::kSplit:
        POSEFOREST_RETURN_IF_ERROR(ValidateSplit(d.split()));
        if (d.split().left_child() <= d.node_id()) return Bad("left child not after node " + S(d.node_id()));
        break;
      case v1::NodeDecision::kLeaf:
        if (d.leaf().part_counts().empty() ||
            (num_parts != 0 && static_cast<uint32_t>(d.leaf().part_counts_size()) != num_parts))
          return Bad("leaf of node " + S(d.node_id()) + " has " + S(d.leaf().part_counts_size()) + " part counts");
        break;
      case v1::NodeDecision::kDelegated: break;
      case v1::NodeDecision::KIND_NOT_SET: return Bad("decision without kind for node " + S(d.node_id()));
    }
  }
  return Status::Ok();
}

Status ValidateSubtreeTask(const v1::SubtreeTask& m) {
  if (m.epoch() == 0) return Bad("epoch 0");
  if (m.depth() > kMaxDepth) return Bad("depth " + S(m.depth()));
  if (static_cast<uint32_t>(m.path_size()) != m.depth())
    return Bad("path of " + S(m.path_size()) + " steps for depth " + S(m.depth()));
  for (const auto& step : m.path()) POSEFOREST_RETURN_IF_ERROR(ValidateSplit(step.split()));
  return ValidateRanges(m.ranges());
}

Status ValidateSubtreeTasks(const v1::SubtreeTasks& m) {
  if (m.tasks_size() == 0) return Bad("no subtree tasks");
  if (m.tasks_size() > kMaxSubtreeTasks)
    return Bad(S(uint64_t(m.tasks_size())) + " subtree tasks above " + S(uint64_t(kMaxSubtreeTasks)));
  for (int i = 0; i < m.tasks_size(); ++i) {
    if (m.tasks(i).tree() != m.tasks(0).tree())
      return Bad("task " + S(uint64_t(i)) + " of tree " + S(m.tasks(i).tree()) + ", the first of tree " +
                 S(m.tasks(0).tree()));
    if (Status st = ValidateSubtreeTask(m.tasks(i)); !st.ok())
      return Status(st.code(), "task " + S(uint64_t(i)) + ": " + st.message());
  }
  return Status::Ok();
}

Status ValidateSubtreeResult(const v1::SubtreeResult& m) {
  constexpr uint64_t kNodeBytes = 16;
  if (m.num_nodes() == 0) return Bad("empty subtree");
  if (m.num_parts() < 2 || m.num_parts() > kMaxParts) return Bad("num_parts " + S(m.num_parts()));
  if (m.nodes().size() != m.num_nodes() * kNodeBytes)
    return Bad(S(m.nodes().size()) + " node bytes for " + S(m.num_nodes()) + " nodes");
  const uint64_t stride = (uint64_t(m.num_parts()) + 15) / 16 * 16;
  if (m.leaves().size() != m.num_leaves() * stride)
    return Bad(S(m.leaves().size()) + " leaf bytes for " + S(m.num_leaves()) + " leaves");
  if (m.num_leaves() == 0 || m.num_leaves() > m.num_nodes()) return Bad("leaf count " + S(m.num_leaves()));
  uint32_t crc = core::Crc32(m.nodes().data(), m.nodes().size());
  crc = core::Crc32(m.leaves().data(), m.leaves().size(), crc);
  if (crc != m.crc32()) return Status(ErrorCode::kDataLoss, "subtree CRC mismatch");
  return Status::Ok();
}

Status ValidateStatus(const v1::StatusEvent& m) {
  if (m.kind() == v1::STATUS_KIND_UNSPECIFIED) return Bad("status kind unspecified");
  if (!(m.progress() >= 0.0 && m.progress() <= 1.0)) return Bad("progress outside 0..1");
  POSEFOREST_RETURN_IF_ERROR(ValidateFigure("samples_per_s", m.samples_per_s(), kMaxRate));
  POSEFOREST_RETURN_IF_ERROR(ValidateFigure("evaluations_per_s", m.evaluations_per_s(), kMaxRate));
  if (m.has_eta_s()) POSEFOREST_RETURN_IF_ERROR(ValidateFigure("eta_s", m.eta_s(), kMaxSeconds));
  POSEFOREST_RETURN_IF_ERROR(ValidateFigure("elapsed_s", m.elapsed_s(), kMaxSeconds));
  if (m.level_nodes_done() > m.level_nodes_total()) return Bad("level nodes done above total");
  for (uint64_t c : {m.forest_nodes(), m.evaluations(), m.bytes_received(), m.retries()})
    if (c > kMaxCount) return Bad("count " + S(c) + " above 2^62");
  if (m.workers_size() > kMaxStatusWorkers)
    return Bad(S(uint64_t(m.workers_size())) + " workers above 4096");
  if (m.levels_size() > kMaxStatusLevels) return Bad(S(uint64_t(m.levels_size())) + " levels above 256");
  for (const v1::LevelStatus& l : m.levels()) {
    const std::string at = "level row tree " + S(l.tree()) + " level " + S(l.level()) + ": ";
    if (l.level() > kMaxDepth) return Bad(at + "too deep");
    if (l.split() > l.nodes() || l.nodes() > kMaxCount || l.samples() > kMaxCount || l.evaluations() > kMaxCount)
      return Bad(at + "counts above 2^62 or more split than frontier nodes");
    if (!(l.entropy() >= 0.0 && l.entropy() <= kMaxBits) || !(l.gain() >= 0.0 && l.gain() <= kMaxBits))
      return Bad(at + "entropy or gain outside 0..64 bits");
    POSEFOREST_RETURN_IF_ERROR(ValidateFigure("level evaluations_per_s", l.evaluations_per_s(), kMaxRate));
    POSEFOREST_RETURN_IF_ERROR(ValidateFigure("level seconds", l.seconds(), kMaxSeconds));
  }
  for (const v1::WorkerStatus& w : m.workers()) {
    if (w.id().empty() || w.id().size() > kMaxWorkerId)
      return Bad("worker id of " + S(w.id().size()) + " bytes");
    if (w.state() == v1::WORKER_STATE_UNSPECIFIED) return Bad("worker " + w.id() + ": state unspecified");
    POSEFOREST_RETURN_IF_ERROR(ValidateFigure("worker evaluations_per_s", w.evaluations_per_s(), kMaxRate));
    if (!std::isfinite(w.last_seen_s()) || w.last_seen_s() > kMaxSeconds)
      return Bad("worker " + w.id() + ": last_seen_s not finite or above 1e9");
    if (w.evaluations() > kMaxCount || w.frames() > kMaxCount || w.replies() > kMaxCount)
      return Bad("worker " + w.id() + ": count above 2^62");
  }
  return Status::Ok();
}

MessageGate::MessageGate(GateConfig config) : config_(std::move(config)) {
  if (!config_.log) config_.log = [](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); };
}

MessageGate::Outcome MessageGate::Finish(Outcome out, Verdict verdict, std::string reason, std::string detail) {
  out.verdict = verdict;
  out.reason = std::move(reason);
  out.detail = std::move(detail);
  SenderStats& st = stats_[out.sender];
  switch (verdict) {
    case Verdict::kAccepted: ++st.accepted; break;
    case Verdict::kIgnored: ++st.ignored; break;
    case Verdict::kStale: {
      const uint64_t n = ++st.reasons[out.reason];
      ++st.stale;
      if (n <= 5 || n % 1000 == 0)
        config_.log("[gate] stale message from " + out.sender + " (" + out.reason + ", #" + S(n) + "): " + out.detail);
      break;
    }
    case Verdict::kRejected: {
      ++total_rejected_;
      ++st.rejected;
      const uint64_t n = ++st.reasons[out.reason];
      if (st.rejected <= 5 || st.rejected % 1000 == 0)
        config_.log("[gate] dropped message from " + out.sender + " (" + out.reason + ", #" + S(n) +
                    " of this kind, " + S(st.rejected) + " bad in all): " + out.detail);
      if (!st.flagged && st.rejected > config_.bad_message_budget) {
        st.flagged = true;
        offenders_.push_back(out.sender);
        config_.log("[gate] sender " + out.sender + " exceeded the bad-message budget (" +
                    S(config_.bad_message_budget) + "): flagged for eviction");
      }
      break;
    }
  }
  return out;
}

MessageGate::Outcome MessageGate::Check(Topic topic, std::span<const uint8_t> bytes, std::string_view writer_guid) {
  Outcome out;
  const std::string guid(writer_guid);
  const std::string participant = guid.substr(0, guid.find('|'));
  if (auto it = sender_of_writer_.find(guid); it != sender_of_writer_.end()) {
    out.sender = it->second;
  } else {
    out.sender = "writer:" + guid;
  }
  if (auto it = stats_.find(out.sender); it != stats_.end() && it->second.flagged)
    return Finish(std::move(out), Verdict::kRejected, "evicted", "sender is flagged");

  if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max()) ||
      !out.envelope.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())))
    return Finish(std::move(out), Verdict::kRejected, "unparseable",
                  S(bytes.size()) + " bytes on " + TopicShortName(topic) + " are not an Envelope");
  const v1::Envelope& env = out.envelope;
  if (env.sender_id().empty())
    return Finish(std::move(out), Verdict::kRejected, "no_sender", "envelope without sender id");
  // From here on the sender is named by its id, bound to the participant that first used it.
  if (auto it = participant_of_sender_.find(env.sender_id());
      it != participant_of_sender_.end() && it->second != participant) {
    return Finish(std::move(out), Verdict::kRejected, "impersonation",
                  "sender id '" + env.sender_id() + "' belongs to participant " + it->second + ", not " + participant);
  }
  if (auto it = sender_of_participant_.find(participant);
      it != sender_of_participant_.end() && it->second != env.sender_id()) {
    return Finish(std::move(out), Verdict::kRejected, "impersonation",
                  "participant " + participant + " speaks as '" + it->second + "', not '" + env.sender_id() + "'");
  }
  out.sender = env.sender_id();
  // Bind now, so later garbage from this writer is blamed on the id it used.
  participant_of_sender_.emplace(env.sender_id(), participant);
  sender_of_participant_.emplace(participant, env.sender_id());
  sender_of_writer_[guid] = env.sender_id();
  if (auto it = stats_.find(out.sender); it != stats_.end() && it->second.flagged)
    return Finish(std::move(out), Verdict::kRejected, "evicted", "sender is flagged");

  if (env.protocol_version() != kProtocolVersion)
    return Finish(std::move(out), Verdict::kRejected, "protocol_version",
                  "protocol version " + S(env.protocol_version()) + ", this build speaks " + S(kProtocolVersion));
  const Body body = env.body_case();
  if (body == v1::Envelope::BODY_NOT_SET)
    return Finish(std::move(out), Verdict::kRejected, "no_body", "envelope without body (or of a newer protocol)");
  if (!BodyAllowedOnTopic(body, topic))
    return Finish(std::move(out), Verdict::kRejected, "wrong_topic",
                  std::string(BodyName(body)) + " on topic " + TopicShortName(topic));
  if (env.sender_kind() != SenderKindOfBody(body))
    return Finish(std::move(out), Verdict::kRejected, "sender_kind",
                  std::string(BodyName(body)) + " from a sender of kind " + v1::SenderKind_Name(env.sender_kind()));
  if (SenderKindOfBody(body) == v1::SENDER_KIND_COORDINATOR && !coordinator_id_.empty() &&
      env.sender_id() != coordinator_id_)
    return Finish(std::move(out), Verdict::kRejected, "not_coordinator",
                  std::string(BodyName(body)) + " from '" + env.sender_id() + "', coordinator is '" + coordinator_id_ + "'");
  if (config_.job_id.empty()) {
    if (body != v1::Envelope::kJob)
      return Finish(std::move(out), Verdict::kIgnored, "no_job", "no job announced yet");
  } else if (env.job_id() != config_.job_id) {
    return Finish(std::move(out), Verdict::kRejected, "job_id",
                  "job '" + env.job_id() + "', expected '" + config_.job_id + "'");
  }
  if (!env.recipient_id().empty() && env.recipient_id() != config_.self_id)
    return Finish(std::move(out), Verdict::kIgnored, "recipient", "for " + env.recipient_id());

  const auto key = std::make_pair(env.sender_id(), static_cast<int>(topic));
  if (env.sequence() == 0)
    return Finish(std::move(out), Verdict::kRejected, "sequence", "sequence 0");
  if (auto it = last_sequence_.find(key); it != last_sequence_.end() && env.sequence() <= it->second)
    return Finish(std::move(out), Verdict::kRejected, "sequence",
                  "sequence " + S(env.sequence()) + " not above " + S(it->second) + " on " + TopicShortName(topic));

  Verdict verdict = Verdict::kAccepted;
  if (Status st = CheckBody(env, &verdict); !st.ok())
    return Finish(std::move(out), Verdict::kRejected, "body",
                  std::string(BodyName(body)) + ": " + st.message());
  // The sequence advances for stale messages too: they were genuine.
  last_sequence_[key] = env.sequence();
  if (verdict == Verdict::kStale) {
    uint64_t epoch = 0;
    if (body == v1::Envelope::kHistogram) epoch = env.histogram().epoch();
    if (body == v1::Envelope::kLevelRequest) epoch = env.level_request().epoch();
    if (body == v1::Envelope::kDecisions) epoch = env.decisions().epoch();
    return Finish(std::move(out), Verdict::kStale, "stale_epoch",
                  std::string(BodyName(body)) + " of epoch " + S(epoch) + ", current " +
                      S(expected_ ? expected_->epoch() : newest_epoch_));
  }
  if (body == v1::Envelope::kLevelRequest) newest_epoch_ = std::max(newest_epoch_, env.level_request().epoch());
  if (body == v1::Envelope::kDecisions) newest_epoch_ = std::max(newest_epoch_, env.decisions().epoch());
  return Finish(std::move(out), Verdict::kAccepted, "", "");
}

Status MessageGate::CheckBody(const v1::Envelope& env, Verdict* verdict) {
  switch (env.body_case()) {
    case v1::Envelope::kJob:
      POSEFOREST_RETURN_IF_ERROR(ValidateJob(env.job()));
      if (env.job().coordinator_id() != env.sender_id()) return Bad("job announced by someone else than its coordinator");
      return Status::Ok();
    case v1::Envelope::kHello: return ValidateHello(env.hello());
    case v1::Envelope::kHeartbeat: return ValidateHeartbeat(env.heartbeat());
    case v1::Envelope::kShard: return ValidateShard(env.shard());
    case v1::Envelope::kLevelRequest: {
      const auto& m = env.level_request();
      POSEFOREST_RETURN_IF_ERROR(ValidateLevelRequest(m));
      if (num_parts_ != 0 && m.num_parts() != num_parts_)
        return Bad("num_parts " + S(m.num_parts()) + ", job has " + S(num_parts_));
      if (m.epoch() < newest_epoch_) *verdict = Verdict::kStale;
      return Status::Ok();
    }
    case v1::Envelope::kHistogram: {
      const auto& m = env.histogram();
      if (!expected_) {
        *verdict = Verdict::kStale;  // nothing outstanding: a late reply to a finished level
        return Status::Ok();
      }
      const auto& req = *expected_;
      if (m.epoch() < req.epoch()) {
        *verdict = Verdict::kStale;
        return Status::Ok();
      }
      if (m.epoch() > req.epoch()) return Bad("epoch " + S(m.epoch()) + " from the future (current " + S(req.epoch()) + ")");
      if (m.tree() != req.tree() || m.level() != req.level())
        return Bad("tree/level " + S(m.tree()) + "/" + S(m.level()) + ", requested " + S(req.tree()) + "/" + S(req.level()));
      if (m.num_candidates() != req.num_candidates() || m.num_bins() != req.num_thresholds() ||
          m.num_parts() != req.num_parts())
        return Bad("dimensions " + S(m.num_candidates()) + "x" + S(m.num_bins()) + "x" + S(m.num_parts()) +
                   ", requested " + S(req.num_candidates()) + "x" + S(req.num_thresholds()) + "x" + S(req.num_parts()));
      if (m.nodes_size() != req.node_ids_size())
        return Bad(S(m.nodes_size()) + " nodes, requested " + S(req.node_ids_size()));
      for (int i = 0; i < m.nodes_size(); ++i)
        if (m.nodes(i).node_id() != req.node_ids(i))
          return Bad("node " + S(i) + " is " + S(m.nodes(i).node_id()) + ", requested " + S(req.node_ids(i)));
      return ValidateHistogramReply(m);
    }
    case v1::Envelope::kDecisions:
      POSEFOREST_RETURN_IF_ERROR(ValidateDecisions(env.decisions(), num_parts_));
      if (env.decisions().epoch() < newest_epoch_) *verdict = Verdict::kStale;
      return Status::Ok();
    case v1::Envelope::kSubtreeTask: return ValidateSubtreeTask(env.subtree_task());
    case v1::Envelope::kSubtreeTasks: return ValidateSubtreeTasks(env.subtree_tasks());
    case v1::Envelope::kSubtreeResult: {
      POSEFOREST_RETURN_IF_ERROR(ValidateSubtreeResult(env.subtree_result()));
      if (num_parts_ != 0 && env.subtree_result().num_parts() != num_parts_)
        return Bad("num_parts " + S(env.subtree_result().num_parts()) + ", job has " + S(num_parts_));
      return Status::Ok();
    }
    case v1::Envelope::kStatus: return ValidateStatus(env.status());
    case v1::Envelope::BODY_NOT_SET: return Bad("no body");
  }
  return Bad("unknown body");
}

void MessageGate::ExpectLevel(const v1::LevelRequest& request) {
  expected_ = request;
  newest_epoch_ = std::max(newest_epoch_, request.epoch());
}

std::vector<std::string> MessageGate::TakeOffenders() {
  std::vector<std::string> out;
  out.swap(offenders_);
  return out;
}

void MessageGate::Forget(const std::string& sender) {
  stats_.erase(sender);
  participant_of_sender_.erase(sender);
  for (auto it = sender_of_participant_.begin(); it != sender_of_participant_.end();)
    it = it->second == sender ? sender_of_participant_.erase(it) : std::next(it);
  for (auto it = last_sequence_.begin(); it != last_sequence_.end();)
    it = it->first.first == sender ? last_sequence_.erase(it) : std::next(it);
  for (auto it = sender_of_writer_.begin(); it != sender_of_writer_.end();)
    it = it->second == sender ? sender_of_writer_.erase(it) : std::next(it);
}

const MessageGate::SenderStats* MessageGate::stats(const std::string& sender) const {
  auto it = stats_.find(sender);
  return it == stats_.end() ? nullptr : &it->second;
}

}  // namespace poseforest::proto::dds
