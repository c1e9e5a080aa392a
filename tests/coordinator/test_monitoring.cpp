// Monitoring of the distributed service: the coordinator's status JSON, Prometheus metrics and
// dashboard (loaded in headless Chromium) during and after a real run with local workers,
// `poseforest monitor --once`, the event log (a worker SIGKILLed gives WORKER_LOST, the job still
// finishes), `poseforest export` (byte-identical to --out for a finished job; a stopped job loads
// in the runtime), hostile HTTP clients, and corrupt checkpoints.

#include <arpa/inet.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/stubs/logging.h>
#include <google/protobuf/util/json_util.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "coordinator/checkpoint_export.h"
#include "coordinator/monitoring/dashboard.h"
#include "coordinator/monitoring/event_log.h"
#include "coordinator/monitoring/status_model.h"
#include "poseforest/v1/checkpoint.pb.h"
#include "poseforest/v1/status.pb.h"
#include "proto/http/http_server.h"
#include "tests/coordinator/dist_test_util.h"
#include "tests/coordinator/http_test_util.h"
#include "tests/proto/dds_test_util.h"
#include "tests/support/process.h"

using namespace poseforest;
using namespace poseforest::proto::http;
using namespace poseforest::coordinator;
using namespace poseforest::coordinator::monitoring;
using namespace poseforest::coordinator::testing;
using poseforest::proto::dds::testing::Child;
using poseforest::proto::dds::testing::HelperDir;
using namespace std::chrono_literals;
namespace pb = google::protobuf;
namespace fs = std::filesystem;

namespace {
std::string Program() { return (HelperDir() / "poseforest").string(); }

std::string SmokeJob() {
  const std::string text = ReadText(fs::path(POSEFOREST_SOURCE_DIR) / "docs/training/smoke_job.textproto");
  REQUIRE(!text.empty());
  return text;
}

pb::Struct ParseJson(const std::string& text) {
  pb::Struct s;
  const auto st = pb::util::JsonStringToMessage(text, &s);
  INFO(text.substr(0, 2000));
  REQUIRE(st.ok());
  return s;
}

double Num(const pb::Struct& s, const std::string& k) {
  auto it = s.fields().find(k);
  REQUIRE(it != s.fields().end());
  return it->second.number_value();
}
std::string Str(const pb::Struct& s, const std::string& k) {
  auto it = s.fields().find(k);
  REQUIRE(it != s.fields().end());
  return it->second.string_value();
}
const pb::ListValue& List(const pb::Struct& s, const std::string& k) {
  auto it = s.fields().find(k);
  REQUIRE(it != s.fields().end());
  return it->second.list_value();
}

/// `text` into `m` strictly (an unknown field or a wrong type fails), as status.proto says.
template <typename Message>
Message ParseStrict(const std::string& text) {
  Message m;
  const auto st = pb::util::JsonStringToMessage(text, &m);  // default: unknown fields rejected
  INFO(text.substr(0, 2000));
  INFO(st.ToString());
  REQUIRE(st.ok());
  return m;
}

pb::Struct GetStatus(const std::string& url) {
  auto body = HttpGet(url + "/status.json", 5s);
  if (!body.ok()) FAIL(body.status().ToString());
  (void)ParseStrict<v1::JobStatus>(*body);  // the schema holds every field the coordinator prints
  return ParseJson(*body);
}

/// The keys of `s`, sorted.
std::set<std::string> Keys(const pb::Struct& s) {
  std::set<std::string> keys;
  for (const auto& [k, v] : s.fields()) keys.insert(k);
  return keys;
}

/// The URL from the coordinator's "status: http://..." line.
std::string WaitForUrl(Child& c) {
  auto line = c.WaitForLine("status: http://", 60s);
  INFO(c.output());
  REQUIRE(line.has_value());
  const size_t a = line->find("http://");
  const size_t b = line->find("/ (dashboard)");
  REQUIRE(b != std::string::npos);
  return line->substr(a, b - a);
}

uint16_t PortOf(const std::string& url) { return uint16_t(std::stoi(url.substr(url.rfind(':') + 1))); }

/// Every sample line of a Prometheus text exposition is NAME{LABELS} VALUE and every family has
/// HELP and TYPE lines.
void CheckPrometheusSyntax(const std::string& text) {
  static const std::regex sample(
      R"(^[a-zA-Z_:][a-zA-Z0-9_:]*(\{([a-zA-Z_][a-zA-Z0-9_]*="([^"\\]|\\.)*",?)*\})? ([-+]?[0-9.eE+-]+|NaN|[+-]Inf)$)");
  static const std::regex comment(R"(^# (HELP|TYPE) [a-zA-Z_:][a-zA-Z0-9_:]* .+$)");
  std::istringstream in(text);
  std::string line;
  int samples = 0;
  while (std::getline(in, line)) {
    INFO(line);
    if (line.rfind("#", 0) == 0)
      CHECK(std::regex_match(line, comment));
    else {
      CHECK(std::regex_match(line, sample));
      ++samples;
    }
  }
  CHECK(samples > 20);
  // Prometheus sets `job` itself: none of ours (it would clash); the build's own series.
  CHECK(text.find("{job=") == std::string::npos);
  CHECK(text.find(",job=") == std::string::npos);
  CHECK(text.find("poseforest_build_info{version=\"") != std::string::npos);
}

/// `promtool check metrics` (Debian's prometheus package): the text parses, and its lint (names,
/// units, counter suffixes, HELP) finds nothing.
void CheckWithPromtool(const std::string& text, const fs::path& dir) {
  const fs::path file = dir / "metrics.txt";
  std::ofstream(file) << text;
  auto r = poseforest::testing::RunCommand("promtool check metrics < " + file.string());
  INFO("promtool check metrics:\n" << r.output);
  CHECK(r.exit_code == 0);
  CHECK(r.output.find_first_not_of(" \n") == std::string::npos);  // no lint findings
}

std::vector<pb::Struct> EventLines(const fs::path& p) {
  std::vector<pb::Struct> out;
  std::istringstream in(ReadText(p));
  std::string line;
  while (std::getline(in, line)) {
    (void)ParseStrict<v1::JobEvent>(line);
    out.push_back(ParseJson(line));
  }
  return out;
}

int CountEvents(const std::vector<pb::Struct>& events, const std::string& kind) {
  int n = 0;
  for (const auto& e : events) n += Str(e, "event") == kind;
  return n;
}

int CountMatches(const std::string& text, const std::string& pattern) {
  const std::regex re(pattern);
  return int(std::distance(std::sregex_iterator(text.begin(), text.end(), re), std::sregex_iterator()));
}

int CountLines(const std::string& text, const std::string& needle) {
  int n = 0;
  for (size_t p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++n;
  return n;
}

/// The rows of `monitor --levels`' table: tree, level, nodes, split, samples, mean entropy, mean
/// gain, evaluations/s, seconds, workers. Empty without the table.
std::vector<std::vector<double>> LevelTableRows(const std::string& output) {
  std::vector<std::vector<double>> rows;
  std::istringstream in(output);
  std::string line;
  bool in_table = false;
  while (std::getline(in, line)) {
    if (line.rfind("levels (mean entropy and gain in bits)", 0) == 0) {
      in_table = true;
      std::getline(in, line);  // the column names
      continue;
    }
    if (!in_table) continue;
    std::istringstream cells(line);
    std::vector<double> row;
    for (double v; cells >> v;) row.push_back(v);
    if (row.size() != 10) break;
    rows.push_back(row);
  }
  return rows;
}

/// `rows` (LevelTableRows) against /status.json's "levels", each figure to the digits shown.
void CheckLevelRows(const std::vector<std::vector<double>>& rows, const pb::ListValue& levels) {
  REQUIRE(rows.size() == size_t(levels.values_size()));
  for (size_t i = 0; i < rows.size(); ++i) {
    const pb::Struct& l = levels.values(int(i)).struct_value();
    INFO("row " << i);
    CHECK(rows[i][0] == Num(l, "tree"));
    CHECK(rows[i][1] == Num(l, "level"));
    CHECK(rows[i][2] == Num(l, "nodes"));
    CHECK(rows[i][3] == Num(l, "split"));
    CHECK(rows[i][4] == Num(l, "samples"));
    CHECK(std::abs(rows[i][5] - Num(l, "entropy")) <= 0.0005 + 1e-12);
    CHECK(std::abs(rows[i][6] - Num(l, "gain")) <= 0.0005 + 1e-12);
    CHECK(std::abs(rows[i][7] - Num(l, "evaluations_per_s")) <= 0.5 + 1e-9);
    CHECK(std::abs(rows[i][8] - Num(l, "seconds")) <= 0.0005 + 1e-12);
    CHECK(rows[i][9] == Num(l, "workers"));
  }
}

/// A figure as `monitor` prints it ("127.31 M", "290.1 k", "12").
double SiValue(const std::string& text) {
  double v = std::stod(text);
  if (text.back() == 'k') v *= 1e3;
  if (text.back() == 'M') v *= 1e6;
  if (text.back() == 'G') v *= 1e9;
  return v;
}

}  // namespace

