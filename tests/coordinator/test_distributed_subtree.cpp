// Subtree hand-off (SubtreeTask / SubtreeResult): small nodes are trained whole by one worker,
// and the forest is still byte-identical to LocalTrainer's with 1, 2, 3 workers, when the
// worker holding a task dies, when a worker answers with a hostile result, and across a
// coordinator restart. Workers on threads, real DDS participants over shared memory.

#include <array>
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <thread>

#include "engine/candidates.h"
#include "engine/subtree_trainer.h"
#include "tests/coordinator/dist_test_util.h"

using namespace poseforest;
using namespace poseforest::proto::dds;
using namespace poseforest::worker;
using namespace poseforest::coordinator;
using namespace poseforest::coordinator::testing;

namespace {
CoordinatorOptions Options(uint32_t domain, int min_workers) {
  CoordinatorOptions o;
  o.domain = domain;
  o.min_workers = min_workers;
  o.worker_wait = std::chrono::seconds(30);
  if (!std::getenv("POSEFOREST_TEST_VERBOSE")) o.log = [](const std::string&) {};
  return o;
}

/// Levels with hand-offs and nodes decided by subtree results, summed over a run.
struct HandOff {
  size_t tasks = 0, nodes = 0, histogram_levels = 0;
  int retries = 0;
  /// Per level with hand-offs: samples handed, to the busiest worker, the largest task.
  std::vector<std::array<uint64_t, 3>> handed;
  void Add(const DistLevelStats& s) {
    tasks += s.subtree_tasks;
    nodes += s.subtree_nodes;
    histogram_levels += s.subtree_nodes < s.frontier_nodes;
    retries += s.retries;
    if (s.subtree_samples > 0)
      handed.push_back({s.subtree_samples, s.subtree_samples_busiest, s.subtree_largest_task});
  }
};

/// The level's time split (the per-level table) adds up: each round's critical worker computing +
/// its request queued + traffic is the rounds' wall time, and rounds + merge + waiting for
/// subtrees fit in the level's wall time. Summed over a run.
struct TimeSplit {
  double compute = 0, queued = 0, traffic = 0, subtree_wait = 0, subtree_busy = 0, render = 0, first_compute = 0;
  int rounds = 0;
  void Add(const DistLevelStats& s) {
    INFO("tree " << s.tree << " level " << s.level);
    CHECK(s.round_compute_seconds + s.round_queued_seconds + s.round_traffic_seconds ==
          Approx(s.round_seconds).margin(1e-6));
    CHECK(s.round_seconds + s.merge_seconds + s.subtree_wait_seconds <= s.level_seconds + 1e-6);
    if (s.level == 0) {  // the root is split by histogram rounds
      CHECK(s.rounds >= 1);
      first_compute += s.round_compute_seconds;
    }
    compute += s.round_compute_seconds, queued += s.round_queued_seconds, traffic += s.round_traffic_seconds;
    subtree_wait += s.subtree_wait_seconds, subtree_busy += s.subtree_busy_seconds, render += s.render_seconds;
    rounds += s.rounds;
  }
};

// Tiny job: 1800 samples at the root, ~900 at depth 1; 300 hands off nodes from depth ~2 on.
constexpr uint64_t kSubtreeMax = 300;
}  // namespace

TEST_CASE("heap positions: children, parents and depths", "[distributed][unit]") {
  CHECK(engine::LeftChildPosition(0) == 1);
  CHECK(engine::RightChildPosition(0) == 2);
  CHECK(engine::ParentPosition(5) == 2);
  CHECK(engine::ParentPosition(6) == 2);
  CHECK(engine::PositionDepth(0) == 0);
  CHECK(engine::PositionDepth(2) == 1);
  CHECK(engine::PositionDepth(6) == 2);
  CHECK(engine::PositionDepth((uint64_t(1) << 31) - 2) == 30);  // deepest node of a depth-30 tree
}

