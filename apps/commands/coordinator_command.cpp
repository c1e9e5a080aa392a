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

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/dds_options.h"
#include "apps/commands/job_dds.h"
#include "coordinator/checkpoint_export.h"
#include "coordinator/dist_coordinator.h"
#include "coordinator/monitoring/coordinator_monitoring.h"
#include "engine/job_spec.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/build_id.h"
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

class CoordinatorCommand final : public Command {
 public:
  CoordinatorCommand();
  int Run() override;

 private:
  /// The settings checked after parsing (job file, DDS, credentials, lists) into `opt`; 0 to go on.
  std::optional<int> Prepare(coordinator::CoordinatorOptions* opt);
  /// --check-config: everything a start would read, without joining DDS or opening the HTTP port.
  int CheckConfig(const coordinator::CoordinatorOptions& opt) const;
  int CheckStatePaths() const;
  /// The token of --http-token-file, and that the HTTP files go with an HTTP server; 0 to go on.
  int CheckHttpFiles(std::string* token) const;
  /// The level's lines on stdout and the --status-file.
  void PrintLevel(const coordinator::DistLevelStats& s) const;

  std::string job_path_, out_, checkpoint_, status_file_, pause_file_, job_id_,
      http_ = coordinator::monitoring::kDefaultHttp, token_file_, tls_cert_, tls_key_, event_log_, min_workers_per_tree_;
  std::optional<std::string> worker_security_;
  int local_ = 0, worker_threads_ = 1, wait_s_ = 60, linger_s_ = 2;
  std::optional<long> domain_;
  std::optional<int> min_workers_;
  bool resume_ = false, check_config_ = false, quiet_ = false;
  proto::dds::DdsSettings dds_;

  // Filled in by Prepare.
  v1::TrainerConfig config_;
  engine::TrainParams params_;
  proto::dds::DdsFlags dds_flags_;
  long domain_used_ = 0;
  std::string worker_security_dir_;
};

CoordinatorCommand::CoordinatorCommand() : Command("coordinator", "") {
  app_.add_option("JOB.textproto", job_path_, "the job config")->required();
  app_.add_option("--out", out_, "forest file to write")->type_name("FOREST.pff")->required();
  app_.add_option("--local-workers", local_, "start N worker processes of this program on this machine")
      ->type_name("N")
      ->check(IntIn(0, 256));
  app_.add_option("--domain", domain_, "DDS domain (default: the job's dds section, else 0)")
      ->type_name("D")
      ->check(IntIn(0, 232));
  app_.add_option("--checkpoint", checkpoint_, "write a checkpoint after every level into DIR")->type_name("DIR");
  app_.add_flag("--resume", resume_, "go on from the checkpoint of --checkpoint DIR");
  // `train JOB --local-workers N --quiet` runs this command: --quiet means what it means for train.
  app_.add_flag("--quiet", quiet_,
                "no per-level progress lines (the event log, status and metrics still get every level)");
  app_.add_option("--status-file", status_file_,
                  "a JSON line with the last level's figures, rewritten each level")
      ->type_name("FILE");
  app_.add_option("--min-workers", min_workers_, "workers to wait for before the first level (default: --local-workers, at least 1)")
      ->type_name("N")
      ->check(IntIn(1, 4096));
  app_.add_option("--job-id", job_id_, "the job's id (default: from the job config)")
      ->type_name("ID")
      ->check(NonEmptyName());
  app_.add_option("--worker-threads", worker_threads_, "threads of each local worker")
      ->type_name("N")
      ->check(IntIn(1, 1024));
  app_.add_option("--worker-wait-s", wait_s_, "how long to wait for workers")->type_name("S")->check(IntIn(1, 86400));
  app_.add_option("--http", http_,
                  "status, metrics and dashboard over HTTP (127.0.0.1:0: a free loopback port, printed)")
      ->type_name("HOST:PORT|off");
  app_.add_option("--event-log", event_log_, "JSON-lines event log")->type_name("F.jsonl");
  app_.add_option("--http-linger-s", linger_s_, "the final state stays up S s if anyone read it")
      ->type_name("S")
      ->check(IntIn(0, 3600));
  app_.add_option("--http-token-file", token_file_,
                  "every HTTP request needs \"Authorization: Bearer TOKEN\"; the dashboard: open\n"
                  "/?token=TOKEN; FILE: one line, mode 600 (or root-owned 440); /healthz stays open,\n"
                  "for probes")
      ->type_name("FILE");
  app_.add_option("--http-tls-cert", tls_cert_,
                  "HTTPS only, TLS 1.2+: the certificate chain, with --http-tls-key its unencrypted key,\n"
                  "mode 600 (or root-owned 440); both or neither")
      ->type_name("CERT.pem");
  app_.add_option("--http-tls-key", tls_key_, "the key of --http-tls-cert")->type_name("KEY.pem");
  app_.add_option("--worker-security", worker_security_, "--local-workers with --security: the workers' credentials")
      ->type_name("DIR");
  app_.add_flag("--check-config", check_config_,
                "parse the flags, load the job, the XML profile and the security files, print what\n"
                "would run and exit 0, without joining DDS; 2 on a bad setting");
  app_.add_option("--min-workers-per-tree", min_workers_per_tree_, "tests: before tree t, wait for Nt live workers")
      ->type_name("N0,N1,...");
  app_.add_option("--pause-file", pause_file_, "while F exists, hold between levels; remove it to go on")
      ->type_name("FILE");
  AddDdsOptions(app_, &dds_);
}

