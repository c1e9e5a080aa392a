// Real Fast DDS participants in one process: shared memory, UDP only, default (SHM + UDP),
// discovery-server clients (with Debian's fast-discovery-server as a child process), the
// deploy/ XML profiles, transient-local job announcements for late joiners, a writer of
// bad messages whose samples the gate drops, counts and attributes, and the choice of
// shared-memory participant ids whose ports no dead process left behind.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <thread>

#include "proto/dds/dds_node.h"
#include "proto/dds/dds_node_qos.h"
#include "proto/dds/message_gate.h"
#include "tests/proto/dds_test_util.h"

namespace pd = poseforest::proto::dds;
namespace v1 = poseforest::v1;
using namespace std::chrono_literals;
using pd::testing::TestDomain;

namespace {

constexpr auto kMatchTimeout = 20s;

std::unique_ptr<pd::DdsNode> MakeNode(pd::NodeConfig cfg) {
  auto node = pd::DdsNode::Create(cfg);
  INFO(node.status().ToString());
  REQUIRE(node.ok());
  return std::move(node.value());
}

pd::NodeConfig Config(uint32_t domain, pd::TransportKind kind, std::string name, std::vector<pd::Topic> w,
                      std::vector<pd::Topic> r) {
  pd::NodeConfig c;
  c.domain_id = domain;
  c.transport = kind;
  c.participant_name = std::move(name);
  c.write_topics = std::move(w);
  c.read_topics = std::move(r);
  return c;
}

v1::Envelope LevelRequestEnvelope(uint64_t epoch) {
  v1::Envelope env;
  auto* r = env.mutable_level_request();
  r->set_tree(1);
  r->set_level(2);
  r->set_epoch(epoch);
  r->add_node_ids(3);
  r->add_candidate_seeds(77);
  r->set_num_candidates(100);
  r->set_num_thresholds(20);
  r->set_num_parts(31);
  return env;
}

/// Sends `n` LevelRequests coordinator -> worker and checks they all arrive, in order, accepted.
void ExchangeControl(pd::DdsNode& coordinator, pd::DdsNode& worker, int n) {
  REQUIRE(coordinator.WaitForMatch(pd::Topic::kControl, 1, kMatchTimeout));
  REQUIRE(worker.WaitForMatch(pd::Topic::kControl, 1, kMatchTimeout));
  pd::EnvelopeStamper stamper("job-T", "coordinator", v1::SENDER_KIND_COORDINATOR);
  for (int i = 1; i <= n; ++i) {
    v1::Envelope env = LevelRequestEnvelope(uint64_t(i));
    REQUIRE(coordinator.Publish(pd::Topic::kControl, stamper.Seal(pd::Topic::kControl, env)).ok());
  }
  pd::GateConfig gc;
  gc.self_id = "worker-1";
  gc.job_id = "job-T";
  pd::MessageGate gate(gc);
  for (int i = 1; i <= n; ++i) {
    auto s = worker.Receive(10s);
    REQUIRE(s.has_value());
    CHECK(s->topic == pd::Topic::kControl);
    auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
    INFO(out.detail);
    REQUIRE(out.verdict == pd::MessageGate::Verdict::kAccepted);
    CHECK(out.envelope.level_request().epoch() == uint64_t(i));
  }
}

}  // namespace

TEST_CASE("two participants exchange over shared memory only", "[dds][integration]") {
  const uint32_t d = TestDomain(1);
  auto coord = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "coordinator", {pd::Topic::kControl}, {}));
  auto worker = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "worker-1", {}, {pd::Topic::kControl}));
  ExchangeControl(*coord, *worker, 50);
}

TEST_CASE("two participants exchange over UDPv4 only (loopback whitelist, initial peers)", "[dds][integration]") {
  const uint32_t d = TestDomain(2);
  auto a = Config(d, pd::TransportKind::kUdpOnly, "coordinator", {pd::Topic::kControl}, {});
  a.interface_whitelist = {"127.0.0.1"};
  a.initial_peers = {"127.0.0.1"};
  auto b = Config(d, pd::TransportKind::kUdpOnly, "worker-1", {}, {pd::Topic::kControl});
  b.interface_whitelist = {"127.0.0.1"};
  b.initial_peers = {"127.0.0.1"};
  a.participant_id = 0;  // see NodeConfig::participant_id
  b.participant_id = 1;
  auto coord = MakeNode(a);
  auto worker = MakeNode(b);
  ExchangeControl(*coord, *worker, 50);
}