TEST_CASE("with subtree hand-off the forest is byte-identical to LocalTrainer with 1, 2, 3 workers",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(2, 6, kSubtreeMax));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  // The job without hand-off gives the same bytes (LocalTrainer ignores the setting).
  CHECK(ReferenceBytes(ParseJob(TinyJobText(2, 6, 0))) == reference);
  for (int n : {1, 2, 3}) {
    DYNAMIC_SECTION(n << " workers") {
      const uint32_t domain = Domain(40 + uint32_t(n));
      const std::string job_id = "t-subtree-" + std::to_string(n);
      ThreadWorkers workers(n, domain, job_id);
      CoordinatorOptions o = Options(domain, n);
      o.job_id = job_id;
      HandOff h;
      TimeSplit time;
      o.progress = [&](const DistLevelStats& s) { h.Add(s), time.Add(s); };
      DistCoordinator coordinator(job.config, job.params, o);
      auto forest = coordinator.Train();
      INFO(forest.status().ToString());
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      CHECK(time.first_compute > 0);  // the workers' compute_micros arrived
      CHECK(time.subtree_busy > 0);   // and the SubtreeResults' busy_micros
      CHECK(h.tasks >= 2);             // deep nodes were handed off ...
      CHECK(h.nodes > h.tasks);        // ... and their subtrees came back whole
      CHECK(h.histogram_levels >= 2);  // the shallow levels still ran histogram rounds
      // Every level's subtree work is spread over the workers: largest task first to the least
      // loaded, so the busiest worker gets at most an even share plus one task (list
      // scheduling's bound), however the samples sit in the workers' shards.
      for (const auto& [total, busiest, largest] : h.handed) {
        INFO(total << " samples handed, " << busiest << " to the busiest worker, largest task " << largest);
        CHECK(busiest <= (total + uint64_t(n) - 1) / uint64_t(n) + largest);
        if (n > 1 && total > 2 * largest) CHECK(busiest < total);
      }
      CHECK(coordinator.workers_lost() == 0);
      CHECK(coordinator.rejected_messages() == 0);
    }
  }
}

TEST_CASE("the frame rule hands off larger nodes whose samples lie in few frames; same forest",
          "[distributed][integration]") {
  // 12 frames per tree: every node's samples lie in at most 12 frames, so with
  // subtree_max_frames 16 nodes of up to min(16 x 100, a quarter of the tree's samples per
  // worker) samples go whole from level 1 on; with 0 only nodes of at most 100 samples do.
  constexpr uint64_t kSmall = 100;
  const std::vector<uint8_t> reference = ReferenceBytes(ParseJob(TinyJobText(1, 6, kSmall, 16)));
  CHECK(ReferenceBytes(ParseJob(TinyJobText(1, 6, kSmall, 0))) == reference);
  for (uint32_t frames : {0u, 16u, 11u}) {
    DYNAMIC_SECTION("subtree_max_frames " << frames) {
      const Job job = ParseJob(TinyJobText(1, 6, kSmall, frames));
      const uint32_t domain = Domain(60 + frames);
      const std::string job_id = "t-subtree-frames-" + std::to_string(frames);
      ThreadWorkers workers(2, domain, job_id);
      CoordinatorOptions o = Options(domain, 2);
      o.job_id = job_id;
      HandOff h;
      uint64_t largest = 0;
      int first_level = -1;
      o.progress = [&](const DistLevelStats& s) {
        h.Add(s);
        largest = std::max(largest, s.subtree_largest_task);
        if (s.subtree_tasks > 0 && first_level < 0) first_level = s.level;
      };
      DistCoordinator coordinator(job.config, job.params, o);
      auto forest = coordinator.Train();
      INFO(forest.status().ToString());
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      CHECK(h.tasks >= 2);
      if (frames == 0 || frames == 11) {
        // The sample rule alone (11 < the frames a node of level 1-2 spans: those stay on rounds).
        CHECK(largest <= kSmall);
      } else {
        CHECK(largest > kSmall);  // handed off by the frame rule
        CHECK(largest <= 16 * kSmall);
        CHECK(first_level <= 2);
      }
      CHECK(coordinator.rejected_messages() == 0);
    }
  }
}

