// deploy/ through the real command line: `poseforest coordinator` and `poseforest worker`
// processes with the DDS flags a deployment uses (docs/distributed/README.md, "Deployment").
//  - the shipped Fast DDS XML profile (deploy/fastdds/profiles.xml, poseforest_shm) by flags and
//    by the POSEFOREST_DDS_XML / POSEFOREST_DDS_PROFILE environment: `poseforest train`'s forest;
//  - discovery through a real fast-discovery-server process (--discovery-server), and nothing
//    without the server; through two servers (ids 0 and 1, a client of both, workers of either
//    one); a server id that is not the server's -i finds nothing;
//  - DDS-Security (--security, credentials from deploy/security/make-test-ca.sh): the job trains,
//    while a worker without credentials and participants that hello/heartbeat on the presence
//    topic without credentials or with another CA's certificate are never matched, never get
//    work and are never counted; same forest; `monitor --domain` sees the job only with credentials;
//  - host names in --discovery-server / --peers: `localhost` resolved once at start-up and shown,
//    a coordinator and a worker meet through a discovery server named `localhost`; a name that
//    does not resolve (checked in a network namespace of its own: no DNS query leaves) is refused
//    naming the flag and the name, also from the job's dds section;
//  - flag errors name the file, the profile, the missing credential or the contradiction;
//  - every command line of deploy/docker/Dockerfile.* and of what `kubectl kustomize deploy/k8s`
//    renders (containers and exec probes) passes the real argument parser (`--check-config`), and
//    a manifest with a wrong flag fails the check;
//  - deploy/compose.yaml as compose renders it: each service's command through the parser with the
//    services' names as hosts, internal network only, images built by their Dockerfiles,
//    Prometheus's config through promtool and its targets the services' --http ports (the live
//    cluster run is scripts/compose-test.sh, not part of ctest: it needs a container engine);
//  - the rendered deploy/k8s is what operators expect: the coordinator a batch/v1 Job
//    (OnFailure) resuming from a checkpoint on a PersistentVolumeClaim, the forest on that volume;
//    the workers scaled by replicas, with readiness and liveness probes.

#include <algorithm>
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <nlohmann/json.hpp>
#include <tuple>

#include "proto/dds/build_id.h"
#include "proto/dds/dds_flags.h"
#include "tests/coordinator/dist_test_util.h"
#include "tests/proto/dds_test_util.h"

using namespace poseforest;
using namespace poseforest::coordinator::testing;
using poseforest::proto::dds::testing::Child;
using poseforest::proto::dds::testing::HelperDir;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }
std::string Peer() { return (HelperDir() / "poseforest_dds_peer").string(); }
fs::path Source() { return fs::path(POSEFOREST_SOURCE_DIR); }
std::string ShippedXml() { return (Source() / "deploy/fastdds/profiles.xml").string(); }

/// Runs argv to the end; its exit code and output.
std::pair<int, std::string> Run(const std::vector<std::string>& argv,
                                std::chrono::milliseconds timeout = 60s) {
  Child c;
  std::string error;
  if (!c.Start(argv, &error)) return {-1, error};
  auto rc = c.Wait(timeout);
  return {rc.value_or(-1000), c.output()};
}

/// The job (1 tree, depth 6) in `dir` and `poseforest train`'s forest of it: the reference.
std::vector<uint8_t> WriteJobAndTrain(const fs::path& dir) {
  std::ofstream(dir / "job.textproto") << TinyJobText(1, 6);
  auto [rc, out] = Run(
      {Program(), "train", (dir / "job.textproto").string(), "--out", (dir / "ref.pff").string(), "--quiet"});
  INFO(out);
  REQUIRE(rc == 0);
  auto bytes = ReadAll(dir / "ref.pff");
  REQUIRE(bytes.size() > 100);
  return bytes;
}

/// deploy/security/make-test-ca.sh OUT NAMES...
void MakeCa(const fs::path& out, const std::vector<std::string>& names) {
  std::vector<std::string> argv = {"sh", (Source() / "deploy/security/make-test-ca.sh").string(),
                                   out.string()};
  argv.insert(argv.end(), names.begin(), names.end());
  auto [rc, text] = Run(argv);
  INFO(text);
  REQUIRE(rc == 0);
}
}  // namespace