std::optional<int> CoordinatorCommand::Prepare(coordinator::CoordinatorOptions* opt) {
  // Workers receive the config with its paths resolved here.
  auto config = ReadJobConfig(job_path_);
  if (!config.ok()) {
    const bool unreadable = config.status().code() == core::ErrorCode::kIo;
    std::fprintf(stderr, "coordinator: %s\n",
                 (unreadable ? config.status().message() : config.status().ToString()).c_str());
    return unreadable ? 1 : 2;
  }
  config_ = std::move(*config);
  auto params = engine::ParamsFromConfig(config_, job_path_);
  if (!params.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", params.status().ToString().c_str());
    return 2;
  }
  params_ = std::move(*params);
  auto job_dds = JobDdsDefaults(config_, job_path_, dds_, domain_.has_value());
  if (!job_dds.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", job_dds.status().message().c_str());
    return 2;
  }
  domain_used_ = domain_ ? *domain_ : job_dds->domain.value_or(0);
  auto dds_flags = proto::dds::CheckDdsSettings(job_dds->settings);
  if (!dds_flags.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", job_dds->Explain(dds_flags.status()).message().c_str());
    return 2;
  }
  dds_flags_ = std::move(*dds_flags);
  // Local workers under DDS-Security need credentials of their own (a worker grant).
  if (worker_security_) {
    if (local_ == 0 || !dds_flags_.extras.security.enabled()) {
      std::fprintf(stderr, "coordinator: --worker-security is for --local-workers N with --security DIR\n");
      return 2;
    }
    auto files = proto::dds::SecurityFilesIn(*worker_security_, "--worker-security");
    if (!files.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", files.status().message().c_str());
      return 2;
    }
    worker_security_dir_ = std::filesystem::path(files->identity_certificate).parent_path().string();
  } else if (local_ > 0 && dds_flags_.extras.security.enabled()) {
    std::fprintf(stderr,
                 "coordinator: --local-workers with --security needs --worker-security DIR (the workers' "
                 "credentials, e.g. make-test-ca.sh OUT coordinator worker-1 -> --security OUT/coordinator "
                 "--worker-security OUT/worker-1)\n");
    return 2;
  }
  opt->udp_peers = dds_flags_.peers;
  opt->udp_interfaces = dds_flags_.interfaces;
  opt->transport_extras = dds_flags_.extras;
  opt->job_id = job_id_;
  if (opt->job_id.empty()) opt->job_id = engine::DefaultJobId(config_);
  opt->domain = uint32_t(domain_used_);
  opt->transport = dds_flags_.transport;
  opt->min_workers = min_workers_ ? *min_workers_ : std::max(1, local_);
  opt->worker_wait = std::chrono::seconds(wait_s_);
  if (Given("min-workers-per-tree")) {
    std::stringstream items(min_workers_per_tree_);
    for (std::string item; std::getline(items, item, ',');) {
      int n = -1;
      const auto [end, ec] = std::from_chars(item.data(), item.data() + item.size(), n);
      if (ec != std::errc() || end != item.data() + item.size() || n < 0 || n > 4096) {
        std::fprintf(stderr, "coordinator: --min-workers-per-tree: \"%s\" is not a list of counts 0..4096\n",
                     min_workers_per_tree_.c_str());
        return 2;
      }
      opt->min_workers_per_tree.push_back(n);
    }
  }
  opt->checkpoint_dir = checkpoint_;
  opt->resume = resume_;
  opt->pause_file = pause_file_;
  if (opt->resume && opt->checkpoint_dir.empty()) {
    std::fprintf(stderr,
                 "coordinator: --resume needs --checkpoint DIR (the folder the interrupted run wrote)\n");
    return 2;
  }
  // A restart that forgot --resume would start the job over and overwrite the checkpoint after
  // its first level: the finished trees would be lost without a word.
  if (!opt->resume && !opt->checkpoint_dir.empty() &&
      std::filesystem::exists(std::filesystem::path(opt->checkpoint_dir) / "checkpoint.pb")) {
    std::fprintf(
        stderr,
        "coordinator: --checkpoint %s already holds a checkpoint (checkpoint.pb); add --resume to go on "
        "from it, or move the folder away to start the job over (this run would overwrite it)\n",
        opt->checkpoint_dir.c_str());
    return 2;
  }
  if (opt->resume) {  // with --checkpoint (checked above)
    // Check every field of the checkpoint before the coordinator replays it: a corrupt file is
    // an error naming it, never a crash (the same checks as `poseforest export`).
    const auto ckpt = std::filesystem::path(opt->checkpoint_dir) / "checkpoint.pb";
    if (std::filesystem::exists(ckpt)) {
      auto checked =
          coordinator::ForestFromCheckpoint(ckpt.string(), coordinator::PartialTree::kFinishAsLeaves);
      if (!checked.ok() && checked.status().code() != core::ErrorCode::kInvalidArgument) {
        std::fprintf(stderr, "coordinator: cannot resume: %s\n", checked.status().message().c_str());
        return 1;
      }
    }
  }
  return std::nullopt;
}

