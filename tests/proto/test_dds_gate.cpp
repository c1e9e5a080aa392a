// Wire protocol without a network: histogram run codec, body validators, and the MessageGate's
// drop/count/flag logic on hand-made envelopes (garbage, wrong job, wrong dimensions, stale epoch,
// replays, impersonation).
#include <catch2/catch.hpp>
#include <cstdio>
#include <limits>
#include <random>

#include "proto/dds/build_id.h"
#include "proto/dds/cdr_bytes.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "tests/proto/dds_test_util.h"

namespace pd = poseforest::proto::dds;
namespace v1 = poseforest::v1;

namespace {

std::vector<uint32_t> SparseHistogram(const pd::HistogramDims& d, uint64_t samples, uint32_t seed,
                                      int parts_present) {
  // Every candidate distributes the same `samples` over a few parts and bins.
  std::vector<uint32_t> dense(d.cells(), 0);
  std::mt19937 rng(seed);
  for (uint32_t c = 0; c < d.num_candidates; ++c)
    for (uint64_t s = 0; s < samples; ++s) {
      const uint32_t bin = rng() % d.num_bins;
      const uint32_t part = (s % parts_present) * (d.num_parts / parts_present);
      ++dense[(uint64_t(c) * d.num_bins + bin) * d.num_parts + part];
    }
  return dense;
}

v1::NodeHistogram MakeNode(uint32_t id, const pd::HistogramDims& d, uint64_t samples, int parts_present) {
  v1::NodeHistogram n;
  n.set_node_id(id);
  n.set_samples(samples);
  auto dense = SparseHistogram(d, samples, id, parts_present);
  pd::EncodeHistogramRuns(dense, n.mutable_runs());
  std::vector<uint64_t> parts(d.num_parts, 0);
  for (uint64_t s = 0; s < samples; ++s) ++parts[(s % parts_present) * (d.num_parts / parts_present)];
  for (auto p : parts) n.add_part_counts(p);
  return n;
}

v1::LevelRequest Request(uint64_t epoch) {
  v1::LevelRequest r;
  r.set_tree(0);
  r.set_level(3);
  r.set_epoch(epoch);
  for (uint32_t id : {7u, 8u, 11u}) {
    r.add_node_ids(id);
    r.add_candidate_seeds(1000 + id);
  }
  r.set_job_seed(42);
  r.set_num_candidates(20);
  r.set_num_thresholds(10);
  r.set_num_parts(31);
  return r;
}

v1::HistogramReply Reply(const v1::LevelRequest& req) {
  v1::HistogramReply rep;
  rep.set_tree(req.tree());
  rep.set_level(req.level());
  rep.set_epoch(req.epoch());
  rep.set_num_candidates(req.num_candidates());
  rep.set_num_bins(req.num_thresholds());
  rep.set_num_parts(req.num_parts());
  const pd::HistogramDims d{req.num_candidates(), req.num_thresholds(), req.num_parts()};
  for (uint32_t id : req.node_ids()) *rep.add_nodes() = MakeNode(id, d, 50 + id, 3);
  return rep;
}

std::vector<uint8_t> Bytes(const std::string& s) { return {s.begin(), s.end()}; }

}  // namespace

TEST_CASE("histogram runs round-trip and are compact", "[dds][unit]") {
  const pd::HistogramDims d{200, 32, 31};
  for (int parts_present : {1, 3, 31}) {
    auto dense = SparseHistogram(d, 400, 9, parts_present);
    google::protobuf::RepeatedField<uint64_t> runs;
    pd::EncodeHistogramRuns(dense, &runs);
    auto back = pd::DecodeHistogramRuns(runs, d);
    REQUIRE(back.ok());
    CHECK(*back == dense);
    v1::NodeHistogram n;
    *n.mutable_runs() = runs;
    const size_t sparse_bytes = n.ByteSizeLong();
    const size_t dense_bytes = d.cells() * 4;
    INFO("parts present " << parts_present << ": " << sparse_bytes << " bytes sparse vs " << dense_bytes << " dense");
    std::printf("[histogram] 200 candidates x 32 bins x 31 parts, 400 samples, %d parts present: %zu bytes "
                "(dense uint32: %zu)\n",
                parts_present, sparse_bytes, dense_bytes);
    // Few parts at a node (the common case below the top levels): far smaller than dense;
    // every part present: still smaller than dense.
    if (parts_present <= 3)
      CHECK(sparse_bytes < dense_bytes / 8);
    else
      CHECK(sparse_bytes < dense_bytes / 2);
  }
  // All zeros: nothing to send.
  std::vector<uint32_t> zeros(d.cells(), 0);
  google::protobuf::RepeatedField<uint64_t> runs;
  pd::EncodeHistogramRuns(zeros, &runs);
  CHECK(runs.empty());
  auto back = pd::DecodeHistogramRuns(runs, d);
  REQUIRE(back.ok());
  CHECK(*back == zeros);
}

