#pragma once
// Helpers of the distributed-service tests: a tiny job, the LocalTrainer reference bytes, and
// in-process workers on threads.

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "coordinator/dist_coordinator.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/forest_format.h"
#include "tests/support/dds_domain.h"
#include "worker/dist_worker.h"

namespace poseforest::coordinator::testing {

/// A fresh directory under the system temp dir ("<name>-<pid>"), removed with its contents.
struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& name)
      : path(std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

/// A whole file's bytes / text ("" or empty when it cannot be read).
inline std::vector<uint8_t> ReadAll(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
inline std::string ReadText(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// A job small enough for a loaded 2-core machine (procedural frames, small images).
/// `subtree_max_samples`: nodes of at most this many samples go to one worker whole
/// (SubtreeTask); 0 (the default here) keeps every level on histogram rounds. `subtree_max_frames`
/// (the frame rule, job.proto) is 0 here unless given: 12 frames per tree would hand off every
/// node of level >= 1.
inline std::string TinyJobText(int trees = 2, int depth = 6, uint64_t subtree_max_samples = 0,
                               uint32_t subtree_max_frames = 0) {
  return "seed: 5\nnum_trees: " + std::to_string(trees) + "\nmax_depth: " + std::to_string(depth) +
         "\nimages_per_tree: 12\npixels_per_image: 150\ncandidate_features: 40\nthresholds_per_feature: 12\n"
         "max_probe_offset_pixel_m: 60\nthreshold_reference_pixels: 200\n"
         "subtree_max_samples: " +
         std::to_string(subtree_max_samples) + "\nsubtree_max_frames: " + std::to_string(subtree_max_frames) +
         "\n"
         "source { procedural { seed: 9 width: 96 height: 72 } }\n";
}

struct Job {
  v1::TrainerConfig config;
  engine::TrainParams params;
};

inline Job ParseJob(const std::string& text) {
  auto c = engine::ParseJobText(text, "tiny.textproto");
  if (!c.ok()) throw std::runtime_error(c.status().ToString());
  auto p = engine::ParamsFromConfig(*c, "tiny.textproto");
  if (!p.ok()) throw std::runtime_error(p.status().ToString());
  p->threads = 1;
  return {*c, *p};
}

/// SerializeForest bytes of LocalTrainer on `job` (one shard).
inline std::vector<uint8_t> ReferenceBytes(const Job& job) {
  engine::LocalTrainer trainer(job.params, {});
  auto forest = trainer.Train();
  if (!forest.ok()) throw std::runtime_error(forest.status().ToString());
  return core::SerializeForest(*forest);
}

/// A domain id unlikely to collide with parallel test processes.
/// A domain no parallel test process uses (tests/support/dds_domain.h); the same `offset` gives
/// the same domain within a process.
inline uint32_t Domain(uint32_t offset) { return poseforest::testing::UniqueDomain(offset); }

/// N DistWorkers on threads; stopped and joined on destruction.
class ThreadWorkers {
 public:
  ThreadWorkers(int n, uint32_t domain, const std::string& job_id) {
    for (int i = 0; i < n; ++i)
      Add(domain, job_id, "tw-" + std::to_string(::getpid()) + "-" + std::to_string(i));
  }
  void Add(uint32_t domain, const std::string& job_id, const std::string& id) {
    worker::WorkerOptions o;
    o.worker_id = id;
    o.domain = domain;
    o.job_id = job_id;
    Add(std::move(o));
  }
  /// A worker with the caller's options (test hooks); threads 1, stays after the job.
  void Add(worker::WorkerOptions o) {
    o.threads = 1;
    o.exit_when_done = false;
    if (!std::getenv("POSEFOREST_TEST_VERBOSE")) o.log = [](const std::string&) {};
    workers_.push_back(std::make_unique<worker::DistWorker>(o));
    worker::DistWorker* w = workers_.back().get();
    threads_.emplace_back([w] { (void)w->Run(); });
  }
  worker::DistWorker& worker(size_t i) { return *workers_[i]; }
  void Stop(size_t i) {
    workers_[i]->Stop();
    if (threads_[i].joinable()) threads_[i].join();
  }
  ~ThreadWorkers() {
    for (size_t i = 0; i < workers_.size(); ++i) Stop(i);
  }

 private:
  std::vector<std::unique_ptr<worker::DistWorker>> workers_;
  std::vector<std::thread> threads_;
};

}  // namespace poseforest::coordinator::testing
