#include "proto/dds/dds_flags.h"

#include <arpa/inet.h>
#include <fastrtps/config.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "proto/dds/node_config.h"
#include "proto/dds/xml_profile_check.h"

namespace poseforest::proto::dds {

using core::ErrorCode;
using core::Result;
using core::Status;
namespace fs = std::filesystem;

namespace {
bool Readable(const fs::path& p) {
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) return false;
  if (FILE* f = std::fopen(p.c_str(), "rb")) {
    std::fclose(f);
    return true;
  }
  return false;
}

std::string Absolute(const std::string& path) {
  std::error_code ec;
  const fs::path a = fs::absolute(path, ec);
  return ec ? path : a.lexically_normal().string();
}

std::optional<std::string> Env(const char* name) {
  const char* v = std::getenv(name);
  if (!v || !*v) return std::nullopt;
  return std::string(v);
}
}  // namespace

Result<std::vector<std::string>> ResolveIPv4(const std::string& name) {
  if (IsIPv4Address(name)) return std::vector<std::string>{name};
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* list = nullptr;
  const int rc = ::getaddrinfo(name.c_str(), nullptr, &hints, &list);
  if (rc != 0)
    return Status(ErrorCode::kNotFound, "host name '" + name + "' does not resolve to an IPv4 address (" +
                                            (rc == EAI_SYSTEM ? std::strerror(errno) : ::gai_strerror(rc)) +
                                            ")");
  std::vector<std::string> out;
  for (const addrinfo* a = list; a; a = a->ai_next) {
    if (a->ai_family != AF_INET) continue;
    char text[INET_ADDRSTRLEN] = {};
    ::inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(a->ai_addr)->sin_addr, text, sizeof text);
    if (std::find(out.begin(), out.end(), text) == out.end()) out.push_back(text);
  }
  ::freeaddrinfo(list);
  if (out.empty()) return Status(ErrorCode::kNotFound, "host name '" + name + "' has no IPv4 address");
  return out;
}

std::string DdsFlags::ResolvedText() const {
  std::string s;
  for (const ResolvedHost& r : resolved) {
    s += (s.empty() ? "" : "; ") + r.flag + " " + r.name + " -> ";
    for (size_t i = 0; i < r.addresses.size(); ++i) s += (i ? "," : "") + r.addresses[i];
  }
  return s;
}

std::string DdsFlags::Label() const {
  std::string s;
  switch (transport) {
    case TransportKind::kDefault:
      s = "default";
      break;
    case TransportKind::kSharedMemoryOnly:
      s = "shm";
      break;
    case TransportKind::kUdpOnly:
      s = "udp";
      break;
    case TransportKind::kDiscoveryClient:
      s = "discovery-server";
      break;
    case TransportKind::kXmlProfile:
      s = "xml:" + extras.xml_profile;
      break;
  }
  if (extras.security.enabled()) s += "+security";
  return s;
}

std::string DdsFlags::Describe() const {
  std::string s;
  switch (transport) {
    case TransportKind::kDefault:
      s = "shared memory + UDP (--profile default)";
      break;
    case TransportKind::kSharedMemoryOnly:
      s = "shared memory (--profile shm)";
      break;
    case TransportKind::kUdpOnly: {
      s = "UDP, initial peers ";
      std::string list;
      for (const auto& p : peers.empty() ? std::vector<std::string>{"127.0.0.1"} : peers)
        list += (list.empty() ? "" : ",") + p;
      s += list;
      break;
    }
    case TransportKind::kDiscoveryClient: {
      // Each server with the id and GUID prefix the client expects of it (--check-config).
      auto servers = ParseDiscoveryServers(extras.discovery_server);
      if (!servers.ok()) {
        s = "UDP, discovery server " + extras.discovery_server;
        break;
      }
      s = servers->size() == 1 ? "UDP, discovery server " : "UDP, discovery servers ";
      for (size_t i = 0; i < servers->size(); ++i) {
        const DiscoveryServerAddress& a = (*servers)[i];
        s += (i ? ", " : "") + FormatDiscoveryServers({a}) + " (id " + std::to_string(a.id) +
             ", GUID prefix " + DiscoveryServerGuidPrefix(a.id) + ")";
      }
      break;
    }
    case TransportKind::kXmlProfile:
      s = "Fast DDS XML profile " + extras.xml_profile + " of " + extras.xml_file;
      break;
  }
  if (!interfaces.empty()) {
    std::string list;
    for (const auto& i : interfaces) list += (list.empty() ? "" : ",") + i;
    s += ", interfaces " + list;
  }
  if (extras.security.enabled()) s += "; DDS-Security with " + extras.security.identity_certificate;
  if (!resolved.empty()) s += "; host names resolved once, at start-up: " + ResolvedText();
  return s;
}

