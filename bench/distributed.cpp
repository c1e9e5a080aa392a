// bench/distributed: the distributed training service against the single-process engine, in one
// run on one job: LocalTrainer (1 thread), then the coordinator (this process) with 1 and with 2
// worker processes (this program re-started with --worker-process, 1 OpenMP thread each,
// Fast DDS over shared memory, as `poseforest coordinator --local-workers N` does).
//
// Prints per level and per tree: nodes, samples, bytes received (replies) and sent (control),
// coordinator merge time, level wall time; per run: wall, CPU seconds of every process involved
// (getrusage: the bench process for the engine and the coordinator, the reaped worker processes
// for the workers), evaluations/s (wall) and evaluations per CPU-second. "Per core" = per
// CPU-second actually used, so idle waiting costs nothing and a busy coordinator counts.
// Every run's forest is checked byte for byte against the engine's.
//
//   distributed [JOB.textproto] [--csv FILE] [--domain D] [--subtree-max S] (--help: every option)
// Each worker count runs twice: without subtree hand-off (subtree_max_samples 0: every level
// by histogram rounds) and with it (nodes of at most S samples trained whole by one worker; S
// defaults to the job's subtree_max_samples, 4096 unless set; 0 skips the second run). The
// per-level table then also shows the nodes handed off and the nodes decided by results. The
// job's frame rule (subtree_max_frames, default 256; job.proto) applies too: this job's 100
// frames per tree let nodes of up to 16 x S samples go whole once they hold at most a quarter
// of the level's samples per worker.
// The last line is `distributed/engine per core: <ratio> ratio`: the two commands as users run
// them, `poseforest train JOB --threads N` (the engine) and `poseforest train JOB --local-workers
// N` (coordinator + N worker processes), N = 2 (else the largest count), each a fresh process,
// CPU of each command and its reaped worker processes, forests checked against the engine's:
// engine CPU / service CPU = evaluations per CPU-second of the service over the engine's; the
// median over --repeat pairs (alternating which runs first). Until 21 Nov 2026 (fifth session)
// the last line was the in-process comparison, still printed above it: 2 workers against the
// engine run inside this process (LocalTrainer with 2 OpenMP threads). That one is lopsided: the
// engine's CPU counts Train() alone, in a process whose heap, libraries and OpenMP pool are warm
// from its earlier runs, while the workers count whole fresh processes (start-up, exit). Measured
// over 25 quiet pairs: `train --threads 2` costs 0.128 CPU s more than the in-process engine,
// `train --local-workers 2` 0.053 more than the in-process service (docs/distributed/service.md).
// The engine also runs with 1 thread and as N concurrent 1-thread processes; those ratios are
// printed above the last line too.
// The bench re-executes itself with OMP_WAIT_POLICY=PASSIVE (unless set) so idle OpenMP threads
// sleep instead of spinning: CPU seconds then count work, for the engine and the workers alike.
// --csv writes the per-level rows of the runs without hand-off (input of
// scripts/traffic_model.py, which models histogram traffic).
//
// The engine also runs as N concurrent 1-thread processes (this program with --engine-process,
// each training the whole job; N = the headline's workers), once and in every --repeat pair:
// the same multi-process load on the machine without the service, printed as "engine, N
// processes" and as the ratio "vs the engine as N concurrent 1-thread processes" above the last
// line (what the service costs beyond running N processes at once on these cores).
// Every run also prints where its CPU went: the coordinator, and the workers by phase (each
// worker process writes its worker::WorkerCpu to a --stats file when it exits), and a "why the
// ratio" line splits the headline run's CPU into the training work the engine also does and
// what the service adds (docs/distributed/service.md, "Per-core overhead").
//   --workers N,N   worker counts to run (default 1,2)     --skip-off   only runs with hand-off
//   --repeat R      R (engine, headline run) pairs; the last line is the median ratio
//   --engine-only   the engine alone (e.g. under a profiler)
//   --no-sample-lists  subtree tasks without their sample lists (workers route every sample of
//                   the tasks' frames, one task at a time): the service before that change
// The headline's commands run the poseforest program next to this bench (../bin/poseforest) or
// --poseforest PATH; --repeat R gives R in-process pairs and R command pairs.
//   --neighbour-test R  instead of the service runs: the 1-thread engine alone, next to a busy
//                   loop and next to random reads over 16 MiB, R rounds; shows what a second
//                   busy process costs through the shared L3 (docs/distributed/service.md)
// POSEFOREST_BENCH_WORKER_WRAP="CMD ARGS": worker processes run under CMD (a profiler).
//   --commands-only [--keep-logs DIR]  only the two commands as users run them (no in-process
//                   runs: for big jobs, e.g. 2,000 images per tree), --repeat R pairs;
//                   per pair the wall and CPU of each, the forests compared, and a per-level
//                   table both ways from their event logs (--event-log, JSON Lines; kept
//                   with --keep-logs) with the service's level time split into
//                   the rounds (the critical worker's computing, its request queued while it
//                   was busy, traffic), merge, waiting for subtree results and other, beside
//                   the workers' subtree and rendering seconds. Above the last line: the
//                   median wall ratio (service / engine; the goal: at most 1.10).
//   --scale N,N,..  many workers on one machine (docs/distributed/scaling.md): instead
//                   of the runs above, the engine once (the reference forest) and then one service
//                   run per N (1..64) worker processes, 1 thread each, subtree hand-off off unless
//                   --subtree-max S is given (every level by histogram rounds: the coordinator's
//                   cost per reply is what is measured). Oversubscribed on a small machine, so it
//                   counts CPU seconds, not wall: per N and level the coordinator's CPU seconds
//                   (CLOCK_PROCESS_CPUTIME_ID from the level's start to its end, all its threads)
//                   and merge time, replies and heartbeats heard, control messages written and
//                   bytes both ways, rounds; per N the workers' CPU (wait4) and peak RSS (each
//                   worker's VmHWM), this process's peak RSS, and whether the forest is the
//                   engine's, byte for byte. Then least-squares fits of the coordinator's CPU per
//                   level on the runs with N <= 8 (1: a + b x replies; 1b: an intercept per level +
//                   b x replies; 2: per level, per reply, per MB received, per dense cell searched,
//                   per heartbeat), checked against the runs with N > 8, the byte law of
//                   traffic_model.md checked the same way, fit 2's terms fitted on every N (fit 3),
//                   and from fit 3 a projection to the paper's job (3 trees, depth 20, 300k images
//                   per tree, 2000 x 50) on 10..1000 workers of 2 and 16 cores, with what would
//                   lift the coordinator's limit (hand-off, a reduction tree, a sharded merge).
//                   Workers get a 10 s liveliness lease and a 60 s heartbeat timeout (32 processes
//                   on 2 cores must not be taken for lost); the coordinator waits for all N
//                   (min_workers, up to 10 min). --csv writes the per-level rows (the columns of
//                   the default mode's, then rounds, replies, node entries in them, heartbeats,
//                   control messages, coordinator CPU). Last line: `coordinator CPU per reply:
//                   <b> ms` (fit 1b's slope: what one more worker's reply costs the coordinator on
//                   the same level).

#include <fcntl.h>
#include <google/protobuf/text_format.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "bench/bench_cli.h"
#include "coordinator/dist_coordinator.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/node_config.h"
#include "runtime/core/forest_format.h"
#include "runtime/core/malloc_tuning.h"
#include "worker/dist_worker.h"

extern char** environ;

using namespace poseforest;