TEST_CASE("deploy: the shipped XML profile poseforest_shm, by flags and by environment, gives train's forest",
          "[deploy][integration]") {
  TempDir dir("pf-deploy-xml");
  const auto reference = WriteJobAndTrain(dir.path);
  const std::string domain = std::to_string(Domain(41));
  const std::string job_id = "deploy-xml-" + std::to_string(::getpid());
  Child w0, w1, coord;
  std::string error;
  REQUIRE(w0.Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", "xw-0", "--dds-xml",
                    ShippedXml(), "--dds-profile", "poseforest_shm"},
                   &error));
  // The container images set the profile through the environment instead of flags.
  REQUIRE(w1.Start({"env", "POSEFOREST_DDS_XML=" + ShippedXml(), "POSEFOREST_DDS_PROFILE=poseforest_shm",
                    Program(), "worker", "--domain", domain, "--job", job_id, "--id", "xw-1"},
                   &error));
  REQUIRE(coord.Start(
      {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
       (dir.path / "forest.pff").string(), "--domain", domain, "--job-id", job_id, "--min-workers", "2",
       "--http", "off", "--dds-xml", ShippedXml(), "--dds-profile", "poseforest_shm"},
      &error));
  auto rc = coord.Wait(90s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(coord.output().find("2 workers alive") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  for (Child* w : {&w0, &w1}) {
    CHECK(w->Wait(10s).has_value());  // they exit on JOB_DONE
    INFO(w->output());
    CHECK(w->output().find("joined job " + job_id) != std::string::npos);
  }
}

TEST_CASE("deploy: --discovery-server through a real fast-discovery-server; nothing without it",
          "[deploy][integration]") {
  TempDir dir("pf-deploy-ds");
  const auto reference = WriteJobAndTrain(dir.path);
  const int port = 20000 + int((::getpid() * 7) % 20000);
  Child server;
  std::string error;
  REQUIRE(server.Start({"fast-discovery-server", "-i", "0", "-l", "127.0.0.1", "-p", std::to_string(port)},
                       &error));
  REQUIRE(server.WaitForLine("Server is running", 10s).has_value());
  // --local-workers hands the flag on to the worker processes.
  auto [rc, out] =
      Run({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
           (dir.path / "forest.pff").string(), "--local-workers", "2", "--domain", std::to_string(Domain(42)),
           "--http", "off", "--discovery-server", "127.0.0.1:" + std::to_string(port)},
          90s);
  INFO(out);
  REQUIRE(rc == 0);
  CHECK(out.find("2 workers alive") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  server.Kill(SIGTERM);
  CHECK(server.Wait(10s).has_value());

  // The same without a server at that address: clients do not discover each other by multicast.
  auto [rc2, out2] = Run(
      {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
       (dir.path / "none.pff").string(), "--local-workers", "1", "--domain", std::to_string(Domain(42)),
       "--http", "off", "--worker-wait-s", "3", "--discovery-server", "127.0.0.1:" + std::to_string(port)},
      60s);
  INFO(out2);
  CHECK(rc2 == 1);
  CHECK(out2.find("0 of 1 workers") != std::string::npos);
  CHECK_FALSE(fs::exists(dir.path / "none.pff"));
}

TEST_CASE(
    "deploy: host names in --discovery-server and --peers, resolved once at start-up; unknown names refused",
    "[deploy][integration]") {
  // `localhost` comes from /etc/hosts (no DNS query); the IPv4 address, not ::1.
  auto local = proto::dds::ResolveIPv4("localhost");
  REQUIRE(local.ok());
  CHECK(std::find(local->begin(), local->end(), "127.0.0.1") != local->end());
  for (const std::string& a : *local) CHECK(proto::dds::IsIPv4Address(a));
  CHECK(*proto::dds::ResolveIPv4("10.1.2.3") == std::vector<std::string>{"10.1.2.3"});
  for (const char* ok : {"localhost", "coordinator-0.poseforest",
                         "dds-discovery.poseforest.svc.cluster.local.", "10.0.0.1", "a1"})
    CHECK(proto::dds::CheckHost(ok, true).ok());
  for (const char* bad :
       {"10.0.0", "10.0.0.256", "-x.local", "x-.local", "a..b", "a_b", "::1", "fe80::1", "", "host.123"})
    CHECK_FALSE(proto::dds::CheckHost(bad, true).ok());
  CHECK_FALSE(proto::dds::CheckHost("localhost", false).ok());

  TempDir dir("pf-deploy-names");
  const auto reference = WriteJobAndTrain(dir.path);
  const std::string job = (dir.path / "job.textproto").string();
  {  // --check-config shows what each name became; a local worker gets the addresses
    auto [rc, text] =
        Run({Program(), "worker", "--check-config", "--discovery-server", "0@localhost:7000,1@10.0.0.2"});
    INFO(text);
    CHECK(rc == 0);
    CHECK(text.find("discovery servers 127.0.0.1:7000 (id 0, GUID prefix 44.53.00.5f") != std::string::npos);
    CHECK(text.find("host names resolved once, at start-up: --discovery-server localhost -> 127.0.0.1") !=
          std::string::npos);
    // Both name the build they would run as: a host of another build is refused at the job.
    const std::string build = "build \"" + proto::dds::BuildId() + "\"";
    CHECK(text.find(build) != std::string::npos);
    auto [rc2, text2] = Run({Program(), "coordinator", job, "--out", (dir.path / "x.pff").string(),
                             "--check-config", "--profile", "udp", "--peers", "localhost:7410,10.0.0.9"});
    INFO(text2);
    CHECK(rc2 == 0);
    CHECK(text2.find("UDP, initial peers 127.0.0.1:7410,10.0.0.9") != std::string::npos);
    CHECK(text2.find("--peers localhost -> 127.0.0.1") != std::string::npos);
    CHECK(text2.find(build) != std::string::npos);
  }
  {  // A name that does not resolve: exit 2 naming the flag and the name, at --check-config and at
     // start, from the command line and from the job's dds section. Run in a network namespace of
     // its own (no routes), so that the lookup never leaves this host: glibc would ask the DNS
     // server of /etc/resolv.conf about `.invalid` names too.
    const std::vector<std::string> netns = {"unshare", "-r", "-n"};
    auto isolated = [&](std::vector<std::string> argv) {
      argv.insert(argv.begin(), netns.begin(), netns.end());
      return Run(argv);
    };
    const std::string ds_error =
        "--discovery-server 0@no-such-host.invalid:7000: host name 'no-such-host.invalid' does not resolve "
        "to an "
        "IPv4 address";
    const std::string peers_error =
        "--peers 10.0.0.1,no-such-host.invalid: host name 'no-such-host.invalid' does not resolve to an IPv4 "
        "address";
    struct Case {
      std::vector<std::string> argv;
      std::string expect;
    };
    std::ofstream(dir.path / "job-names.textproto")
        << TinyJobText(1, 6) << "dds { discovery_server: \"no-such-host.invalid\" }\n";
    const std::vector<Case> cases = {
        {{Program(), "worker", "--check-config", "--discovery-server", "0@no-such-host.invalid:7000"},
         ds_error},
        {{Program(), "worker", "--job", "x", "--discovery-server", "0@no-such-host.invalid:7000"}, ds_error},
        {{Program(), "coordinator", job, "--out", (dir.path / "x.pff").string(), "--discovery-server",
          "0@no-such-host.invalid:7000"},
         ds_error},
        {{Program(), "worker", "--check-config", "--profile", "udp", "--peers",
          "10.0.0.1,no-such-host.invalid"},
         peers_error},
        {{Program(), "monitor", "--domain", "3", "--profile", "udp", "--peers",
          "10.0.0.1,no-such-host.invalid"},
         peers_error},
        {{Program(), "coordinator", (dir.path / "job-names.textproto").string(), "--out",
          (dir.path / "x.pff").string(), "--check-config"},
         "host name 'no-such-host.invalid' does not resolve to an IPv4 address"},
        {{Program(), "worker", "--job-file", (dir.path / "job-names.textproto").string(), "--check-config"},
         "(transport settings from the dds section of " + (dir.path / "job-names.textproto").string() + ")"},
        // localhost still resolves there: /etc/hosts
        {{Program(), "worker", "--check-config", "--discovery-server", "localhost"},
         "localhost -> 127.0.0.1"},
    };
    for (const Case& c : cases) {
      auto [rc, text] = isolated(c.argv);
      INFO(c.argv[1] << " " << c.argv.back() << ": " << text);
      CHECK(rc == (c.expect.find("->") != std::string::npos ? 0 : 2));
      CHECK(text.find(c.expect) != std::string::npos);
    }
    CHECK_FALSE(fs::exists(dir.path / "x.pff"));
  }
  // The real thing: a coordinator and a worker process meet through a fast-discovery-server they
  // both name `localhost` (the worker with the server's id): `poseforest train`'s forest.
  const int port = 20000 + int((::getpid() * 7 + 9) % 20000);
  Child server, worker, coord;
  std::string error;
  REQUIRE(server.Start({"fast-discovery-server", "-i", "0", "-l", "127.0.0.1", "-p", std::to_string(port)},
                       &error));
  REQUIRE(server.WaitForLine("Server is running", 10s).has_value());
  const std::string domain = std::to_string(Domain(50));
  const std::string job_id = "deploy-names-" + std::to_string(::getpid());
  REQUIRE(worker.Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", "nw-0",
                        "--discovery-server", "0@localhost:" + std::to_string(port)},
                       &error));
  REQUIRE(coord.Start({Program(), "coordinator", job, "--out", (dir.path / "forest.pff").string(), "--domain",
                       domain, "--job-id", job_id, "--min-workers", "1", "--worker-wait-s", "40", "--http",
                       "off", "--discovery-server", "localhost:" + std::to_string(port)},
                      &error));
  auto rc = coord.Wait(90s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(
      coord.output().find("DDS host names resolved at start-up: --discovery-server localhost -> 127.0.0.1") !=
      std::string::npos);
  CHECK(coord.output().find("1 workers alive") != std::string::npos);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  CHECK(worker.Wait(10s).has_value());  // it exits on JOB_DONE
  INFO(worker.output());
  CHECK(worker.output().find(
            "DDS host names resolved at start-up: --discovery-server localhost -> 127.0.0.1") !=
        std::string::npos);
  CHECK(worker.output().find("joined job " + job_id) != std::string::npos);
  server.Kill(SIGTERM);
  CHECK(server.Wait(10s).has_value());
}

TEST_CASE("deploy: --discovery-server with redundant servers (ids 0 and 1); the id must be the server's -i",
          "[deploy][integration]") {
  TempDir dir("pf-deploy-ds2");
  const auto reference = WriteJobAndTrain(dir.path);
  const int p0 = 20000 + int((::getpid() * 7 + 3) % 20000), p1 = 20000 + int((::getpid() * 7 + 5) % 20000);
  const std::string s0 = "0@127.0.0.1:" + std::to_string(p0), s1 = "1@127.0.0.1:" + std::to_string(p1);
  Child server0, server1;
  std::string error;
  REQUIRE(server0.Start({"fast-discovery-server", "-i", "0", "-l", "127.0.0.1", "-p", std::to_string(p0)},
                        &error));
  REQUIRE(server1.Start({"fast-discovery-server", "-i", "1", "-l", "127.0.0.1", "-p", std::to_string(p1)},
                        &error));
  REQUIRE(server0.WaitForLine("Server is running", 10s).has_value());
  REQUIRE(server1.WaitForLine("Server is running", 10s).has_value());
  {  // The coordinator and one worker are clients of both servers; the two other workers each of
     // one only, so the coordinator finds one through server 0 and one through server 1 alone.
    const std::string domain = std::to_string(Domain(44));
    const std::string job_id = "deploy-ds2-" + std::to_string(::getpid());
    Child w_both, w_0, w_1, coord;
    auto worker = [&](Child* c, const std::string& id, const std::string& servers) {
      REQUIRE(c->Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", id,
                        "--discovery-server", servers},
                       &error));
    };
    worker(&w_both, "dw-both", s1 + "," + s0);
    worker(&w_0, "dw-0", s0);
    worker(&w_1, "dw-1", s1);
    REQUIRE(coord.Start(
        {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
         (dir.path / "forest.pff").string(), "--domain", domain, "--job-id", job_id, "--min-workers", "3",
         "--worker-wait-s", "40", "--http", "off", "--discovery-server", s0 + "," + s1},
        &error));
    auto rc = coord.Wait(90s);
    INFO(coord.output());
    REQUIRE(rc.has_value());
    REQUIRE(*rc == 0);
    CHECK(coord.output().find("3 workers alive") != std::string::npos);
    CHECK(ReadAll(dir.path / "forest.pff") == reference);
    for (Child* w : {&w_both, &w_0, &w_1}) {
      CHECK(w->Wait(10s).has_value());  // they exit on JOB_DONE
      INFO(w->output());
      CHECK(w->output().find("joined job " + job_id) != std::string::npos);
    }
  }
  server0.Kill(SIGTERM);
  CHECK(server0.Wait(10s).has_value());

  // Only the id-1 server runs: its id reaches it (--local-workers hands the list on)...
  auto [rc, out] = Run({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                        (dir.path / "forest1.pff").string(), "--local-workers", "1", "--domain",
                        std::to_string(Domain(46)), "--http", "off", "--discovery-server", s1},
                       90s);
  INFO(out);
  REQUIRE(rc == 0);
  CHECK(ReadAll(dir.path / "forest1.pff") == reference);
  // ...another id at the same address does not: the client expects another GUID prefix there.
  auto [rc2, out2] = Run(
      {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
       (dir.path / "none.pff").string(), "--local-workers", "1", "--domain", std::to_string(Domain(48)),
       "--http", "off", "--worker-wait-s", "3", "--discovery-server", "2@127.0.0.1:" + std::to_string(p1)},
      60s);
  INFO(out2);
  CHECK(rc2 == 1);
  CHECK(out2.find("0 of 1 workers") != std::string::npos);
  CHECK_FALSE(fs::exists(dir.path / "none.pff"));
  server1.Kill(SIGTERM);
  CHECK(server1.Wait(10s).has_value());
}