std::vector<std::string> DdsFlags::TransportArgs() const {
  auto join = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ",") + x;
    return s;
  };
  std::vector<std::string> a;
  switch (transport) {
    case TransportKind::kDefault:
      a = {"--profile", "default"};
      break;
    case TransportKind::kSharedMemoryOnly:
      a = {"--profile", "shm"};
      break;
    case TransportKind::kUdpOnly:
      a = {"--profile", "udp"};
      if (!peers.empty()) a.insert(a.end(), {"--peers", join(peers)});
      break;
    case TransportKind::kDiscoveryClient:
      a = {"--discovery-server", extras.discovery_server};
      break;
    case TransportKind::kXmlProfile:
      a = {"--dds-xml", extras.xml_file, "--dds-profile", extras.xml_profile};
      break;
  }
  if (!interfaces.empty()) a.insert(a.end(), {"--interfaces", join(interfaces)});
  return a;
}

Result<SecurityFiles> SecurityFilesIn(const std::string& dir, const std::string& flag) {
  std::error_code ec;
  fs::path d = fs::path(Absolute(dir));
  if (d.filename().empty()) d = d.parent_path();  // "ca/worker-1/": the parent is ca, not worker-1
  if (!fs::is_directory(d, ec))
    return Status(ErrorCode::kIo, flag + " " + dir +
                                      ": not a directory (expected the folder of cert.pem, key.pem, "
                                      "permissions.p7s made by deploy/security/make-test-ca.sh)");
  SecurityFiles s;
  std::string missing;
  auto own = [&](const char* name, std::string* out) {
    if (Readable(d / name))
      *out = (d / name).string();
    else
      missing += std::string(missing.empty() ? "" : "; ") + name + " (looked in " + d.string() + ")";
  };
  auto shared = [&](const char* name, std::string* out) {
    for (const fs::path& p : {d / name, d.parent_path() / name})
      if (Readable(p)) {
        *out = p.string();
        return;
      }
    missing += std::string(missing.empty() ? "" : "; ") + name + " (looked in " + d.string() + " and " +
               d.parent_path().string() + ")";
  };
  shared("identity_ca.pem", &s.identity_ca);
  own("cert.pem", &s.identity_certificate);
  own("key.pem", &s.private_key);
  shared("permissions_ca.pem", &s.permissions_ca);
  shared("governance.p7s", &s.governance);
  own("permissions.p7s", &s.permissions);
  if (!missing.empty())
    return Status(ErrorCode::kIo, flag + " " + dir + ": missing or unreadable " + missing);
  return s;
}

