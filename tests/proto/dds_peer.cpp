// poseforest_dds_peer: a small real DDS participant that the multi-process tests start as a
// child process (and that an operator can use to check a deployment by hand).
//
//   poseforest_dds_peer --mode=send    --count=N --size=BYTES   1 MiB-class SubtreeResults on replies
//   poseforest_dds_peer --mode=alive   --seconds=S              WorkerHello + heartbeats on presence
//   poseforest_dds_peer --mode=monitor --seconds=S              prints what arrives (gate verdicts, events)
// Common: --domain=D --transport=default|shm|udp|ds|xml --whitelist=IP[,IP] --peers=IP[,IP]
//         --ds=IP:PORT --xml=FILE --profile=NAME --job=ID --id=SENDER --lease-ms=MS
//         --participant-id=N --liveliness=manual|automatic (presence topic)
//         --sec-dir=DIR (make-test-ca.sh output; uses DIR/<id>/cert.pem, key.pem)
// Output lines (stdout, flushed): STARTED <guid>, MATCHED <topic> <n>, SENT ..., SAMPLE ...,
// DROP ..., EVENT ..., DONE. Every mode ends by itself (bounded by --seconds / --timeout-s).

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "proto/dds/build_id.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "tests/proto/dds_test_util.h"

namespace pd = poseforest::proto::dds;
namespace v1 = poseforest::v1;
using namespace std::chrono_literals;

namespace {

std::map<std::string, std::string> ParseArgs(int argc, char** argv) {
  std::map<std::string, std::string> a;
  for (int i = 1; i < argc; ++i) {
    std::string_view s = argv[i];
    if (s.size() < 3 || s.substr(0, 2) != "--") continue;
    s.remove_prefix(2);
    const auto eq = s.find('=');
    if (eq == std::string_view::npos)
      a[std::string(s)] = "1";
    else
      a[std::string(s.substr(0, eq))] = std::string(s.substr(eq + 1));
  }
  return a;
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start < s.size()) {
    size_t comma = s.find(',', start);
    if (comma == std::string::npos) comma = s.size();
    if (comma > start) out.push_back(s.substr(start, comma - start));
    start = comma + 1;
  }
  return out;
}