TEST_CASE("deploy: --security trains; participants without credentials or from another CA get nothing in",
          "[deploy][integration]") {
  TempDir dir("pf-deploy-sec");
  const auto reference = WriteJobAndTrain(dir.path);
  const fs::path ca = dir.path / "ca", other = dir.path / "other-ca";
  MakeCa(ca, {"coordinator", "worker-1", "worker-2"});
  MakeCa(other, {"worker-1"});  // same names and layout, another CA
  const std::string domain = std::to_string(Domain(43));
  const std::string job_id = "deploy-sec-" + std::to_string(::getpid());
  std::string error;
  // Intruders first, so that they are there for the whole job: a real worker without
  // credentials, and participants that say hello and heartbeat for the job on the presence topic
  // (what a worker does to be counted) without credentials and with another CA's certificate.
  Child intruder_worker, plain_peer, foreign_peer;
  REQUIRE(intruder_worker.Start(
      {Program(), "worker", "--domain", domain, "--job", job_id, "--id", "intruder"}, &error));
  REQUIRE(plain_peer.Start({Peer(), "--mode=alive", "--transport=shm", "--domain=" + domain,
                            "--job=" + job_id, "--id=plain-peer", "--seconds=120"},
                           &error));
  REQUIRE(
      foreign_peer.Start({Peer(), "--mode=alive", "--transport=shm", "--domain=" + domain, "--job=" + job_id,
                          "--id=worker-1", "--sec-dir=" + other.string(), "--seconds=120"},
                         &error));
  REQUIRE(plain_peer.WaitForLine("STARTED", 20s).has_value());
  REQUIRE(foreign_peer.WaitForLine("STARTED", 20s).has_value());
  Child w1, w2, coord;
  REQUIRE(w1.Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", "sw-1", "--security",
                    (ca / "worker-1").string()},
                   &error));
  REQUIRE(w2.Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", "sw-2", "--security",
                    (ca / "worker-2").string()},
                   &error));
  const fs::path events = dir.path / "events.jsonl", pause = dir.path / "pause";
  std::ofstream(pause) << "hold\n";
  REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                       (dir.path / "forest.pff").string(), "--domain", domain, "--job-id", job_id,
                       "--min-workers", "2", "--http", "off", "--event-log", events.string(), "--pause-file",
                       pause.string(), "--security", (ca / "coordinator").string()},
                      &error));
  {  // Held before level 0 with both workers assigned: `monitor --domain` sees the job only with
     // credentials (a worker's grant reads the job and status topics).
    auto paused = coord.WaitForLine("paused (next: tree 0, level 0)", 60s);
    INFO(coord.output());
    // On failure, what the secure workers said too (a CI run once saw sw-2 never join).
    if (!paused) {
      INFO("sw-1:\n" << w1.OutputNow());
      INFO("sw-2:\n" << w2.OutputNow());
      INFO("intruder:\n" << intruder_worker.OutputNow());
      FAIL("the job was never held before level 0 with both secure workers");
    }
    // Asked up to 3 times while the job is held: on a loaded CI machine the secure handshake
    // with a fresh participant once took longer than one 20 s wait (the test_deploy failure seen
    // in a fresh-clone CI); the job stays paused, so every attempt sees the same job.
    int mrc = -1;
    std::string mout;
    for (int attempt = 0; attempt < 3 && mrc != 0; ++attempt)
      std::tie(mrc, mout) = Run({Program(), "monitor", "--domain", domain, "--job", job_id, "--once",
                                 "--timeout-s", "20", "--security", (ca / "worker-2").string()});
    INFO(mout);
    CHECK(mrc == 0);
    CHECK(mout.find("job " + job_id) != std::string::npos);
    auto [mrc2, mout2] =
        Run({Program(), "monitor", "--domain", domain, "--job", job_id, "--once", "--timeout-s", "3"});
    INFO(mout2);
    CHECK(mrc2 == 1);
    CHECK(mout2.find("no status of " + job_id) != std::string::npos);
    fs::remove(pause);
  }
  auto rc = coord.Wait(90s);
  INFO(coord.output());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  CHECK(coord.output().find("2 workers alive") != std::string::npos);
  CHECK(coord.output().find("3 workers alive") == std::string::npos);
  CHECK(coord.output().find(" 0 messages rejected") != std::string::npos);
  const std::string log = ReadText(events);
  INFO(log);
  CHECK(log.find("sw-1") != std::string::npos);  // the log names the workers it counted...
  CHECK(log.find("sw-2") != std::string::npos);
  for (const char* stranger : {"intruder", "plain-peer", "worker-1"})  // ...and none of these
    CHECK(log.find(stranger) == std::string::npos);
  for (const char* stranger : {"intruder", "plain-peer", "worker-1"})
    CHECK(coord.output().find(stranger) == std::string::npos);
  for (Child* w : {&w1, &w2}) CHECK(w->Wait(10s).has_value());
  // The intruders never matched anyone of the job: no job for the worker, no reader for the
  // presence samples (a peer prints "MATCHED presence" when one of its readers appears).
  intruder_worker.Kill(SIGKILL);
  plain_peer.Kill(SIGKILL);
  foreign_peer.Kill(SIGKILL);
  INFO(intruder_worker.output());
  INFO(plain_peer.output());
  INFO(foreign_peer.output());
  CHECK(intruder_worker.output().find("joined job") == std::string::npos);
  CHECK(plain_peer.output().find("MATCHED") == std::string::npos);
  CHECK(foreign_peer.output().find("MATCHED") == std::string::npos);
}

