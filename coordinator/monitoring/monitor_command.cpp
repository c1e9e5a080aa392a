// `poseforest monitor`: a live terminal view of a training job, read from the coordinator's
// /status.json (--url) or its status events on DDS (--domain) (docs/distributed/monitoring.md).

#include <google/protobuf/struct.pb.h>
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

#include "coordinator/monitoring/http_server.h"
#include "coordinator/monitoring/status_model.h"
#include "poseforest/v1/wire.pb.h"
#include "proto/dds/dds_node.h"
#include "proto/dds/message_gate.h"
#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"


namespace poseforest::cli {

using core::Status;
namespace pb = google::protobuf;

namespace {
const pb::Value* Field(const pb::Struct& s, const std::string& key) {
  auto it = s.fields().find(key);
  return it == s.fields().end() ? nullptr : &it->second;
}
double Num(const pb::Struct& s, const std::string& key, double fallback = NAN) {
  const pb::Value* v = Field(s, key);
  return v && v->kind_case() == pb::Value::kNumberValue ? v->number_value() : fallback;
}
std::string Str(const pb::Struct& s, const std::string& key) {
  const pb::Value* v = Field(s, key);
  return v && v->kind_case() == pb::Value::kStringValue ? v->string_value() : "";
}
const pb::Struct* Obj(const pb::Struct& s, const std::string& key) {
  const pb::Value* v = Field(s, key);
  return v && v->kind_case() == pb::Value::kStructValue ? &v->struct_value() : nullptr;
}
const pb::ListValue* List(const pb::Struct& s, const std::string& key) {
  const pb::Value* v = Field(s, key);
  return v && v->kind_case() == pb::Value::kListValue ? &v->list_value() : nullptr;
}

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
std::string LevelTable(const pb::ListValue* levels, const std::string& note) {
  std::string out = "levels (mean entropy and gain in bits)" + (note.empty() ? "" : "; " + note) + ":\n";
  char line[512];
  std::snprintf(line, sizeof line, "  %4s %5s %9s %9s %12s %12s %10s %14s %9s %7s\n", "tree", "level",
                "nodes", "split", "samples", "mean entropy", "mean gain", "evaluations/s", "seconds",
                "workers");
  out += line;
  int rows = 0;
  if (levels)
    for (const auto& l : levels->values()) {
      if (!l.has_struct_value()) continue;
      const pb::Struct& ls = l.struct_value();
      std::snprintf(line, sizeof line, "  %4.0f %5.0f %9.0f %9.0f %12.0f %12.3f %10.3f %14.0f %9.3f %7.0f\n",
                    Num(ls, "tree", 0), Num(ls, "level", 0), Num(ls, "nodes", 0), Num(ls, "split", 0),
                    Num(ls, "samples", 0), Num(ls, "entropy", 0), Num(ls, "gain", 0),
                    Num(ls, "evaluations_per_s", 0), Num(ls, "seconds", 0), Num(ls, "workers", 0));
      out += line;
      ++rows;
    }
  if (rows == 0) out += "  (no level finished yet)\n";
  return out;
}

/// The text of one snapshot; with `levels_table` the per-level table after it (`levels_note`
/// under its heading).
std::string Render(const pb::Struct& s, bool levels_table = false, const std::string& levels_note = "") {
  std::string out;
  char line[512];
  const pb::Struct* cfg = Obj(s, "config");
  const double trees = cfg ? Num(*cfg, "num_trees", 0) : 0, depth = cfg ? Num(*cfg, "max_depth", 0) : 0;
  const std::string state = Str(s, "state");
  std::snprintf(line, sizeof line, "job %s  state %s  elapsed %s  ETA %s\n", Str(s, "job_id").c_str(),
                state.c_str(), Duration(Num(s, "elapsed_s")).c_str(),
                state == "done" ? "done" : Duration(Num(s, "eta_s")).c_str());
  out += line;
  const double p = std::clamp(Num(s, "progress", 0), 0.0, 1.0);
  std::string bar(30, '.');
  for (int i = 0; i < int(std::lround(p * 30)); ++i) bar[size_t(i)] = '#';
  std::snprintf(line, sizeof line, "progress [%s] %5.1f %%  trees done %.0f of %.0f\n", bar.c_str(), p * 100,
                Num(s, "trees_done", 0), trees);
  out += line;
  std::snprintf(line, sizeof line, "tree %.0f/%.0f  level %.0f/%.0f  nodes %.0f/%.0f  forest nodes %.0f\n",
                Num(s, "tree", 0) + 1, trees, Num(s, "level", 0), depth, Num(s, "level_nodes_done", 0),
                Num(s, "level_nodes_total", 0), Num(s, "forest_nodes", 0));
  out += line;
  std::snprintf(line, sizeof line, "samples/s %s  evaluations/s %s", Si(Num(s, "samples_per_s")).c_str(),
                Si(Num(s, "evaluations_per_s")).c_str());
  out += line;
  if (const pb::Struct* t = Obj(s, "totals"))
    std::snprintf(line, sizeof line, "  (%s evaluations, %.1f MiB received, %.0f retries)\n",
                  Si(Num(*t, "evaluations", 0)).c_str(), Num(*t, "bytes_received", 0) / 1048576,
                  Num(*t, "retries", 0));
  else
    std::snprintf(line, sizeof line, "\n");
  out += line;
  if (!Str(s, "message").empty()) out += "message: " + Str(s, "message") + "\n";
  const pb::ListValue* workers = List(s, "workers");
  int alive = 0, lost = 0;
  if (workers)
    for (const auto& w : workers->values())
      if (w.has_struct_value()) {
        const std::string ws = Str(w.struct_value(), "state");
        alive += ws == "training" || ws == "joined";
        lost += ws == "lost" || ws == "evicted";
      }
  std::snprintf(line, sizeof line, "workers: %d alive, %d lost or evicted\n", alive, lost);
  out += line;
  std::snprintf(line, sizeof line, "  %-32s %-9s %7s %8s %15s %12s %10s\n", "worker", "state", "frames",
                "replies", "evaluations/s", "evaluations", "last seen");
  out += line;
  if (workers)
    for (const auto& w : workers->values()) {
      if (!w.has_struct_value()) continue;
      const pb::Struct& ws = w.struct_value();
      const double seen = Num(ws, "last_seen_s", -1);
      std::snprintf(line, sizeof line, "  %-32.32s %-9s %7.0f %8.0f %15s %12s %10s\n", Str(ws, "id").c_str(),
                    Str(ws, "state").c_str(), Num(ws, "frames", 0), Num(ws, "replies", 0),
                    Si(Num(ws, "evaluations_per_s", 0)).c_str(), Si(Num(ws, "evaluations", 0)).c_str(),
                    seen >= 0 ? (Duration(seen) + " ago").c_str() : "-");
      out += line;
    }
  if (const pb::ListValue* levels = List(s, "levels"); levels && levels->values_size() > 0) {
    const auto& l = levels->values(levels->values_size() - 1);
    if (l.has_struct_value()) {
      const pb::Struct& ls = l.struct_value();
      std::snprintf(line, sizeof line,
                    "last level: tree %.0f level %.0f, %.0f nodes (%.0f split), entropy %.3f bits, gain %.3f "
                    "bits, %.2f s\n",
                    Num(ls, "tree", 0), Num(ls, "level", 0), Num(ls, "nodes", 0), Num(ls, "split", 0),
                    Num(ls, "entropy", 0), Num(ls, "gain", 0), Num(ls, "seconds", 0));
      out += line;
    }
  }
  if (levels_table) out += LevelTable(List(s, "levels"), levels_note);
  if (const pb::ListValue* events = List(s, "events"); events && events->values_size() > 0) {
    const auto& e = events->values(events->values_size() - 1);
    if (e.has_struct_value()) {
      const pb::Struct& es = e.struct_value();
      out += "last event: " + Str(es, "event");
      if (!Str(es, "worker").empty()) out += " " + Str(es, "worker");
      if (!Str(es, "message").empty()) out += " (" + Str(es, "message") + ")";
      out += "\n";
    }
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
    default:
      return "?";
  }
}

/// A StatusEvent (checked by the gate) as the /status.json object Render() shows. `age_s`: how
/// long ago the coordinator wrote it (elapsed and ETA move on by that much).
pb::Struct StatusAsJson(const v1::StatusEvent& e, const std::string& job_id, int trees, int depth,
                        double age_s) {
  pb::Struct s;
  auto& f = *s.mutable_fields();
  auto num = [](double v) {
    pb::Value x;
    x.set_number_value(v);
    return x;
  };
  auto str = [](const std::string& v) {
    pb::Value x;
    x.set_string_value(v);
    return x;
  };
  const bool done = e.kind() == v1::STATUS_KIND_JOB_DONE, failed = e.kind() == v1::STATUS_KIND_ERROR;
  const bool live = !done && !failed;
  f["job_id"] = str(job_id);
  f["state"] = str(done ? "done" : failed ? "failed" : "training");
  if (failed) f["message"] = str(e.message());
  f["elapsed_s"] = num(e.elapsed_s() + (live ? age_s : 0));
  if (e.has_eta_s()) f["eta_s"] = num(std::max(0.0, e.eta_s() - (live ? age_s : 0)));
  f["progress"] = num(e.progress());
  pb::Value cfg;
  (*cfg.mutable_struct_value()->mutable_fields())["num_trees"] = num(trees);
  (*cfg.mutable_struct_value()->mutable_fields())["max_depth"] = num(depth);
  f["config"] = cfg;
  f["trees_done"] = num(done ? trees : e.trees_done());
  f["tree"] = num(e.tree());
  f["level"] = num(e.level());
  f["level_nodes_done"] = num(e.level_nodes_done());
  f["level_nodes_total"] = num(e.level_nodes_total());
  f["forest_nodes"] = num(double(e.forest_nodes()));
  f["samples_per_s"] = num(e.samples_per_s());
  f["evaluations_per_s"] = num(e.evaluations_per_s());
  pb::Value totals;
  auto& t = *totals.mutable_struct_value()->mutable_fields();
  t["evaluations"] = num(double(e.evaluations()));
  t["bytes_received"] = num(double(e.bytes_received()));
  t["retries"] = num(double(e.retries()));
  f["totals"] = totals;
  pb::Value workers;
  for (const v1::WorkerStatus& w : e.workers()) {
    pb::Value wv;
    auto& ws = *wv.mutable_struct_value()->mutable_fields();
    ws["id"] = str(w.id());
    ws["state"] = str(WorkerStateName(w.state()));
    ws["frames"] = num(double(w.frames()));
    ws["replies"] = num(double(w.replies()));
    ws["evaluations"] = num(double(w.evaluations()));
    ws["evaluations_per_s"] = num(w.evaluations_per_s());
    ws["last_seen_s"] = num(w.last_seen_s() >= 0 ? w.last_seen_s() + age_s : -1);
    *workers.mutable_list_value()->add_values() = wv;
  }
  workers.mutable_list_value();  // an empty list, not null
  f["workers"] = workers;
  pb::Value levels;  // the newest levels, as /status.json's "levels" entries
  for (const v1::LevelStatus& l : e.levels()) {
    pb::Value lv;
    auto& ls = *lv.mutable_struct_value()->mutable_fields();
    ls["tree"] = num(l.tree());
    ls["level"] = num(l.level());
    ls["nodes"] = num(double(l.nodes()));
    ls["split"] = num(double(l.split()));
    ls["samples"] = num(double(l.samples()));
    ls["entropy"] = num(l.entropy());
    ls["gain"] = num(l.gain());
    ls["evaluations"] = num(double(l.evaluations()));
    ls["evaluations_per_s"] = num(l.evaluations_per_s());
    ls["seconds"] = num(l.seconds());
    ls["workers"] = num(l.workers());
    *levels.mutable_list_value()->add_values() = lv;
  }
  levels.mutable_list_value();
  f["levels"] = levels;
  return s;
}

/// `monitor --domain D [--job ID]`: the job announcement and the status events from DDS (the
/// status topic keeps its last 64 events for late readers; the coordinator sends one at least
/// every 2 s). Every event carries the figures of the coordinator's /status.json and its newest
/// 64 levels, so the view is the one of --url (`levels`: the per-level table of those); the last
/// events are listed below it.
int MonitorDds(uint32_t domain, const dist::DdsFlags& dds_flags, std::string job_id, bool once,
               long interval_ms, long timeout_s, bool levels) {
  if (!dds_flags.resolved.empty())  // once: a name that moves later is not followed
    std::fprintf(stderr, "DDS host names resolved at start-up: %s\n", dds_flags.ResolvedText().c_str());
  dds::NodeConfig cfg;
  cfg.domain_id = domain;
  cfg.participant_name = "monitor-" + std::to_string(::getpid());
  dist::ApplyDdsFlags(dds_flags, &cfg);
  cfg.read_topics = {dds::Topic::kJob, dds::Topic::kStatus};
  auto node = dds::DdsNode::Create(cfg);
  if (!node.ok()) {
    std::fprintf(stderr, "monitor: %s\n", node.status().ToString().c_str());
    return 1;
  }
  // Hostile or garbled status events (NaN or negative rates, absurd counts) are dropped here
  // and counted; the count is shown.
  dds::MessageGate gate(dds::GateConfig{cfg.participant_name, job_id, 16, [](const std::string&) {}});
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
      const double age = std::clamp(dist::UnixSeconds() - t_last, 0.0, 5.0);
      const int rows = last.levels_size();
      out += Render(StatusAsJson(last, job_id, trees, depth, age), levels,
                    rows >= dist::StatusModel::kMaxStatusLevels
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
      if (out.verdict == dds::MessageGate::Verdict::kAccepted) {
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
          t_last = s->source_timestamp_ns > 0 ? double(s->source_timestamp_ns) * 1e-9 : dist::UnixSeconds();
          if (last.kind() != v1::STATUS_KIND_PROGRESS) {
            events.push_back(dist::StatusKindName(last.kind()) + " tree " + std::to_string(last.tree()) +
                             " level " + std::to_string(last.level()) +
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

int MonitorMain(int argc, char** argv) {
  std::set<std::string> value_options = {"url",       "http-token-file", "http-ca-file", "interval-ms",
                                         "timeout-s", "domain",          "job"};
  for (const char* o : dist::kDdsValueOptions) value_options.insert(o);  // the DDS transport flags
  Args args(value_options, {"once", "levels", "help"});
  if (Status st = args.Parse(argc, argv);
      !st.ok() || args.Has("help") || !args.positional().empty() || args.Has("url") == args.Has("domain")) {
    if (!st.ok()) std::fprintf(stderr, "monitor: %s\n", st.message().c_str());
    std::fprintf(
        stderr,
        "usage: poseforest monitor --url http[s]://HOST:PORT [--http-token-file FILE] [--http-ca-file "
        "CA.pem]\n"
        "                          [--once] [--interval-ms 1000]\n"
        "                          [--timeout-s 10] [--levels]\n"
        "       poseforest monitor --domain D [--job ID] [DDS transport flags] [--once] [--levels] ...\n"
        "  Shows a training job's live status from its coordinator (the URL the coordinator prints,\n"
        "  `--http` there): tree, level, nodes done/total, samples/s, evaluations/s, ETA, workers.\n"
        "  Refreshes every second and exits when the job is done (0) or failed (1); --once prints one\n"
        "  snapshot. Exits 1 when the coordinator cannot be reached for --timeout-s seconds.\n"
        "  --levels: add the per-level table (tree, level, nodes, split, samples, mean entropy and gain\n"
        "  in bits, evaluations/s, seconds, workers: the dashboard's Levels table), oldest first; over\n"
        "  --domain the newest 64 levels (the status event carries no more).\n"
        "  --http-token-file: the coordinator's token file (its --http-token-file), sent as\n"
        "  \"Authorization: Bearer TOKEN\"; the same checks (mode 600, one line). A wrong or missing token\n"
        "  (HTTP 401) exits 1 at once.\n"
        "  https:// (a coordinator with --http-tls-cert): the certificate must name HOST and chain to\n"
        "  --http-ca-file CA.pem (PEM; default: the system's trust store); TLS 1.2+. An untrusted\n"
        "  certificate exits 1 at once, saying why.\n"
        "  --domain: reads the job announcement and the coordinator's status events from DDS instead\n"
        "  (the same figures and worker table, no URL needed); --job picks one job of the domain.\n"
        "  DDS transport flags, as for the job's coordinator and workers (`poseforest coordinator --help`):\n"
        "  --profile shm|udp|default, --peers, --interfaces, --dds-xml FILE --dds-profile NAME,\n"
        "  --discovery-server [ID@]HOST[:PORT], --security DIR (a worker's credentials: a worker grant\n"
        "  reads the job and status topics).\n");
    return args.Has("help") ? 0 : 2;
  }
  auto interval = args.GetInt("interval-ms", 1000, 50, 3600000);
  auto timeout = args.GetInt("timeout-s", 10, 1, 86400);
  if (!interval.ok() || !timeout.ok()) {
    std::fprintf(stderr, "monitor: %s\n",
                 (!interval.ok() ? interval.status() : timeout.status()).message().c_str());
    return 2;
  }
  if ((args.Has("http-token-file") || args.Has("http-ca-file")) && args.Has("domain")) {
    std::fprintf(
        stderr,
        "monitor: --http-token-file and --http-ca-file are for --url (the coordinator's HTTP status)\n");
    return 2;
  }
  if (args.Has("domain")) {
    auto domain = args.GetInt("domain", 0, 0, 232);
    auto dds_flags = dist::ParseDdsFlags([&](const std::string& name) { return args.Get(name); });
    if (!domain.ok() || !dds_flags.ok()) {
      std::fprintf(stderr, "monitor: %s\n",
                   (!domain.ok() ? domain.status() : dds_flags.status()).message().c_str());
      return 2;
    }
    return MonitorDds(uint32_t(*domain), *dds_flags, args.GetOr("job", ""), args.Has("once"), *interval,
                      *timeout, args.Has("levels"));
  }
  std::string token;
  if (args.Has("http-token-file")) {
    auto t = dist::ReadHttpTokenFile(*args.Get("http-token-file"));
    if (!t.ok()) {
      std::fprintf(stderr, "monitor: %s\n", t.status().message().c_str());
      return 2;
    }
    token = *t;
  }
  std::string url = *args.Get("url");
  while (!url.empty() && url.back() == '/') url.pop_back();
  const std::string ca_file = args.GetOr("http-ca-file", "");
  if (!ca_file.empty()) {
    if (url.rfind("https://", 0) != 0) {
      std::fprintf(stderr, "monitor: --http-ca-file is for https:// URLs (%s)\n", url.c_str());
      return 2;
    }
    if (Status ca = dist::CheckHttpCaFile(ca_file); !ca.ok()) {
      std::fprintf(stderr, "monitor: %s\n", ca.message().c_str());
      return 2;
    }
  }
  const bool once = args.Has("once");
  const bool tty = ::isatty(1) && !once;
  auto last_ok = std::chrono::steady_clock::now();
  std::string last_state;
  for (;;) {
    auto body = dist::HttpGet(url + "/status.json", std::chrono::milliseconds(5000), token, ca_file);
    pb::Struct status;
    Status st = body.ok() ? Status::Ok() : body.status();
    if (st.ok()) {
      pb::util::JsonParseOptions po;
      po.ignore_unknown_fields = true;
      if (!pb::util::JsonStringToMessage(*body, &status, po).ok())
        st = Status(core::ErrorCode::kDataLoss, url + "/status.json: not a JSON object");
    }
    if (!st.ok()) {
      // InvalidArgument: a bad URL, HTTP 401, a certificate not trusted: retrying will not help.
      if (once || st.code() == core::ErrorCode::kInvalidArgument) {
        std::fprintf(stderr, "monitor: %s\n", st.message().c_str());
        return 1;
      }
      if (std::chrono::steady_clock::now() - last_ok > std::chrono::seconds(*timeout)) {
        std::fprintf(stderr, "monitor: %s (for %ld s; last state: %s)\n", st.message().c_str(), *timeout,
                     last_state.empty() ? "never reached" : last_state.c_str());
        return 1;
      }
    } else {
      last_ok = std::chrono::steady_clock::now();
      last_state = Str(status, "state");
      const std::string text = Render(status, args.Has("levels"));
      if (tty) std::fputs("\033[H\033[2J", stdout);
      std::fputs(text.c_str(), stdout);
      if (!tty && !once) std::fputs("\n", stdout);
      std::fflush(stdout);
      if (once) return 0;
      if (last_state == "done") return 0;
      if (last_state == "failed") return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(*interval));
  }
}

}  // namespace poseforest::cli
