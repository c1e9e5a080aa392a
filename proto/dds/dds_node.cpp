#include "proto/dds/dds_node.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <mutex>
#include <optional>
#include <sstream>

#include "proto/dds/dds_node_qos.h"
#include "proto/dds/proto_bytes_type.h"

namespace poseforest::proto::dds {

namespace fdds = eprosima::fastdds::dds;
namespace frtps = eprosima::fastrtps::rtps;
using core::ErrorCode;
using core::Status;

const char* EventKindName(DdsEvent::Kind kind) {
  switch (kind) {
    case DdsEvent::Kind::kWriterMatched: return "WriterMatched";
    case DdsEvent::Kind::kWriterUnmatched: return "WriterUnmatched";
    case DdsEvent::Kind::kReaderMatched: return "ReaderMatched";
    case DdsEvent::Kind::kReaderUnmatched: return "ReaderUnmatched";
    case DdsEvent::Kind::kLivelinessLost: return "LivelinessLost";
    case DdsEvent::Kind::kLivelinessRecovered: return "LivelinessRecovered";
    case DdsEvent::Kind::kParticipantDiscovered: return "ParticipantDiscovered";
    case DdsEvent::Kind::kParticipantLost: return "ParticipantLost";
  }
  return "?";
}

namespace {
/// Fast DDS's log entries on stderr, one line each, prefixed "Fast DDS: ". Its own consumers
/// colour every line with terminal escapes even into a file or pipe; these colour only a terminal.
class StderrLogConsumer final : public fdds::LogConsumer {
 public:
  void Consume(const fdds::Log::Entry& entry) override {
    const bool color = ::isatty(STDERR_FILENO) != 0;
    std::ostringstream line;
    line << "Fast DDS: ";
    print_header(line, entry, color);
    print_message(line, entry, color);
    print_context(line, entry, color);
    print_new_line(line, color);
    const std::string text = line.str();
    std::fwrite(text.data(), 1, text.size(), stderr);
  }
};
}  // namespace

void ConfigureDdsLogging() {
  static std::once_flag once;
  std::call_once(once, [] {
    fdds::Log::ClearConsumers();
    fdds::Log::RegisterConsumer(std::make_unique<StderrLogConsumer>());
    const char* env = std::getenv("POSEFOREST_DDS_LOG");
    std::string level = env ? env : "error";
    if (level == "warning")
      fdds::Log::SetVerbosity(fdds::Log::Kind::Warning);
    else if (level == "info")
      fdds::Log::SetVerbosity(fdds::Log::Kind::Info);
    else
      fdds::Log::SetVerbosity(fdds::Log::Kind::Error);
  });
}

namespace {

std::string ToString(const frtps::GUID_t& guid) {
  std::ostringstream os;
  os << guid;
  return os.str();
}
std::string ToString(const frtps::GuidPrefix_t& prefix) {
  std::ostringstream os;
  os << prefix;
  return os.str();
}

constexpr size_t kMaxQueuedEvents = 4096;

bool IsKeepAll(Topic t) { return t == Topic::kControl || t == Topic::kReplies; }
bool HasLease(Topic t) { return t == Topic::kJob || t == Topic::kPresence; }
bool IsTransientLocal(Topic t) { return t == Topic::kJob || t == Topic::kStatus; }
int KeepLastDepth(Topic t) {
  switch (t) {
    case Topic::kJob: return 1;
    case Topic::kPresence: return 8;
    case Topic::kStatus: return 64;
    default: return 1;
  }
}

}  // namespace

struct DdsNode::Impl : public fdds::DomainParticipantListener {
  NodeConfig config;
  fdds::DomainParticipant* participant = nullptr;
  fdds::Publisher* publisher = nullptr;
  fdds::Subscriber* subscriber = nullptr;
  fdds::TypeSupport type{new ProtoBytesType()};
  std::array<fdds::Topic*, kNumTopics> topics{};
  std::array<fdds::DataWriter*, kNumTopics> writers{};
  std::array<fdds::DataReader*, kNumTopics> readers{};
  std::array<std::atomic<int>, kNumTopics> matched_readers{};  // per our writer
  std::array<std::atomic<int>, kNumTopics> matched_writers{};  // per our reader