namespace {

/// Default job: 1 tree, depth 12, 100 procedural frames of 160x120, 1000 pixels each, 300
/// candidates x 30 thresholds (about 2 s for the engine on one core).
const char* kDefaultJob =
    "seed: 3\nnum_trees: 1\nmax_depth: 12\nimages_per_tree: 100\npixels_per_image: 1000\n"
    "candidate_features: 300\nthresholds_per_feature: 30\nmax_probe_offset_pixel_m: 80\n"
    "source { procedural { seed: 4 width: 160 height: 120 } }\n";

double CpuSeconds(int who) {
  rusage u{};
  ::getrusage(who, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double ProcessCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

/// This process's peak resident set (VmHWM), MB; reset by ResetPeakRss.
double PeakRssMb() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

/// Starts a new peak-RSS window for this process (Linux: "5" to clear_refs resets VmHWM).
void ResetPeakRss() { std::ofstream("/proc/self/clear_refs") << "5"; }

/// Starts args[0] (looked up in PATH if `search_path`) with this process's environment; -1 if
/// it cannot be started.
pid_t Spawn(std::vector<std::string> args, const posix_spawn_file_actions_t* actions = nullptr,
            bool search_path = false) {
  std::vector<char*> c;
  for (auto& a : args) c.push_back(a.data());
  c.push_back(nullptr);
  pid_t pid = -1;
  const int err = search_path ? ::posix_spawnp(&pid, c[0], actions, nullptr, c.data(), environ)
                              : ::posix_spawn(&pid, c[0], actions, nullptr, c.data(), environ);
  return err == 0 ? pid : -1;
}

double LoadAverage() {
  double l[1] = {0};
  return ::getloadavg(l, 1) == 1 ? l[0] : -1;
}

/// Runs `args` (args[0]: the program) with stdout and stderr appended to `log`; its CPU and that
/// of its reaped descendants in *cpu, its wall time in *wall. False if it could not start or
/// did not exit 0.
bool RunCommand(const std::vector<std::string>& args, const std::string& log, double* cpu, double* wall) {
  posix_spawn_file_actions_t fa;
  ::posix_spawn_file_actions_init(&fa);
  ::posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  ::posix_spawn_file_actions_adddup2(&fa, 1, 2);
  const double c0 = CpuSeconds(RUSAGE_CHILDREN), t0 = proto::dds::NowSeconds();
  const pid_t pid = Spawn(args, &fa);
  ::posix_spawn_file_actions_destroy(&fa);
  if (pid < 0) return false;
  int status = 0;
  ::waitpid(pid, &status, 0);
  *cpu = CpuSeconds(RUSAGE_CHILDREN) - c0;
  *wall = proto::dds::NowSeconds() - t0;
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

std::vector<uint8_t> ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Per (tree, level): seconds of the level in the event log (--event-log, JSON Lines) of
/// `poseforest train JOB --threads N` (LEVEL_DONE's `seconds`: since the previous level, frame
/// loading left out) or of `train JOB --local-workers N` (the coordinator's LEVEL_DONE events:
/// `seconds`, and where they went: rounds, the critical worker's computing, its request queued,
/// traffic, merge, waiting for subtrees; docs/distributed/monitoring.md).
struct LevelTimes {
  struct Service {
    double level = 0, rounds = 0, compute = 0, queued = 0, traffic = 0, merge = 0, wait = 0, busy = 0, render = 0;
    double received_mib = 0;
    int tasks = 0;
  };
  std::map<std::pair<int, int>, double> engine;
  std::map<std::pair<int, int>, Service> service;
  /// Calls `f(key, event)` for each LEVEL_DONE line of the event log at `path`.
  template <typename F>
  static void ForEachLevel(const std::string& path, F f) {
    std::ifstream in(path);
    for (std::string line; std::getline(in, line);) {
      const auto e = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
      if (!e.is_object() || e.value("event", "") != "LEVEL_DONE") continue;
      f(std::pair<int, int>{e.value("tree", 0), e.value("level", 0)}, e);
    }
  }
  void ReadEngine(const std::string& path) {
    ForEachLevel(path, [&](std::pair<int, int> key, const nlohmann::json& e) {
      engine[key] = e.value("seconds", 0.0);
    });
  }
  void ReadService(const std::string& path) {
    ForEachLevel(path, [&](std::pair<int, int> key, const nlohmann::json& e) {
      Service& s = service[key];
      s.level = e.value("seconds", 0.0);
      s.rounds = e.value("round_seconds", 0.0);
      s.compute = e.value("compute_seconds", 0.0);
      s.queued = e.value("queued_seconds", 0.0);
      s.traffic = e.value("traffic_seconds", 0.0);
      s.merge = e.value("merge_seconds", 0.0);
      s.wait = e.value("subtree_wait_seconds", 0.0);
      s.busy = e.value("subtree_busy_seconds", 0.0);
      s.render = e.value("render_seconds", 0.0);
      s.received_mib = e.value("bytes_received", 0.0) / 1048576.0;
      s.tasks = e.value("subtree_tasks", 0);
    });
  }
  /// The table: per level both ways and where the service's time went.
  void Print() const {
    std::printf("\nper level, seconds (service: the rounds split into the critical worker's computing, its request "
                "queued while it was busy, traffic; then merge, waiting for subtree results, other; workers' "
                "subtree and rendering seconds are summed over the workers and overlap the rest)\n");
    std::printf("%4s %5s %9s %9s %7s %9s %9s %9s %9s %7s %9s %7s %9s %9s %9s\n", "tree", "level", "engine", "service",
                "ratio", "rounds", "computing", "queued", "traffic", "merge", "wait sub", "other", "MiB recv",
                "subtree s", "render s");
    double te = 0, ts = 0;
    Service sum;
    std::set<std::pair<int, int>> keys;
    for (const auto& [k, v] : engine) keys.insert(k);
    for (const auto& [k, v] : service) keys.insert(k);
    for (const auto& k : keys) {
      const double e = engine.count(k) ? engine.at(k) : 0;
      const Service s = service.count(k) ? service.at(k) : Service{};
      te += e, ts += s.level;
      sum.rounds += s.rounds, sum.compute += s.compute, sum.queued += s.queued, sum.traffic += s.traffic;
      sum.merge += s.merge, sum.wait += s.wait, sum.busy += s.busy, sum.render += s.render;
      sum.received_mib += s.received_mib;
      const double other = std::max(0.0, s.level - s.rounds - s.merge - s.wait);
      std::printf("%4d %5d %9.2f %9.2f %7.2f %9.2f %9.2f %9.2f %9.2f %7.2f %9.2f %7.2f %9.1f %9.2f %9.2f\n",
                  k.first, k.second, e, s.level, e > 0 ? s.level / e : 0.0, s.rounds, s.compute, s.queued, s.traffic,
                  s.merge, s.wait, other, s.received_mib, s.busy, s.render);
    }
    std::printf("%4s %5s %9.1f %9.1f %7.3f %9.1f %9.1f %9.1f %9.1f %7.1f %9.1f %7.1f %9.0f %9.1f %9.1f\n", "all", "",
                te, ts, te > 0 ? ts / te : 0.0, sum.rounds, sum.compute, sum.queued, sum.traffic, sum.merge, sum.wait,
                std::max(0.0, ts - sum.rounds - sum.merge - sum.wait), sum.received_mib, sum.busy, sum.render);
  }
};

/// --commands-only: the two commands as users run them on JOB, R pairs (alternating which runs
/// first), forests compared byte for byte, per-level times both ways from their logs, wall and
/// CPU ratios. For jobs far too big for the in-process runs (a 2,000-image job).
int CommandsOnly(const std::string& job_path_in, const std::string& text, const std::string& cli, int n, int repeat,
                 uint32_t domain, const std::string& keep_logs) {
  const auto tmp = std::filesystem::temp_directory_path();
  const std::string tag = "bench-" + std::to_string(::getpid());
  std::string job_path = job_path_in;
  if (job_path.empty()) {
    job_path = (tmp / (tag + "-job.textproto")).string();
    std::ofstream(job_path) << text;
  }
  const std::string out_e = (tmp / (tag + "-engine.pff")).string(), out_s = (tmp / (tag + "-service.pff")).string();
  const std::string n_str = std::to_string(n);
  std::vector<double> cpu_ratio, wall_ratio;
  bool ok = true;
  std::printf("\ncommands only, %d pair(s): `%s train JOB --threads %d` against `... train JOB --local-workers %d`, "
              "fresh processes, one after the other\n",
              repeat, cli.c_str(), n, n);
  std::fflush(stdout);
  for (int r = 0; r < repeat; ++r) {
    const std::string log_e = (tmp / (tag + "-engine-" + std::to_string(r) + ".log")).string(),
                      log_s = (tmp / (tag + "-service-" + std::to_string(r) + ".log")).string();
    const std::string events_e = (tmp / (tag + "-engine-" + std::to_string(r) + ".events.jsonl")).string(),
                      events_s = (tmp / (tag + "-service-" + std::to_string(r) + ".events.jsonl")).string();
    double ce = 0, we = 0, cs = 0, ws = 0;
    const bool engine_first = r % 2 == 0;
    bool a = false, b = false;
    for (int which = 0; which < 2; ++which) {
      const bool engine_now = (which == 0) == engine_first;
      std::filesystem::remove(engine_now ? out_e : out_s);
      std::filesystem::remove(engine_now ? events_e : events_s);  // the event log is appended to
      const bool run_ok = engine_now
                              ? RunCommand({cli, "train", job_path, "--threads", n_str, "--event-log",
                                            events_e, "--out", out_e},
                                           log_e, &ce, &we)
                              : RunCommand({cli, "train", job_path, "--local-workers", n_str, "--domain",
                                            std::to_string((domain + 101 + uint32_t(r)) % 233), "--http",
                                            "off", "--event-log", events_s, "--out", out_s},
                                           log_s, &cs, &ws);
      (which == 0 ? a : b) = run_ok;
      std::printf("  %s: %.1f s wall, %.1f CPU s, load average %.1f\n", engine_now ? "engine " : "service",
                  engine_now ? we : ws, engine_now ? ce : cs, LoadAverage());
      std::fflush(stdout);
    }
    const bool same = a && b && ReadBytes(out_e) == ReadBytes(out_s);
    if (!same) {
      std::printf("pair %d: a command failed or the forests differ; logs: %s %s\n", r + 1, log_e.c_str(),
                  log_s.c_str());
      ok = false;
      break;
    }
    cpu_ratio.push_back(ce / cs);
    wall_ratio.push_back(ws / we);
    std::printf("pair %d (%s first): forests identical; wall service / engine %.3f, per CPU-second %.3f\n", r + 1,
                engine_first ? "engine" : "service", wall_ratio.back(), cpu_ratio.back());
    LevelTimes times;
    times.ReadEngine(events_e);
    times.ReadService(events_s);
    times.Print();
    if (!keep_logs.empty()) {
      std::filesystem::create_directories(keep_logs);
      for (const std::string& f : {log_e, log_s, events_e, events_s})
        std::filesystem::copy_file(f, std::filesystem::path(keep_logs) / std::filesystem::path(f).filename(),
                                   std::filesystem::copy_options::overwrite_existing);
    }
    for (const std::string& f : {log_e, log_s, events_e, events_s}) std::filesystem::remove(f);
    std::fflush(stdout);
  }
  for (const std::string& f : {out_e, out_s}) std::filesystem::remove(f);
  if (job_path_in.empty()) std::filesystem::remove(job_path);
  if (!ok || cpu_ratio.empty()) return 1;
  std::sort(cpu_ratio.begin(), cpu_ratio.end());
  std::sort(wall_ratio.begin(), wall_ratio.end());
  std::printf("wall, service / engine: median %.3f over %zu pair(s) (goal: at most 1.10)\n",
              wall_ratio[wall_ratio.size() / 2], wall_ratio.size());
  std::printf("distributed/engine per core: %.3f ratio\n", cpu_ratio[cpu_ratio.size() / 2]);
  return 0;
}

/// A worker's CPU breakdown as (name, value) pairs: what a worker process writes to its
/// --stats file, summed over the workers of a run by the bench.
std::vector<std::pair<std::string, double>> CpuFields(const worker::WorkerCpu& c) {
  std::vector<std::pair<std::string, double>> out = {{"process_at_start", c.process_at_start}};
  for (const auto& [name, seconds] : c.NamedPhases()) out.emplace_back(name, seconds);
  std::vector<std::pair<std::string, double>> rest = {
          {"run_total", c.run_total},
          {"other_threads", c.run_total - c.Phases()},
          {"shard_frames", double(c.shard_frames)},
          {"task_frames", double(c.task_frames)},
          {"task_frames_cached", double(c.task_frames_cached)},
          {"subtree_tasks", double(c.subtree_tasks)},
          {"subtree_batches", double(c.subtree_batches)},
          {"rounds_in_batches", double(c.rounds_in_batches)},
          {"task_cache_peak_bytes", double(c.task_cache_peak_bytes)},
          {"task_cache_evictions", double(c.task_cache_evictions)}};
  out.insert(out.end(), rest.begin(), rest.end());
  return out;
}

/// A worker process: this program with --worker-process. Its arguments are written by this
/// program when it starts the process, never by a user, so they are read as they are (main's
/// command line, the user's, goes through CLI11).
int WorkerProcess(int argc, char** argv) {
  // Go when the bench goes (killed or interrupted), as `worker --exit-with-parent` does.
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (::getppid() == 1) return 0;
  worker::WorkerOptions o;
  std::string stats_path;
  for (int i = 1; i + 1 < argc; ++i) {
    if (!std::strcmp(argv[i], "--stats"))
      stats_path = argv[++i];
    else if (!std::strcmp(argv[i], "--domain"))
      o.domain = uint32_t(std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--job"))
      o.job_id = argv[++i];
    else if (!std::strcmp(argv[i], "--id"))
      o.worker_id = argv[++i];
    else if (!std::strcmp(argv[i], "--lease-ms"))
      o.lease = std::chrono::milliseconds(std::atoi(argv[++i]));
  }
  o.threads = 1;
  o.exit_when_done = true;
  o.log = [](const std::string&) {};
  worker::DistWorker w(o);
  const core::Status st = w.Run();
  if (!st.ok()) std::fprintf(stderr, "worker: %s\n", st.ToString().c_str());
  if (!stats_path.empty()) {
    std::ofstream out(stats_path);
    for (const auto& [name, value] : CpuFields(w.cpu())) out << name << ' ' << value << '\n';
    out << "process_at_report " << CpuSeconds(RUSAGE_SELF) << '\n';
    out << "peak_rss_mb " << PeakRssMb() << '\n';  // --scale (wait4's ru_maxrss holds the bench's peak)
  }
  return st.ok() ? 0 : 1;
}

struct RunFigures {
  double wall = 0, cpu = 0, coordinator_cpu = 0, workers_cpu = 0, levels_wall = 0;
  uint64_t evaluations = 0, bytes_received = 0, bytes_sent = 0;
  uint64_t subtree_samples = 0, subtree_busiest = 0;  ///< handed samples; of which to each level's busiest worker
  double merge = 0;
  bool identical = false;
  std::map<std::string, double> worker_cpu;  ///< CpuFields summed over the run's workers
  double workers_reported = 0;               ///< process CPU the workers reported before exiting
};

/// Reads a worker's --stats file into `sum` (adding); false if it is missing or unreadable.
bool AddStats(const std::string& path, std::map<std::string, double>* sum) {
  std::ifstream in(path);
  if (!in) return false;
  std::string name;
  double value = 0;
  bool any = false;
  while (in >> name >> value) (*sum)[name] += value, any = true;
  return any;
}

/// Where a run's CPU went: the coordinator, and the workers by phase (WorkerCpu), next to the
/// engine's total. "Also in the engine" = work the single-process engine does too (its frames,
/// histograms and routing); the rest is what the service adds.
void PrintBreakdown(const RunFigures& f, double engine_cpu) {
  std::map<std::string, double> c = f.worker_cpu;
  auto g = [&](const char* k) { return c.count(k) ? c.at(k) : 0.0; };
  const double exit_cpu = f.workers_cpu - g("process_at_report");
  const double startup = g("process_at_start") + g("participant");
  const double shared_work =
      g("shard") + g("decisions") + g("level_compute") + g("subtree_route") + g("subtree_train");
  std::printf("  where the CPU went (CPU s; engine %.3f):\n", engine_cpu);
  std::printf("    %-58s %7.3f\n", "coordinator (this process: merges, rounds, waiting, DDS)", f.coordinator_cpu);
  std::printf("    %-58s %7.3f\n", "workers, all", f.workers_cpu);
  auto row = [&](const std::string& what, double v) { std::printf("      %-56s %7.3f\n", what.c_str(), v); };
  row("start-up: exec, libraries, static init", g("process_at_start"));
  row("DDS participant, readers, writers", g("participant"));
  row("own shard: " + std::to_string(int64_t(g("shard_frames"))) + " frames rendered, sampled", g("shard"));
  row("routing samples (SplitDecisions)", g("decisions"));
  row("level rounds: ranges, histograms (builder)", g("level_compute"));
  row("level rounds: plans, counts, reply messages", g("level_encode"));
  row("subtree tasks (" + std::to_string(int64_t(g("subtree_tasks"))) + ", " +
          std::to_string(int64_t(g("subtree_batches"))) + " batches of several): frames rendered (" +
          std::to_string(int64_t(g("task_frames"))) + "; " + std::to_string(int64_t(g("task_frames_cached"))) +
          " held)",
      g("subtree_render"));
  row("subtree tasks: SampleSet + routing along the path", g("subtree_route"));
  row("subtree tasks: training (TrainSubtree)", g("subtree_train"));
  row("subtree tasks: result messages", g("subtree_encode"));
  row("receiving: DDS take, gate (decode + checks), polling", g("receive"));
  row("sending: serialize, DDS write, match waits", g("publish"));
  row("other threads: DDS (discovery, transport), heartbeats", g("other_threads"));
  row("exit: participant teardown, destructors", exit_cpu);
  const double service_only = f.cpu - shared_work;
  std::printf(
      "    work the engine does too (frames, routing, histograms, training): %.3f; the rest (start-up %.3f, "
      "messages, DDS, coordinator, frames rendered again): %.3f = %.0f%% of the service's CPU\n",
      shared_work, startup, service_only, 100.0 * service_only / std::max(1e-9, f.cpu));
  if (g("task_cache_peak_bytes") > 0)
    std::printf("    task frame cache: peak %.1f MB (sum over workers), %lld evictions\n",
                g("task_cache_peak_bytes") / 1e6, (long long)g("task_cache_evictions"));
}

/// The headline run's CPU against the engine's, in a few lines: what the service spends that the
/// engine does not (from PrintBreakdown's figures).
void PrintWhy(const RunFigures& f, double engine_cpu, int n, uint64_t sm) {
  const std::map<std::string, double>& c = f.worker_cpu;
  auto g = [&](const char* k) { return c.count(k) ? c.at(k) : 0.0; };
  const double work = g("shard") + g("decisions") + g("level_compute") + g("subtree_route") + g("subtree_train");
  const double startup_exit = g("process_at_start") + g("participant") + (f.workers_cpu - g("process_at_report"));
  const double messages = g("level_encode") + g("subtree_encode") + g("receive") + g("publish");
  std::printf(
      "why the ratio (%d workers, hand-off %s): service %.3f CPU s vs engine on as many cores %.3f; service = "
      "training work on the workers %.3f (frames, routing, histograms, subtrees incl. their sample sets %.3f)"
      " + coordinator %.3f (merges, split choice, rounds, its DDS) + worker start-up and exit %.3f"
      " + messages (encode, send, receive, gate) %.3f + workers' DDS and heartbeat threads %.3f"
      " + frames rendered again for subtree tasks %.3f\n",
      n, sm ? std::to_string(sm).c_str() : "off", f.cpu, engine_cpu, work, g("subtree_route"), f.coordinator_cpu,
      startup_exit, messages, g("other_threads"), g("subtree_render"));
}

struct Row {
  int workers, tree, level;
  size_t nodes, split;
  uint64_t samples, evaluations, bytes_received, bytes_sent;
  double merge_s, level_s;
};

}  // namespace

/// An engine process: this program with --engine-process JOB.textproto: LocalTrainer with 1
/// thread on the job, nothing else (the two-process comparison, see main).
int EngineProcess(const char* job_path) {
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  std::ifstream in(job_path);
  std::stringstream text;
  text << in.rdbuf();
  auto config = engine::ParseJobText(text.str(), job_path);
  if (!config.ok()) return std::fprintf(stderr, "%s\n", config.status().ToString().c_str()), 1;
  auto params = engine::ParamsFromConfig(*config, job_path);
  if (!params.ok()) return std::fprintf(stderr, "%s\n", params.status().ToString().c_str()), 1;
  params->threads = 1;
  engine::LocalTrainer local(*params, {});
  auto forest = local.Train();
  if (!forest.ok()) return std::fprintf(stderr, "%s\n", forest.status().ToString().c_str()), 1;
  return 0;
}

/// A neighbour process for --neighbour-test: this program with --neighbour spin (a busy loop:
/// takes a core, touches almost no memory) or --neighbour reads MB (random 8-byte reads over MB
/// MiB: takes a core and keeps evicting the shared L3). Runs until killed.
int NeighbourProcess(int argc, char** argv) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  const bool reads = argc > 3 && !std::strcmp(argv[2], "reads");
  uint64_t x = 88172645463325252ull;
  if (!reads)
    for (;;) {
      x ^= x << 13, x ^= x >> 7, x ^= x << 17;
      asm volatile("" : : "r"(x));  // the loop has an effect
    }
  const size_t n = size_t(std::max(1, std::atoi(argv[3]))) << 17;  // 8-byte words in MB MiB
  std::vector<uint64_t> mem(n, 1);
  for (uint64_t acc = 0;;) {
    for (int i = 0; i < 4096; ++i) x ^= x << 13, x ^= x >> 7, x ^= x << 17, acc += mem[x % n];
    asm volatile("" : : "r"(acc));
  }
}

namespace {

// ---- --scale: many worker processes on one machine, one job ----

/// One level of one --scale run, as the coordinator saw it.
struct ScaleLevel {
  int workers = 0, tree = 0, level = 0;
  size_t nodes = 0;
  uint64_t samples = 0, evaluations = 0;
  int rounds = 0;
  uint64_t replies = 0;      ///< histogram replies accepted (every round of the level)
  uint64_t reply_nodes = 0;  ///< node entries in them (ranges or histograms of one node from one worker)
  uint64_t heartbeats = 0;   ///< workers' heartbeats accepted while the level ran
  /// Control messages written: one request per round, one SplitDecisions, the SubtreeTasks
  /// messages (coordinator/rounds.cpp Round, remote_shard_set.cpp ApplySplits, subtree_scheduler.cpp
  /// FlushTasks); each reaches every worker.
  uint64_t sent = 0;
  uint64_t bytes_received = 0, bytes_sent = 0;
  double cpu_s = 0;    ///< coordinator process CPU from the level's start to its end (all threads)
  double merge_s = 0;  ///< DistLevelStats::merge_seconds (wall: decode + sum + split choice)
  double level_s = 0;
  double mcells = 0;  ///< millions of dense histogram cells searched: n x K x B x min(31, samples per node)
  int k = 0;          ///< candidates per node
  int sweep = 0;      ///< which of the --repeat sweeps
};

/// The coordinator's CPU per level as fitted: per level, per reply, per MB received, per million
/// dense cells searched (the split search). Tried first and dropped (docs/distributed/scaling.md):
/// a term per node-candidate in the replies, which extrapolated from N <= 8 to 16 and 32 worse,
/// and one per heartbeat heard, which the fits filled with what grows with N (heartbeats do:
/// N x the level's wall time) at an impossible ~2 ms per 100-byte message.
std::vector<double> CpuTerms(double replies, double bytes, double mcells) {
  return {1.0, replies, bytes * 1e-6, mcells};
}
std::vector<double> CpuTerms(const ScaleLevel& r) {
  return CpuTerms(double(r.replies), double(r.bytes_received), r.mcells);
}
constexpr size_t kTerms = 4;
const char* const kTermNames[kTerms] = {"per level", "per reply", "per MB received", "per M dense cells"};

/// Counts what the coordinator hears during each level and the CPU it spends then. Called on the
/// coordinator's training thread (CoordinatorObserver).
class ScaleObserver final : public coordinator::CoordinatorObserver {
 public:
  ScaleObserver(int workers, int candidates, int bins) : workers_(workers), k_(candidates), b_(bins) {}
  void OnLevelStart(int, int, size_t, uint64_t) override {
    cpu0_ = ProcessCpu();
    replies_ = reply_nodes_ = heartbeats_ = 0;
  }
  void OnWorkerReply(const std::string&, uint64_t, const v1::HistogramReply& r) override {
    ++replies_;
    reply_nodes_ += uint64_t(std::max(r.ranges_size(), r.nodes_size()));
  }
  void OnWorkerHeartbeat(const std::string&, const v1::Heartbeat&) override { ++heartbeats_; }
  void OnLevelDone(const coordinator::DistLevelStats& s) override {
    ScaleLevel r;
    r.workers = workers_, r.tree = s.tree, r.level = s.level, r.nodes = s.frontier_nodes;
    r.samples = s.samples, r.evaluations = s.evaluations, r.rounds = s.rounds;
    r.replies = replies_, r.reply_nodes = reply_nodes_, r.heartbeats = heartbeats_, r.k = k_;
    r.sent = uint64_t(s.rounds) + 1 + s.subtree_task_messages;
    r.bytes_received = s.bytes_received, r.bytes_sent = s.bytes_sent;
    r.cpu_s = ProcessCpu() - cpu0_;
    r.merge_s = s.merge_seconds, r.level_s = s.level_seconds;
    const double per_node = s.frontier_nodes ? double(s.samples) / double(s.frontier_nodes) : 0;
    r.mcells = double(s.frontier_nodes) * k_ * b_ * std::min(31.0, per_node) * 1e-6;
    rows.push_back(r);
  }
  std::vector<ScaleLevel> rows;

 private:
  int workers_, k_, b_;
  double cpu0_ = 0;
  uint64_t replies_ = 0, reply_nodes_ = 0, heartbeats_ = 0;
};

/// One N of --scale.
struct ScaleRun {
  int workers = 0;
  double wall = 0, load = 0;
  double coordinator_cpu = 0, levels_cpu = 0, merge = 0, coordinator_rss_mb = 0;
  double workers_cpu = 0, worker_cpu_max = 0, worker_rss_max_mb = 0, worker_rss_mean_mb = 0;
  uint64_t evaluations = 0, replies = 0, heartbeats = 0, sent = 0, bytes_received = 0, bytes_sent = 0;
  int rounds = 0, lost = 0, reaped = 0;
  bool identical = false;
  std::map<std::string, double> worker_cpu;  ///< CpuFields summed over the workers
};

/// y ~ sum_j c_j x_j (least squares) with every c_j >= 0: the best unconstrained fit over the
/// subsets of the terms whose coefficients all come out >= 0 (a handful of terms: exhaustive).
/// Columns are scaled to unit RMS before solving (cells and replies differ by orders of magnitude).
std::vector<double> FitNonNegative(const std::vector<std::vector<double>>& x, const std::vector<double>& y) {
  const size_t m = x.empty() ? 0 : x[0].size();
  std::vector<double> best(m, 0.0);
  double best_sse = 0;
  for (double v : y) best_sse += v * v;
  std::vector<double> scale(m, 0.0);
  for (const auto& row : x)
    for (size_t j = 0; j < m; ++j) scale[j] += row[j] * row[j];
  for (double& s : scale) s = s > 0 ? std::sqrt(s / double(x.size())) : 1.0;
  for (unsigned mask = 1; mask < (1u << m); ++mask) {
    std::vector<size_t> cols;
    for (size_t j = 0; j < m; ++j)
      if (mask & (1u << j)) cols.push_back(j);
    const size_t k = cols.size();
    std::vector<std::vector<double>> a(k, std::vector<double>(k + 1, 0.0));  // normal equations
    for (size_t i = 0; i < x.size(); ++i)
      for (size_t p = 0; p < k; ++p) {
        const double xp = x[i][cols[p]] / scale[cols[p]];
        for (size_t q = 0; q < k; ++q) a[p][q] += xp * x[i][cols[q]] / scale[cols[q]];
        a[p][k] += xp * y[i];
      }
    bool singular = false;
    for (size_t p = 0; p < k && !singular; ++p) {
      size_t piv = p;
      for (size_t r = p + 1; r < k; ++r)
        if (std::fabs(a[r][p]) > std::fabs(a[piv][p])) piv = r;
      std::swap(a[p], a[piv]);
      if (std::fabs(a[p][p]) < 1e-12) singular = true;
      for (size_t r = 0; r < k && !singular; ++r)
        if (r != p) {
          const double f = a[r][p] / a[p][p];
          for (size_t c = p; c <= k; ++c) a[r][c] -= f * a[p][c];
        }
    }
    if (singular) continue;
    std::vector<double> coef(m, 0.0);
    bool negative = false;
    for (size_t p = 0; p < k; ++p) {
      coef[cols[p]] = a[p][k] / a[p][p] / scale[cols[p]];
      negative = negative || coef[cols[p]] < 0;
    }
    if (negative) continue;
    double sse = 0;
    for (size_t i = 0; i < x.size(); ++i) {
      double f = 0;
      for (size_t j = 0; j < m; ++j) f += coef[j] * x[i][j];
      sse += (f - y[i]) * (f - y[i]);
    }
    if (sse < best_sse) best_sse = sse, best = coef;
  }
  return best;
}

double Dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) s += a[i] * b[i];
  return s;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

std::string Human(double bytes) {
  char buf[32];
  const char* units[] = {"B", "kB", "MB", "GB", "TB", "PB"};
  int u = 0;
  while (bytes >= 1000 && u < 5) bytes /= 1000, ++u;
  std::snprintf(buf, sizeof buf, u ? "%.3g %s" : "%.0f %s", bytes, units[u]);
  return buf;
}

std::string Duration(double s) {
  char buf[32];
  if (s >= 86400)
    std::snprintf(buf, sizeof buf, "%.3g d", s / 86400);
  else if (s >= 3600)
    std::snprintf(buf, sizeof buf, "%.3g h", s / 3600);
  else if (s >= 60)
    std::snprintf(buf, sizeof buf, "%.3g min", s / 60);
  else
    std::snprintf(buf, sizeof buf, "%.3g s", s);
  return buf;
}

/// What the projection takes from the measurements.
struct Measured {
  std::vector<double> cpu_fit;  ///< seconds per CpuTerms term
  double q_c = 0, q_e = 0;      ///< reply bytes per node, candidate and worker = q_c * s_w^q_e (capped)
  double eval_rate = 0;         ///< evaluations per CPU-second of a worker's level work (one core)
  /// CPU seconds a worker spends per node it answers in a round, whatever its samples there (it
  /// draws the node's candidates and cuts, ranges and encodes every candidate): the fitted slope.
  double per_node_entry = 0;
  double sent_per_node_k = 0;  ///< control bytes per frontier node and candidate
  double worker_base_mb = 0;   ///< peak RSS of a worker process (DDS, libraries) whose shard is small
};

/// The paper's job (Shotton et al. 2011, section 4; job.proto's defaults) and the cluster it would
/// run on. Every figure not measured by this bench is here, named.
struct PaperJob {
  int trees = 3, depth = 20;
  double images = 300000;  ///< per tree (3 trees: ~1M images)
  double pixels = 2000;    ///< samples per image
  double k = 2000;         ///< candidate features per node
  double bins = 51;        ///< 50 thresholds + 1
  double parts = 31;       ///< all present in every node (an upper bound: deep nodes hold fewer)
  double batch_bytes = 64.0 * (1 << 20);  ///< CoordinatorOptions::max_batch_bytes (below histogram_memory_mb)
  double round_latency_s = 0.5e-3;        ///< per request/reply round: LAN round trip and wake-ups
  double nic_bytes_per_s = 1.25e9;        ///< the coordinator's 10 Gb/s link, which every reply crosses
  /// Per image a worker holds 75.7 kB (compact frames + 13-byte samples, service.md "Memory"),
  /// its compact frames twice (frame cache and SampleSet, 49.7 kB) and while routing a second copy
  /// of the per-sample columns (26 kB).
  double worker_bytes_per_image = 75.7e3 + 49.7e3 + 26e3;
  double renderer_mb = 300;  ///< meshes, EGL (service.md: ~300 MB with 200 images)
};

/// One level of one tree of the paper's job on `w` workers of `cores` cores each; hand-off
/// (nodes of at most `handoff` samples trained whole by one worker) when handoff > 0.
struct ProjectedLevel {
  double nodes = 0, samples_per_node = 0, rounds = 0, replies = 0, bytes = 0, sent = 0;
  double coordinator = 0, compute = 0, network = 0, latency = 0, wall = 0;
  std::vector<double> by_term =
      std::vector<double>(kTerms, 0.0);  ///< the coordinator's seconds per CpuTerms term
  double held_per_round = 0;             ///< reply bytes one merge holds at once (a round's)
  double reply_per_worker = 0;           ///< bytes of one worker's reply in one round
  bool handed_off = false, inside_subtree = false;
};

/// Where the level's histograms are summed: at the coordinator (the service today); through a
/// reduction tree of fan-in 10 (workers sum their children's replies, the coordinator gets 10);
/// or sharded over the workers (reduce-scatter: each worker sums 1/W of each round's nodes from
/// every worker's slice and picks their splits, as LightGBM's data-parallel learner does).
enum class MergeAt { kCoordinator, kTree, kSharded };
constexpr double kTreeFanIn = 10;

ProjectedLevel ProjectLevel(const PaperJob& j, const Measured& m, int d, double w, double cores,
                            double handoff, MergeAt at = MergeAt::kCoordinator) {
  ProjectedLevel p;
  const double s_tree = j.images * j.pixels;
  p.nodes = std::ldexp(1.0, d);
  p.samples_per_node = s_tree / p.nodes;
  const double s = p.samples_per_node;
  // Every level evaluates every sample on every candidate, wherever it is trained; and every
  // worker answers every node of the level's rounds twice (ranges, histograms) whatever its
  // samples there (subtree levels: each node once, by one worker).
  p.compute = s_tree * j.k / (w * cores * m.eval_rate);
  const double node_work = m.per_node_entry / cores;
  std::vector<double> t(kTerms, 0.0);
  double hops = 1;  // merges one after the other (the reduction tree's depth)
  if (handoff > 0 && s <= handoff) {
    if (d > 0 && 2 * s <= handoff) {
      p.inside_subtree = true;  // decided inside the subtree of an earlier level: no coordinator
    } else {
      // One SubtreeResult per node (tasks go a few per message): the per-reply cost, no merge.
      p.handed_off = true;
      p.replies = p.nodes;
      p.compute += p.nodes / w * node_work;
      t = CpuTerms(p.replies, 0, 0);
      t[0] = 0;
    }
  } else {
    const double slots = std::min(j.parts, s);
    const bool sample_bins = s < 4 * j.bins * slots;  // engine::UseSampleBins
    const double plan_bytes = sample_bins ? s * (j.k + 1) : j.k * j.bins * slots * 4;  // PlanHistogramBytes
    const double per_batch = std::max(1.0, std::floor(j.batch_bytes / plan_bytes));
    p.rounds = 2 * std::ceil(p.nodes / per_batch) + (d == 0 ? 1 : 0);  // ranges + histograms (+ census)
    p.replies = w * p.rounds;
    p.compute += 2 * p.nodes * node_work;
    auto bytes_from = [&](double senders) {
      const double s_w = s / senders;
      return senders * p.nodes * j.k *
             std::min({m.q_c * std::pow(s_w, m.q_e), 2 * j.bins * j.parts, 12 + 3 * s_w});
    };
    p.bytes = bytes_from(w);
    p.sent = m.sent_per_node_k * p.nodes * j.k * w;  // written once, delivered to every worker
    const double mcells = p.nodes * j.k * j.bins * slots * 1e-6;
    // Every worker answers every round (no node is fused: its samples lie in frames of every
    // worker), so replies = W x rounds.
    // Requests go to every worker, one copy each (DDS over UDP writes to each reader's unicast
    // locator), the replies come back: the coordinator's link carries the larger of the two.
    if (at == MergeAt::kCoordinator) {
      t = CpuTerms(p.replies, p.bytes, mcells);
      p.network = std::max(p.bytes, p.sent) / j.nic_bytes_per_s;
    } else if (at == MergeAt::kTree) {
      // Each merge sums kTreeFanIn replies; the top one's replies each cover W / fan-in workers
      // and carry the bytes of that many samples (sparse histograms of disjoint samples do not
      // shrink when summed): the top merge costs what the coordinator pays with fan-in workers.
      // The lower hops (in parallel within a hop, one hop after the other) cost at most as much.
      const double f = std::min(kTreeFanIn, w);
      hops = std::max(1.0, std::ceil(std::log(w) / std::log(kTreeFanIn) - 1e-9));
      t = CpuTerms(f * p.rounds, bytes_from(f), mcells / hops);  // the split search once, at the top
      p.network =
          std::max(bytes_from(f), p.sent / w * f) / j.nic_bytes_per_s;  // requests relayed down the tree
    } else {
      // Each worker merges 1/W of the nodes: it gets a slice of every worker's reply, and the
      // merged ranges go to every worker peer to peer (an all-gather): each link carries 1/W.
      t = CpuTerms(p.replies, p.bytes / w, mcells / w);
      p.network = std::max(p.bytes, p.sent) / w / j.nic_bytes_per_s;
    }
    p.latency = p.rounds * j.round_latency_s * hops;
    p.held_per_round = t[2] * 1e6 / p.rounds;  // what one merge holds: a round's replies
    p.reply_per_worker = p.bytes / w / p.rounds;
  }
  for (size_t i = 0; i < t.size(); ++i) p.by_term[i] = m.cpu_fit[i] * t[i] * hops;
  p.coordinator = Dot(m.cpu_fit, t) * hops;
  // Rounds are synchronous: the workers wait while the level's histograms are merged.
  p.wall = p.compute + p.coordinator + p.network * hops + p.latency;
  return p;
}

struct ProjectedJob {
  double wall = 0, coordinator = 0, compute = 0, network = 0, latency = 0;
  std::vector<double> by_term = std::vector<double>(kTerms, 0.0);
  double bytes = 0, peak_level_bytes = 0, peak_level_sent = 0, sent = 0, rounds = 0, replies = 0;
  int peak_level = 0;
  double worker_peak = 0, coordinator_held = 0;  ///< bytes
};

ProjectedJob ProjectJob(const PaperJob& j, const Measured& m, double w, double cores, double handoff,
                        MergeAt at = MergeAt::kCoordinator) {
  ProjectedJob r;
  double max_reply = 0;
  for (int d = 0; d < j.depth; ++d) {
    const ProjectedLevel p = ProjectLevel(j, m, d, w, cores, handoff, at);
    r.wall += p.wall, r.coordinator += p.coordinator, r.compute += p.compute;
    r.network += p.network, r.latency += p.latency;
    for (size_t i = 0; i < r.by_term.size(); ++i) r.by_term[i] += p.by_term[i];
    r.bytes += p.bytes, r.sent += p.sent, r.rounds += p.rounds, r.replies += p.replies;
    if (p.bytes > r.peak_level_bytes) r.peak_level_bytes = p.bytes, r.peak_level = d;
    r.peak_level_sent = std::max(r.peak_level_sent, p.sent);
    r.coordinator_held = std::max(r.coordinator_held, p.held_per_round);
    max_reply =
        std::max(max_reply, p.reply_per_worker + (at == MergeAt::kCoordinator ? 0 : p.held_per_round));
  }
  for (double* v : {&r.wall, &r.coordinator, &r.compute, &r.network, &r.latency, &r.bytes, &r.sent, &r.rounds,
                    &r.replies})
    *v *= j.trees;
  for (double& v : r.by_term) v *= j.trees;
  // Trees one after the other: a worker holds one tree's shard at a time.
  r.worker_peak = m.worker_base_mb * 1e6 + j.renderer_mb * 1e6 + j.images / w * j.worker_bytes_per_image +
                  j.batch_bytes + max_reply;
  return r;
}

void PrintProjection(const Measured& m) {
  const PaperJob j;
  std::printf(
      "\nprojection: the paper's job (3 trees, depth 20, 300k images per tree = ~1M images, 2000 pixels per "
      "image, 2000 candidates x 50 thresholds), hand-off off (every level by histogram rounds, as measured "
      "here)\n");
  std::printf(
      "assumptions: %.3g evaluations per CPU-second per core and %.3f ms per node a worker answers in a "
      "round (fitted here: the workers' level work), cores scale perfectly; coordinator CPU per level = fit "
      "3 on one core; reply bytes = W x nodes x K x "
      "%.3g x s_w^%.3f (fitted here, capped as traffic_model.md); %.0f MiB batches, all 31 parts in every "
      "node (rounds = 2 x batches); %.1f ms per round; %.0f Gb/s into the coordinator; rounds synchronous "
      "(workers wait while the coordinator merges); a worker holds "
      "%.0f MB (measured: process, DDS) + %.0f MB renderer + %.0f kB per image of its shard + a batch + a "
      "reply\n",
      m.eval_rate, m.per_node_entry * 1e3, m.q_c, m.q_e, j.batch_bytes / (1 << 20), j.round_latency_s * 1e3,
      j.nic_bytes_per_s * 8 / 1e9, m.worker_base_mb, j.renderer_mb, j.worker_bytes_per_image / 1e3);
  std::printf("%8s %6s %10s %10s %10s %6s %10s %16s %16s %10s %10s %10s %10s %12s %12s\n", "workers", "cores",
              "wall", "compute", "coord", "share", "network", "coord % by term", "peak level", "peak sent",
              "job bytes", "rounds", "replies", "worker peak", "coord holds");
  for (double cores : {2.0, 16.0})
    for (double w : {10.0, 100.0, 1000.0}) {
      const ProjectedJob r = ProjectJob(j, m, w, cores, 0);
      char shares[64] = "";
      for (size_t i = 1; i < r.by_term.size(); ++i) {
        const size_t used = std::strlen(shares);
        std::snprintf(shares + used, sizeof shares - used, "%s%.0f", i > 1 ? "/" : "",
                      100 * r.by_term[i] / r.coordinator);
      }
      std::printf(
          "%8.0f %6.0f %10s %10s %10s %5.0f%% %10s %16s %11s (%2d) %10s %10s %10.3g %10.3g %12s %12s\n", w,
          cores, Duration(r.wall).c_str(), Duration(r.compute).c_str(), Duration(r.coordinator).c_str(),
          100 * r.coordinator / r.wall, Duration(r.network).c_str(), shares,
          Human(r.peak_level_bytes).c_str(), r.peak_level, Human(r.peak_level_sent).c_str(),
          Human(r.bytes).c_str(), r.rounds, r.replies, Human(r.worker_peak).c_str(),
          Human(r.coordinator_held).c_str());
    }
  std::printf(
      "(wall = compute + coordinator + network + round latency, summed over levels; share: the "
      "coordinator's CPU / wall; network: the coordinator's link, the larger direction per level; by term: "
      "replies / MB / dense cells; \"peak level\": the largest level's reply bytes in one tree, its level in "
      "brackets; \"peak sent\": the largest level's control bytes, every worker's copy; \"coord holds\": one "
      "round's replies)\n");
  std::printf(
      "\nper level of one tree, 100 workers of 16 cores, hand-off off (bytes sent: every worker's "
      "copy):\n%5s %8s "
      "%12s %8s %10s %12s %10s %10s %10s %10s %10s\n",
      "level", "nodes", "samples/node", "rounds", "replies", "bytes recv", "bytes sent", "compute", "coord",
      "network", "wall");
  for (int d = 0; d < j.depth; ++d) {
    const ProjectedLevel p = ProjectLevel(j, m, d, 100, 16, 0);
    std::printf("%5d %8.0f %12.3g %8.0f %10.3g %12s %10s %10s %10s %10s %10s\n", d, p.nodes,
                p.samples_per_node, p.rounds, p.replies, Human(p.bytes).c_str(), Human(p.sent).c_str(),
                Duration(p.compute).c_str(), Duration(p.coordinator).c_str(), Duration(p.network).c_str(),
                Duration(p.wall).c_str());
  }
  // What would lift it: the same job with the histograms summed elsewhere, or fewer levels of
  // histograms (hand-off; the frames the subtrees need, rendered or fetched, not counted).
  struct Variant {
    const char* name;
    double handoff;
    MergeAt at;
  };
  const Variant variants[] = {{"as is", 0, MergeAt::kCoordinator},
                              {"hand-off 4096 (job default)", 4096, MergeAt::kCoordinator},
                              {"hand-off 50000", 50000, MergeAt::kCoordinator},
                              {"reduction tree, fan-in 10", 0, MergeAt::kTree},
                              {"merge sharded over the workers", 0, MergeAt::kSharded},
                              {"sharded + hand-off 4096", 4096, MergeAt::kSharded}};
  std::printf(
      "\nwhat would lift it: wall (share of the busiest merger's CPU; \"merger\": the coordinator, the top "
      "of the tree, or each worker when sharded)\n%-32s",
      "");
  for (double cores : {2.0, 16.0})
    for (double w : {10.0, 100.0, 1000.0}) std::printf(" %6.0f x %-2.0f      ", w, cores);
  std::printf("\n");
  for (const Variant& v : variants) {
    std::printf("%-32s", v.name);
    for (double cores : {2.0, 16.0})
      for (double w : {10.0, 100.0, 1000.0}) {
        const ProjectedJob r = ProjectJob(j, m, w, cores, v.handoff, v.at);
        char cell[32];
        std::snprintf(cell, sizeof cell, "%s (%.0f%%)", Duration(r.wall).c_str(),
                      100 * r.coordinator / r.wall);
        std::printf(" %-17s", cell);
      }
    std::printf("\n");
  }
  // Where the coordinator becomes the bottleneck: the worker count where it takes half the wall
  // time, and the one where adding workers stops paying (lowest wall).
  std::printf("\nwhere the merge becomes the bottleneck:\n");
  for (const Variant& v : variants)
    for (double cores : {2.0, 16.0}) {
      double half = 0, best_w = 1, best_wall = 1e300;
      for (double w = 1; w <= 100000; w = std::max(w + 1, std::round(w * 1.05))) {
        const ProjectedJob r = ProjectJob(j, m, w, cores, v.handoff, v.at);
        if (!half && r.coordinator >= 0.5 * r.wall) half = w;
        if (r.wall < best_wall) best_wall = r.wall, best_w = w;
      }
      const ProjectedJob at = ProjectJob(j, m, best_w, cores, v.handoff, v.at);
      const std::string lowest = best_w * 1.05 > 100000
                                     ? std::string("still falling at 100000 workers")
                                     : "lowest at " + std::to_string(int(best_w)) + " workers";
      std::printf(
          "  %-32s %2.0f cores per worker: merger CPU >= half the wall from %s workers; wall %s: %s (merger "
          "%s of it)\n",
          v.name, cores, half ? std::to_string(int(half)).c_str() : "(none up to 100000)", lowest.c_str(),
          Duration(best_wall).c_str(), Duration(at.coordinator).c_str());
    }
}

/// --scale: one service run per worker count, then the fits, their check and the projection.
int Scale(const std::string& self, v1::TrainerConfig config, engine::TrainParams params,
          const std::vector<int>& counts, int repeat, uint32_t domain, long long subtree_max,
          bool sample_lists, const std::string& csv_path, const std::vector<uint8_t>& ref_bytes,
          uint64_t engine_evaluations, double engine_cpu) {
  const uint64_t sm = subtree_max > 0 ? uint64_t(subtree_max) : 0;
  config.set_subtree_max_samples(sm);
  params.subtree_max_samples = sm;
  const int k = params.candidate_features, bins = params.thresholds_per_feature + 1;
  std::vector<ScaleLevel> all_rows;  // every run's levels; `rows`: their medians over the repeats
  std::vector<ScaleRun> all_runs;
  std::printf(
      "\nscale: one job, %zu worker counts x %d sweep(s), 1 thread per worker process, subtree hand-off %s; "
      "coordinator CPU from the level's start to its end (all its threads), workers' CPU from wait4\n",
      counts.size(), repeat, sm ? ("at <= " + std::to_string(sm) + " samples").c_str() : "off");
  std::printf(
      "(per level: rounds = request/reply rounds; replies = histogram replies received; hb = heartbeats "
      "received; sent = control messages written, each delivered to all N workers; coord_ms = the "
      "coordinator's CPU; merge_ms = its merge wall time)\n");
  // Sweeps one after the other, so that a change in the machine's load falls on every N alike.
  for (int sweep = 0; sweep < repeat; ++sweep)
    for (size_t ci = 0; ci < counts.size(); ++ci) {
      const int n = counts[ci];
      const uint32_t dom = (domain + 1 + uint32_t(ci)) % 233;
      const std::string job_id =
          "scale-" + std::to_string(::getpid()) + "-" + std::to_string(n) + "-" + std::to_string(sweep);
      ScaleRun run;
      run.workers = n;
      std::vector<pid_t> pids;
      std::vector<std::string> stats_files;
      const double t0 = proto::dds::NowSeconds();
      for (int i = 0; i < n; ++i) {
        stats_files.push_back(
            (std::filesystem::temp_directory_path() / (job_id + "-w" + std::to_string(i) + ".stats"))
                .string());
        const pid_t pid =
            Spawn({self, "--worker-process", "--domain", std::to_string(dom), "--job", job_id, "--id",
                   "scale-w" + std::to_string(i), "--stats", stats_files.back(), "--lease-ms", "10000"});
        if (pid < 0) return std::fprintf(stderr, "distributed: cannot start a worker process\n"), 1;
        pids.push_back(pid);
      }
      coordinator::CoordinatorOptions co;
      co.domain = dom;
      co.job_id = job_id;
      co.min_workers = n;                                  // waits (polling DDS) until all n joined
      co.worker_wait = std::chrono::milliseconds(600000);  // 32 processes on 2 cores discover slowly
      co.lease = std::chrono::milliseconds(10000);
      co.heartbeat_timeout = std::chrono::milliseconds(60000);
      co.subtree_sample_lists = sample_lists;
      co.merge_threads = std::max(1, int(std::thread::hardware_concurrency()) - n);
      co.log = [](const std::string&) {};
      ScaleObserver obs(n, k, bins);
      co.observer = &obs;
      ResetPeakRss();
      const double c0 = ProcessCpu();
      core::Result<core::Forest> forest = core::Status(core::ErrorCode::kInternal, "not run");
      {
        coordinator::DistCoordinator coord(config, params, co);
        forest = coord.Train();
        run.lost = coord.workers_lost();
      }
      run.coordinator_cpu = ProcessCpu() - c0;
      run.coordinator_rss_mb = PeakRssMb();
      // Workers leave on JOB_DONE: reap each, with its own CPU and peak RSS.
      const double deadline = proto::dds::NowSeconds() + 300;
      std::vector<double> rss;
      for (pid_t p : pids) {
        int status = 0;
        rusage ru{};
        pid_t got = 0;
        while ((got = ::wait4(p, &status, WNOHANG, &ru)) == 0) {
          if (proto::dds::NowSeconds() > deadline) {
            ::kill(p, SIGKILL);
            got = ::wait4(p, &status, 0, &ru);
            break;
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (got != p) continue;
        run.reaped += WIFEXITED(status) && WEXITSTATUS(status) == 0;
        // Not ru_maxrss: posix_spawn starts the child in this process's memory (vfork), and Linux
        // keeps that memory's peak as the child's; each worker reports its own VmHWM instead.
        const double cpu = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                           1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
        run.workers_cpu += cpu;
        run.worker_cpu_max = std::max(run.worker_cpu_max, cpu);
      }
      run.wall = proto::dds::NowSeconds() - t0;
      run.load = LoadAverage();
      for (const std::string& path : stats_files) {
        std::map<std::string, double> one;
        if (AddStats(path, &one)) {
          rss.push_back(one["peak_rss_mb"]);
          for (const auto& [key, value] : one) run.worker_cpu[key] += value;
        }
        std::filesystem::remove(path);
      }
      for (double r : rss)
        run.worker_rss_max_mb = std::max(run.worker_rss_max_mb, r), run.worker_rss_mean_mb += r;
      if (!rss.empty()) run.worker_rss_mean_mb /= double(rss.size());
      if (!forest.ok())
        return std::fprintf(stderr, "%d workers: %s\n", n, forest.status().ToString().c_str()), 1;
      run.identical = core::SerializeForest(*forest) == ref_bytes;
      for (const ScaleLevel& r : obs.rows) {
        run.levels_cpu += r.cpu_s, run.merge += r.merge_s, run.evaluations += r.evaluations;
        run.replies += r.replies, run.heartbeats += r.heartbeats, run.sent += r.sent, run.rounds += r.rounds;
        run.bytes_received += r.bytes_received, run.bytes_sent += r.bytes_sent;
      }
      for (ScaleLevel& r : obs.rows) r.sweep = sweep;
      std::printf(
          "\nsweep %d: %d worker process(es): %.1f s wall (load average %.1f); coordinator %.3f CPU s "
          "(levels %.3f, "
          "outside them %.3f: start-up, discovery, shards, teardown), merge %.3f s, process peak RSS %.0f "
          "MB; "
          "workers "
          "%.2f CPU s (mean %.3f, max %.3f per worker), peak RSS per worker max %.0f MB, mean %.0f MB; %d of "
          "%d exited normally, %d lost; forest identical to the engine's: %s\n",
          sweep + 1, n, run.wall, run.load, run.coordinator_cpu, run.levels_cpu,
          run.coordinator_cpu - run.levels_cpu, run.merge, run.coordinator_rss_mb, run.workers_cpu,
          run.workers_cpu / n, run.worker_cpu_max, run.worker_rss_max_mb, run.worker_rss_mean_mb, run.reaped,
          n, run.lost, run.identical ? "yes" : "NO");
      std::printf("  %4s %5s %6s %8s %6s %8s %6s %6s %14s %11s %9s %9s %8s\n", "tree", "level", "nodes",
                  "samples", "rounds", "replies", "hb", "sent", "bytes_recv", "bytes_sent", "coord_ms",
                  "merge_ms", "level_s");
      for (const ScaleLevel& r : obs.rows)
        std::printf("  %4d %5d %6zu %8llu %6d %8llu %6llu %6llu %14llu %11llu %9.1f %9.1f %8.3f\n", r.tree,
                    r.level, r.nodes, (unsigned long long)r.samples, r.rounds, (unsigned long long)r.replies,
                    (unsigned long long)r.heartbeats, (unsigned long long)r.sent,
                    (unsigned long long)r.bytes_received, (unsigned long long)r.bytes_sent, r.cpu_s * 1e3,
                    r.merge_s * 1e3, r.level_s);
      std::fflush(stdout);
      all_rows.insert(all_rows.end(), obs.rows.begin(), obs.rows.end());
      all_runs.push_back(run);
    }

  // Medians over the sweeps: per (N, tree, level) the timed figures (the counts are the same in
  // every sweep but the heartbeats'), per N the run's.
  std::vector<ScaleLevel> rows;
  {
    std::map<std::tuple<int, int, int>, std::vector<const ScaleLevel*>> by;
    for (const ScaleLevel& r : all_rows) by[{r.workers, r.tree, r.level}].push_back(&r);
    for (const int n : counts)
      for (const auto& [key, v] : by) {
        if (std::get<0>(key) != n) continue;
        ScaleLevel m = *v.front();
        auto med = [&](double ScaleLevel::*f) {
          std::vector<double> x;
          for (const ScaleLevel* r : v) x.push_back(r->*f);
          return Median(x);
        };
        m.cpu_s = med(&ScaleLevel::cpu_s), m.merge_s = med(&ScaleLevel::merge_s),
        m.level_s = med(&ScaleLevel::level_s);
        std::vector<double> hb;
        for (const ScaleLevel* r : v) hb.push_back(double(r->heartbeats));
        m.heartbeats = uint64_t(Median(hb));
        rows.push_back(m);
      }
  }
  std::vector<ScaleRun> runs;
  for (const int n : counts) {
    std::vector<const ScaleRun*> v;
    for (const ScaleRun& r : all_runs)
      if (r.workers == n) v.push_back(&r);
    ScaleRun m = *v.front();
    auto med = [&](double ScaleRun::*f) {
      std::vector<double> x;
      for (const ScaleRun* r : v) x.push_back(r->*f);
      return Median(x);
    };
    for (double ScaleRun::*f :
         {&ScaleRun::wall, &ScaleRun::load, &ScaleRun::coordinator_cpu, &ScaleRun::levels_cpu,
          &ScaleRun::merge, &ScaleRun::coordinator_rss_mb, &ScaleRun::workers_cpu, &ScaleRun::worker_cpu_max,
          &ScaleRun::worker_rss_max_mb, &ScaleRun::worker_rss_mean_mb})
      m.*f = med(f);
    for (const auto& [key, value] : m.worker_cpu) {
      std::vector<double> x;
      for (const ScaleRun* r : v) x.push_back(r->worker_cpu.count(key) ? r->worker_cpu.at(key) : 0.0);
      m.worker_cpu[key] = Median(x);
    }
    for (const ScaleRun* r : v) m.identical = m.identical && r->identical, m.lost = std::max(m.lost, r->lost);
    runs.push_back(m);
  }

  // Per N, side by side.
  auto g = [](const ScaleRun& r, const char* key) {
    return r.worker_cpu.count(key) ? r.worker_cpu.at(key) : 0.0;
  };
  std::printf("\nscale summary, medians over %d sweep(s) (engine, 1 thread: %.2f CPU s, %llu evaluations)\n",
              repeat, engine_cpu, (unsigned long long)engine_evaluations);
  std::printf("%4s %8s %9s %9s %8s %8s %7s %9s %9s %7s %10s %9s %9s %10s %8s %9s %9s\n", "N", "wall_s",
              "coord_s", "levels_s", "merge_s", "replies", "rounds", "MB_recv", "MB_sent", "sent",
              "workers_s", "start_s", "dds_s", "eval/cpu_s", "rss_MB", "coord_MB", "identical");
  for (const ScaleRun& r : runs)
    std::printf(
        "%4d %8.1f %9.3f %9.3f %8.3f %8llu %7d %9.2f %9.3f %7llu %10.2f %9.2f %9.2f %10.3g %8.0f %9.0f %9s\n",
        r.workers, r.wall, r.coordinator_cpu, r.levels_cpu, r.merge, (unsigned long long)r.replies, r.rounds,
        double(r.bytes_received) / 1e6, double(r.bytes_sent) / 1e6, (unsigned long long)r.sent, r.workers_cpu,
        g(r, "process_at_start") + g(r, "participant"), g(r, "other_threads"),
        double(r.evaluations) /
            std::max(1e-9, g(r, "level_compute") + g(r, "level_encode") + g(r, "decisions")),
        r.worker_rss_max_mb, r.coordinator_rss_mb,
        r.identical && r.evaluations == engine_evaluations ? "yes" : "NO");
  std::printf(
      "(coord_s: the coordinator's CPU over the run, levels_s: of it within levels; sent: control messages "
      "written, each delivered to all N workers; workers_s: all worker processes' CPU, of which start_s "
      "start-up and DDS participant, dds_s their DDS and heartbeat threads; eval/cpu_s: evaluations per "
      "CPU-second of the workers' level work (ranges, histograms, replies, routing); rss_MB: the largest "
      "worker's "
      "peak RSS (VmHWM); coord_MB: this process's peak RSS during the run, which includes the engine's "
      "freed heap, kept (KeepFreedMemory))\n");
  // Per level across N: the coordinator's CPU ms, merge ms and MB received.
  std::set<std::pair<int, int>> levels;
  std::map<std::tuple<int, int, int>, const ScaleLevel*> at;
  for (const ScaleLevel& r : rows) levels.insert({r.tree, r.level}), at[{r.workers, r.tree, r.level}] = &r;
  for (int what = 0; what < 3; ++what) {
    std::printf("\n%s per level (medians), N = ", what == 0   ? "coordinator CPU ms"
                                                  : what == 1 ? "merge ms"
                                                              : "MB received");
    for (const ScaleRun& r : runs) std::printf("%d ", r.workers);
    std::printf("\n%4s %5s", "tree", "level");
    for (const ScaleRun& r : runs) std::printf(" %8d", r.workers);
    std::printf("\n");
    for (const auto& [t, l] : levels) {
      std::printf("%4d %5d", t, l);
      for (const ScaleRun& r : runs) {
        const auto it = at.find({r.workers, t, l});
        const ScaleLevel* s = it == at.end() ? nullptr : it->second;
        std::printf(" %8.2f", !s          ? 0.0
                              : what == 0 ? s->cpu_s * 1e3
                              : what == 1 ? s->merge_s * 1e3
                                          : double(s->bytes_received) / 1e6);
      }
      std::printf("\n");
    }
  }
  if (!csv_path.empty()) {
    std::ofstream csv(csv_path);
    csv << "workers,tree,level,nodes,split,samples,evaluations,bytes_received,bytes_sent,merge_s,level_s,"
           "candidates,bins,images_per_tree,pixels_per_image,rounds,replies,reply_nodes,heartbeats,sent,"
           "coordinator_cpu_s,sweep\n";
    for (const ScaleLevel& r : all_rows)
      csv << r.workers << ',' << r.tree << ',' << r.level << ',' << r.nodes << ",0," << r.samples << ','
          << r.evaluations << ',' << r.bytes_received << ',' << r.bytes_sent << ',' << r.merge_s << ','
          << r.level_s << ',' << k << ',' << bins << ',' << config.images_per_tree() << ','
          << config.pixels_per_image() << ',' << r.rounds << ',' << r.replies << ',' << r.reply_nodes << ','
          << r.heartbeats << ',' << r.sent << ',' << r.cpu_s << ',' << r.sweep << '\n';
    std::printf("\nwrote %zu per-level rows (every sweep) to %s\n", all_rows.size(), csv_path.c_str());
  }

  // Fits on N <= 8, checked on N > 8.
  std::vector<const ScaleLevel*> fit_rows, check_rows;
  for (const ScaleLevel& r : rows) (r.workers <= 8 ? fit_rows : check_rows).push_back(&r);
  if (fit_rows.size() < 4) return std::printf("scale: fewer than 4 levels with N <= 8: no fit\n"), 1;
  std::vector<std::vector<double>> x1, x2;
  std::vector<double> y, ym;
  for (const ScaleLevel* r : fit_rows) {
    x1.push_back({1.0, double(r->replies)});
    x2.push_back(CpuTerms(*r));
    y.push_back(r->cpu_s);
    ym.push_back(r->merge_s);
  }
  const std::vector<std::vector<double>>& xm = x2;
  const std::vector<double> f1 = FitNonNegative(x1, y), f2 = FitNonNegative(x2, y),
                            fm = FitNonNegative(xm, ym);
  // Fit 1b: what one more reply costs the coordinator, level by level: cpu = a_level + b x replies
  // with an intercept per (tree, level) (every N trains the same forest, so the same levels) and
  // one slope: the level's own work (nodes, split search) drops out, what grows with the workers
  // stays.
  std::map<std::pair<int, int>, std::pair<double, double>> level_mean;  // (tree, level) -> mean replies, cpu
  std::map<std::pair<int, int>, int> level_n;
  for (const ScaleLevel* r : fit_rows) {
    auto& mean = level_mean[{r->tree, r->level}];
    mean.first += double(r->replies), mean.second += r->cpu_s, ++level_n[{r->tree, r->level}];
  }
  for (auto& [key, mean] : level_mean) mean.first /= level_n[key], mean.second /= level_n[key];
  double sxy = 0, sxx = 0;
  for (const ScaleLevel* r : fit_rows) {
    const auto& mean = level_mean[{r->tree, r->level}];
    sxy += (double(r->replies) - mean.first) * (r->cpu_s - mean.second);
    sxx += (double(r->replies) - mean.first) * (double(r->replies) - mean.first);
  }
  const double per_reply = sxx > 0 ? sxy / sxx : 0;
  auto fit1b = [&](const ScaleLevel& r) {
    const auto it = level_mean.find({r.tree, r.level});
    return it == level_mean.end() ? 0.0
                                  : it->second.second + per_reply * (double(r.replies) - it->second.first);
  };
  auto print_fit = [](const char* what, const std::vector<double>& f) {
    std::printf("  %s =", what);
    for (size_t i = 0; i < f.size(); ++i)
      std::printf("%s %.4g ms %s", i ? " +" : "", f[i] * 1e3, kTermNames[i]);
    std::printf("\n");
  };
  std::printf(
      "\nfits on the %zu levels of N <= 8 (least squares, coefficients >= 0; a term left at 0 did not "
      "help):\n",
      fit_rows.size());
  std::printf("  fit 1: coordinator CPU per level = %.3f ms + %.4f ms per reply\n", f1[0] * 1e3, f1[1] * 1e3);
  std::printf("  fit 1b: coordinator CPU per level = its own intercept (%zu levels) + %.4f ms per reply\n",
              level_mean.size(), per_reply * 1e3);
  print_fit("fit 2: coordinator CPU per level", f2);
  print_fit("merge: merge time per level", fm);
  // Fit 3, for the projection: fit 2's terms on every N. Checked above, fit 2 over-predicts the
  // larger N (the CPU per MB falls as replies get smaller: 7.4 ms per MB at 1 worker, 5.0 at
  // 32 on the scale job); the paper's replies (0.3-2 MB each) are the size of N = 16-32's here.
  std::vector<std::vector<double>> x3;
  std::vector<double> y3;
  for (const ScaleLevel& r : rows) x3.push_back(CpuTerms(r)), y3.push_back(r.cpu_s);
  const std::vector<double> f3 = FitNonNegative(x3, y3);
  print_fit("fit 3 (every N, for the projection): coordinator CPU per level", f3);
  // Bytes: traffic_model.md's law, bytes = W x n x K x c x s_w^e, fitted the same way (log-log).
  double c_q = 0, e_q = 0;
  {
    std::vector<double> lx, ly;
    for (const ScaleLevel* r : fit_rows)
      if (r->bytes_received > 0 && r->nodes > 0) {
        const double wnk = double(r->workers) * double(r->nodes) * k;
        lx.push_back(std::log(double(r->samples) / double(r->nodes) / r->workers));
        ly.push_back(std::log(double(r->bytes_received) / wnk));
      }
    double mx = 0, my = 0, sxx = 0, sxy = 0;
    for (size_t i = 0; i < lx.size(); ++i) mx += lx[i], my += ly[i];
    mx /= double(lx.size()), my /= double(lx.size());
    for (size_t i = 0; i < lx.size(); ++i)
      sxx += (lx[i] - mx) * (lx[i] - mx), sxy += (lx[i] - mx) * (ly[i] - my);
    e_q = sxx > 0 ? sxy / sxx : 0;
    c_q = std::exp(my - e_q * mx);
  }
  auto q_bytes = [&](const ScaleLevel& r, double c, double e) {
    const double s_w = double(r.samples) / double(r.nodes) / r.workers;
    return double(r.workers) * double(r.nodes) * k *
           std::min({c * std::pow(s_w, e), 2.0 * bins * 31, 12 + 3 * s_w});
  };
  std::printf(
      "  bytes: reply bytes per level = W x nodes x K x %.3g x s_w^%.3f (traffic_model.md's law, fitted "
      "here; its own fit on 1-2 workers: 5.99 x s_w^0.377)\n",
      c_q, e_q);
  if (check_rows.empty()) {
    std::printf("no runs with N > 8: nothing to check the fits against\n");
  } else {
    std::printf("\ncheck on N > 8 (the fits above never saw these runs): per N, summed over the levels\n");
    std::printf("%4s %10s %9s %6s %9s %6s %9s %6s %8s %9s %6s %9s %9s %6s %10s %6s\n", "N", "cpu meas s",
                "fit 1 s", "err", "fit 1b s", "err", "fit 2 s", "err", "merge s", "merge fit", "err",
                "MB meas", "MB law", "err", "MB 1-2 law", "err");
    for (const ScaleRun& run : runs) {
      if (run.workers <= 8) continue;
      double cpu = 0, p1 = 0, p1b = 0, p2 = 0, mg = 0, pm = 0, mb = 0, pb = 0, pb12 = 0;
      for (const ScaleLevel* r : check_rows) {
        if (r->workers != run.workers) continue;
        const std::vector<double> t = CpuTerms(*r);
        cpu += r->cpu_s, p1 += f1[0] + f1[1] * double(r->replies), p1b += fit1b(*r), p2 += Dot(f2, t);
        mg += r->merge_s, pm += Dot(fm, t);
        mb += double(r->bytes_received), pb += q_bytes(*r, c_q, e_q), pb12 += q_bytes(*r, 5.99, 0.377);
      }
      std::printf(
          "%4d %10.3f %9.3f %5.0f%% %9.3f %5.0f%% %9.3f %5.0f%% %8.3f %9.3f %5.0f%% %9.1f %9.1f %5.0f%% "
          "%10.1f "
          "%5.0f%%\n",
          run.workers, cpu, p1, 100 * (p1 / cpu - 1), p1b, 100 * (p1b / cpu - 1), p2, 100 * (p2 / cpu - 1),
          mg, pm, 100 * (pm / mg - 1), mb / 1e6, pb / 1e6, 100 * (pb / mb - 1), pb12 / 1e6,
          100 * (pb12 / mb - 1));
    }
    std::printf(
        "\nper level at N > 8: coordinator CPU ms measured, fit 1, fit 1b, fit 2\n%4s %4s %5s %8s %8s %10s "
        "%9s "
        "%9s %9s\n",
        "N", "tree", "level", "replies", "MB", "measured", "fit 1", "fit 1b", "fit 2");
    std::vector<double> e1, e1b, e2;
    for (const ScaleLevel* r : check_rows) {
      const double a = f1[0] + f1[1] * double(r->replies), ab = fit1b(*r);
      const double b = Dot(f2, CpuTerms(*r));
      if (r->cpu_s > 0)
        e1.push_back(std::fabs(a / r->cpu_s - 1)), e1b.push_back(std::fabs(ab / r->cpu_s - 1)),
            e2.push_back(std::fabs(b / r->cpu_s - 1));
      std::printf("%4d %4d %5d %8llu %8.2f %10.2f %9.2f %9.2f %9.2f\n", r->workers, r->tree, r->level,
                  (unsigned long long)r->replies, double(r->bytes_received) / 1e6, r->cpu_s * 1e3, a * 1e3,
                  ab * 1e3, b * 1e3);
    }
    std::printf("median |error| per level at N > 8: fit 1 %.0f %%, fit 1b %.0f %%, fit 2 %.0f %%\n",
                100 * Median(e1), 100 * Median(e1b), 100 * Median(e2));
  }
  {
    std::printf("fit 3 (fitted on every N), summed over the levels, predicted / measured - 1:");
    for (const ScaleRun& run : runs) {
      double cpu = 0, p3 = 0;
      for (const ScaleLevel& r : rows)
        if (r.workers == run.workers) cpu += r.cpu_s, p3 += Dot(f3, CpuTerms(r));
      std::printf(" N = %d %+.0f %%;", run.workers, 100 * (p3 / cpu - 1));
    }
    std::printf("\n");
  }

  // The projection's measured inputs.
  Measured m;
  m.cpu_fit = f3;
  m.q_c = c_q, m.q_e = e_q;
  {
    // The workers' level work (ranges, histograms, replies, routing; all workers) against N x the
    // node entries each worker answered: the intercept is the evaluations' own cost (the same job
    // at every N), the slope what each worker pays per node whatever its samples there.
    std::vector<std::vector<double>> xw;
    std::vector<double> yw;
    for (const ScaleRun& r : runs) {
      double entries = 0;  // node entries one worker answered, every level
      for (const ScaleLevel& l : rows)
        if (l.workers == r.workers) entries += double(l.reply_nodes) / r.workers;
      xw.push_back({1.0, double(r.workers) * entries});
      yw.push_back(g(r, "level_compute") + g(r, "level_encode") + g(r, "decisions"));
    }
    const std::vector<double> fw = FitNonNegative(xw, yw);
    m.eval_rate = fw[0] > 0 ? double(engine_evaluations) / fw[0] : double(engine_evaluations) / engine_cpu;
    m.per_node_entry = fw[1];
    std::printf("\nworkers' level work (ranges, histograms, replies, routing; all workers), CPU s:");
    for (size_t i = 0; i < runs.size(); ++i)
      std::printf(" N = %d %.2f (fit %.2f);", runs[i].workers, yw[i], Dot(fw, xw[i]));
    std::printf(
        "\n  = %.2f s (the evaluations: %.3g per CPU-second) + %.3f ms per node entry per worker "
        "(%.0f entries per worker); the engine, 1 thread, whole run: %.3g evaluations per CPU-second\n",
        fw[0], m.eval_rate, fw[1] * 1e3, xw.front()[1] / std::max(1, runs.front().workers),
        double(engine_evaluations) / engine_cpu);
    // Control bytes per node and candidate (the histogram requests' ranges), from the levels
    // with rounds of runs with more than one worker (with one, every node is answered fused).
    std::vector<double> per;
    for (const ScaleLevel& r : rows)
      if (r.nodes && r.rounds && r.workers > 1) per.push_back(double(r.bytes_sent) / (double(r.nodes) * k));
    m.sent_per_node_k = Median(per);
    // The smallest mean worker peak measured (it includes this job's shard and a batch of
    // histograms; it grows with N here: shared-memory segments per peer).
    m.worker_base_mb = runs.front().worker_rss_mean_mb;
    for (const ScaleRun& r : runs) m.worker_base_mb = std::min(m.worker_base_mb, r.worker_rss_mean_mb);
  }
  PrintProjection(m);

  bool ok = true;
  for (const ScaleRun& r : runs) ok = ok && r.identical && r.evaluations == engine_evaluations && r.lost == 0;
  if (!ok)
    std::printf(
        "WARNING: a run's forest or evaluation count differs from the engine's, or a worker was lost\n");
  std::printf("coordinator CPU per reply: %.4f ms\n", per_reply * 1e3);
  return ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  poseforest::core::KeepFreedMemory();  // runtime/core/malloc_tuning.h
  if (argc > 2 && !std::strcmp(argv[1], "--neighbour")) return NeighbourProcess(argc, argv);
  if (argc > 1 && !std::strcmp(argv[1], "--worker-process")) return WorkerProcess(argc, argv);
  if (argc > 2 && !std::strcmp(argv[1], "--engine-process")) return EngineProcess(argv[2]);
  // libgomp reads its wait policy when it is loaded: set it and start again.
  if (!std::getenv("OMP_WAIT_POLICY")) {
    ::setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
    ::execv("/proc/self/exe", argv);
    std::fprintf(stderr, "distributed: cannot re-execute with OMP_WAIT_POLICY=PASSIVE: %s\n", std::strerror(errno));
    return 1;
  }
  std::string text = kDefaultJob, csv_path;
  uint32_t domain = 1 + uint32_t(::getpid()) % 200;
  long long subtree_max = -1;
  std::vector<int> worker_counts = {1, 2};
  std::vector<int> scale_counts;  // --scale
  bool skip_off = false;
  int repeat = 1;
  bool engine_only = false, sample_lists = true;
  int neighbour_test = 0;
  std::string cli_path;  // the poseforest program (default: ../bin/poseforest next to this bench)
  bool commands_only = false;
  std::string job_path, keep_logs;
  std::string job_arg;
  CLI::App app(
      "The distributed service against the engine on one job: time per level with N workers over DDS "
      "(and --scale, --neighbour-test, --commands-only); its last line is the headline",
      "bench/distributed");
  app.add_option("JOB.textproto", job_arg, "the job (default: the embedded bench job)")
      ->check(bench::kNonEmptyPath);
  app.add_option("--workers", worker_counts, "worker counts to time, comma-separated")
      ->type_name("N,N")
      ->delimiter(',')
      ->allow_extra_args(false)
      ->capture_default_str()
      ->check(CLI::Range(1, 16));
  app.add_option("--scale", scale_counts,
                 "instead of the runs above: one service run per count of worker processes (1..64)")
      ->type_name("N,N,...")
      ->delimiter(',')
      ->allow_extra_args(false)
      ->check(CLI::Range(1, 64));
  app.add_flag("--commands-only", commands_only,
               "only the two commands as users run them (train --threads N and train --local-workers N)");
  app.add_option("--keep-logs", keep_logs, "with --commands-only: keep the commands' logs in this folder")
      ->type_name("DIR")
      ->check(bench::kNonEmptyPath);
  app.add_flag("--skip-off", skip_off, "only the runs with subtree hand-off");
  app.add_flag("--engine-only", engine_only, "the engine alone (e.g. under a profiler)");
  app.add_option("--neighbour-test", neighbour_test,
                 "instead of the service runs: the 1-thread engine next to a busy loop and next to random "
                 "reads, R rounds")
      ->type_name("R")
      ->check(CLI::Range(1, 50));
  app.add_option("--poseforest", cli_path,
                 "the poseforest program (default: ../bin/poseforest beside this bench)")
      ->type_name("PATH")
      ->check(bench::kNonEmptyPath);
  app.add_flag(
      "--no-sample-lists", [&](int64_t) { sample_lists = false; },
      "subtree tasks without their sample lists (the service before that change)");
  app.add_option("--repeat", repeat, "(engine, headline run) pairs; the last line is the median ratio")
      ->type_name("R")
      ->capture_default_str()
      ->check(CLI::Range(1, 50));
  app.add_option("--domain", domain, "the DDS domain (default: 1 + pid % 200)")
      ->type_name("D")
      ->check(CLI::Range(0, 232));
  app.add_option("--csv", csv_path, "also write the table as CSV")
      ->type_name("FILE")
      ->check(bench::kNonEmptyPath);
  app.add_option("--subtree-max", subtree_max, "the job's subtree_max_samples (the hand-off to one worker)")
      ->type_name("S")
      ->check(CLI::Range(0LL, std::numeric_limits<long long>::max()));
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  if (!job_arg.empty()) {
    std::ifstream in(job_arg);
    if (!in) return std::fprintf(stderr, "bench/distributed: cannot read %s\n", job_arg.c_str()), 1;
    job_path = std::filesystem::absolute(job_arg).string();
    std::stringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  auto config = engine::ParseJobText(text, "bench job");
  if (!config.ok()) return std::fprintf(stderr, "%s\n", config.status().ToString().c_str()), 1;
  auto params = engine::ParamsFromConfig(*config, "bench job");
  if (!params.ok()) return std::fprintf(stderr, "%s\n", params.status().ToString().c_str()), 1;
  params->threads = 1;
  const bool subtree_max_given = subtree_max >= 0;  // --scale: hand-off only when asked for
  if (subtree_max < 0) subtree_max = (long long)params->subtree_max_samples;
  std::printf("job: %s\n", engine::DescribeParams(*params).c_str());
  std::printf(
      "machine: %u hardware threads, load average %.1f at start (a shared machine: timings are noisy)\n",
      std::thread::hardware_concurrency(), LoadAverage());
  std::printf("OpenMP wait policy: %s (idle threads %s)\n", std::getenv("OMP_WAIT_POLICY"),
              std::getenv("OMP_WAIT_POLICY") == std::string("PASSIVE") ? "sleep: CPU seconds count work"
                                                                         : "may spin: CPU seconds include waiting");
  std::fflush(stdout);
  if (commands_only) {
    if (cli_path.empty()) {
      std::error_code ec;
      cli_path = (std::filesystem::read_symlink("/proc/self/exe", ec).parent_path() / ".." / "bin" / "poseforest")
                     .string();
    }
    if (::access(cli_path.c_str(), X_OK) != 0)
      return std::fprintf(stderr, "distributed: %s is not executable (build poseforest, or --poseforest PATH)\n",
                          cli_path.c_str()),
             1;
    const int n = std::count(worker_counts.begin(), worker_counts.end(), 2)
                      ? 2
                      : *std::max_element(worker_counts.begin(), worker_counts.end());
    return CommandsOnly(job_path, text, cli_path, n, repeat, domain, keep_logs);
  }

  // 1. The engine.
  RunFigures engine;
  std::vector<uint8_t> ref_bytes;
  auto run_engine = [&](RunFigures& engine, int threads, bool verbose) -> int {
    engine::TrainParams p = *params;
    p.threads = threads;
    engine::LocalTrainer local(p, {});
    const double c0 = CpuSeconds(RUSAGE_SELF), t0 = proto::dds::NowSeconds();
    auto ref = local.Train();
    engine.wall = proto::dds::NowSeconds() - t0;
    engine.cpu = CpuSeconds(RUSAGE_SELF) - c0;
    if (!ref.ok()) return std::fprintf(stderr, "%s\n", ref.status().ToString().c_str()), 1;
    engine.evaluations = local.stats().evaluations;
    engine.identical = ref_bytes.empty() || core::SerializeForest(*ref) == ref_bytes;
    if (ref_bytes.empty()) ref_bytes = core::SerializeForest(*ref);
    if (!verbose) return 0;
    std::printf(
        "\nengine (LocalTrainer, %d thread(s)): %.2f s wall, %.2f CPU s, %llu evaluations: %.3g evaluations/s, "
        "%.3g per CPU-second (histogram builder alone: %.3g evaluations/s)\n",
        threads, engine.wall, engine.cpu, (unsigned long long)engine.evaluations,
        double(engine.evaluations) / engine.wall, double(engine.evaluations) / engine.cpu,
        double(engine.evaluations) /
            std::max(1e-9, local.stats().histogram_seconds + local.stats().range_seconds));
    std::printf("  engine wall by phase: frames %.3f s, ranges %.3f s, histograms %.3f s, the rest %.3f s\n",
                local.stats().load_seconds, local.stats().range_seconds, local.stats().histogram_seconds,
                engine.wall - local.stats().load_seconds - local.stats().range_seconds -
                    local.stats().histogram_seconds);
    std::fflush(stdout);
    return 0;
  };
  if (int rc = run_engine(engine, 1, true); rc != 0) return rc;
  if (!scale_counts.empty()) {
    std::error_code ec;
    const std::string self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
    if (ec) return std::fprintf(stderr, "distributed: cannot find /proc/self/exe\n"), 1;
    return Scale(self, *config, *params, scale_counts, repeat, domain, subtree_max_given ? subtree_max : 0,
                 sample_lists, csv_path, ref_bytes, engine.evaluations, engine.cpu);
  }
  // The engine on as many cores as each worker count (the headline's comparison).
  std::map<int, RunFigures> engines;  // threads -> figures
  engines[1] = engine;
  for (int n : worker_counts)
    if (!engines.count(n))
      if (int rc = run_engine(engines[n], n, true); rc != 0) return rc;
  if (engine_only) return 0;

  std::string self;
  {
    std::error_code ec;
    self = std::filesystem::read_symlink("/proc/self/exe", ec).string();
    if (ec) return std::fprintf(stderr, "distributed: cannot find /proc/self/exe\n"), 1;
  }
  // The engine as n concurrent 1-thread processes, each training the whole job: the same
  // two-process load on the machine as n workers, without the service. CPU: the reaped children's.
  const std::string job_file = (std::filesystem::temp_directory_path() /
                                ("bench-" + std::to_string(::getpid()) + "-job.textproto"))
                                   .string();
  std::ofstream(job_file) << text;
  // --neighbour-test R: what another busy process on the other core costs the 1-thread engine:
  // R rounds of (alone, next to a busy loop, next to random reads over 16 MiB, next to another
  // 1-thread engine process on the same job), CPU seconds, medians. A busy loop shares nothing
  // but the machine; the reader also shares the L3; the engine process is what a second worker is.
  if (neighbour_test > 0) {
    std::string l3 = "unknown";
    std::getline(std::ifstream("/sys/devices/system/cpu/cpu0/cache/index3/size"), l3);
    std::printf("\nneighbour test: the 1-thread engine alone, next to a busy loop, next to random reads over "
                "16 MiB (this core's L3: %s) and next to another 1-thread engine process; %d rounds\n",
                l3.c_str(), neighbour_test);
    const char* kinds[4] = {"alone", "a busy loop", "a 16 MiB reader", "an engine process"};
    std::vector<double> cpu[4];
    for (int r = 0; r < neighbour_test; ++r) {
      for (int k = 0; k < 4; ++k) {
        pid_t pid = -1;
        if (k > 0) {
          std::vector<std::string> a = {self, "--neighbour", k == 1 ? "spin" : "reads", "16"};
          if (k == 3) a = {self, "--engine-process", job_file};  // starts with ours, runs as long
          pid = Spawn(a);
          if (pid < 0) return std::fprintf(stderr, "distributed: cannot start a neighbour process\n"), 1;
          if (k < 3) std::this_thread::sleep_for(std::chrono::milliseconds(300));  // its memory is touched
        }
        RunFigures f;
        const int rc = run_engine(f, 1, false);
        if (pid > 0) {
          if (k < 3) ::kill(pid, SIGKILL);
          ::waitpid(pid, nullptr, 0);
        }
        if (rc != 0) return rc;
        cpu[k].push_back(f.cpu);
      }
      std::printf("round %d: engine CPU s alone %.3f, next to a busy loop %.3f, to a 16 MiB reader %.3f, to an engine "
                  "process %.3f\n",
                  r + 1, cpu[0].back(), cpu[1].back(), cpu[2].back(), cpu[3].back());
      std::fflush(stdout);
    }
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    };
    const double alone = median(cpu[0]);
    for (int k = 1; k < 4; ++k)
      std::printf("engine CPU next to %s / alone: %.3f (median %.3f vs %.3f CPU s)\n", kinds[k],
                  median(cpu[k]) / alone, median(cpu[k]), alone);
    std::filesystem::remove(job_file);
    std::printf("distributed/engine CPU next to an engine process vs alone: %.3f ratio\n", median(cpu[3]) / alone);
    return 0;
  }
  auto run_engine_procs = [&](int n, RunFigures& f) -> int {
    const double kids0 = CpuSeconds(RUSAGE_CHILDREN), t0 = proto::dds::NowSeconds();
    std::vector<pid_t> pids;
    for (int i = 0; i < n; ++i) {
      const pid_t pid = Spawn({self, "--engine-process", job_file});
      if (pid < 0) return std::fprintf(stderr, "distributed: cannot start an engine process\n"), 1;
      pids.push_back(pid);
    }
    bool ok = true;
    for (pid_t p : pids) {
      int status = 0;
      ::waitpid(p, &status, 0);
      ok = ok && WIFEXITED(status) && WEXITSTATUS(status) == 0;
    }
    f.wall = proto::dds::NowSeconds() - t0;
    f.cpu = CpuSeconds(RUSAGE_CHILDREN) - kids0;
    f.evaluations = uint64_t(n) * engine.evaluations;
    if (!ok) return std::fprintf(stderr, "distributed: an engine process failed\n"), 1;
    return 0;
  };
  std::vector<Row> rows;
  std::map<std::pair<int, uint64_t>, RunFigures> runs;  // (workers, subtree_max_samples)
  std::vector<std::pair<int, uint64_t>> plan;
  for (int n : worker_counts) {
    if (!skip_off || subtree_max <= 0) plan.push_back({n, 0});
    if (subtree_max > 0) plan.push_back({n, uint64_t(subtree_max)});
  }
  uint32_t run_index = 0;
  // One service run: n worker processes, hand-off at sm samples; figures into f; verbose: the
  // per-level table, totals and breakdown.
  auto run_service = [&](int n, uint64_t sm, RunFigures& f, bool verbose) -> int {
    ++run_index;
    config->set_subtree_max_samples(sm);
    params->subtree_max_samples = sm;
    const uint32_t dom = (domain + run_index) % 233;
    const std::string job_id =
        "bench-" + std::to_string(::getpid()) + "-" + std::to_string(n) + "-" + std::to_string(sm);
    const double kids_cpu0 = CpuSeconds(RUSAGE_CHILDREN);
    std::vector<pid_t> pids;
    std::vector<std::string> stats_files;
    for (int i = 0; i < n; ++i) {
      stats_files.push_back((std::filesystem::temp_directory_path() /
                             (job_id + "-w" + std::to_string(i) + ".stats"))
                                .string());
      std::vector<std::string> a = {self,
                                    "--worker-process",
                                    "--domain",
                                    std::to_string(dom),
                                    "--job",
                                    job_id,
                                    "--id",
                                    "bench-w" + std::to_string(i),
                                    "--stats",
                                    stats_files.back()};
      // POSEFOREST_BENCH_WORKER_WRAP="valgrind --tool=callgrind ...": workers run under that
      // command (instruction counts on a loaded machine).
      std::vector<std::string> wrap;
      if (const char* w = std::getenv("POSEFOREST_BENCH_WORKER_WRAP"))
        for (std::stringstream ss(w); ss.good();) {
          std::string word;
          ss >> word;
          if (!word.empty()) wrap.push_back(word);
        }
      a.insert(a.begin(), wrap.begin(), wrap.end());
      const pid_t pid = Spawn(a, nullptr, /*search_path=*/true);
      if (pid < 0) return std::fprintf(stderr, "distributed: cannot start a worker process\n"), 1;
      pids.push_back(pid);
    }
    coordinator::CoordinatorOptions co;
    co.domain = dom;
    co.job_id = job_id;
    co.min_workers = n;
    co.subtree_sample_lists = sample_lists;
    // As `coordinator --local-workers n`: the coordinator merges on the cores the workers leave.
    co.merge_threads = std::max(1, int(std::thread::hardware_concurrency()) - n);
    co.log = [](const std::string&) {};
    std::map<int, RunFigures> trees;
    if (verbose)
      std::printf(
        "\n%d worker process(es), subtree hand-off %s:\n  tree level  nodes  samples  handed  from_sub  "
        "bytes_received  bytes_sent  merge_ms  level_s  evaluations/s\n",
        n, sm ? ("at <= " + std::to_string(sm) + " samples").c_str() : "off");
    co.progress = [&](const coordinator::DistLevelStats& s) {
      if (sm == 0 && verbose)
        rows.push_back({n, s.tree, s.level, s.frontier_nodes, s.split_nodes, s.samples, s.evaluations,
                        s.bytes_received, s.bytes_sent, s.merge_seconds, s.level_seconds});
      for (RunFigures* t : {&f, &trees[s.tree]}) {
        t->evaluations += s.evaluations;
        t->bytes_received += s.bytes_received;
        t->bytes_sent += s.bytes_sent;
        t->merge += s.merge_seconds;
        t->levels_wall += s.level_seconds;
        t->subtree_samples += s.subtree_samples;
        t->subtree_busiest += s.subtree_samples_busiest;
      }
      if (!verbose) return;
      std::printf("  %4d %5d  %5zu  %7llu  %6zu  %8zu  %14llu  %10llu  %8.2f  %7.3f  %.3g\n", s.tree, s.level,
                  s.frontier_nodes, (unsigned long long)s.samples, s.subtree_tasks, s.subtree_nodes,
                  (unsigned long long)s.bytes_received, (unsigned long long)s.bytes_sent,
                  s.merge_seconds * 1e3, s.level_seconds, s.evaluations_per_s);
      std::fflush(stdout);
    };
    coordinator::DistCoordinator coord(*config, *params, co);
    const double c0 = CpuSeconds(RUSAGE_SELF), t0 = proto::dds::NowSeconds();
    auto forest = coord.Train();
    f.wall = proto::dds::NowSeconds() - t0;
    f.coordinator_cpu = CpuSeconds(RUSAGE_SELF) - c0;
    // Workers leave on JOB_DONE; reap them so that their CPU time is counted.
    const double deadline = proto::dds::NowSeconds() + 10;
    for (pid_t p : pids) {
      int status = 0;
      while (::waitpid(p, &status, WNOHANG) == 0) {
        if (proto::dds::NowSeconds() > deadline) {
          ::kill(p, SIGKILL);
          ::waitpid(p, &status, 0);
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    }
    f.workers_cpu = CpuSeconds(RUSAGE_CHILDREN) - kids_cpu0;
    f.cpu = f.coordinator_cpu + f.workers_cpu;
    for (const std::string& path : stats_files) {
      if (!AddStats(path, &f.worker_cpu))
        std::printf("  (no CPU breakdown from %s: the worker did not finish normally)\n", path.c_str());
      std::filesystem::remove(path);
    }
    if (!forest.ok()) return std::fprintf(stderr, "%s\n", forest.status().ToString().c_str()), 1;
    f.identical = core::SerializeForest(*forest) == ref_bytes;
    if (!verbose) return 0;
    for (const auto& [t, tf] : trees)
      std::printf("  tree %d: %llu bytes received, %llu bytes sent, merge %.1f ms, levels %.2f s\n", t,
                  (unsigned long long)tf.bytes_received, (unsigned long long)tf.bytes_sent, tf.merge * 1e3,
                  tf.levels_wall);
    std::printf(
        "  total: %.2f s wall (levels %.2f s), %.2f CPU s (coordinator %.2f, workers %.2f), %llu "
        "evaluations, "
        "%.3g evaluations/s, %.3g per CPU-second, %llu bytes received, merge %.1f ms, identical to the "
        "engine: %s\n",
        f.wall, f.levels_wall, f.cpu, f.coordinator_cpu, f.workers_cpu, (unsigned long long)f.evaluations,
        double(f.evaluations) / f.wall, double(f.evaluations) / f.cpu, (unsigned long long)f.bytes_received,
        f.merge * 1e3, f.identical ? "yes" : "NO");
    if (f.subtree_samples > 0)
      std::printf(
          "  subtree hand-off balance: %llu samples handed; the busiest worker of each level got %.1f %% of "
          "them (even: %.1f %%)\n",
          (unsigned long long)f.subtree_samples, 100.0 * double(f.subtree_busiest) / double(f.subtree_samples),
          100.0 / n);
    PrintBreakdown(f, engine.cpu);
    std::fflush(stdout);
    return 0;
  };
  for (const auto& [n, sm] : plan)
    if (int rc = run_service(n, sm, runs[{n, sm}], true); rc != 0) return rc;

  if (!csv_path.empty()) {
    std::ofstream csv(csv_path);
    csv << "workers,tree,level,nodes,split,samples,evaluations,bytes_received,bytes_sent,merge_s,level_s,"
           "candidates,bins,images_per_tree,pixels_per_image\n";
    for (const Row& r : rows)
      csv << r.workers << ',' << r.tree << ',' << r.level << ',' << r.nodes << ',' << r.split << ','
          << r.samples << ',' << r.evaluations << ',' << r.bytes_received << ',' << r.bytes_sent << ','
          << r.merge_s << ',' << r.level_s << ',' << params->candidate_features << ','
          << (params->thresholds_per_feature + 1) << ',' << config->images_per_tree() << ','
          << config->pixels_per_image() << '\n';
    std::printf("\nwrote %zu per-level rows to %s\n", rows.size(), csv_path.c_str());
  }

  // Same work everywhere: the evaluations of the engine (the service's equal them; checked below).
  const double engine_per_cpu = double(engine.evaluations) / engine.cpu;
  std::printf("\n%-26s %10s %10s %14s %16s %12s %14s\n", "", "wall s", "CPU s", "evaluations/s",
              "per CPU-second", "vs 1 thread", "vs same cores");
  bool ok = true;
  for (const auto& [t, e] : engines) {
    ok = ok && e.identical && e.evaluations == engine.evaluations;
    std::printf("%-26s %10.2f %10.2f %14.3g %16.3g %12.2f %14.2f\n",
                ("engine, " + std::to_string(t) + " thread" + (t > 1 ? "s" : "")).c_str(), e.wall, e.cpu,
                double(engine.evaluations) / e.wall, double(engine.evaluations) / e.cpu,
                double(engine.evaluations) / e.cpu / engine_per_cpu, 1.0);
  }
  for (const auto& [key, f] : runs) {
    const auto [n, sm] = key;
    ok = ok && f.identical && f.evaluations == engine.evaluations;
    std::printf("%-26s %10.2f %10.2f %14.3g %16.3g %12.2f %14.2f\n",
                (std::to_string(n) + " worker" + (n > 1 ? "s" : "") + ", hand-off " +
                 (sm ? std::to_string(sm) : std::string("off")))
                    .c_str(),
                f.wall, f.cpu, double(engine.evaluations) / f.wall, double(engine.evaluations) / f.cpu,
                double(engine.evaluations) / f.cpu / engine_per_cpu, engines[n].cpu / f.cpu);
  }
  // The same engine as concurrent processes (one per worker of the headline run).
  const int procs_n = std::count(worker_counts.begin(), worker_counts.end(), 2)
                          ? 2
                          : *std::max_element(worker_counts.begin(), worker_counts.end());
  RunFigures procs;
  if (procs_n > 1) {
    if (int rc = run_engine_procs(procs_n, procs); rc != 0) return rc;
    std::printf("%-26s %10.2f %10.2f %14.3g %16.3g %12.2f %14s\n",
                ("engine, " + std::to_string(procs_n) + " processes").c_str(), procs.wall, procs.cpu,
                double(procs.evaluations) / procs.wall, double(procs.evaluations) / procs.cpu,
                double(procs.evaluations) / procs.cpu / engine_per_cpu, "-");
  }
  std::printf("(\"vs same cores\": against the engine with as many OpenMP threads as the run has workers; "
              "\"engine, N processes\": N concurrent 1-thread engine processes, each training the whole job)\n");
  // The headline: 2 workers (else the largest count run), with hand-off as configured.
  const int head_n = std::count(worker_counts.begin(), worker_counts.end(), 2)
                         ? 2
                         : *std::max_element(worker_counts.begin(), worker_counts.end());
  const RunFigures& two = runs[{head_n, uint64_t(subtree_max > 0 ? subtree_max : 0)}];
  const RunFigures& two_off = runs.count({head_n, 0}) ? runs[{head_n, 0}] : two;
  if (&two_off != &two)
    std::printf("bytes received, %d worker(s): %.1f MB without subtree hand-off, %.1f MB with (%.2f x less)\n",
                head_n, double(two_off.bytes_received) / 1e6, double(two.bytes_received) / 1e6,
                two.bytes_received ? double(two_off.bytes_received) / double(two.bytes_received) : 0.0);
  else
    std::printf("bytes received, %d worker(s): %.1f MB\n", head_n, double(two.bytes_received) / 1e6);
  std::printf(
      "%d worker(s) vs engine, wall per worker: %.2f (evaluations/s / workers / engine evaluations/s)\n",
      head_n, (double(engine.evaluations) / two.wall / head_n) / (double(engine.evaluations) / engine.wall));
  PrintWhy(two, engines[head_n].cpu, head_n, subtree_max > 0 ? uint64_t(subtree_max) : 0);
  // --repeat: more (engine, headline run) pairs, one after the other, and the median ratio (a
  // loaded machine's CPU seconds vary from run to run by more than the overhead measured).
  std::vector<double> ratios = {engines[head_n].cpu / two.cpu};
  std::vector<double> ratios_1t = {engine.cpu / two.cpu};
  // Service vs the engine as head_n concurrent processes, per CPU-second.
  std::vector<double> ratios_procs;
  if (head_n > 1 && procs_n == head_n) ratios_procs.push_back(procs.cpu / double(head_n) / two.cpu);
  for (int r = 1; r < repeat; ++r) {
    RunFigures e, e1, f;
    if (int rc = run_engine(e, head_n, false); rc != 0) return rc;
    if (head_n == 1)
      e1 = e;
    else if (int rc = run_engine(e1, 1, false); rc != 0)
      return rc;
    if (int rc = run_service(head_n, subtree_max > 0 ? uint64_t(subtree_max) : 0, f, false); rc != 0) return rc;
    RunFigures ep;
    if (head_n > 1)
      if (int rc = run_engine_procs(head_n, ep); rc != 0) return rc;
    ok = ok && e.identical && e1.identical && f.identical && f.evaluations == e.evaluations;
    ratios.push_back(e.cpu / f.cpu);
    ratios_1t.push_back(e1.cpu / f.cpu);
    if (head_n > 1) ratios_procs.push_back(ep.cpu / double(head_n) / f.cpu);
    std::printf("repeat %d: engine %d thread(s) %.2f CPU s, 1 thread %.2f CPU s, service %.2f CPU s (coordinator "
                "%.2f, workers %.2f), ratio %.3f (vs 1 thread %.3f%s), load average %.1f\n",
                r + 1, head_n, e.cpu, e1.cpu, f.cpu, f.coordinator_cpu, f.workers_cpu, ratios.back(),
                ratios_1t.back(),
                head_n > 1 ? (", vs " + std::to_string(head_n) + " engine processes " +
                              std::to_string(ratios_procs.back()).substr(0, 5) + " (" +
                              std::to_string(ep.cpu).substr(0, 5) + " CPU s for " + std::to_string(head_n) + " jobs)")
                                 .c_str()
                           : "",
                LoadAverage());
    std::fflush(stdout);
  }
  // As users run them: `poseforest train JOB --threads N` against `poseforest
  // train JOB --local-workers N`, each a fresh process (the service: the coordinator and its N
  // worker processes), CPU of the process and its reaped descendants, forests compared with the
  // engine's. The in-process engine above runs warm: after its first run its heap pages are
  // already faulted in (the process keeps freed memory, core::KeepFreedMemory) and its libraries
  // and OpenMP pool are loaded, while the service's workers always start cold; a user's `train`
  // starts cold too. Pairs alternate which command runs first.
  const uint64_t head_sm = subtree_max > 0 ? uint64_t(subtree_max) : 0;
  std::vector<double> ratios_cli;
  {
    if (cli_path.empty()) cli_path = (std::filesystem::path(self).parent_path() / ".." / "bin" / "poseforest").string();
    if (::access(cli_path.c_str(), X_OK) != 0)
      return std::fprintf(stderr,
                          "distributed: the headline runs the poseforest program and %s is not executable "
                          "(build the target poseforest, or give --poseforest PATH)\n",
                          cli_path.c_str()),
             1;
    config->set_subtree_max_samples(head_sm);
    std::string head_text;
    google::protobuf::TextFormat::PrintToString(*config, &head_text);
    const auto tmp = std::filesystem::temp_directory_path();
    const std::string tag = "bench-" + std::to_string(::getpid()), head_job = (tmp / (tag + "-cli.textproto")).string(),
                      out_e = (tmp / (tag + "-cli-engine.pff")).string(),
                      out_s = (tmp / (tag + "-cli-service.pff")).string(), log = (tmp / (tag + "-cli.log")).string();
    std::ofstream(head_job) << head_text;
    const std::string n_str = std::to_string(head_n);
    // One command, output to `log`; its CPU (and its reaped descendants'); false if it failed or
    // its forest is not the engine's.
    auto run_cli = [&](std::vector<std::string> a, const std::string& out, double* cpu) -> bool {
      a.insert(a.begin(), cli_path);
      std::filesystem::remove(out);
      double wall = 0;
      return RunCommand(a, log, cpu, &wall) && ReadBytes(out) == ref_bytes;
    };
    std::printf("\nas users run them, %d pairs: `%s train JOB --threads %d` against `... train JOB "
                "--local-workers %d`, fresh processes, CPU of each command and its worker processes\n",
                repeat, cli_path.c_str(), head_n, head_n);
    for (int r = 0; r < repeat; ++r) {
      double ce = 0, cs = 0;
      const uint32_t dom = (domain + 101 + uint32_t(r)) % 233;
      auto engine_cmd = [&] {
        return run_cli({"train", head_job, "--threads", n_str, "--quiet", "--out", out_e}, out_e, &ce);
      };
      auto service_cmd = [&] {
        return run_cli({"train", head_job, "--local-workers", n_str, "--domain", std::to_string(dom), "--http", "off",
                        "--out", out_s},
                       out_s, &cs);
      };
      const bool engine_first = r % 2 == 0;
      const bool a = engine_first ? engine_cmd() : service_cmd();
      const bool b = engine_first ? service_cmd() : engine_cmd();
      if (!a || !b) {
        std::printf("pair %d: a command failed or its forest differs from the engine's; its output: %s\n", r + 1,
                    log.c_str());
        ok = false;
        break;
      }
      ratios_cli.push_back(ce / cs);
      std::printf("pair %d (%s first): train --threads %d %.3f CPU s, train --local-workers %d %.3f CPU s, ratio "
                  "%.3f, load average %.1f\n",
                  r + 1, engine_first ? "engine" : "service", head_n, ce, head_n, cs, ratios_cli.back(),
                  LoadAverage());
      std::fflush(stdout);
    }
    for (const std::string& f : {head_job, out_e, out_s}) std::filesystem::remove(f);
    if (ok) std::filesystem::remove(log);
  }
  const auto median_of = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
  };
  const double median = median_of(ratios), median_1t = median_of(ratios_1t);
  if (repeat > 1)
    std::printf("ratio over %d pairs: median %.3f, min %.3f, max %.3f\n", repeat, median,
                *std::min_element(ratios.begin(), ratios.end()), *std::max_element(ratios.begin(), ratios.end()));
  std::printf("%d worker(s) vs the engine with 1 thread, per CPU-second: %.3f (median); vs the engine on %d "
              "core(s): %.3f\n",
              head_n, median_1t, head_n, median);
  if (!ratios_procs.empty())
    std::printf("%d worker(s) vs the engine as %d concurrent 1-thread processes (the same multi-process load on the "
                "machine, without the service), per CPU-second: %.3f (median of %zu, min %.3f, max %.3f)\n",
                head_n, head_n, median_of(ratios_procs), ratios_procs.size(),
                *std::min_element(ratios_procs.begin(), ratios_procs.end()),
                *std::max_element(ratios_procs.begin(), ratios_procs.end()));
  std::filesystem::remove(job_file);
  if (!ok) std::printf("WARNING: a service run differs from the engine (forest bytes or evaluation count)\n");
  if (ratios_cli.empty()) return 1;
  std::printf("in-process (the engine warm inside this process; the last line until the fifth session): %d "
              "worker(s) vs the engine on %d core(s), per CPU-second: %.3f (median of %zu)\n",
              head_n, head_n, median, ratios.size());
  const double median_cli = median_of(ratios_cli);
  std::printf("as users run them: train --local-workers %d vs train --threads %d, fresh processes, per CPU-second: "
              "median %.3f over %zu pairs (min %.3f, max %.3f)\n",
              head_n, head_n, median_cli, ratios_cli.size(), *std::min_element(ratios_cli.begin(), ratios_cli.end()),
              *std::max_element(ratios_cli.begin(), ratios_cli.end()));
  // Same evaluations in both (the same job; forests checked byte for byte): the ratio of
  // evaluations per CPU-second is engine CPU / service CPU.
  std::printf("distributed/engine per core: %.3f ratio\n", median_cli);
  return ok ? 0 : 1;
}