TEST_CASE("default transport (SHM + UDP) carries 1 MiB samples in one process", "[dds][integration]") {
  const uint32_t d = TestDomain(3);
  auto w = MakeNode(Config(d, pd::TransportKind::kDefault, "worker-1", {pd::Topic::kReplies}, {}));
  auto c = MakeNode(Config(d, pd::TransportKind::kDefault, "coordinator", {}, {pd::Topic::kReplies}));
  REQUIRE(w->WaitForMatch(pd::Topic::kReplies, 1, kMatchTimeout));
  REQUIRE(c->WaitForMatch(pd::Topic::kReplies, 1, kMatchTimeout));
  pd::EnvelopeStamper stamper("job-T", "worker-1", v1::SENDER_KIND_WORKER);
  pd::GateConfig gc;
  gc.self_id = "coordinator";
  gc.job_id = "job-T";
  pd::MessageGate gate(gc);
  constexpr int kSamples = 8;
  for (int i = 0; i < kSamples; ++i) {
    v1::Envelope env;
    *env.mutable_subtree_result() = pd::testing::BigSubtree(1 << 20, uint32_t(i));
    REQUIRE(w->Publish(pd::Topic::kReplies, stamper.Seal(pd::Topic::kReplies, env)).ok());
  }
  for (int i = 0; i < kSamples; ++i) {
    auto s = c->Receive(20s);
    REQUIRE(s.has_value());
    auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
    INFO(out.detail);
    REQUIRE(out.verdict == pd::MessageGate::Verdict::kAccepted);  // includes the CRC of 1 MiB
    CHECK(out.envelope.subtree_result().node_id() == uint32_t(i));
  }
}

TEST_CASE("a late joiner receives the transient-local job announcement", "[dds][integration]") {
  const uint32_t d = TestDomain(4);
  auto coord = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "coordinator", {pd::Topic::kJob}, {}));
  pd::EnvelopeStamper stamper("job-L", "coordinator", v1::SENDER_KIND_COORDINATOR);
  v1::Envelope env;
  auto* job = env.mutable_job();
  job->mutable_config()->set_num_trees(3);
  job->set_coordinator_id("coordinator");
  job->set_num_parts(31);
  job->set_thresholds_per_feature(50);
  REQUIRE(coord->Publish(pd::Topic::kJob, stamper.Seal(pd::Topic::kJob, env)).ok());
  // The worker starts after the announcement was written.
  auto worker = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "worker-7", {}, {pd::Topic::kJob}));
  auto s = worker->Receive(kMatchTimeout);
  REQUIRE(s.has_value());
  pd::GateConfig gc;
  gc.self_id = "worker-7";  // no job id yet: only a JobAnnouncement passes
  pd::MessageGate gate(gc);
  auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
  REQUIRE(out.verdict == pd::MessageGate::Verdict::kAccepted);
  CHECK(out.envelope.job_id() == "job-L");
  CHECK(out.envelope.job().config().num_trees() == 3u);
}

