// `poseforest worker`: a worker process of the training service (worker/dist_worker.h).
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "apps/commands/job_dds.h"
#include "engine/job_spec.h"
#include "proto/dds/dds_flags.h"
#include "proto/dds/node_config.h"
#include "proto/http/http_server.h"
#include "worker/dist_worker.h"
#include "worker/worker_metrics.h"

namespace poseforest::apps::commands {

using core::Status;

namespace {
std::atomic<poseforest::worker::DistWorker*> g_worker{nullptr};
void OnWorkerSignal(int) {
  if (auto* w = g_worker.load()) w->Stop();
}
}  // namespace

int WorkerMain(int argc, char** argv) {
  Args args(WithDdsOptions({"domain", "threads", "job", "job-file", "id", "task-cache-mb", "parent-pid",
                            "http", "http-token-file", "http-tls-cert", "http-tls-key"}),
            {"stay", "exit-with-parent", "check-config", "help"});
  if (Status st = args.Parse(argc, argv); !st.ok() || args.Has("help") || !args.positional().empty()) {
    if (!st.ok()) std::fprintf(stderr, "worker: %s\n", st.message().c_str());
    std::fprintf(stderr,
                 "usage: poseforest worker [--domain D] [--threads N] [--job ID] [--id NAME] [DDS transport flags]\n"
                 "         [--job-file JOB.textproto]   (the job's id (unless --job) and its dds section: domain\n"
                 "          and transport, used where the command line gives none; the coordinator's job file,\n"
                 "          at the same path when the job names relative files)\n"
                 "         (--id: the sender id, unique per job; default worker-HOST-PID-RANDOM)\n"
                 "         [--stay]   (keep serving jobs after one is done)\n"
                 "         [--exit-with-parent [--parent-pid PID]]   (exit when the process that started this\n"
                 "          one exits; PID: that process, checked at start; `coordinator --local-workers` passes both)\n"
                 "         [--task-cache-mb M]   (frames of other shards kept between subtree tasks of a\n"
                 "          tree, least recently used dropped first; default 0 = auto: every frame of a tree,\n"
                 "          at most an eighth of this machine's memory, at least 256 MiB)\n"
                 "         [--http HOST:PORT|off]   (the worker's own Prometheus metrics at /metrics, and\n"
                 "          /healthz; default off; e.g. 127.0.0.1:9101, :9101 = every interface, port 0 =\n"
                 "          a free one; the URL is printed at start)\n"
                 "         [--http-token-file FILE]   (every request but /healthz needs \"Authorization:\n"
                 "          Bearer TOKEN\"; FILE: one line, mode 600 (or root-owned 440))\n"
                 "         [--http-tls-cert CERT.pem --http-tls-key KEY.pem]   (HTTPS only, TLS 1.2+: the\n"
                 "          certificate chain and its unencrypted key; both or neither)\n"
                 "         [--check-config]   (parse the flags, load the XML profile, the security files and\n"
                 "          the HTTP token and TLS files, print what would run and exit 0, without joining DDS\n"
                 "          or opening the HTTP port; 2 on a bad setting)\n"
                 "%s",
                 kDdsUsage);
    return args.Has("help") ? 0 : 2;
  }
  // --job-file: the job id and the job's DDS settings (its dds section) from the coordinator's job.
  JobDds job_dds;
  std::string job_id = args.GetOr("job", "");
  if (args.Has("job-file")) {
    const std::string job_path = *args.Get("job-file");
    auto config = ReadJobConfig(job_path);  // resolved as the coordinator does: the same job id
    if (!config.ok()) {
      std::fprintf(stderr, "worker: --job-file: %s\n",
                   (config.status().code() == core::ErrorCode::kIo ? config.status().message()
                                                                   : config.status().ToString())
                       .c_str());
      return 2;
    }
    auto defaults = JobDdsDefaults(*config, job_path, args);
    if (!defaults.ok()) {
      std::fprintf(stderr, "worker: %s\n", defaults.status().message().c_str());
      return 2;
    }
    job_dds = std::move(*defaults);
    if (job_id.empty()) job_id = engine::DefaultJobId(*config);
  }
  auto domain = args.GetInt("domain", job_dds.values.count("domain") ? std::stol(job_dds.values["domain"]) : 0, 0, 232);
  auto threads = args.GetInt("threads", 1, 1, 1024);
  auto task_cache_mb = args.GetInt("task-cache-mb", 0, 0, 1 << 20);
  auto dds_flags =
      proto::dds::ParseDdsFlags([&](const std::string& name) { return job_dds.Get(args, name); });
  if (!domain.ok() || !threads.ok() || !task_cache_mb.ok() || !dds_flags.ok()) {
    std::fprintf(stderr, "worker: %s\n",
                 (!domain.ok()           ? domain.status()
                  : !threads.ok()        ? threads.status()
                  : !task_cache_mb.ok()  ? task_cache_mb.status()
                                         : job_dds.Explain(dds_flags.status()))
                     .message()
                     .c_str());
    return 2;
  }
  // --http: the worker's own /metrics (off by default); its token and TLS files, checked here.
  const std::string http = args.GetOr("http", "off");
  proto::http::HttpServerOptions http_opt;
  if (http != "off") {
    if (Status st = proto::http::ParseHttpAddress(http, &http_opt); !st.ok()) {
      std::fprintf(stderr, "worker: %s\n", st.message().c_str());
      return 2;
    }
  } else if (args.Has("http-token-file") || args.Has("http-tls-cert") || args.Has("http-tls-key")) {
    std::fprintf(stderr,
                 "worker: --http-token-file/--http-tls-cert/--http-tls-key are for the metrics server: give "
                 "--http HOST:PORT\n");
    return 2;
  }
  if (args.Has("http-token-file")) {
    auto token = proto::http::ReadHttpTokenFile(*args.Get("http-token-file"));
    if (!token.ok()) {
      std::fprintf(stderr, "worker: %s\n", token.status().message().c_str());
      return 2;
    }
    http_opt.bearer_token = std::move(*token);
  }
  http_opt.tls_cert_file = args.GetOr("http-tls-cert", "");
  http_opt.tls_key_file = args.GetOr("http-tls-key", "");
  if (!http_opt.tls_cert_file.empty() || !http_opt.tls_key_file.empty()) {
    if (Status st = proto::http::CheckHttpTlsFiles(http_opt.tls_cert_file, http_opt.tls_key_file); !st.ok()) {
      std::fprintf(stderr, "worker: %s\n", st.message().c_str());
      return 2;
    }
  }
  const std::string metrics_text =
      http == "off" ? "metrics off"
                    : std::string("metrics on ") + (http_opt.tls_cert_file.empty() ? "http" : "https") +
                          "://" + http_opt.address + ":" + std::to_string(http_opt.port) + "/metrics" +
                          (http_opt.port == 0 ? " (port 0: a free one, printed at start)" : "") +
                          (http_opt.bearer_token.empty() ? "" : " with a bearer token");
  if (args.Has("check-config")) {
    std::printf("worker config ok: id %s, job %s, %ld threads; DDS domain %ld, %s; %s\n",
                args.GetOr("id", "(worker-HOST-PID-RANDOM)").c_str(),
                job_id.empty() ? "(any)" : job_id.c_str(), *threads, *domain, dds_flags->Describe().c_str(),
                metrics_text.c_str());
    return 0;
  }
  if (!dds_flags->resolved.empty())  // resolved once: a name that moves later is not followed
    std::fprintf(stderr, "DDS host names resolved at start-up: %s\n", dds_flags->ResolvedText().c_str());
  worker::WorkerOptions opt;
  opt.udp_peers = dds_flags->peers;
  opt.udp_interfaces = dds_flags->interfaces;
  opt.transport_extras = dds_flags->extras;
  opt.worker_id = args.GetOr("id", "");
  if (opt.worker_id.empty()) opt.worker_id = proto::dds::DefaultWorkerId();  // worker-HOST-PID-RANDOM
  opt.domain = uint32_t(*domain);
  opt.transport = dds_flags->transport;
  opt.threads = int(*threads);
  opt.task_cache_bytes = uint64_t(*task_cache_mb) << 20;
  opt.job_id = job_id;
  opt.exit_when_done = !args.Has("stay");
  worker::DistWorker worker(opt);
  g_worker = &worker;
  struct sigaction sa = {};
  sa.sa_handler = OnWorkerSignal;
  ::sigaction(SIGTERM, &sa, nullptr);
  ::sigaction(SIGINT, &sa, nullptr);
  // Started by `coordinator --local-workers`: go when the coordinator goes, even on SIGKILL.
  if (args.Has("exit-with-parent")) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    // The parent may have gone before prctl: then this process was re-parented. Without
    // --parent-pid, pid 1 stands for "re-parented" (wrong when the parent is pid 1 itself, as a
    // coordinator that is a container's entrypoint; it passes --parent-pid).
    auto parent = args.GetInt("parent-pid", 0, 0, std::numeric_limits<int32_t>::max());
    if (!parent.ok()) {
      std::fprintf(stderr, "worker: %s\n", parent.status().message().c_str());
      return 2;
    }
    const pid_t expected = *parent > 0 ? pid_t(*parent) : pid_t(0);
    if (expected > 0 ? ::getppid() != expected : ::getppid() == 1) {
      std::fprintf(stderr, "worker: the process that started it (%s) is gone; exiting\n",
                   expected > 0 ? ("pid " + std::to_string(expected)).c_str() : "its parent");
      return 0;
    }
  }
  // After `worker`: the server (its handler reads the worker) stops first.
  std::unique_ptr<proto::http::HttpServer> metrics;
  if (http != "off") {
    http_opt.log = [](const std::string& line) {
      std::fprintf(stderr, "worker: %s\n", line.c_str());
      std::fflush(stderr);
    };
    for (const std::string& w :
         proto::http::HttpExposureWarnings(http_opt, http, "the worker's metrics", "the metrics"))
      std::fprintf(stderr, "worker: %s\n", w.c_str());
    auto server = proto::http::HttpServer::Start(http_opt, worker::WorkerMetricsHandler(&worker));
    if (!server.ok()) {
      std::fprintf(stderr, "worker: %s\n", server.status().ToString().c_str());
      return server.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;  // 1: port in use
    }
    metrics = std::move(*server);
    std::fprintf(stderr, "worker: metrics: %s/metrics%s\n", metrics->url().c_str(),
                 http_opt.bearer_token.empty() ? "" : " (with the token of --http-token-file)");
    std::fflush(stderr);
  }
  Status st = worker.Run();
  g_worker = nullptr;
  if (!st.ok()) {
    std::fprintf(stderr, "worker: %s\n", st.ToString().c_str());
    return 1;
  }
  return 0;
}

}  // namespace poseforest::apps::commands
