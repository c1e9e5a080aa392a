#include "proto/dds/dds_node.h"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include <fastdds/rtps/attributes/ServerAttributes.h>

// Discovery server addresses ([ID@]HOST[:PORT],...) and host names: parsed, checked, formatted.

namespace poseforest::proto::dds {

namespace frtps = eprosima::fastrtps::rtps;
using core::ErrorCode;
using core::Status;

bool IsIPv4Address(const std::string& host) {
  int octets = 0;
  for (size_t p = 0; p <= host.size(); ++octets) {
    const size_t dot = std::min(host.find('.', p), host.size());
    const std::string t = host.substr(p, dot - p);
    if (t.empty() || t.size() > 3 || t.find_first_not_of("0123456789") != std::string::npos || std::stoi(t) > 255)
      return false;
    p = dot + 1;
  }
  return octets == 4;
}

Status CheckHost(const std::string& host, bool allow_names) {
  auto bad = [](const std::string& why) { return Status(ErrorCode::kInvalidArgument, why); };
  if (host.find(':') != std::string::npos || host.find('[') != std::string::npos)
    return bad("is an IPv6 address, not supported: the transports are UDPv4");
  if (IsIPv4Address(host)) return Status::Ok();
  if (host.empty()) return bad("is empty");
  if (!allow_names) return bad("is not an IPv4 address");
  // A name whose last label is all digits ("10.0.0", "10.0.0.256") is a mistyped address:
  // getaddrinfo would read "10.0.0" as 10.0.0.0 (inet_aton) instead of failing.
  std::string name = host;
  if (name.back() == '.') name.pop_back();
  const size_t last_dot = name.rfind('.');
  const std::string last = name.substr(last_dot == std::string::npos ? 0 : last_dot + 1);
  if (!last.empty() && last.find_first_not_of("0123456789") == std::string::npos)
    return bad("is not an IPv4 address");
  if (name.empty() || name.size() > 253) return bad("is not a host name: longer than 253 characters");
  for (size_t p = 0; p <= name.size();) {
    const size_t dot = std::min(name.find('.', p), name.size());
    const std::string label = name.substr(p, dot - p);
    if (label.empty() || label.size() > 63)
      return bad("is not a host name: a label of " + std::to_string(label.size()) + " characters (1..63)");
    if (label.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-") !=
        std::string::npos)
      return bad("is not a host name: '" + label + "' has characters other than letters, digits and '-'");
    if (label.front() == '-' || label.back() == '-')
      return bad("is not a host name: '" + label + "' starts or ends with '-'");
    p = dot + 1;
  }
  return Status::Ok();
}

core::Result<std::vector<DiscoveryServerAddress>> ParseDiscoveryServers(const std::string& list) {
  auto bad = [&](const std::string& item, const std::string& why) {
    return Status(ErrorCode::kInvalidArgument, "'" + item + "' " + why);
  };
  auto number = [](const std::string& t, unsigned long max, unsigned long* v) {
    if (t.empty() || t.size() > 5 || t.find_first_not_of("0123456789") != std::string::npos) return false;
    *v = std::stoul(t);
    return *v <= max;
  };
  std::vector<DiscoveryServerAddress> out;
  std::vector<std::string> items;
  for (size_t start = 0; start <= list.size();) {
    const size_t comma = std::min(list.find(',', start), list.size());
    std::string item = list.substr(start, comma - start);
    start = comma + 1;
    if (item.empty()) continue;
    DiscoveryServerAddress a;
    std::string rest = item;
    if (const size_t at = item.find('@'); at != std::string::npos) {
      unsigned long id = 0;
      if (!number(item.substr(0, at), 255, &id))
        return bad(item, "has server id '" + item.substr(0, at) +
                             "': expected 0..255 (the -i of fast-discovery-server) before the @");
      a.id = int(id);
      a.id_given = true;
      rest = item.substr(at + 1);
    }
    // More than one ':' (or a '['): an IPv6 address, refused by CheckHost with its reason.
    const bool v6 = rest.find('[') != std::string::npos || rest.find(':') != rest.rfind(':');
    const size_t colon = v6 ? std::string::npos : rest.find(':');
    a.host = rest.substr(0, colon);
    if (Status host = CheckHost(a.host, true); !host.ok())
      return bad(item, host.message() + " (expected [ID@]a.b.c.d[:port] or [ID@]HOST-NAME[:port])");
    if (colon != std::string::npos) {
      unsigned long port = 0;
      if (!number(rest.substr(colon + 1), 65535, &port) || port == 0)
        return bad(item, "has port '" + rest.substr(colon + 1) + "': expected 1..65535");
      a.port = uint32_t(port);
    }
    for (size_t i = 0; i < out.size(); ++i) {
      if (out[i].id == a.id)
        return bad(item, "repeats server id " + std::to_string(a.id) + " of '" + items[i] +
                             "' (each fast-discovery-server has its own -i; the id selects its GUID prefix)");
      if (out[i].host == a.host && out[i].port == a.port)
        return bad(item,
                   "repeats the address " + a.host + ":" + std::to_string(a.port) + " of '" + items[i] + "'");
    }
    out.push_back(a);
    items.push_back(item);
  }
  if (out.empty()) return Status(ErrorCode::kInvalidArgument, "no server given ([ID@]HOST[:port],...)");
  return out;
}

std::string FormatDiscoveryServers(const std::vector<DiscoveryServerAddress>& servers) {
  std::string s;
  for (const DiscoveryServerAddress& a : servers) {
    if (!s.empty()) s += ',';
    if (a.id != 0) s += std::to_string(a.id) + "@";
    s += a.host + ":" + std::to_string(a.port);
  }
  return s;
}

std::string DiscoveryServerGuidPrefix(int id) {
  if (id < 0 || id > 255) return "";
  frtps::GuidPrefix_t prefix;
  if (!eprosima::fastdds::rtps::get_server_client_default_guidPrefix(id, prefix)) return "";
  std::string s;
  char byte[4];
  for (size_t i = 0; i < frtps::GuidPrefix_t::size; ++i) {
    std::snprintf(byte, sizeof byte, "%02x", unsigned(prefix.value[i]));
    if (i) s += '.';
    s += byte;
  }
  return s;
}

}  // namespace poseforest::proto::dds