TEST_CASE("ValidateNodeHistogram checks each candidate's sum and the part counts from the runs", "[dds][unit]") {
  const pd::HistogramDims d{20, 8, 31};
  const uint64_t samples = 150;
  auto dense = SparseHistogram(d, samples, 5, 3);
  v1::NodeHistogram n;
  n.set_node_id(7);
  n.set_samples(samples);
  pd::EncodeHistogramRuns(dense, n.mutable_runs());
  for (int p = 0; p < 31; ++p) n.add_part_counts(p == 0 ? samples : 0);
  CHECK(pd::ValidateNodeHistogram(n, d).ok());
  // The reference: decode to a dense tensor and sum, as the gate did before it summed the runs.
  auto reference = [&](const v1::NodeHistogram& h) -> std::string {
    auto back = pd::DecodeHistogramRuns(h.runs(), d);
    if (!back.ok()) return "node " + std::to_string(h.node_id()) + ": " + back.status().message();
    for (uint32_t c = 0; c < d.num_candidates; ++c) {
      uint64_t sum = 0;
      for (uint64_t j = 0; j < uint64_t(d.num_bins) * d.num_parts; ++j) sum += (*back)[c * d.num_bins * d.num_parts + j];
      if (sum != h.samples())
        return "node " + std::to_string(h.node_id()) + " candidate " + std::to_string(c) + " counts " +
               std::to_string(sum) + " samples, node has " + std::to_string(h.samples());
    }
    return "";
  };
  auto message = [&](const v1::NodeHistogram& h) {
    const auto st = pd::ValidateNodeHistogram(h, d);
    return st.ok() ? std::string() : st.message();
  };
  // One count off in candidate 13 (the last cell of its block), and in the last candidate.
  for (uint32_t c : {13u, 19u}) {
    auto bad = dense;
    ++bad[(uint64_t(c) + 1) * d.num_bins * d.num_parts - 1];
    v1::NodeHistogram h = n;
    pd::EncodeHistogramRuns(bad, h.mutable_runs());
    CHECK(message(h) == "node 7 candidate " + std::to_string(c) + " counts 151 samples, node has 150");
    CHECK(message(h) == reference(h));
  }
  // Candidate 0 empty (all its counts moved to candidate 1): both sums are wrong, 0 is named.
  {
    auto bad = dense;
    const uint64_t block = uint64_t(d.num_bins) * d.num_parts;
    for (uint64_t j = 0; j < block; ++j) bad[block + j] += bad[j], bad[j] = 0;
    v1::NodeHistogram h = n;
    pd::EncodeHistogramRuns(bad, h.mutable_runs());
    CHECK(message(h) == "node 7 candidate 0 counts 0 samples, node has 150");
  }
  // Nothing sent for a node that claims samples: every candidate sums to 0.
  {
    v1::NodeHistogram h = n;
    h.clear_runs();
    CHECK(message(h) == "node 7 candidate 0 counts 0 samples, node has 150");
  }
  // Malformed runs are named with the node, before any sum.
  {
    v1::NodeHistogram h = n;
    h.add_runs(1);
    CHECK(message(h).rfind("node 7: histogram runs", 0) == 0);
    CHECK(message(h) == reference(h));
  }
  // Part counts: wrong number, wrong sum.
  {
    v1::NodeHistogram h = n;
    h.add_part_counts(0);
    CHECK(message(h) == "node 7 has 32 part counts, expected 31");
    h = n;
    h.set_part_counts(3, 1);
    CHECK(message(h) == "node 7 part counts sum to 151, samples 150");
  }
  // Random damage: the streamed check agrees with the dense reference.
  std::mt19937_64 rng(3);
  for (int i = 0; i < 300; ++i) {
    v1::NodeHistogram h = n;
    auto* runs = h.mutable_runs();
    const int k = int(rng() % uint64_t(runs->size()));
    runs->Set(k, rng() % 4 == 0 ? rng() % 400 : runs->Get(k) + (rng() % 3) - 1);
    CHECK(message(h) == reference(h));
  }
}

