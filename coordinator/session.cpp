#include "coordinator/session.h"

#include <unistd.h>

#include <algorithm>

#include "coordinator/worker_registry.h"
#include "proto/dds/build_id.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"

namespace poseforest::coordinator {

using core::Status;
using proto::dds::Topic;

namespace {
constexpr int kParts = core::kNumParts;
}  // namespace

Status Session::Send(Topic topic, v1::Envelope& env) {
  const std::string bytes = stamper.Seal(topic, env);
  if (topic == Topic::kControl) level_bytes_sent += bytes.size();
  return node->Publish(topic, bytes);
}

void Session::PublishStatus(v1::StatusKind kind, const std::string& message, const std::string& worker, int level,
                            double progress) {
  v1::Envelope env;
  auto* s = env.mutable_status();
  s->set_kind(kind);
  s->set_tree(uint32_t(std::max(0, tree)));
  s->set_level(uint32_t(level));
  s->set_epoch(epoch);
  s->set_progress(std::clamp(progress, 0.0, 1.0));
  s->set_worker_id(worker);
  s->set_message(message);
  s->set_active_workers(uint32_t(registry ? registry->AliveCount() : 0));
  if (opt.observer) {
    if (kind != v1::STATUS_KIND_PROGRESS) opt.observer->OnStatus(*s);
    opt.observer->FillStatus(s);  // throughput, ETA, workers (monitor --domain)
  }
  last_status_time = proto::dds::NowSeconds();
  (void)Send(Topic::kStatus, env);
}

void Session::StartSender() {
  if (job_id.empty()) job_id = engine::DefaultJobId(config);
  build_id = proto::dds::BuildId();
  // A fresh sender id per run: a restarted coordinator is a new sender (sequence numbers
  // restart), and workers take its announcement as "start over".
  char host[128] = {};
  ::gethostname(host, sizeof host - 1);
  self_id = "coordinator-" + std::string(host) + "-" + std::to_string(::getpid()) + "-" +
            std::to_string(uint64_t(proto::dds::NowSeconds() * 1e6) & 0xFFFFFF);
  stamper = proto::dds::EnvelopeStamper(job_id, self_id, v1::SENDER_KIND_COORDINATOR);
  gate = std::make_unique<proto::dds::MessageGate>(proto::dds::GateConfig{self_id, job_id, 16, opt.log});
  gate->set_num_parts(uint32_t(kParts));
}

Status Session::Announce() {
  proto::dds::NodeConfig node_config =
      proto::dds::MakeNodeConfig(opt.domain, opt.transport, true, self_id, opt.lease, opt.udp_peers,
                                 opt.udp_interfaces, opt.transport_extras);
  node_config.log = opt.log;
  auto n = proto::dds::DdsNode::Create(node_config);
  if (!n.ok()) return n.status();
  node = std::move(*n);
  v1::Envelope job_env;
  auto* job = job_env.mutable_job();
  *job->mutable_config() = config;
  job->set_coordinator_id(self_id);
  job->set_num_parts(uint32_t(kParts));
  job->set_thresholds_per_feature(uint32_t(params.thresholds_per_feature + 1));
  job->set_build_id(build_id);
  job_announcement = job_env;
  POSEFOREST_RETURN_IF_ERROR(Send(Topic::kJob, job_env));
  Log("announced " + job_id + " as " + self_id + " on domain " + std::to_string(opt.domain) + " (build \"" +
      build_id + "\"): " + engine::DescribeParams(params));
  PublishStatus(v1::STATUS_KIND_JOB_STARTED, engine::DescribeParams(params));
  return Status::Ok();
}

}  // namespace poseforest::coordinator
