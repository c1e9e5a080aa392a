#pragma once
// The DDS settings shared by every command that joins Fast DDS (`coordinator`, `worker`,
// `train --local-workers`, `monitor --domain`): how the participant reaches its peers and with
// which credentials, as written (DdsSettings: the command line's flags, declared in
// apps/commands/dds_options.h, or a job's dds section) and checked (DdsFlags).
// docs/distributed/README.md ("Transports and deployment profiles").
//
// Host names (--peers, --discovery-server) are resolved to IPv4 addresses once, by
// CheckDdsSettings at start-up (getaddrinfo, AF_INET), never again: Fast DDS 2.9 fixes a
// participant's initial peers and server locators when it is created. IPv6 addresses are
// refused (UDPv4 transports).

#include <chrono>
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

/// The DDS settings as written, each named after its flag; nullopt: not given.
struct DdsSettings {
  std::optional<std::string> profile;           ///< --profile shm|udp|default
  std::optional<std::string> peers;             ///< --peers HOST[:PORT],...
  std::optional<std::string> interfaces;        ///< --interfaces IP,...
  std::optional<std::string> dds_xml;           ///< --dds-xml FILE
  std::optional<std::string> dds_profile;       ///< --dds-profile NAME
  std::optional<std::string> discovery_server;  ///< --discovery-server [ID@]HOST[:PORT],...
  std::optional<std::string> security;          ///< --security DIR
  /// Whether a transport setting (anything but --security) is given.
  bool transport_given() const {
    return profile || peers || interfaces || dds_xml || dds_profile || discovery_server;
  }
};

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

/// Checks the DDS settings as written.
/// POSEFOREST_DDS_XML / POSEFOREST_DDS_PROFILE stand in for a missing --dds-xml / --dds-profile
/// unless --profile, --peers, --interfaces or --discovery-server is given (flags win; the
/// environment of a container image never contradicts an explicit command line).
/// Checks everything that can be checked without joining DDS: contradictory flags, addresses,
/// host names (resolved here, once: an unknown name is an error naming the flag and the name),
/// that the XML file loads in Fast DDS and has the participant profile (the error lists the
/// profiles it has), that every security file is readable (the error names the missing one).
/// Errors: kInvalidArgument / kNotFound / kIo with a message naming the flag or variable.
core::Result<DdsFlags> CheckDdsSettings(const DdsSettings& written);

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
