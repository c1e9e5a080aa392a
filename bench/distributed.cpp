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
//   distributed [JOB.textproto] [--csv FILE] [--domain D] [--subtree-max S]
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
// worker process writes its dist::WorkerCpu to a --stats file when it exits), and a "why the
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
//                   runs: for big jobs, e.g. issue 13's 2,000 images per tree), --repeat R pairs;
//                   per pair the wall and CPU of each, the forests compared, and a per-level
//                   table both ways from their logs with the service's level time split into
//                   the rounds (the critical worker's computing, its request queued while it
//                   was busy, traffic), merge, waiting for subtree results and other, beside
//                   the workers' subtree and rendering seconds. Above the last line: the
//                   median wall ratio (service / engine; issue 13's goal: at most 1.10).

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <google/protobuf/text_format.h>

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
  const double c0 = CpuSeconds(RUSAGE_CHILDREN), t0 = dist::NowSeconds();
  const pid_t pid = Spawn(args, &fa);
  ::posix_spawn_file_actions_destroy(&fa);
  if (pid < 0) return false;
  int status = 0;
  ::waitpid(pid, &status, 0);
  *cpu = CpuSeconds(RUSAGE_CHILDREN) - c0;
  *wall = dist::NowSeconds() - t0;
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

std::vector<uint8_t> ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Per (tree, level): seconds of the level in the log of `poseforest train JOB --threads N`
/// (its "tree T level L: ... S s," lines give seconds since the start; a tree's "loaded in S s"
/// line is frame loading, not part of its first level) or of `train JOB --local-workers N`
/// (its "level S s" and, under each level, the "time:" line of where it went: rounds, the
/// critical worker's computing, its request queued, traffic, merge, waiting for subtrees).
struct LevelTimes {
  struct Service {
    double level = 0, rounds = 0, compute = 0, queued = 0, traffic = 0, merge = 0, wait = 0, busy = 0, render = 0;
    double received_mib = 0;
    int tasks = 0;
  };
  std::map<std::pair<int, int>, double> engine;
  std::map<std::pair<int, int>, Service> service;
  void ReadEngine(const std::string& path) {
    std::ifstream in(path);
    double last = 0;
    for (std::string line; std::getline(in, line);) {
      int t = 0, l = 0;
      double v = 0;
      // "tree T: N samples from F frames in S shard(s), M MiB frames+samples (B bytes per image),
      // loaded in X s": the tree's frames, before its first level.
      if (const size_t at = line.find(", loaded in "); at != std::string::npos &&
          std::sscanf(line.c_str(), "tree %d:", &t) == 1 && std::sscanf(line.c_str() + at, ", loaded in %lf s", &v) == 1) {
        last += v;
        continue;
      }
      const size_t at = line.find(" evaluations/s, ");
      if (std::sscanf(line.c_str(), "tree %d level %d:", &t, &l) == 2 && at != std::string::npos &&
          std::sscanf(line.c_str() + at, " evaluations/s, %lf s,", &v) == 1) {
        engine[{t, l}] = v - last;
        last = v;
      }
    }
  }
  void ReadService(const std::string& path) {
    std::ifstream in(path);
    std::pair<int, int> key{-1, -1};
    for (std::string line; std::getline(in, line);) {
      int t = 0, l = 0, rounds = 0;
      if (std::sscanf(line.c_str(), "tree %d level %d:", &t, &l) == 2) {
        key = {t, l};
        Service& s = service[key];
        s = {};
        if (const size_t at = line.find(", level "); at != std::string::npos)
          std::sscanf(line.c_str() + at, ", level %lf s", &s.level);
        if (const size_t at = line.find(" subtrees handed off"); at != std::string::npos) {
          const size_t from = line.rfind(", ", at);
          if (from != std::string::npos) s.tasks = std::atoi(line.c_str() + from + 2);
        }
        double v = 0;
        char unit[8] = {};
        if (const size_t at = line.find(" workers alive, "); at != std::string::npos &&
            std::sscanf(line.c_str() + at, " workers alive, %lf %7s received", &v, unit) == 2)
          s.received_mib = v * (!std::strcmp(unit, "GiB") ? 1024 : !std::strcmp(unit, "MiB") ? 1
                                : !std::strcmp(unit, "KiB") ? 1.0 / 1024 : 1.0 / (1 << 20));
        continue;
      }
      Service* s = service.count(key) ? &service[key] : nullptr;
      if (s && std::sscanf(line.c_str(),
                           "  time: %d rounds %lf s (worker computing %lf s, busy before it %lf s, traffic %lf s), "
                           "merge %lf s, waiting for subtrees %lf s, other %*f s; workers: subtrees %lf s, "
                           "rendering %lf s",
                           &rounds, &s->rounds, &s->compute, &s->queued, &s->traffic, &s->merge, &s->wait, &s->busy,
                           &s->render) == 9)
        continue;
    }
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
/// CPU ratios. For jobs far too big for the in-process runs (issue 13's 2,000-image job).
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
    double ce = 0, we = 0, cs = 0, ws = 0;
    const bool engine_first = r % 2 == 0;
    bool a = false, b = false;
    for (int which = 0; which < 2; ++which) {
      const bool engine_now = (which == 0) == engine_first;
      std::filesystem::remove(engine_now ? out_e : out_s);
      const bool run_ok =
          engine_now ? RunCommand({cli, "train", job_path, "--threads", n_str, "--out", out_e}, log_e, &ce, &we)
                     : RunCommand({cli, "train", job_path, "--local-workers", n_str, "--domain",
                                   std::to_string((domain + 101 + uint32_t(r)) % 233), "--http", "off", "--out", out_s},
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
    times.ReadEngine(log_e);
    times.ReadService(log_s);
    times.Print();
    if (!keep_logs.empty()) {
      std::filesystem::create_directories(keep_logs);
      for (const std::string& f : {log_e, log_s})
        std::filesystem::copy_file(f, std::filesystem::path(keep_logs) / std::filesystem::path(f).filename(),
                                   std::filesystem::copy_options::overwrite_existing);
    }
    for (const std::string& f : {log_e, log_s}) std::filesystem::remove(f);
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
std::vector<std::pair<std::string, double>> CpuFields(const dist::WorkerCpu& c) {
  return {{"process_at_start", c.process_at_start},
          {"participant", c.participant},
          {"receive", c.receive},
          {"shard", c.shard},
          {"decisions", c.decisions},
          {"level_compute", c.level_compute},
          {"level_encode", c.level_encode},
          {"subtree_render", c.subtree_render},
          {"subtree_route", c.subtree_route},
          {"subtree_train", c.subtree_train},
          {"subtree_encode", c.subtree_encode},
          {"publish", c.publish},
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
}

/// A worker process: this program with --worker-process.
int WorkerProcess(int argc, char** argv) {
  // Go when the bench goes (killed or interrupted), as `worker --exit-with-parent` does.
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (::getppid() == 1) return 0;
  dist::WorkerOptions o;
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
  }
  o.threads = 1;
  o.exit_when_done = true;
  o.log = [](const std::string&) {};
  dist::DistWorker w(o);
  const core::Status st = w.Run();
  if (!st.ok()) std::fprintf(stderr, "worker: %s\n", st.ToString().c_str());
  if (!stats_path.empty()) {
    std::ofstream out(stats_path);
    for (const auto& [name, value] : CpuFields(w.cpu())) out << name << ' ' << value << '\n';
    out << "process_at_report " << CpuSeconds(RUSAGE_SELF) << '\n';
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
  auto config = worker::ParseJobText(text.str(), job_path);
  if (!config.ok()) return std::fprintf(stderr, "%s\n", config.status().ToString().c_str()), 1;
  auto params = worker::ParamsFromConfig(*config, job_path);
  if (!params.ok()) return std::fprintf(stderr, "%s\n", params.status().ToString().c_str()), 1;
  params->threads = 1;
  coordinator::LocalTrainer local(*params, {});
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
  bool skip_off = false;
  int repeat = 1;
  bool engine_only = false, sample_lists = true;
  int neighbour_test = 0;
  std::string cli_path;  // the poseforest program (default: ../bin/poseforest next to this bench)
  bool commands_only = false;
  std::string job_path, keep_logs;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--workers") && i + 1 < argc) {
      worker_counts.clear();
      for (std::stringstream ss(argv[++i]); ss.good();) {
        std::string item;
        std::getline(ss, item, ',');
        const int n = std::atoi(item.c_str());
        if (n < 1 || n > 16) return std::fprintf(stderr, "distributed: --workers wants counts 1..16\n"), 2;
        worker_counts.push_back(n);
      }
    } else if (!std::strcmp(argv[i], "--commands-only")) {
      commands_only = true;
    } else if (!std::strcmp(argv[i], "--keep-logs") && i + 1 < argc) {
      keep_logs = argv[++i];
    } else if (!std::strcmp(argv[i], "--skip-off")) {
      skip_off = true;
    } else if (!std::strcmp(argv[i], "--engine-only")) {
      engine_only = true;
    } else if (!std::strcmp(argv[i], "--neighbour-test") && i + 1 < argc) {
      neighbour_test = std::atoi(argv[++i]);
      if (neighbour_test < 1 || neighbour_test > 50)
        return std::fprintf(stderr, "distributed: --neighbour-test wants 1..50\n"), 2;
    } else if (!std::strcmp(argv[i], "--poseforest") && i + 1 < argc) {
      cli_path = argv[++i];
    } else if (!std::strcmp(argv[i], "--no-sample-lists")) {
      sample_lists = false;
    } else if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc) {
      repeat = std::atoi(argv[++i]);
      if (repeat < 1 || repeat > 50) return std::fprintf(stderr, "distributed: --repeat wants 1..50\n"), 2;
    } else if (!std::strcmp(argv[i], "--domain") && i + 1 < argc) {
      domain = uint32_t(std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--csv") && i + 1 < argc) {
      csv_path = argv[++i];
    } else if (!std::strcmp(argv[i], "--subtree-max") && i + 1 < argc) {
      subtree_max = std::atoll(argv[++i]);
    } else if (!std::strcmp(argv[i], "--help") || argv[i][0] == '-') {
      std::fprintf(stderr,
                   "usage: distributed [JOB.textproto] [--csv FILE] [--domain D] [--subtree-max S] "
                   "[--workers N,N] [--skip-off] [--repeat R] [--engine-only] [--no-sample-lists] "
                   "[--neighbour-test R] [--poseforest PATH] [--commands-only [--keep-logs DIR]]\n");
      return std::strcmp(argv[i], "--help") ? 2 : 0;
    } else {
      std::ifstream in(argv[i]);
      if (!in) return std::fprintf(stderr, "distributed: cannot read %s\n", argv[i]), 1;
      job_path = std::filesystem::absolute(argv[i]).string();
      std::stringstream ss;
      ss << in.rdbuf();
      text = ss.str();
    }
  }
  auto config = worker::ParseJobText(text, "bench job");
  if (!config.ok()) return std::fprintf(stderr, "%s\n", config.status().ToString().c_str()), 1;
  auto params = worker::ParamsFromConfig(*config, "bench job");
  if (!params.ok()) return std::fprintf(stderr, "%s\n", params.status().ToString().c_str()), 1;
  params->threads = 1;
  if (subtree_max < 0) subtree_max = (long long)params->subtree_max_samples;
  std::printf("job: %s\n", worker::DescribeParams(*params).c_str());
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
    worker::TrainParams p = *params;
    p.threads = threads;
    coordinator::LocalTrainer local(p, {});
    const double c0 = CpuSeconds(RUSAGE_SELF), t0 = dist::NowSeconds();
    auto ref = local.Train();
    engine.wall = dist::NowSeconds() - t0;
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
    const double kids0 = CpuSeconds(RUSAGE_CHILDREN), t0 = dist::NowSeconds();
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
    f.wall = dist::NowSeconds() - t0;
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
    dist::CoordinatorOptions co;
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
    co.progress = [&](const dist::DistLevelStats& s) {
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
    dist::DistCoordinator coord(*config, *params, co);
    const double c0 = CpuSeconds(RUSAGE_SELF), t0 = dist::NowSeconds();
    auto forest = coord.Train();
    f.wall = dist::NowSeconds() - t0;
    f.coordinator_cpu = CpuSeconds(RUSAGE_SELF) - c0;
    // Workers leave on JOB_DONE; reap them so that their CPU time is counted.
    const double deadline = dist::NowSeconds() + 10;
    for (pid_t p : pids) {
      int status = 0;
      while (::waitpid(p, &status, WNOHANG) == 0) {
        if (dist::NowSeconds() > deadline) {
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