TEST_CASE("bad messages over DDS are dropped, counted per sender, offender flagged", "[dds][integration]") {
  const uint32_t d = TestDomain(5);
  auto coord = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "coordinator", {}, {pd::Topic::kReplies}));
  auto good = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "worker-good", {pd::Topic::kReplies}, {}));
  auto bad = MakeNode(Config(d, pd::TransportKind::kSharedMemoryOnly, "worker-bad", {pd::Topic::kReplies}, {}));
  REQUIRE(coord->WaitForMatch(pd::Topic::kReplies, 2, kMatchTimeout));
  REQUIRE(good->WaitForMatch(pd::Topic::kReplies, 1, kMatchTimeout));
  REQUIRE(bad->WaitForMatch(pd::Topic::kReplies, 1, kMatchTimeout));

  // The coordinator waits for epoch-5 replies with these dimensions.
  v1::LevelRequest req;
  req.set_tree(0);
  req.set_level(1);
  req.set_epoch(5);
  req.add_node_ids(1);
  req.add_node_ids(2);
  req.add_candidate_seeds(11);
  req.add_candidate_seeds(12);
  req.set_num_candidates(4);
  req.set_num_thresholds(3);
  req.set_num_parts(5);
  auto reply = [&](uint64_t epoch, uint32_t bins) {
    v1::Envelope env;
    auto* r = env.mutable_histogram();
    r->set_tree(0);
    r->set_level(1);
    r->set_epoch(epoch);
    r->set_num_candidates(4);
    r->set_num_bins(bins);
    r->set_num_parts(5);
    for (uint32_t id : {1u, 2u}) {
      auto* n = r->add_nodes();
      n->set_node_id(id);
      n->set_samples(2);
      std::vector<uint32_t> dense(4 * bins * 5, 0);
      for (int c = 0; c < 4; ++c) dense[c * bins * 5 + (c % bins) * 5 + 1] = 2;  // 2 samples of part 1
      pd::EncodeHistogramRuns(dense, n->mutable_runs());
      for (int p = 0; p < 5; ++p) n->add_part_counts(p == 1 ? 2 : 0);
    }
    return env;
  };

  std::vector<std::string> log;
  pd::GateConfig gc;
  gc.self_id = "coordinator";
  gc.job_id = "job-G";
  gc.bad_message_budget = 8;
  gc.log = [&](const std::string& s) { log.push_back(s); };
  pd::MessageGate gate(gc);
  gate.ExpectLevel(req);

  pd::EnvelopeStamper good_st("job-G", "worker-good", v1::SENDER_KIND_WORKER);
  pd::EnvelopeStamper bad_st("job-G", "worker-bad", v1::SENDER_KIND_WORKER);
  pd::EnvelopeStamper other_job("job-OTHER", "worker-bad", v1::SENDER_KIND_WORKER);

  // worker-bad first introduces itself with one valid reply, then misbehaves.
  { auto e = reply(5, 3); REQUIRE(bad->Publish(pd::Topic::kReplies, bad_st.Seal(pd::Topic::kReplies, e)).ok()); }
  const std::string garbage = "\x08\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\x01 not protobuf";
  for (int i = 0; i < 3; ++i) REQUIRE(bad->Publish(pd::Topic::kReplies, garbage).ok());
  { auto e = reply(5, 3); REQUIRE(bad->Publish(pd::Topic::kReplies, other_job.Seal(pd::Topic::kReplies, e)).ok()); }
  { auto e = reply(5, 4); REQUIRE(bad->Publish(pd::Topic::kReplies, bad_st.Seal(pd::Topic::kReplies, e)).ok()); }
  { auto e = reply(4, 3); REQUIRE(bad->Publish(pd::Topic::kReplies, bad_st.Seal(pd::Topic::kReplies, e)).ok()); }
  { auto e = reply(5, 3); REQUIRE(bad->Publish(pd::Topic::kReplies, bad_st.Seal(pd::Topic::kReplies, e)).ok()); }
  for (int i = 0; i < 4; ++i) REQUIRE(bad->Publish(pd::Topic::kReplies, garbage).ok());
  // worker-good is unaffected.
  for (int i = 0; i < 3; ++i) {
    auto e = reply(5, 3);
    REQUIRE(good->Publish(pd::Topic::kReplies, good_st.Seal(pd::Topic::kReplies, e)).ok());
  }
  constexpr int kTotal = 1 + 3 + 1 + 1 + 1 + 1 + 4 + 3;
  std::map<std::string, int> accepted;
  for (int i = 0; i < kTotal; ++i) {
    auto s = coord->Receive(10s);
    REQUIRE(s.has_value());
    auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
    if (out.verdict == pd::MessageGate::Verdict::kAccepted) ++accepted[out.sender];
  }
  CHECK(accepted["worker-good"] == 3);
  CHECK(accepted["worker-bad"] == 2);  // the first reply and the valid one after the stale one
  const auto* st = gate.stats("worker-bad");
  REQUIRE(st != nullptr);
  CHECK(st->reasons.at("unparseable") == 7);  // garbage attributed by writer GUID to worker-bad
  CHECK(st->reasons.at("job_id") == 1);
  CHECK(st->reasons.at("body") == 1);         // wrong dimensions
  CHECK(st->reasons.at("stale_epoch") == 1);  // counted, not bad
  CHECK(st->stale == 1);
  CHECK(st->rejected == 9);
  CHECK(st->flagged);
  CHECK(gate.TakeOffenders() == std::vector<std::string>{"worker-bad"});
  CHECK(gate.stats("worker-good")->rejected == 0);
  bool logged_sender = false;
  for (const auto& line : log) logged_sender |= line.find("worker-bad") != std::string::npos;
  CHECK(logged_sender);
}

