// `poseforest monitor`: a live terminal view of a training job, read from the coordinator's
// /status.json (--url) or its status events on DDS (--domain) (docs/distributed/monitoring.md).

#include <google/protobuf/util/json_util.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <map>
#include <set>
#include <string>
#include <thread>

#include "apps/commands/cli.h"
#include "apps/commands/dds_options.h"
#include "apps/commands/commands.h"
#include "coordinator/monitoring/status_model.h"
#include "poseforest/v1/status.pb.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "proto/http/http_server.h"

namespace poseforest::apps::commands {

using core::Status;
namespace pb = google::protobuf;

namespace {
std::string Si(double v) {
  if (!std::isfinite(v)) return "-";
  char buf[32];
  const double a = std::fabs(v);
  if (a >= 1e9)
    std::snprintf(buf, sizeof buf, "%.2f G", v / 1e9);
  else if (a >= 1e6)
    std::snprintf(buf, sizeof buf, "%.2f M", v / 1e6);
  else if (a >= 1e3)
    std::snprintf(buf, sizeof buf, "%.1f k", v / 1e3);
  else
    std::snprintf(buf, sizeof buf, "%.0f", v);
  return buf;
}

std::string Duration(double s) {
  if (!std::isfinite(s) || s < 0) return "-";
  const long t = std::lround(s);
  char buf[32];
  if (t >= 3600)
    std::snprintf(buf, sizeof buf, "%ldh %02ldm %02lds", t / 3600, (t % 3600) / 60, t % 60);
  else if (t >= 60)
    std::snprintf(buf, sizeof buf, "%ldm %02lds", t / 60, t % 60);
  else
    std::snprintf(buf, sizeof buf, "%lds", t);
  return buf;
}

/// The per-level table (`--levels`): the columns of the dashboard's "Levels" table, oldest level
/// first. `note`: said under the heading (where the rows come from), may be empty.
std::string LevelTable(const v1::JobStatus& s, const std::string& note) {
  std::string out = "levels (mean entropy and gain in bits)" + (note.empty() ? "" : "; " + note) + ":\n";
  char line[512];
  std::snprintf(line, sizeof line, "  %4s %5s %9s %9s %12s %12s %10s %14s %9s %7s\n", "tree", "level",
                "nodes", "split", "samples", "mean entropy", "mean gain", "evaluations/s", "seconds",
                "workers");
  out += line;
  for (const v1::JobStatus::Level& l : s.levels()) {
    std::snprintf(line, sizeof line, "  %4d %5d %9u %9u %12.0f %12.3f %10.3f %14.0f %9.3f %7d\n", l.tree(),
                  l.level(), l.nodes(), l.split(), l.samples(), l.entropy(), l.gain(), l.evaluations_per_s(),
                  l.seconds(), l.workers());
    out += line;
  }
  if (s.levels().empty()) out += "  (no level finished yet)\n";
  return out;
}

/// The text of one snapshot; with `levels_table` the per-level table after it (`levels_note`
/// under its heading).
std::string Render(const v1::JobStatus& s, bool levels_table = false, const std::string& levels_note = "") {
  std::string out;
  char line[512];
  const int trees = s.config().num_trees(), depth = s.config().max_depth();
  const std::string& state = s.state();
  std::snprintf(line, sizeof line, "job %s  state %s  elapsed %s  ETA %s\n", s.job_id().c_str(),
                state.c_str(), Duration(s.elapsed_s()).c_str(),
                state == "done" ? "done" : Duration(s.has_eta_s() ? s.eta_s() : NAN).c_str());
  out += line;
  const double p = std::clamp(s.progress(), 0.0, 1.0);
  std::string bar(30, '.');
  for (int i = 0; i < int(std::lround(p * 30)); ++i) bar[size_t(i)] = '#';
  std::snprintf(line, sizeof line, "progress [%s] %5.1f %%  trees done %d of %d\n", bar.c_str(), p * 100,
                s.trees_done(), trees);
  out += line;
  std::snprintf(line, sizeof line, "tree %d/%d  level %d/%d  nodes %u/%u  forest nodes %.0f\n", s.tree() + 1,
                trees, s.level(), depth, s.level_nodes_done(), s.level_nodes_total(), s.forest_nodes());
  out += line;
  std::snprintf(line, sizeof line, "samples/s %s  evaluations/s %s", Si(s.samples_per_s()).c_str(),
                Si(s.evaluations_per_s()).c_str());
  out += line;
  if (s.has_totals())
    std::snprintf(line, sizeof line, "  (%s evaluations, %.1f MiB received, %u retries)\n",
                  Si(s.totals().evaluations()).c_str(), s.totals().bytes_received() / 1048576,
                  s.totals().retries());
  else
    std::snprintf(line, sizeof line, "\n");
  out += line;
  if (!s.message().empty()) out += "message: " + s.message() + "\n";
  int alive = 0, lost = 0;
  for (const v1::JobStatus::Worker& w : s.workers()) {
    alive += w.state() == "training" || w.state() == "joined";
    lost += w.state() == "lost" || w.state() == "evicted";
  }
  std::snprintf(line, sizeof line, "workers: %d alive, %d lost or evicted\n", alive, lost);
  out += line;
  std::snprintf(line, sizeof line, "  %-32s %-9s %7s %8s %15s %12s %10s\n", "worker", "state", "frames",
                "replies", "evaluations/s", "evaluations", "last seen");
  out += line;
  for (const v1::JobStatus::Worker& w : s.workers()) {
    const double seen = w.last_seen_s();
    std::snprintf(line, sizeof line, "  %-32.32s %-9s %7.0f %8.0f %15s %12s %10s\n", w.id().c_str(),
                  w.state().c_str(), w.frames(), w.replies(), Si(w.evaluations_per_s()).c_str(),
                  Si(w.evaluations()).c_str(), seen >= 0 ? (Duration(seen) + " ago").c_str() : "-");
    out += line;
  }
  if (!s.levels().empty()) {
    const v1::JobStatus::Level& l = *s.levels().rbegin();
    std::snprintf(
        line, sizeof line,
        "last level: tree %d level %d, %u nodes (%u split), entropy %.3f bits, gain %.3f bits, %.2f s\n",
        l.tree(), l.level(), l.nodes(), l.split(), l.entropy(), l.gain(), l.seconds());
    out += line;
  }
  if (levels_table) out += LevelTable(s, levels_note);
  if (!s.events().empty()) {
    const v1::JobEvent& e = *s.events().rbegin();
    out += "last event: " + e.event();
    if (!e.worker().empty()) out += " " + e.worker();
    if (!e.message().empty()) out += " (" + e.message() + ")";
    out += "\n";
  }
  return out;
}

std::string WorkerStateName(v1::WorkerState s) {
  switch (s) {
    case v1::WORKER_STATE_JOINED:
      return "joined";
    case v1::WORKER_STATE_TRAINING:
      return "training";
    case v1::WORKER_STATE_LOST:
      return "lost";
    case v1::WORKER_STATE_EVICTED:
      return "evicted";
    case v1::WORKER_STATE_DONE:
      return "done";
    case v1::WORKER_STATE_REFUSED:
      return "refused";
    default:
      return "?";
  }
}

/// A StatusEvent (checked by the gate) as the JobStatus of /status.json that Render() shows.
/// `age_s`: how long ago the coordinator wrote it (elapsed and ETA move on by that much).
v1::JobStatus StatusAsJobStatus(const v1::StatusEvent& e, const std::string& job_id, int trees, int depth,
                                double age_s) {
  v1::JobStatus s;
  const bool done = e.kind() == v1::STATUS_KIND_JOB_DONE, failed = e.kind() == v1::STATUS_KIND_ERROR;
  const bool live = !done && !failed;
  s.set_job_id(job_id);
  s.set_state(done ? "done" : failed ? "failed" : "training");
  if (failed) s.set_message(e.message());
  s.set_elapsed_s(e.elapsed_s() + (live ? age_s : 0));
  if (e.has_eta_s()) s.set_eta_s(std::max(0.0, e.eta_s() - (live ? age_s : 0)));
  s.set_progress(e.progress());
  s.mutable_config()->set_num_trees(trees);
  s.mutable_config()->set_max_depth(depth);
  s.set_trees_done(done ? trees : int(e.trees_done()));
  s.set_tree(int(e.tree()));
  s.set_level(int(e.level()));
  s.set_level_nodes_done(e.level_nodes_done());
  s.set_level_nodes_total(e.level_nodes_total());
  s.set_forest_nodes(double(e.forest_nodes()));
  s.set_samples_per_s(e.samples_per_s());
  s.set_evaluations_per_s(e.evaluations_per_s());
  s.mutable_totals()->set_evaluations(double(e.evaluations()));
  s.mutable_totals()->set_bytes_received(double(e.bytes_received()));
  s.mutable_totals()->set_retries(uint32_t(std::min<uint64_t>(e.retries(), UINT32_MAX)));
  for (const v1::WorkerStatus& w : e.workers()) {
    v1::JobStatus::Worker* ws = s.add_workers();
    ws->set_id(w.id());
    ws->set_state(WorkerStateName(w.state()));
    ws->set_frames(double(w.frames()));
    ws->set_replies(double(w.replies()));
    ws->set_evaluations(double(w.evaluations()));
    ws->set_evaluations_per_s(w.evaluations_per_s());
    ws->set_last_seen_s(w.last_seen_s() >= 0 ? w.last_seen_s() + age_s : -1);
  }
  for (const v1::LevelStatus& l : e.levels()) {  // the newest levels
    v1::JobStatus::Level* ls = s.add_levels();
    ls->set_tree(int(l.tree()));
    ls->set_level(int(l.level()));
    ls->set_nodes(uint32_t(std::min<uint64_t>(l.nodes(), UINT32_MAX)));
    ls->set_split(uint32_t(std::min<uint64_t>(l.split(), UINT32_MAX)));
    ls->set_samples(double(l.samples()));
    ls->set_entropy(l.entropy());
    ls->set_gain(l.gain());
    ls->set_evaluations(double(l.evaluations()));
    ls->set_evaluations_per_s(l.evaluations_per_s());
    ls->set_seconds(l.seconds());
    ls->set_workers(int(l.workers()));
  }
  return s;
}

/// `monitor --domain D [--job ID]`: the job announcement and the status events from DDS (the
/// status topic keeps its last 64 events for late readers; the coordinator sends one at least
/// every 2 s). Every event carries the figures of the coordinator's /status.json and its newest
/// 64 levels, so the view is the one of --url (`levels`: the per-level table of those); the last
/// events are listed below it.
int MonitorDds(uint32_t domain, const proto::dds::DdsFlags& dds_flags, std::string job_id, bool once,
               long interval_ms, long timeout_s, bool levels) {
  if (!dds_flags.resolved.empty())  // once: a name that moves later is not followed
    std::fprintf(stderr, "DDS host names resolved at start-up: %s\n", dds_flags.ResolvedText().c_str());
  proto::dds::NodeConfig cfg;
  cfg.domain_id = domain;
  cfg.participant_name = "monitor-" + std::to_string(::getpid());
  proto::dds::ApplyDdsFlags(dds_flags, &cfg);
  cfg.read_topics = {proto::dds::Topic::kJob, proto::dds::Topic::kStatus};
  auto node = proto::dds::DdsNode::Create(cfg);
  if (!node.ok()) {
    std::fprintf(stderr, "monitor: %s\n", node.status().ToString().c_str());
    return 1;
  }
  // Hostile or garbled status events (NaN or negative rates, absurd counts) are dropped here
  // and counted; the count is shown.
  proto::dds::MessageGate gate(
      proto::dds::GateConfig{cfg.participant_name, job_id, 16, [](const std::string&) {}});
  std::string coordinator;
  int trees = 0, depth = 0;
  v1::StatusEvent last;
  bool have_status = false;
  std::deque<std::string> events;
  double t_last = 0;  // the writer's timestamp of `last`
  auto render = [&] {
    const std::string state = !have_status                              ? "waiting"
                              : last.kind() == v1::STATUS_KIND_JOB_DONE ? "done"
                              : last.kind() == v1::STATUS_KIND_ERROR    ? "failed"
                                                                        : "training";
    std::string out;
    char line[512];
    std::snprintf(line, sizeof line, "DDS domain %u  coordinator %s\n", domain,
                  coordinator.empty() ? "-" : coordinator.c_str());
    out += line;
    if (!have_status) {
      out +=
          "job " + (job_id.empty() ? std::string("-") : job_id) + "  state waiting (no status event yet)\n";
    } else {
      const double age = std::clamp(coordinator::monitoring::UnixSeconds() - t_last, 0.0, 5.0);
      const int rows = last.levels_size();
      out += Render(StatusAsJobStatus(last, job_id, trees, depth, age), levels,
                    rows >= coordinator::monitoring::StatusModel::kMaxStatusLevels
                        ? "the newest " + std::to_string(rows) + " (all of them: --url)"
                        : "");
    }
    out += "last events:\n";
    for (const std::string& e : events) out += "  " + e + "\n";
    if (gate.total_rejected() > 0) {
      std::snprintf(line, sizeof line, "(%llu malformed status messages dropped)\n",
                    static_cast<unsigned long long>(gate.total_rejected()));
      out += line;
    }
    return std::make_pair(out, state);
  };
  auto last_print = std::chrono::steady_clock::now() - std::chrono::hours(1);
  auto last_heard = std::chrono::steady_clock::now();
  const bool tty = ::isatty(1) && !once;
  for (;;) {
    auto s = (*node)->Receive(std::chrono::milliseconds(50));
    if (s) {
      auto out = gate.Check(s->topic, s->bytes, s->writer_guid);
      if (out.verdict == proto::dds::MessageGate::Verdict::kAccepted) {
        last_heard = std::chrono::steady_clock::now();
        const v1::Envelope& env = out.envelope;
        if (env.has_job() && (job_id.empty() || env.job_id() == job_id)) {
          job_id = env.job_id();
          coordinator = env.job().coordinator_id();
          gate.set_job_id(job_id);
          gate.set_coordinator_id(coordinator);
          trees = int(env.job().config().has_num_trees() ? env.job().config().num_trees() : 3);
          depth = int(env.job().config().has_max_depth() ? env.job().config().max_depth() : 20);
        } else if (env.has_status()) {
          last = env.status();
          have_status = true;
          t_last = s->source_timestamp_ns > 0 ? double(s->source_timestamp_ns) * 1e-9
                                              : coordinator::monitoring::UnixSeconds();
          if (last.kind() != v1::STATUS_KIND_PROGRESS) {
            events.push_back(coordinator::monitoring::StatusKindName(last.kind()) + " tree " +
                             std::to_string(last.tree()) + " level " + std::to_string(last.level()) +
                             (last.worker_id().empty() ? "" : " " + last.worker_id()) +
                             (last.message().empty() ? "" : " (" + last.message() + ")"));
            while (events.size() > 8) events.pop_front();
          }
        }
      }
      continue;  // drain what is there before printing
    }
    const auto now = std::chrono::steady_clock::now();
    const bool done =
        have_status && (last.kind() == v1::STATUS_KIND_JOB_DONE || last.kind() == v1::STATUS_KIND_ERROR);
    // --once: print after the history has arrived (a quiet moment after the first status) and
    // the job's announcement (trees, depth).
    if ((once && have_status && !coordinator.empty()) || done ||
        (!once && now - last_print >= std::chrono::milliseconds(interval_ms))) {
      auto [text, state] = render();
      if (tty) std::fputs("\033[H\033[2J", stdout);
      std::fputs(text.c_str(), stdout);
      if (!tty && !once) std::fputs("\n", stdout);
      std::fflush(stdout);
      last_print = now;
      if (once || state == "done") return 0;
      if (state == "failed") return 1;
    }
    if (now - last_heard > std::chrono::seconds(timeout_s)) {
      std::fprintf(stderr, "monitor: no status of %s on DDS domain %u for %ld s\n",
                   job_id.empty() ? "any job" : job_id.c_str(), domain, timeout_s);
      return 1;
    }
  }
}
}  // namespace

namespace {

class MonitorCommand final : public Command {
 public:
  MonitorCommand();
  int Run() override;