TEST_CASE("deploy: --security over UDP initial peers (the multi-host way) trains train's forest",
          "[deploy][integration]") {
  // With Fast DDS 2.9 DDS-Security across hosts goes over --profile udp --peers: it has no secure
  // discovery server (the combination is refused, below). A worker and a coordinator on loopback.
  TempDir dir("pf-deploy-sec-udp");
  const auto reference = WriteJobAndTrain(dir.path);
  const fs::path ca = dir.path / "ca";
  MakeCa(ca, {"coordinator", "worker-1"});
  const std::string domain = std::to_string(Domain(50));
  const std::string job_id = "deploy-sec-udp-" + std::to_string(::getpid());
  std::string error;
  Child w1, coord;
  REQUIRE(w1.Start({Program(), "worker", "--domain", domain, "--job", job_id, "--id", "su-1", "--profile",
                    "udp", "--peers", "127.0.0.1", "--security", (ca / "worker-1").string()},
                   &error));
  REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                       (dir.path / "forest.pff").string(), "--domain", domain, "--job-id", job_id,
                       "--min-workers", "1", "--http", "off", "--profile", "udp", "--peers", "127.0.0.1",
                       "--security", (ca / "coordinator").string()},
                      &error));
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  INFO("su-1:\n" << w1.OutputNow());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  CHECK(ReadAll(dir.path / "forest.pff") == reference);
  CHECK(coord.output().find("worker su-1 joined") != std::string::npos);
  CHECK(w1.Wait(20s).has_value());
}

