#pragma once
// The DDS topics of the distributed trainer and their QoS. Every topic carries one serialized
// poseforest.v1.Envelope per sample (type name kEnvelopeTypeName); which bodies travel on which
// topic is listed in proto/poseforest/v1/wire.proto. No Fast DDS type appears here.
//
// QoS (applied by DdsNode, proto/dds/dds_node.cpp; docs/distributed/README.md explains why):
//   topic      reliability  durability        history        liveliness
//   job        RELIABLE     TRANSIENT_LOCAL   keep-last 1    AUTOMATIC, lease (coordinator presence)
//   control    RELIABLE     VOLATILE          keep-all       AUTOMATIC, infinite
//   replies    RELIABLE     VOLATILE          keep-all       AUTOMATIC, infinite
//   presence   RELIABLE     VOLATILE          keep-last 8    MANUAL_BY_TOPIC, lease (worker presence;
//                                                            AUTOMATIC selectable, see NodeConfig)
//   status     RELIABLE     TRANSIENT_LOCAL   keep-last 64   AUTOMATIC, infinite
// Keep-all writer histories are bounded by resource limits (kKeepAllMaxSamples): a full history
// makes the writer wait for the slowest live reader (flow control) instead of dropping a
// histogram; readers hold up to kKeepAllReaderMaxSamples and so never reject a sample.

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

namespace poseforest::proto::dds {

enum class Topic : uint8_t { kJob = 0, kControl, kReplies, kPresence, kStatus };
inline constexpr int kNumTopics = 5;
inline constexpr std::array<Topic, kNumTopics> kAllTopics = {Topic::kJob, Topic::kControl, Topic::kReplies,
                                                             Topic::kPresence, Topic::kStatus};

/// DDS type name registered for every topic.
inline constexpr const char* kEnvelopeTypeName = "poseforest::v1::Envelope";

/// Samples a keep-all writer holds unacknowledged before it blocks (flow control).
inline constexpr int kKeepAllMaxSamples = 256;
/// Samples a keep-all reader holds before it rejects more: far above any writer's history, so a
/// reader never rejects (Fast DDS 2.9 would not ask for a rejected sample again: the writer
/// stalled for good). The intake threads read them out as they arrive.
inline constexpr int kKeepAllReaderMaxSamples = 1 << 16;

/// DDS topic name ("poseforest/control").
inline constexpr const char* TopicName(Topic t) {
  switch (t) {
    case Topic::kJob: return "poseforest/job";
    case Topic::kControl: return "poseforest/control";
    case Topic::kReplies: return "poseforest/replies";
    case Topic::kPresence: return "poseforest/presence";
    case Topic::kStatus: return "poseforest/status";
  }
  return "poseforest/unknown";
}

/// Short name for logs ("control").
inline constexpr const char* TopicShortName(Topic t) { return TopicName(t) + 11; }

}  // namespace poseforest::proto::dds
