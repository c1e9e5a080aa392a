#pragma once
// The worker's own metrics (`poseforest worker --http ADDR`): /metrics in Prometheus text format
// 0.0.4 from DistWorker::Stats(), and /healthz, on the services' HTTP server (proto/http). The
// coordinator's /metrics shows each worker as the coordinator sees it (its replies); this is the
// worker's side: what it computed, rendered, cached and sent, and where its CPU went.
// docs/distributed/monitoring.md, "The worker's /metrics".

#include <string>

#include "proto/http/http_server.h"
#include "worker/dist_worker.h"

namespace poseforest::worker {

/// `stats` as Prometheus text: counters (`_total`, base units) and gauges, each with HELP and TYPE
/// lines, then the process's CPU, memory and start time (ProcessMetrics). No `job` label (Prometheus
/// sets it to the scrape job); the job joined is in poseforest_worker_job_info{job_id,coordinator_id}.
std::string WorkerPrometheus(const WorkerStats& stats);

/// Routes "/metrics" (WorkerPrometheus of `worker->Stats()`, then the server's own counters) and
/// "/healthz" ("ok"); anything else is a 404. `worker` is not owned and must outlive the server.
proto::http::HttpServer::Handler WorkerMetricsHandler(const DistWorker* worker);

}  // namespace poseforest::worker
