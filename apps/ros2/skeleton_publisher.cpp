#include "apps/ros2/skeleton_publisher.h"

#include <chrono>
#include <condition_variable>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <mutex>
#include <thread>

namespace poseforest::apps::ros2 {
namespace fdds = eprosima::fastdds::dds;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {

// A sample already serialized by us (ros2_messages.h), encapsulation header included: copied
// into the payload as it is, and copied out as it came. The type name is the ROS 2 one, so
// rmw_fastrtps matches it.
struct RawSample {
  std::vector<uint8_t> bytes;
};

class RawCdrType : public fdds::TopicDataType {
 public:
  explicit RawCdrType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 64 * 1024;
    m_isGetKeyDefined = false;
    auto_fill_type_object(false);
    auto_fill_type_information(false);
  }
  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    const auto& b = static_cast<RawSample*>(data)->bytes;
    if (b.size() < 4) return false;
    if (payload->max_size < b.size()) payload->reserve(uint32_t(b.size()));
    if (payload->max_size < b.size()) return false;
    std::memcpy(payload->data, b.data(), b.size());
    payload->length = uint32_t(b.size());
    payload->encapsulation = b[1] == 1 ? CDR_LE : CDR_BE;
    return true;
  }
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    auto& b = static_cast<RawSample*>(data)->bytes;
    b.assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return uint32_t(static_cast<RawSample*>(data)->bytes.size()); };
  }
  void* createData() override { return new RawSample(); }
  void deleteData(void* data) override { delete static_cast<RawSample*>(data); }
  bool getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) override { return false; }
  bool is_bounded() const override { return false; }
  bool is_plain() const override { return false; }
};

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

struct SkeletonPublisher::Impl {
  DdsOptions options;
  fdds::DomainParticipant* participant = nullptr;
  fdds::Publisher* publisher = nullptr;
  fdds::DataWriter* skeletons = nullptr;
  fdds::DataWriter* markers = nullptr;
  ~Impl() {
    if (!participant) return;
    participant->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  }
};