TEST_CASE("deploy: DDS flag errors name the file, the profile, the credential or the contradiction",
          "[deploy][integration]") {
  TempDir dir("pf-deploy-flags");
  std::ofstream(dir.path / "job.textproto") << TinyJobText(1, 6);
  const std::string job = (dir.path / "job.textproto").string(), out = (dir.path / "f.pff").string();
  auto worker = [&](std::vector<std::string> flags) {
    flags.insert(flags.begin(), {Program(), "worker", "--check-config"});
    return Run(flags);
  };
  auto coordinator = [&](std::vector<std::string> flags) {
    flags.insert(flags.begin(), {Program(), "coordinator", job, "--out", out, "--check-config"});
    return Run(flags);
  };
  struct Case {
    std::vector<std::string> flags;
    std::string expect;
  };
  const std::string xml = ShippedXml();
  const fs::path ca = dir.path / "ca";
  MakeCa(ca, {"coordinator", "worker-1"});
  fs::create_directories(dir.path / "incomplete");
  fs::copy_file(ca / "worker-1" / "cert.pem", dir.path / "incomplete" / "cert.pem");
  fs::copy_file(ca / "worker-1" / "permissions.p7s", dir.path / "incomplete" / "permissions.p7s");
  const std::vector<Case> bad = {
      {{"--dds-xml", "/nonexistent/profiles.xml", "--dds-profile", "x"},
       "cannot read Fast DDS XML profiles file /nonexistent/profiles.xml"},
      {{"--dds-xml", xml, "--dds-profile", "poseforest_nope"},
       "no participant profile 'poseforest_nope' in " + xml + " (it has: poseforest_shm"},
      {{"--dds-xml", xml}, "needs a participant profile name: --dds-profile NAME"},
      {{"--dds-profile", "poseforest_shm"}, "needs the XML file: --dds-xml FILE"},
      {{"--dds-xml", xml, "--dds-profile", "poseforest_shm", "--profile", "udp"},
       "cannot be combined with --profile"},
      {{"--dds-xml", xml, "--dds-profile", "poseforest_shm", "--discovery-server", "127.0.0.1"},
       "cannot be combined with --discovery-server"},
      {{"--discovery-server", "127.0.0.1:11811", "--profile", "shm"}, "--profile shm contradicts it"},
      {{"--discovery-server", "127.0.0.1", "--peers", "10.0.0.1"},
       "--peers cannot be combined with --discovery-server"},
      {{"--discovery-server", "server_1.local"},
       "'server_1.local' is not a host name: 'server_1' has characters other than letters, digits and '-'"},
      {{"--discovery-server", "1@::1"},
       "'1@::1' is an IPv6 address, not supported: the transports are UDPv4"},
      {{"--discovery-server", "localhost,1@127.0.0.1"},
       "1@127.0.0.1:11811 and localhost:11811 are the same address 127.0.0.1:11811"},
      {{"--profile", "udp", "--peers", "10.0.0"}, "--peers 10.0.0: '10.0.0' is not an IPv4 address"},
      {{"--profile", "udp", "--peers", "[::1]:7400"}, "'[::1]:7400' is an IPv6 address, not supported"},
      {{"--profile", "udp", "--interfaces", "localhost"},
       "--interfaces localhost: 'localhost' is not an IPv4 address (expected a.b.c.d)"},
      {{"--discovery-server", "256@127.0.0.1"}, "'256@127.0.0.1' has server id '256': expected 0..255"},
      {{"--discovery-server", "0@127.0.0.1,x@127.0.0.2"}, "'x@127.0.0.2' has server id 'x': expected 0..255"},
      {{"--discovery-server", "1@127.0.0.1:0"}, "'1@127.0.0.1:0' has port '0': expected 1..65535"},
      {{"--discovery-server", "127.0.0.1:70000"}, "'127.0.0.1:70000' has port '70000': expected 1..65535"},
      {{"--discovery-server", "1@10.0.0"},
       "'1@10.0.0' is not an IPv4 address (expected [ID@]a.b.c.d[:port] or [ID@]HOST-NAME[:port])"},
      {{"--discovery-server", "1@10.0.0.1,1@10.0.0.2"}, "'1@10.0.0.2' repeats server id 1 of '1@10.0.0.1'"},
      {{"--discovery-server", "10.0.0.1,0@10.0.0.2"}, "'0@10.0.0.2' repeats server id 0 of '10.0.0.1'"},
      {{"--discovery-server", "0@10.0.0.1:7000,1@10.0.0.1:7000"},
       "'1@10.0.0.1:7000' repeats the address 10.0.0.1:7000 of '0@10.0.0.1:7000'"},
      {{"--discovery-server", ","}, "--discovery-server ,: no server given"},
      {{"--interfaces", "127.0.0.1"}, "--interfaces needs --profile udp or --discovery-server"},
      {{"--security", (dir.path / "nothing").string()}, "not a directory"},
      {{"--security", (dir.path / "incomplete").string()},
       "missing or unreadable identity_ca.pem (looked in"},
      {{"--security", (dir.path / "incomplete").string()},
       "key.pem (looked in " + (dir.path / "incomplete").string() + ")"},
      {{"--dds-xml", xml, "--dds-profile", "poseforest_secure_template"},
       "file:///etc/poseforest/dds/identity_ca.pem, which cannot be read"},
      // Fast DDS 2.9 has no secure discovery server: secured participants find each other through
      // an unauthenticated one, but none of their endpoints ever match (tried by hand with
      // fast-discovery-server: "Security manager returns an error"), so the combination is refused.
      {{"--discovery-server", "127.0.0.1", "--security", (ca / "worker-1").string()},
       "with a discovery server (--discovery-server): Fast DDS 2.9 has no secure discovery server"},
      {{"--dds-xml", xml, "--dds-profile", "poseforest_discovery_client", "--security",
        (ca / "worker-1").string()},
       "with a discovery server (profile poseforest_discovery_client): Fast DDS 2.9 has no secure"},
  };
  for (const Case& c : bad) {
    for (bool as_worker : {true, false}) {
      auto [rc, text] = as_worker ? worker(c.flags) : coordinator(c.flags);
      INFO((as_worker ? "worker " : "coordinator ") << c.flags[0] << " " << c.flags.back() << ": " << text);
      CHECK(rc == 2);
      CHECK(text.find(c.expect) != std::string::npos);
    }
  }
  {  // the environment: named in the error; ignored once a transport flag is given
    auto [rc, text] = Run({"env", "POSEFOREST_DDS_XML=" + xml, Program(), "worker", "--check-config"});
    INFO(text);
    CHECK(rc == 2);
    CHECK(text.find("POSEFOREST_DDS_XML=" + xml + " needs a participant profile name") != std::string::npos);
    auto [rc2, text2] = Run({"env", "POSEFOREST_DDS_XML=" + xml, "POSEFOREST_DDS_PROFILE=poseforest_nope",
                             Program(), "worker", "--check-config", "--profile", "udp"});
    INFO(text2);
    CHECK(rc2 == 0);
    CHECK(text2.find("UDP, initial peers 127.0.0.1") != std::string::npos);
  }
  {  // --check-config shows each discovery server with the id and GUID prefix the client expects
     // (Fast DDS: 44.53.<id>.5f.45.50.52.4f.53.49.4d.41); the single-server form is unchanged.
    auto [rc, text] = worker({"--discovery-server", "0@127.0.0.1:7400,255@10.0.0.2"});
    INFO(text);
    CHECK(rc == 0);
    CHECK(
        text.find(
            "UDP, discovery servers 127.0.0.1:7400 (id 0, GUID prefix 44.53.00.5f.45.50.52.4f.53.49.4d.41), "
            "255@10.0.0.2:11811 (id 255, GUID prefix 44.53.ff.5f.45.50.52.4f.53.49.4d.41)") !=
        std::string::npos);
    auto [rc2, text2] = worker({"--discovery-server", "127.0.0.1"});
    INFO(text2);
    CHECK(rc2 == 0);
    CHECK(text2.find("UDP, discovery server 127.0.0.1:11811 (id 0, GUID prefix 44.53.00.5f") !=
          std::string::npos);
  }
  {  // make-test-ca.sh's layout, also written with a trailing slash: the CA files come from the parent
    auto [rc, text] = worker({"--security", (ca / "worker-1").string() + "/"});
    INFO(text);
    CHECK(rc == 0);
    CHECK(text.find("DDS-Security with " + (ca / "worker-1" / "cert.pem").string()) != std::string::npos);
  }
  {  // A restart that forgot --resume would start over and overwrite the checkpoint after its first
     // level: refused, the file untouched. --resume without a folder to resume from: refused.
    fs::create_directories(dir.path / "ckpt");
    std::ofstream(dir.path / "ckpt" / "checkpoint.pb") << "a checkpoint";
    auto [rc, text] = coordinator({"--checkpoint", (dir.path / "ckpt").string()});
    INFO(text);
    CHECK(rc == 2);
    CHECK(text.find("--checkpoint " + (dir.path / "ckpt").string() +
                    " already holds a checkpoint (checkpoint.pb); add --resume") != std::string::npos);
    std::ifstream in(dir.path / "ckpt" / "checkpoint.pb");
    CHECK(std::string(std::istreambuf_iterator<char>(in), {}) == "a checkpoint");
    auto [rc2, text2] = coordinator({"--resume"});
    INFO(text2);
    CHECK(rc2 == 2);
    CHECK(text2.find("--resume needs --checkpoint DIR") != std::string::npos);
  }
  // --local-workers under --security: the workers need credentials of their own.
  auto [rc, text] = coordinator({"--local-workers", "2", "--security", (ca / "coordinator").string()});
  INFO(text);
  CHECK(rc == 2);
  CHECK(text.find("needs --worker-security DIR") != std::string::npos);
  auto [rc2, text2] = coordinator({"--local-workers", "2", "--security", (ca / "coordinator").string(),
                                   "--worker-security", (ca / "worker-1").string()});
  INFO(text2);
  CHECK(rc2 == 0);
  CHECK(text2.find("DDS-Security with " + (ca / "coordinator" / "cert.pem").string()) != std::string::npos);
  auto [rc3, text3] = coordinator({"--dds-xml", xml, "--dds-profile", "poseforest_udp_loopback"});
  INFO(text3);
  CHECK(rc3 == 0);
  CHECK(text3.find("coordinator config ok") != std::string::npos);
  auto [rc4, text4] =
      Run({Program(), "coordinator", job, "--out", "/nonexistent-dir/f.pff", "--check-config"});
  INFO(text4);
  CHECK(rc4 == 2);
  CHECK(text4.find("folder /nonexistent-dir does not exist") != std::string::npos);
  // A checkpoint "folder" that is a file, and a status file in no folder: found before the job
  // starts (they used to pass --check-config, then stop the job after its first level).
  auto [rc6, text6] = coordinator({"--checkpoint", job});
  INFO(text6);
  CHECK(rc6 == 2);
  CHECK(text6.find("--checkpoint " + job + ": a file, not a folder") != std::string::npos);
  auto [rc7, text7] = coordinator({"--status-file", "/nonexistent-dir/s.json"});
  INFO(text7);
  CHECK(rc7 == 2);
  CHECK(text7.find("--status-file /nonexistent-dir/s.json: folder /nonexistent-dir does not exist") !=
        std::string::npos);
  // monitor --domain takes the same flags (and the same checks).
  auto [rc5, text5] =
      Run({Program(), "monitor", "--domain", "3", "--dds-xml", xml, "--dds-profile", "poseforest_nope"});
  INFO(text5);
  CHECK(rc5 == 2);
  CHECK(text5.find("no participant profile 'poseforest_nope'") != std::string::npos);
}

