#pragma once
// What the coordinator's and the workers' participants share: transport profiles, participant
// settings, address lists, worker ids. The messages are poseforest.v1
// (proto/poseforest/v1/wire.proto); engine/wire_codec.h converts the engine's histograms.

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "proto/dds/dds_flags.h"
#include "proto/dds/dds_node.h"
#include "runtime/core/result.h"

namespace poseforest::proto::dds {

/// Transport profile names accepted by --profile: "shm" (shared memory only), "udp" (UDPv4 only,
/// loopback + interfaces), "default" (shared memory + UDP). Errors name the bad value.
core::Result<TransportKind> ParseProfile(const std::string& name);

/// Participant settings of a trainer node on `domain` with `transport`, reading/writing the topics
/// of a coordinator (`coordinator` true) or a worker. `lease`: presence liveliness lease.
/// kUdpOnly: `peers` ("a.b.c.d[:port]") replace the default initial peer 127.0.0.1 (hosts without
/// multicast: workers list the coordinator), `interfaces` restricts the local IPv4 addresses used
/// (kUdpOnly, kDiscoveryClient). `extras`: the XML profile (kXmlProfile), the discovery server
/// (kDiscoveryClient) and DDS-Security credentials (any transport) of the --dds-xml,
/// --discovery-server and --security flags (dds_flags.h).
NodeConfig MakeNodeConfig(uint32_t domain, TransportKind transport, bool coordinator, const std::string& name,
                          std::chrono::milliseconds lease, const std::vector<std::string>& peers = {},
                          const std::vector<std::string>& interfaces = {},
                          const TransportExtras& extras = {});

/// Splits a comma-separated --peers / --interfaces value; InvalidArgument naming `flag` and the
/// entry for one that is not an IPv4 address, or with `allow_names` a host name (CheckHost;
/// the names are kept as written: CheckDdsSettings resolves them), with an optional :port when
/// `allow_port`. IPv6 addresses are refused by name.
core::Result<std::vector<std::string>> ParseAddressList(const std::string& value, const std::string& flag,
                                                        bool allow_port, bool allow_names = false);

/// Seconds on a monotonic clock.
double NowSeconds();

/// A worker id for a worker given none: "worker-HOST-PID-XXXXXX". Host and pid alone collide
/// between containers on the host network (each worker is pid 1 on the same hostname) and
/// between workers of one process: the coordinator would take two workers for one. XXXXXX (24
/// bits, hex) is a random number drawn once per process plus a per-process counter, so two ids
/// of one process always differ and those of different processes differ but by chance (2^-24).
std::string DefaultWorkerId();

}  // namespace poseforest::proto::dds