 private:
  /// --url: polls the coordinator's /status.json.
  int MonitorUrl();

  std::string url_, token_file_, ca_file_, job_;
  long interval_ms_ = 1000, timeout_s_ = 10;
  std::optional<long> domain_;
  bool once_ = false, levels_ = false;
  proto::dds::DdsSettings dds_;
};

MonitorCommand::MonitorCommand()
    : Command("monitor",
              "Shows a training job's live status from its coordinator (the URL the coordinator prints,\n"
              "`--http` there): tree, level, nodes done/total, samples/s, evaluations/s, ETA, workers.\n"
              "Refreshes every second and exits when the job is done (0) or failed (1); --once prints one\n"
              "snapshot. Exits 1 when the coordinator cannot be reached for --timeout-s seconds.\n"
              "Give --url or --domain (not both).") {
  app_.add_option("--url", url_, "the coordinator's status server")->type_name("http[s]://HOST:PORT");
  app_.add_option("--http-token-file", token_file_,
                  "the coordinator's token file (its --http-token-file), sent as \"Authorization: Bearer\n"
                  "TOKEN\"; the same checks (mode 600, one line). A wrong or missing token (HTTP 401)\n"
                  "exits 1 at once.")
      ->type_name("FILE");
  app_.add_option("--http-ca-file", ca_file_,
                  "https:// (a coordinator with --http-tls-cert): the certificate must name HOST and\n"
                  "chain to CA.pem (PEM; default: the system's trust store); TLS 1.2+. An untrusted\n"
                  "certificate exits 1 at once, saying why.")
      ->type_name("CA.pem");
  app_.add_flag("--once", once_, "print one snapshot");
  app_.add_option("--interval-ms", interval_ms_, "refresh interval")->type_name("MS")->check(IntIn(50, 3600000));
  app_.add_option("--timeout-s", timeout_s_, "give up when the coordinator cannot be reached for S seconds")
      ->type_name("S")
      ->check(IntIn(1, 86400));
  app_.add_flag("--levels", levels_,
                "add the per-level table (tree, level, nodes, split, samples, mean entropy and gain in\n"
                "bits, evaluations/s, seconds, workers: the dashboard's Levels table), oldest first;\n"
                "over --domain the newest 64 levels (the status event carries no more)");
  app_.add_option("--domain", domain_,
                  "read the job announcement and the coordinator's status events from DDS instead (the\n"
                  "same figures and worker table, no URL needed), with the DDS transport options of the\n"
                  "job's coordinator and workers (--security: a worker's credentials: a worker grant\n"
                  "reads the job and status topics)")
      ->type_name("D")
      ->check(IntIn(0, 232));
  app_.add_option("--job", job_, "--domain: the job to show, of the domain's jobs")
      ->type_name("ID")
      ->check(NonEmptyName());
  AddDdsOptions(app_, &dds_);
}

int MonitorCommand::Run() {
  if (Given("url") == Given("domain")) return UsageError("give --url or --domain (one of them)");
  if (Given("job") && Given("url"))
    return UsageError("--job is for --domain (a coordinator's --url serves its own job only)");
  if ((Given("http-token-file") || Given("http-ca-file")) && Given("domain")) {
    std::fprintf(
        stderr,
        "monitor: --http-token-file and --http-ca-file are for --url (the coordinator's HTTP status)\n");
    return 2;
  }
  if (Given("domain")) {
    auto dds_flags = proto::dds::CheckDdsSettings(dds_);
    if (!dds_flags.ok()) {
      std::fprintf(stderr, "monitor: %s\n", dds_flags.status().message().c_str());
      return 2;
    }
    return MonitorDds(uint32_t(*domain_), *dds_flags, job_, once_, interval_ms_, timeout_s_, levels_);
  }
  return MonitorUrl();
}

int MonitorCommand::MonitorUrl() {
  std::string token;
  if (Given("http-token-file")) {
    auto t = proto::http::ReadHttpTokenFile(token_file_);
    if (!t.ok()) {
      std::fprintf(stderr, "monitor: %s\n", t.status().message().c_str());
      return 2;
    }
    token = *t;
  }
  std::string url = url_;
  while (!url.empty() && url.back() == '/') url.pop_back();
  if (Status form = proto::http::CheckHttpUrl(url); !form.ok()) {
    std::fprintf(stderr, "monitor: --url %s\n", form.message().c_str());
    return 2;
  }
  const std::string& ca_file = ca_file_;
  if (!ca_file.empty()) {
    if (url.rfind("https://", 0) != 0) {
      std::fprintf(stderr, "monitor: --http-ca-file is for https:// URLs (%s)\n", url.c_str());
      return 2;
    }
    if (Status ca = proto::http::CheckHttpCaFile(ca_file); !ca.ok()) {
      std::fprintf(stderr, "monitor: %s\n", ca.message().c_str());
      return 2;
    }
  }
  const bool once = once_;
  const bool tty = ::isatty(1) && !once;
  auto last_ok = std::chrono::steady_clock::now();
  std::string last_state;
  for (;;) {
    auto body = proto::http::HttpGet(url + "/status.json", std::chrono::milliseconds(5000), token, ca_file);
    v1::JobStatus status;
    Status st = body.ok() ? Status::Ok() : body.status();
    if (st.ok()) {
      pb::util::JsonParseOptions po;
      po.ignore_unknown_fields = true;  // a newer coordinator's fields (status.proto)
      if (const auto parsed = pb::util::JsonStringToMessage(*body, &status, po); !parsed.ok())
        st = Status(core::ErrorCode::kDataLoss, url + "/status.json: not a JobStatus JSON object (" +
                                                    std::string(parsed.message()) + ")");
      // Every coordinator's status names its job, its state and its trees: an object without them
      // (`{}`) is some other server's, which retrying will not change.
      else if (status.job_id().empty() || status.state().empty() || status.config().num_trees() <= 0)
        st = Status(core::ErrorCode::kInvalidArgument,
                    url +
                        "/status.json: not a poseforest coordinator's status (no job_id, state or "
                        "config.num_trees)");
    }
    if (!st.ok()) {
      // InvalidArgument: a bad URL, HTTP 401, a certificate not trusted: retrying will not help.
      if (once || st.code() == core::ErrorCode::kInvalidArgument) {
        std::fprintf(stderr, "monitor: %s\n", st.message().c_str());
        return 1;
      }
      if (std::chrono::steady_clock::now() - last_ok > std::chrono::seconds(timeout_s_)) {
        std::fprintf(stderr, "monitor: %s (for %ld s; last state: %s)\n", st.message().c_str(), timeout_s_,
                     last_state.empty() ? "never reached" : last_state.c_str());
        return 1;
      }
    } else {
      last_ok = std::chrono::steady_clock::now();
      last_state = status.state();
      const std::string text = Render(status, levels_);
      if (tty) std::fputs("\033[H\033[2J", stdout);
      std::fputs(text.c_str(), stdout);
      if (!tty && !once) std::fputs("\n", stdout);
      std::fflush(stdout);
      if (once) return 0;
      if (last_state == "done") return 0;
      if (last_state == "failed") return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(interval_ms_));
  }
}

}  // namespace

std::unique_ptr<Command> MakeMonitorCommand() { return std::make_unique<MonitorCommand>(); }

}  // namespace poseforest::apps::commands