int CoordinatorCommand::CheckConfig(const coordinator::CoordinatorOptions& opt) const {
  if (const std::string bad = CheckOutputFile("--out", out_, {job_path_}); !bad.empty()) {
    std::fprintf(stderr, "coordinator: %s\n", bad.c_str());
    return 2;
  }
  if (http_ != "off") {
    proto::http::HttpServerOptions http_opt;
    if (Status st = proto::http::ParseHttpAddress(http_, &http_opt); !st.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
      return 2;
    }
  }
  if (Given("http-token-file")) {
    if (auto token = proto::http::ReadHttpTokenFile(token_file_); !token.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", token.status().message().c_str());
      return 2;
    }
  }
  if (Given("http-tls-cert") || Given("http-tls-key")) {
    if (Status st = proto::http::CheckHttpTlsFiles(tls_cert_, tls_key_); !st.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", st.message().c_str());
      return 2;
    }
  }
  if (Given("event-log")) {
    if (const std::string bad = CheckOutputFile("--event-log", event_log_); !bad.empty()) {
      std::fprintf(stderr, "coordinator: %s\n", bad.c_str());
      return 2;
    }
  }
  std::printf(
      "coordinator config ok: job %s (%s), %d trees of depth %d, %d images per tree; DDS domain %u, %s; "
      "%d local workers%s; writes %s%s%s; build \"%s\"\n",
      opt.job_id.c_str(), job_path_.c_str(), params_.num_trees, params_.max_depth, params_.images_per_tree,
      opt.domain, dds_flags_.Describe().c_str(), local_,
      worker_security_dir_.empty() ? "" : (" with credentials of " + worker_security_dir_).c_str(),
      out_.c_str(), opt.checkpoint_dir.empty() ? "" : ", checkpoints in ", opt.checkpoint_dir.c_str(),
      proto::dds::BuildId().c_str());
  return 0;
}

void CoordinatorCommand::PrintLevel(const coordinator::DistLevelStats& s) const {
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
  if (!status_file_.empty()) {
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
        status_file_, std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(j.data()), j.size()));
  }
}

int CoordinatorCommand::CheckHttpFiles(std::string* token) const {
  if (Given("http-token-file")) {
    if (http_ == "off") {
      std::fprintf(stderr, "coordinator: --http-token-file is for the HTTP status server, not --http off\n");
      return 2;
    }
    auto t = proto::http::ReadHttpTokenFile(token_file_);
    if (!t.ok()) {
      std::fprintf(stderr, "coordinator: %s\n", t.status().message().c_str());
      return 2;
    }
    *token = *t;
  }
  if ((!tls_cert_.empty() || !tls_key_.empty()) && http_ == "off") {
    std::fprintf(stderr,
                 "coordinator: --http-tls-cert/--http-tls-key are for the HTTP status server, not --http off\n");
    return 2;
  }
  return 0;
}

