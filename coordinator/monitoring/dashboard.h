#pragma once
// The coordinator's HTTP endpoints over a StatusModel: "/" (the dashboard: one self-contained
// HTML page whose script polls /status.json every second), "/status.json", "/metrics"
// (Prometheus text format 0.0.4) and "/healthz". docs/distributed/monitoring.md.

#include <string>

#include "coordinator/monitoring/http_server.h"
#include "coordinator/monitoring/status_model.h"

namespace poseforest::dist {

/// The dashboard page (no external resources).
const std::string& DashboardHtml();

/// The status server's own counters in Prometheus text (poseforest_http_requests_total by outcome:
/// ok, bad_request, unauthorized, rejected_connection, tls_handshake_failed); /metrics ends with them.
std::string HttpServerMetrics(const HttpServer& server);

/// Routes requests to `model` (not owned; must outlive the server).
HttpServer::Handler StatusHandler(const StatusModel* model);

}  // namespace poseforest::dist
