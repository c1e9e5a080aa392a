#include "worker/worker_metrics.h"

#include <utility>
#include <vector>

#include "proto/dds/topics.h"
#include "proto/http/prometheus_text.h"

namespace poseforest::worker {

namespace {
using Samples = std::vector<std::pair<std::string, double>>;

std::string L(const char* name, const std::string& value) {
  return std::string(name) + "=\"" + proto::http::PromLabelValue(value) + "\"";
}

/// One sample per DDS topic ("topic" label: job, control, replies, presence, status).
template <typename Array>
Samples ByTopic(const Array& counts) {
  Samples out;
  for (proto::dds::Topic t : proto::dds::kAllTopics)
    out.push_back({L("topic", proto::dds::TopicShortName(t)), double(counts[size_t(t)])});
  return out;
}
}  // namespace

std::string WorkerPrometheus(const WorkerStats& s) {
  std::string m;
  auto family = [&m](const char* name, const char* type, const char* help, const Samples& samples) {
    proto::http::AppendPromFamily(&m, name, type, help, samples);
  };
  family("poseforest_build_info", "gauge", "The poseforest build serving these metrics (always 1).",
         {{L("version", POSEFOREST_BUILD_VERSION), 1}});
  family("poseforest_worker_info", "gauge", "The worker's sender id (always 1).",
         {{L("worker_id", s.worker_id), 1}});
  family("poseforest_worker_up", "gauge",
         "1 while the worker serves, 0 once it has stopped (the last scrapes before it exits).",
         {{"", s.stopped ? 0.0 : 1.0}});
  if (!s.job_id.empty())
    family("poseforest_worker_job_info", "gauge",
           "The job the worker joined last and its coordinator (always 1).",
           {{L("job_id", s.job_id) + "," + L("coordinator_id", s.coordinator_id), 1}});
  family("poseforest_worker_threads", "gauge", "Threads the worker computes with (--threads).",
         {{"", double(s.threads)}});
  family("poseforest_worker_busy_threads", "gauge",
         "Threads busy now in a histogram round or a subtree task (0 or the worker's threads).",
         {{"", double(s.busy_threads)}});

  Samples rounds;
  for (size_t i = 0; i < s.rounds.size(); ++i)
    rounds.push_back({L("phase", WorkerStats::kRoundPhases[i]), double(s.rounds[i])});
  family(
      "poseforest_worker_rounds_total", "counter",
      "Level requests answered, by phase (ranges: pass 1; histograms: pass 2; counts: the census at a tree's "
      "start; frames: frame lists before a subtree hand-off).",
      rounds);
  family("poseforest_worker_histograms_total", "counter",
         "Node histograms sent (fused ones answering pass 1, and pass 2's).", {{"", double(s.histograms)}});
  family("poseforest_worker_subtrees_total", "counter", "Subtrees trained and sent (subtree tasks done).",
         {{"", double(s.subtrees)}});
  family("poseforest_worker_subtree_nodes_total", "counter", "Nodes of the subtrees sent.",
         {{"", double(s.subtree_nodes)}});
  family("poseforest_worker_evaluations_total", "counter",
         "Sample x candidate evaluations binned by this worker, histogram rounds and subtree tasks.",
         {{"", double(s.evaluations)}});

  const std::string shard = L("frames", "shard"), subtree = L("frames", "subtree");
  family("poseforest_worker_frames_rendered_total", "counter",
         "Frames rendered or loaded: of the worker's shard, and of other shards for subtree tasks.",
         {{shard, double(s.shard_frames.rendered)}, {subtree, double(s.task_frames.rendered)}});
  family("poseforest_worker_render_seconds_total", "counter",
         "Wall seconds spent rendering or loading frames (shard frames on all threads at once).",
         {{shard, s.shard_frames.render_seconds}, {subtree, s.task_frames.render_seconds}});
  family("poseforest_worker_frame_cache_hits_total", "counter",
         "Frames needed and already held, not rendered again (shard: kept from the tree's last assignment; "
         "subtree: in the shard or the task-frame cache).",
         {{shard, double(s.shard_frames.cache_hits)}, {subtree, double(s.task_frames.cache_hits)}});
  family("poseforest_worker_frame_cache_evictions_total", "counter",
         "Frames dropped from the task-frame cache to stay under its cap (--task-cache-mb).",
         {{"", double(s.frame_cache_evictions)}});
  family("poseforest_worker_frame_cache_bytes", "gauge", "Bytes of frames in the task-frame cache now.",
         {{"", double(s.frame_cache_bytes)}});
  family("poseforest_worker_frame_cache_capacity_bytes", "gauge",
         "Cap of the task-frame cache (--task-cache-mb, or sized from the job).",
         {{"", double(s.frame_cache_capacity_bytes)}});

  family("poseforest_worker_messages_sent_total", "counter", "Messages written to DDS, by topic.",
         ByTopic(s.messages_sent));
  family("poseforest_worker_sent_bytes_total", "counter",
         "Serialized bytes of the messages written to DDS, by topic (replies: histograms and subtrees; "
         "presence: "
         "heartbeats).",
         ByTopic(s.bytes_sent));
  family("poseforest_worker_messages_received_total", "counter", "Messages taken off DDS, by topic.",
         ByTopic(s.messages_received));
  family("poseforest_worker_messages_dropped_total", "counter",
         "Messages the message gate dropped (rejected: malformed or not allowed; stale: an older epoch or "
         "level).",
         {{L("reason", "rejected"), double(s.messages_rejected)},
          {L("reason", "stale"), double(s.messages_stale)}});
  family("poseforest_worker_inbox_bytes", "gauge",
         "Bytes of messages taken off DDS and queued for the training thread now.",
         {{"", double(s.inbox_bytes)}});

  Samples cpu;
  for (const auto& [phase, seconds] : s.cpu.NamedPhases()) cpu.push_back({L("phase", phase), seconds});
  family("poseforest_worker_cpu_seconds_total", "counter",
         "CPU seconds of the training thread (and the frame-loading threads it starts) by phase, counted as "
         "each "
         "phase ends; the whole process (DDS, heartbeats, HTTP) is process_cpu_seconds_total.",
         cpu);
  return m + proto::http::ProcessMetrics();
}

proto::http::HttpServer::Handler WorkerMetricsHandler(const DistWorker* worker) {
  return [worker](const proto::http::HttpRequest& req) -> proto::http::HttpResponse {
    if (req.path == "/metrics")
      return {200, "text/plain; version=0.0.4; charset=utf-8",
              WorkerPrometheus(worker->Stats()) +
                  (req.server ? proto::http::HttpServerMetrics(*req.server) : "")};
    if (req.path == "/healthz") return {200, "text/plain; charset=utf-8", "ok\n"};
    return {404, "text/plain; charset=utf-8", "404 Not Found: " + req.path + " (try /metrics, /healthz)\n"};
  };
}

}  // namespace poseforest::worker