  std::mutex mu;
  std::condition_variable data_cv;   // data available or match count changed
  uint64_t data_generation = 0;
  std::deque<DdsEvent> events;
  std::condition_variable event_cv;
  size_t next_topic = 0;  // round robin in Receive
  // One lock and sample per topic: DataWriter::write is thread-safe, the sample isn't; a write
  // waiting on a full control or replies history must not hold up the presence heartbeats.
  std::array<std::mutex, kNumTopics> write_mu;
  std::array<ProtoBytesSample, kNumTopics> write_sample;
  std::atomic<uint64_t> slow_writes{0};
  int KeepAllMax() const {
    return config.keep_all_max_samples > 0 ? config.keep_all_max_samples : kKeepAllMaxSamples;
  }

  /// A writer or reader (un)matched on `topic` with the remote endpoint `peer`.
  void PushMatchEvent(DdsEvent::Kind kind, Topic topic, const frtps::InstanceHandle_t& peer, int32_t count) {
    DdsEvent e{kind};
    e.topic = topic;
    const frtps::GUID_t guid = frtps::iHandle2GUID(peer);
    e.peer_guid = ToString(guid);
    e.peer_participant = ToString(guid.guidPrefix);
    e.current_count = count;
    PushEvent(std::move(e));
  }

  // Per-endpoint listeners know their topic.
  struct WriterListener : public fdds::DataWriterListener {
    Impl* impl = nullptr;
    Topic topic = Topic::kJob;
    void on_publication_matched(fdds::DataWriter*, const fdds::PublicationMatchedStatus& info) override {
      impl->matched_readers[static_cast<int>(topic)] = info.current_count;
      impl->PushMatchEvent(info.current_count_change > 0 ? DdsEvent::Kind::kWriterMatched : DdsEvent::Kind::kWriterUnmatched,
                           topic, info.last_subscription_handle, info.current_count);
    }
  };
  struct ReaderListener : public fdds::DataReaderListener {
    Impl* impl = nullptr;
    Topic topic = Topic::kJob;
    void on_data_available(fdds::DataReader*) override {
      {
        std::lock_guard<std::mutex> lock(impl->mu);
        ++impl->data_generation;
      }
      impl->data_cv.notify_all();
    }
    void on_subscription_matched(fdds::DataReader*, const fdds::SubscriptionMatchedStatus& info) override {
      impl->matched_writers[static_cast<int>(topic)] = info.current_count;
      impl->PushMatchEvent(info.current_count_change > 0 ? DdsEvent::Kind::kReaderMatched : DdsEvent::Kind::kReaderUnmatched,
                           topic, info.last_publication_handle, info.current_count);
    }
    void on_liveliness_changed(fdds::DataReader*, const fdds::LivelinessChangedStatus& status) override {
      const frtps::GUID_t guid = frtps::iHandle2GUID(status.last_publication_handle);
      if (status.not_alive_count_change > 0 || status.alive_count_change < 0) {
        DdsEvent e{DdsEvent::Kind::kLivelinessLost};
        e.topic = topic;
        e.peer_guid = ToString(guid);
        e.peer_participant = ToString(guid.guidPrefix);
        e.current_count = status.alive_count;
        impl->PushEvent(std::move(e));
      }
      if (status.alive_count_change > 0) {
        DdsEvent e{DdsEvent::Kind::kLivelinessRecovered};
        e.topic = topic;
        e.peer_guid = ToString(guid);
        e.peer_participant = ToString(guid.guidPrefix);
        e.current_count = status.alive_count;
        impl->PushEvent(std::move(e));
      }
    }
  };
  std::array<WriterListener, kNumTopics> writer_listeners;
  std::array<ReaderListener, kNumTopics> reader_listeners;