TEST_CASE("discovery-server clients find each other through fast-discovery-server", "[dds][integration]") {
  const int port = 20000 + int(::getpid() % 20000);
  pd::testing::Child server;
  std::string error;
  REQUIRE(server.Start({"fast-discovery-server", "-i", "0", "-l", "127.0.0.1", "-p", std::to_string(port)}, &error));
  REQUIRE(server.WaitForLine("Server is running", 10s).has_value());
  auto a = Config(0, pd::TransportKind::kDiscoveryClient, "coordinator", {pd::Topic::kControl}, {});
  a.discovery_server = "127.0.0.1:" + std::to_string(port);
  auto b = Config(0, pd::TransportKind::kDiscoveryClient, "worker-1", {}, {pd::Topic::kControl});
  b.discovery_server = a.discovery_server;
  {
    auto coord = MakeNode(a);
    auto worker = MakeNode(b);
    ExchangeControl(*coord, *worker, 10);
  }
  server.Kill(SIGTERM);
  CHECK(server.Wait(10s).has_value());
}

TEST_CASE("the deploy/ XML participant profiles load and communicate", "[dds][integration]") {
  const std::filesystem::path xml = std::filesystem::path(POSEFOREST_SOURCE_DIR) / "deploy/fastdds/profiles.xml";
  REQUIRE(std::filesystem::exists(xml));
  for (const char* profile : {"poseforest_shm", "poseforest_udp_loopback"}) {
    INFO(profile);
    auto a = Config(0, pd::TransportKind::kXmlProfile, "coordinator", {pd::Topic::kControl}, {});
    a.xml_file = xml.string();
    a.xml_profile = profile;
    auto b = a;
    b.participant_name = "worker-1";
    b.write_topics = {};
    b.read_topics = {pd::Topic::kControl};
    // Peers without ports reach participant ids 0..3 only; earlier participants of this
    // process used those ids, so pin them.
    a.participant_id = 0;
    b.participant_id = 1;
    // Profiles carry no domain id: use a private one per profile.
    a.domain_id = b.domain_id = TestDomain(std::string(profile).size());
    auto coord = MakeNode(a);
    auto worker = MakeNode(b);
    ExchangeControl(*coord, *worker, 10);
  }
  // The discovery-client and security profiles must at least parse (their servers/credentials
  // are deployment specific).
  for (const char* profile : {"poseforest_discovery_client", "poseforest_udp_peers"}) {
    INFO(profile);
    auto c = Config(0, pd::TransportKind::kXmlProfile, "probe", {}, {});
    c.xml_file = xml.string();
    c.xml_profile = profile;
    auto node = pd::DdsNode::Create(c);
    CHECK(node.ok());
  }
}

TEST_CASE("configuration errors are reported, not crashes", "[dds][unit]") {
  auto c = Config(0, pd::TransportKind::kUdpOnly, "x", {}, {});
  c.initial_peers = {"not-an-ip"};
  CHECK_FALSE(pd::DdsNode::Create(c).ok());
  c.initial_peers = {"127.0.0.1:99999"};
  CHECK_FALSE(pd::DdsNode::Create(c).ok());
  c.initial_peers = {};
  c.interface_whitelist = {"eth0"};
  CHECK_FALSE(pd::DdsNode::Create(c).ok());
  auto x = Config(0, pd::TransportKind::kXmlProfile, "x", {}, {});
  x.xml_file = "/nonexistent.xml";
  CHECK_FALSE(pd::DdsNode::Create(x).ok());
  auto s = Config(0, pd::TransportKind::kSharedMemoryOnly, "x", {}, {});
  s.security.identity_ca = "/nonexistent/ca.pem";
  auto r = pd::DdsNode::Create(s);
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().message().find("cannot read security file /nonexistent/ca.pem") != std::string::npos);
}