TEST_CASE("histogram run decoder refuses malformed runs", "[dds][unit]") {
  const pd::HistogramDims d{2, 3, 4};  // 24 cells
  auto decode = [&](std::vector<uint64_t> v) {
    google::protobuf::RepeatedField<uint64_t> runs(v.begin(), v.end());
    return pd::DecodeHistogramRuns(runs, d);
  };
  CHECK(decode({0, 2, 5, 6}).ok());
  CHECK(decode({23, 1, 9}).ok());
  CHECK_FALSE(decode({24, 1, 9}).ok());               // overruns
  CHECK_FALSE(decode({0, 0}).ok());                   // zero-length literal run
  CHECK_FALSE(decode({0, 3, 1, 2}).ok());             // ends inside literal run
  CHECK_FALSE(decode({5}).ok());                      // ends inside header
  CHECK_FALSE(decode({0, 1, 1ull << 33}).ok());       // count above 32 bits
  CHECK_FALSE(decode({~0ull, 1, 1}).ok());            // huge zero run (overflow guard)
  CHECK_FALSE(decode({1, ~0ull, 1}).ok());
  CHECK_FALSE(pd::DecodeHistogramRuns({}, pd::HistogramDims{4096, 256, 255}).ok());  // too big
  // Random garbage never crashes.
  std::mt19937_64 rng(1);
  for (int i = 0; i < 2000; ++i) {
    std::vector<uint64_t> v(rng() % 12);
    for (auto& x : v) x = rng() % 30;
    (void)decode(v);
  }
}