TEST_CASE("a worker lost while it holds a subtree task: the task goes to another, same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 6, kSubtreeMax));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(47);
  const std::string job_id = "t-subtree-loss";
  ThreadWorkers workers(0, domain, job_id);
  std::atomic<int> died{0};
  for (int i = 0; i < 3; ++i) {
    WorkerOptions w;
    w.worker_id = "tw-" + std::to_string(::getpid()) + "-sl" + std::to_string(i);
    w.domain = domain;
    w.job_id = job_id;
    // The first task that reaches any worker kills that worker.
    w.die_on_subtree_task = [&died] { return died.fetch_add(1) == 0; };
    workers.Add(std::move(w));
  }
  CoordinatorOptions o = Options(domain, 3);
  o.job_id = job_id;
  o.heartbeat_timeout = std::chrono::milliseconds(2000);
  HandOff h;
  o.progress = [&](const DistLevelStats& s) { h.Add(s); };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  CHECK(died >= 1);
  CHECK(coordinator.workers_lost() == 1);
  CHECK(h.retries >= 1);
  CHECK(h.tasks >= 2);
  CHECK(core::SerializeForest(*forest) == reference);
}

// A 6,000-image job died with "DataWriter::write failed on poseforest/control (history
// full for 10 s ...)": each small node went out as its own SubtreeTask sample, every worker's
// reader gets every control sample, and a worker busy in a long batch read none of them, so
// the keep-all history filled and the coordinator's write failed. At CI size: histories of 4
// samples, 300 ms write slices, a worker that holds 2.5 s when its first tasks arrive, and a
// level handing off far more than 4 nodes. Before the fix this failed at the first such level.
TEST_CASE("a worker busy in a subtree batch never fails the job (small control history)",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 8, 60));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(48);
  const std::string job_id = "t-subtree-busy";
  TransportExtras small;
  small.keep_all_max_samples = 4;
  small.write_block_slice = std::chrono::milliseconds(300);
  ThreadWorkers workers(0, domain, job_id);
  std::atomic<int> held{0};
  for (int i = 0; i < 2; ++i) {
    WorkerOptions w;
    w.worker_id = "tw-" + std::to_string(::getpid()) + "-busy" + std::to_string(i);
    w.domain = domain;
    w.job_id = job_id;
    w.transport_extras = small;
    // The first worker to get subtree tasks trains nothing for 2.5 s (a long batch).
    w.hold_on_subtree_task = [&held] {
      if (held.fetch_add(1) == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2500));
    };
    workers.Add(std::move(w));
  }
  CoordinatorOptions o = Options(domain, 2);
  o.job_id = job_id;
  o.transport_extras = small;
  HandOff h;
  TimeSplit time;
  double longest_subtree_wait = 0, most_queued = 0;
  uint64_t most_tasks = 0, most_messages = 0;
  o.progress = [&](const DistLevelStats& s) {
    h.Add(s);
    time.Add(s);
    longest_subtree_wait = std::max(longest_subtree_wait, s.subtree_wait_seconds);
    most_queued = std::max(most_queued, s.round_queued_seconds);
    most_tasks = std::max<uint64_t>(most_tasks, s.subtree_tasks);
    most_messages = std::max<uint64_t>(most_messages, s.subtree_task_messages);
    // A level's tasks go as one SubtreeTasks message per worker (these are far below 4 MiB).
    CHECK(s.subtree_task_messages <= 2);
    if (s.subtree_tasks > 0) CHECK(s.subtree_task_messages >= 1);
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  CHECK(held >= 1);
  // The held worker's 2.5 s show in the level's split: the coordinator waited for its subtree
  // results after the rounds, or a round's request waited in its inbox.
  INFO("longest subtree wait " << longest_subtree_wait << " s, most queued " << most_queued << " s");
  CHECK(std::max(longest_subtree_wait, most_queued) >= 2.0);
  INFO("most tasks in a level " << most_tasks);
  CHECK(most_tasks >= 12);  // one sample each would be 3x the history
  CHECK(coordinator.workers_lost() == 0);
  CHECK(coordinator.rejected_messages() == 0);
  CHECK(core::SerializeForest(*forest) == reference);
}

