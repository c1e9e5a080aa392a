// `poseforest coordinator` (and `train --local-workers N`, which starts N worker processes of
// this program): a thin wrapper around DistCoordinator (docs/distributed/service.md).

#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "apps/commands/job_dds.h"
#include "coordinator/checkpoint_export.h"
#include "coordinator/dist_coordinator.h"
#include "coordinator/monitoring/coordinator_monitoring.h"
#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/node_config.h"
#include "proto/http/http_server.h"
#include "runtime/core/forest_format.h"

extern char** environ;

namespace poseforest::apps::commands {

using core::Status;

namespace {

std::string Human(double bytes) {
  char buf[32];
  if (bytes >= 1 << 20)
    std::snprintf(buf, sizeof buf, "%.1f MiB", bytes / (1 << 20));
  else
    std::snprintf(buf, sizeof buf, "%.1f KiB", bytes / 1024);
  return buf;
}

/// Worker processes started by --local-workers; killed (TERM, then KILL) at the end.
struct LocalWorkers {
  std::vector<pid_t> pids;
  ~LocalWorkers() { StopAll(); }
  bool Start(int n, const std::vector<std::string>& args) {
    std::string self;
    std::error_code ec;
    self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
    if (ec) return false;
    for (int i = 0; i < n; ++i) {
      std::vector<std::string> argv = {self, "worker"};
      argv.insert(argv.end(), args.begin(), args.end());
      // The worker exits with this process; --parent-pid lets it tell "my parent is gone" from
      // "my parent is pid 1" (the coordinator as a container's entrypoint).
      argv.push_back("--exit-with-parent");
      argv.push_back("--parent-pid");
      argv.push_back(std::to_string(::getpid()));
      argv.push_back("--id");
      argv.push_back("local-worker-" + std::to_string(::getpid()) + "-" + std::to_string(i));
      std::vector<char*> c;
      for (auto& a : argv) c.push_back(a.data());
      c.push_back(nullptr);
      pid_t pid = -1;
      if (::posix_spawn(&pid, self.c_str(), nullptr, nullptr, c.data(), environ) != 0) return false;
      pids.push_back(pid);
    }
    return true;
  }
  void StopAll() {
    for (pid_t p : pids) ::kill(p, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
    for (pid_t p : pids) {
      int status = 0;
      while (::waitpid(p, &status, WNOHANG) == 0) {
        if (std::chrono::steady_clock::now() > deadline) {
          ::kill(p, SIGKILL);
          ::waitpid(p, &status, 0);
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    }
    pids.clear();
  }
};
}  // namespace

int CoordinatorMain(int argc, char** argv) {
  Args args(WithDdsOptions({"out", "local-workers", "domain", "checkpoint", "status-file", "min-workers",
                             "min-workers-per-tree", "pause-file", "job-id", "worker-threads", "worker-wait-s",
                             "http", "http-token-file", "http-tls-cert", "http-tls-key", "event-log",
                             "http-linger-s", "worker-security"}),
            {"resume", "check-config", "help"});
  if (Status st = args.Parse(argc, argv);
      !st.ok() || args.Has("help") || args.positional().size() != 1 || !args.Has("out")) {
    if (!st.ok()) std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
    std::fprintf(
        stderr,
        "usage: poseforest coordinator JOB.textproto --out FOREST.pff [--local-workers N] [--domain D]\n"
        "         [DDS transport flags, below] [--checkpoint DIR] [--resume] [--status-file F]\n"
        "         [--min-workers N] [--job-id ID] [--worker-threads N] [--worker-wait-s S]\n"
        "         [--http HOST:PORT|off] [--event-log F.jsonl] [--http-linger-s S]   (status, metrics and\n"
        "          dashboard over HTTP, default 127.0.0.1:0 = a free loopback port, printed; the final\n"
        "          state stays up S s (default 2) if anyone read it; JSON-lines event log)\n"
        "         [--http-token-file FILE]   (every HTTP request needs \"Authorization: Bearer TOKEN\";\n"
        "          the dashboard: open /?token=TOKEN; FILE: one line, mode 600 (or root-owned 440);\n"
        "          /healthz stays open, for probes)\n"
        "         [--http-tls-cert CERT.pem --http-tls-key KEY.pem]   (HTTPS only, TLS 1.2+: the\n"
        "          certificate chain and its unencrypted key, mode 600 (or root-owned 440); both or neither)\n"
        "         [--worker-security DIR]   (--local-workers with --security: the workers' credentials)\n"
        "         [--check-config]   (parse the flags, load the job, the XML profile and the security\n"
        "          files, print what would run and exit 0, without joining DDS; 2 on a bad setting)\n"
        "         [--min-workers-per-tree N0,N1,...]   (tests: before tree t, wait for Nt live workers)\n"
        "         [--pause-file F]   (while F exists, hold between levels; remove it to go on)\n"
        "%s",
        kDdsUsage);
    return args.Has("help") ? 0 : 2;
  }
  const std::string job_path = args.positional()[0];
  // Workers receive the config with its paths resolved here.
  auto config = ReadJobConfig(job_path);
  if (!config.ok()) {
    const bool unreadable = config.status().code() == core::ErrorCode::kIo;
    std::fprintf(stderr, "coordinator: %s\n",
                 (unreadable ? config.status().message() : config.status().ToString()).c_str());
    return unreadable ? 1 : 2;
  }
  auto params = engine::ParamsFromConfig(*config, job_path);
  if (!params.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", params.status().ToString().c_str());
    return 2;
  }
  auto job_dds = JobDdsDefaults(*config, job_path, args);
  if (!job_dds.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", job_dds.status().message().c_str());
    return 2;
  }
  auto local = args.GetInt("local-workers", 0, 0, 256);
  auto domain = args.GetInt("domain", job_dds->values.count("domain") ? std::stol(job_dds->values["domain"]) : 0, 0, 232);
  auto min_workers = args.GetInt("min-workers", -1, 1, 4096);
  auto worker_threads = args.GetInt("worker-threads", 1, 1, 1024);
  auto wait_s = args.GetInt("worker-wait-s", 60, 1, 86400);
  auto dds_flags =
      proto::dds::ParseDdsFlags([&](const std::string& name) { return job_dds->Get(args, name); });
  if (!local.ok() || !domain.ok() || !min_workers.ok() || !worker_threads.ok() || !wait_s.ok() ||
      !dds_flags.ok()) {
    for (const Status& st :
         {local.ok() ? Status::Ok() : local.status(), domain.ok() ? Status::Ok() : domain.status(),
          min_workers.ok() ? Status::Ok() : min_workers.status(),
          worker_threads.ok() ? Status::Ok() : worker_threads.status(),
          wait_s.ok() ? Status::Ok() : wait_s.status(),
          dds_flags.ok() ? Status::Ok() : job_dds->Explain(dds_flags.status())})
      if (!st.ok()) std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
    return 2;
  }
  // Local workers under DDS-Security need credentials of their own (a worker grant).
  std::string worker_security;
  if (args.Has("worker-security")) {
    if (*local == 0 || !dds_flags->extras.security.enabled()) {
      std::fprintf(stderr, "coordinator: --worker-security is for --local-workers N with --security DIR\n");
      return 2;
    }
    auto files = proto::dds::SecurityFilesIn(*args.Get("worker-security"), "--worker-security");
    if (!files.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", files.status().message().c_str());
      return 2;
    }
    worker_security = std::filesystem::path(files->identity_certificate).parent_path().string();
  } else if (*local > 0 && dds_flags->extras.security.enabled()) {
    std::fprintf(stderr,
                 "coordinator: --local-workers with --security needs --worker-security DIR (the workers' "
                 "credentials, e.g. make-test-ca.sh OUT coordinator worker-1 -> --security OUT/coordinator "
                 "--worker-security OUT/worker-1)\n");
    return 2;
  }
  coordinator::CoordinatorOptions opt;
  opt.udp_peers = dds_flags->peers;
  opt.udp_interfaces = dds_flags->interfaces;
  opt.transport_extras = dds_flags->extras;
  opt.job_id = args.GetOr("job-id", "");
  if (opt.job_id.empty()) opt.job_id = engine::DefaultJobId(*config);
  opt.domain = uint32_t(*domain);
  opt.transport = dds_flags->transport;
  opt.min_workers = *min_workers > 0 ? int(*min_workers) : std::max(1, int(*local));
  opt.worker_wait = std::chrono::seconds(*wait_s);
  if (args.Has("min-workers-per-tree")) {
    const std::string list = *args.Get("min-workers-per-tree");
    std::stringstream items(list);
    for (std::string item; std::getline(items, item, ',');) {
      int n = -1;
      const auto [end, ec] = std::from_chars(item.data(), item.data() + item.size(), n);
      if (ec != std::errc() || end != item.data() + item.size() || n < 0 || n > 4096) {
        std::fprintf(stderr, "coordinator: --min-workers-per-tree: \"%s\" is not a list of counts 0..4096\n",
                     list.c_str());
        return 2;
      }
      opt.min_workers_per_tree.push_back(n);
    }
  }
  opt.checkpoint_dir = args.GetOr("checkpoint", "");
  opt.resume = args.Has("resume");
  opt.pause_file = args.GetOr("pause-file", "");
  if (opt.resume && !opt.checkpoint_dir.empty()) {
    // Check every field of the checkpoint before the coordinator replays it: a corrupt file is
    // an error naming it, never a crash (the same checks as `poseforest export`).
    const auto ckpt = std::filesystem::path(opt.checkpoint_dir) / "checkpoint.pb";
    if (std::filesystem::exists(ckpt)) {
      auto checked =
          coordinator::ForestFromCheckpoint(ckpt.string(), coordinator::PartialTree::kFinishAsLeaves);
      if (!checked.ok() && checked.status().code() != core::ErrorCode::kInvalidArgument) {
        std::fprintf(stderr, "coordinator: cannot resume: %s\n", checked.status().message().c_str());
        return 1;
      }
    }
  }
  if (args.Has("check-config")) {
    // Everything a start would read, without joining DDS or opening the HTTP port.
    const std::filesystem::path out_dir = std::filesystem::absolute(*args.Get("out")).parent_path();
    if (std::error_code ec; !std::filesystem::is_directory(out_dir, ec)) {
      std::fprintf(stderr, "coordinator: --out %s: folder %s does not exist\n", args.Get("out")->c_str(),
                   out_dir.c_str());
      return 2;
    }
    if (const std::string http = args.GetOr("http", coordinator::monitoring::kDefaultHttp); http != "off") {
      proto::http::HttpServerOptions http_opt;
      if (Status st = proto::http::ParseHttpAddress(http, &http_opt); !st.ok()) {
        std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
        return 2;
      }
    }
    if (args.Has("http-token-file")) {
      if (auto token = proto::http::ReadHttpTokenFile(*args.Get("http-token-file")); !token.ok()) {
        std::fprintf(stderr, "coordinator: %s\n", token.status().message().c_str());
        return 2;
      }
    }
    if (args.Has("http-tls-cert") || args.Has("http-tls-key")) {
      if (Status st =
              proto::http::CheckHttpTlsFiles(args.GetOr("http-tls-cert", ""), args.GetOr("http-tls-key", ""));
          !st.ok()) {
        std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
        return 2;
      }
    }
    if (args.Has("event-log")) {
      const auto log_dir = std::filesystem::absolute(*args.Get("event-log")).parent_path();
      if (std::error_code ec; !std::filesystem::is_directory(log_dir, ec)) {
        std::fprintf(stderr, "coordinator: --event-log %s: folder %s does not exist\n",
                     args.Get("event-log")->c_str(), log_dir.c_str());
        return 2;
      }
    }
    std::printf("coordinator config ok: job %s (%s), %d trees of depth %d, %d images per tree; DDS domain %u, %s; "
                "%d local workers%s; writes %s%s%s\n",
                opt.job_id.c_str(), job_path.c_str(), params->num_trees, params->max_depth, params->images_per_tree,
                opt.domain, dds_flags->Describe().c_str(), int(*local),
                worker_security.empty() ? "" : (" with credentials of " + worker_security).c_str(),
                args.Get("out")->c_str(), opt.checkpoint_dir.empty() ? "" : ", checkpoints in ",
                opt.checkpoint_dir.c_str());
    return 0;
  }
  if (!dds_flags->resolved.empty()) {  // resolved once: a name that moves later is not followed
    std::printf("DDS host names resolved at start-up: %s\n", dds_flags->ResolvedText().c_str());
    std::fflush(stdout);
  }
  const std::string status_file = args.GetOr("status-file", "");
  opt.progress = [&](const coordinator::DistLevelStats& s) {
    char line[512];
    std::snprintf(
        line, sizeof line,
        "tree %d level %d: %zu nodes (%zu split), %llu samples, %.3g evaluations/s, %d workers alive, "
        "%s received, %s sent, merge %.1f ms, level %.2f s%s%s",
        s.tree, s.level, s.frontier_nodes, s.split_nodes, (unsigned long long)s.samples, s.evaluations_per_s,
        s.workers_alive, Human(double(s.bytes_received)).c_str(), Human(double(s.bytes_sent)).c_str(),
        s.merge_seconds * 1e3, s.level_seconds,
        s.subtree_tasks ? (", " + std::to_string(s.subtree_tasks) + " subtrees handed off").c_str() : "",
        s.retries ? (", " + std::to_string(s.retries) + " retries").c_str() : "");
    std::printf("%s\n", line);
    // Where the level's time went (docs/distributed/service.md, "Where the time goes").
    const double other = s.level_seconds - s.round_seconds - s.merge_seconds - s.subtree_wait_seconds;
    if (s.rounds > 0 || s.subtree_wait_seconds > 0 || s.subtree_busy_seconds > 0)  // else: decided by subtrees
      std::printf("  time: %d rounds %.2f s (worker computing %.2f s, busy before it %.2f s, traffic %.2f s), merge "
                "%.2f s, waiting for subtrees %.2f s, other %.2f s; workers: subtrees %.2f s, rendering %.2f s\n",
                s.rounds, s.round_seconds, s.round_compute_seconds, s.round_queued_seconds, s.round_traffic_seconds,
                s.merge_seconds, s.subtree_wait_seconds, std::max(0.0, other), s.subtree_busy_seconds,
                s.render_seconds);
    std::fflush(stdout);
    if (!status_file.empty()) {
      const std::string j = nlohmann::ordered_json{{"tree", s.tree},
                                                   {"level", s.level},
                                                   {"nodes", s.frontier_nodes},
                                                   {"split", s.split_nodes},
                                                   {"samples", s.samples},
                                                   {"evaluations_per_s", s.evaluations_per_s},
                                                   {"workers_alive", s.workers_alive},
                                                   {"bytes_received", s.bytes_received},
                                                   {"merge_s", s.merge_seconds},
                                                   {"elapsed_s", s.elapsed_s}}
                                .dump() +
                            "\n";
      (void)core::WriteFileAtomic(
          status_file, std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(j.data()), j.size()));
    }
  };
  // Monitoring: status model, HTTP (dashboard, /status.json, /metrics), event log.
  auto linger = args.GetInt("http-linger-s", 2, 0, 3600);
  if (!linger.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", linger.status().message().c_str());
    return 2;
  }
  std::string http_token;
  if (args.Has("http-token-file")) {
    if (args.GetOr("http", coordinator::monitoring::kDefaultHttp) == "off") {
      std::fprintf(stderr, "coordinator: --http-token-file is for the HTTP status server, not --http off\n");
      return 2;
    }
    auto token = proto::http::ReadHttpTokenFile(*args.Get("http-token-file"));
    if (!token.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", token.status().message().c_str());
      return 2;
    }
    http_token = *token;
  }
  const std::string tls_cert = args.GetOr("http-tls-cert", ""), tls_key = args.GetOr("http-tls-key", "");
  if (!tls_cert.empty() || !tls_key.empty()) {
    if (args.GetOr("http", coordinator::monitoring::kDefaultHttp) == "off") {
      std::fprintf(stderr,
                   "coordinator: --http-tls-cert/--http-tls-key are for the HTTP status server, not --http off\n");
      return 2;
    }
  }
  auto monitoring = coordinator::monitoring::CoordinatorMonitoring::Start(
      {opt.job_id, opt.domain, dds_flags->Label(), params->num_trees, params->max_depth,
       params->images_per_tree, params->pixels_per_image, params->candidate_features,
       params->thresholds_per_feature, *args.Get("out")},
      args.GetOr("http", coordinator::monitoring::kDefaultHttp), args.GetOr("event-log", ""), http_token,
      tls_cert, tls_key);
  if (!monitoring.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", monitoring.status().ToString().c_str());
    return monitoring.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;  // 1: port in use
  }
  opt.observer = (*monitoring)->observer();
  if (const std::string url = (*monitoring)->url(); !url.empty()) {
    if (http_token.empty())
      std::printf("status: %s/ (dashboard), %s/status.json, %s/metrics; poseforest monitor --url %s\n", url.c_str(),
                  url.c_str(), url.c_str(), url.c_str());
    else  // the token itself is never printed
      std::printf("status: %s/ (dashboard), %s/status.json, %s/metrics; each needs the token of --http-token-file "
                  "%s (\"Authorization: Bearer TOKEN\"; the dashboard: %s/?token=TOKEN); poseforest monitor --url "
                  "%s --http-token-file %s\n",
                  url.c_str(), url.c_str(), url.c_str(), args.Get("http-token-file")->c_str(), url.c_str(),
                  url.c_str(), args.Get("http-token-file")->c_str());
    if (!tls_cert.empty())
      std::printf("status: HTTPS only (certificate %s); a certificate from a private CA: monitor --http-ca-file "
                  "CA.pem; use a host name the certificate names\n",
                  tls_cert.c_str());
    std::fflush(stdout);
  }
  LocalWorkers workers;
  if (*local > 0) {
    // The workers' cores are theirs: merge on what is left (at least 1 thread).
    const int64_t cores = std::max<int64_t>(1, int64_t(std::thread::hardware_concurrency()));
    opt.merge_threads = int(std::max<int64_t>(1, cores - *local * *worker_threads));
    std::vector<std::string> wargs = {"--domain", std::to_string(*domain), "--job", opt.job_id, "--threads",
                                      std::to_string(*worker_threads)};
    for (const std::string& a : dds_flags->TransportArgs()) wargs.push_back(a);
    if (!worker_security.empty()) wargs.insert(wargs.end(), {"--security", worker_security});
    if (!workers.Start(int(*local), wargs)) {
      std::fprintf(stderr, "coordinator: cannot start local workers\n");
      return 1;
    }
  }
  coordinator::DistCoordinator coordinator(*config, *params, opt);
  const double t0 = proto::dds::NowSeconds();
  auto forest = coordinator.Train();
  workers.StopAll();
  if (!forest.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", forest.status().ToString().c_str());
    (*monitoring)->Finish(false, forest.status().ToString(), double(*linger));
    return 1;
  }
  const std::string out = *args.Get("out");
  if (Status st = core::SaveForest(*forest, out); !st.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", st.ToString().c_str());
    (*monitoring)->Finish(false, st.ToString(), double(*linger));
    return 1;
  }
  std::printf(
      "wrote %s: %zu trees in %.2f s, %s received, %llu messages rejected, %llu stale messages dropped, %d "
      "workers lost\n",
      out.c_str(), forest->trees.size(), proto::dds::NowSeconds() - t0,
      Human(double(coordinator.bytes_received())).c_str(),
      (unsigned long long)coordinator.rejected_messages(), (unsigned long long)coordinator.stale_messages(),
      coordinator.workers_lost());
  std::fflush(stdout);
  (*monitoring)->Finish(true, "wrote " + out, double(*linger));
  return 0;
}


}  // namespace poseforest::apps::commands
