// DDS-Security end to end with credentials made by deploy/security/make-test-ca.sh: two
// authorized participants exchange; a participant without credentials, and one whose
// certificates come from another CA, can neither read nor inject; permissions deny a worker
// the coordinator's topics.
#include <catch2/catch.hpp>
#include <thread>

#include <cstdio>
#include <filesystem>

#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "tests/proto/dds_test_util.h"
#include "tests/support/paths.h"

namespace pd = poseforest::proto::dds;
namespace v1 = poseforest::v1;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

/// Removes the generated credentials when the test case ends (also on failure).
struct ScratchCleanup {
  std::vector<std::filesystem::path> dirs;
  ~ScratchCleanup() {
    std::error_code ec;
    for (const auto& d : dirs) std::filesystem::remove_all(d, ec);
  }
};
thread_local ScratchCleanup* g_cleanup = nullptr;

std::filesystem::path MakeCa(const std::string& name) {
  const auto dir = poseforest::testing::ScratchDir(name);
  if (g_cleanup) g_cleanup->dirs.push_back(dir);
  const std::string script = std::string(POSEFOREST_SOURCE_DIR) + "/deploy/security/make-test-ca.sh";
  const std::string cmd = "sh " + script + " " + dir.string() + " coordinator worker-1 > " + dir.string() + "/log.txt 2>&1";
  INFO(cmd);
  REQUIRE(std::system(cmd.c_str()) == 0);
  return dir;
}

pd::SecurityFiles Files(const std::filesystem::path& dir, const std::string& id) {
  const std::string d = dir.string();
  return {d + "/identity_ca.pem", d + "/" + id + "/cert.pem", d + "/" + id + "/key.pem", d + "/permissions_ca.pem",
          d + "/governance.p7s", d + "/" + id + "/permissions.p7s"};
}

pd::NodeConfig Config(uint32_t domain, const std::string& name, std::vector<pd::Topic> w, std::vector<pd::Topic> r) {
  pd::NodeConfig c;
  c.domain_id = domain;
  c.participant_name = name;
  c.write_topics = std::move(w);
  c.read_topics = std::move(r);
  return c;
}

std::string Heartbeat(pd::EnvelopeStamper& st) {
  v1::Envelope env;
  *env.mutable_heartbeat()->mutable_capacity() = pd::testing::Capacity();
  return st.Seal(pd::Topic::kPresence, env);
}

}  // namespace