// In a 2,000-image run the rounds of levels 7-13 waited 883 of 1,917 s for
// workers busy in subtree batches ("busy before it"). A worker now answers queued rounds at
// every pause of a batch (between its histogram batches and levels). Here each pause sleeps
// 150 ms, so a batch takes seconds: the rounds' requests must not wait for whole batches.
// Before the change a round's request waited for the rest of the batch (queued about half the
// workers' subtree seconds, as two workers share them); now at most a pause or two per round.
TEST_CASE("a worker answers queued rounds in the middle of its subtree batch; same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 8, 200));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(79);
  const std::string job_id = "t-subtree-serve";
  ThreadWorkers workers(0, domain, job_id);
  std::atomic<int> pauses{0};
  for (int i = 0; i < 2; ++i) {
    WorkerOptions w;
    w.worker_id = "tw-" + std::to_string(::getpid()) + "-serve" + std::to_string(i);
    w.domain = domain;
    w.job_id = job_id;
    w.in_subtree_batch = [&pauses] {
      ++pauses;
      std::this_thread::sleep_for(std::chrono::milliseconds(150));
    };
    workers.Add(std::move(w));
  }
  CoordinatorOptions o = Options(domain, 2);
  o.job_id = job_id;
  TimeSplit time;
  HandOff h;
  o.progress = [&](const DistLevelStats& s) { time.Add(s), h.Add(s); };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  CHECK(core::SerializeForest(*forest) == reference);
  INFO(pauses << " pauses; rounds " << time.rounds << ", queued " << time.queued << " s, workers' subtree work "
              << time.subtree_busy << " s, " << h.tasks << " tasks");
  REQUIRE(h.tasks >= 4);
  REQUIRE(time.subtree_busy >= 3.0);  // the pauses made the batches long
  CHECK(time.queued <= 0.25 * time.subtree_busy);
  CHECK(coordinator.workers_lost() == 0);
}

// Seen in a 2,000-image run: a coordinator busy for longer than the heartbeat timeout (a long
// merge on a loaded machine) took a live worker for lost, because it handled one queued sample
// and then checked the heartbeats, the rest of them still queued. Here the coordinator sleeps
// 3 s after each level with a 2 s heartbeat timeout; the workers heartbeat all along.
TEST_CASE("a coordinator busy past the heartbeat timeout does not take live workers for lost",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 3));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(49);
  const std::string job_id = "t-busy-coordinator";
  ThreadWorkers workers(2, domain, job_id);
  CoordinatorOptions o = Options(domain, 2);
  o.job_id = job_id;
  o.heartbeat_timeout = std::chrono::milliseconds(2000);
  int levels = 0;
  o.progress = [&](const DistLevelStats&) {
    ++levels;
    std::this_thread::sleep_for(std::chrono::milliseconds(3000));
  };
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  CHECK(levels >= 2);
  CHECK(coordinator.workers_lost() == 0);
  CHECK(core::SerializeForest(*forest) == reference);
}

