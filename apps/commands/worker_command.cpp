// `poseforest worker`: a worker process of the training service (worker/dist_worker.h).
#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/dds_options.h"
#include "apps/commands/job_dds.h"
#include "engine/job_spec.h"
#include "proto/dds/build_id.h"
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

namespace {

class WorkerCommand final : public Command {
 public:
  WorkerCommand();
  int Run() override;

 private:
  int CheckHttp(proto::http::HttpServerOptions* http_opt) const;

  std::optional<long> domain_;
  int threads_ = 1;
  long task_cache_mb_ = 0;
  std::optional<long> parent_pid_;
  std::string job_, job_file_, id_, http_ = "off", token_file_, tls_cert_, tls_key_;
  bool stay_ = false, exit_with_parent_ = false, check_config_ = false;
  proto::dds::DdsSettings dds_;
};

WorkerCommand::WorkerCommand() : Command("worker", "") {
  app_.add_option("--domain", domain_, "DDS domain (default: the job file's, else 0)")
      ->type_name("D")
      ->check(IntIn(0, 232));
  app_.add_option("--threads", threads_, "threads")->type_name("N")->check(IntIn(1, 1024));
  app_.add_option("--job", job_, "serve only the job with this id")->type_name("ID")->check(NonEmptyName());
  app_.add_option("--job-file", job_file_,
                  "the job's id (unless --job) and its dds section: domain and transport, used where\n"
                  "the command line gives none; the coordinator's job file, at the same path when the\n"
                  "job names relative files")
      ->type_name("JOB.textproto");
  app_.add_option("--id", id_, "the sender id, unique per job (default worker-HOST-PID-RANDOM)")
      ->type_name("NAME")
      ->check(NonEmptyName());
  app_.add_flag("--stay", stay_, "keep serving jobs after one is done");
  app_.add_flag("--exit-with-parent", exit_with_parent_,
                "exit when the process that started this one exits (`coordinator --local-workers`\n"
                "passes it with --parent-pid)");
  app_.add_option("--parent-pid", parent_pid_, "with --exit-with-parent: that process, checked at start")
      ->type_name("PID")
      ->check(IntIn(0, std::numeric_limits<int32_t>::max()));
  app_.add_option("--task-cache-mb", task_cache_mb_,
                  "frames of other shards kept between subtree tasks of a tree, least recently used\n"
                  "dropped first; 0 = auto: every frame of a tree, at most an eighth of this machine's\n"
                  "memory, at least 256 MiB")
      ->type_name("M")
      ->check(IntIn(0, 1 << 20));
  app_.add_option("--http", http_,
                  "the worker's own Prometheus metrics at /metrics, and /healthz; e.g. 127.0.0.1:9101,\n"
                  ":9101 = every interface, port 0 = a free one; the URL is printed at start")
      ->type_name("HOST:PORT|off");
  app_.add_option("--http-token-file", token_file_,
                  "every request but /healthz needs \"Authorization: Bearer TOKEN\"; FILE: one line,\n"
                  "mode 600 (or root-owned 440)")
      ->type_name("FILE");
  app_.add_option("--http-tls-cert", tls_cert_,
                  "HTTPS only, TLS 1.2+: the certificate chain (with --http-tls-key, its unencrypted key)")
      ->type_name("CERT.pem");
  app_.add_option("--http-tls-key", tls_key_, "the key of --http-tls-cert")->type_name("KEY.pem");
  app_.add_flag("--check-config", check_config_,
                "parse the flags, load the XML profile, the security files and the HTTP token and TLS\n"
                "files, print what would run and exit 0, without joining DDS or opening the HTTP port;\n"
                "2 on a bad setting");
  AddDdsOptions(app_, &dds_);
}

/// --http: the worker's own /metrics (off by default); its token and TLS files, checked here.
int WorkerCommand::CheckHttp(proto::http::HttpServerOptions* http_opt) const {
  if (http_ != "off") {
    if (Status st = proto::http::ParseHttpAddress(http_, http_opt); !st.ok()) {
      std::fprintf(stderr, "worker: %s\n", st.message().c_str());
      return 2;
    }
  } else if (Given("http-token-file") || Given("http-tls-cert") || Given("http-tls-key")) {
    std::fprintf(stderr,
                 "worker: --http-token-file/--http-tls-cert/--http-tls-key are for the metrics server: give "
                 "--http HOST:PORT\n");
    return 2;
  }
  if (Given("http-token-file")) {
    auto token = proto::http::ReadHttpTokenFile(token_file_);
    if (!token.ok()) {
      std::fprintf(stderr, "worker: %s\n", token.status().message().c_str());
      return 2;
    }
    http_opt->bearer_token = std::move(*token);
  }
  http_opt->tls_cert_file = tls_cert_;
  http_opt->tls_key_file = tls_key_;
  if (!http_opt->tls_cert_file.empty() || !http_opt->tls_key_file.empty()) {
    if (Status st = proto::http::CheckHttpTlsFiles(http_opt->tls_cert_file, http_opt->tls_key_file); !st.ok()) {
      std::fprintf(stderr, "worker: %s\n", st.message().c_str());
      return 2;
    }
  }
  return 0;
}

int WorkerCommand::Run() {
  // --job-file: the job id and the job's DDS settings (its dds section) from the coordinator's job.
  JobDds job_dds;
  job_dds.settings = dds_;
  std::string job_id = job_;
  if (!job_file_.empty()) {
    const std::string& job_path = job_file_;
    auto config = ReadJobConfig(job_path);  // resolved as the coordinator does: the same job id
    if (!config.ok()) {
      std::fprintf(stderr, "worker: --job-file: %s\n",
                   (config.status().code() == core::ErrorCode::kIo ? config.status().message()
                                                                   : config.status().ToString())
                       .c_str());
      return 2;
    }
    auto defaults = JobDdsDefaults(*config, job_path, dds_, domain_.has_value());
    if (!defaults.ok()) {
      std::fprintf(stderr, "worker: %s\n", defaults.status().message().c_str());
      return 2;
    }
    job_dds = std::move(*defaults);
    if (job_id.empty()) job_id = engine::DefaultJobId(*config);
  }
  const long domain = domain_ ? *domain_ : job_dds.domain.value_or(0);
  auto dds_flags = proto::dds::CheckDdsSettings(job_dds.settings);
  if (!dds_flags.ok()) {
    std::fprintf(stderr, "worker: %s\n", job_dds.Explain(dds_flags.status()).message().c_str());
    return 2;
  }
  proto::http::HttpServerOptions http_opt;
  if (int rc = CheckHttp(&http_opt); rc != 0) return rc;
  const std::string metrics_text =
      http_ == "off" ? "metrics off"
                     : std::string("metrics on ") + (http_opt.tls_cert_file.empty() ? "http" : "https") +
                           "://" + http_opt.address + ":" + std::to_string(http_opt.port) + "/metrics" +
                           (http_opt.port == 0 ? " (port 0: a free one, printed at start)" : "") +
                           (http_opt.bearer_token.empty() ? "" : " with a bearer token");
  if (check_config_) {
    std::printf("worker config ok: id %s, job %s, %d threads; DDS domain %ld, %s; %s; build \"%s\"\n",
                (id_.empty() ? "(worker-HOST-PID-RANDOM)" : id_).c_str(),
                job_id.empty() ? "(any)" : job_id.c_str(), threads_, domain, dds_flags->Describe().c_str(),
                metrics_text.c_str(), proto::dds::BuildId().c_str());
    return 0;
  }
  if (!dds_flags->resolved.empty())  // resolved once: a name that moves later is not followed
    std::fprintf(stderr, "DDS host names resolved at start-up: %s\n", dds_flags->ResolvedText().c_str());
  worker::WorkerOptions opt;
  opt.udp_peers = dds_flags->peers;
  opt.udp_interfaces = dds_flags->interfaces;
  opt.transport_extras = dds_flags->extras;
  opt.worker_id = id_;
  if (opt.worker_id.empty()) opt.worker_id = proto::dds::DefaultWorkerId();  // worker-HOST-PID-RANDOM
  opt.domain = uint32_t(domain);
  opt.transport = dds_flags->transport;
  opt.threads = threads_;
  opt.task_cache_bytes = uint64_t(task_cache_mb_) << 20;
  opt.job_id = job_id;
  opt.exit_when_done = !stay_;
  worker::DistWorker worker(opt);
  g_worker = &worker;
  struct sigaction sa = {};
  sa.sa_handler = OnWorkerSignal;
  ::sigaction(SIGTERM, &sa, nullptr);
  ::sigaction(SIGINT, &sa, nullptr);
  // Started by `coordinator --local-workers`: go when the coordinator goes, even on SIGKILL.
  if (exit_with_parent_) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    // The parent may have gone before prctl: then this process was re-parented. Without
    // --parent-pid, pid 1 stands for "re-parented" (wrong when the parent is pid 1 itself, as a
    // coordinator that is a container's entrypoint; it passes --parent-pid).
    const pid_t expected = parent_pid_.value_or(0) > 0 ? pid_t(*parent_pid_) : pid_t(0);
    if (expected > 0 ? ::getppid() != expected : ::getppid() == 1) {
      std::fprintf(stderr, "worker: the process that started it (%s) is gone; exiting\n",
                   expected > 0 ? ("pid " + std::to_string(expected)).c_str() : "its parent");
      return 0;
    }
  }
  // After `worker`: the server (its handler reads the worker) stops first.
  std::unique_ptr<proto::http::HttpServer> metrics;
  if (http_ != "off") {
    http_opt.log = [](const std::string& line) {
      std::fprintf(stderr, "worker: %s\n", line.c_str());
      std::fflush(stderr);
    };
    for (const std::string& w :
         proto::http::HttpExposureWarnings(http_opt, http_, "the worker's metrics", "the metrics"))
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

}  // namespace

std::unique_ptr<Command> MakeWorkerCommand() { return std::make_unique<WorkerCommand>(); }

}  // namespace poseforest::apps::commands
