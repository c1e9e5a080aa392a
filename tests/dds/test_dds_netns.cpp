// Multi-host test on one machine: three network namespaces (A, B, C) joined by veth pairs to a
// bridge in a fourth (hub) namespace, 10.77.0.0/24 addresses assigned inside them. Workers run
// the poseforest_dds_peer helper in A and B (UDPv4 only, interface whitelist, initial peers), a
// monitor runs in C. Traffic crosses the bridge; then A's link is cut and C must see A's
// liveliness lost while B keeps delivering; the link comes back and A recovers.
//
// Needs root (CAP_NET_ADMIN) and `ip netns`. Without them the test FAILS with a clear message:
// it is the only test of the multi-host path. Everything it creates is removed at the end,
// also on failure.
#include <catch2/catch.hpp>

#include <cstdio>
#include <memory>

#include "tests/support/process.h"
#include "tests/dds/dds_test_util.h"

namespace pdt = poseforest::dds::testing;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

using poseforest::testing::CommandResult;

CommandResult Run(const std::string& cmd) { return poseforest::testing::RunCommand(cmd); }

/// The namespaces of one test run; the destructor removes them (and with them the veths/bridge).
struct Topology {
  std::string suffix = std::to_string(::getpid() % 100000);
  std::string hub = "pfhub" + suffix, a = "pfa" + suffix, b = "pfb" + suffix, c = "pfc" + suffix;
  std::vector<std::string> created;

  ~Topology() {
    for (auto it = created.rbegin(); it != created.rend(); ++it) Run("ip netns delete " + *it);
  }
  void Must(const std::string& cmd) {
    auto r = Run(cmd);
    if (r.exit_code != 0)
      FAIL("network namespace set-up failed (the multi-host test needs root and `ip netns`): `" << cmd
                                                                                                 << "` -> " << r.output);
  }
  void Build() {
    for (const auto& ns : {hub, a, b, c}) {
      Must("ip netns add " + ns);
      created.push_back(ns);
      Must("ip -n " + ns + " link set lo up");
    }
    Must("ip -n " + hub + " link add br0 type bridge");
    Must("ip -n " + hub + " link set br0 up");
    const std::vector<std::pair<std::string, std::string>> hosts = {{a, "10.77.0.1"}, {b, "10.77.0.2"}, {c, "10.77.0.3"}};
    for (size_t i = 0; i < hosts.size(); ++i) {
      const std::string port = "port" + std::to_string(i);
      Must("ip -n " + hub + " link add " + port + " type veth peer name eth0 netns " + hosts[i].first);
      Must("ip -n " + hub + " link set " + port + " master br0 up");
      Must("ip -n " + hosts[i].first + " addr add " + hosts[i].second + "/24 dev eth0");
      Must("ip -n " + hosts[i].first + " link set eth0 up");
      // Multicast discovery may use the link too; the route keeps it on eth0.
      Must("ip -n " + hosts[i].first + " route add 224.0.0.0/4 dev eth0");
    }
  }
};

}  // namespace

