#pragma once
// The coordinator's live status for monitoring: job, tree, level, nodes decided, throughput,
// ETA, per-level entropy and gain, workers with their state and throughput, recent events.
// Fed on the training thread (a CoordinatorObserver), read by the HTTP server's thread as JSON
// (/status.json, `poseforest monitor`, the dashboard) and Prometheus text (/metrics).
// Schema: JobStatus in proto/poseforest/v1/status.proto (docs/distributed/monitoring.md).

#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "coordinator/dist_coordinator.h"
#include "poseforest/v1/status.pb.h"

namespace poseforest::coordinator::monitoring {

/// What the status model knows about the job before it starts.
struct JobInfo {
  std::string job_id;
  uint32_t domain = 0;
  std::string profile;  ///< shm | udp | default
  int num_trees = 0;
  int max_depth = 0;
  int images_per_tree = 0;
  int pixels_per_image = 0;
  int candidate_features = 0;
  int thresholds_per_feature = 0;
  std::string out_path;  ///< the forest file the coordinator will write
};

class StatusModel : public CoordinatorObserver {
 public:
  explicit StatusModel(JobInfo info);

  void OnStatus(const v1::StatusEvent& e) override;
  void OnLevelStart(int tree, int level, size_t nodes, uint64_t samples) override;
  void OnNodesDecided(size_t done, size_t total) override;
  void OnLevelDone(const DistLevelStats& s) override;
  void OnWorkerSeen(const std::string& id) override;
  void OnWorkerAssigned(const std::string& id, int tree, uint64_t frames) override;
  void OnWorkerReply(const std::string& id, uint64_t bytes, const v1::HistogramReply& reply) override;
  void OnWorkerHeartbeat(const std::string& id, const v1::Heartbeat& hb) override;
  /// The figures of Json() in a StatusEvent (monitor --domain), with the newest
  /// kMaxStatusLevels rows of "levels"; a PROGRESS event also gets the tree and level in
  /// training and the progress. Clamped to what the message gate accepts.
  void FillStatus(v1::StatusEvent* e) override;

  /// The run ended: state "done" (ok) or "failed", with `message` (the error or what was written).
  void Finish(bool ok, const std::string& message);
  /// The dashboard's address, shown in the JSON (empty: none).
  void SetUrl(const std::string& url);

  /// The status now (schema: proto/poseforest/v1/status.proto).
  v1::JobStatus Snapshot() const;
  /// Snapshot() as one line of JSON (GET /status.json), every field present.
  std::string Json() const;
  /// Prometheus text exposition format 0.0.4.
  std::string Prometheus() const;

  /// Most events kept for "events" in the JSON; levels kept for "levels".
  static constexpr size_t kMaxEvents = 50;
  static constexpr size_t kMaxLevels = 2000;
  /// Most workers listed in a StatusEvent (the gate allows 4096).
  static constexpr int kMaxStatusWorkers = 1024;
  /// Most levels (the newest) in a StatusEvent (the gate allows 256): a 3-tree depth-20 job
  /// whole, ~3.5 KiB per event.
  static constexpr int kMaxStatusLevels = 64;

 private:
  struct Worker {
    std::string state = "joined";  ///< joined | training | lost | evicted | refused | done
    double joined = 0;             ///< unix seconds
    double last_seen = 0;          ///< steady seconds
    uint64_t frames = 0;           ///< frames of tree `tree` it holds
    int tree = -1;
    uint64_t replies = 0;
    uint64_t samples = 0;  ///< samples counted in its histograms
    uint64_t evaluations = 0;
    uint64_t bytes = 0;
    double compute_s = 0;  ///< its own reported compute time
    // Its heartbeats' figures: histogram rounds and subtree tasks (those replies lack).
    uint64_t reported_evaluations = 0;
    double reported_rate = 0;
    // Frames of other shards for its subtree tasks, of tree task_tree (counts restart per tree).
    int task_tree = -1;
    uint64_t task_rendered = 0, task_cached = 0, task_evicted = 0;
    // Throughput over its recent replies (a sliding window of ~10 s of compute).
    std::deque<std::pair<double, uint64_t>> recent;  ///< (steady time, evaluations)
  };
  struct Event {
    double unix_s = 0;
    std::string kind, worker, message;
    int tree = 0, level = 0;
  };