TEST_CASE(
    "coordinator status over HTTP during and after a run: JSON, metrics, dashboard, monitor, event log, "
    "export",
    "[distributed][monitoring][integration][slow]") {
  TempDir dir("pf-mon-run");
  std::ofstream(dir.path / "job.textproto") << SmokeJob();
  const std::string job_id = "mon-" + std::to_string(::getpid());
  Child coord;
  std::string error;
  REQUIRE(coord.Start({Program(),
                       "coordinator",
                       (dir.path / "job.textproto").string(),
                       "--out",
                       (dir.path / "forest.pff").string(),
                       "--local-workers",
                       "2",
                       "--domain",
                       std::to_string(Domain(41)),
                       "--job-id",
                       job_id,
                       "--http",
                       "127.0.0.1:0",
                       "--event-log",
                       (dir.path / "events.jsonl").string(),
                       "--checkpoint",
                       (dir.path / "ckpt").string(),
                       "--http-linger-s",
                       "10",
                       "--pause-file",
                       (dir.path / "pause").string()},
                      &error));
  const std::string url = WaitForUrl(coord);
  {
    auto line = coord.WaitForLine("tree 0 level 3:", 120s);
    INFO(coord.output());
    REQUIRE(line.has_value());
  }
  // Hold the job between levels while the live views are checked (on a fast machine the small
  // job would otherwise end first); it goes on when the file is removed.
  std::ofstream(dir.path / "pause") << "held by test_monitoring\n";
  {
    auto line = coord.WaitForLine("paused (next: tree ", 60s);
    INFO(coord.output());
    REQUIRE(line.has_value());
  }
  // `monitor --once --domain` first (the workers' rates cover their last 10 s): the same view
  // from the DDS status topic, no URL needed, throughput figures and worker table included.
  {
    // The newest status at the moment of the pause may predate the workers' first heartbeat
    // with counted work (a fast machine reaches level 3 within a second); while the job is held
    // the coordinator publishes PROGRESS every 2 s with the heartbeats' figures, so ask again,
    // for a few seconds, until the worker rows carry work (the checks below then hold or fail).
    static const std::regex busy_row(
        R"(  local-worker-\S+ +training +30 +[0-9]+ +[1-9][0-9.]*(?: [kMG])? +[1-9])");
    poseforest::testing::CommandResult mon_dds;
    for (int attempt = 0; attempt < 8; ++attempt) {
      if (attempt > 0) std::this_thread::sleep_for(1s);
      mon_dds = poseforest::testing::RunPoseforest("monitor --once --domain " + std::to_string(Domain(41)) +
                                                   " --job " + job_id + " --timeout-s 30");
      const std::string& o = mon_dds.output;
      const auto rows_busy =
          std::distance(std::sregex_iterator(o.begin(), o.end(), busy_row), std::sregex_iterator());
      if (rows_busy >= 2) break;
    }
    INFO(mon_dds.output);
    CHECK(mon_dds.exit_code == 0);
    CHECK(mon_dds.output.find("DDS domain " + std::to_string(Domain(41)) + "  coordinator coordinator-") !=
          std::string::npos);
    CHECK(mon_dds.output.find("job " + job_id + "  state training") != std::string::npos);
    CHECK(std::regex_search(mon_dds.output, std::regex(R"(ETA [0-9]+[hms])")));  // known, not "-"
    CHECK(std::regex_search(mon_dds.output,
                            std::regex(R"(tree [12]/2  level [0-9]+/14  nodes [0-9]+/[0-9]+)")));
    std::smatch m;
    REQUIRE(std::regex_search(
        mon_dds.output, m,
        std::regex(
            R"(samples/s ([0-9.]+(?: [kMG])?)  evaluations/s ([0-9.]+(?: [kMG])?)  \(([0-9.]+(?: [kMG])?) evaluations)")));
    CHECK(SiValue(m[1]) > 0);
    CHECK(SiValue(m[2]) > 0);
    CHECK(SiValue(m[3]) > 0);
    CHECK(mon_dds.output.find("workers: 2 alive, 0 lost or evicted") != std::string::npos);
    // The worker table: id, state, frames, replies, evaluations/s (its heartbeats' rate over
    // its last 10 s), evaluations, last seen.
    static const std::regex row(
        R"(  (local-worker-\S+) +training +30 +([0-9]+) +([0-9.]+(?: [kMG])?) +([0-9.]+(?: [kMG])?) +[0-9]+s ago)");
    std::istringstream in(mon_dds.output);
    std::string line;
    int rows = 0;
    while (std::getline(in, line)) {
      if (line.rfind("  local-worker-", 0) != 0) continue;
      INFO(line);
      std::smatch r;
      REQUIRE(std::regex_match(line, r, row));
      CHECK(std::stoi(r[2]) > 0);
      CHECK(SiValue(r[3]) > 0);
      CHECK(SiValue(r[4]) > 0);
      ++rows;
    }
    CHECK(rows == 2);
    CHECK(LevelTableRows(mon_dds.output).empty());  // the table only with --levels
  }
  // `monitor --once --levels`, over HTTP and over DDS, while the job is held (no level finishes
  // meanwhile): the per-level table, row for row the coordinator's /status.json "levels".
  {
    const pb::Struct held = GetStatus(url);
    const auto& held_levels = List(held, "levels");
    REQUIRE(held_levels.values_size() >= 4);  // tree 0, levels 0..3 at least
    auto by_url = poseforest::testing::RunPoseforest("monitor --once --levels --url " + url);
    INFO(by_url.output);
    CHECK(by_url.exit_code == 0);
    CheckLevelRows(LevelTableRows(by_url.output), held_levels);
    // Over DDS the newest event is what the table shows; while held the coordinator publishes
    // PROGRESS every 2 s with its levels, so a reader that got an older event asks again.
    poseforest::testing::CommandResult by_dds;
    for (int attempt = 0; attempt < 5; ++attempt) {
      if (attempt > 0) std::this_thread::sleep_for(1s);
      by_dds = poseforest::testing::RunPoseforest("monitor --once --levels --domain " +
                                                  std::to_string(Domain(41)) + " --job " + job_id +
                                                  " --timeout-s 30");
      if (LevelTableRows(by_dds.output).size() == size_t(held_levels.values_size())) break;
    }
    INFO(by_dds.output);
    CHECK(by_dds.exit_code == 0);
    CheckLevelRows(LevelTableRows(by_dds.output), held_levels);
    CHECK(List(GetStatus(url), "levels").values_size() == held_levels.values_size());  // still held
  }
  // During the run.
  const pb::Struct s = GetStatus(url);
  CHECK(Str(s, "job_id") == job_id);
  CHECK(Str(s, "state") == "training");
  CHECK(Num(s, "level") >= 3);
  CHECK(Num(s, "level_nodes_total") >= 1);
  CHECK(Num(s, "level_nodes_done") <= Num(s, "level_nodes_total"));
  CHECK(Num(s, "evaluations_per_s") > 0);
  CHECK(Num(s, "samples_per_s") > 0);
  CHECK(Num(s, "progress") > 0);
  CHECK(Num(s, "progress") < 1);
  CHECK(s.fields().at("eta_s").has_number_value());
  const auto& levels = List(s, "levels");
  REQUIRE(levels.values_size() >= 4);
  const pb::Struct& root = levels.values(0).struct_value();
  CHECK(Num(root, "tree") == 0);
  CHECK(Num(root, "level") == 0);
  CHECK(Num(root, "nodes") == 1);
  CHECK(Num(root, "entropy") > 1.0);  // 31 parts: several bits at the root
  CHECK(Num(root, "gain") > 0);
  CHECK(Num(levels.values(3).struct_value(), "entropy") < Num(root, "entropy"));
  const auto& workers = List(s, "workers");
  REQUIRE(workers.values_size() == 2);
  for (const auto& w : workers.values()) {
    CHECK(Str(w.struct_value(), "id").find("local-worker-") == 0);
    CHECK(Str(w.struct_value(), "state") == "training");
    CHECK(Num(w.struct_value(), "frames") == 30);  // 60 frames per tree over 2 workers
    CHECK(Num(w.struct_value(), "evaluations") > 0);
  }
  // Metrics.
  auto metrics = HttpGet(url + "/metrics", 5s);
  REQUIRE(metrics.ok());
  CheckPrometheusSyntax(*metrics);
  CheckWithPromtool(*metrics, dir.path);
  CHECK(metrics->find("poseforest_job_state{exported_job=\"" + job_id + "\",state=\"training\"} 1") !=
        std::string::npos);
  CHECK(metrics->find("# TYPE poseforest_evaluations_total counter") != std::string::npos);
  CHECK(CountLines(*metrics, "poseforest_worker_up{") == 2);
  CHECK(metrics->find("poseforest_workers{exported_job=\"" + job_id + "\",state=\"training\"} 2") !=
        std::string::npos);
  // `poseforest monitor --once`.
  auto mon = poseforest::testing::RunPoseforest("monitor --once --url " + url);
  INFO(mon.output);
  CHECK(mon.exit_code == 0);
  CHECK(mon.output.find("job " + job_id + "  state training") != std::string::npos);
  CHECK(mon.output.find("workers: 2 alive, 0 lost or evicted") != std::string::npos);
  CHECK(CountLines(mon.output, "  local-worker-") == 2);
  CHECK(std::regex_search(mon.output, std::regex(R"(tree [12]/2  level [0-9]+/14  nodes [0-9]+/[0-9]+)")));
  // Hostile clients against the live coordinator: answered, and training goes on.
  CHECK(StatusCode(RawExchange(PortOf(url), "BREW /pot HTCPCP/1.0\r\n\r\n")) == 400);
  CHECK(StatusCode(RawExchange(PortOf(url), "GET / HTTP/1.1\r\nX: " + std::string(100000, 'a'))) == 431);
  // The dashboard in headless Chromium: its script fetched /status.json and filled the page.
  const std::string dom = DumpDom(url + "/");
  INFO(dom.substr(0, 4000));
  CHECK(ElementText(dom, "job") == job_id);
  CHECK(std::regex_match(ElementText(dom, "tree"), std::regex(R"([12] / 2)")));
  CHECK(std::regex_match(ElementText(dom, "level"), std::regex(R"([0-9]+ / 14)")));
  CHECK(std::regex_match(ElementText(dom, "nodes"), std::regex(R"([0-9]+ / [0-9]+)")));
  CHECK(CountLines(dom, "class=\"worker-row\"") == 2);
  CHECK(dom.find("<td class=\"l\">local-worker-") != std::string::npos);
  CHECK(std::regex_search(dom, std::regex(R"(id="chart-eps"[^>]*points="[0-9])")));  // the chart is drawn
  CHECK(coord.output().find("resumed") == std::string::npos);  // still held: the views saw a live job
  std::filesystem::remove(dir.path / "pause");

  // After the run: the final state stays up for --http-linger-s.
  {
    auto line = coord.WaitForLine("wrote ", 180s);
    INFO(coord.output());
    REQUIRE(line.has_value());
  }
  const pb::Struct done = GetStatus(url);
  CHECK(Str(done, "state") == "done");
  CHECK(Num(done, "progress") == 1);
  CHECK(Num(done, "trees_done") == 2);
  const int level_lines = CountMatches(coord.output(), R"(tree [0-9]+ level [0-9]+: )");
  CHECK(level_lines > 10);
  CHECK(Num(done.fields().at("totals").struct_value(), "levels") == double(level_lines));
  CHECK(List(done, "levels").values_size() == level_lines);
  for (const auto& w : List(done, "workers").values()) CHECK(Str(w.struct_value(), "state") == "done");
  auto final_metrics = HttpGet(url + "/metrics", 5s);
  REQUIRE(final_metrics.ok());
  CHECK(final_metrics->find("poseforest_job_state{exported_job=\"" + job_id + "\",state=\"done\"} 1") !=
        std::string::npos);
  CHECK(final_metrics->find("poseforest_job_progress_ratio{exported_job=\"" + job_id + "\"} 1") != std::string::npos);
  auto mon_done = poseforest::testing::RunPoseforest("monitor --url " + url);  // exits on "done"
  CHECK(mon_done.exit_code == 0);
  CHECK(mon_done.output.find("state done") != std::string::npos);
  auto rc = coord.Wait(60s);
  REQUIRE(rc.has_value());
  CHECK(*rc == 0);

  // Event log.
  const auto events = EventLines(dir.path / "events.jsonl");
  CHECK(CountEvents(events, "JOB_STARTED") == 1);
  CHECK(CountEvents(events, "WORKER_JOINED") == 2);
  CHECK(CountEvents(events, "LEVEL_DONE") == level_lines);
  CHECK(CountEvents(events, "TREE_DONE") == 2);
  CHECK(CountEvents(events, "JOB_DONE") == 1);
  CHECK(CountEvents(events, "FOREST_WRITTEN") == 1);
  CHECK(Str(events.front(), "event") == "JOB_STARTED");
  CHECK(Str(events.back(), "event") == "FOREST_WRITTEN");
  for (const auto& e : events) {
    CHECK(Str(e, "job") == job_id);
    if (Str(e, "event") == "LEVEL_DONE") CHECK(Num(e, "mean_entropy") >= 0);
  }

  // Export from the checkpoint = the coordinator's forest, byte for byte.
  auto ex = poseforest::testing::RunPoseforest("export --checkpoint " + (dir.path / "ckpt").string() +
                                               " --out " + (dir.path / "exported.pff").string());
  INFO(ex.output);
  CHECK(ex.exit_code == 0);
  CHECK(ex.output.find("job " + job_id + " finished: 2 of 2 trees") != std::string::npos);
  CHECK(ReadText(dir.path / "exported.pff") == ReadText(dir.path / "forest.pff"));
}

TEST_CASE("a worker SIGKILLed mid-job: WORKER_LOST in the status and the event log, the job finishes",
          "[distributed][monitoring][integration][slow]") {
  TempDir dir("pf-mon-kill");
  const std::string text = TinyJobText(2, 8);
  std::ofstream(dir.path / "job.textproto") << text;
  const uint32_t domain = Domain(43);
  const std::string job_id = "mon-kill-" + std::to_string(::getpid());
  Child w[3];
  std::string error;
  for (int i = 0; i < 3; ++i)
    REQUIRE(w[i].Start({Program(), "worker", "--domain", std::to_string(domain), "--job", job_id, "--id",
                        "mk-" + std::to_string(i)},
                       &error));
  Child coord;
  REQUIRE(coord.Start(
      {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
       (dir.path / "forest.pff").string(), "--domain", std::to_string(domain), "--job-id", job_id,
       "--min-workers", "3", "--event-log", (dir.path / "events.jsonl").string(), "--http-linger-s", "10"},
      &error));
  const std::string url = WaitForUrl(coord);
  // One read while the job runs: the final state then stays up for --http-linger-s (the server
  // lingers only if someone read it), so the read after "wrote" below does not race its exit
  // (once, under CI load: "Connection reset by peer").
  CHECK(Str(GetStatus(url), "job_id") == job_id);
  {
    auto line = coord.WaitForLine("tree 0 level 1:", 90s);
    INFO(coord.output());
    REQUIRE(line.has_value());
  }
  w[1].Kill(SIGKILL);
  auto line = coord.WaitForLine("wrote ", 120s);
  INFO(coord.output());
  REQUIRE(line.has_value());
  const pb::Struct s = GetStatus(url);
  CHECK(Str(s, "state") == "done");
  // Under a loaded CI machine a live worker's heartbeats can run late: it is counted lost and
  // joins again (seen once: mk-0, "heartbeat timeout"). What must hold is that the killed worker
  // was noticed and the job ended with the engine's forest.
  CHECK(Num(s.fields().at("totals").struct_value(), "workers_lost") >= 1);
  std::map<std::string, std::string> states;
  for (const auto& x : List(s, "workers").values())
    states[Str(x.struct_value(), "id")] = Str(x.struct_value(), "state");
  CHECK(states["mk-1"] == "lost");
  CHECK(states["mk-0"] == "done");
  CHECK(states["mk-2"] == "done");
  auto rc = coord.Wait(60s);
  REQUIRE(rc.has_value());
  CHECK(*rc == 0);
  const auto events = EventLines(dir.path / "events.jsonl");
  CHECK(CountEvents(events, "JOB_STARTED") == 1);
  CHECK(CountEvents(events, "WORKER_JOINED") >= 3);
  CHECK(CountEvents(events, "WORKER_LOST") >= 1);
  CHECK(CountEvents(events, "LEVEL_DONE") > 2);
  CHECK(CountEvents(events, "JOB_DONE") == 1);
  std::set<std::string> lost;
  for (const auto& e : events)
    if (Str(e, "event") == "WORKER_LOST") lost.insert(Str(e, "worker"));
  CHECK(lost.count("mk-1") == 1);
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(text));
  CHECK(ReadText(dir.path / "forest.pff") == std::string(reference.begin(), reference.end()));
}

TEST_CASE("export after a stopped job: finished trees + the tree in progress as leaves, loads in the runtime",
          "[distributed][monitoring][integration][slow]") {
  TempDir dir("pf-mon-stop");
  std::ofstream(dir.path / "job.textproto") << SmokeJob();
  {
    Child coord;
    std::string error;
    REQUIRE(coord.Start(
        {Program(), "coordinator", (dir.path / "job.textproto").string(), "--out",
         (dir.path / "forest.pff").string(), "--local-workers", "2", "--domain", std::to_string(Domain(45)),
         "--checkpoint", (dir.path / "ckpt").string(), "--http", "off"},
        &error));
    auto line = coord.WaitForLine("tree 1 level 4:", 180s);
    INFO(coord.output());
    REQUIRE(line.has_value());
    CHECK(coord.output().find("status: http") == std::string::npos);  // --http off
    coord.Kill(SIGKILL);
  }
  const std::string ckpt = (dir.path / "ckpt").string();
  auto leaves = poseforest::testing::RunPoseforest("export --checkpoint " + ckpt + " --out " +
                                                   (dir.path / "leaves.pff").string());
  INFO(leaves.output);
  REQUIRE(leaves.exit_code == 0);
  CHECK(std::regex_search(
      leaves.output,
      std::regex(
          R"(stopped: 1 of 2 trees finished; tree 1 \(in progress, [0-9]+ levels decided\) finished as [0-9]+ leaves)")));
  auto drop = poseforest::testing::RunPoseforest("export --checkpoint " + ckpt + " --partial drop --out " +
                                                 (dir.path / "drop.pff").string());
  INFO(drop.output);
  REQUIRE(drop.exit_code == 0);
  CHECK(drop.output.find("dropped") != std::string::npos);
  auto inspect = poseforest::testing::RunPoseforest("inspect " + (dir.path / "leaves.pff").string() + " " +
                                                    (dir.path / "drop.pff").string());
  INFO(inspect.output);
  CHECK(inspect.exit_code == 0);
  // Tree 0 is the finished job's tree 0 (same job, same seed): check against LocalTrainer.
  auto job = ParseJob(SmokeJob());
  job.params.threads = 2;
  engine::LocalTrainer trainer(job.params, {});
  auto full = trainer.Train();
  REQUIRE(full.ok());
  auto exported = core::LoadForest((dir.path / "leaves.pff").string());
  REQUIRE(exported.ok());
  REQUIRE(exported->trees.size() == 2);
  const auto& a = exported->trees[0].nodes;
  const auto& b = full->trees[0].nodes;
  REQUIRE(a.size() == b.size());
  CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0);
  CHECK(exported->trees[0].leaves == full->trees[0].leaves);
  // The partial tree is the full tree cut at the checkpoint's depth: fewer nodes, same top.
  CHECK(exported->trees[1].nodes.size() < full->trees[1].nodes.size());
  CHECK(exported->trees[1].nodes[0].is_leaf() == full->trees[1].nodes[0].is_leaf());
  auto dropped = core::LoadForest((dir.path / "drop.pff").string());
  REQUIRE(dropped.ok());
  CHECK(dropped->trees.size() == 1);
}