TEST_CASE("three hosts in network namespaces: traffic crosses, a cut link is noticed", "[dds][integration][slow]") {
  if (::geteuid() != 0)
    FAIL("the multi-host test needs root to create network namespaces (ip netns); run it as root or in a "
         "privileged container");
  Topology topo;
  topo.Build();

  const std::string peer = pdt::PeerBinary();
  pdt::Child wa, wb, mon;
  std::string error;
  REQUIRE(mon.Start({"ip", "netns", "exec", topo.c, peer, "--mode=monitor", "--id=coordinator", "--transport=udp",
                     "--whitelist=10.77.0.3", "--peers=10.77.0.1,10.77.0.2", "--job=job-NS", "--lease-ms=1000",
                     "--seconds=45", "--participant-id=0"},
                    &error));
  REQUIRE(wa.Start({"ip", "netns", "exec", topo.a, peer, "--mode=alive", "--id=worker-a", "--transport=udp",
                    "--whitelist=10.77.0.1", "--peers=10.77.0.3", "--job=job-NS", "--lease-ms=1000", "--seconds=45",
                    "--period-ms=100", "--participant-id=0"},
                   &error));
  REQUIRE(wb.Start({"ip", "netns", "exec", topo.b, peer, "--mode=alive", "--id=worker-b", "--transport=udp",
                    "--whitelist=10.77.0.2", "--peers=10.77.0.3", "--job=job-NS", "--lease-ms=1000", "--seconds=45",
                    "--period-ms=100", "--participant-id=0"},
                   &error));

  // 1. Both workers' heartbeats reach the monitor in namespace C.
  bool seen_a = false, seen_b = false;
  const auto t0 = Clock::now();
  while (!(seen_a && seen_b) && Clock::now() - t0 < 25s) {
    auto line = mon.ReadLine(1s);
    if (!line) continue;
    seen_a |= line->rfind("SAMPLE presence sender=worker-a", 0) == 0;
    seen_b |= line->rfind("SAMPLE presence sender=worker-b", 0) == 0;
  }
  INFO("monitor output:\n" << mon.output() << "\nworker-a:\n" << wa.output());
  REQUIRE(seen_a);
  REQUIRE(seen_b);
  std::printf("[netns] both workers seen by the monitor %.2f s after start\n",
              std::chrono::duration<double>(Clock::now() - t0).count());

  // 2. Cut A's link at the bridge: the monitor reports worker-a's liveliness lost, B goes on.
  const auto cut = Clock::now();
  topo.Must("ip -n " + topo.hub + " link set port0 down");
  bool lost_a = false, b_after = false;
  double lost_ms = 0;
  while (!(lost_a && b_after) && Clock::now() - cut < 15s) {
    auto line = mon.ReadLine(500ms);
    if (!line) continue;
    if (std::getenv("PF_DEBUG") && line->rfind("SAMPLE", 0) != 0) std::printf("%.0f ms: %s\n", std::chrono::duration<double, std::milli>(Clock::now() - cut).count(), line->c_str());
    if (line->rfind("EVENT LivelinessLost presence sender=worker-a", 0) == 0 && !lost_a) {
      lost_a = true;
      lost_ms = std::chrono::duration<double, std::milli>(Clock::now() - cut).count();
    }
    if (lost_a && line->rfind("SAMPLE presence sender=worker-b", 0) == 0) b_after = true;
    CHECK(line->rfind("EVENT LivelinessLost presence sender=worker-b", 0) != 0);
  }
  INFO("monitor output:\n" << mon.output());
  REQUIRE(lost_a);
  CHECK(b_after);
  std::printf("[netns] link of A cut: liveliness lost reported after %.0f ms (lease 1000 ms)\n", lost_ms);
  // While the link is down nothing of A gets through (a bounded negative check: 1.5 s).
  int b_samples = 0;
  for (const auto quiet = Clock::now(); Clock::now() - quiet < 1500ms;) {
    auto line = mon.ReadLine(100ms);
    if (!line) continue;
    CHECK(line->rfind("SAMPLE presence sender=worker-a", 0) != 0);
    CHECK(line->rfind("EVENT LivelinessRecovered presence sender=worker-a", 0) != 0);
    b_samples += line->rfind("SAMPLE presence sender=worker-b", 0) == 0;
  }
  CHECK(b_samples >= 5);  // B heartbeats every 100 ms

  // 3. Restore the link: A's liveliness recovers and its heartbeats arrive again.
  topo.Must("ip -n " + topo.hub + " link set port0 up");
  bool recovered = false, a_again = false;
  const auto up = Clock::now();
  while (!(recovered && a_again) && Clock::now() - up < 20s) {
    auto line = mon.ReadLine(500ms);
    if (!line) continue;
    recovered |= line->rfind("EVENT LivelinessRecovered presence sender=worker-a", 0) == 0;
    a_again |= recovered && line->rfind("SAMPLE presence sender=worker-a", 0) == 0;
  }
  INFO("monitor output:\n" << mon.output());
  CHECK(recovered);
  CHECK(a_again);
  std::printf("[netns] link restored: worker-a recovered=%d heartbeats again=%d after %.2f s\n", int(recovered),
              int(a_again), std::chrono::duration<double>(Clock::now() - up).count());

  // 4. Large samples across the bridge (MTU 1500: every 1 MiB sample is many IP fragments).
  pdt::Child sender;
  REQUIRE(sender.Start({"ip", "netns", "exec", topo.b, peer, "--mode=send", "--id=worker-b-data", "--transport=udp",
                        "--whitelist=10.77.0.2", "--peers=10.77.0.3", "--job=job-NS", "--count=8", "--size=1048576",
                        "--seconds=30", "--participant-id=1"},
                       &error));
  int big = 0;
  const auto t_send = Clock::now();
  while (big < 8 && Clock::now() - t_send < 30s) {
    auto line = mon.ReadLine(500ms);
    if (!line) continue;
    big += line->rfind("SAMPLE replies sender=worker-b-data", 0) == 0;
    CHECK(line->rfind("DROP replies", 0) != 0);  // the gate checks each MiB's CRC
  }
  auto rc = sender.Wait(30s);
  INFO("sender output:\n" << sender.output());
  CHECK(big == 8);
  CHECK((rc && *rc == 0));
  std::printf("[netns] 8 x 1 MiB from B to C across the bridge in %.2f s: %s\n",
              std::chrono::duration<double>(Clock::now() - t_send).count(),
              sender.output().find("SENT") != std::string::npos
                  ? sender.output().substr(sender.output().find("SENT")).c_str()
                  : "(no SENT line)\n");

  wa.Kill(SIGKILL);
  wb.Kill(SIGKILL);
  mon.Kill(SIGKILL);
}
