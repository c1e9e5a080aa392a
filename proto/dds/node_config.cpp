#include "proto/dds/node_config.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace poseforest::proto::dds {

using core::ErrorCode;
using core::Result;
using core::Status;

Result<TransportKind> ParseProfile(const std::string& name) {
  if (name == "shm") return TransportKind::kSharedMemoryOnly;
  if (name == "udp") return TransportKind::kUdpOnly;
  if (name == "default") return TransportKind::kDefault;
  return Status(ErrorCode::kInvalidArgument, "--profile " + name + ": expected shm, udp or default");
}

NodeConfig MakeNodeConfig(uint32_t domain, TransportKind transport, bool coordinator, const std::string& name,
                          std::chrono::milliseconds lease, const std::vector<std::string>& peers,
                          const std::vector<std::string>& interfaces, const TransportExtras& extras) {
  NodeConfig c;
  c.domain_id = domain;
  c.participant_name = name;
  c.liveliness_lease = lease;
  DdsFlags flags;
  flags.transport = transport;
  flags.peers = peers;
  flags.interfaces = interfaces;
  flags.extras = extras;
  ApplyDdsFlags(flags, &c);
  if (coordinator) {
    c.write_topics = {Topic::kJob, Topic::kControl, Topic::kStatus};
    c.read_topics = {Topic::kReplies, Topic::kPresence};
  } else {
    c.write_topics = {Topic::kReplies, Topic::kPresence};
    c.read_topics = {Topic::kJob, Topic::kControl, Topic::kStatus};
  }
  return c;
}

Result<std::vector<std::string>> ParseAddressList(const std::string& value, const std::string& flag,
                                                  bool allow_port, bool allow_names) {
  std::vector<std::string> out;
  const std::string form = std::string(allow_names ? "a.b.c.d or a host name" : "a.b.c.d") +
                           (allow_port ? ", with an optional :port" : "");
  auto bad = [&](const std::string& item, const std::string& why) {
    return Status(ErrorCode::kInvalidArgument, "--" + flag + " " + value + ": '" + item + "' " + why);
  };
  size_t start = 0;
  while (start <= value.size()) {
    const size_t comma = std::min(value.find(',', start), value.size());
    const std::string item = value.substr(start, comma - start);
    start = comma + 1;
    if (item.empty()) continue;
    // More than one ':' (or a '['): an IPv6 address, which CheckHost refuses with its reason.
    const bool v6 = item.find('[') != std::string::npos || item.find(':') != item.rfind(':');
    const size_t colon = v6 ? std::string::npos : item.find(':');
    if (Status host = CheckHost(item.substr(0, colon), allow_names); !host.ok())
      return bad(item, host.message() + " (expected " + form + ")");
    if (colon != std::string::npos) {
      const std::string port = item.substr(colon + 1);
      const bool ok = allow_port && !port.empty() && port.size() <= 5 &&
                      port.find_first_not_of("0123456789") == std::string::npos && std::stoi(port) > 0 &&
                      std::stoi(port) < 65536;
      if (!ok)
        return bad(item, allow_port
                             ? "has port '" + port + "': expected 1..65535"
                             : "has a port; --" + flag + " takes addresses only (expected " + form + ")");
    }
    out.push_back(item);
  }
  if (out.empty()) return Status(ErrorCode::kInvalidArgument, "--" + flag + ": no address given");
  return out;
}

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string DefaultWorkerId() {
  static const uint32_t base = uint32_t(std::random_device{}());
  static std::atomic<uint32_t> count{0};
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  char suffix[16];
  std::snprintf(suffix, sizeof suffix, "%06x", unsigned((base + count++) & 0xFFFFFF));
  return "worker-" + std::string(host) + "-" + std::to_string(::getpid()) + "-" + suffix;
}

}  // namespace poseforest::proto::dds