// A 2,000-image run stopped in tree 2 on a livelock: after a pause the coordinator sent a
// worker's ShardAssignment again every 3 s, each with a new epoch, and the worker loaded each in
// turn, each load slower than 3 s. Here the worker is busy for 3.5 s when its first assignment
// arrives (a re-send queues behind it) and every load takes 3.2 s. Before the fix it loaded
// assignment after assignment and never answered the level.
TEST_CASE("a worker busy when its assignment arrives loads it once (no re-send livelock)",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 3));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(56);
  const std::string job_id = "t-assign-busy";
  ThreadWorkers workers(0, domain, job_id);
  std::atomic<int> taken{0}, loads{0};
  WorkerOptions w;
  w.worker_id = "tw-" + std::to_string(::getpid()) + "-slowload";
  w.domain = domain;
  w.job_id = job_id;
  w.hold_before_shard = [&taken] {
    if (taken.fetch_add(1) == 0) std::this_thread::sleep_for(std::chrono::milliseconds(3500));
  };
  w.hold_in_shard_load = [&loads] {
    ++loads;
    std::this_thread::sleep_for(std::chrono::milliseconds(3200));
  };
  workers.Add(std::move(w));
  CoordinatorOptions o = Options(domain, 1);
  o.job_id = job_id;
  std::vector<std::string> log;
  std::mutex log_mu;
  o.log = [&](const std::string& line) {
    std::lock_guard<std::mutex> lock(log_mu);
    log.push_back(line);
  };
  // Without the fix this never ends: give up after a minute instead of ctest's timeout.
  o.reply_timeout = std::chrono::seconds(60);
  DistCoordinator coordinator(job.config, job.params, o);
  auto forest = coordinator.Train();
  INFO(forest.status().ToString());
  REQUIRE(forest.ok());
  int resent = 0;
  for (const std::string& line : log) resent += line.find("has not seen its assignment") != std::string::npos;
  INFO("assignments taken " << taken << ", loaded " << loads << ", re-sent " << resent);
  CHECK(resent >= 1);      // the busy worker did get one again while busy
  CHECK(taken >= 2);       // and took both
  CHECK(loads == 1);       // but loaded one: the newest
  CHECK(coordinator.workers_lost() == 0);
  CHECK(core::SerializeForest(*forest) == reference);
}

TEST_CASE("a hostile SubtreeResult is dropped, counted, its sender evicted; same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(1, 6, kSubtreeMax));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  for (int corrupt : {1, 2}) {  // 1: a root at the wrong position; 2: part counts that do not add up
    DYNAMIC_SECTION("corruption " << corrupt) {
      const uint32_t domain = Domain(50 + uint32_t(corrupt));
      const std::string job_id = "t-subtree-hostile-" + std::to_string(corrupt);
      // The liar is alone when the tree starts, so it holds every sample and gets the first
      // task; an honest worker joins after the root level and gets the task after the eviction.
      ThreadWorkers workers(0, domain, job_id);
      WorkerOptions liar;
      liar.worker_id = "tw-" + std::to_string(::getpid()) + "-liar";
      liar.domain = domain;
      liar.job_id = job_id;
      liar.corrupt_subtree_results = corrupt;
      workers.Add(std::move(liar));
      CoordinatorOptions o = Options(domain, 1);
      o.job_id = job_id;
      HandOff h;
      bool added = false;
      o.progress = [&](const DistLevelStats& s) {
        h.Add(s);
        if (!added) {
          CHECK(s.subtree_tasks == 0);
          workers.Add(domain, job_id, "tw-" + std::to_string(::getpid()) + "-honest");
          added = true;
        }
      };
      DistCoordinator coordinator(job.config, job.params, o);
      auto forest = coordinator.Train();
      INFO(forest.status().ToString());
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      CHECK(h.tasks >= 2);
      CHECK(h.retries >= 1);                   // the liar's task was handed on
      CHECK(coordinator.workers_lost() == 1);  // the liar, evicted
      CHECK(coordinator.rejected_messages() >= 1);
    }
  }
}