namespace {
/// tests/coordinator/check_deploy_commands.py on `deploy` (a deploy/ folder), plus `extra` flags.
std::pair<int, std::string> CheckDeployCommands(const fs::path& deploy,
                                                const std::vector<std::string>& extra = {}) {
  std::vector<std::string> argv = {
      "python3",  (Source() / "tests/coordinator/check_deploy_commands.py").string(),
      "--bin",    Program(),
      "--source", Source().string(),
      "--deploy", deploy.string()};
  argv.insert(argv.end(), extra.begin(), extra.end());
  return Run(argv, 120s);
}

void Replace(const fs::path& file, const std::string& from, const std::string& to) {
  std::string text = ReadText(file);
  const size_t at = text.find(from);
  REQUIRE(at != std::string::npos);
  text.replace(at, from.size(), to);
  std::ofstream(file) << text;
}
}  // namespace

TEST_CASE(
    "deploy: every command line of deploy/k8s, deploy/docker and deploy/compose.yaml passes the real parser",
    "[deploy][integration]") {
  auto [rc, out] = CheckDeployCommands(Source() / "deploy");
  INFO(out);
  CHECK(rc == 0);
  for (const char* what :
       {"ok   deploy/docker/Dockerfile.coordinator: poseforest coordinator",
        "ok   deploy/docker/Dockerfile.worker: poseforest worker",
        "ok   deploy/docker/Dockerfile.discovery-server", "ok   deploy/k8s: `kubectl kustomize` renders",
        "ok   deploy/k8s/coordinator.yaml Job/coordinator", "ok   deploy/k8s/workers.yaml StatefulSet/worker",
        "ok   deploy/k8s/workers.yaml StatefulSet/worker container worker readinessProbe: poseforest worker",
        "ok   deploy/k8s/workers.yaml StatefulSet/worker container worker livenessProbe: sh -c",
        "ok   deploy/k8s/coordinator.yaml Job/coordinator container coordinator livenessProbe: httpGet "
        "/healthz",
        "ok   deploy/k8s/discovery-server.yaml Deployment/dds-discovery", "coordinator config ok",
        "worker config ok: id worker-0", "Fast DDS XML profile poseforest_k8s",
        // deploy/compose.yaml (docs/distributed/compose.md): the services' names resolve as on
        // the compose network; Prometheus's config through promtool, its targets the services.
        "ok   deploy/compose.yaml service coordinator: poseforest coordinator",
        "--discovery-server discovery -> 10.250.0.",
        "ok   deploy/compose.yaml service worker: poseforest worker",
        "metrics on http://0.0.0.0:9101/metrics",
        "ok   deploy/compose.yaml service discovery: fast-discovery-server",
        "ok   deploy/compose.yaml service prometheus: promtool check config /etc/prometheus/prometheus.yml",
        " 0 problems"})
    CHECK(out.find(what) != std::string::npos);
  // The compose CLI's own `config` (docker compose v2 or Debian's docker-compose, which
  // scripts/setup.sh installs): it must be there and accept the file.
  INFO("no compose CLI: install Debian's docker-compose (scripts/setup.sh does)");
  CHECK(out.find("no compose CLI here") == std::string::npos);
  CHECK(out.find("config` accepts it: services") != std::string::npos);

  // A manifest or image with a wrong flag, profile or value fails the check, naming it.
  struct Mutation {
    std::string file, from, to, expect;
    std::string fails = "";  ///< the file whose command fails, when not `file`
  };
  const std::vector<Mutation> mutations = {
      {"k8s/coordinator.yaml", "\"--checkpoint\", \"/var/lib/poseforest/checkpoint\"",
       "\"--checkpoint-dir=/var/lib/poseforest/checkpoint\"", "unknown option --checkpoint-dir"},
      {"k8s/workers.yaml", "value: poseforest_k8s", "value: poseforest_k9s",
       "no participant profile 'poseforest_k9s'"},
      {"k8s/workers.yaml", "\"--threads\", \"4\"", "\"--threads\", \"four\"", "--threads"},
      {"k8s/coordinator.yaml", "/etc/poseforest/job.textproto", "/etc/poseforest/jobs.textproto",
       "jobs.textproto"},
      {"k8s/coordinator.yaml", "\"--http-tls-key\", \"/etc/poseforest-http-tls/tls.key\"",
       "\"--http-tls-key\", \"/etc/poseforest-http-tls/tls.crt\"", "no PEM private key in it"},
      {"docker/Dockerfile.worker", "CMD [\"--stay\"]", "CMD [\"--stay\", \"--profile\", \"tcp\"]",
       "expected shm, udp or default"},
      {"docker/Dockerfile.coordinator", "POSEFOREST_DDS_PROFILE=poseforest_discovery_client",
       "POSEFOREST_DDS_PROFILE=poseforest_discovery", "no participant profile 'poseforest_discovery'"},
      // Host names must name a Service of the manifests (the checker's stand-in for cluster DNS).
      {"k8s/configmap.yaml", "<address>dds-discovery</address>", "<address>dds-discovry</address>",
       "Fast DDS cannot parse the XML profiles", "k8s/workers.yaml"},
      {"k8s/workers.yaml", "\"--stay\"]", "\"--stay\", \"--discovery-server\", \"dds-discovry:11811\"]",
       "--discovery-server dds-discovry:11811: host name 'dds-discovry' does not resolve"},
      // Exec probes run through the parser too, with the container's transport and job flags.
      {"k8s/workers.yaml", "\"--check-config\"]", "\"--chek-config\", \"--check-config\"]",
       "unknown option --chek-config"},
      {"k8s/workers.yaml", "\"--job\", \"poseforest-k8s\", \"--check-config\"]",
       "\"--job\", \"poseforest-k9s\", \"--check-config\"]", "it would check another transport"},
      {"k8s/workers.yaml", "\"--job\", \"poseforest-k8s\", \"--check-config\"]",
       "\"--id=$(POD_NAME)\", \"--job\", \"poseforest-k8s\", \"--check-config\"]",
       "$(POD_NAME) in the command: in a probe Kubernetes expands only env entries with a value"},
      {"k8s/coordinator.yaml", "httpGet: {path: /healthz, port: status,",
       "httpGet: {path: /healthz, port: stats,", "httpGet port stats is not a port of the container"},
      // What `kubectl apply -k` applies is what is checked: a file left out of the kustomization,
      // a claim nobody creates, a kustomization that does not render.
      {"k8s/kustomization.yaml", "  - state-pvc.yaml\n", "",
       "PersistentVolumeClaim/poseforest-state is not in what `kubectl kustomize deploy/k8s` renders",
       "k8s/state-pvc.yaml"},
      {"k8s/coordinator.yaml", "claimName: poseforest-state", "claimName: poseforest-sate",
       "PersistentVolumeClaim poseforest-sate is not in deploy/k8s"},
      {"k8s/kustomization.yaml", "  - workers.yaml\n", "  - worker.yaml\n", "`kubectl kustomize` fails",
       "k8s:"},
      // deploy/compose.yaml: a wrong value, a name that is no service, a network with a way out,
      // an image built from another Dockerfile, Prometheus scraping a port nobody serves.
      {"compose.yaml", "\"--min-workers\", \"${POSEFOREST_WORKERS:-2}\"",
       "\"--min-workers\", \"${POSEFOREST_WORKERS:-two}\"", "--min-workers must be an integer",
       "compose.yaml service coordinator"},
      {"compose.yaml", "\"--discovery-server\", \"discovery\",\n              \"--http\", \"0.0.0.0:9101\"",
       "\"--discovery-server\", \"discovry\",\n              \"--http\", \"0.0.0.0:9101\"",
       "host name 'discovry' does not resolve", "compose.yaml service worker"},
      {"compose.yaml", "    internal: true", "    internal: false", "is not `internal: true`"},
      {"compose.yaml", "dockerfile: deploy/docker/Dockerfile.worker",
       "dockerfile: deploy/docker/Dockerfile.coordinator", "is built as poseforest-coordinator",
       "compose.yaml service worker"},
      {"compose.yaml", "    networks: [poseforest]\n    restart: unless-stopped\n\n  coordinator:",
       "    restart: unless-stopped\n\n  coordinator:", "no network: it would join compose's default network",
       "compose.yaml service discovery"},
      {"prometheus/prometheus.yml", "port: 9101", "port: 9102", "service worker serves --http on port 9101",
       "compose.yaml service prometheus"},
  };
  for (const Mutation& m : mutations) {
    TempDir dir("pf-deploy-mutant");
    fs::copy(Source() / "deploy", dir.path / "deploy", fs::copy_options::recursive);
    Replace(dir.path / "deploy" / m.file, m.from, m.to);
    auto [mrc, mout] = CheckDeployCommands(dir.path / "deploy");
    INFO(m.file << ": " << m.to << "\n" << mout);
    CHECK(mrc == 1);
    CHECK(mout.find("FAIL deploy/" + (m.fails.empty() ? m.file : m.fails)) != std::string::npos);
    CHECK(mout.find(m.expect) != std::string::npos);
  }
  {  // ...and the Service's name, short or in full, resolves as in the cluster
    TempDir dir("pf-deploy-names");
    fs::copy(Source() / "deploy", dir.path / "deploy", fs::copy_options::recursive);
    Replace(dir.path / "deploy/k8s/workers.yaml", "\"--stay\"]",
            "\"--stay\", \"--discovery-server\", \"dds-discovery.poseforest.svc.cluster.local\"]");
    Replace(dir.path / "deploy/k8s/workers.yaml", "\"--check-config\"]",
            "\"--discovery-server\", \"dds-discovery.poseforest.svc.cluster.local\", \"--check-config\"]");
    Replace(dir.path / "deploy/k8s/coordinator.yaml", "\"--resume\",",
            "\"--resume\", \"--discovery-server\", \"dds-discovery\",");
    auto [mrc, mout] = CheckDeployCommands(dir.path / "deploy");
    INFO(mout);
    CHECK(mrc == 0);
    CHECK(mout.find("--discovery-server dds-discovery.poseforest.svc.cluster.local -> 10.96.255.") !=
          std::string::npos);
    CHECK(mout.find("--discovery-server dds-discovery -> 10.96.255.") != std::string::npos);
  }
}

