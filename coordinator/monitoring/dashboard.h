#pragma once
// The coordinator's HTTP endpoints over a StatusModel: "/" (the dashboard: one self-contained
// HTML page whose script polls /status.json every second), "/status.json", "/metrics"
// (Prometheus text format 0.0.4) and "/healthz". docs/distributed/monitoring.md.

#include <string>

#include "coordinator/monitoring/status_model.h"
#include "proto/http/http_server.h"
#include "proto/http/prometheus_text.h"  // HttpServerMetrics (/metrics ends with the server's counters)

namespace poseforest::coordinator::monitoring {

/// The dashboard page (no external resources).
const std::string& DashboardHtml();

/// Routes requests to `model` (not owned; must outlive the server).
proto::http::HttpServer::Handler StatusHandler(const StatusModel* model);

}  // namespace poseforest::coordinator::monitoring
