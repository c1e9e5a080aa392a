#pragma once
// Multi-host tests on one machine: network namespaces ("hosts") joined by veth pairs to a bridge
// in a hub namespace, with addresses from a private /24 that the test picks. Names carry the
// test's pid, so parallel runs do not collide; the destructor deletes every namespace it made
// (and with them the veths and the bridge), also when a REQUIRE fails. Namespaces left behind by
// a test process that was killed are removed by the next run (RemoveStale).
//
// Needs root (CAP_NET_ADMIN) and `ip netns`; Build() returns an error message otherwise.

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/process.h"

namespace poseforest::testing {

class NetnsTopology {
 public:
  struct Host {
    std::string ns;    ///< namespace name
    std::string ip;    ///< its address on the bridge (eth0)
    std::string port;  ///< the veth end on the hub's bridge: set it down to cut the host's link
  };

  /// `prefix`: 2-5 letters naming the test (namespace names are prefix + role + pid).
  explicit NetnsTopology(std::string prefix) : prefix_(std::move(prefix)) {
    const unsigned pid = unsigned(::getpid());
    suffix_ = std::to_string(pid % 1000000);
    // 10.<100..227>.<0..255>.0/24: private, unique enough per run, never routed off the bridge.
    subnet_ = "10." + std::to_string(100 + (pid / 256) % 128) + "." + std::to_string(pid % 256) + ".";
    hub_ = prefix_ + "hub" + suffix_;
  }
  NetnsTopology(const NetnsTopology&) = delete;
  NetnsTopology& operator=(const NetnsTopology&) = delete;
  ~NetnsTopology() {
    for (auto it = created_.rbegin(); it != created_.rend(); ++it) RunCommand("ip netns delete " + *it);
  }

  /// Deletes namespaces "<prefix>*<pid>" whose pid is no longer running (a test killed mid-way).
  void RemoveStale() const {
    std::istringstream list(RunCommand("ip netns list").output);
    std::string line;
    while (std::getline(list, line)) {
      const std::string name = line.substr(0, line.find(' '));
      if (name.rfind(prefix_, 0) != 0) continue;
      size_t d = name.size();
      while (d > 0 && std::isdigit(static_cast<unsigned char>(name[d - 1]))) --d;
      if (d == name.size()) continue;
      const long pid = std::stol(name.substr(d));
      if (pid == long(::getpid() % 1000000)) continue;
      if (::kill(pid_t(pid), 0) != 0 && errno == ESRCH) RunCommand("ip netns delete " + name);
    }
  }

  /// Creates the hub with its bridge and one namespace per role, host i at <subnet>.(i + 1).
  /// Returns "" or the failing command and its output.
  std::string Build(const std::vector<std::string>& roles) {
    RemoveStale();
    if (std::string e = Must("ip netns add " + hub_); !e.empty()) return e;
    created_.push_back(hub_);
    for (const std::string& cmd :
         {"ip -n " + hub_ + " link set lo up", "ip -n " + hub_ + " link add br0 type bridge",
          "ip -n " + hub_ + " link set br0 up"})
      if (std::string e = Must(cmd); !e.empty()) return e;
    for (size_t i = 0; i < roles.size(); ++i) {
      Host h{prefix_ + roles[i] + suffix_, subnet_ + std::to_string(i + 1), "port" + std::to_string(i)};
      if (std::string e = Must("ip netns add " + h.ns); !e.empty()) return e;
      created_.push_back(h.ns);
      for (const std::string& cmd :
           {"ip -n " + h.ns + " link set lo up",
            "ip -n " + hub_ + " link add " + h.port + " type veth peer name eth0 netns " + h.ns,
            "ip -n " + hub_ + " link set " + h.port + " master br0 up",
            "ip -n " + h.ns + " addr add " + h.ip + "/24 dev eth0", "ip -n " + h.ns + " link set eth0 up"})
        if (std::string e = Must(cmd); !e.empty()) return e;
      hosts_.push_back(h);
    }
    return "";
  }

  /// Routes multicast (224.0.0.0/4) out of every host's eth0, so multicast discovery crosses the
  /// bridge as well. "" or the error.
  std::string AddMulticastRoutes() {
    for (const Host& h : hosts_)
      if (std::string e = Must("ip -n " + h.ns + " route add 224.0.0.0/4 dev eth0"); !e.empty()) return e;
    return "";
  }

  const Host& host(size_t i) const { return hosts_.at(i); }
  const std::string& hub() const { return hub_; }

  /// Cuts (false) or restores (true) host i's link at the bridge. "" or the error.
  std::string SetLink(size_t i, bool up) {
    return Must("ip -n " + hub_ + " link set " + hosts_.at(i).port + (up ? " up" : " down"));
  }

  /// Bytes received / sent on host i's eth0 (the kernel's counters), -1 on error.
  long long Counter(size_t i, const std::string& which) const {
    auto r = RunCommand("ip netns exec " + hosts_.at(i).ns + " cat /sys/class/net/eth0/statistics/" + which);
    if (r.exit_code != 0) return -1;
    try {
      return std::stoll(r.output);
    } catch (...) {
      return -1;
    }
  }

  /// argv prefix that runs a program inside host i's namespace.
  std::vector<std::string> Exec(size_t i) const { return {"ip", "netns", "exec", hosts_.at(i).ns}; }

 private:
  static std::string Must(const std::string& cmd) {
    auto r = RunCommand(cmd);
    return r.exit_code == 0 ? "" : "`" + cmd + "` -> " + r.output;
  }

  std::string prefix_, suffix_, subnet_, hub_;
  std::vector<std::string> created_;
  std::vector<Host> hosts_;
};

}  // namespace poseforest::testing
