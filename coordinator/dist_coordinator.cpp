// The coordinator's job, tree by tree: it wires the concept files together and runs the
// engine's frontier loop over the remote shard set, with hooks that hand small nodes off
// (subtree_scheduler.h), lay out and log every decision (level_records.h), checkpoint every
// level (checkpoint.h) and report each level's figures.

#include "coordinator/dist_coordinator.h"

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "coordinator/checkpoint.h"
#include "coordinator/level_records.h"
#include "coordinator/remote_shard_set.h"
#include "coordinator/rounds.h"
#include "coordinator/session.h"
#include "coordinator/subtree_scheduler.h"
#include "coordinator/worker_registry.h"
#include "engine/candidates.h"
#include "engine/frontier_loop.h"
#include "engine/image_source.h"
#include "proto/dds/node_config.h"
#include "runtime/core/forest_format.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;
using proto::dds::Topic;

struct DistCoordinator::Impl {
  Session s;
  LevelRecords records;
  WorkerRegistry registry{s, records.tree_decisions()};
  Rounds rounds{s, registry};
  SubtreeScheduler scheduler{s, registry, rounds, records};
  Checkpoint checkpoint;

  Impl(v1::TrainerConfig config, engine::TrainParams params, CoordinatorOptions options)
      : checkpoint(options.checkpoint_dir) {
    s.config = std::move(config);
    s.params = std::move(params);
    s.opt = std::move(options);
    s.job_id = s.opt.job_id;
    if (!s.opt.log)
      s.opt.log = [](const std::string& m) { std::fprintf(stderr, "[coordinator] %s\n", m.c_str()); };
    s.registry = &registry;
    registry.pump = [this](std::chrono::milliseconds timeout) { rounds.Pump(timeout); };
    rounds.on_subtree_result = [this](const std::string& sender, const v1::SubtreeResult& res) {
      scheduler.OnSubtreeResult(sender, res);
    };
  }

  /// The root of a fresh tree, its part counts from every worker's shard (a COUNTS round).
  Result<engine::OpenNode> Census(RemoteShardSet& shards) {
    engine::OpenNode root;
    root.position = engine::kRootPosition;
    s.level_time = {};
    POSEFOREST_RETURN_IF_ERROR(shards.CountParts(0, &root.parts));
    // The census waits for every worker's shard: its frames rendered (summed over workers).
    char line[160];
    std::snprintf(line, sizeof line, "tree %d: shards ready in %.2f s (workers rendered %.2f s in all)", s.tree,
                  s.level_time.round_s, s.level_time.render_s);
    s.Log(line);
    if (root.total() == 0)
      return Status(ErrorCode::kInvalidArgument, "tree " + std::to_string(s.tree) +
                                                     ": no body pixels in any of its " +
                                                     std::to_string(s.params.images_per_tree) + " frames");
    return root;
  }

  /// The frontier loop's before_decide: holds while the pause file exists, starts the level's
  /// figures, takes delegated nodes out of *to_split and hands off the small ones.
  Status BeforeDecide(int level, std::span<const engine::OpenNode> level_nodes, std::vector<size_t>* to_split,
                      RemoteShardSet& shards, LevelFigures& fig) {
    const CoordinatorOptions& opt = s.opt;
    if (!opt.pause_file.empty() && std::filesystem::exists(opt.pause_file)) {
      s.Log("paused (next: tree " + std::to_string(s.tree) + ", level " + std::to_string(level) + "); remove " +
            opt.pause_file + " to go on");
      while (std::filesystem::exists(opt.pause_file)) rounds.Pump(std::chrono::milliseconds(50));
      s.Log("resumed");
    }
    fig = LevelFigures{};
    fig.t_level = proto::dds::NowSeconds();
    s.level_bytes_received = s.level_bytes_sent = 0;
    s.level_retries = 0;
    scheduler.BeginLevel();
    s.level_time = {};
    shards.ResetTimes();
    fig.frontier_size = level_nodes.size();
    for (const engine::OpenNode& f : level_nodes) fig.samples += f.total();
    // Nodes of delegated subtrees are decided by their SubtreeResult.
    std::erase_if(*to_split, [&](size_t i) { return records.delegated().count(level_nodes[i].position) > 0; });
    if (opt.observer) {
      opt.observer->OnLevelStart(s.tree, level, level_nodes.size(), fig.samples);
      opt.observer->OnNodesDecided(level_nodes.size() - to_split->size(), level_nodes.size());
    }
    auto handed = scheduler.HandOff(level, level_nodes, fig.samples, to_split);
    if (!handed.ok()) return handed.status();
    fig.handed_off = *handed;
    fig.histogram_nodes = to_split->size();
    return Status::Ok();
  }