void Say(const std::string& line) {
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  auto args = ParseArgs(argc, argv);
  auto get = [&](const char* k, const std::string& def) { return args.count(k) ? args[k] : def; };
  const std::string mode = get("mode", "");
  const std::string job = get("job", "test-job");
  const std::string id = get("id", mode == "monitor" ? "coordinator" : "worker-1");

  pd::NodeConfig cfg;
  cfg.domain_id = uint32_t(std::stoul(get("domain", "0")));
  cfg.participant_name = id;
  const std::string transport = get("transport", "default");
  if (transport == "shm") cfg.transport = pd::TransportKind::kSharedMemoryOnly;
  else if (transport == "udp") cfg.transport = pd::TransportKind::kUdpOnly;
  else if (transport == "ds") cfg.transport = pd::TransportKind::kDiscoveryClient;
  else if (transport == "xml") cfg.transport = pd::TransportKind::kXmlProfile;
  cfg.interface_whitelist = Split(get("whitelist", ""));
  cfg.initial_peers = Split(get("peers", ""));
  cfg.discovery_server = get("ds", cfg.discovery_server);
  cfg.xml_file = get("xml", "");
  cfg.xml_profile = get("profile", "");
  cfg.presence_manual_liveliness = get("liveliness", "manual") == "manual";
  cfg.participant_id = std::stoi(get("participant-id", "-1"));
  cfg.liveliness_lease = std::chrono::milliseconds(std::stol(get("lease-ms", "1000")));
  if (args.count("sec-dir")) {
    const std::string d = args["sec-dir"];
    cfg.security = {d + "/identity_ca.pem", d + "/" + id + "/cert.pem", d + "/" + id + "/key.pem",
                    d + "/permissions_ca.pem", d + "/governance.p7s", d + "/" + id + "/permissions.p7s"};
  }
  const double seconds = std::stod(get("seconds", "30"));
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000));

  if (mode == "send") {
    cfg.write_topics = {pd::Topic::kReplies};
  } else if (mode == "alive") {
    cfg.write_topics = {pd::Topic::kPresence};
  } else if (mode == "monitor") {
    cfg.read_topics = {pd::Topic::kPresence, pd::Topic::kReplies};
  } else {
    std::fprintf(stderr, "usage: poseforest_dds_peer --mode=send|alive|monitor [options] (see the source)\n");
    return 2;
  }
  auto node = pd::DdsNode::Create(cfg);
  if (!node.ok()) {
    Say("ERROR " + node.status().ToString());
    return 1;
  }
  Say("STARTED " + (*node)->participant_guid());
  pd::EnvelopeStamper stamper(job, id, v1::SENDER_KIND_WORKER);

  if (mode == "send") {
    const int count = std::stoi(get("count", "10"));
    const size_t size = std::stoul(get("size", "1048576"));
    const int readers = std::stoi(get("wait-readers", "1"));
    if (!(*node)->WaitForMatch(pd::Topic::kReplies, readers, std::chrono::milliseconds(int64_t(seconds * 1000)))) {
      Say("ERROR no reader matched");
      return 1;
    }
    Say("MATCHED replies " + std::to_string((*node)->MatchedReaders(pd::Topic::kReplies)));
    const auto t0 = std::chrono::steady_clock::now();
    size_t total = 0;
    for (int i = 0; i < count; ++i) {
      v1::Envelope env;
      *env.mutable_subtree_result() = pd::testing::BigSubtree(size, uint32_t(i));
      const std::string bytes = stamper.Seal(pd::Topic::kReplies, env);
      total += bytes.size();
      if (auto st = (*node)->Publish(pd::Topic::kReplies, bytes); !st.ok()) {
        Say("ERROR " + st.ToString());
        return 1;
      }
    }
    const bool acked = (*node)->WaitForAcknowledgments(pd::Topic::kReplies, std::chrono::milliseconds(int64_t(seconds * 1000)));
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    char line[256];
    std::snprintf(line, sizeof line, "SENT %d samples %zu bytes %.3f s %.1f MB/s acked=%d", count, total, s,
                  total / s / 1e6, int(acked));
    Say(line);
    Say("DONE");
    return acked ? 0 : 1;
  }

  if (mode == "alive") {
    const auto period = std::chrono::milliseconds(std::stol(get("period-ms", "200")));
    uint64_t n = 0;
    bool matched = false;
    while (std::chrono::steady_clock::now() < until) {
      if (!matched && (*node)->MatchedReaders(pd::Topic::kPresence) > 0) {
        matched = true;
        Say("MATCHED presence " + std::to_string((*node)->MatchedReaders(pd::Topic::kPresence)));
      }
      v1::Envelope env;
      if (n == 0) {
        auto* h = env.mutable_hello();
        *h->mutable_capacity() = pd::testing::Capacity();
        h->set_hostname(id);
        h->set_pid(uint32_t(::getpid()));
        h->set_build_version(pd::BuildId());  // as a worker of this build: a coordinator admits it
      } else {
        *env.mutable_heartbeat()->mutable_capacity() = pd::testing::Capacity();
      }
      if (auto st = (*node)->Publish(pd::Topic::kPresence, stamper.Seal(pd::Topic::kPresence, env)); !st.ok())
        Say("ERROR " + st.ToString());
      ++n;
      std::this_thread::sleep_for(period);
    }
    Say("DONE " + std::to_string(n));
    return 0;
  }

  // monitor
  pd::GateConfig gc;
  gc.self_id = id;
  gc.job_id = job;
  gc.log = [](const std::string&) {};
  pd::MessageGate gate(gc);
  std::map<std::string, std::string> sender_of_participant;
  while (std::chrono::steady_clock::now() < until) {
    while (auto e = (*node)->NextEvent(0ms)) {
      auto it = sender_of_participant.find(e->peer_participant);
      Say(std::string("EVENT ") + pd::EventKindName(e->kind) + " " + pd::TopicShortName(e->topic) + " sender=" +
          (it == sender_of_participant.end() ? "?" : it->second) + " participant=" + e->peer_participant +
          " count=" + std::to_string(e->current_count));
    }
    auto sample = (*node)->Receive(50ms);
    if (!sample) continue;
    auto out = gate.Check(sample->topic, sample->bytes, sample->writer_guid);
    if (out.verdict == pd::MessageGate::Verdict::kAccepted) {
      sender_of_participant[sample->writer_participant] = out.sender;
      Say(std::string("SAMPLE ") + pd::TopicShortName(sample->topic) + " sender=" + out.sender +
          " seq=" + std::to_string(out.envelope.sequence()) + " bytes=" + std::to_string(sample->bytes.size()) +
          " body=" + pd::BodyName(out.envelope.body_case()));
    } else {
      Say(std::string("DROP ") + pd::TopicShortName(sample->topic) + " sender=" + out.sender + " reason=" + out.reason +
          " " + out.detail);
    }
  }
  Say("DONE");
  return 0;
}