TEST_CASE("export: missing and corrupt checkpoints give errors, never a crash",
          "[distributed][monitoring][integration]") {
  TempDir dir("pf-mon-corrupt");
  // A real checkpoint of a small job, trained in-process with thread workers.
  const std::string text = TinyJobText(2, 5);
  Job job = ParseJob(text);
  const uint32_t domain = Domain(47);
  const std::string job_id = "mon-ck-" + std::to_string(::getpid());
  std::vector<uint8_t> trained;
  {
    ThreadWorkers workers(2, domain, job_id);
    CoordinatorOptions opt;
    opt.job_id = job_id;
    opt.domain = domain;
    opt.min_workers = 2;
    opt.checkpoint_dir = (dir.path / "ckpt").string();
    opt.log = [](const std::string&) {};
    DistCoordinator c(job.config, job.params, opt);
    auto f = c.Train();
    REQUIRE(f.ok());
    trained = core::SerializeForest(*f);
  }
  const std::string good = ReadText(dir.path / "ckpt" / "checkpoint.pb");
  REQUIRE(good.size() > 100);
  {
    auto r = ForestFromCheckpoint((dir.path / "ckpt").string(), PartialTree::kFinishAsLeaves);
    REQUIRE(r.ok());
    CHECK(core::SerializeForest(r->forest) == trained);
  }
  // Through the command: missing, garbage, a config of another kind.
  auto missing = poseforest::testing::RunPoseforest("export --checkpoint " + (dir.path / "nope").string() +
                                                    " --out " + (dir.path / "x.pff").string());
  CHECK(missing.exit_code == 1);
  CHECK(missing.output.find("no checkpoint") != std::string::npos);
  fs::create_directories(dir.path / "bad");
  std::ofstream(dir.path / "bad" / "checkpoint.pb") << "this is not a protobuf \xff\xff\xff\xff";
  auto garbage = poseforest::testing::RunPoseforest("export --checkpoint " + (dir.path / "bad").string() +
                                                    " --out " + (dir.path / "x.pff").string());
  CHECK(garbage.exit_code == 1);
  CHECK(garbage.output.find((dir.path / "bad" / "checkpoint.pb").string()) != std::string::npos);
  CHECK(!fs::exists(dir.path / "x.pff"));
  auto usage = poseforest::testing::RunPoseforest("export --checkpoint " + (dir.path / "ckpt").string());
  CHECK(usage.exit_code == 2);

  // Every truncation and a byte flip at every offset: an error, never a crash, and never another
  // forest (format 3: the file's CRC-32 trailer). Before the trailer a flip could parse as
  // another job state, and a cut at a field's end as a shorter one.
  const std::string file = "mutated.pb";
  REQUIRE(good.size() > 8);
  REQUIRE(good.compare(good.size() - 8, 4, "PFCK") == 0);
  const std::string message = good.substr(0, good.size() - 8);
  REQUIRE(poseforest::coordinator::SealCheckpoint(message) == good);
  {
    poseforest::v1::Checkpoint ck;
    REQUIRE(ck.ParseFromString(message));
    CHECK(ck.format() == 3);
    ck.set_format(2);  // a checkpoint written before the trailer: read unchecked, the same forest
    auto legacy = ForestFromCheckpointBytes(ck.SerializeAsString(), file, PartialTree::kFinishAsLeaves);
    REQUIRE(legacy.ok());
    auto sealed = ForestFromCheckpointBytes(good, file, PartialTree::kFinishAsLeaves);
    REQUIRE(sealed.ok());
    CHECK(core::SerializeForest(legacy->forest) == core::SerializeForest(sealed->forest));
    // A format-3 message without its trailer: cut short.
    auto cut = ForestFromCheckpointBytes(message, file, PartialTree::kFinishAsLeaves);
    REQUIRE_FALSE(cut.ok());
    CHECK(cut.status().message() == file + ": no checksum at its end: the checkpoint is cut short");
  }
  int errors = 0, valid = 0;
  auto attempt = [&](const std::string& bytes) {
    auto r = ForestFromCheckpointBytes(bytes, file, PartialTree::kFinishAsLeaves);
    if (!r.ok()) {
      ++errors;
      CHECK(r.status().message().find(file) != std::string::npos);
    } else {
      ++valid;
      CHECK(core::ValidateForest(r->forest, "mutated").ok());
    }
  };
  google::protobuf::LogSilencer quiet;  // libprotobuf logs invalid UTF-8 in string fields
  for (size_t n = 0; n < good.size(); ++n) attempt(good.substr(0, n));
  CHECK(valid == 0);
  for (size_t i = 0; i < good.size(); ++i) {
    std::string b = good;
    b[i] = char(b[i] ^ 0x5A);
    attempt(b);
  }
  CHECK(valid == 0);
  CHECK(errors == int(2 * good.size()));
  // The checksum's own message names the file.
  std::string flipped = good;
  flipped[good.size() / 2] = char(flipped[good.size() / 2] ^ 1);
  auto bad_crc = ForestFromCheckpointBytes(flipped, file, PartialTree::kFinishAsLeaves);
  REQUIRE_FALSE(bad_crc.ok());
  CHECK(bad_crc.status().message() == file + ": checksum mismatch: the checkpoint is corrupt");
}

