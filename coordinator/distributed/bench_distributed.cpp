// Figures of the distributed service on a small procedural job, in one process (workers on
// threads, DDS over shared memory): bytes received and coordinator merge time per level, and
// evaluations/s with 1 and 2 workers vs LocalTrainer. Not a timed test.
//   poseforest_bench_distributed [JOB.textproto] [--domain D]

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
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--domain") && i + 1 < argc) {
      domain = uint32_t(std::atoi(argv[++i]));
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

  for (int n : {1, 2}) {
    std::vector<std::unique_ptr<dist::DistWorker>> workers;
    std::vector<std::thread> threads;
    const std::string job_id = "bench-" + std::to_string(n);
    for (int i = 0; i < n; ++i) {
      dist::WorkerOptions wo;
      wo.worker_id = "bench-w" + std::to_string(i);
      wo.domain = domain + uint32_t(n);
      wo.job_id = job_id;
      wo.threads = 1;
      wo.exit_when_done = false;
      wo.log = [](const std::string&) {};
      workers.push_back(std::make_unique<dist::DistWorker>(wo));
      threads.emplace_back([w = workers.back().get()] { (void)w->Run(); });
    }
    dist::CoordinatorOptions co;
    co.domain = domain + uint32_t(n);
    co.job_id = job_id;
    co.min_workers = n;
    co.log = [](const std::string&) {};
    uint64_t evals = 0, bytes = 0;
    double merge = 0;
    std::printf(
        "\n%d worker(s):\n  level  nodes  samples   bytes_received  merge_ms  level_s  evaluations/s\n", n);
    co.progress = [&](const dist::DistLevelStats& s) {
      evals += s.evaluations;
      bytes += s.bytes_received;
      merge += s.merge_seconds;
      std::printf("  %5d  %5zu  %7llu  %15llu  %8.2f  %7.3f  %.3g\n", s.level, s.frontier_nodes,
                  (unsigned long long)s.samples, (unsigned long long)s.bytes_received, s.merge_seconds * 1e3,
                  s.level_seconds, s.evaluations_per_s);
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
  }
  return 0;
}