namespace {
using Json = nlohmann::json;

/// The value at a JSON pointer ("/spec/template/spec"), or null when any part is missing.
const Json& At(const Json& j, const std::string& pointer) {
  static const Json kNull;
  const Json::json_pointer p(pointer);
  return j.contains(p) ? j.at(p) : kNull;
}

/// The string at a JSON pointer, or "".
std::string StringAt(const Json& j, const std::string& pointer) {
  const Json& v = At(j, pointer);
  return v.is_string() ? v.get<std::string>() : "";
}

/// The rendered object of `kind` named `name`, or nullptr.
const Json* FindObject(const Json& objects, const std::string& kind, const std::string& name) {
  for (const Json& o : objects)
    if (StringAt(o, "/kind") == kind && StringAt(o, "/metadata/name") == name) return &o;
  return nullptr;
}

/// The container named `name` of a workload's pod template, or nullptr.
const Json* FindContainer(const Json& workload, const std::string& name) {
  const Json& containers = At(workload, "/spec/template/spec/containers");
  if (!containers.is_array()) return nullptr;
  for (const Json& c : containers)
    if (StringAt(c, "/name") == name) return &c;
  return nullptr;
}

/// A container's command line (command + args).
std::vector<std::string> CommandLine(const Json& container) {
  std::vector<std::string> argv;
  for (const char* key : {"/command", "/args"})
    if (const Json& list = At(container, key); list.is_array())
      for (const Json& a : list) argv.push_back(a.is_string() ? a.get<std::string>() : a.dump());
  return argv;
}

/// The value of `flag` ("--flag V" or "--flag=V") in argv, or "" when absent.
std::string FlagValue(const std::vector<std::string>& argv, const std::string& flag) {
  for (size_t i = 0; i < argv.size(); ++i) {
    if (argv[i] == flag && i + 1 < argv.size()) return argv[i + 1];
    if (argv[i].rfind(flag + "=", 0) == 0) return argv[i].substr(flag.size() + 1);
  }
  return "";
}

/// The claim of the PersistentVolumeClaim volume mounted over `path` in `container` of
/// `workload`, or "" when `path` is on no such volume.
std::string ClaimHolding(const Json& workload, const Json& container, const std::string& path) {
  const Json& mounts = At(container, "/volumeMounts");
  const Json& volumes = At(workload, "/spec/template/spec/volumes");
  if (!mounts.is_array() || !volumes.is_array()) return "";
  for (const Json& m : mounts) {
    const std::string mount = StringAt(m, "/mountPath");
    if (mount.empty() || path.rfind(mount + "/", 0) != 0) continue;
    for (const Json& v : volumes)
      if (StringAt(v, "/name") == StringAt(m, "/name"))
        return StringAt(v, "/persistentVolumeClaim/claimName");
  }
  return "";
}

/// True when the JSON value is an integer of at least `min`.
bool IntAtLeast(const Json& v, int min) { return v.is_number_integer() && v.get<int64_t>() >= min; }

/// What operators expect of the rendered deploy/k8s: the coordinator a batch/v1 Job,
/// done when it completes once, whose restarted container resumes from a checkpoint on a
/// PersistentVolumeClaim (the forest on that volume too); the workers a set scaled by replicas,
/// with readiness and liveness probes. One line per problem; none when all of that holds.
std::vector<std::string> OperatorProblems(const Json& objects) {
  std::vector<std::string> problems;
  const Json* job = FindObject(objects, "Job", "coordinator");
  if (job == nullptr || StringAt(*job, "/apiVersion") != "batch/v1") {
    problems.push_back("no batch/v1 Job coordinator");
  } else {
    if (At(*job, "/spec/completions") != 1 || At(*job, "/spec/parallelism") != 1)
      problems.push_back("Job coordinator: completions and parallelism are not 1");
    if (!IntAtLeast(At(*job, "/spec/backoffLimit"), 1))
      problems.push_back("Job coordinator: no backoffLimit of 1 or more");
    if (StringAt(*job, "/spec/template/spec/restartPolicy") != "OnFailure")
      problems.push_back("Job coordinator: restartPolicy is not OnFailure (a restarted container resumes)");
    const Json* c = FindContainer(*job, "coordinator");
    if (c == nullptr) {
      problems.push_back("Job coordinator: no container coordinator");
    } else {
      const auto argv = CommandLine(*c);
      if (std::find(argv.begin(), argv.end(), "--resume") == argv.end())
        problems.push_back("Job coordinator: no --resume");
      for (const char* flag : {"--checkpoint", "--out"}) {
        const std::string path = FlagValue(argv, flag);
        const std::string claim = path.empty() ? "" : ClaimHolding(*job, *c, path);
        if (claim.empty())
          problems.push_back(std::string("Job coordinator: ") + flag + " '" + path +
                             "' is not on a PersistentVolumeClaim volume");
        else if (FindObject(objects, "PersistentVolumeClaim", claim) == nullptr)
          problems.push_back("PersistentVolumeClaim " + claim + " is not rendered");
      }
    }
  }
  if (FindObject(objects, "Deployment", "coordinator") != nullptr)
    problems.push_back("the coordinator is (also) a Deployment: it would run again after the job is done");
  const Json* workers = FindObject(objects, "StatefulSet", "worker");
  if (workers == nullptr) workers = FindObject(objects, "Deployment", "worker");
  if (workers == nullptr) {
    problems.push_back("no StatefulSet or Deployment worker");
  } else {
    if (!IntAtLeast(At(*workers, "/spec/replicas"), 1)) problems.push_back("worker: no replicas");
    const Json* c = FindContainer(*workers, "worker");
    for (const char* probe : {"readinessProbe", "livenessProbe"})
      if (c == nullptr || !c->contains(probe)) problems.push_back(std::string("worker: no ") + probe);
  }
  return problems;
}
}  // namespace