TEST_CASE("gate accepts valid messages and drops bad ones per sender", "[dds][unit]") {
  std::vector<std::string> log;
  pd::GateConfig gc;
  gc.self_id = "coordinator";
  gc.job_id = "job-A";
  gc.bad_message_budget = 5;
  gc.log = [&](const std::string& s) { log.push_back(s); };
  pd::MessageGate gate(gc);
  const v1::LevelRequest req = Request(7);
  gate.ExpectLevel(req);

  pd::EnvelopeStamper w1("job-A", "worker-1", v1::SENDER_KIND_WORKER);
  const std::string g1 = "01.0f.aa.aa.00.00.00.00.01.00.00.00|0.0.1.3";
  auto check = [&](pd::EnvelopeStamper& st, v1::Envelope env, pd::Topic topic, const std::string& guid) {
    const std::string bytes = st.Seal(topic, env);
    return gate.Check(topic, Bytes(bytes), guid);
  };

  SECTION("valid reply") {
    v1::Envelope env;
    *env.mutable_histogram() = Reply(req);
    auto out = check(w1, env, pd::Topic::kReplies, g1);
    INFO(out.detail);
    CHECK(out.verdict == pd::MessageGate::Verdict::kAccepted);
    CHECK(out.sender == "worker-1");
    CHECK(gate.stats("worker-1")->accepted == 1);
  }

  SECTION("each kind of bad message is dropped with its reason") {
    // Garbage bytes: attributed to the writer GUID (no sender id to read).
    const std::vector<uint8_t> junk = {0xff, 0xff, 0xff, 0x01, 0x02};
    auto out = gate.Check(pd::Topic::kReplies, junk, "01.0f.bb|0.0.1.3");
    CHECK(out.verdict == pd::MessageGate::Verdict::kRejected);
    CHECK(out.reason == "unparseable");
    CHECK(out.sender == "writer:01.0f.bb|0.0.1.3");

    v1::Envelope env;
    *env.mutable_histogram() = Reply(req);
    pd::EnvelopeStamper wrong_job("job-B", "worker-1", v1::SENDER_KIND_WORKER);
    CHECK(check(wrong_job, env, pd::Topic::kReplies, g1).reason == "job_id");

    v1::Envelope dims = env;
    dims.mutable_histogram()->set_num_bins(11);
    CHECK(check(w1, dims, pd::Topic::kReplies, g1).reason == "body");

    v1::Envelope lie = env;  // dimensions right, but a candidate's counts do not add up
    lie.mutable_histogram()->mutable_nodes(1)->set_samples(999);
    auto lie_out = check(w1, lie, pd::Topic::kReplies, g1);
    CHECK(lie_out.reason == "body");
    CHECK(lie_out.detail.find("candidate") != std::string::npos);

    v1::Envelope nodes = env;
    nodes.mutable_histogram()->mutable_nodes(0)->set_node_id(99);
    CHECK(check(w1, nodes, pd::Topic::kReplies, g1).reason == "body");

    v1::Envelope wrong_topic = env;
    CHECK(check(w1, wrong_topic, pd::Topic::kControl, g1).reason == "wrong_topic");

    v1::Envelope posing;  // a worker sending a coordinator's message
    *posing.mutable_level_request() = req;
    CHECK(check(w1, posing, pd::Topic::kControl, g1).reason == "sender_kind");

    CHECK(gate.stats("worker-1")->rejected == 6);
    CHECK(gate.stats("worker-1")->reasons.at("body") == 3);
    // Six bad messages exceed the budget of 5: worker-1 is reported once for eviction.
    CHECK(gate.TakeOffenders() == std::vector<std::string>{"worker-1"});
  }

  SECTION("stale epoch is counted but not bad; future epoch is bad") {
    v1::Envelope env;
    v1::LevelRequest old = req;
    old.set_epoch(6);
    *env.mutable_histogram() = Reply(old);
    auto out = check(w1, env, pd::Topic::kReplies, g1);
    CHECK(out.verdict == pd::MessageGate::Verdict::kStale);
    CHECK(gate.stats("worker-1")->stale == 1);
    CHECK(gate.stats("worker-1")->rejected == 0);
    v1::LevelRequest future = req;
    future.set_epoch(8);
    *env.mutable_histogram() = Reply(future);
    CHECK(check(w1, env, pd::Topic::kReplies, g1).verdict == pd::MessageGate::Verdict::kRejected);
  }

  SECTION("replayed sequence numbers are dropped") {
    v1::Envelope env;
    *env.mutable_histogram() = Reply(req);
    const std::string bytes = w1.Seal(pd::Topic::kReplies, env);
    CHECK(gate.Check(pd::Topic::kReplies, Bytes(bytes), g1).verdict == pd::MessageGate::Verdict::kAccepted);
    auto again = gate.Check(pd::Topic::kReplies, Bytes(bytes), g1);
    CHECK(again.verdict == pd::MessageGate::Verdict::kRejected);
    CHECK(again.reason == "sequence");
  }

  SECTION("another participant cannot use a bound sender id") {
    v1::Envelope env;
    *env.mutable_heartbeat()->mutable_capacity() = pd::testing::Capacity();
    CHECK(check(w1, env, pd::Topic::kPresence, g1).verdict == pd::MessageGate::Verdict::kAccepted);
    auto out = check(w1, env, pd::Topic::kPresence, "01.0f.cc.cc|0.0.1.3");
    CHECK(out.reason == "impersonation");
    gate.Forget("worker-1");  // e.g. worker-1's liveliness was lost and it restarted
    CHECK(check(w1, env, pd::Topic::kPresence, "01.0f.cc.cc|0.0.1.3").verdict == pd::MessageGate::Verdict::kAccepted);
  }

  SECTION("a repeated offender is flagged once and then muted") {
    v1::Envelope env;
    *env.mutable_histogram() = Reply(req);
    env.mutable_histogram()->set_num_parts(30);
    for (int i = 0; i < 5; ++i) CHECK(check(w1, env, pd::Topic::kReplies, g1).reason == "body");
    CHECK(gate.TakeOffenders().empty());
    CHECK(check(w1, env, pd::Topic::kReplies, g1).reason == "body");  // 6th > budget 5
    CHECK(gate.TakeOffenders() == std::vector<std::string>{"worker-1"});
    CHECK(gate.TakeOffenders().empty());
    // Even a valid message is now dropped, and garbage from its writer is attributed to it.
    *env.mutable_histogram() = Reply(req);
    CHECK(check(w1, env, pd::Topic::kReplies, g1).reason == "evicted");
    const std::vector<uint8_t> junk = {1, 2, 3};
    CHECK(gate.Check(pd::Topic::kReplies, junk, g1).sender == "worker-1");
    // Logging is rate limited: 5 lines of drops + the flag line, not one per message.
    CHECK(log.size() <= 7);
  }

  SECTION("messages for another recipient are ignored, not counted bad") {
    v1::Envelope env;
    *env.mutable_heartbeat()->mutable_capacity() = pd::testing::Capacity();
    env.set_recipient_id("someone-else");
    CHECK(check(w1, env, pd::Topic::kPresence, g1).verdict == pd::MessageGate::Verdict::kIgnored);
    CHECK(gate.stats("worker-1")->rejected == 0);
  }
}