TEST_CASE("HTTP server: bad requests, huge heads, slow clients and floods do not block it",
          "[distributed][monitoring][unit]") {
  StatusModel model({"hostile-job", 3, "shm", 2, 6, 10, 100, 20, 8, "/tmp/x.pff"});
  HttpServerOptions opt;
  opt.timeout = 700ms;
  opt.max_connections = 8;
  auto server = HttpServer::Start(opt, StatusHandler(&model));
  REQUIRE(server.ok());
  HttpServer& http = **server;
  const uint16_t port = http.port();
  const std::string url = http.url();
  auto ok = [&](int line) {
    auto body = HttpGet(url + "/status.json", 2s);
    if (!body.ok()) FAIL("line " << line << ": " << body.status().ToString());
    CHECK(Str(ParseJson(*body), "job_id") == "hostile-job");
  };
  ok(__LINE__);
  CHECK(StatusCode(RawExchange(port, "GARBAGE\r\n\r\n")) == 400);
  CHECK(StatusCode(RawExchange(port, "GET /status.json HTTP/9.9\r\n\r\n")) == 400);
  CHECK(StatusCode(RawExchange(port, "GET  /  HTTP/1.1\r\n\r\n")) == 400);
  CHECK(StatusCode(RawExchange(port, "GET nopath HTTP/1.1\r\n\r\n")) == 400);
  CHECK(StatusCode(RawExchange(port, std::string("G\0T / HTTP/1.1\r\n\r\n", 18))) == 400);
  CHECK(StatusCode(RawExchange(port, "POST /status.json HTTP/1.1\r\nContent-Length: 3\r\n\r\nabc")) == 405);
  CHECK(StatusCode(RawExchange(port, "GET /nothing HTTP/1.1\r\n\r\n")) == 404);
  CHECK(StatusCode(RawExchange(port, "GET /status.json HTTP/1.0\r\n\r\n")) == 200);
  const std::string head = RawExchange(port, "HEAD /metrics HTTP/1.1\r\n\r\n");
  CHECK(StatusCode(head) == 200);
  CHECK(head.substr(head.find("\r\n\r\n") + 4).empty());
  // A head that never ends: 431 once it passes the limit, the connection closed.
  CHECK(StatusCode(RawExchange(port, "GET / HTTP/1.1\r\n" + std::string(1 << 20, 'h'))) == 431);
  CHECK(StatusCode(RawExchange(port, "GET / HTTP/1.1\r\nCookie: " + std::string(20000, 'c') + "\r\n\r\n")) ==
        431);
  ok(__LINE__);
  // Slow clients (a few bytes, then silence) hold no one up and get 408 at the timeout: a request
  // meanwhile is served while all four are still held (none has had its 408 yet).
  std::vector<std::thread> slow;
  std::vector<int> slow_codes(4, 0);
  std::atomic<int> slow_done{0};
  for (int i = 0; i < 4; ++i)
    slow.emplace_back([&, i] {
      slow_codes[size_t(i)] = StatusCode(RawExchange(port, "GET /sta", 5s));
      ++slow_done;
    });
  std::this_thread::sleep_for(100ms);
  ok(__LINE__);
  CHECK(slow_done.load() == 0);
  for (auto& t : slow) t.join();
  for (int c : slow_codes) CHECK(c == 408);
  // A flood beyond max_connections: the extra ones are refused with 503, then all is well again.
  std::vector<int> fds;
  for (int i = 0; i < 8; ++i) {
    const int fd = ConnectLoopback(port);
    fds.push_back(fd);
  }
  std::this_thread::sleep_for(200ms);
  CHECK(StatusCode(RawExchange(port, "GET / HTTP/1.1\r\n\r\n")) == 503);
  for (int fd : fds) ::close(fd);
  std::this_thread::sleep_for(300ms);
  ok(__LINE__);
  CHECK(http.dropped() >= 1);
  CHECK(http.bad_requests() >= 12);
  // Clients that connect and reset.
  for (int i = 0; i < 20; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) {
      ::send(fd, "GET / HTTP/1.1\r\n\r\n", 18, MSG_NOSIGNAL);
      linger l{1, 0};
      ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof l);
    }
    ::close(fd);
  }
  std::this_thread::sleep_for(300ms);  // with max_connections 8 the dead ones must be reaped first
  ok(__LINE__);
  // The dashboard is one self-contained page.
  auto page = HttpGet(url + "/", 2s);
  REQUIRE(page.ok());
  CHECK(page->find("<script>") != std::string::npos);
  CHECK(page->find("src=") == std::string::npos);
  CHECK(page->find("href=") == std::string::npos);
  // Bad addresses.
  HttpServerOptions bad;
  CHECK(!ParseHttpAddress("nohost", &bad).ok());
  CHECK(!ParseHttpAddress("1.2.3:80", &bad).ok());
  CHECK(!ParseHttpAddress("127.0.0.1:70000", &bad).ok());
  CHECK(!ParseHttpAddress("example.com:80", &bad).ok());
  HttpServerOptions taken;
  taken.port = port;
  CHECK(!HttpServer::Start(taken, StatusHandler(&model)).ok());
  CHECK(!HttpGet("http://127.0.0.1:1/status.json", 1s).ok());
}