// A 6,000-image job failed with "DataWriter::write failed on poseforest/control
// (history full for 10 s ...)": a worker busy in a long subtree batch read nothing, its keep-all
// reader history (as small as the writer's) filled, and Fast DDS 2.9 never asks again for a
// sample a full reader history rejected, so the writer stalled for good. Readers now hold far
// more than a writer may leave unacknowledged: a reader that takes nothing for a while costs the
// writer nothing.
TEST_CASE("a reader that takes nothing for a while never stalls a keep-all writer", "[dds][integration]") {
  const uint32_t domain = TestDomain(120);
  auto cfg_w = Config(domain, pd::TransportKind::kSharedMemoryOnly, "w", {pd::Topic::kControl}, {});
  cfg_w.keep_all_max_samples = 2;
  cfg_w.write_block_slice = 200ms;
  cfg_w.write_give_up = 15s;  // a failure of this test, not a hang
  auto writer = MakeNode(cfg_w);
  auto reader = MakeNode(Config(domain, pd::TransportKind::kSharedMemoryOnly, "r", {}, {pd::Topic::kControl}));
  REQUIRE(writer->WaitForMatch(pd::Topic::kControl, 1, kMatchTimeout));
  REQUIRE(reader->WaitForMatch(pd::Topic::kControl, 1, kMatchTimeout));
  pd::EnvelopeStamper stamper("job-T", "coordinator", v1::SENDER_KIND_COORDINATOR);
  constexpr int kSamples = 600;  // more than twice kKeepAllMaxSamples
  for (int i = 1; i <= kSamples; ++i) {
    v1::Envelope env = LevelRequestEnvelope(uint64_t(i));
    const auto st = writer->Publish(pd::Topic::kControl, stamper.Seal(pd::Topic::kControl, env));
    INFO("sample " << i << ": " << st.ToString());
    REQUIRE(st.ok());
  }
  CHECK(writer->slow_writes() == 0);  // no write found the history full for a 200 ms slice
  std::this_thread::sleep_for(500ms);  // the reader still takes nothing
  pd::GateConfig gc;
  gc.self_id = "worker-1";
  gc.job_id = "job-T";
  pd::MessageGate gate(gc);
  for (int i = 1; i <= kSamples; ++i) {  // all of them, in order
    auto s = reader->Receive(10s);
    REQUIRE(s.has_value());
    auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
    REQUIRE(out.verdict == pd::MessageGate::Verdict::kAccepted);
    CHECK(out.envelope.level_request().epoch() == uint64_t(i));
  }
}

TEST_CASE("shared-memory participants take ids whose ports left no file on the host", "[dds][unit]") {
  // FreshSharedMemoryParticipantId on a directory of its own: the files Fast DDS 2.9 leaves in
  // /dev/shm for a port (segment, exclusive and shared lock) each make the id taken.
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("pf-fresh-ids-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const uint32_t domain = 3;
  const uint32_t base = 7400 + 250 * domain;
  auto touch = [&](const std::string& name) { std::ofstream(dir / name) << ""; };
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {}) == 0);
  touch("fastrtps_port" + std::to_string(base + 10));  // id 0's metatraffic segment (a live or dead peer)
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {}) == 1);
  touch("fastrtps_port" + std::to_string(base + 13) + "_el");  // id 1's user port, locked or left by a SIGKILL
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {}) == 2);
  touch("fastrtps_port" + std::to_string(base + 14) + "_sl");
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {}) == 3);
  // Ids this process gave before are skipped; another domain's files do not count.
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {3, 4}) == 5);
  CHECK(pd::FreshSharedMemoryParticipantId(domain + 1, dir.string(), {}) == 0);
  // Files of other names (the mutex, data segments) do not count.
  touch("sem.fastrtps_port" + std::to_string(base + 16) + "_mutex");
  touch("fastrtps_0123456789abcdef");
  CHECK(pd::FreshSharedMemoryParticipantId(domain, dir.string(), {}) == 3);
  // The last domain Fast DDS accepts has fewer ids below port 65536; all taken: -1 (automatic).
  const uint32_t last = 232, last_base = 7400 + 250 * last;
  std::set<int> all;
  for (int id = 0; id < 120; ++id) all.insert(id);
  CHECK(pd::FreshSharedMemoryParticipantId(last, dir.string(), all) == -1);
  int top = -1;
  for (int id = 0; id < 120; ++id)
    if (last_base + 11 + 2 * uint32_t(id) <= 65535) top = id;
  std::set<int> below(all.begin(), all.find(top));
  CHECK(pd::FreshSharedMemoryParticipantId(last, dir.string(), below) == top);
  fs::remove_all(dir);
}