// The checkpoint folder and the status file's folder, checked before the job starts (and by
// --check-config): found wrong after the first level they would stop the job.
int CoordinatorCommand::CheckStatePaths() const {
  if (!checkpoint_.empty()) {
    if (std::error_code ec;
        std::filesystem::exists(checkpoint_, ec) && !std::filesystem::is_directory(checkpoint_, ec)) {
      std::fprintf(stderr, "coordinator: --checkpoint %s: a file, not a folder\n", checkpoint_.c_str());
      return 2;
    }
  }
  if (!status_file_.empty())
    if (const std::string bad = CheckOutputFile("--status-file", status_file_); !bad.empty()) {
      std::fprintf(stderr, "coordinator: %s\n", bad.c_str());
      return 2;
    }
  return 0;
}

int CoordinatorCommand::Run() {
  coordinator::CoordinatorOptions opt;
  if (auto rc = Prepare(&opt)) return *rc;
  if (int rc = CheckStatePaths(); rc != 0) return rc;
  if (check_config_) return CheckConfig(opt);
  if (!dds_flags_.resolved.empty()) {  // resolved once: a name that moves later is not followed
    std::printf("DDS host names resolved at start-up: %s\n", dds_flags_.ResolvedText().c_str());
    std::fflush(stdout);
  }
  opt.progress = [this](const coordinator::DistLevelStats& s) {
    if (!quiet_) PrintLevel(s);
  };
  // Monitoring: status model, HTTP (dashboard, /status.json, /metrics), event log.
  std::string http_token;
  if (int rc = CheckHttpFiles(&http_token); rc != 0) return rc;
  auto monitoring = coordinator::monitoring::CoordinatorMonitoring::Start(
      {opt.job_id, opt.domain, dds_flags_.Label(), params_.num_trees, params_.max_depth, params_.images_per_tree,
       params_.pixels_per_image, params_.candidate_features, params_.thresholds_per_feature, out_},
      http_, event_log_, http_token, tls_cert_, tls_key_);
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
                  url.c_str(), url.c_str(), url.c_str(), token_file_.c_str(), url.c_str(), url.c_str(),
                  token_file_.c_str());
    if (!tls_cert_.empty())
      std::printf("status: HTTPS only (certificate %s); a certificate from a private CA: monitor --http-ca-file "
                  "CA.pem; use a host name the certificate names\n",
                  tls_cert_.c_str());
    std::fflush(stdout);
  }
  LocalWorkers workers;
  if (local_ > 0) {
    // The workers' cores are theirs: merge on what is left (at least 1 thread).
    const int64_t cores = std::max<int64_t>(1, int64_t(std::thread::hardware_concurrency()));
    opt.merge_threads = int(std::max<int64_t>(1, cores - int64_t(local_) * worker_threads_));
    std::vector<std::string> wargs = {"--domain", std::to_string(domain_used_), "--job", opt.job_id, "--threads",
                                      std::to_string(worker_threads_)};
    for (const std::string& a : dds_flags_.TransportArgs()) wargs.push_back(a);
    if (!worker_security_dir_.empty()) wargs.insert(wargs.end(), {"--security", worker_security_dir_});
    if (!workers.Start(local_, wargs)) {
      std::fprintf(stderr, "coordinator: cannot start local workers\n");
      return 1;
    }
  }
  coordinator::DistCoordinator coordinator(config_, params_, opt);
  const double t0 = proto::dds::NowSeconds();
  auto forest = coordinator.Train();
  workers.StopAll();
  if (!forest.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", forest.status().ToString().c_str());
    (*monitoring)->Finish(false, forest.status().ToString(), double(linger_s_));
    return 1;
  }
  if (Status st = core::SaveForest(*forest, out_); !st.ok()) {
    std::fprintf(stderr, "coordinator: %s\n", st.ToString().c_str());
    (*monitoring)->Finish(false, st.ToString(), double(linger_s_));
    return 1;
  }
  std::printf(
      "wrote %s: %zu trees in %.2f s, %s received, %llu messages rejected, %llu stale messages dropped, %d "
      "workers lost\n",
      out_.c_str(), forest->trees.size(), proto::dds::NowSeconds() - t0,
      Human(double(coordinator.bytes_received())).c_str(), (unsigned long long)coordinator.rejected_messages(),
      (unsigned long long)coordinator.stale_messages(), coordinator.workers_lost());
  std::fflush(stdout);
  (*monitoring)->Finish(true, "wrote " + out_, double(linger_s_));
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeCoordinatorCommand() { return std::make_unique<CoordinatorCommand>(); }

}  // namespace poseforest::apps::commands
