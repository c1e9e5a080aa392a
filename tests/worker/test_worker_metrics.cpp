// The worker's own /metrics (`poseforest worker --http ADDR`, worker/worker_metrics.h;
// docs/distributed/monitoring.md, "The worker's /metrics"): the text format and promtool's lint on
// hostile ids; DistWorker::Stats() read from another thread while a job runs (never going down,
// agreeing with the coordinator's own figures and with cpu()); a real coordinator and a real worker
// process, its /metrics fetched with cpp-httplib's client while the coordinator holds before the
// first level (the shard and the census counted, nothing else) and after the job (every counter
// that must move did), promtool clean both times; the token; bad --http values (exit 2 naming the
// flag), a port in use (exit 1), --check-config and --help.

#include <sys/stat.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "coordinator/dist_coordinator.h"
#include "proto/http/http_server.h"
#include "tests/coordinator/dist_test_util.h"
#include "tests/proto/dds_test_util.h"
#include "tests/support/process.h"
#include "worker/worker_metrics.h"

using namespace poseforest;
using namespace poseforest::proto::http;
using namespace poseforest::worker;
using namespace poseforest::coordinator;
using namespace poseforest::coordinator::testing;
using poseforest::proto::dds::testing::Child;
using poseforest::proto::dds::testing::HelperDir;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }

/// Every sample of a Prometheus text page: "name{labels}" (as written) -> value. Checks the
/// syntax of every line on the way, and that each sample's family has HELP and TYPE lines before it.
std::map<std::string, double> ParseMetrics(const std::string& text) {
  static const std::regex sample(
      R"(^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{([a-zA-Z_][a-zA-Z0-9_]*="([^"\\]|\\.)*",?)*\})? ([-+]?[0-9.eE+-]+|NaN|[+-]Inf)$)");
  static const std::regex comment(R"(^# (HELP|TYPE) ([a-zA-Z_:][a-zA-Z0-9_:]*) .+$)");
  std::map<std::string, double> out;
  std::set<std::string> help, type;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    INFO(line);
    std::smatch m;
    if (line.rfind("#", 0) == 0) {
      REQUIRE(std::regex_match(line, m, comment));
      (m[1] == "HELP" ? help : type).insert(m[2]);
      continue;
    }
    REQUIRE(std::regex_match(line, m, sample));
    CHECK(help.count(m[1]) == 1);
    CHECK(type.count(m[1]) == 1);
    const std::string series = line.substr(0, line.rfind(' '));
    CHECK(out.count(series) == 0);  // no series twice
    out[series] = std::stod(line.substr(line.rfind(' ') + 1));
  }
  // Prometheus sets `job` itself (the scrape job): none of ours.
  CHECK(text.find("{job=") == std::string::npos);
  CHECK(text.find(",job=") == std::string::npos);
  return out;
}

/// `promtool check metrics` (Debian's prometheus package): the text parses and its lint (names,
/// units, counter suffixes, HELP) finds nothing.
void CheckWithPromtool(const std::string& text, const fs::path& dir) {
  REQUIRE(fs::exists("/usr/bin/promtool"));  // scripts/setup.sh installs it (prometheus)
  const fs::path file = dir / "worker-metrics.txt";
  std::ofstream(file) << text;
  auto r = poseforest::testing::RunCommand("promtool check metrics < " + file.string());
  INFO("promtool check metrics:\n" << r.output << "\non:\n" << text);
  CHECK(r.exit_code == 0);
  CHECK(r.output.find_first_not_of(" \n") == std::string::npos);  // no lint findings
}

double At(const std::map<std::string, double>& m, const std::string& series) {
  auto it = m.find(series);
  INFO("series " << series);
  REQUIRE(it != m.end());
  return it->second;
}

/// GETs `url` until `ready` holds for its metrics (a counter is bumped just after the message it
/// counts is written, so the peer may have it a moment before the counter moves), at most 30 s;
/// the last page.
std::string WaitForMetrics(const std::string& url, const std::function<bool(const std::string&)>& ready) {
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  std::string last;
  for (;;) {
    auto page = HttpGet(url, 10s);
    INFO(page.status().ToString());
    REQUIRE(page.ok());
    last = *page;
    if (ready(last) || std::chrono::steady_clock::now() > deadline) return last;
    std::this_thread::sleep_for(50ms);
  }
}