TEST_CASE("status JSON and metrics escape hostile worker ids", "[distributed][monitoring][unit]") {
  StatusModel model({"job-\"x\"", 0, "shm", 1, 4, 10, 100, 20, 8, ""});
  const std::string evil = "w\"1\\\n<script>alert(1)</script>\x01\xff";
  v1::StatusEvent e;
  e.set_kind(v1::STATUS_KIND_WORKER_JOINED);
  e.set_worker_id(evil);
  model.OnStatus(e);
  model.OnWorkerAssigned(evil, 0, 5);
  const pb::Struct s = ParseJson(model.Json());
  CHECK(Str(s, "job_id") == "job-\"x\"");
  const auto& w = List(s, "workers");
  REQUIRE(w.values_size() == 1);
  // Control characters and invalid UTF-8 come back escaped / replaced, everything else as sent.
  CHECK(Str(w.values(0).struct_value(), "id") == "w\"1\\\n<script>alert(1)</script>\x01\xef\xbf\xbd");
  CheckPrometheusSyntax(model.Prometheus());
  CHECK(model.Prometheus().find("worker=\"w\\\"1\\\\\\n<script>") != std::string::npos);
}

TEST_CASE("throughput figures on the wire: hostile values are dropped and counted, ours always pass",
          "[distributed][monitoring][unit]") {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  // Heartbeat: evaluations_per_s must be finite, 0..1e13; evaluations at most 2^62.
  v1::Heartbeat hb;
  *hb.mutable_capacity() = poseforest::proto::dds::testing::Capacity(2);
  hb.set_evaluations(123456);
  hb.set_evaluations_per_s(5e6);
  CHECK(poseforest::proto::dds::ValidateHeartbeat(hb).ok());
  for (double bad : {nan, inf, -inf, -1.0, 2e13, 1e300}) {
    v1::Heartbeat h = hb;
    h.set_evaluations_per_s(bad);
    INFO(bad);
    CHECK_FALSE(poseforest::proto::dds::ValidateHeartbeat(h).ok());
  }
  {
    v1::Heartbeat h = hb;
    h.set_evaluations(uint64_t(1) << 63);
    CHECK_FALSE(poseforest::proto::dds::ValidateHeartbeat(h).ok());
  }

  // The coordinator's gate drops them, counts them against the sender, and flags it.
  {
    std::vector<std::string> log;
    poseforest::proto::dds::MessageGate gate(poseforest::proto::dds::GateConfig{
        "coord", "job-1", 2, [&](const std::string& l) { log.push_back(l); }});
    poseforest::proto::dds::EnvelopeStamper w("job-1", "w-hostile", v1::SENDER_KIND_WORKER);
    auto send = [&](double rate) {
      v1::Envelope env;
      *env.mutable_heartbeat() = hb;
      env.mutable_heartbeat()->set_evaluations_per_s(rate);
      const std::string bytes = w.Seal(poseforest::proto::dds::Topic::kPresence, env);
      return gate.Check(
          poseforest::proto::dds::Topic::kPresence,
          std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
          "p1|writer1");
    };
    CHECK(send(1e6).verdict == poseforest::proto::dds::MessageGate::Verdict::kAccepted);
    auto out = send(nan);
    CHECK(out.verdict == poseforest::proto::dds::MessageGate::Verdict::kRejected);
    CHECK(out.sender == "w-hostile");
    CHECK(out.detail.find("evaluations_per_s") != std::string::npos);
    CHECK(send(-5).verdict == poseforest::proto::dds::MessageGate::Verdict::kRejected);
    CHECK(send(1e300).verdict == poseforest::proto::dds::MessageGate::Verdict::kRejected);
    CHECK(gate.total_rejected() == 3);
    CHECK(gate.TakeOffenders() == std::vector<std::string>{"w-hostile"});  // budget 2
    REQUIRE(!log.empty());
    CHECK(log.front().find("w-hostile") != std::string::npos);  // logged with the sender
  }

  // StatusEvent: rates, times, counts and the worker table.
  v1::StatusEvent ok;
  ok.set_kind(v1::STATUS_KIND_PROGRESS);
  ok.set_progress(0.25);
  ok.set_samples_per_s(1e5);
  ok.set_evaluations_per_s(1e8);
  ok.set_eta_s(30);
  ok.set_elapsed_s(10);
  ok.set_level_nodes_done(3);
  ok.set_level_nodes_total(8);
  auto* w = ok.add_workers();
  w->set_id("w-0");
  w->set_state(v1::WORKER_STATE_TRAINING);
  w->set_evaluations_per_s(4e7);
  w->set_last_seen_s(0.2);
  auto* lv = ok.add_levels();
  lv->set_tree(1);
  lv->set_level(20);
  lv->set_nodes(900);
  lv->set_split(400);
  lv->set_samples(123456);
  lv->set_entropy(2.5);
  lv->set_gain(0.3);
  lv->set_evaluations(1000000);
  lv->set_evaluations_per_s(5e7);
  lv->set_seconds(0.02);
  lv->set_workers(2);
  CHECK(poseforest::proto::dds::ValidateStatus(ok).ok());
  std::vector<std::pair<std::string, std::function<void(v1::StatusEvent&)>>> hostile = {
      {"NaN samples/s", [&](v1::StatusEvent& e) { e.set_samples_per_s(nan); }},
      {"negative evaluations/s", [&](v1::StatusEvent& e) { e.set_evaluations_per_s(-1); }},
      {"huge evaluations/s", [&](v1::StatusEvent& e) { e.set_evaluations_per_s(1e200); }},
      {"negative ETA", [&](v1::StatusEvent& e) { e.set_eta_s(-3); }},
      {"infinite ETA", [&](v1::StatusEvent& e) { e.set_eta_s(inf); }},
      {"NaN elapsed", [&](v1::StatusEvent& e) { e.set_elapsed_s(nan); }},
      {"nodes done above total", [&](v1::StatusEvent& e) { e.set_level_nodes_done(9); }},
      {"huge count", [&](v1::StatusEvent& e) { e.set_evaluations(uint64_t(1) << 63); }},
      {"worker rate NaN", [&](v1::StatusEvent& e) { e.mutable_workers(0)->set_evaluations_per_s(nan); }},
      {"worker rate negative", [&](v1::StatusEvent& e) { e.mutable_workers(0)->set_evaluations_per_s(-2); }},
      {"worker last seen NaN", [&](v1::StatusEvent& e) { e.mutable_workers(0)->set_last_seen_s(nan); }},
      {"worker without id", [&](v1::StatusEvent& e) { e.mutable_workers(0)->clear_id(); }},
      {"worker id of 1000 bytes",
       [&](v1::StatusEvent& e) { e.mutable_workers(0)->set_id(std::string(1000, 'w')); }},
      {"worker state unspecified", [&](v1::StatusEvent& e) { e.mutable_workers(0)->clear_state(); }},
      {"5000 workers",
       [&](v1::StatusEvent& e) {
         for (int i = 0; i < 5000; ++i) *e.add_workers() = e.workers(0);
       }},
      {"level entropy NaN", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_entropy(nan); }},
      {"level gain negative", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_gain(-0.5); }},
      {"level gain of 100 bits", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_gain(100); }},
      {"level rate infinite", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_evaluations_per_s(inf); }},
      {"level seconds negative", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_seconds(-1); }},
      {"level 65", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_level(65); }},
      {"more split than nodes", [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_split(901); }},
      {"level samples 2^63",
       [&](v1::StatusEvent& e) { e.mutable_levels(0)->set_samples(uint64_t(1) << 63); }},
      {"300 levels",
       [&](v1::StatusEvent& e) {
         for (int i = 0; i < 300; ++i) *e.add_levels() = e.levels(0);
       }},
  };
  for (auto& [name, spoil] : hostile) {
    v1::StatusEvent e = ok;
    spoil(e);
    INFO(name);
    CHECK_FALSE(poseforest::proto::dds::ValidateStatus(e).ok());
  }

  // The status model fills events the gate accepts, whatever it was fed: a 300-byte worker id
  // is left out of the table, a level of no measurable time does not give an infinite rate.
  StatusModel model({"job-1", 0, "shm", 2, 4, 10, 100, 20, 8, ""});
  const std::string long_id(300, 'x');
  for (const std::string& id : {std::string("w-a"), long_id}) {
    v1::StatusEvent j;
    j.set_kind(v1::STATUS_KIND_WORKER_JOINED);
    j.set_worker_id(id);
    model.OnStatus(j);
    model.OnWorkerAssigned(id, 0, 5);
  }
  model.OnLevelStart(0, 0, 1, 1000);
  v1::Heartbeat beat = hb;
  beat.set_evaluations(777);
  beat.set_evaluations_per_s(3e6);
  model.OnWorkerHeartbeat("w-a", beat);
  model.OnWorkerHeartbeat("unknown-worker", beat);  // never joined: ignored
  DistLevelStats st;
  st.frontier_nodes = 1;
  st.split_nodes = 1;
  st.samples = 1000;
  st.evaluations = 20000;
  st.level_seconds = 0;  // too fast to measure
  model.OnLevelDone(st);
  st.level = 1;
  st.level_seconds = 0.5;
  model.OnLevelDone(st);
  model.OnLevelStart(0, 2, 4, 1000);
  model.OnNodesDecided(1, 4);
  v1::StatusEvent filled;
  filled.set_kind(v1::STATUS_KIND_PROGRESS);
  model.FillStatus(&filled);
  INFO(filled.DebugString());
  CHECK(poseforest::proto::dds::ValidateStatus(filled).ok());
  CHECK(filled.level() == 2);
  CHECK(filled.level_nodes_done() == 1);
  CHECK(filled.level_nodes_total() == 4);
  CHECK(filled.evaluations() == 40000);
  CHECK(filled.evaluations_per_s() == Approx(80000));  // 40000 evaluations over 0.5 s
  CHECK(filled.samples_per_s() == Approx(4000));
  CHECK(filled.progress() > 0);
  CHECK(filled.has_eta_s());
  REQUIRE(filled.workers_size() == 1);
  CHECK(filled.workers(0).id() == "w-a");
  CHECK(filled.workers(0).state() == v1::WORKER_STATE_TRAINING);
  CHECK(filled.workers(0).evaluations() == 777);
  CHECK(filled.workers(0).evaluations_per_s() == 3e6);
  CHECK(filled.workers(0).frames() == 5);
  // The levels, as in the JSON; a level of no measurable time has rate 0, not infinity.
  REQUIRE(filled.levels_size() == 2);
  CHECK(filled.levels(0).level() == 0);
  CHECK(filled.levels(0).seconds() == 0);
  CHECK(filled.levels(1).level() == 1);
  CHECK(filled.levels(1).samples() == 1000);
  CHECK(filled.levels(1).seconds() == 0.5);
  // At most the newest 64 levels; absurd figures clamped to what the gate accepts.
  {
    StatusModel many({"job-2", 0, "shm", 4, 20, 10, 100, 20, 8, ""});
    DistLevelStats l;
    l.frontier_nodes = 4;
    l.split_nodes = 2;
    l.mean_entropy = 3;
    l.mean_gain = 0.5;
    for (int i = 0; i < 84; ++i) {
      l.tree = i / 21;
      l.level = i % 21;
      if (i == 83) l.mean_gain = std::numeric_limits<double>::infinity(), l.evaluations_per_s = -4;
      many.OnLevelDone(l);
    }
    v1::StatusEvent e;
    e.set_kind(v1::STATUS_KIND_PROGRESS);
    many.FillStatus(&e);
    CHECK(poseforest::proto::dds::ValidateStatus(e).ok());
    REQUIRE(e.levels_size() == StatusModel::kMaxStatusLevels);
    CHECK(e.levels(0).tree() == 0);  // level 20 of tree 0 = the 21st of 84: 84 - 64 = 20 left out
    CHECK(e.levels(0).level() == 20);
    CHECK(e.levels(63).tree() == 3);
    CHECK(e.levels(63).level() == 20);
    CHECK(e.levels(63).gain() == 0);
    CHECK(e.levels(63).evaluations_per_s() == 0);
    CHECK(e.levels(62).gain() == 0.5);
  }
  // A worker not admitted (another build, or it refused the job): listed as refused.
  v1::StatusEvent refused;
  refused.set_kind(v1::STATUS_KIND_WORKER_REFUSED);
  refused.set_worker_id("w-b");
  refused.set_message("refused the job: job-1: mocap file missing");
  model.OnStatus(refused);
  v1::StatusEvent with_refused;
  with_refused.set_kind(v1::STATUS_KIND_PROGRESS);
  model.FillStatus(&with_refused);
  CHECK(poseforest::proto::dds::ValidateStatus(with_refused).ok());
  REQUIRE(with_refused.workers_size() == 2);
  CHECK(with_refused.workers(1).id() == "w-b");
  CHECK(with_refused.workers(1).state() == v1::WORKER_STATE_REFUSED);
  // The job done: workers "done" (a refused one stays refused), no rate, ETA 0.
  v1::StatusEvent done;
  done.set_kind(v1::STATUS_KIND_JOB_DONE);
  model.OnStatus(done);
  model.FillStatus(&done);
  CHECK(poseforest::proto::dds::ValidateStatus(done).ok());
  CHECK(done.workers(0).state() == v1::WORKER_STATE_DONE);
  CHECK(done.workers(1).state() == v1::WORKER_STATE_REFUSED);
  CHECK(done.workers(0).evaluations_per_s() == 0);
  CHECK(done.eta_s() == 0);
  CHECK(done.trees_done() == 2);
}