TEST_CASE("two shared-memory participants of one process get distinct fresh ids", "[dds][integration]") {
  // TakeFreshSharedMemoryParticipantId never gives an id twice in a process, so a participant
  // that replaces an earlier one does not take the earlier one's ports (peers hold its segments).
  pd::NodeConfig cfg;
  cfg.domain_id = TestDomain(6);
  cfg.transport = pd::TransportKind::kSharedMemoryOnly;
  cfg.write_topics = {pd::Topic::kPresence};
  std::string first_guid;
  {
    auto a = MakeNode(cfg);
    first_guid = a->participant_guid();
  }
  auto b = MakeNode(cfg);
  // The GUID prefix ends with the participant id (little endian): different ones.
  INFO(first_guid << " then " << b->participant_guid());
  CHECK(first_guid.substr(0, 35) != b->participant_guid().substr(0, 35));
}

TEST_CASE("the participant-id lock is held by one holder at a time and waits a bounded time", "[dds]") {
  // DdsNode::Create holds it from the id's choice until the participant's ports exist
  // (test_dds_multiprocess: processes started together take distinct ids).
  const std::string path =
      (std::filesystem::temp_directory_path() / ("pf-hostlock-" + std::to_string(::getpid()) + ".lock"))
          .string();
  {
    pd::HostLock first(path, std::chrono::milliseconds(100));
    REQUIRE(first.held());
    const auto t0 = std::chrono::steady_clock::now();
    pd::HostLock second(path, std::chrono::milliseconds(200));  // another open file: flock excludes it
    const auto waited = std::chrono::steady_clock::now() - t0;
    CHECK_FALSE(second.held());
    CHECK(waited >= std::chrono::milliseconds(200));
    CHECK(waited < std::chrono::seconds(5));
  }
  pd::HostLock again(path, std::chrono::milliseconds(100));  // the first one's close dropped it
  CHECK(again.held());
  CHECK((std::filesystem::status(path).permissions() & std::filesystem::perms::others_write) !=
        std::filesystem::perms::none);  // any user's processes can take it
  // A folder that cannot hold the file: not held, no wait, and no error to the caller.
  pd::HostLock nowhere("/nonexistent-dir/pf.lock", std::chrono::seconds(10));
  CHECK_FALSE(nowhere.held());
  std::filesystem::remove(path);
}

TEST_CASE("which participants take a fresh shared-memory id: shm, default and a shm-only XML profile",
          "[dds][integration]") {
  const std::filesystem::path xml = std::filesystem::path(POSEFOREST_SOURCE_DIR) / "deploy/fastdds/profiles.xml";
  auto id_of = [&](pd::TransportKind kind, const std::string& profile, int pinned) {
    pd::NodeConfig cfg;
    cfg.domain_id = TestDomain(7);
    cfg.transport = kind;
    cfg.participant_id = pinned;
    cfg.xml_file = xml.string();
    cfg.xml_profile = profile;
    if (kind == pd::TransportKind::kUdpOnly) cfg.initial_peers = {"127.0.0.1"};
    eprosima::fastdds::dds::DomainParticipantQos qos;
    auto st = pd::BuildParticipantQos(cfg, qos);
    INFO(st.ToString());
    REQUIRE(st.ok());
    return qos.wire_protocol().participant_id;
  };
  CHECK(id_of(pd::TransportKind::kSharedMemoryOnly, "", -1) >= 0);
  CHECK(id_of(pd::TransportKind::kDefault, "", -1) >= 0);
  CHECK(id_of(pd::TransportKind::kXmlProfile, "poseforest_shm", -1) >= 0);
  // UDP: automatic as before (peers without ports reach ids 0..3); a pinned id is kept.
  CHECK(id_of(pd::TransportKind::kUdpOnly, "", -1) == -1);
  CHECK(id_of(pd::TransportKind::kXmlProfile, "poseforest_udp_loopback", -1) == -1);
  CHECK(id_of(pd::TransportKind::kSharedMemoryOnly, "", 7) == 7);
  // Never the same id twice in a process.
  const int a = id_of(pd::TransportKind::kSharedMemoryOnly, "", -1);
  const int b = id_of(pd::TransportKind::kSharedMemoryOnly, "", -1);
  CHECK(a != b);
}