TEST_CASE("worker-side gate: job announcement, coordinator identity, decisions", "[dds][unit]") {
  pd::GateConfig gc;
  gc.self_id = "worker-1";
  gc.log = [](const std::string&) {};
  pd::MessageGate gate(gc);  // no job yet
  pd::EnvelopeStamper coord("job-A", "coordinator", v1::SENDER_KIND_COORDINATOR);
  const std::string gc1 = "01.0f.01|0.0.1.3";

  v1::Envelope req;
  *req.mutable_level_request() = Request(3);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, req)), gc1).verdict ==
        pd::MessageGate::Verdict::kIgnored);

  v1::Envelope job;
  auto* j = job.mutable_job();
  j->mutable_config()->set_seed(5);
  j->set_coordinator_id("coordinator");
  j->set_num_parts(31);
  j->set_thresholds_per_feature(10);
  auto out = gate.Check(pd::Topic::kJob, Bytes(coord.Seal(pd::Topic::kJob, job)), gc1);
  REQUIRE(out.verdict == pd::MessageGate::Verdict::kAccepted);
  gate.set_job_id(out.envelope.job_id());
  gate.set_coordinator_id(out.envelope.job().coordinator_id());
  gate.set_num_parts(out.envelope.job().num_parts());

  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, req)), gc1).verdict ==
        pd::MessageGate::Verdict::kAccepted);

  // A second "coordinator" is refused.
  pd::EnvelopeStamper rogue("job-A", "coordinator-2", v1::SENDER_KIND_COORDINATOR);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(rogue.Seal(pd::Topic::kControl, req)), "01.0f.02|0.0.1.3").reason ==
        "not_coordinator");

  v1::Envelope dec;
  auto* d = dec.mutable_decisions();
  d->set_epoch(3);
  auto* n = d->add_nodes();
  n->set_node_id(7);
  auto* s = n->mutable_split();
  s->set_ux(100);
  s->set_threshold(12.5f);
  s->set_left_child(15);
  auto* leaf = d->add_nodes();
  leaf->set_node_id(8);
  for (int p = 0; p < 31; ++p) leaf->mutable_leaf()->add_part_counts(p);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, dec)), gc1).verdict ==
        pd::MessageGate::Verdict::kAccepted);
  // Wrong leaf dimension, out-of-range offset, stale epoch.
  leaf->mutable_leaf()->add_part_counts(1);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, dec)), gc1).reason == "body");
  leaf->mutable_leaf()->mutable_part_counts()->RemoveLast();
  s->set_ux(40000);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, dec)), gc1).reason == "body");
  s->set_ux(1);
  *req.mutable_level_request() = Request(4);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, req)), gc1).verdict ==
        pd::MessageGate::Verdict::kAccepted);
  CHECK(gate.Check(pd::Topic::kControl, Bytes(coord.Seal(pd::Topic::kControl, dec)), gc1).verdict ==
        pd::MessageGate::Verdict::kStale);
}

