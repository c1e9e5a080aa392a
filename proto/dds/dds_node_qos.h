#pragma once
// The participant QoS of a DdsNode (transports, discovery, security) from its NodeConfig
// (dds_node_qos.cpp). Internal to proto/dds: it shows Fast DDS types.

#include <chrono>
#include <cstdint>

#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>

#include "proto/dds/dds_node.h"

namespace poseforest::proto::dds {

inline eprosima::fastrtps::Duration_t ToDuration(std::chrono::milliseconds ms) {
  return eprosima::fastrtps::Duration_t(static_cast<int32_t>(ms.count() / 1000),
                          static_cast<uint32_t>((ms.count() % 1000) * 1000000));
}

/// The participant QoS for `config`: the XML profile's (kXmlProfile) or the defaults, with the
/// name, participant id, leases, transports, discovery and DDS-Security. Errors name what is wrong.
core::Status BuildParticipantQos(const NodeConfig& config, eprosima::fastdds::dds::DomainParticipantQos& qos);

}  // namespace poseforest::proto::dds
