// Figures of the distributed service on a small procedural job, in one process (workers on
// threads, DDS over shared memory): bytes received and coordinator merge time per level, and
// evaluations/s with 1 and 2 workers vs LocalTrainer, each without and with subtree hand-off
// (nodes of at most S samples trained whole by one worker). Not a timed test.
//   poseforest_bench_distributed [JOB.textproto] [--domain D] [--subtree-max S]
// S defaults to the job's subtree_max_samples (4096 unless the job sets it).

#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>
#include <vector>

#include "coordinator/distributed/dist_coordinator.h"
#include "coordinator/local_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/forest_format.h"
#include "worker/distributed/dist_common.h"
#include "worker/distributed/dist_worker.h"
#include "worker/job_spec.h"

using namespace poseforest;

int main(int argc, char** argv) {
  std::string text =
      "seed: 3\nnum_trees: 1\nmax_depth: 12\nimages_per_tree: 100\npixels_per_image: 1000\n"
      "candidate_features: 300\nthresholds_per_feature: 30\nmax_probe_offset_pixel_m: 80\n"
      "source { procedural { seed: 4 width: 160 height: 120 } }\n";
  uint32_t domain = 1 + uint32_t(::getpid()) % 200;
  long long subtree_max = -1;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--domain") && i + 1 < argc) {
      domain = uint32_t(std::atoi(argv[++i]));
    } else if (!std::strcmp(argv[i], "--subtree-max") && i + 1 < argc) {
      subtree_max = std::atoll(argv[++i]);
    } else {
      std::ifstream in(argv[i]);
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

  coordinator::LocalTrainerOptions lo;
  uint64_t local_evals = 0;
  double local_hist_s = 0;
  coordinator::LocalTrainer local(*params, lo);
  const double t0 = dist::NowSeconds();
  auto ref = local.Train();
  if (!ref.ok()) return std::fprintf(stderr, "%s\n", ref.status().ToString().c_str()), 1;
  const double local_s = dist::NowSeconds() - t0;
  local_evals = local.stats().evaluations;
  local_hist_s = local.stats().histogram_seconds + local.stats().range_seconds;
  std::printf(
      "LocalTrainer (1 thread): %.2f s, %llu evaluations, %.3g evaluations/s (histogram+range time)\n",
      local_s, (unsigned long long)local_evals, local_hist_s > 0 ? double(local_evals) / local_hist_s : 0.0);
  const auto ref_bytes = core::SerializeForest(*ref);

  struct Run {
    int workers;
    uint64_t subtree_max;
    double wall;
    uint64_t bytes;
  };
  std::vector<Run> runs;
  uint32_t run_index = 0;
  for (int n : {1, 2})
    for (uint64_t sm : {uint64_t(0), uint64_t(subtree_max)}) {
      if (sm == 0 && subtree_max == 0 && !runs.empty() && runs.back().workers == n) continue;
      ++run_index;
      config->set_subtree_max_samples(sm);
      params->subtree_max_samples = sm;
      std::vector<std::unique_ptr<dist::DistWorker>> workers;
      std::vector<std::thread> threads;
      const std::string job_id = "bench-" + std::to_string(n) + "-" + std::to_string(sm);
      for (int i = 0; i < n; ++i) {
        dist::WorkerOptions wo;
        wo.worker_id = "bench-w" + std::to_string(i);
        wo.domain = (domain + run_index) % 230;
        wo.job_id = job_id;
        wo.threads = 1;
        wo.exit_when_done = false;
        wo.log = [](const std::string&) {};
        workers.push_back(std::make_unique<dist::DistWorker>(wo));
        threads.emplace_back([w = workers.back().get()] { (void)w->Run(); });
      }
      dist::CoordinatorOptions co;
      co.domain = (domain + run_index) % 230;
      co.job_id = job_id;
      co.min_workers = n;
      co.log = [](const std::string&) {};
      uint64_t evals = 0, bytes = 0;
      double merge = 0;
      std::printf(
          "\n%d worker(s), subtree hand-off %s:\n  tree  level  nodes  samples  handed  from_sub   "
          "bytes_received  "
          "bytes_sent  merge_ms  level_s  evaluations/s\n",
          n, sm ? ("at <= " + std::to_string(sm) + " samples").c_str() : "off");
      co.progress = [&](const dist::DistLevelStats& s) {
        evals += s.evaluations;
        bytes += s.bytes_received;
        merge += s.merge_seconds;
        std::printf("  %4d  %5d  %5zu  %7llu  %6zu  %8zu  %15llu  %10llu  %8.2f  %7.3f  %.3g\n", s.tree,
                    s.level, s.frontier_nodes, (unsigned long long)s.samples, s.subtree_tasks,
                    s.subtree_nodes, (unsigned long long)s.bytes_received, (unsigned long long)s.bytes_sent,
                    s.merge_seconds * 1e3, s.level_seconds, s.evaluations_per_s);
      };
      dist::DistCoordinator coord(*config, *params, co);
      const double t1 = dist::NowSeconds();
      auto forest = coord.Train();
      const double wall = dist::NowSeconds() - t1;
      for (auto& w : workers) w->Stop();
      for (auto& t : threads) t.join();
      if (!forest.ok()) return std::fprintf(stderr, "%s\n", forest.status().ToString().c_str()), 1;
      std::printf(
          "  total: %.2f s wall, %llu evaluations, %.3g evaluations/s (wall), %llu bytes received, "
          "merge %.1f ms, identical to LocalTrainer: %s\n",
          wall, (unsigned long long)evals, double(evals) / wall, (unsigned long long)bytes, merge * 1e3,
          core::SerializeForest(*forest) == ref_bytes ? "yes" : "NO");
      if (core::SerializeForest(*forest) != ref_bytes) return 1;
      runs.push_back({n, sm, wall, bytes});
    }
  std::printf("\nsummary:\n");
  for (const Run& r : runs)
    std::printf("  %d worker(s), hand-off %-6s: %.2f s wall, %.1f MB received\n", r.workers,
                r.subtree_max ? std::to_string(r.subtree_max).c_str() : "off", r.wall, double(r.bytes) / 1e6);
  const Run& last = runs.back();
  const Run& off = runs[runs.size() >= 2 ? runs.size() - 2 : 0];
  std::printf("bytes received without / with subtree hand-off (%d workers): %.2f x\n", last.workers,
              last.bytes ? double(off.bytes) / double(last.bytes) : 0.0);
  return 0;
}
