#include "coordinator/monitoring/event_log.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <ctime>

#include "coordinator/monitoring/status_model.h"

namespace poseforest::coordinator::monitoring {

using core::ErrorCode;
using core::Status;

namespace {
std::string IsoTime(double unix_s) {
  const auto secs = std::time_t(std::floor(unix_s));
  std::tm tm{};
  ::gmtime_r(&secs, &tm);
  char buf[48];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1,
                tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, int((unix_s - std::floor(unix_s)) * 1000));
  return buf;
}
}  // namespace

core::Result<std::unique_ptr<EventLog>> EventLog::Open(const std::string& path, const std::string& job_id) {
  std::unique_ptr<EventLog> log(new EventLog());
  log->file_ = std::fopen(path.c_str(), "ae");
  if (!log->file_) return Status(ErrorCode::kIo, "event log " + path + ": " + std::strerror(errno));
  log->path_ = path;
  log->job_id_ = job_id;
  return log;
}

EventLog::~EventLog() {
  if (file_) std::fclose(file_);
}

void EventLog::Write(v1::JobEvent e) {
  const double now = UnixSeconds();
  e.set_time(IsoTime(now));
  e.set_unix(now);
  e.set_job(ValidUtf8(job_id_));
  if (e.has_worker()) e.set_worker(ValidUtf8(e.worker()));
  if (e.has_message()) e.set_message(ValidUtf8(e.message()));
  const std::string line = MessageJson(e, /*every_field=*/false) + "\n";
  std::lock_guard<std::mutex> lock(mu_);
  // A full disk must not stop training: the error is not fatal, the line is lost.
  (void)std::fwrite(line.data(), 1, line.size(), file_);
  (void)std::fflush(file_);
}

void EventLog::OnLevelDone(const DistLevelStats& s) {
  last_level_ = s;
  have_level_ = true;
}

void EventLog::OnWorkerAssigned(const std::string& id, int tree, uint64_t frames) {
  v1::JobEvent e;
  e.set_event("WORKER_ASSIGNED");
  e.set_worker(id);
  e.set_tree(tree);
  e.set_frames(double(frames));
  Write(std::move(e));
}

void EventLog::OnStatus(const v1::StatusEvent& s) {
  v1::JobEvent e;
  e.set_event(StatusKindName(s.kind()));
  e.set_tree(int32_t(s.tree()));
  e.set_level(int32_t(s.level()));
  e.set_epoch(uint32_t(std::min<uint64_t>(s.epoch(), UINT32_MAX)));
  e.set_progress(Finite(s.progress()));
  e.set_active_workers(s.active_workers());
  if (!s.worker_id().empty()) e.set_worker(s.worker_id());
  if (!s.message().empty()) e.set_message(s.message());
  if (s.kind() == v1::STATUS_KIND_LEVEL_DONE && have_level_) {
    const DistLevelStats& l = last_level_;
    e.set_nodes(uint32_t(std::min<size_t>(l.frontier_nodes, UINT32_MAX)));
    e.set_split(uint32_t(std::min<size_t>(l.split_nodes, UINT32_MAX)));
    e.set_samples(double(l.samples));
    e.set_evaluations(double(l.evaluations));
    e.set_evaluations_per_s(Finite(l.evaluations_per_s));
    e.set_mean_entropy(Finite(l.mean_entropy));
    e.set_mean_gain(Finite(l.mean_gain));
    e.set_bytes_received(double(l.bytes_received));
    e.set_seconds(Finite(l.level_seconds));
    e.set_retries(l.retries);
    e.set_rounds(l.rounds);
    e.set_round_seconds(Finite(l.round_seconds));
    e.set_compute_seconds(Finite(l.round_compute_seconds));
    e.set_queued_seconds(Finite(l.round_queued_seconds));
    e.set_traffic_seconds(Finite(l.round_traffic_seconds));
    e.set_merge_seconds(Finite(l.merge_seconds));
    e.set_subtree_wait_seconds(Finite(l.subtree_wait_seconds));
    e.set_subtree_busy_seconds(Finite(l.subtree_busy_seconds));
    e.set_render_seconds(Finite(l.render_seconds));
    e.set_subtree_tasks(uint32_t(std::min<size_t>(l.subtree_tasks, UINT32_MAX)));
  }
  Write(std::move(e));
}

}  // namespace poseforest::coordinator::monitoring
