#include "coordinator/monitoring/event_log.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>

#include "coordinator/monitoring/status_model.h"

namespace poseforest::dist {

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

void EventLog::Write(const std::string& event,
                     const std::vector<std::pair<std::string, std::string>>& fields) {
  const double now = UnixSeconds();
  std::string line = "{\"time\":" + JsonString(IsoTime(now)) + ",\"unix\":" + JsonNumber(now) +
                     ",\"job\":" + JsonString(job_id_) + ",\"event\":" + JsonString(event);
  for (const auto& [k, v] : fields) line += "," + JsonString(k) + ":" + v;
  line += "}\n";
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
  Write("WORKER_ASSIGNED",
        {{"worker", JsonString(id)}, {"tree", std::to_string(tree)}, {"frames", std::to_string(frames)}});
}

void EventLog::OnStatus(const v1::StatusEvent& e) {
  std::vector<std::pair<std::string, std::string>> f = {
      {"tree", std::to_string(e.tree())},
      {"level", std::to_string(e.level())},
      {"epoch", std::to_string(e.epoch())},
      {"progress", JsonNumber(e.progress())},
      {"active_workers", std::to_string(e.active_workers())},
  };
  if (!e.worker_id().empty()) f.push_back({"worker", JsonString(e.worker_id())});
  if (!e.message().empty()) f.push_back({"message", JsonString(e.message())});
  if (e.kind() == v1::STATUS_KIND_LEVEL_DONE && have_level_) {
    const DistLevelStats& s = last_level_;
    f.insert(f.end(), {{"nodes", std::to_string(s.frontier_nodes)},
                       {"split", std::to_string(s.split_nodes)},
                       {"samples", std::to_string(s.samples)},
                       {"evaluations", std::to_string(s.evaluations)},
                       {"evaluations_per_s", JsonNumber(s.evaluations_per_s)},
                       {"mean_entropy", JsonNumber(s.mean_entropy)},
                       {"mean_gain", JsonNumber(s.mean_gain)},
                       {"bytes_received", std::to_string(s.bytes_received)},
                       {"seconds", JsonNumber(s.level_seconds)},
                       {"retries", std::to_string(s.retries)}});
  }
  Write(StatusKindName(e.kind()), f);
}

}  // namespace poseforest::dist