TEST_CASE("DDS-Security: authorized peers talk, outsiders can neither read nor inject", "[dds][integration][slow]") {
  ScratchCleanup cleanup;
  g_cleanup = &cleanup;
  const auto ca = MakeCa("dds-ca");
  const auto other_ca = MakeCa("dds-other-ca");
  const uint32_t domain = pd::testing::TestDomain(21);

  auto cc = Config(domain, "coordinator", {}, {pd::Topic::kPresence});
  cc.security = Files(ca, "coordinator");
  auto wc = Config(domain, "worker-1", {pd::Topic::kPresence}, {});
  wc.security = Files(ca, "worker-1");
  const auto t0 = Clock::now();
  auto coord = pd::DdsNode::Create(cc);
  INFO(coord.status().ToString());
  REQUIRE(coord.ok());
  auto worker = pd::DdsNode::Create(wc);
  INFO(worker.status().ToString());
  REQUIRE(worker.ok());

  // Outsiders on the same domain: no security at all, and the right names from another CA.
  auto plain_reader = pd::DdsNode::Create(Config(domain, "eavesdropper", {}, {pd::Topic::kPresence}));
  REQUIRE(plain_reader.ok());
  auto plain_writer = pd::DdsNode::Create(Config(domain, "worker-1", {pd::Topic::kPresence}, {}));
  REQUIRE(plain_writer.ok());
  // Valid-looking identities (same names) from another CA: their own CA accepts them, the
  // handshake with the real participants must fail.
  auto fc = Config(domain, "worker-1", {pd::Topic::kPresence}, {});
  fc.security = Files(other_ca, "worker-1");
  auto forged = pd::DdsNode::Create(fc);
  INFO(forged.status().ToString());
  REQUIRE(forged.ok());
  auto frc = Config(domain, "coordinator", {}, {pd::Topic::kPresence});
  frc.security = Files(other_ca, "coordinator");
  auto forged_reader = pd::DdsNode::Create(frc);
  INFO(forged_reader.status().ToString());
  REQUIRE(forged_reader.ok());

  REQUIRE((*worker)->WaitForMatch(pd::Topic::kPresence, 1, 20s));
  REQUIRE((*coord)->WaitForMatch(pd::Topic::kPresence, 1, 20s));
  std::printf("[security] secure participants matched %.0f ms after creation\n",
              std::chrono::duration<double, std::milli>(Clock::now() - t0).count());

  pd::EnvelopeStamper good("job-S", "worker-1", v1::SENDER_KIND_WORKER);
  pd::EnvelopeStamper evil("job-S", "worker-1", v1::SENDER_KIND_WORKER);
  pd::GateConfig gc;
  gc.self_id = "coordinator";
  gc.job_id = "job-S";
  pd::MessageGate gate(gc);
  constexpr int kCount = 20;
  for (int i = 0; i < kCount; ++i) {
    REQUIRE((*worker)->Publish(pd::Topic::kPresence, Heartbeat(good)).ok());
    REQUIRE((*plain_writer)->Publish(pd::Topic::kPresence, Heartbeat(evil)).ok());
    REQUIRE((*forged)->Publish(pd::Topic::kPresence, Heartbeat(evil)).ok());
  }
  // The coordinator gets exactly the authorized worker's samples (keep-last 8 history: at least
  // the newest ones), all from the worker's participant.
  int received = 0;
  const std::string worker_participant = (*worker)->participant_guid();
  while (auto s = (*coord)->Receive(1500ms)) {
    CHECK(s->writer_participant == worker_participant);
    auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
    CHECK(out.verdict == pd::MessageGate::Verdict::kAccepted);
    ++received;
  }
  CHECK(received >= 1);
  // Nobody outside the CA matched or received anything (bounded: the 1.5 s above plus this).
  CHECK((*coord)->MatchedWriters(pd::Topic::kPresence) == 1);
  CHECK((*worker)->MatchedReaders(pd::Topic::kPresence) == 1);
  // The plain pair's own match may land late on a loaded machine: wait for the count, bounded.
  for (const auto until = Clock::now() + 10s;
       (*plain_reader)->MatchedWriters(pd::Topic::kPresence) < 1 && Clock::now() < until;)
    std::this_thread::sleep_for(50ms);
  CHECK((*plain_reader)->MatchedWriters(pd::Topic::kPresence) == 1);  // only the plain writer
  int leaked = 0;
  while (auto s = (*plain_reader)->Receive(500ms)) leaked += s->writer_participant == worker_participant;
  CHECK(leaked == 0);
  // The forged pair may match each other (same other CA), never the real ones.
  CHECK((*forged)->MatchedReaders(pd::Topic::kPresence) <= 1);
  int forged_leaked = 0;
  while (auto s = (*forged_reader)->Receive(500ms)) forged_leaked += s->writer_participant == worker_participant;
  CHECK(forged_leaked == 0);
  std::printf("[security] coordinator received %d samples, all from worker-1; eavesdropper got %d, other-CA reader got %d "
              "of worker-1's\n",
              received, leaked, forged_leaked);
}

TEST_CASE("DDS-Security: permissions keep a worker off the coordinator's topics", "[dds][integration][slow]") {
  ScratchCleanup cleanup;
  g_cleanup = &cleanup;
  const auto ca = MakeCa("dds-ca-perm");
  auto wc = Config(pd::testing::TestDomain(22), "worker-1", {pd::Topic::kControl}, {});
  wc.security = Files(ca, "worker-1");
  auto node = pd::DdsNode::Create(wc);
  REQUIRE_FALSE(node.ok());
  CHECK(node.status().message().find("cannot create writer on poseforest/control") != std::string::npos);
  // Its own topics are fine.
  wc.write_topics = {pd::Topic::kReplies, pd::Topic::kPresence};
  wc.read_topics = {pd::Topic::kControl, pd::Topic::kJob};
  auto ok = pd::DdsNode::Create(wc);
  INFO(ok.status().ToString());
  CHECK(ok.ok());
}

TEST_CASE("DDS-Security: a permissions file signed by another CA is refused", "[dds][integration][slow]") {
  ScratchCleanup cleanup;
  g_cleanup = &cleanup;
  const auto ca = MakeCa("dds-ca-a");
  const auto other = MakeCa("dds-ca-b");
  auto wc = Config(pd::testing::TestDomain(23), "worker-1", {pd::Topic::kPresence}, {});
  wc.security = Files(ca, "worker-1");
  wc.security.permissions = (other / "worker-1" / "permissions.p7s").string();
  auto node = pd::DdsNode::Create(wc);
  REQUIRE_FALSE(node.ok());
  CHECK(node.status().message().find("security enabled") != std::string::npos);
}
