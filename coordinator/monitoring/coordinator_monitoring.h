#pragma once
// The monitoring of one `poseforest coordinator` run: the status model, the HTTP server (dashboard,
// /status.json, /metrics) and the event log, set up from the command's --http / --event-log
// options and fed through CoordinatorOptions::observer. docs/distributed/monitoring.md.

#include <memory>
#include <string>

#include "coordinator/monitoring/event_log.h"
#include "coordinator/monitoring/status_model.h"
#include "proto/http/http_server.h"

namespace poseforest::coordinator::monitoring {

/// Default of `coordinator --http`: loopback, a free port chosen by the kernel (printed).
inline constexpr const char* kDefaultHttp = "127.0.0.1:0";

class CoordinatorMonitoring {
 public:
  /// `http`: "off" or HOST:PORT; `event_log`: a file to append to, or empty; `http_token`: the
  /// bearer token every HTTP request but /healthz must carry (empty: none; ReadHttpTokenFile);
  /// `tls_cert`/`tls_key`: PEM files for HTTPS (both or neither). Refused requests and failed TLS
  /// handshakes are logged to stderr ("coordinator: http: 401 ... from IP:PORT", rate-limited); a
  /// non-loopback address without a token, or with a token but without TLS, prints a warning.
  /// Errors: a bad address, certificate or key (InvalidArgument), a port in use, an event log
  /// that cannot be opened.
  static core::Result<std::unique_ptr<CoordinatorMonitoring>> Start(
      const JobInfo& job, const std::string& http, const std::string& event_log,
      const std::string& http_token = "", const std::string& tls_cert = "", const std::string& tls_key = "");

  /// For CoordinatorOptions::observer.
  CoordinatorObserver* observer() { return &fanout_; }
  StatusModel& model() { return *model_; }
  /// "http://HOST:PORT" ("https://" with TLS) or empty when --http off.
  std::string url() const { return http_ ? http_->url() : ""; }

  /// The run ended: final state in the model and the event log (FOREST_WRITTEN or JOB_FAILED).
  /// When someone has been reading the status (a monitor, a dashboard), keeps serving the final
  /// state for `linger_s` seconds so that they see it.
  void Finish(bool ok, const std::string& message, double linger_s);

 private:
  CoordinatorMonitoring() : fanout_({}) {}
  std::unique_ptr<StatusModel> model_;
  std::unique_ptr<EventLog> log_;
  std::unique_ptr<proto::http::HttpServer> http_;
  ObserverFanOut fanout_;
};

}  // namespace poseforest::coordinator::monitoring