TEST_CASE("a live job: status events carry the figures, a worker's hostile heartbeats are dropped",
          "[distributed][monitoring][integration]") {
  const std::string text = TinyJobText(1, 5);
  const Job job = ParseJob(text);
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(49);
  const std::string job_id = "mon-hb-" + std::to_string(::getpid());
  ThreadWorkers workers(2, domain, job_id);
  // A participant that speaks as worker "rogue-w" with well-formed heartbeats whose throughput
  // figures are NaN, negative or huge.
  proto::dds::NodeConfig rc;
  rc.domain_id = domain;
  rc.participant_name = "rogue";
  rc.transport = proto::dds::TransportKind::kSharedMemoryOnly;
  rc.liveliness_lease = CoordinatorOptions{}.lease;
  rc.write_topics = {proto::dds::Topic::kPresence};
  auto rogue = proto::dds::DdsNode::Create(rc);
  REQUIRE(rogue.ok());
  // A reader of the status topic, through its own gate, as `monitor --domain` reads it.
  proto::dds::NodeConfig sc;
  sc.domain_id = domain;
  sc.participant_name = "status-reader";
  sc.transport = proto::dds::TransportKind::kSharedMemoryOnly;
  sc.read_topics = {proto::dds::Topic::kStatus};
  auto reader = proto::dds::DdsNode::Create(sc);
  REQUIRE(reader.ok());
  std::atomic<bool> done{false};
  std::atomic<int> sent{0};
  std::thread rogue_thread([&] {
    proto::dds::EnvelopeStamper stamper(job_id, "rogue-w", v1::SENDER_KIND_WORKER);
    const double bad[] = {std::numeric_limits<double>::quiet_NaN(), -1.0, 1e300,
                          std::numeric_limits<double>::infinity()};
    for (int i = 0; !done; ++i) {
      v1::Envelope env;
      auto* hb = env.mutable_heartbeat();
      *hb->mutable_capacity() = poseforest::proto::dds::testing::Capacity(1);
      hb->set_evaluations_per_s(bad[i % 4]);
      (void)(*rogue)->Publish(proto::dds::Topic::kPresence, stamper.Seal(proto::dds::Topic::kPresence, env));
      ++sent;
      std::this_thread::sleep_for(20ms);
    }
  });
  std::vector<v1::StatusEvent> events;
  std::thread status_thread([&] {
    proto::dds::MessageGate gate(
        proto::dds::GateConfig{"status-reader", job_id, 16, [](const std::string&) {}});
    while (!done) {
      auto s = (*reader)->Receive(50ms);
      if (!s) continue;
      auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
      if (out.verdict == proto::dds::MessageGate::Verdict::kAccepted && out.envelope.has_status())
        events.push_back(out.envelope.status());
    }
  });
  StatusModel model({job_id, domain, "shm", 1, 5, 12, 150, 40, 12, ""});
  std::mutex log_mu;
  std::string log;
  // Held 3 s after level 2 (the tiny job would end before a heartbeat or a PROGRESS event):
  // the file is made on the training thread, before the next level looks for it.
  TempDir dir("pf-mon-hb");
  const fs::path pause = dir.path / "pause";
  std::atomic<bool> held{false};
  std::thread release([&] {
    while (!held && !done) std::this_thread::sleep_for(10ms);
    std::this_thread::sleep_for(3s);
    fs::remove(pause);
  });
  CoordinatorOptions opt;
  opt.job_id = job_id;
  opt.domain = domain;
  opt.min_workers = 2;
  opt.observer = &model;
  opt.pause_file = pause.string();
  opt.progress = [&](const DistLevelStats& st) {
    if (st.level == 2 && !held) {
      std::ofstream(pause) << "held\n";
      held = true;
    }
  };
  opt.log = [&](const std::string& l) {
    std::lock_guard<std::mutex> lock(log_mu);
    log += l + "\n";
  };
  DistCoordinator coordinator(job.config, job.params, opt);
  auto forest = coordinator.Train();
  std::this_thread::sleep_for(300ms);  // the last events reach the reader
  done = true;
  rogue_thread.join();
  status_thread.join();
  release.join();
  REQUIRE(forest.ok());
  CHECK(core::SerializeForest(*forest) == reference);
  CHECK(held);
  CHECK(sent > 0);
  CHECK(coordinator.rejected_messages() > 0);
  INFO(log);
  CHECK(log.find("dropped message from rogue-w") != std::string::npos);
  CHECK(log.find("evaluations_per_s") != std::string::npos);
  CHECK(model.Json().find("rogue-w") == std::string::npos);  // never a worker of the job
  // The events, as the monitor sees them: throughput while training, both real workers with
  // their own (heartbeat) figures, the rogue nowhere.
  REQUIRE(!events.empty());
  CHECK(events.back().kind() == v1::STATUS_KIND_JOB_DONE);
  int progress_events = 0;
  for (const v1::StatusEvent& e : events) {
    for (const v1::WorkerStatus& w : e.workers()) CHECK(w.id() != "rogue-w");
    if (e.kind() != v1::STATUS_KIND_PROGRESS) continue;
    // While held after level 2: the coordinator's figures and the workers' heartbeat figures.
    ++progress_events;
    INFO(e.DebugString());
    CHECK(e.level() == 2);
    CHECK(e.progress() > 0);
    CHECK(e.has_eta_s());
    CHECK(e.evaluations_per_s() > 0);
    CHECK(e.samples_per_s() > 0);
    CHECK(e.evaluations() > 0);
    CHECK(e.active_workers() == 2);
    REQUIRE(e.workers_size() == 2);
    for (const v1::WorkerStatus& w : e.workers()) {
      CHECK(w.state() == v1::WORKER_STATE_TRAINING);
      CHECK(w.frames() == 6);  // 12 frames over 2 workers
      CHECK(w.replies() > 0);
      CHECK(w.evaluations() > 0);
      CHECK(w.evaluations_per_s() > 0);
      CHECK(w.last_seen_s() >= 0);
      CHECK(w.last_seen_s() < 2);
    }
  }
  CHECK(progress_events >= 1);  // 3 s held: one after 2 s without other events
  const v1::StatusEvent& last = events.back();
  CHECK(last.workers_size() == 2);
  CHECK(last.trees_done() == 1);
  CHECK(last.level_nodes_done() == last.level_nodes_total());
  CHECK(last.evaluations() > 0);
  for (const v1::WorkerStatus& w : last.workers()) CHECK(w.state() == v1::WORKER_STATE_DONE);
}