  double Progress() const;  // 0..1, lock held
  double Eta() const;       // seconds, < 0 unknown; lock held
  double WorkerRate(const Worker& w, double now) const;

  mutable std::mutex mu_;
  JobInfo info_;
  std::string state_ = "waiting";  ///< waiting | training | done | failed
  std::string message_, url_;
  double start_unix_ = 0, start_steady_ = 0, train_start_steady_ = -1, end_steady_ = -1;
  int tree_ = 0, level_ = 0, trees_done_ = 0, levels_done_in_tree_ = 0;
  size_t nodes_done_ = 0, nodes_total_ = 0;
  uint64_t level_samples_ = 0;
  uint64_t nodes_finished_trees_ = 0, nodes_current_tree_ = 1;  ///< node counts of the trees
  double samples_per_s_ = 0, evaluations_per_s_ = 0;
  uint64_t total_samples_ = 0, total_evaluations_ = 0, total_bytes_received_ = 0, total_bytes_sent_ = 0;
  uint64_t total_levels_ = 0, total_retries_ = 0, workers_lost_ = 0, workers_evicted_ = 0;
  double total_level_s_ = 0;
  std::vector<DistLevelStats> levels_;
  std::map<std::string, Worker> workers_;
  std::deque<Event> events_;
};

/// Forwards every observer call to each of `targets` (not owned, non-null).
class ObserverFanOut : public CoordinatorObserver {
 public:
  explicit ObserverFanOut(std::vector<CoordinatorObserver*> targets) : targets_(std::move(targets)) {}
  void OnStatus(const v1::StatusEvent& e) override {
    for (auto* t : targets_) t->OnStatus(e);
  }
  void OnLevelStart(int tree, int level, size_t nodes, uint64_t samples) override {
    for (auto* t : targets_) t->OnLevelStart(tree, level, nodes, samples);
  }
  void OnNodesDecided(size_t done, size_t total) override {
    for (auto* t : targets_) t->OnNodesDecided(done, total);
  }
  void OnLevelDone(const DistLevelStats& s) override {
    for (auto* t : targets_) t->OnLevelDone(s);
  }
  void OnWorkerSeen(const std::string& id) override {
    for (auto* t : targets_) t->OnWorkerSeen(id);
  }
  void OnWorkerAssigned(const std::string& id, int tree, uint64_t frames) override {
    for (auto* t : targets_) t->OnWorkerAssigned(id, tree, frames);
  }
  void OnWorkerReply(const std::string& id, uint64_t bytes, const v1::HistogramReply& r) override {
    for (auto* t : targets_) t->OnWorkerReply(id, bytes, r);
  }
  void OnWorkerHeartbeat(const std::string& id, const v1::Heartbeat& hb) override {
    for (auto* t : targets_) t->OnWorkerHeartbeat(id, hb);
  }
  void FillStatus(v1::StatusEvent* e) override {
    for (auto* t : targets_) t->FillStatus(e);
  }

 private:
  std::vector<CoordinatorObserver*> targets_;
};

/// `s` with every byte that is not part of well-formed UTF-8 replaced by U+FFFD (a protobuf
/// string must be UTF-8; worker ids and messages come from peers).
std::string ValidUtf8(const std::string& s);
/// `v`, or 0 when it is NaN or infinite (the JSON figures are numbers, never "NaN").
double Finite(double v);
/// `m` as one line of JSON by Protobuf's printer, field names as in the .proto; `every_field`:
/// also the fields at their default (0, "", []), else only the fields set.
std::string MessageJson(const google::protobuf::Message& m, bool every_field);
/// Short name of a StatusKind ("LEVEL_DONE", ...).
std::string StatusKindName(v1::StatusKind kind);
/// Seconds since the Unix epoch (wall clock).
double UnixSeconds();

}  // namespace poseforest::coordinator::monitoring