Result<DdsFlags> CheckDdsSettings(const DdsSettings& written) {
  auto invalid = [](const std::string& m) { return Status(ErrorCode::kInvalidArgument, m); };
  DdsFlags f;
  const auto &profile = written.profile, &peers = written.peers, &interfaces = written.interfaces,
             &server = written.discovery_server, &security = written.security;
  auto xml = written.dds_xml, xml_profile = written.dds_profile;
  bool xml_discovery_client = false;
  const bool xml_from_flags = xml || xml_profile;
  const bool builtin_flags = profile || peers || interfaces || server;
  // "--dds-xml FILE" or "POSEFOREST_DDS_XML=FILE": where a value came from, for messages.
  std::string xml_source = "--dds-xml ", profile_source = "--dds-profile ";
  if (!builtin_flags) {  // the environment stands in for missing --dds-xml / --dds-profile
    if (!xml && (xml = Env(kEnvDdsXml))) xml_source = std::string(kEnvDdsXml) + "=";
    if (!xml_profile && (xml_profile = Env(kEnvDdsProfile)))
      profile_source = std::string(kEnvDdsProfile) + "=";
  }
  if (xml_from_flags && builtin_flags)
    return invalid(std::string("--dds-xml/--dds-profile choose the whole transport from the XML profile; ") +
                   "they cannot be combined with " +
                   (profile      ? "--profile"
                    : peers      ? "--peers"
                    : interfaces ? "--interfaces"
                                 : "--discovery-server") +
                   " (edit the profile instead)");
  if (xml && !xml_profile)
    return invalid(xml_source + *xml + " needs a participant profile name: --dds-profile NAME (or " +
                   kEnvDdsProfile + ")");
  if (xml_profile && !xml)
    return invalid(profile_source + *xml_profile + " needs the XML file: --dds-xml FILE (or " + kEnvDdsXml +
                   ")");

  if (xml) {
    f.transport = TransportKind::kXmlProfile;
    if (xml->empty()) return invalid(xml_source + ": empty file name");
    if (xml_profile->empty()) return invalid(profile_source + ": empty profile name");
    f.extras.xml_file = Absolute(*xml);
    f.extras.xml_profile = *xml_profile;
    auto info = CheckXmlParticipantProfile(f.extras.xml_file, f.extras.xml_profile);
    if (!info.ok())
      return Status(info.status().code(),
                    xml_source + *xml + " " + profile_source + *xml_profile + ": " + info.status().message());
    xml_discovery_client = info->discovery_client;
    if (info->has_security && security)
      return invalid("--security " + *security + ": profile " + *xml_profile + " of " + *xml +
                     " sets DDS-Security properties itself; use one or the other");
  } else if (server) {
    if (profile && *profile != "udp")
      return invalid("--discovery-server talks UDP to the server and its clients; --profile " + *profile +
                     " contradicts it (leave --profile out)");
    if (peers)
      return invalid("--peers cannot be combined with --discovery-server (the server introduces the peers)");
    auto list = ParseDiscoveryServers(*server);
    if (!list.ok()) return invalid("--discovery-server " + *server + ": " + list.status().message());
    // Names -> their first address (one server is one locator); then no two entries may meet at
    // one address and port, which ParseDiscoveryServers could only check for what was written.
    std::vector<std::string> written;
    for (DiscoveryServerAddress& a : *list) {
      written.push_back(FormatDiscoveryServers({a}));
      if (IsIPv4Address(a.host)) continue;
      auto addresses = ResolveIPv4(a.host);
      if (!addresses.ok())
        return Status(addresses.status().code(),
                      "--discovery-server " + *server + ": " + addresses.status().message());
      f.resolved.push_back({"--discovery-server", a.host, *addresses});
      a.host = addresses->front();
    }
    for (size_t i = 0; i < list->size(); ++i)
      for (size_t j = 0; j < i; ++j)
        if ((*list)[i].host == (*list)[j].host && (*list)[i].port == (*list)[j].port)
          return invalid("--discovery-server " + *server + ": " + written[i] + " and " + written[j] +
                         " are the same address " + (*list)[i].host + ":" + std::to_string((*list)[i].port));
    f.transport = TransportKind::kDiscoveryClient;
    f.extras.discovery_server = FormatDiscoveryServers(*list);
  } else {
    auto kind = ParseProfile(profile.value_or("shm"));
    if (!kind.ok()) return kind.status();
    f.transport = *kind;
    if (peers && f.transport != TransportKind::kUdpOnly) return invalid("--peers needs --profile udp");
    if (peers) {
      auto list = ParseAddressList(*peers, "peers", true, true);
      if (!list.ok()) return list.status();
      // A name stands for all its addresses (a headless Kubernetes Service: every pod), each
      // with the entry's port.
      for (const std::string& item : *list) {
        const size_t colon = item.find(':');
        const std::string host = item.substr(0, colon),
                          port = colon == std::string::npos ? "" : item.substr(colon);
        std::vector<std::string> addresses = {host};
        if (!IsIPv4Address(host)) {
          auto resolved = ResolveIPv4(host);
          if (!resolved.ok())
            return Status(resolved.status().code(), "--peers " + *peers + ": " + resolved.status().message());
          if (std::none_of(f.resolved.begin(), f.resolved.end(),
                           [&](const ResolvedHost& r) { return r.name == host; }))
            f.resolved.push_back({"--peers", host, *resolved});
          addresses = std::move(*resolved);
        }
        for (const std::string& a : addresses)
          if (std::find(f.peers.begin(), f.peers.end(), a + port) == f.peers.end())
            f.peers.push_back(a + port);
      }
    }
  }
  if (interfaces) {
    if (f.transport != TransportKind::kUdpOnly && f.transport != TransportKind::kDiscoveryClient)
      return invalid("--interfaces needs --profile udp or --discovery-server");
    auto list = ParseAddressList(*interfaces, "interfaces", false);
    if (!list.ok()) return list.status();
    f.interfaces = std::move(*list);
  }
  if (security) {
    if (security->empty()) return invalid("--security: empty folder name");
#if FASTRTPS_VERSION_MAJOR == 2 && FASTRTPS_VERSION_MINOR < 10
    // Fast DDS got secure discovery servers in 2.10. With 2.9 the participants find each other
    // through the (unauthenticated) server, but every endpoint match fails ("Security manager
    // returns an error ... assignRemoteEndpoints"): the job would wait for workers that never
    // join. Say so now instead.
    if (f.transport == TransportKind::kDiscoveryClient || xml_discovery_client)
      return invalid("--security " + *security + " with a discovery server (" +
                     (f.transport == TransportKind::kDiscoveryClient ? "--discovery-server"
                                                                     : "profile " + *xml_profile) +
                     "): Fast DDS " + std::to_string(FASTRTPS_VERSION_MAJOR) + "." +
                     std::to_string(FASTRTPS_VERSION_MINOR) +
                     " has no secure discovery server (it came in 2.10), so secured participants never match "
                     "through one; use --profile udp --peers HOST,... with --security across hosts");
#endif
    auto files = SecurityFilesIn(*security);
    if (!files.ok()) return files.status();
    f.extras.security = std::move(*files);
    f.security_dir = Absolute(*security);
  }
  return f;
}

void ApplyDdsFlags(const DdsFlags& flags, NodeConfig* c) {
  c->transport = flags.transport;
  if (flags.transport == TransportKind::kUdpOnly) {
    c->initial_peers = flags.peers.empty() ? std::vector<std::string>{"127.0.0.1"} : flags.peers;
    c->peer_participant_ids = 16;
  }
  if (flags.transport == TransportKind::kUdpOnly || flags.transport == TransportKind::kDiscoveryClient)
    c->interface_whitelist = flags.interfaces;
  if (!flags.extras.discovery_server.empty()) c->discovery_server = flags.extras.discovery_server;
  c->xml_file = flags.extras.xml_file;
  c->xml_profile = flags.extras.xml_profile;
  c->security = flags.extras.security;
  c->keep_all_max_samples = flags.extras.keep_all_max_samples;
  c->write_block_slice = flags.extras.write_block_slice;
}

}  // namespace poseforest::proto::dds