TEST_CASE("coordinator stopped with delegated subtrees pending resumes: same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(2, 6, kSubtreeMax));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  const uint32_t domain = Domain(53);
  const std::string job_id = "t-subtree-resume";
  const auto dir = std::filesystem::temp_directory_path() / ("pf-subtree-ckpt-" + std::to_string(::getpid()));
  ThreadWorkers workers(2, domain, job_id);
  for (int stop_after : {3, 4, 9}) {
    DYNAMIC_SECTION("stop after " << stop_after << " levels") {
      std::filesystem::remove_all(dir);
      CoordinatorOptions o = Options(domain, 2);
      o.job_id = job_id;
      o.checkpoint_dir = dir.string();
      o.stop_after_levels = stop_after;
      HandOff before;
      o.progress = [&](const DistLevelStats& s) { before.Add(s); };
      {
        DistCoordinator first(job.config, job.params, o);
        auto r = first.Train();
        REQUIRE(!r.ok());
        CHECK(r.status().message().find("test hook") != std::string::npos);
      }
      o.stop_after_levels = -1;
      o.resume = true;
      HandOff after;
      o.progress = [&](const DistLevelStats& s) { after.Add(s); };
      DistCoordinator second(job.config, job.params, o);
      auto forest = second.Train();
      INFO(forest.status().ToString());
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      CHECK(before.tasks + after.tasks >= 2);
    }
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("subtree tasks: listed samples or routing, a task-frame cache that evicts: same forest",
          "[distributed][integration]") {
  const Job job = ParseJob(TinyJobText(2, 6, kSubtreeMax));
  const std::vector<uint8_t> reference = ReferenceBytes(job);
  // A frame of the tiny job: 96 x 72 depth + 150 samples; the cap holds one, so nearly every
  // frame a task renders pushes another out.
  constexpr uint64_t kFrameBytes = 96 * 72 * 2 + 150 * sizeof(engine::PixelSample);
  for (const bool lists : {true, false}) {
    DYNAMIC_SECTION((lists ? "samples listed in the task" : "samples routed along the path")) {
      const uint32_t domain = Domain(lists ? 48 : 49);
      const std::string job_id = std::string("t-subtree-cache-") + (lists ? "l" : "r");
      ThreadWorkers workers(0, domain, job_id);
      for (int i = 0; i < 2; ++i) {
        WorkerOptions w;
        w.worker_id = "tw-" + std::to_string(::getpid()) + "-c" + std::to_string(i);
        w.domain = domain;
        w.job_id = job_id;
        w.task_cache_bytes = kFrameBytes + kFrameBytes / 2;
        workers.Add(std::move(w));
      }
      CoordinatorOptions o = Options(domain, 2);
      o.job_id = job_id;
      o.subtree_sample_lists = lists;
      HandOff h;
      o.progress = [&](const DistLevelStats& s) { h.Add(s); };
      DistCoordinator coordinator(job.config, job.params, o);
      auto forest = coordinator.Train();
      INFO(forest.status().ToString());
      REQUIRE(forest.ok());
      CHECK(core::SerializeForest(*forest) == reference);
      CHECK(coordinator.rejected_messages() == 0);
      workers.Stop(0);
      workers.Stop(1);
      WorkerCpu sum;
      for (size_t i = 0; i < 2; ++i) {
        const WorkerCpu& c = workers.worker(i).cpu();
        sum.subtree_tasks += c.subtree_tasks;
        sum.task_frames += c.task_frames;
        sum.task_cache_evictions += c.task_cache_evictions;
        CHECK(c.task_cache_peak_bytes <= kFrameBytes + kFrameBytes / 2);
        CHECK(c.run_total > 0);
        CHECK(c.Phases() <= c.run_total + 0.05);  // the main thread's phases are part of the process
      }
      CHECK(sum.subtree_tasks == h.tasks);   // every task counted once (no retries here)
      CHECK(sum.task_frames >= 2);           // frames of the other shard were rendered ...
      CHECK(sum.task_cache_evictions >= 1);  // ... and the cap pushed some out
    }
  }
}

TEST_CASE("a SubtreeTask's listed samples are checked against the frame's sampled pixels",
          "[distributed][unit]") {
  // Sampled pixels (ascending) of a 10-pixel-wide frame: indices 1, 5 and 12.
  const std::vector<engine::PixelSample> picked = {{1, 0, 3}, {5, 0, 4}, {2, 1, 5}};
  std::vector<engine::PixelSample> out;
  auto select = [&](std::vector<uint32_t> deltas) {
    return SelectListedSamples(picked, 10, 7, deltas, &out);
  };
  REQUIRE(select({1, 4, 7}).ok());
  REQUIRE(out.size() == 3);
  CHECK(out[2].x == 2);
  CHECK(out[2].y == 1);
  CHECK(out[2].part == 5);
  REQUIRE(select({5}).ok());
  REQUIRE(out.size() == 1);
  CHECK(out[0].part == 4);
  REQUIRE(select({}).ok());
  CHECK(out.empty());
  const core::Status twice = select({1, 0});
  CHECK(twice.code() == core::ErrorCode::kInvalidArgument);
  CHECK_THAT(twice.message(), Catch::Contains("frame 7") && Catch::Contains("pixel 1 listed twice"));
  const core::Status absent = select({1, 2});
  CHECK(absent.code() == core::ErrorCode::kInvalidArgument);
  CHECK_THAT(absent.message(), Catch::Contains("frame 7: pixel 3 is not one of its sampled pixels"));
  CHECK_FALSE(select({13}).ok());  // past the last sampled pixel
}

TEST_CASE("TrainSubtrees: several roots in one sample set give each root's TrainSubtree result",
          "[distributed][unit]") {
  const Job job = ParseJob(TinyJobText(1, 8, 0));
  const engine::TrainParams& p = job.params;
  auto source = engine::MakeImageSource(p.source);
  REQUIRE(source.ok());
  // Root A: the samples of the even frames, at heap position 3; root B: the odd frames', at 5.
  engine::SampleSet all, even, odd;
  std::vector<uint32_t> node_of_sample;
  std::vector<uint64_t> parts_a(size_t(core::kNumParts), 0), parts_b(size_t(core::kNumParts), 0);
  for (uint64_t i = 0; i < 12; ++i) {
    auto frame = (*source)->Frame(i);
    REQUIRE(frame.ok());
    const auto picked = engine::SamplePixels(*frame, p.pixels_per_image, p.part_balance,
                                             core::CounterRng(p.seed, 0, i, engine::kSamplingStream));
    if (picked.empty()) continue;
    all.AddFrame(i, frame->depth, picked, p.constants);
    (i % 2 ? odd : even).AddFrame(i, frame->depth, picked, p.constants);
    for (const engine::PixelSample& s : picked) {
      node_of_sample.push_back(uint32_t(i % 2));
      ++(i % 2 ? parts_b : parts_a)[s.part];
    }
  }
  all.StartTree(node_of_sample);
  even.StartTree(0);
  odd.StartTree(0);
  REQUIRE(all.RangeOf(0).end - all.RangeOf(0).begin == even.num_samples());
  REQUIRE(all.RangeOf(1).end - all.RangeOf(1).begin == odd.num_samples());
  engine::HistogramBuilder b1(p.constants, 1), b2(p.constants, 1), b3(p.constants, 1);
  auto a = engine::TrainSubtree(even, 0, p, 0, 3, parts_a, b1);
  auto b = engine::TrainSubtree(odd, 0, p, 0, 5, parts_b, b2);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  // Counts that do not match a root's samples: an error naming that root (checked before any
  // training, so `all` is untouched).
  std::vector<uint64_t> off_by_one = parts_b;
  ++off_by_one[0];
  const std::vector<engine::SubtreeRoot> wrong = {{0, 3, parts_a}, {1, 5, off_by_one}};
  auto bad = engine::TrainSubtrees(all, wrong, p, 0, b3);
  CHECK_FALSE(bad.ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("position 5"));
  const std::vector<engine::SubtreeRoot> roots = {{0, 3, parts_a}, {1, 5, parts_b}};
  auto both = engine::TrainSubtrees(all, roots, p, 0, b3);
  INFO(both.status().ToString());
  REQUIRE(both.ok());
  REQUIRE(both->size() == 2);
  for (const auto& [one, together] : {std::pair{&*a, &(*both)[0]}, std::pair{&*b, &(*both)[1]}}) {
    CHECK(one->nodes.size() > 3);  // a real subtree, deeper than one split
    REQUIRE(one->nodes.size() == together->nodes.size());
    for (size_t n = 0; n < one->nodes.size(); ++n) {
      CHECK(one->nodes[n].position == together->nodes[n].position);
      CHECK(one->nodes[n].split == together->nodes[n].split);
      CHECK(one->nodes[n].cut == together->nodes[n].cut);
      CHECK(one->nodes[n].parts == together->nodes[n].parts);
    }
    REQUIRE(one->tree.nodes.size() == together->tree.nodes.size());
    CHECK(std::memcmp(one->tree.nodes.data(), together->tree.nodes.data(),
                      one->tree.nodes.size() * sizeof(core::Node)) == 0);
    CHECK(one->tree.leaves == together->tree.leaves);
    CHECK(one->evaluations == together->evaluations);
  }
  CHECK(b3.evaluations() == b1.evaluations() + b2.evaluations());
}

TEST_CASE("a worker's task set: frames added once in any order, samples per batch, same subtrees",
          "[distributed][unit]") {
  // What a worker does with batches of SubtreeTasks: its frames are copied into one set once
  // (here in reverse order, as tasks ask for them), then each batch adds its samples, trains,
  // and clears them. Every subtree equals the one trained on a fresh set built with AddFrame.
  const Job job = ParseJob(TinyJobText(1, 8, 0));
  const engine::TrainParams& p = job.params;
  auto source = engine::MakeImageSource(p.source);
  REQUIRE(source.ok());
  std::vector<core::DepthImage> depth;
  std::vector<std::vector<engine::PixelSample>> picked;
  for (uint64_t i = 0; i < 12; ++i) {
    auto frame = (*source)->Frame(i);
    REQUIRE(frame.ok());
    depth.push_back(frame->depth);
    picked.push_back(engine::SamplePixels(*frame, p.pixels_per_image, p.part_balance,
                                          core::CounterRng(p.seed, 0, i, engine::kSamplingStream)));
  }
  engine::SampleSet kept;
  std::vector<uint32_t> local(12);
  for (uint64_t i = 12; i-- > 0;) local[i] = kept.AddFrameOnly(i, depth[i], p.constants);
  CHECK(kept.num_frames() == 12);
  CHECK(kept.num_samples() == 0);
  // Batch 1: the even frames; batch 2: frames 3..10. Each against a fresh set.
  for (const auto& frames :
       {std::vector<uint64_t>{0, 2, 4, 6, 8, 10}, std::vector<uint64_t>{3, 4, 5, 6, 7, 8, 9, 10}}) {
    engine::SampleSet fresh;
    std::vector<uint64_t> parts(size_t(core::kNumParts), 0);
    kept.ClearSamples();
    for (uint64_t i : frames) {
      if (picked[i].empty()) continue;
      fresh.AddFrame(i, depth[i], picked[i], p.constants);
      kept.AddSamples(local[i], depth[i], picked[i], p.constants);
      for (const engine::PixelSample& s : picked[i]) ++parts[s.part];
    }
    REQUIRE(kept.num_samples() == fresh.num_samples());
    fresh.StartTree(0);
    kept.StartTree(0);
    engine::HistogramBuilder b1(p.constants, 1), b2(p.constants, 1);
    auto a = engine::TrainSubtree(fresh, 0, p, 0, 4, parts, b1);
    auto b = engine::TrainSubtree(kept, 0, p, 0, 4, parts, b2);
    REQUIRE(a.ok());
    REQUIRE(b.ok());
    CHECK(a->nodes.size() > 3);
    REQUIRE(a->tree.nodes.size() == b->tree.nodes.size());
    CHECK(std::memcmp(a->tree.nodes.data(), b->tree.nodes.data(),
                      a->tree.nodes.size() * sizeof(core::Node)) == 0);
    CHECK(a->tree.leaves == b->tree.leaves);
    CHECK(a->evaluations == b->evaluations);
  }
  CHECK(kept.num_frames() == 12);  // no frame copied twice
}

TEST_CASE("the automatic task-frame cache holds a tree's frames within an eighth of memory",
          "[distributed][unit]") {
  engine::TrainParams p;
  p.source.width = 640;
  p.source.height = 480;
  p.pixels_per_image = 2000;
  p.images_per_tree = 2000;
  const uint64_t frame = 640 * 480 * 2 + 2000 * sizeof(engine::PixelSample);
  // A 2,000-image tree (13,029 evictions at the old 256 MiB): all of it fits.
  CHECK(TaskCacheBytesFor(p, uint64_t(24) << 30) == 2000 * frame);
  CHECK(TaskCacheBytesFor(p, uint64_t(4) << 30) == uint64_t(512) << 20);  // an eighth of 4 GiB
  p.images_per_tree = 12;
  CHECK(TaskCacheBytesFor(p, uint64_t(24) << 30) == uint64_t(256) << 20);  // at least 256 MiB
}