SkeletonPublisher::SkeletonPublisher(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SkeletonPublisher::~SkeletonPublisher() = default;

core::Result<std::unique_ptr<SkeletonPublisher>> SkeletonPublisher::Create(const DdsOptions& options) {
  if (options.domain < 0 || options.domain > 232)
    return core::Status(core::ErrorCode::kInvalidArgument,
                        "--dds-domain must be in 0..232 (got " + std::to_string(options.domain) + ")");
  if (options.topic_prefix.empty() || options.topic_prefix.find_first_of(" \t\"'") != std::string::npos)
    return core::Status(core::ErrorCode::kInvalidArgument,
                        "--dds-topic '" + options.topic_prefix + "' is not a topic name");
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  fdds::DomainParticipantQos pqos;
  pqos.name("poseforest_live");
  impl->participant =
      fdds::DomainParticipantFactory::get_instance()->create_participant(options.domain, pqos);
  if (!impl->participant)
    return core::Status(core::ErrorCode::kInternal,
                        "DDS: cannot create a participant on domain " + std::to_string(options.domain));
  impl->publisher = impl->participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::DataWriterQos wq = fdds::DATAWRITER_QOS_DEFAULT;
  wq.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  wq.durability().kind = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
  wq.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  wq.history().depth = 100;
  wq.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  const std::string prefix = "rt/" + options.topic_prefix + "/";
  for (const auto& [suffix, type_name, out] : {std::tuple{"skeletons", kSkeletonsTypeName, &impl->skeletons},
                                               std::tuple{"markers", kMarkerArrayTypeName, &impl->markers}}) {
    fdds::TypeSupport type(new RawCdrType(type_name));
    if (type.register_type(impl->participant) != ReturnCode_t::RETCODE_OK)
      return core::Status(core::ErrorCode::kInternal, std::string("DDS: cannot register ") + type_name);
    auto* topic = impl->participant->create_topic(prefix + suffix, type_name, fdds::TOPIC_QOS_DEFAULT);
    if (!topic)
      return core::Status(core::ErrorCode::kInternal, "DDS: cannot create topic " + prefix + suffix);
    *out = impl->publisher->create_datawriter(topic, wq);
    if (!*out)
      return core::Status(core::ErrorCode::kInternal, "DDS: cannot create a writer on " + prefix + suffix);
  }
  return std::unique_ptr<SkeletonPublisher>(new SkeletonPublisher(std::move(impl)));
}

bool SkeletonPublisher::Publish(int64_t index, double time_s, const std::string& source,
                                const std::vector<runtime::Skeleton>& skeletons) {
  const FrameStamp stamp{index, time_s, source, impl_->options.frame_id};
  RawSample s{EncodeSkeletons(stamp, skeletons)};
  RawSample m{EncodeMarkerArray(stamp, skeletons)};
  const bool a = impl_->skeletons->write(&s);
  const bool b = impl_->markers->write(&m);
  return a && b;
}

bool SkeletonPublisher::WaitForSubscribers(int count, double seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  while (true) {
    fdds::PublicationMatchedStatus a, b;
    impl_->skeletons->get_publication_matched_status(a);
    impl_->markers->get_publication_matched_status(b);
    if (a.current_count >= count && b.current_count >= count) return true;
    if (Since(t0) >= seconds) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

bool SkeletonPublisher::Flush(double seconds) {
  const eprosima::fastrtps::Duration_t d(int32_t(seconds), uint32_t((seconds - int32_t(seconds)) * 1e9));
  const bool a = impl_->skeletons->wait_for_acknowledgments(d) == ReturnCode_t::RETCODE_OK;
  const bool b = impl_->markers->wait_for_acknowledgments(d) == ReturnCode_t::RETCODE_OK;
  return a && b;
}

std::string SkeletonPublisher::Describe() const {
  const std::string p = "rt/" + impl_->options.topic_prefix + "/";
  return "DDS domain " + std::to_string(impl_->options.domain) + ": " + p + "skeletons (" +
         kSkeletonsTypeName + "), " + p + "markers (" + kMarkerArrayTypeName + "), frame_id " +
         impl_->options.frame_id;
}

struct RawSampleCapture::Impl : public fdds::DataReaderListener {
  fdds::DomainParticipant* participant = nullptr;
  fdds::DataReader* reader = nullptr;
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::vector<uint8_t>> samples;
  // Listener callbacks only take the samples into our queue (STYLE: callbacks enqueue).
  void on_data_available(fdds::DataReader* r) override {
    RawSample s;
    fdds::SampleInfo info;
    while (r->take_next_sample(&s, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard lock(mu);
      samples.push_back(s.bytes);
      cv.notify_all();
    }
  }
  ~Impl() override {
    if (!participant) return;
    if (reader) reader->set_listener(nullptr);
    participant->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  }
};

RawSampleCapture::RawSampleCapture(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
RawSampleCapture::~RawSampleCapture() = default;

core::Result<std::unique_ptr<RawSampleCapture>> RawSampleCapture::Create(int domain,
                                                                         const std::string& topic_name,
                                                                         const std::string& type_name) {
  auto impl = std::make_unique<Impl>();
  impl->participant = fdds::DomainParticipantFactory::get_instance()->create_participant(
      domain, fdds::PARTICIPANT_QOS_DEFAULT);
  if (!impl->participant) return core::Status(core::ErrorCode::kInternal, "DDS: cannot create a participant");
  fdds::TypeSupport type(new RawCdrType(type_name));
  if (type.register_type(impl->participant) != ReturnCode_t::RETCODE_OK)
    return core::Status(core::ErrorCode::kInternal, "DDS: cannot register " + type_name);
  auto* topic = impl->participant->create_topic(topic_name, type_name, fdds::TOPIC_QOS_DEFAULT);
  auto* sub = impl->participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  fdds::DataReaderQos rq = fdds::DATAREADER_QOS_DEFAULT;
  rq.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  rq.durability().kind = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
  rq.history().kind = fdds::KEEP_ALL_HISTORY_QOS;
  rq.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  if (!topic || !sub)
    return core::Status(core::ErrorCode::kInternal, "DDS: cannot subscribe to " + topic_name);
  impl->reader = sub->create_datareader(topic, rq, impl.get());
  if (!impl->reader)
    return core::Status(core::ErrorCode::kInternal, "DDS: cannot create a reader on " + topic_name);
  return std::unique_ptr<RawSampleCapture>(new RawSampleCapture(std::move(impl)));
}

std::vector<std::vector<uint8_t>> RawSampleCapture::Wait(size_t count, double seconds) {
  std::unique_lock lock(impl_->mu);
  impl_->cv.wait_for(lock, std::chrono::duration<double>(seconds),
                     [&] { return impl_->samples.size() >= count; });
  return impl_->samples;
}

}  // namespace poseforest::apps::ros2
