#include "worker/intake.h"

#include <algorithm>

namespace poseforest::worker {

using proto::dds::Topic;

void Intake::Loop() {
  CpuTimer timer(&cpu_);
  while (!ctx_.stop && !ctx_.node_restart) {
    {
      std::unique_lock<std::mutex> lock(mu_);
      if (bytes_ > kMaxBytes) {
        cv_.wait_for(lock, std::chrono::milliseconds(20));
        continue;
      }
    }
    std::optional<proto::dds::ReceivedSample> s = ctx_.node->Receive(std::chrono::milliseconds(50));
    if (!s) continue;
    s->received_s = proto::dds::NowSeconds();
    ++ctx_.live.received[size_t(s->topic)];
    std::lock_guard<std::mutex> lock(mu_);
    bytes_ += s->bytes.size();
    ctx_.live.inbox_bytes = bytes_;
    queue_.push_back(std::move(*s));
    cv_.notify_all();
  }
}

std::optional<proto::dds::ReceivedSample> Intake::Take(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!cv_.wait_for(lock, timeout, [&] { return !queue_.empty() || ctx_.stop; }) || queue_.empty())
    return std::nullopt;
  proto::dds::ReceivedSample s = std::move(queue_.front());
  queue_.pop_front();
  bytes_ -= s.bytes.size();
  ctx_.live.inbox_bytes = bytes_;
  cv_.notify_all();
  return s;
}

uint64_t Intake::NewerQueuedShard(const std::string& control_writer, uint64_t epoch) {
  if (control_writer.empty()) return 0;
  uint64_t newest = 0;
  std::lock_guard<std::mutex> lock(mu_);
  for (const proto::dds::ReceivedSample& q : queue_) {
    // Assignments are small (a few ranges); big samples are replies, tasks or decisions.
    if (q.topic != Topic::kControl || q.writer_guid != control_writer || q.bytes.size() > (64u << 10)) continue;
    v1::Envelope peek;
    if (!peek.ParseFromArray(q.bytes.data(), int(q.bytes.size())) || !peek.has_shard()) continue;
    if (peek.recipient_id() == ctx_.opt.worker_id && peek.job_id() == ctx_.job_id && peek.shard().epoch() > epoch)
      newest = std::max<uint64_t>(newest, peek.shard().epoch());
  }
  return newest;
}

}  // namespace poseforest::worker