  void PushEvent(DdsEvent e) {
    {
      std::lock_guard<std::mutex> lock(mu);
      events.push_back(std::move(e));
      if (events.size() > kMaxQueuedEvents) events.pop_front();  // nobody is reading them
      ++data_generation;  // wakes WaitForMatch too
    }
    event_cv.notify_all();
    data_cv.notify_all();
  }

  void on_participant_discovery(fdds::DomainParticipant*, frtps::ParticipantDiscoveryInfo&& info) override {
    DdsEvent e{DdsEvent::Kind::kParticipantDiscovered};
    switch (info.status) {
      case frtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT: e.kind = DdsEvent::Kind::kParticipantDiscovered; break;
      case frtps::ParticipantDiscoveryInfo::REMOVED_PARTICIPANT:
      case frtps::ParticipantDiscoveryInfo::DROPPED_PARTICIPANT: e.kind = DdsEvent::Kind::kParticipantLost; break;
      default: return;
    }
    e.peer_guid = ToString(info.info.m_guid);
    e.peer_participant = ToString(info.info.m_guid.guidPrefix);
    e.peer_name = info.info.m_participantName.to_string();
    PushEvent(std::move(e));
  }

  Status CreateEndpoints();
  void Destroy();
};

Status DdsNode::Impl::CreateEndpoints() {
  if (type.register_type(participant) != ReturnCode_t::RETCODE_OK)
    return Status(ErrorCode::kInternal, "register_type failed");
  publisher = participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  subscriber = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (!publisher || !subscriber) return Status(ErrorCode::kInternal, "cannot create publisher/subscriber");

  auto want = [](const std::vector<Topic>& list, Topic t) {
    for (Topic x : list)
      if (x == t) return true;
    return false;
  };
  for (Topic t : kAllTopics) {
    const bool w = want(config.write_topics, t), r = want(config.read_topics, t);
    if (!w && !r) continue;
    const int i = static_cast<int>(t);
    topics[i] = participant->create_topic(TopicName(t), type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    if (!topics[i]) return Status(ErrorCode::kInternal, std::string("cannot create topic ") + TopicName(t));

    const auto lease = HasLease(t) ? ToDuration(config.liveliness_lease) : eprosima::fastrtps::c_TimeInfinite;
    const auto liveliness_kind = (t == Topic::kPresence && config.presence_manual_liveliness)
                                     ? fdds::MANUAL_BY_TOPIC_LIVELINESS_QOS
                                     : fdds::AUTOMATIC_LIVELINESS_QOS;
    const auto announce = HasLease(t) ? ToDuration(config.liveliness_lease / 4) : eprosima::fastrtps::c_TimeInfinite;
    // QoS that writer and reader of a topic must agree on (reliability, durability, history,
    // liveliness), set once for both.
    auto apply_common = [&](auto& q) {
      q.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
      q.durability().kind = IsTransientLocal(t) ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS : fdds::VOLATILE_DURABILITY_QOS;
      if (IsKeepAll(t)) {
        q.history().kind = fdds::KEEP_ALL_HISTORY_QOS;
        q.resource_limits().max_samples = KeepAllMax();
        q.resource_limits().max_instances = 1;
        q.resource_limits().max_samples_per_instance = KeepAllMax();
        q.resource_limits().allocated_samples = std::min(16, KeepAllMax());
      } else {
        q.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
        q.history().depth = KeepLastDepth(t);
        q.resource_limits().allocated_samples = KeepLastDepth(t);
      }
      q.liveliness().kind = liveliness_kind;
      q.liveliness().lease_duration = lease;
      q.endpoint().history_memory_policy = frtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    };
    if (w) {
      fdds::DataWriterQos q = fdds::DATAWRITER_QOS_DEFAULT;
      apply_common(q);
      q.reliability().max_blocking_time = ToDuration(std::max(config.write_block_slice, std::chrono::milliseconds(1)));
      q.liveliness().announcement_period = announce;
      // Recover lost fragments of large samples quickly (default heartbeat period is 3 s).
      q.reliable_writer_qos().times.heartbeatPeriod = eprosima::fastrtps::Duration_t(0, 100000000);
      writer_listeners[i].impl = this;
      writer_listeners[i].topic = t;
      writers[i] = publisher->create_datawriter(topics[i], q, &writer_listeners[i], fdds::StatusMask::all());
      if (!writers[i]) return Status(ErrorCode::kInternal, std::string("cannot create writer on ") + TopicName(t));
    }
    if (r) {
      fdds::DataReaderQos q = fdds::DATAREADER_QOS_DEFAULT;
      apply_common(q);
      if (IsKeepAll(t)) {
        // A reader history far larger than any writer's: it stores (and acknowledges) what
        // arrives however long the application takes to read it. Fast DDS 2.9 never asks again
        // for a sample its full keep-all reader history rejected, so a full reader history
        // stalled the writer for good (seen here with histories of 2: the reader emptied its
        // history and the writer stayed blocked); the writer's own history (KeepAllMax) is the
        // flow control on the wire. Memory grows only with what is actually queued
        // (PREALLOCATED_WITH_REALLOC).
        q.resource_limits().max_samples = kKeepAllReaderMaxSamples;
        q.resource_limits().max_samples_per_instance = kKeepAllReaderMaxSamples;
      }
      reader_listeners[i].impl = this;
      reader_listeners[i].topic = t;
      readers[i] = subscriber->create_datareader(topics[i], q, &reader_listeners[i], fdds::StatusMask::all());
      if (!readers[i]) return Status(ErrorCode::kInternal, std::string("cannot create reader on ") + TopicName(t));
    }
  }
  return Status::Ok();
}

void DdsNode::Impl::Destroy() {
  if (!participant) return;
  // Listeners first, so no callback runs into a half-destroyed node.
  for (auto* w : writers)
    if (w) w->set_listener(nullptr);
  for (auto* r : readers)
    if (r) r->set_listener(nullptr);
  participant->set_listener(nullptr);
  participant->delete_contained_entities();
  fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  participant = nullptr;
}

DdsNode::DdsNode(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

DdsNode::~DdsNode() {
  if (impl_) impl_->Destroy();
}

core::Result<std::unique_ptr<DdsNode>> DdsNode::Create(const NodeConfig& config) {
  ConfigureDdsLogging();
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  // From the id's choice until the participant's ports exist, no other process of this host
  // chooses (HostLock): they would see the same free ports and take the same id. 10 s at most:
  // a process stuck while holding it delays the others, it does not stop them.
  std::optional<HostLock> id_lock;
  if (MayTakeFreshParticipantId(config)) id_lock.emplace(kParticipantIdLockPath, std::chrono::seconds(10));
  fdds::DomainParticipantQos qos;
  POSEFOREST_RETURN_IF_ERROR(BuildParticipantQos(impl->config, qos));
  // Participant discovery events only; data and match callbacks go to the endpoint listeners.
  fdds::StatusMask mask = fdds::StatusMask::none();
  impl->participant =
      fdds::DomainParticipantFactory::get_instance()->create_participant(config.domain_id, qos, impl.get(), mask);
  if (!impl->participant && config.participant_id < 0 && qos.wire_protocol().participant_id >= 0) {
    // The id BuildParticipantQos chose is one an automatic participant of this process holds
    // (one made from an XML profile, say): Fast DDS's own choice then.
    qos.wire_protocol().participant_id = -1;
    impl->participant =
        fdds::DomainParticipantFactory::get_instance()->create_participant(config.domain_id, qos, impl.get(), mask);
  }
  if (!impl->participant) {
    return Status(ErrorCode::kInvalidArgument,
                  "cannot create DDS participant '" + config.participant_name + "' on domain " +
                      std::to_string(config.domain_id) +
                      (config.security.enabled()
                           ? " (security enabled: check the certificates, key, signed governance/permissions; "
                             "POSEFOREST_DDS_LOG=warning shows why)"
                           : " (POSEFOREST_DDS_LOG=warning shows why)"));
  }
  id_lock.reset();
  if (const char* env = std::getenv("POSEFOREST_DDS_LOG");
      env && (std::string(env) == "warning" || std::string(env) == "info"))
    // Which participant id a process took (FreshSharedMemoryParticipantId): with Fast DDS's own
    // warnings, what tells one shared-memory participant from another in a failing test's output.
    std::fprintf(stderr, "[dds] participant '%s' on domain %u: id %d asked, guid %s\n",
                 config.participant_name.c_str(), unsigned(config.domain_id),
                 int(qos.wire_protocol().participant_id),
                 ToString(impl->participant->guid().guidPrefix).c_str());
  std::unique_ptr<DdsNode> node(new DdsNode(std::move(impl)));
  Status st = node->impl_->CreateEndpoints();
  if (!st.ok()) return st;  // ~DdsNode cleans up
  return node;
}

Status DdsNode::Publish(Topic topic, const void* data, size_t size) {
  const int i = static_cast<int>(topic);
  auto* w = impl_->writers[i];
  if (!w) return Status(ErrorCode::kInvalidArgument, std::string("this node does not write ") + TopicName(topic));
  if (size > ProtoBytesType::kMaxBytes)
    return Status(ErrorCode::kInvalidArgument, "sample of " + std::to_string(size) + " bytes exceeds the maximum");
  std::lock_guard<std::mutex> lock(impl_->write_mu[i]);
  auto& bytes = impl_->write_sample[i].bytes;
  bytes.assign(static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
  // A full keep-all history makes write() wait up to one slice for the slowest matched reader to
  // acknowledge. A reader that is still matched is alive as far as DDS knows (a dead peer is
  // unmatched when its participant lease runs out, and its unacknowledged samples no longer hold
  // the history), so it is waited for: a busy peer never fails the job (a worker in a
  // long subtree batch made the coordinator's write fail after 10 s).
  const auto start = std::chrono::steady_clock::now();
  bool waited = false;
  int no_reader_tries = 0;
  std::chrono::steady_clock::duration next_log{};
  for (;;) {
    if (w->write(&impl_->write_sample[i])) {
      if (waited && impl_->config.log)
        impl_->config.log(std::string("DDS write on ") + TopicName(topic) + " went through after " +
                          std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(
                                             std::chrono::steady_clock::now() - start)
                                             .count()) +
                          " ms");
      return Status::Ok();
    }
    const auto waited_for = std::chrono::steady_clock::now() - start;
    if (!IsKeepAll(topic))
      return Status(ErrorCode::kIo, std::string("DataWriter::write failed on ") + TopicName(topic) +
                                        " (the sample was refused)");
    if (impl_->matched_readers[i] <= 0) {
      // The reader it waited for has gone (unmatched while write() waited): nobody is left to
      // acknowledge, so the next write goes through.
      if (no_reader_tries++ > 0)
        return Status(ErrorCode::kIo, std::string("DataWriter::write failed on ") + TopicName(topic) +
                                          " with no reader matched");
      continue;
    }
    if (impl_->config.write_give_up.count() > 0 && waited_for >= impl_->config.write_give_up)
      return Status(ErrorCode::kIo,
                    std::string("DataWriter::write failed on ") + TopicName(topic) + ": history full for " +
                        std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(waited_for).count()) +
                        " ms with " + std::to_string(impl_->matched_readers[i].load()) + " reader(s) matched");
    if (!waited || waited_for >= next_log) {
      if (!waited) ++impl_->slow_writes;
      waited = true;
      next_log = waited_for + std::chrono::seconds(30);  // then every 30 s while it waits
      if (impl_->config.log)
        impl_->config.log(std::string("DDS write on ") + TopicName(topic) + ": history full (" +
                          std::to_string(impl_->KeepAllMax()) + " samples) for " +
                          std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(waited_for).count()) +
                          " ms; waiting for the slowest of " + std::to_string(impl_->matched_readers[i].load()) +
                          " matched reader(s)");
    }
  }
}

uint64_t DdsNode::slow_writes() const { return impl_->slow_writes.load(); }

std::optional<ReceivedSample> DdsNode::Receive(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  ProtoBytesSample sample;
  fdds::SampleInfo info;
  for (;;) {
    uint64_t generation;
    {
      std::lock_guard<std::mutex> lock(impl_->mu);
      generation = impl_->data_generation;
    }
    for (int k = 0; k < kNumTopics; ++k) {
      const int i = static_cast<int>((impl_->next_topic + k) % kNumTopics);
      auto* r = impl_->readers[i];
      if (!r) continue;
      while (r->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;  // instance state change (writer gone), not data
        impl_->next_topic = (i + 1) % kNumTopics;
        ReceivedSample out;
        out.topic = static_cast<Topic>(i);
        out.bytes = std::move(sample.bytes);
        const frtps::GUID_t guid = frtps::iHandle2GUID(info.publication_handle);
        out.writer_guid = ToString(guid);
        out.writer_participant = ToString(guid.guidPrefix);
        out.source_timestamp_ns = info.source_timestamp.to_ns();
        return out;
      }
    }
    std::unique_lock<std::mutex> lock(impl_->mu);
    if (impl_->data_generation != generation) continue;
    if (impl_->data_cv.wait_until(lock, deadline) == std::cv_status::timeout &&
        impl_->data_generation == generation)
      return std::nullopt;
  }
}

std::optional<DdsEvent> DdsNode::NextEvent(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(impl_->mu);
  if (!impl_->event_cv.wait_for(lock, timeout, [&] { return !impl_->events.empty(); })) return std::nullopt;
  DdsEvent e = std::move(impl_->events.front());
  impl_->events.pop_front();
  return e;
}

int DdsNode::MatchedReaders(Topic topic) const { return impl_->matched_readers[static_cast<int>(topic)]; }
int DdsNode::MatchedWriters(Topic topic) const { return impl_->matched_writers[static_cast<int>(topic)]; }

bool DdsNode::WaitForMatch(Topic topic, int n, std::chrono::milliseconds timeout) {
  const int i = static_cast<int>(topic);
  auto done = [&] {
    return (!impl_->writers[i] || impl_->matched_readers[i] >= n) &&
           (!impl_->readers[i] || impl_->matched_writers[i] >= n);
  };
  std::unique_lock<std::mutex> lock(impl_->mu);
  return impl_->data_cv.wait_for(lock, timeout, done);
}

bool DdsNode::WaitForAcknowledgments(Topic topic, std::chrono::milliseconds timeout) {
  auto* w = impl_->writers[static_cast<int>(topic)];
  if (!w) return false;
  return w->wait_for_acknowledgments(ToDuration(timeout)) == ReturnCode_t::RETCODE_OK;
}

Status DdsNode::AssertLiveliness(Topic topic) {
  auto* w = impl_->writers[static_cast<int>(topic)];
  if (!w) return Status(ErrorCode::kInvalidArgument, std::string("this node does not write ") + TopicName(topic));
  if (w->assert_liveliness() != ReturnCode_t::RETCODE_OK)
    return Status(ErrorCode::kInternal, std::string("assert_liveliness failed on ") + TopicName(topic));
  return Status::Ok();
}

std::string DdsNode::participant_guid() const { return ToString(impl_->participant->guid().guidPrefix); }

const NodeConfig& DdsNode::config() const { return impl_->config; }

}  // namespace poseforest::proto::dds