TEST_CASE("every truncation of a valid envelope is handled without crashing", "[dds][unit]") {
  pd::GateConfig gc;
  gc.self_id = "coordinator";
  gc.job_id = "job-A";
  gc.bad_message_budget = 1u << 30;
  gc.log = [](const std::string&) {};
  pd::MessageGate gate(gc);
  const v1::LevelRequest req = Request(7);
  gate.ExpectLevel(req);
  pd::EnvelopeStamper w1("job-A", "worker-1", v1::SENDER_KIND_WORKER);
  v1::Envelope env;
  *env.mutable_histogram() = Reply(req);
  const std::string bytes = w1.Seal(pd::Topic::kReplies, env);
  int accepted_truncated = 0, accepted_flipped = 0;
  for (size_t cut = 0; cut < bytes.size(); ++cut) {
    std::vector<uint8_t> part(bytes.begin(), bytes.begin() + cut);
    accepted_truncated +=
        gate.Check(pd::Topic::kReplies, part, "01.0f.aa|0.0.1.3").verdict == pd::MessageGate::Verdict::kAccepted;
  }
  // The body is the last field and length-delimited: no truncation parses as a whole message.
  CHECK(accepted_truncated == 0);
  // Flip each byte: never crashes; what still passes every check (e.g. a flipped sequence
  // number) is a well-formed message.
  for (size_t i = 0; i < bytes.size(); ++i) {
    std::vector<uint8_t> b(bytes.begin(), bytes.end());
    b[i] ^= 0x5a;
    accepted_flipped +=
        gate.Check(pd::Topic::kReplies, b, "01.0f.aa|0.0.1.3").verdict == pd::MessageGate::Verdict::kAccepted;
  }
  INFO(bytes.size() << " bytes, " << accepted_flipped << " single-byte corruptions accepted");
  CHECK(accepted_flipped < 8);
}

TEST_CASE("CDR sample payload: round trip, both endiannesses, malformed delivered raw", "[dds][unit]") {
  const std::vector<uint8_t> msg = {1, 2, 3, 4, 5};
  std::vector<uint8_t> payload(pd::kCdrHeaderBytes + msg.size());
  pd::EncodeCdrBytes(msg, payload.data());
  CHECK(payload[1] == 0x01);  // little endian
  std::vector<uint8_t> out;
  CHECK(pd::DecodeCdrBytes(payload, &out));
  CHECK(out == msg);
  // Big-endian encapsulation from another vendor's writer.
  std::vector<uint8_t> be = {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 9, 8};
  CHECK(pd::DecodeCdrBytes(be, &out));
  CHECK(out == std::vector<uint8_t>{9, 8});
  // Length beyond the payload, short header, wrong encapsulation: raw bytes, false.
  auto bad = payload;
  bad[4] = 200;
  CHECK_FALSE(pd::DecodeCdrBytes(bad, &out));
  CHECK(out == bad);
  const std::vector<uint8_t> tiny = {0x00, 0x01, 0x00};
  CHECK_FALSE(pd::DecodeCdrBytes(tiny, &out));
  CHECK(out == tiny);
  auto xcdr2 = payload;
  xcdr2[1] = 0x07;
  CHECK_FALSE(pd::DecodeCdrBytes(xcdr2, &out));
  // Empty message.
  std::vector<uint8_t> empty(pd::kCdrHeaderBytes);
  pd::EncodeCdrBytes({}, empty.data());
  CHECK(pd::DecodeCdrBytes(empty, &out));
  CHECK(out.empty());
}