/// The URL the worker printed ("worker: metrics: http://127.0.0.1:PORT/metrics").
std::string MetricsUrl(Child& worker) {
  auto line = worker.WaitForLine("worker: metrics: ", 30s);
  INFO(worker.OutputNow());
  REQUIRE(line.has_value());
  const size_t at = line->find("http");
  REQUIRE(at != std::string::npos);
  return line->substr(
      at, line->find(' ', at) == std::string::npos ? std::string::npos : line->find(' ', at) - at);
}
}  // namespace

TEST_CASE("worker metrics: text format, escaping and promtool's lint", "[worker][metrics][unit]") {
  TempDir dir("pf-worker-metrics-text");
  WorkerStats s;
  s.worker_id = "w\"1\\\n<script>";
  s.threads = 4;
  s.busy_threads = 4;
  s.rounds = {3, 2, 1, 1};
  s.histograms = 40;
  s.subtrees = 7;
  s.subtree_nodes = 90;
  s.evaluations = uint64_t(1) << 40;  // past 2^32
  s.shard_frames = {12, 0.75, 0};
  s.task_frames = {5, 0.25, 9};
  s.frame_cache_evictions = 2;
  s.frame_cache_bytes = 1 << 20;
  s.frame_cache_capacity_bytes = 256 << 20;
  s.messages_sent[size_t(proto::dds::Topic::kReplies)] = 10;
  s.bytes_sent[size_t(proto::dds::Topic::kReplies)] = 123456;
  s.messages_received[size_t(proto::dds::Topic::kControl)] = 11;
  s.messages_rejected = 1;
  s.cpu.level_compute = 1.5;
  SECTION("before a job: no job_info series") {
    const std::string text = WorkerPrometheus(s);
    const auto m = ParseMetrics(text);
    CHECK(text.find("poseforest_worker_job_info") == std::string::npos);
    CHECK(At(m, "poseforest_worker_up") == 1);
    CheckWithPromtool(text, dir.path);
  }
  SECTION("a job with hostile ids") {
    s.job_id = "job \"x\"\\y\nz";
    s.coordinator_id = "coord-1";
    const std::string text = WorkerPrometheus(s);
    const auto m = ParseMetrics(text);
    CHECK(At(m, R"(poseforest_worker_info{worker_id="w\"1\\\n<script>"})") == 1);
    CHECK(At(m, R"(poseforest_worker_job_info{job_id="job \"x\"\\y\nz",coordinator_id="coord-1"})") == 1);
    CHECK(At(m, "poseforest_worker_evaluations_total") == 1099511627776.0);
    CHECK(At(m, R"(poseforest_worker_rounds_total{phase="ranges"})") == 3);
    CHECK(At(m, R"(poseforest_worker_rounds_total{phase="frames"})") == 1);
    CHECK(At(m, R"(poseforest_worker_render_seconds_total{frames="shard"})") == 0.75);
    CHECK(At(m, R"(poseforest_worker_frame_cache_hits_total{frames="subtree"})") == 9);
    CHECK(At(m, R"(poseforest_worker_sent_bytes_total{topic="replies"})") == 123456);
    CHECK(At(m, R"(poseforest_worker_messages_sent_total{topic="job"})") == 0);  // every topic, from 0
    CHECK(At(m, R"(poseforest_worker_messages_dropped_total{reason="rejected"})") == 1);
    CHECK(At(m, R"(poseforest_worker_cpu_seconds_total{phase="level_compute"})") == 1.5);
    CHECK(At(m, "poseforest_worker_busy_threads") == 4);
    CHECK(At(m, "process_cpu_seconds_total") > 0);
    CHECK(At(m, "process_resident_memory_bytes") > 1e6);
    CHECK(At(m, "process_start_time_seconds") > 1.7e9);
    CheckWithPromtool(text, dir.path);
  }
}

