#include "proto/dds/dds_node_qos.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

namespace poseforest::proto::dds {

namespace fdds = eprosima::fastdds::dds;
namespace frtps = eprosima::fastrtps::rtps;
using core::ErrorCode;
using core::Status;

namespace {

/// "a.b.c.d" or "a.b.c.d:port" -> address, port (0 when absent).
core::Result<std::pair<std::string, uint32_t>> ParseHostPort(const std::string& text) {
  std::string host = text;
  uint32_t port = 0;
  if (auto colon = text.rfind(':'); colon != std::string::npos) {
    host = text.substr(0, colon);
    const std::string p = text.substr(colon + 1);
    char* end = nullptr;
    const unsigned long v = std::strtoul(p.c_str(), &end, 10);
    if (p.empty() || *end != '\0' || v == 0 || v > 65535)
      return Status(ErrorCode::kInvalidArgument, "bad port in '" + text + "'");
    port = static_cast<uint32_t>(v);
  }
  if (!frtps::IPLocator::isIPv4(host))
    return Status(ErrorCode::kInvalidArgument, "not an IPv4 address: '" + text + "'");
  return std::make_pair(host, port);
}

std::shared_ptr<eprosima::fastdds::rtps::UDPv4TransportDescriptor> UdpTransport(const NodeConfig& config) {
  auto d = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  d->sendBufferSize = config.udp_buffer_bytes;
  d->receiveBufferSize = config.udp_buffer_bytes;
  for (const auto& ip : config.interface_whitelist) d->interfaceWhiteList.push_back(ip);
  return d;
}

std::shared_ptr<eprosima::fastdds::rtps::SharedMemTransportDescriptor> ShmTransport() {
  auto d = std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>();
  d->segment_size(8u << 20);  // whole 1 MiB+ samples fit without waiting for the reader
  return d;
}

/// kUdpOnly: the initial peers' metatraffic locators.
Status AddInitialPeers(const NodeConfig& config, frtps::BuiltinAttributes& builtin) {
  const uint32_t d = config.domain_id;
  for (const auto& peer : config.initial_peers) {
    auto hp = ParseHostPort(peer);
    if (!hp.ok()) return Status(ErrorCode::kInvalidArgument, "initial peer: " + hp.status().message());
    std::vector<uint32_t> ports;
    if (hp->second != 0) {
      ports.push_back(hp->second);
    } else {
      // RTPS well-known metatraffic unicast port: PB + DG*domain + d1 + PG*participant_id.
      for (int id = 0; id < config.peer_participant_ids; ++id) ports.push_back(7400 + 250 * d + 10 + 2 * id);
    }
    for (uint32_t port : ports) {
      frtps::Locator_t loc;
      loc.kind = LOCATOR_KIND_UDPv4;
      frtps::IPLocator::setIPv4(loc, hp->first);
      loc.port = port;
      builtin.initialPeersList.push_back(loc);
    }
  }
  return Status::Ok();
}

/// kDiscoveryClient: a client of every listed server.
Status AddDiscoveryServers(const NodeConfig& config, frtps::BuiltinAttributes& builtin) {
  auto servers = ParseDiscoveryServers(config.discovery_server);
  if (!servers.ok())
    return Status(ErrorCode::kInvalidArgument, "discovery server: " + servers.status().message());
  builtin.discovery_config.discoveryProtocol = frtps::DiscoveryProtocol_t::CLIENT;
  for (const DiscoveryServerAddress& a : *servers) {
    // A client of every listed server: each one is known by its GUID prefix (the -i of
    // fast-discovery-server) and reached at its locator; a wrong prefix never matches.
    eprosima::fastdds::rtps::RemoteServerAttributes server;
    const std::string prefix =
        a.id_given ? DiscoveryServerGuidPrefix(a.id) : config.discovery_server_prefix;
    if (!server.ReadguidPrefix(prefix.c_str()))
      return Status(ErrorCode::kInvalidArgument, "bad discovery server GUID prefix '" + prefix + "'");
    if (!IsIPv4Address(a.host))  // names are resolved once, by the DDS flags (dds_flags.h)
      return Status(ErrorCode::kInvalidArgument, "discovery server '" + a.host +
                                                     "': a host name; the participant needs its IPv4 address");
    frtps::Locator_t loc;
    loc.kind = LOCATOR_KIND_UDPv4;
    frtps::IPLocator::setIPv4(loc, a.host);
    loc.port = a.port;
    server.metatrafficUnicastLocatorList.push_back(loc);
    builtin.discovery_config.m_DiscoveryServers.push_back(server);
  }
  return Status::Ok();
}

/// DDS-Security's builtin plugins on the (absolute, readable) files of `s`.
Status AddSecurity(const SecurityFiles& s, fdds::DomainParticipantQos& qos) {
  for (const std::string* path : {&s.identity_ca, &s.identity_certificate, &s.private_key, &s.permissions_ca,
                                  &s.governance, &s.permissions}) {
    if (path->empty() || (*path)[0] != '/')
      return Status(ErrorCode::kInvalidArgument, "security file paths must be absolute: '" + *path + "'");
    if (FILE* f = std::fopen(path->c_str(), "rb")) {
      std::fclose(f);
    } else {
      return Status(ErrorCode::kIo, "cannot read security file " + *path);
    }
  }
  auto& props = qos.properties().properties();
  auto add = [&](const char* name, const std::string& value) { props.emplace_back(name, value); };
  add("dds.sec.auth.plugin", "builtin.PKI-DH");
  add("dds.sec.auth.builtin.PKI-DH.identity_ca", "file://" + s.identity_ca);
  add("dds.sec.auth.builtin.PKI-DH.identity_certificate", "file://" + s.identity_certificate);
  add("dds.sec.auth.builtin.PKI-DH.private_key", "file://" + s.private_key);
  add("dds.sec.access.plugin", "builtin.Access-Permissions");
  add("dds.sec.access.builtin.Access-Permissions.permissions_ca", "file://" + s.permissions_ca);
  add("dds.sec.access.builtin.Access-Permissions.governance", "file://" + s.governance);
  add("dds.sec.access.builtin.Access-Permissions.permissions", "file://" + s.permissions);
  add("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
  return Status::Ok();
}

/// Ids this process gave its shared-memory participants: never given twice. A participant that
/// replaces an earlier one of this process (a worker after a lost coordinator) must not take the
/// earlier one's ports either: its peers still hold the old segments.
std::mutex fresh_ids_mu;
std::set<int> fresh_ids_given;

/// An XML profile's transports: shared memory only (deploy/'s poseforest_shm).
bool SharedMemoryOnly(const fdds::DomainParticipantQos& qos) {
  const auto& t = qos.transport();
  if (t.use_builtin_transports || t.user_transports.empty()) return false;
  for (const auto& d : t.user_transports)
    if (!std::dynamic_pointer_cast<eprosima::fastdds::rtps::SharedMemTransportDescriptor>(d)) return false;
  return true;
}

}  // namespace

int FreshSharedMemoryParticipantId(uint32_t domain, const std::string& shm_dir, const std::set<int>& skip) {
  namespace fs = std::filesystem;
  const uint32_t base = 7400 + 250 * domain;  // RTPS: PB + DG * domain
  auto leaves_file = [&](uint32_t port) {
    const std::string name = "fastrtps_port" + std::to_string(port);
    std::error_code ec;
    for (const char* suffix : {"", "_el", "_sl"})
      if (fs::exists(fs::path(shm_dir) / (name + suffix), ec)) return true;
    return false;
  };
  // Ids up to 119 (Fast DDS's ports stay below 65536 for every domain it accepts up to there).
  for (int id = 0; id < 120; ++id) {
    const uint32_t meta = base + 10 + 2 * uint32_t(id), user = base + 11 + 2 * uint32_t(id);
    if (user > 65535) break;
    if (skip.count(id)) continue;
    if (!leaves_file(meta) && !leaves_file(user)) return id;
  }
  return -1;
}

int TakeFreshSharedMemoryParticipantId(uint32_t domain) {
  std::lock_guard<std::mutex> lock(fresh_ids_mu);
  const int id = FreshSharedMemoryParticipantId(domain, "/dev/shm", fresh_ids_given);
  if (id >= 0) fresh_ids_given.insert(id);
  return id;
}

HostLock::HostLock(const std::string& path, std::chrono::milliseconds wait) {
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  if (fd_ < 0) return;
  ::fchmod(fd_, 0666);  // shared by every user's processes on the host (the umask would narrow it)
  const auto deadline = std::chrono::steady_clock::now() + wait;
  for (;;) {
    if (::flock(fd_, LOCK_EX | LOCK_NB) == 0) {
      held_ = true;
      return;
    }
    if (errno != EWOULDBLOCK && errno != EINTR) return;
    if (std::chrono::steady_clock::now() >= deadline) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

HostLock::~HostLock() {
  if (fd_ >= 0) ::close(fd_);  // closing the descriptor drops the lock
}

bool MayTakeFreshParticipantId(const NodeConfig& config) {
  return config.participant_id < 0 && (config.transport == TransportKind::kDefault ||
                                       config.transport == TransportKind::kSharedMemoryOnly ||
                                       config.transport == TransportKind::kXmlProfile);
}

Status BuildParticipantQos(const NodeConfig& config, fdds::DomainParticipantQos& qos) {
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  qos = fdds::PARTICIPANT_QOS_DEFAULT;
  if (config.transport == TransportKind::kXmlProfile) {
    if (factory->load_XML_profiles_file(config.xml_file) != ReturnCode_t::RETCODE_OK)
      return Status(ErrorCode::kInvalidArgument, "cannot load Fast DDS XML profiles from " + config.xml_file);
    if (factory->get_participant_qos_from_profile(config.xml_profile, qos) != ReturnCode_t::RETCODE_OK)
      return Status(ErrorCode::kNotFound,
                    "no participant profile '" + config.xml_profile + "' in " + config.xml_file);
  }
  qos.name(config.participant_name);
  if (config.participant_id >= 0) {
    qos.wire_protocol().participant_id = config.participant_id;
  } else if (config.transport == TransportKind::kDefault || config.transport == TransportKind::kSharedMemoryOnly ||
             (config.transport == TransportKind::kXmlProfile && qos.wire_protocol().participant_id < 0 &&
              SharedMemoryOnly(qos))) {
    // Ports no dead process left behind (FreshSharedMemoryParticipantId); automatic when none is.
    // Not for an XML profile with UDP: its peers may list ports of ids 0..3 only.
    qos.wire_protocol().participant_id = TakeFreshSharedMemoryParticipantId(config.domain_id);
  }
  auto& builtin = qos.wire_protocol().builtin;
  if (config.transport != TransportKind::kXmlProfile) {
    builtin.discovery_config.leaseDuration = ToDuration(config.participant_lease);
    builtin.discovery_config.leaseDuration_announcementperiod = ToDuration(config.participant_lease / 4);
  }
  for (const auto& ip : config.interface_whitelist)
    if (!frtps::IPLocator::isIPv4(ip))
      return Status(ErrorCode::kInvalidArgument, "interface whitelist entry is not an IPv4 address: '" + ip + "'");

  switch (config.transport) {
    case TransportKind::kDefault:
      qos.transport().use_builtin_transports = false;
      qos.transport().user_transports.push_back(ShmTransport());
      qos.transport().user_transports.push_back(UdpTransport(config));
      break;
    case TransportKind::kSharedMemoryOnly:
      qos.transport().use_builtin_transports = false;
      qos.transport().user_transports.push_back(ShmTransport());
      break;
    case TransportKind::kUdpOnly:
      qos.transport().use_builtin_transports = false;
      qos.transport().user_transports.push_back(UdpTransport(config));
      POSEFOREST_RETURN_IF_ERROR(AddInitialPeers(config, builtin));
      break;
    case TransportKind::kDiscoveryClient:
      qos.transport().use_builtin_transports = false;
      qos.transport().user_transports.push_back(UdpTransport(config));
      POSEFOREST_RETURN_IF_ERROR(AddDiscoveryServers(config, builtin));
      break;
    case TransportKind::kXmlProfile: break;
  }

  if (config.security.enabled()) POSEFOREST_RETURN_IF_ERROR(AddSecurity(config.security, qos));
  return Status::Ok();
}

}  // namespace poseforest::proto::dds