  /// The frontier loop's after_decide: the level's subtree results in, its decisions begun.
  Status AfterDecide(int level, RemoteShardSet& shards, LevelFigures& fig) {
    if (scheduler.has_tasks()) {
      const double t_wait = proto::dds::NowSeconds();
      POSEFOREST_RETURN_IF_ERROR(scheduler.WaitSubtrees());
      shards.AddWait(proto::dds::NowSeconds() - t_wait);
      s.level_time.subtree_wait_s += proto::dds::NowSeconds() - t_wait;
      scheduler.TakeResults(&records.delegated());
      fig.evaluations += scheduler.level_evaluations();
      if (s.opt.observer) s.opt.observer->OnNodesDecided(fig.frontier_size, fig.frontier_size);
    }
    records.BeginLevel(s.tree, level, checkpoint.AddLevel());
    shards.decisions = records.level_decisions();
    return Status::Ok();
  }

  DistLevelStats LevelStats(const engine::LevelDone& done, const RemoteShardSet& shards, const LevelFigures& fig) {
    DistLevelStats st;
    st.tree = s.tree;
    st.level = done.level;
    st.frontier_nodes = done.frontier_nodes;
    st.split_nodes = done.split_nodes;
    st.samples = done.samples;
    st.evaluations = fig.evaluations;
    st.evaluations_per_s = shards.hist_seconds() > 0 ? double(fig.evaluations) / shards.hist_seconds() : 0;
    st.workers_alive = registry.AliveCount();
    st.workers_assigned = registry.AssignedCount();
    st.bytes_received = s.level_bytes_received;
    st.bytes_sent = s.level_bytes_sent;
    st.merge_seconds = shards.merge_seconds();
    st.level_seconds = proto::dds::NowSeconds() - fig.t_level;
    st.elapsed_s = proto::dds::NowSeconds() - s.start;
    st.retries = s.level_retries;
    st.subtree_tasks = fig.handed_off;
    st.subtree_nodes = fig.from_subtrees;
    for (const auto& [id, n] : scheduler.level_handed())
      st.subtree_samples += n, st.subtree_samples_busiest = std::max(st.subtree_samples_busiest, n);
    st.subtree_largest_task = scheduler.level_largest_task();
    st.subtree_task_messages = scheduler.level_task_messages();
    st.mean_entropy = done.samples > 0 ? fig.entropy_sum / double(done.samples) : 0;
    st.mean_gain = done.split_nodes > 0 ? fig.gain_sum / double(done.split_nodes) : 0;
    const TimeSplit& time = s.level_time;
    st.rounds = time.rounds;
    st.round_seconds = time.round_s;
    st.round_compute_seconds = time.compute_s;
    st.round_queued_seconds = time.queued_s;
    st.round_traffic_seconds = time.traffic_s;
    st.subtree_wait_seconds = time.subtree_wait_s;
    st.subtree_busy_seconds = time.subtree_busy_s;
    st.render_seconds = time.render_s;
    return st;
  }

  /// The frontier loop's level_done: checkpoint, figures, status; the test hook's "crash".
  Status LevelDone(const engine::LevelDone& done, RemoteShardSet& shards, const LevelFigures& fig,
                   int* levels_done) {
    shards.decisions = nullptr;
    POSEFOREST_RETURN_IF_ERROR(checkpoint.LevelDone(done.next, records.delegated(), s.epoch));
    const DistLevelStats st = LevelStats(done, shards, fig);
    if (s.opt.progress) s.opt.progress(st);
    if (s.opt.observer) s.opt.observer->OnLevelDone(st);
    const double progress =
        (double(s.tree) + std::min(1.0, double(done.level + 1) / double(s.params.max_depth + 1))) /
        double(s.params.num_trees);
    s.PublishStatus(v1::STATUS_KIND_LEVEL_DONE, "level done", "", done.level, progress);
    s.last_progress = progress;
    ++*levels_done;
    if (s.opt.stop_after_levels >= 0 && *levels_done >= s.opt.stop_after_levels)
      return Status(ErrorCode::kInternal, "stopped after " + std::to_string(*levels_done) + " levels (test hook)");
    return Status::Ok();
  }

  Result<core::Tree> TrainTree(std::vector<engine::OpenNode> frontier, int first_level, int* levels_done) {
    const engine::TrainParams& params = s.params;
    POSEFOREST_RETURN_IF_ERROR(records.BeginTree(checkpoint.record()));
    scheduler.Clear();
    // Resumed after its last level, before the tree was filed as finished: nothing left to do.
    if (first_level > 0 && frontier.empty()) return records.FinishTree();
    // Shards: every frame of the tree over the live workers; replays of resumed levels included.
    registry.ClearAssignments();
    POSEFOREST_RETURN_IF_ERROR(registry.Distribute({{0, uint32_t(params.images_per_tree)}}));
    const int merge_threads = s.opt.merge_threads > 0 ? s.opt.merge_threads
                              : params.threads > 0    ? params.threads
                                                      : omp_get_max_threads();
    RemoteShardSet shards(s, registry, rounds, records, merge_threads);
    if (frontier.empty()) {
      auto root = Census(shards);
      if (!root.ok()) return root.status();
      frontier.push_back(std::move(*root));
    }
    LevelFigures fig;  // per level: what the hooks below share
    engine::FrontierLoopHooks hooks;
    hooks.before_decide = [&](int level, std::span<const engine::OpenNode> level_nodes,
                              std::vector<size_t>* to_split) -> Status {
      return BeforeDecide(level, level_nodes, to_split, shards, fig);
    };
    hooks.after_batch = [&](size_t decided, uint64_t /*batch_bytes*/) {
      if (s.opt.observer)
        s.opt.observer->OnNodesDecided(fig.frontier_size - fig.histogram_nodes - fig.handed_off + decided,
                                       fig.frontier_size);
    };
    hooks.after_decide = [&](int level) -> Status { return AfterDecide(level, shards, fig); };
    hooks.place = [&](const engine::OpenNode& f, engine::NodeDecision& d) -> Result<uint32_t> {
      return records.Place(f, d, &fig);
    };
    hooks.level_done = [&](const engine::LevelDone& done) -> Status {
      return LevelDone(done, shards, fig, levels_done);
    };
    POSEFOREST_RETURN_IF_ERROR(engine::RunFrontierLoop(shards, params, s.tree, first_level, std::move(frontier),
                                                       records.num_nodes(),
                                                       std::min(params.histogram_memory_bytes, s.opt.max_batch_bytes),
                                                       hooks));
    return records.FinishTree();
  }