TEST_CASE("validators of the other bodies", "[dds][unit]") {
  // ShardAssignment
  v1::ShardAssignment shard;
  shard.set_epoch(1);
  shard.set_shard_index(0);
  shard.set_shard_count(2);
  auto* r = shard.add_ranges();
  r->set_seed(1);
  r->set_first_index(0);
  r->set_count(100);
  CHECK(pd::ValidateShard(shard).ok());
  shard.set_shard_index(2);
  CHECK_FALSE(pd::ValidateShard(shard).ok());
  shard.set_shard_index(1);
  r->set_count(0);
  CHECK_FALSE(pd::ValidateShard(shard).ok());
  r->set_count(5);
  r->set_first_index(~0ull - 2);
  CHECK_FALSE(pd::ValidateShard(shard).ok());

  // SubtreeTask: path length must equal depth.
  v1::SubtreeTask task;
  task.set_epoch(3);
  task.set_depth(2);
  task.add_path()->mutable_split()->set_threshold(1.0f);
  *task.add_ranges() = v1::ImageRange();
  task.mutable_ranges(0)->set_count(10);
  CHECK_FALSE(pd::ValidateSubtreeTask(task).ok());
  task.add_path()->mutable_split()->set_threshold(-4.0f);
  CHECK(pd::ValidateSubtreeTask(task).ok());
  task.mutable_path(1)->mutable_split()->set_threshold(std::numeric_limits<float>::quiet_NaN());
  CHECK_FALSE(pd::ValidateSubtreeTask(task).ok());

  // SubtreeResult: sizes and CRC.
  v1::SubtreeResult res = pd::testing::BigSubtree(4096, 3);
  CHECK(pd::ValidateSubtreeResult(res).ok());
  std::string nodes = res.nodes();
  nodes[100] ^= 1;
  res.set_nodes(nodes);
  auto crc = pd::ValidateSubtreeResult(res);
  CHECK_FALSE(crc.ok());
  CHECK(crc.code() == poseforest::core::ErrorCode::kDataLoss);
  res.set_num_nodes(res.num_nodes() + 1);
  CHECK_FALSE(pd::ValidateSubtreeResult(res).ok());

  // Hello / Heartbeat / Status
  v1::WorkerHello hello;
  CHECK_FALSE(pd::ValidateHello(hello).ok());
  *hello.mutable_capacity() = pd::testing::Capacity();
  CHECK(pd::ValidateHello(hello).ok());
  // Its strings are bounded: build identity 256 bytes, refusal 2048, host name 256.
  hello.set_build_version(std::string(pd::kMaxBuildIdBytes, 'b'));
  hello.set_refusal(std::string(2048, 'r'));
  hello.set_hostname(std::string(256, 'h'));
  CHECK(pd::ValidateHello(hello).ok());
  hello.set_build_version(std::string(pd::kMaxBuildIdBytes + 1, 'b'));
  CHECK_FALSE(pd::ValidateHello(hello).ok());
  hello.set_build_version("poseforest 0.4.0");
  hello.set_refusal(std::string(2049, 'r'));
  CHECK_FALSE(pd::ValidateHello(hello).ok());
  hello.set_refusal("");
  hello.set_hostname(std::string(257, 'h'));
  CHECK_FALSE(pd::ValidateHello(hello).ok());
  v1::JobAnnouncement announced;
  announced.mutable_config()->set_seed(5);
  announced.set_coordinator_id("coordinator");
  announced.set_num_parts(31);
  announced.set_thresholds_per_feature(10);
  announced.set_build_id(std::string(pd::kMaxBuildIdBytes, 'b'));
  CHECK(pd::ValidateJob(announced).ok());
  announced.set_build_id(std::string(pd::kMaxBuildIdBytes + 1, 'b'));
  CHECK_FALSE(pd::ValidateJob(announced).ok());
  v1::Heartbeat hb;
  *hb.mutable_capacity() = pd::testing::Capacity(4);
  hb.set_busy_threads(5);
  CHECK_FALSE(pd::ValidateHeartbeat(hb).ok());
  v1::StatusEvent st;
  st.set_kind(v1::STATUS_KIND_LEVEL_DONE);
  st.set_progress(0.5);
  CHECK(pd::ValidateStatus(st).ok());
  st.set_progress(std::numeric_limits<double>::quiet_NaN());
  CHECK_FALSE(pd::ValidateStatus(st).ok());

  // LevelRequest
  v1::LevelRequest req = Request(1);
  CHECK(pd::ValidateLevelRequest(req).ok());
  req.add_node_ids(7);  // duplicate, and seeds no longer parallel
  CHECK_FALSE(pd::ValidateLevelRequest(req).ok());
  req.add_candidate_seeds(1);
  CHECK_FALSE(pd::ValidateLevelRequest(req).ok());
}
