// The distributed service in one process (coordinator + workers on threads, real DDS
// participants over shared memory): byte-identical forests with 1, 2, 3 and 5 workers, a worker
// stopped mid-job, a garbage writer, and a coordinator "crash" + resume from its checkpoint.

#include <algorithm>
#include <atomic>
#include <catch2/catch.hpp>
#include <filesystem>
#include <random>

#include "engine/wire_codec.h"
#include "proto/dds/build_id.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "tests/coordinator/dist_test_util.h"

using namespace poseforest;
using namespace poseforest::engine;
using namespace poseforest::proto::dds;
using namespace poseforest::worker;
using namespace poseforest::coordinator;
using namespace poseforest::coordinator::testing;

namespace {
/// The naive reference of EncodeWireRuns: the dense wire tensor (num_candidates x num_bins x
/// num_parts) of a node histogram built with `plan`; slot -> part through plan.part_slot.
std::vector<uint32_t> ToWireCounts(const engine::NodeHistogram& hist, const engine::NodePlan& plan,
                                   int num_parts) {
  const engine::NodeHistogram dense = hist.sample_bins ? hist.ToDense() : hist;
  const size_t k_count = size_t(dense.num_candidates), bins = size_t(dense.num_bins),
               slots = size_t(dense.num_slots);
  std::vector<int> part_of_slot(slots, 0);
  for (int p = 0; p < num_parts && p < int(plan.part_slot.size()); ++p)
    if (plan.part_slot[size_t(p)] != 0xFF) part_of_slot[plan.part_slot[size_t(p)]] = p;
  std::vector<uint32_t> wire(k_count * bins * size_t(num_parts), 0);
  if (dense.counts.empty()) return wire;
  for (size_t kb = 0; kb < k_count * bins; ++kb)
    for (size_t s = 0; s < slots; ++s)
      wire[kb * size_t(num_parts) + size_t(part_of_slot[s])] = dense.counts[kb * slots + s];
  return wire;
}

CoordinatorOptions Options(uint32_t domain, int min_workers) {
  CoordinatorOptions o;
  o.domain = domain;
  o.min_workers = min_workers;
  o.worker_wait = std::chrono::seconds(30);
  if (!std::getenv("POSEFOREST_TEST_VERBOSE")) o.log = [](const std::string&) {};
  return o;
}

/// The forest `job` trains through the service with `n` workers on threads, serialized.
std::vector<uint8_t> ServiceBytes(const Job& job, int n, uint32_t domain_offset, const std::string& job_id) {
  const uint32_t domain = Domain(domain_offset);
  ThreadWorkers workers(n, domain, job_id);
  CoordinatorOptions o = Options(domain, n);
  o.job_id = job_id;
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  REQUIRE(forest.ok());
  return core::SerializeForest(*forest);
}
}  // namespace

TEST_CASE("distributed forest is byte-identical to LocalTrainer with 1, 2, 3 and 5 workers",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText());
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  for (int n : {1, 2, 3, 5}) {
    DYNAMIC_SECTION(n << " workers") {
      const uint32_t domain = Domain(uint32_t(n));
      const std::string job_id = "t-identical-" + std::to_string(n);
      ThreadWorkers workers(n, domain, job_id);
      CoordinatorOptions o = Options(domain, n);
      o.job_id = job_id;
      std::vector<DistLevelStats> levels;
      o.progress = [&](const DistLevelStats& s) { levels.push_back(s); };
      DistCoordinator coordinator(job.config, job.params, o);
      auto forest = coordinator.Train();
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      REQUIRE(!levels.empty());
      CHECK(levels.front().workers_alive == n);
      CHECK(levels.front().workers_assigned == n);  // every worker holds frames
      CHECK(levels.front().bytes_received > 0);
      CHECK(coordinator.workers_lost() == 0);
    }
  }
}

TEST_CASE(
    "a job whose probes read the edge past it (probe_edge: PROBE_EDGE_CLAMP): the same forest with 3 workers",
    "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText() + "probe_edge: PROBE_EDGE_CLAMP\n");
  REQUIRE(job.params.constants.edge == core::ProbeEdge::kClamp);
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  auto parsed = core::ParseForest(reference, "reference");
  REQUIRE(parsed.ok());
  CHECK(parsed->constants.edge == core::ProbeEdge::kClamp);  // the forest records it (PEDG)
  // Trained the paper's way the trees differ: the workers really probed past the edge.
  CHECK(ReferenceBytes(ParseJob(TinyJobText())) != reference);
  CHECK(ServiceBytes(job, 3, 29, "t-identical-clamp") == reference);
}