TEST_CASE(
    "deploy: kubectl kustomize deploy/k8s renders a coordinator Job that resumes from a volume, workers with "
    "probes",
    "[deploy][integration]") {
  TempDir dir("pf-deploy-kustomize");
  const fs::path rendered = dir.path / "rendered.json";
  auto [rc, out] = CheckDeployCommands(Source() / "deploy", {"--rendered-json", rendered.string()});
  INFO(out);
  REQUIRE(rc == 0);  // ...and with it, every command line of the rendering passed --check-config
  const Json objects = Json::parse(ReadText(rendered));
  REQUIRE(objects.is_array());
  const auto problems = OperatorProblems(objects);
  for (const std::string& p : problems) UNSCOPED_INFO(p);
  CHECK(problems.empty());

  // The checks themselves: each way of getting it wrong is named.
  const auto coordinator = [](Json& o) -> Json& {
    for (Json& x : o)
      if (x["kind"] == "Job") return x;
    FAIL("no Job");
    return o;
  };
  const auto mutated = [&](const std::function<void(Json&)>& change) {
    Json copy = objects;
    change(copy);
    const auto found = OperatorProblems(copy);
    std::string all;
    for (const std::string& p : found) all += p + "\n";
    return all;
  };
  CHECK(mutated([&](Json& o) {
          Json& j = coordinator(o);
          j["apiVersion"] = "apps/v1";
          j["kind"] = "Deployment";
        }).find("no batch/v1 Job coordinator") != std::string::npos);
  CHECK(mutated([&](Json& o) {
          coordinator(o)["spec"]["template"]["spec"]["restartPolicy"] = "Never";
        }).find("restartPolicy is not OnFailure") != std::string::npos);
  CHECK(mutated([&](Json& o) {
          coordinator(o)["spec"]["completions"] = 2;
        }).find("completions and parallelism are not 1") != std::string::npos);
  CHECK(mutated([&](Json& o) {
          Json& args = coordinator(o)["spec"]["template"]["spec"]["containers"][0]["args"];
          for (size_t i = 0; i < args.size(); ++i)
            if (args[i] == "--resume") args.erase(i);
        }).find("no --resume") != std::string::npos);
  CHECK(mutated([&](Json& o) {
          for (Json& v : coordinator(o)["spec"]["template"]["spec"]["volumes"])
            if (v.contains("persistentVolumeClaim"))
              v = Json{{"name", v["name"]}, {"emptyDir", Json::object()}};
        }).find("--checkpoint '/var/lib/poseforest/checkpoint' is not on a PersistentVolumeClaim") !=
        std::string::npos);
  CHECK(mutated([&](Json& o) {
          for (size_t i = 0; i < o.size(); ++i)
            if (o[i]["kind"] == "PersistentVolumeClaim") o.erase(i);
        }).find("PersistentVolumeClaim poseforest-state is not rendered") != std::string::npos);
  CHECK(mutated([&](Json& o) {
          for (Json& x : o)
            if (x["kind"] == "StatefulSet")
              x["spec"]["template"]["spec"]["containers"][0].erase("livenessProbe");
        }).find("worker: no livenessProbe") != std::string::npos);

  // Without kubectl the check fails, saying where to get it.
  auto [rc2, out2] = CheckDeployCommands(Source() / "deploy", {"--kubectl", "no-such-kubectl"});
  INFO(out2);
  CHECK(rc2 == 1);
  CHECK(out2.find("no-such-kubectl is not on PATH (Debian: kubernetes-client") != std::string::npos);
}
