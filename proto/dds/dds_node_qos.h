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

/// Holds a host-wide lock on `path` (flock, waiting at most `wait`) from construction until
/// destruction: DdsNode::Create holds it on kParticipantIdLockPath from choosing a fresh id
/// (BuildParticipantQos) until the participant has opened its ports. Without it two processes
/// started together (two workers, a coordinator) saw the same files, took the same id, and one of
/// them was then heard by nobody, or heard nobody (test_deploy's secure workers under load: 2 of 42
/// runs, "sw-1 joined (1 alive)", both printing "id 3 asked"). held() is false when the lock could
/// not be had in time (a process stuck while holding it) or the file not opened: the caller goes
/// on without it, as before the lock.
class HostLock {
 public:
  HostLock(const std::string& path, std::chrono::milliseconds wait);
  ~HostLock();
  HostLock(const HostLock&) = delete;
  HostLock& operator=(const HostLock&) = delete;
  bool held() const { return held_; }

 private:
  int fd_ = -1;
  bool held_ = false;
};

/// The lock file of the participant-id choice: in /dev/shm beside the ports it is about, so every
/// process that sees those ports (network namespaces included) sees it.
inline constexpr const char* kParticipantIdLockPath = "/dev/shm/poseforest_participant_ids.lock";

/// Whether BuildParticipantQos would choose a fresh shared-memory id for `config` (no pinned id,
/// a transport with shared memory; an XML profile only when it is shared memory only and pins no
/// id, which needs the profile: true here, the lock is cheap).
bool MayTakeFreshParticipantId(const NodeConfig& config);

}  // namespace poseforest::proto::dds