TEST_CASE(
    "a job with half its candidates probing against the pixel (pixel_probe_share): the same forest with 2 "
    "workers",
    "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText() + "pixel_probe_share: 0.5\n");
  REQUIRE(job.params.pixel_probe_share == 0.5);
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  // The workers drew the pixel-probe features too: the paper's draw gives other trees.
  CHECK(ReferenceBytes(ParseJob(TinyJobText())) != reference);
  auto parsed = core::ParseForest(reference, "reference");
  REQUIRE(parsed.ok());
  size_t pixel_probes = 0;
  for (const auto& tree : parsed->trees)
    for (const auto& node : tree.nodes)
      pixel_probes += !node.is_leaf() && node.offsets.vx == 0 && node.offsets.vy == 0;
  CHECK(pixel_probes > 0);  // the trees chose some
  CHECK(ServiceBytes(job, 2, 31, "t-identical-pixel-probe") == reference);
}

TEST_CASE("a worker stopped mid-tree: its frames move to the others, same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText());
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(7);
  const std::string job_id = "t-loss";
  ThreadWorkers workers(3, domain, job_id);
  CoordinatorOptions o = Options(domain, 3);
  o.job_id = job_id;
  o.heartbeat_timeout = std::chrono::milliseconds(2000);
  bool stopped = false;
  int retries = 0;
  o.progress = [&](const DistLevelStats& s) {
    retries += s.retries;
    if (!stopped && s.tree == 0 && s.level == 1) {
      workers.Stop(1);  // its participant goes away between two levels
      stopped = true;
    }
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  REQUIRE(forest.ok());
  CHECK(stopped);
  CHECK(coordinator.workers_lost() == 1);
  CHECK(retries >= 1);
  CHECK(core::SerializeForest(*forest) == reference);
}

TEST_CASE("a garbage writer on the replies and presence topics does not break the job",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 5));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(11);
  const std::string job_id = "t-garbage";
  ThreadWorkers workers(2, domain, job_id);
  proto::dds::NodeConfig gc;
  gc.domain_id = domain;
  gc.participant_name = "garbage";
  gc.transport = proto::dds::TransportKind::kSharedMemoryOnly;
  gc.liveliness_lease = CoordinatorOptions{}.lease;  // a longer offered lease would not match
  gc.write_topics = {proto::dds::Topic::kReplies, proto::dds::Topic::kPresence};
  auto garbage = proto::dds::DdsNode::Create(gc);
  REQUIRE(garbage.ok());
  std::atomic<bool> done{false};
  std::atomic<int> sent{0}, sent_matched{0};  // sent_matched: while a reader was matched
  std::thread writer([&] {
    std::mt19937 rng(3);
    proto::dds::EnvelopeStamper stamper(job_id, "evil", v1::SENDER_KIND_WORKER);
    int i = 0;
    while (!done) {
      std::string bytes;
      switch (i++ % 3) {
        case 0: {  // random bytes
          bytes.resize(1 + rng() % 300);
          for (char& c : bytes) c = char(rng());
          break;
        }
        case 1: {  // a well-formed envelope with impossible dimensions
          v1::Envelope env;
          auto* h = env.mutable_histogram();
          h->set_epoch(1);
          h->set_num_candidates(100000);
          bytes = stamper.Seal(proto::dds::Topic::kReplies, env);
          break;
        }
        default: {  // a hello with an invalid capacity
          v1::Envelope env;
          env.mutable_hello()->mutable_capacity()->set_threads(0);
          bytes = stamper.Seal(proto::dds::Topic::kPresence, env);
        }
      }
      const proto::dds::Topic topic = i % 3 == 0 ? proto::dds::Topic::kPresence : proto::dds::Topic::kReplies;
      const bool matched = (*garbage)->MatchedReaders(topic) > 0;
      (void)(*garbage)->Publish(topic, bytes);
      ++sent;
      if (matched) ++sent_matched;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  CoordinatorOptions o = Options(domain, 2);
  o.job_id = job_id;
  // A volatile writer's samples before the match are lost, and matching can take seconds on a
  // loaded machine (once the whole job was over first: 0 rejected). After the first level, wait
  // until the garbage has been flowing to a matched reader for a while.
  bool waited = false;
  o.progress = [&](const DistLevelStats&) {
    if (waited) return;
    waited = true;
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (sent_matched < 60 && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  done = true;
  writer.join();
  REQUIRE(forest.ok());
  CHECK(core::SerializeForest(*forest) == reference);
  CHECK(sent_matched >= 60);
  CHECK(coordinator.rejected_messages() > 0);
}

TEST_CASE("workers of another build or refusing the job are not admitted, and the coordinator names them",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 5));
  const uint32_t domain = Domain(81);
  const std::string job_id = "t-admit";
  std::mutex log_mu;
  std::vector<std::string> log;
  auto options = [&](int min_workers, int wait_ms) {
    CoordinatorOptions o = Options(domain, min_workers);
    o.job_id = job_id;
    o.worker_wait = std::chrono::milliseconds(wait_ms);
    o.log = [&](const std::string& m) {
      std::lock_guard<std::mutex> lock(log_mu);
      log.push_back(m);
    };
    return o;
  };
  auto logged = [&](const std::string& what) {
    std::lock_guard<std::mutex> lock(log_mu);
    return std::count_if(log.begin(), log.end(),
                         [&](const std::string& l) { return l.find(what) != std::string::npos; });
  };

  SECTION("a real worker of another build refuses the job; the coordinator says why, and whose") {
    ThreadWorkers workers(0, domain, job_id);
    worker::WorkerOptions wo;
    wo.worker_id = "tw-other-build";
    wo.domain = domain;
    wo.job_id = job_id;
    wo.build_id = "poseforest 0.0.1 0123456789ab GNU-1.0 x86_64";
    workers.Add(wo);
    DistCoordinator coordinator(job.config, job.params, options(1, 6000));
    auto forest = coordinator.Train();
    REQUIRE(!forest.ok());
    const std::string msg = forest.status().message();
    INFO(msg);
    CHECK(forest.status().code() == core::ErrorCode::kNotFound);
    CHECK(msg.find("0 of 1 workers") != std::string::npos);
    CHECK(msg.find("1 worker(s) not admitted: tw-other-build on ") != std::string::npos);
    CHECK(msg.find("refused the job: the coordinator runs build \"" + std::string(CompiledBuildId()) +
                   "\", this worker \"poseforest 0.0.1 0123456789ab GNU-1.0 x86_64\"") != std::string::npos);
    // Said once, though the job is announced again every 2 s.
    CHECK(logged("refused the job") == 1);
  }

  SECTION("hellos of an older build and of a worker refusing the job: not admitted, the real one trains") {
    const std::vector<uint8_t> reference = ReferenceBytes(job);
    // One participant each: the gate binds a participant to the first sender id it speaks as.
    auto peer = [&](const std::string& name) {
      proto::dds::NodeConfig pc;
      pc.domain_id = domain;
      pc.participant_name = name;
      pc.transport = proto::dds::TransportKind::kSharedMemoryOnly;
      pc.liveliness_lease = CoordinatorOptions{}.lease;
      pc.write_topics = {proto::dds::Topic::kPresence};
      auto node = proto::dds::DdsNode::Create(pc);
      REQUIRE(node.ok());
      return std::move(*node);
    };
    auto old_peer = peer("old-build"), refusing_peer = peer("no-data");
    std::atomic<bool> done{false};
    std::thread writer([&] {
      proto::dds::EnvelopeStamper old_build(job_id, "old-build", v1::SENDER_KIND_WORKER);
      proto::dds::EnvelopeStamper refusing(job_id, "no-data", v1::SENDER_KIND_WORKER);
      while (!done) {
        v1::Envelope a;
        auto* h = a.mutable_hello();
        h->mutable_capacity()->set_threads(1);
        h->mutable_capacity()->set_renderer(v1::RENDERER_KIND_PROCEDURAL);
        h->set_hostname("host-a");
        h->set_build_version("poseforest-dist-1");  // what workers before the check sent
        (void)old_peer->Publish(proto::dds::Topic::kPresence,
                                old_build.Seal(proto::dds::Topic::kPresence, a));
        v1::Envelope b;
        h = b.mutable_hello();
        h->mutable_capacity()->set_threads(1);
        h->mutable_capacity()->set_renderer(v1::RENDERER_KIND_PROCEDURAL);
        h->set_hostname("host-b\x1b[31m");
        h->set_build_version(std::string(CompiledBuildId()));
        h->set_refusal("job t-admit: mocap file /data/x.bvh: No such file");
        (void)refusing_peer->Publish(proto::dds::Topic::kPresence,
                                     refusing.Seal(proto::dds::Topic::kPresence, b));
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    });
    // Both fakes are heard before the real worker starts: the job waits for the one worker.
    CoordinatorOptions o = options(1, 30000);
    ThreadWorkers workers(0, domain, job_id);
    bool started = false;
    o.progress = [&](const DistLevelStats&) { started = true; };
    DistCoordinator coordinator(job.config, job.params, o);
    std::thread late([&] {
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      while ((logged("worker old-build on host-a") == 0 || logged("worker no-data on host-b") == 0) &&
             std::chrono::steady_clock::now() < until)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      workers.Add(domain, job_id, "real-" + std::to_string(::getpid()));
    });
    auto forest = coordinator.Train();
    late.join();
    done = true;
    writer.join();
    REQUIRE(forest.ok());
    CHECK(started);
    CHECK(core::SerializeForest(*forest) == reference);
    CHECK(logged("worker old-build on host-a (pid 0): runs build \"poseforest-dist-1\", this coordinator \"" +
                 std::string(CompiledBuildId()) + "\": not admitted") == 1);
    // Control characters of the peer's strings are not passed to the log.
    CHECK(logged("worker no-data on host-b?[31m (pid 0): refused the job: job t-admit: mocap file "
                 "/data/x.bvh: No such file") == 1);
    CHECK(coordinator.rejected_messages() == 0);
  }
}

TEST_CASE("coordinator stopped after a few levels resumes from its checkpoint: same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText());
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(13);
  const std::string job_id = "t-resume";
  const auto dir = std::filesystem::temp_directory_path() / ("pf-dist-ckpt-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  ThreadWorkers workers(2, domain, job_id);
  // Inside tree 0; after tree 0's last level (7 levels: 0..6); inside tree 1.
  for (int stop_after : {3, 7, 9}) {
    DYNAMIC_SECTION("stop after " << stop_after << " levels") {
      std::filesystem::remove_all(dir);
      CoordinatorOptions o = Options(domain, 2);
      o.job_id = job_id;
      o.checkpoint_dir = dir.string();
      o.stop_after_levels = stop_after;
      {
        DistCoordinator first(job.config, job.params, o);
        auto r = first.Train();
        REQUIRE(!r.ok());
        CHECK(r.status().message().find("test hook") != std::string::npos);
      }
      o.stop_after_levels = -1;
      o.resume = true;
      DistCoordinator second(job.config, job.params, o);
      auto forest = second.Train();
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
    }
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("a checkpoint is resumed only by the build that wrote it", "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 5));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(85);
  const std::string job_id = "t-resume-build";
  TempDir dir("pf-dist-ckpt-build");
  ThreadWorkers workers(1, domain, job_id);
  CoordinatorOptions o = Options(domain, 1);
  o.job_id = job_id;
  o.checkpoint_dir = dir.path.string();
  o.stop_after_levels = 2;
  {
    DistCoordinator first(job.config, job.params, o);
    REQUIRE(!first.Train().ok());
  }
  const std::vector<uint8_t> saved = ReadAll(dir.path / "checkpoint.pb");
  o.stop_after_levels = -1;
  o.resume = true;
  {
    // One byte changed on disk: refused by its checksum (it could parse as another job state),
    // the file left as it is.
    std::vector<uint8_t> corrupt = saved;
    corrupt[corrupt.size() / 2] ^= 0x01;
    REQUIRE(core::WriteFileAtomic((dir.path / "checkpoint.pb").string(), corrupt).ok());
    DistCoordinator resumed(job.config, job.params, o);
    auto r = resumed.Train();
    REQUIRE(!r.ok());
    INFO(r.status().ToString());
    CHECK(r.status().code() == core::ErrorCode::kDataLoss);
    CHECK(r.status().message().find("checkpoint.pb: checksum mismatch: the checkpoint is corrupt") !=
          std::string::npos);
    CHECK(ReadAll(dir.path / "checkpoint.pb") == corrupt);
    REQUIRE(core::WriteFileAtomic((dir.path / "checkpoint.pb").string(), saved).ok());
  }
  {
    // The coordinator reads its build identity when it starts the job.
    ::setenv("POSEFOREST_BUILD_ID", "poseforest 9.9.9 fedcba987654 GNU-99 x86_64", 1);
    DistCoordinator other(job.config, job.params, o);
    auto r = other.Train();
    ::unsetenv("POSEFOREST_BUILD_ID");
    REQUIRE(!r.ok());
    INFO(r.status().ToString());
    CHECK(r.status().code() == core::ErrorCode::kVersionMismatch);
    CHECK(r.status().message().find(
              "written by build \"" + std::string(CompiledBuildId()) +
              "\", this coordinator is \"poseforest 9.9.9 fedcba987654 GNU-99 x86_64\"") !=
          std::string::npos);
  }
  CHECK(ReadAll(dir.path / "checkpoint.pb") == saved);  // untouched
  DistCoordinator same(job.config, job.params, o);
  auto forest = same.Train();
  REQUIRE(forest.ok());
  CHECK(core::SerializeForest(*forest) == reference);
}

TEST_CASE("a worker joining mid-job gets frames at the next tree", "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(2, 5));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(17);
  const std::string job_id = "t-late";
  ThreadWorkers workers(1, domain, job_id);
  CoordinatorOptions o = Options(domain, 1);
  o.job_id = job_id;
  o.min_workers_per_tree = {1, 2};
  bool added = false;
  int assigned_tree1 = 0;
  o.progress = [&](const DistLevelStats& s) {
    if (!added && s.tree == 0 && s.level == 1) {
      CHECK(s.workers_assigned == 1);
      workers.Add(domain, job_id, "tw-late");
      added = true;
    }
    if (s.tree == 1) assigned_tree1 = std::max(assigned_tree1, s.workers_assigned);
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  REQUIRE(forest.ok());
  CHECK(added);
  CHECK(assigned_tree1 == 2);
  CHECK(core::SerializeForest(*forest) == reference);
}

TEST_CASE("a registered worker that sends bad replies is evicted; its frames go to the others",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 5));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(19);
  const std::string job_id = "t-evict";
  ThreadWorkers workers(2, domain, job_id);
  proto::dds::NodeConfig gc;
  gc.domain_id = domain;
  gc.participant_name = "liar";
  gc.transport = proto::dds::TransportKind::kSharedMemoryOnly;
  gc.liveliness_lease = CoordinatorOptions{}.lease;  // a longer offered lease would not match
  gc.write_topics = {proto::dds::Topic::kReplies, proto::dds::Topic::kPresence};
  gc.read_topics = {proto::dds::Topic::kControl};
  auto liar = proto::dds::DdsNode::Create(gc);
  REQUIRE(liar.ok());
  std::atomic<bool> done{false};
  std::thread writer([&] {
    proto::dds::EnvelopeStamper stamper(job_id, "liar", v1::SENDER_KIND_WORKER);
    bool assigned = false;
    while (!done) {
      uint64_t request_epoch = 0;
      while (auto s = (*liar)->Receive(std::chrono::milliseconds(0))) {
        v1::Envelope in;
        if (!in.ParseFromArray(s->bytes.data(), int(s->bytes.size()))) continue;
        if (in.has_shard() && in.recipient_id() == "liar") assigned = true;
        if (in.has_level_request()) request_epoch = in.level_request().epoch();
      }
      // Presence stays valid (a proper hello, then heartbeats), so only the gate can catch it.
      v1::Envelope presence;
      auto* cap = assigned ? presence.mutable_heartbeat()->mutable_capacity()
                           : presence.mutable_hello()->mutable_capacity();
      cap->set_threads(1);
      cap->set_renderer(v1::RENDERER_KIND_PROCEDURAL);
      if (presence.has_hello()) presence.mutable_hello()->set_build_version(std::string(CompiledBuildId()));
      (void)(*liar)->Publish(proto::dds::Topic::kPresence,
                             stamper.Seal(proto::dds::Topic::kPresence, presence));
      for (int i = 0; request_epoch != 0 && i < 20; ++i) {  // answers of the wrong shape
        v1::Envelope env;
        auto* h = env.mutable_histogram();
        h->set_epoch(request_epoch);
        h->set_num_candidates(1);
        h->set_num_bins(2);
        h->set_num_parts(31);
        (void)(*liar)->Publish(proto::dds::Topic::kReplies, stamper.Seal(proto::dds::Topic::kReplies, env));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  CoordinatorOptions o = Options(domain, 3);
  o.job_id = job_id;
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  done = true;
  writer.join();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  CHECK(core::SerializeForest(*forest) == reference);
  CHECK(coordinator.workers_lost() == 1);
  CHECK(coordinator.rejected_messages() > 16);
}

TEST_CASE("EncodeWireRuns gives the runs of EncodeHistogramRuns(ToWireCounts(...)) to the value",
          "[distributed][unit]") {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 300; ++trial) {
    const int k = 1 + int(rng() % 40), bins = 2 + int(rng() % 20);
    std::vector<uint64_t> part_counts(core::kNumParts, 0);
    const int present = 1 + int(rng() % core::kNumParts);
    for (int i = 0; i < present; ++i) part_counts[rng() % core::kNumParts] = 1;
    engine::NodePlan plan;
    plan.SetParts(part_counts);
    const bool per_sample = trial % 3 == 0;
    engine::NodeHistogram h;
    h.Reset(uint32_t(trial), k, bins, plan.num_slots, per_sample);
    // Densities from empty to full, so that runs, isolated zeros and long gaps all occur.
    const uint32_t density = rng() % 101;
    if (per_sample) {
      const int n = int(rng() % 50);
      for (int i = 0; i < n; ++i) {
        h.sample_slot.push_back(uint8_t(rng() % uint32_t(plan.num_slots)));
        for (int c = 0; c < k; ++c) h.sample_bin.push_back(uint8_t(rng() % uint32_t(bins)));
      }
    } else {
      for (uint32_t& c : h.counts)
        if (rng() % 100 < density) c = 1 + rng() % (trial % 2 ? 3 : 100000);
    }
    google::protobuf::RepeatedField<uint64_t> direct, reference;
    EncodeWireRuns(h, plan, core::kNumParts, &direct);
    proto::dds::EncodeHistogramRuns(ToWireCounts(h, plan, core::kNumParts), &reference);
    INFO("trial " << trial << ": " << k << " candidates, " << bins << " bins, " << plan.num_slots << " slots"
                  << (per_sample ? ", per-sample bins" : ""));
    REQUIRE(std::vector<uint64_t>(direct.begin(), direct.end()) ==
            std::vector<uint64_t>(reference.begin(), reference.end()));
  }
}

TEST_CASE("DistWorker without an id gets worker-HOST-PID-RANDOM, a different one each time",
          "[distributed][unit]") {
  WorkerOptions none;
  none.log = [](const std::string&) {};
  DistWorker a(none), b(none);
  const std::string pid = "-" + std::to_string(::getpid()) + "-";
  for (const std::string& id : {a.id(), b.id()}) {
    INFO(id);
    CHECK(id.rfind("worker-", 0) == 0);
    const size_t at = id.rfind(pid);
    REQUIRE(at != std::string::npos);
    const std::string suffix = id.substr(at + pid.size());
    CHECK(suffix.size() == 6);
    CHECK(suffix.find_first_not_of("0123456789abcdef") == std::string::npos);
  }
  CHECK(a.id() != b.id());  // two workers of one process are two workers to the coordinator
  CHECK(DefaultWorkerId() != DefaultWorkerId());
  WorkerOptions named;
  named.worker_id = "w-7";
  CHECK(DistWorker(named).id() == "w-7");
}

TEST_CASE("discovery server lists: [ID@]IP[:PORT], GUID prefixes of fast-discovery-server -i ID",
          "[distributed][unit]") {
  CHECK(proto::dds::DiscoveryServerGuidPrefix(0) == "44.53.00.5f.45.50.52.4f.53.49.4d.41");
  CHECK(proto::dds::DiscoveryServerGuidPrefix(1) == "44.53.01.5f.45.50.52.4f.53.49.4d.41");
  CHECK(proto::dds::DiscoveryServerGuidPrefix(200) == "44.53.c8.5f.45.50.52.4f.53.49.4d.41");
  CHECK(proto::dds::DiscoveryServerGuidPrefix(256).empty());
  auto list = proto::dds::ParseDiscoveryServers("10.0.0.1,3@10.0.0.2:7000,0@10.0.0.3:11811x");
  REQUIRE_FALSE(list.ok());
  CHECK(list.status().message().find("'0@10.0.0.3:11811x' has port '11811x'") != std::string::npos);
  list = proto::dds::ParseDiscoveryServers("10.0.0.1,3@10.0.0.2:7000,,");
  REQUIRE(list.ok());
  REQUIRE(list->size() == 2);
  CHECK((*list)[0].id == 0);
  CHECK_FALSE((*list)[0].id_given);
  CHECK((*list)[0].port == 11811);
  CHECK((*list)[1].id == 3);
  CHECK((*list)[1].id_given);
  CHECK((*list)[1].host == "10.0.0.2");
  CHECK((*list)[1].port == 7000);
  CHECK(proto::dds::FormatDiscoveryServers(*list) == "10.0.0.1:11811,3@10.0.0.2:7000");
  CHECK(proto::dds::FormatDiscoveryServers(*proto::dds::ParseDiscoveryServers("0@10.0.0.1")) ==
        "10.0.0.1:11811");
}