// Frames rendered again for subtree tasks and task-cache evictions, per worker and
// tree, from the workers' heartbeats into /metrics (a cache that thrashes shows here).
TEST_CASE("/metrics shows each worker's subtree-task frames of the current tree", "[monitoring][unit]") {
  StatusModel model({"job-1", 0, "shm", 2, 4, 10, 100, 20, 8, ""});
  v1::StatusEvent j;
  j.set_kind(v1::STATUS_KIND_WORKER_JOINED);
  j.set_worker_id("w-a");
  model.OnStatus(j);
  model.OnWorkerAssigned("w-a", 0, 5);
  CHECK(model.Prometheus().find("poseforest_worker_task_frames_rendered") == std::string::npos);  // none yet
  v1::Heartbeat beat;
  beat.set_task_tree(2);
  beat.set_task_frames_rendered(1234);
  beat.set_task_frames_cached(5678);
  beat.set_task_cache_evictions(91);
  model.OnWorkerHeartbeat("w-a", beat);
  const std::string m = model.Prometheus();
  CHECK(m.find("# TYPE poseforest_worker_task_frames_rendered gauge") != std::string::npos);
  CHECK(m.find("poseforest_worker_task_frames_rendered{exported_job=\"job-1\",worker=\"w-a\",tree=\"2\"} 1234") != std::string::npos);
  CHECK(m.find("poseforest_worker_task_frames_cached{exported_job=\"job-1\",worker=\"w-a\",tree=\"2\"} 5678") != std::string::npos);
  CHECK(m.find("poseforest_worker_task_cache_evictions{exported_job=\"job-1\",worker=\"w-a\",tree=\"2\"} 91") != std::string::npos);
}

