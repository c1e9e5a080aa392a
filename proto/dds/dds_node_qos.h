#pragma once
// The participant QoS of a DdsNode (transports, discovery, security) from its NodeConfig
// (dds_node_qos.cpp). Internal to proto/dds: it shows Fast DDS types.

#include <chrono>
#include <cstdint>
#include <set>
#include <string>

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

/// The lowest participant id of `domain`, not in `skip`, whose two shared-memory unicast ports
/// (metatraffic and user, RTPS's well-known numbers) leave no file in `shm_dir`: no port segment
/// ("fastrtps_port<N>") and no lock ("_el", "_sl"). -1 when every id up to the domain's last has one.
/// Fast DDS 2.9 takes over a port whose owner died (SIGKILL) without telling the processes that
/// still write to the dead one's segment: they write into the removed segment for ever, and never
/// hear the new participant (CI: a worker restarted after a SIGKILL, "0 of 1 lost worker(s) came
/// back"). A port with no file is held by nobody, so nobody holds a stale segment of it.
int FreshSharedMemoryParticipantId(uint32_t domain, const std::string& shm_dir, const std::set<int>& skip);

/// FreshSharedMemoryParticipantId on /dev/shm, skipping the ids this process took before; the id
/// returned is taken. BuildParticipantQos uses it for the transports with shared memory.
int TakeFreshSharedMemoryParticipantId(uint32_t domain);

}  // namespace poseforest::proto::dds