  Result<core::Forest> Train() {
    const engine::TrainParams& params = s.params;
    s.start = proto::dds::NowSeconds();
    std::string config_bytes;
    s.config.SerializeToString(&config_bytes);
    s.StartSender();

    // The forest's header (constants, parts, training focal length), recorded in the checkpoint
    // so `poseforest export` writes the same one on a machine without the job's files.
    auto shell = engine::EmptyForest(params);
    if (!shell.ok()) return shell.status();
    // Resume.
    auto at = checkpoint.Start(s.job_id, config_bytes, s.build_id, shell->training_fx, shell->training_fy,
                               s.opt.resume);
    if (!at.ok()) return at.status();
    std::vector<core::Tree> trees = std::move(at->trees);
    std::vector<engine::OpenNode> frontier = std::move(at->frontier);
    int first_level = at->first_level;
    if (at->resumed) {
      s.epoch = at->epoch;
      s.Log("resuming " + s.job_id + " at tree " + std::to_string(trees.size()) + " level " +
            std::to_string(first_level));
    }

    POSEFOREST_RETURN_IF_ERROR(s.Announce());
    POSEFOREST_RETURN_IF_ERROR(registry.WaitForWorkers(std::max(1, s.opt.min_workers)));

    int levels_done = 0;
    for (int t = int(trees.size()); t < params.num_trees; ++t) {
      s.tree = t;
      if (size_t(t) < s.opt.min_workers_per_tree.size())
        POSEFOREST_RETURN_IF_ERROR(registry.WaitForWorkers(s.opt.min_workers_per_tree[size_t(t)]));
      records.RestoreDecisions(t, checkpoint.record().current());
      auto tr = TrainTree(std::move(frontier), first_level, &levels_done);
      if (!tr.ok()) {
        s.PublishStatus(v1::STATUS_KIND_ERROR, tr.status().ToString());
        return tr.status();
      }
      trees.push_back(std::move(*tr));
      frontier.clear();
      first_level = 0;
      POSEFOREST_RETURN_IF_ERROR(checkpoint.TreeDone(t, s.epoch));
      s.last_progress = double(t + 1) / params.num_trees;
      s.PublishStatus(v1::STATUS_KIND_TREE_DONE, "tree done", "", 0, s.last_progress);
    }
    core::Forest forest = *shell;
    forest.trees = std::move(trees);
    POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(forest, "trained forest"));
    s.PublishStatus(v1::STATUS_KIND_JOB_DONE, "job done", "", 0, 1.0);
    // A worker lost during the job may be coming back (a new DDS participant): it waits for
    // JOB_DONE, which we say again when it is back.
    (void)registry.AwaitLostWorkers(s.opt.done_grace,
                                    [&] { s.PublishStatus(v1::STATUS_KIND_JOB_DONE, "job done", "", 0, 1.0); });
    (void)s.node->WaitForAcknowledgments(Topic::kStatus, std::chrono::milliseconds(2000));
    return forest;
  }
};

DistCoordinator::DistCoordinator(v1::TrainerConfig config, engine::TrainParams params,
                                 CoordinatorOptions options)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(params), std::move(options))) {}

DistCoordinator::~DistCoordinator() = default;

Result<core::Forest> DistCoordinator::Train() { return impl_->Train(); }
const std::string& DistCoordinator::job_id() const { return impl_->s.job_id; }
uint64_t DistCoordinator::bytes_received() const { return impl_->s.total_bytes_received; }
uint64_t DistCoordinator::rejected_messages() const {
  return (impl_->s.gate ? impl_->s.gate->total_rejected() : 0) + impl_->scheduler.rejected();
}
int DistCoordinator::workers_lost() const { return impl_->registry.lost_count(); }
uint64_t DistCoordinator::stale_messages() const { return impl_->s.stale_count; }

}  // namespace poseforest::coordinator
