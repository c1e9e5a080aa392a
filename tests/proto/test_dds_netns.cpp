// Multi-host test on one machine: three network namespaces (A, B, C) joined by veth pairs to a
// bridge in a fourth (hub) namespace (tests/support/netns.h), addresses from a private /24 that
// the test assigns inside them. Workers run
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

#include "tests/proto/dds_test_util.h"
#include "tests/support/netns.h"
#include "tests/support/process.h"

namespace pdt = poseforest::proto::dds::testing;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;


TEST_CASE("three hosts in network namespaces: traffic crosses, a cut link is noticed", "[dds][integration][slow]") {
  if (::geteuid() != 0)
    FAIL("the multi-host test needs root to create network namespaces (ip netns); run it as root or in a "
         "privileged container");
  poseforest::testing::NetnsTopology topo("pfd");
  if (std::string e = topo.Build({"a", "b", "c"}); !e.empty())
    FAIL("network namespace set-up failed (the multi-host test needs root and `ip netns`): " << e);
  // Multicast discovery may use the link too; the route keeps it on eth0.
  if (std::string e = topo.AddMulticastRoutes(); !e.empty()) FAIL("multicast route: " << e);
  const std::string ip_a = topo.host(0).ip, ip_b = topo.host(1).ip, ip_c = topo.host(2).ip;
  const auto in = [&](size_t host, std::vector<std::string> argv) {
    std::vector<std::string> full = topo.Exec(host);
    full.insert(full.end(), argv.begin(), argv.end());
    return full;
  };

  const std::string peer = pdt::PeerBinary();
  pdt::Child wa, wb, mon;
  std::string error;
  REQUIRE(mon.Start(in(2, {peer, "--mode=monitor", "--id=coordinator", "--transport=udp",
                     "--whitelist=" + ip_c, "--peers=" + ip_a + "," + ip_b, "--job=job-NS", "--lease-ms=1000",
                     "--seconds=45", "--participant-id=0"}),
                    &error));
  REQUIRE(wa.Start(in(0, {peer, "--mode=alive", "--id=worker-a", "--transport=udp",
                    "--whitelist=" + ip_a, "--peers=" + ip_c, "--job=job-NS", "--lease-ms=1000", "--seconds=45",
                    "--period-ms=100", "--participant-id=0"}),
                   &error));
  REQUIRE(wb.Start(in(1, {peer, "--mode=alive", "--id=worker-b", "--transport=udp",
                    "--whitelist=" + ip_b, "--peers=" + ip_c, "--job=job-NS", "--lease-ms=1000", "--seconds=45",
                    "--period-ms=100", "--participant-id=0"}),
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
  REQUIRE(topo.SetLink(0, false) == "");
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
  REQUIRE(topo.SetLink(0, true) == "");
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
  REQUIRE(sender.Start(in(1, {peer, "--mode=send", "--id=worker-b-data", "--transport=udp",
                        "--whitelist=" + ip_b, "--peers=" + ip_c, "--job=job-NS", "--count=8", "--size=1048576",
                        "--seconds=30", "--participant-id=1"}),
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
