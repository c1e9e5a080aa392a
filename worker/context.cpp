#include "worker/context.h"

#include <chrono>
#include <optional>

namespace poseforest::worker {

using core::Status;
using proto::dds::Topic;

Status Context::Publish(Topic topic, v1::Envelope& env, bool timed) {
  std::optional<CpuTimer> timer;
  if (timed) timer.emplace(&cpu.publish);
  {
    std::lock_guard<std::mutex> lock(send_mu);
    stamper.Stamp(topic, env);
  }
  // Serialized outside the lock: a reply of tens of MiB took the heartbeat thread's lock long
  // enough, on a loaded machine, for the coordinator to take the worker for lost.
  const std::string bytes = env.SerializeAsString();
  Status st = node->Publish(topic, bytes);
  if (st.ok()) {
    ++live.sent[size_t(topic)];
    live.sent_bytes[size_t(topic)] += bytes.size();
  }
  return st;
}

Status Context::Reply(v1::Envelope& env) {
  (void)node->WaitForMatch(Topic::kReplies, 1, std::chrono::milliseconds(5000));
  return Publish(Topic::kReplies, env);
}

}  // namespace poseforest::worker