// One schema for status (proto/poseforest/v1/status.proto). /status.json and the event
// log parse strictly into JobStatus / JobEvent, with the key names and JSON types users have
// always read (the dashboard's script, `monitor`, their own scripts).
TEST_CASE("/status.json parses strictly into JobStatus, with the names and types users read",
          "[distributed][monitoring][unit]") {
  StatusModel model({"job-7", 3, "udp", 2, 4, 10, 100, 20, 8, "/data/forest.pff"});
  {
    const v1::JobStatus waiting = ParseStrict<v1::JobStatus>(model.Json());
    CHECK(waiting.state() == "waiting");
    CHECK(!waiting.has_eta_s());  // unknown: absent
    CHECK(waiting.levels().empty());
    CHECK(model.Json().find("\"levels\":[]") != std::string::npos);  // arrays are there, empty
  }
  v1::StatusEvent joined;
  joined.set_kind(v1::STATUS_KIND_WORKER_JOINED);
  joined.set_worker_id("w-a");
  model.OnStatus(joined);
  model.OnWorkerAssigned("w-a", 0, 30);
  model.OnLevelStart(0, 0, 1, 6000);
  v1::HistogramReply reply;
  reply.set_num_candidates(20);
  reply.add_nodes()->set_samples(6000);
  model.OnWorkerReply("w-a", 4096, reply);
  DistLevelStats level;
  level.frontier_nodes = 1;
  level.split_nodes = 1;
  level.samples = 6000;
  level.evaluations = 5000000000;  // past 2^32: still a JSON number
  level.evaluations_per_s = 1e9;
  level.mean_entropy = 3.5;
  level.mean_gain = std::numeric_limits<double>::quiet_NaN();  // printed 0, never "NaN"
  level.level_seconds = 5;
  level.workers_alive = 1;
  model.OnLevelDone(level);
  const std::string json = model.Json();
  INFO(json);
  const v1::JobStatus st = ParseStrict<v1::JobStatus>(json);
  CHECK(st.job_id() == "job-7");
  CHECK(st.state() == "training");
  CHECK(st.domain() == 3);
  CHECK(st.out() == "/data/forest.pff");
  CHECK(st.config().num_trees() == 2);
  CHECK(st.config().max_depth() == 4);
  CHECK(st.has_eta_s());
  REQUIRE(st.levels_size() == 1);
  CHECK(st.levels(0).evaluations() == 5000000000.0);
  CHECK(st.levels(0).entropy() == 3.5);
  CHECK(st.levels(0).gain() == 0);
  REQUIRE(st.workers_size() == 1);
  CHECK(st.workers(0).id() == "w-a");
  CHECK(st.workers(0).state() == "training");
  CHECK(st.workers(0).frames() == 30);
  CHECK(st.workers(0).evaluations() == 120000);
  REQUIRE(st.events_size() == 1);
  CHECK(st.events(0).event() == "WORKER_JOINED");
  CHECK(json.find("5000000000") != std::string::npos);
  CHECK(json.find("\"5000000000\"") == std::string::npos);  // not a string (uint64 would be)
  CHECK(json.find("NaN") == std::string::npos);
  // Every field the printer wrote is in the schema: printed again, the same text.
  CHECK(MessageJson(st, /*every_field=*/true) + "\n" == json);
  // The keys of the JSON before the schema (what the dashboard and scripts read), no more, no fewer.
  const pb::Struct s = ParseJson(json);
  CHECK(Keys(s) == std::set<std::string>{"job_id",
                                         "state",
                                         "message",
                                         "url",
                                         "domain",
                                         "profile",
                                         "out",
                                         "started_unix",
                                         "now_unix",
                                         "elapsed_s",
                                         "config",
                                         "tree",
                                         "level",
                                         "trees_done",
                                         "level_nodes_done",
                                         "level_nodes_total",
                                         "level_samples",
                                         "forest_nodes",
                                         "progress",
                                         "eta_s",
                                         "samples_per_s",
                                         "evaluations_per_s",
                                         "totals",
                                         "levels",
                                         "workers",
                                         "events"});
  CHECK(Keys(s.fields().at("config").struct_value()) ==
        std::set<std::string>{"num_trees", "max_depth", "images_per_tree", "pixels_per_image",
                              "candidate_features", "thresholds_per_feature"});
  CHECK(Keys(s.fields().at("totals").struct_value()) ==
        std::set<std::string>{"levels", "samples", "evaluations", "bytes_received", "bytes_sent", "retries",
                              "workers_lost", "workers_evicted", "level_seconds"});
  CHECK(Keys(List(s, "levels").values(0).struct_value()) ==
        std::set<std::string>{"tree", "level", "nodes", "split", "samples", "entropy", "gain", "evaluations",
                              "evaluations_per_s", "samples_per_s", "seconds", "elapsed_s", "workers",
                              "bytes_received", "retries"});
  CHECK(Keys(List(s, "workers").values(0).struct_value()) ==
        std::set<std::string>{"id", "state", "frames", "replies", "samples", "evaluations",
                              "evaluations_per_s", "compute_evaluations_per_s", "reported_evaluations",
                              "reported_evaluations_per_s", "bytes_received", "joined_unix", "last_seen_s"});
  CHECK(Keys(List(s, "events").values(0).struct_value()) ==
        std::set<std::string>{"unix", "event", "tree", "level", "worker", "message"});
  for (const auto& [k, v] : s.fields())
    if (k != "config" && k != "totals" && k != "levels" && k != "workers" && k != "events") {
      INFO(k);
      CHECK((v.has_number_value() || v.has_string_value()));
    }
  // Strict: unknown fields and wrong types are refused.
  v1::JobStatus bad;
  CHECK(!pb::util::JsonStringToMessage(R"({"job_id":"x","no_such_field":1})", &bad).ok());
  CHECK(!pb::util::JsonStringToMessage(R"({"tree":"zero"})", &bad).ok());
  CHECK(!pb::util::JsonStringToMessage(R"({"levels":[{"nodes":-1}]})", &bad).ok());
}

TEST_CASE("event log lines parse strictly into JobEvent, each with the keys of its event",
          "[distributed][monitoring][unit]") {
  TempDir dir("pf-mon-events");
  const fs::path path = dir.path / "events.jsonl";
  {
    auto log = EventLog::Open(path.string(), "job-\"e\"");
    REQUIRE(log.ok());
    DistLevelStats level;
    level.tree = 1;
    level.level = 2;
    level.frontier_nodes = 4;
    level.split_nodes = 3;
    level.samples = 5000000000;
    level.mean_entropy = 2.25;
    (*log)->OnLevelDone(level);
    v1::StatusEvent e;
    e.set_kind(v1::STATUS_KIND_LEVEL_DONE);
    e.set_tree(1);
    e.set_level(2);
    e.set_epoch(9);
    e.set_progress(0.5);
    e.set_active_workers(2);
    (*log)->OnStatus(e);
    (*log)->OnWorkerAssigned("w\xff", 1, 30);
    v1::JobEvent written;
    written.set_event("FOREST_WRITTEN");
    written.set_message("wrote forest.pff");
    (*log)->Write(written);
  }
  const auto lines = EventLines(path);  // each line strictly a JobEvent
  REQUIRE(lines.size() == 3);
  std::set<std::string> level_keys;
  std::istringstream names(
      "time unix job event tree level epoch progress active_workers nodes split samples evaluations "
      "evaluations_per_s mean_entropy mean_gain bytes_received seconds retries "
      // where the level's seconds went (bench/distributed's table)
      "rounds round_seconds compute_seconds queued_seconds traffic_seconds merge_seconds "
      "subtree_wait_seconds subtree_busy_seconds render_seconds subtree_tasks");
  for (std::string k; names >> k;) level_keys.insert(k);
  CHECK(Keys(lines[0]) == level_keys);
  CHECK(Str(lines[0], "event") == "LEVEL_DONE");
  CHECK(Str(lines[0], "job") == "job-\"e\"");
  CHECK(Num(lines[0], "samples") == 5000000000.0);
  CHECK(Num(lines[0], "mean_entropy") == 2.25);
  CHECK(std::regex_match(Str(lines[0], "time"), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z)")));
  CHECK(Keys(lines[1]) == std::set<std::string>{"time", "unix", "job", "event", "worker", "tree", "frames"});
  CHECK(Str(lines[1], "worker") == "w\xef\xbf\xbd");
  CHECK(Num(lines[1], "frames") == 30);
  CHECK(Keys(lines[2]) == std::set<std::string>{"time", "unix", "job", "event", "message"});
  CHECK(Str(lines[2], "event") == "FOREST_WRITTEN");
}