TEST_CASE("DistWorker::Stats() while a job runs: never going down, the coordinator's figures, cpu()",
          "[worker][metrics][distributed][integration]") {
  // One worker, no hand-off: every evaluation and reply byte the coordinator counts is this
  // worker's. Another thread reads Stats() the whole time (the race a tsan build would see).
  const Job job = ParseJob(TinyJobText(1, 5));
  const uint32_t domain = Domain(61);
  const std::string job_id = "t-worker-stats-" + std::to_string(::getpid());
  WorkerOptions wo;
  wo.worker_id = "stats-w";
  wo.domain = domain;
  wo.job_id = job_id;
  wo.threads = 1;
  wo.exit_when_done = false;
  if (!std::getenv("POSEFOREST_TEST_VERBOSE")) wo.log = [](const std::string&) {};
  DistWorker worker(wo);
  CHECK(worker.Stats().evaluations == 0);
  CHECK(!worker.Stats().stopped);
  std::thread run([&] { (void)worker.Run(); });
  std::atomic<bool> done{false};
  std::atomic<int> reads{0}, went_down{0};
  std::thread reader([&] {
    WorkerStats last;
    while (!done) {
      const WorkerStats s = worker.Stats();
      const bool down = s.evaluations < last.evaluations || s.histograms < last.histograms ||
                        s.bytes_sent[size_t(proto::dds::Topic::kReplies)] <
                            last.bytes_sent[size_t(proto::dds::Topic::kReplies)] ||
                        s.shard_frames.rendered < last.shard_frames.rendered ||
                        s.cpu.level_compute < last.cpu.level_compute || s.cpu.receive < last.cpu.receive;
      went_down += down ? 1 : 0;
      last = s;
      ++reads;
      std::this_thread::sleep_for(1ms);
    }
  });
  CoordinatorOptions o;
  o.domain = domain;
  o.min_workers = 1;
  o.job_id = job_id;
  o.worker_wait = std::chrono::seconds(60);
  if (!std::getenv("POSEFOREST_TEST_VERBOSE")) o.log = [](const std::string&) {};
  uint64_t evaluations = 0, bytes_received = 0;
  o.progress = [&](const DistLevelStats& l) {
    evaluations += l.evaluations;
    bytes_received += l.bytes_received;
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  REQUIRE(forest.ok());
  const WorkerStats during = worker.Stats();
  worker.Stop();
  run.join();
  done = true;
  reader.join();
  const WorkerStats s = worker.Stats();
  CHECK(reads > 10);
  CHECK(went_down == 0);
  CHECK(!during.stopped);
  CHECK(s.stopped);
  CHECK(s.job_id == job_id);
  CHECK(!s.coordinator_id.empty());
  CHECK(s.busy_threads == 0);
  CHECK(evaluations > 0);
  CHECK(s.evaluations >= evaluations);  // the worker counts as it computes, the coordinator as it merges
  CHECK(s.bytes_sent[size_t(proto::dds::Topic::kReplies)] >= bytes_received);
  CHECK(s.messages_sent[size_t(proto::dds::Topic::kPresence)] > 0);  // heartbeats
  CHECK(s.messages_received[size_t(proto::dds::Topic::kControl)] > 0);
  CHECK(s.messages_received[size_t(proto::dds::Topic::kJob)] > 0);
  CHECK(s.rounds[1] > 0);   // histograms
  CHECK(s.rounds[2] == 1);  // the census of the one tree
  CHECK(s.histograms > 0);
  CHECK(s.subtrees == 0);                // no hand-off in this job
  CHECK(s.shard_frames.rendered == 12);  // the whole tree, once
  CHECK(s.shard_frames.render_seconds > 0);
  CHECK(s.task_frames.rendered == 0);
  // The CPU by phase in Stats() is cpu() once Run() returned.
  CHECK(s.cpu.level_compute == worker.cpu().level_compute);
  CHECK(s.cpu.receive == worker.cpu().receive);
  CHECK(s.cpu.publish == worker.cpu().publish);
  CHECK(s.cpu.level_compute > 0);
  // The page made of them passes its checks.
  const auto m = ParseMetrics(WorkerPrometheus(s));
  CHECK(At(m, "poseforest_worker_up") == 0);
  CHECK(At(m, "poseforest_worker_evaluations_total") == double(s.evaluations));
}

TEST_CASE("worker --http: /metrics of a real worker process during and after a job, promtool clean",
          "[worker][metrics][distributed][integration]") {
  TempDir dir("pf-worker-metrics-proc");
  // Nodes of <= 300 samples are trained whole (subtree tasks): one worker holds every frame, so its
  // subtree tasks find all their frames in its shard.
  const std::string text = TinyJobText(1, 6, 300);
  std::ofstream(dir.path / "job.textproto") << text;
  const uint32_t domain = Domain(62);
  const std::string job_id = "p-worker-metrics-" + std::to_string(::getpid());
  Child w;
  std::string error;
  REQUIRE(w.Start({Program(), "worker", "--domain", std::to_string(domain), "--job", job_id, "--id", "mw-0",
                   "--stay", "--http", "127.0.0.1:0"},
                  &error));
  const std::string url = MetricsUrl(w);
  INFO("worker metrics at " << url);
  // Before any job: the worker's own series, no job.
  {
    auto first = HttpGet(url, 10s);
    INFO(first.status().ToString());
    REQUIRE(first.ok());
    const auto m = ParseMetrics(*first);
    CHECK(At(m, "poseforest_worker_up") == 1);
    CHECK(At(m, R"(poseforest_worker_info{worker_id="mw-0"})") == 1);
    CHECK(first->find("poseforest_worker_job_info") == std::string::npos);
    CHECK(At(m, "poseforest_worker_evaluations_total") == 0);
    CHECK(At(m, R"(poseforest_http_requests_total{outcome="ok"})") == 0);  // counted once answered
    auto health = HttpGet(url.substr(0, url.rfind('/')) + "/healthz", 10s);
    REQUIRE(health.ok());
    CHECK(*health == "ok\n");
    auto missing = HttpGet(url.substr(0, url.rfind('/')) + "/status.json", 10s);
    CHECK(missing.status().code() == core::ErrorCode::kNotFound);
  }
  // The coordinator holds before level 0 of tree 0 while the pause file exists: by then the
  // worker has rendered its shard and answered the census, and nothing else.
  const fs::path pause = dir.path / "pause";
  std::ofstream(pause) << "";
  Child coord;
  REQUIRE(coord.Start({Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
                       (dir.path / "forest.pff").string(), "--domain", std::to_string(domain), "--job-id",
                       job_id, "--min-workers", "1", "--http", "off", "--pause-file", pause.string()},
                      &error));
  {
    auto paused = coord.WaitForLine("paused (next: tree 0, level 0)", 120s);
    INFO(coord.OutputNow());
    INFO(w.OutputNow());
    REQUIRE(paused.has_value());
    const std::string census = R"(poseforest_worker_rounds_total{phase="counts"} 1)";
    const auto held =
        WaitForMetrics(url, [&](const std::string& t) { return t.find(census + "\n") != std::string::npos; });
    const auto m = ParseMetrics(held);
    CHECK(At(m, "poseforest_worker_up") == 1);
    CHECK(held.find("poseforest_worker_job_info{job_id=\"" + job_id + "\",coordinator_id=\"") !=
          std::string::npos);
    CHECK(At(m, R"(poseforest_worker_frames_rendered_total{frames="shard"})") == 12);
    CHECK(At(m, R"(poseforest_worker_render_seconds_total{frames="shard"})") > 0);
    CHECK(At(m, R"(poseforest_worker_rounds_total{phase="counts"})") == 1);
    CHECK(At(m, R"(poseforest_worker_rounds_total{phase="histograms"})") == 0);
    CHECK(At(m, "poseforest_worker_evaluations_total") == 0);
    CHECK(At(m, "poseforest_worker_busy_threads") == 0);
    CHECK(At(m, R"(poseforest_worker_sent_bytes_total{topic="replies"})") > 0);  // the census reply
    CHECK(At(m, R"(poseforest_worker_cpu_seconds_total{phase="shard"})") > 0);
    CHECK(At(m, R"(poseforest_http_requests_total{outcome="ok"})") >= 2);
    CheckWithPromtool(held, dir.path);
  }
  fs::remove(pause);
  auto rc = coord.Wait(120s);
  INFO(coord.output());
  INFO(w.OutputNow());
  REQUIRE(rc.has_value());
  REQUIRE(*rc == 0);
  // After the job (a --stay worker keeps serving): every counter that must move did.
  auto after = HttpGet(url, 10s);
  REQUIRE(after.ok());
  const auto m = ParseMetrics(*after);
  CHECK(At(m, "poseforest_worker_up") == 1);
  CHECK(At(m, "poseforest_worker_evaluations_total") > 0);
  CHECK(At(m, "poseforest_worker_histograms_total") > 0);
  CHECK(At(m, R"(poseforest_worker_rounds_total{phase="ranges"})") > 0);
  CHECK(At(m, R"(poseforest_worker_rounds_total{phase="histograms"})") > 0);
  CHECK(At(m, R"(poseforest_worker_rounds_total{phase="frames"})") > 0);  // before the hand-offs
  CHECK(At(m, "poseforest_worker_subtrees_total") > 0);
  CHECK(At(m, "poseforest_worker_subtree_nodes_total") >= At(m, "poseforest_worker_subtrees_total"));
  CHECK(At(m, R"(poseforest_worker_frames_rendered_total{frames="shard"})") == 12);
  CHECK(At(m, R"(poseforest_worker_frames_rendered_total{frames="subtree"})") == 0);  // all in its shard
  CHECK(At(m, R"(poseforest_worker_frame_cache_hits_total{frames="subtree"})") > 0);
  CHECK(At(m, "poseforest_worker_frame_cache_evictions_total") == 0);
  CHECK(At(m, "poseforest_worker_frame_cache_capacity_bytes") >= double(256 << 20));
  CHECK(At(m, R"(poseforest_worker_sent_bytes_total{topic="replies"})") > 0);
  CHECK(At(m, R"(poseforest_worker_messages_sent_total{topic="replies"})") > 0);
  CHECK(At(m, R"(poseforest_worker_messages_sent_total{topic="presence"})") > 0);
  CHECK(At(m, R"(poseforest_worker_messages_received_total{topic="control"})") > 0);
  CHECK(At(m, R"(poseforest_worker_cpu_seconds_total{phase="level_compute"})") > 0);
  CHECK(At(m, R"(poseforest_worker_cpu_seconds_total{phase="subtree_train"})") > 0);
  CHECK(At(m, "process_cpu_seconds_total") > 0);
  CheckWithPromtool(*after, dir.path);
  w.Kill(SIGTERM);
  auto wrc = w.Wait(20s);
  INFO(w.output());
  REQUIRE(wrc.has_value());
  CHECK(*wrc == 0);
}

TEST_CASE("worker --http-token-file: /metrics needs the token, /healthz does not",
          "[worker][metrics][integration]") {
  TempDir dir("pf-worker-metrics-token");
  const fs::path token = dir.path / "token";
  std::ofstream(token) << "s3cret-token-for-the-worker\n";
  fs::permissions(token, fs::perms::owner_read | fs::perms::owner_write);
  Child w;
  std::string error;
  REQUIRE(w.Start({Program(), "worker", "--domain", std::to_string(Domain(63)), "--job", "nobody-runs-this",
                   "--id", "tw-0", "--http", "127.0.0.1:0", "--http-token-file", token.string()},
                  &error));
  const std::string url = MetricsUrl(w);
  CHECK(w.output().find("with the token of --http-token-file") != std::string::npos);
  CHECK(w.output().find("s3cret") == std::string::npos);           // the token itself is never printed
  CHECK(w.output().find("warning: --http") == std::string::npos);  // loopback: nothing to warn about
  auto health = HttpGet(url.substr(0, url.rfind('/')) + "/healthz", 10s);
  CHECK(health.ok());
  auto refused = HttpGet(url, 10s);
  REQUIRE(!refused.ok());
  CHECK(refused.status().message().find("HTTP 401") != std::string::npos);
  auto wrong = HttpGet(url, 10s, "not-the-token");
  CHECK(!wrong.ok());
  auto fine = HttpGet(url, 10s, "s3cret-token-for-the-worker");
  INFO(fine.status().ToString());
  REQUIRE(fine.ok());
  const auto m = ParseMetrics(*fine);
  CHECK(At(m, "poseforest_worker_up") == 1);
  CHECK(At(m, R"(poseforest_http_requests_total{outcome="unauthorized"})") == 2);
  w.Kill(SIGTERM);
  auto rc = w.Wait(20s);
  REQUIRE(rc.has_value());
  CHECK(*rc == 0);
}

TEST_CASE("worker --http: bad values exit 2 naming the flag; a port in use exits 1; --check-config, --help",
          "[worker][metrics][integration]") {
  auto run = [](const std::string& args) { return poseforest::testing::RunPoseforest("worker " + args); };
  for (const auto& [value, why] : std::vector<std::pair<std::string, std::string>>{
           {"nohost", "--http nohost: expected HOST:PORT"},
           {"example.com:9101", "--http example.com:9101: host must be an IPv4 address"},
           {"127.0.0.1:70000", "--http 127.0.0.1:70000: port must be 0..65535"},
           {"127.0.0.1:", "--http 127.0.0.1:: port must be 0..65535"},
           {"1.2.3:9101", "--http 1.2.3:9101: host must be an IPv4 address"}}) {
    for (const std::string extra : {"", "--check-config "}) {
      auto r = run(extra + "--domain 1 --http " + value);
      INFO(extra << value << ": " << r.output);
      CHECK(r.exit_code == 2);
      CHECK(r.output.find("worker: " + why) != std::string::npos);
    }
  }
  {  // the token and TLS flags belong to --http
    auto r = run("--domain 1 --http-token-file /nonexistent");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find("give --http HOST:PORT") != std::string::npos);
    auto off = run("--domain 1 --http off --http-tls-cert /nonexistent");
    CHECK(off.exit_code == 2);
    auto missing = run("--check-config --domain 1 --http 127.0.0.1:0 --http-token-file /nonexistent/token");
    INFO(missing.output);
    CHECK(missing.exit_code == 2);
    CHECK(missing.output.find("--http-token-file /nonexistent/token") != std::string::npos);
    auto half = run("--check-config --domain 1 --http 127.0.0.1:0 --http-tls-cert /nonexistent/c.pem");
    INFO(half.output);
    CHECK(half.exit_code == 2);
    CHECK(half.output.find("--http-tls-cert and --http-tls-key go together") != std::string::npos);
  }
  {  // --check-config says what it would serve, without opening the port
    auto every = run("--check-config --domain 1 --http :9101");
    INFO(every.output);
    CHECK(every.exit_code == 0);
    CHECK(every.output.find("metrics on http://0.0.0.0:9101/metrics") != std::string::npos);
    auto local = run("--check-config --domain 1 --http localhost:0");
    INFO(local.output);
    CHECK(local.exit_code == 0);
    CHECK(local.output.find("metrics on http://127.0.0.1:0/metrics (port 0: a free one, printed at start)") !=
          std::string::npos);
    auto off = run("--check-config --domain 1");
    CHECK(off.exit_code == 0);
    CHECK(off.output.find("; metrics off") != std::string::npos);
  }
  {  // a port in use: exit 1 naming the address, before joining DDS
    HttpServerOptions busy_opt;
    auto busy = HttpServer::Start(busy_opt, [](const HttpRequest&) { return HttpResponse{}; });
    REQUIRE(busy.ok());
    const std::string addr = "127.0.0.1:" + std::to_string((*busy)->port());
    auto r = run("--domain " + std::to_string(Domain(64)) + " --http " + addr);
    INFO(r.output);
    CHECK(r.exit_code == 1);
    CHECK(r.output.find(addr) != std::string::npos);
  }
  {
    auto help = run("--help");
    CHECK(help.exit_code == 0);
    CHECK(help.output.find("--http HOST:PORT|off") != std::string::npos);
    CHECK(help.output.find("--http-token-file FILE") != std::string::npos);
  }
}
