#pragma once
// Prometheus text exposition format 0.0.4, as the services' /metrics pages write it
// (coordinator/monitoring/status_model.cpp, worker/worker_metrics.cpp): escaping, numbers, the
// HELP/TYPE lines of a family, and the series every page ends with (the status server's own
// counters, the process's CPU, memory and start time). Names follow Prometheus's conventions,
// checked by `promtool check metrics` in the tests: base units (seconds, bytes) at the end of the
// name, `_total` after it on counters. docs/distributed/monitoring.md.

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace poseforest::proto::http {

class HttpServer;

/// A label value: backslash, double quote and newline escaped.
std::string PromLabelValue(std::string_view s);

/// A sample value: shortest round-trip decimal ("%.17g"), NaN, +Inf, -Inf.
std::string PromNumber(double v);

/// Appends one metric family to `*out`: "# HELP name help", "# TYPE name type" (`type`: "counter"
/// or "gauge"), then a line per sample, `samples` being (labels, value) with labels as written
/// inside the braces (`a="x",b="y"`, values through PromLabelValue), or empty for none. A family
/// without samples is written with its HELP and TYPE lines only.
void AppendPromFamily(std::string* out, std::string_view name, std::string_view type, std::string_view help,
                      const std::vector<std::pair<std::string, double>>& samples);

/// The status server's own counters (poseforest_http_requests_total by outcome: ok, bad_request,
/// unauthorized, rejected_connection, tls_handshake_failed); each service's /metrics ends with them.
std::string HttpServerMetrics(const HttpServer& server);

/// The process's standard series, as Prometheus's client libraries name them:
/// process_cpu_seconds_total (user + system CPU of every thread), process_resident_memory_bytes and
/// process_start_time_seconds (Unix time; from /proc, absent where it cannot be read).
std::string ProcessMetrics();

}  // namespace poseforest::proto::http
