#pragma once
// The DDS flags shared by every command that joins Fast DDS (`coordinator`, `worker`,
// `train --local-workers`, `monitor --domain`): how the participant reaches its peers and with
// which credentials. docs/distributed/README.md ("Transports and deployment profiles").
//
//   --profile shm|udp|default   built-in transports (default shm)
//   --peers HOST[:PORT],...     --profile udp: initial peers (IPv4 addresses or host names)
//   --interfaces IP,...         --profile udp or --discovery-server: local addresses to use
//   --dds-xml FILE --dds-profile NAME   a Fast DDS XML participant profile (deploy/fastdds/profiles.xml);
//                               env POSEFOREST_DDS_XML / POSEFOREST_DDS_PROFILE when no transport flag is
//                               given
//   --discovery-server [ID@]HOST[:PORT],...  discovery through fast-discovery-server -i ID (default
//                               0, port 11811): a client of every listed server (UDP, no multicast)
//
// Host names (--peers, --discovery-server) are resolved to IPv4 addresses once, by ParseDdsFlags
// at start-up (getaddrinfo, AF_INET), never again: Fast DDS 2.9 fixes a participant's initial
// peers and server locators when it is created. IPv6 addresses are refused (UDPv4 transports).
//   --security DIR              DDS-Security with the six files of DIR (deploy/security/make-test-ca.sh)

#include <array>
#include <chrono>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "proto/dds/dds_node.h"
#include "runtime/core/result.h"

namespace poseforest::proto::dds {

/// Transport settings beyond the profile, peers and interfaces; empty fields are unused.
struct TransportExtras {
  std::string xml_file;     ///< kXmlProfile: absolute path of the Fast DDS XML file
  std::string xml_profile;  ///< kXmlProfile: participant profile name in it
  /// kDiscoveryClient: the servers, canonical "a.b.c.d:port" (id 0) or "ID@a.b.c.d:port", comma-
  /// separated (FormatDiscoveryServers); one id-0 server is "a.b.c.d:port" as before.
  std::string discovery_server;
  SecurityFiles security;  ///< DDS-Security on any transport when enabled() (absolute paths)
  /// Flow-control settings of the keep-all topics (NodeConfig): tests lower them to fill a
  /// history at CI size; 0 / the default: the node's.
  int keep_all_max_samples = 0;
  std::chrono::milliseconds write_block_slice{10000};
};

/// The value options ParseDdsFlags reads (to register with a command's argument parser).
inline constexpr std::array<const char*, 7> kDdsValueOptions = {
    "profile", "peers", "interfaces", "dds-xml", "dds-profile", "discovery-server", "security"};

/// Environment fallbacks of --dds-xml / --dds-profile.
inline constexpr const char* kEnvDdsXml = "POSEFOREST_DDS_XML";
inline constexpr const char* kEnvDdsProfile = "POSEFOREST_DDS_PROFILE";

/// A host name of --peers or --discovery-server and what it resolved to.
struct ResolvedHost {
  std::string flag;                    ///< "--peers" or "--discovery-server"
  std::string name;                    ///< as written
  std::vector<std::string> addresses;  ///< its IPv4 addresses, getaddrinfo's order, no repeats
};

/// The IPv4 addresses of host name `name` (getaddrinfo with AF_INET: /etc/hosts, DNS, search
/// domains as the system resolves them), in getaddrinfo's order without repeats; an IPv4
/// address is returned as itself without a lookup. NotFound with getaddrinfo's reason otherwise.
core::Result<std::vector<std::string>> ResolveIPv4(const std::string& name);

/// Checked DDS settings of one command line.
struct DdsFlags {
  TransportKind transport = TransportKind::kSharedMemoryOnly;
  /// kUdpOnly: initial peers (empty: 127.0.0.1); kUdpOnly / kDiscoveryClient: local interfaces.
  /// IPv4 addresses ("a.b.c.d[:port]"): host names of --peers are replaced by all their addresses.
  std::vector<std::string> peers, interfaces;
  /// extras.discovery_server holds addresses too: a server given by name gets its first address.
  TransportExtras extras;
  /// The names resolved at start-up (shown by Describe and ResolvedText).
  std::vector<ResolvedHost> resolved;
  std::string security_dir;  ///< absolute --security DIR, empty without
  /// Short name for status pages: "shm", "udp", "default", "xml:NAME", "discovery-server", with
  /// "+security" appended under DDS-Security.
  std::string Label() const;
  /// One line for logs: the transport, the XML file or server, the credentials' folder, and
  /// the host names resolved.
  std::string Describe() const;
  /// "--discovery-server NAME -> a.b.c.d; --peers NAME -> a.b.c.d,e.f.g.h" for the names
  /// resolved; empty without names.
  std::string ResolvedText() const;
  /// Flags that give another process (a local worker) the same transport and domain-wide
  /// settings, with the addresses resolved here (not the names); never the credentials (each
  /// participant has its own: --worker-security).
  std::vector<std::string> TransportArgs() const;
};

/// Reads and checks the DDS flags; `get(name)` returns the value of --name when it was given.
/// POSEFOREST_DDS_XML / POSEFOREST_DDS_PROFILE stand in for a missing --dds-xml / --dds-profile
/// unless --profile, --peers, --interfaces or --discovery-server is given (flags win; the
/// environment of a container image never contradicts an explicit command line).
/// Checks everything that can be checked without joining DDS: contradictory flags, addresses,
/// host names (resolved here, once: an unknown name is an error naming the flag and the name),
/// that the XML file loads in Fast DDS and has the participant profile (the error lists the
/// profiles it has), that every security file is readable (the error names the missing one).
/// Errors: kInvalidArgument / kNotFound / kIo with a message naming the flag or variable.
core::Result<DdsFlags> ParseDdsFlags(
    const std::function<std::optional<std::string>(const std::string&)>& get);

/// The six DDS-Security files for --security DIR (`flag` names it in errors). cert.pem, key.pem
/// and permissions.p7s are this participant's and sit in DIR; identity_ca.pem,
/// permissions_ca.pem and governance.p7s are shared and are taken from DIR, else from DIR/..
/// (make-test-ca.sh OUT writes OUT/NAME/{cert.pem,key.pem,permissions.p7s} and the shared
/// files in OUT; a mounted Kubernetes Secret holds all six in one folder). Paths are absolute.
/// Errors name each missing file and where it was looked for.
core::Result<SecurityFiles> SecurityFilesIn(const std::string& dir, const std::string& flag = "--security");

/// Sets `config`'s transport, peers, interfaces, XML profile, discovery server and security
/// from `flags` (kUdpOnly without peers: 127.0.0.1, participant ids 0..15).
void ApplyDdsFlags(const DdsFlags& flags, NodeConfig* config);

}  // namespace poseforest::proto::dds
