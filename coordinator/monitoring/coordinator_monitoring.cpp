#include "coordinator/monitoring/coordinator_monitoring.h"

#include <chrono>
#include <cstdio>
#include <thread>

#include "coordinator/monitoring/dashboard.h"

namespace poseforest::coordinator::monitoring {

core::Result<std::unique_ptr<CoordinatorMonitoring>> CoordinatorMonitoring::Start(
    const JobInfo& job, const std::string& http, const std::string& event_log, const std::string& http_token,
    const std::string& tls_cert, const std::string& tls_key) {
  std::unique_ptr<CoordinatorMonitoring> m(new CoordinatorMonitoring());
  m->model_ = std::make_unique<StatusModel>(job);
  std::vector<CoordinatorObserver*> targets = {m->model_.get()};
  if (!event_log.empty()) {
    auto log = EventLog::Open(event_log, job.job_id);
    if (!log.ok()) return log.status();
    m->log_ = std::move(*log);
    targets.push_back(m->log_.get());
  }
  m->fanout_ = ObserverFanOut(targets);
  if (http != "off") {
    proto::http::HttpServerOptions opt;
    POSEFOREST_RETURN_IF_ERROR(proto::http::ParseHttpAddress(http, &opt));
    opt.bearer_token = http_token;
    opt.tls_cert_file = tls_cert;
    opt.tls_key_file = tls_key;
    opt.log = [](const std::string& line) {
      std::fprintf(stderr, "coordinator: %s\n", line.c_str());
      std::fflush(stderr);
    };
    for (const std::string& w : proto::http::HttpExposureWarnings(
             opt, http, "the job's status, metrics and dashboard", "the job's status"))
      std::fprintf(stderr, "coordinator: %s\n", w.c_str());
    std::fflush(stderr);
    auto server = proto::http::HttpServer::Start(opt, StatusHandler(m->model_.get()));
    if (!server.ok()) return server.status();
    m->http_ = std::move(*server);
    m->model_->SetUrl(m->http_->url() + "/");
  }
  return m;
}

void CoordinatorMonitoring::Finish(bool ok, const std::string& message, double linger_s) {
  model_->Finish(ok, message);
  if (log_) {
    v1::JobEvent e;
    e.set_event(ok ? "FOREST_WRITTEN" : "JOB_FAILED");
    e.set_message(message);
    log_->Write(std::move(e));
  }
  if (http_ && http_->requests() > 0 && linger_s > 0)
    std::this_thread::sleep_for(std::chrono::duration<double>(linger_s));
}

}  // namespace poseforest::coordinator::monitoring
