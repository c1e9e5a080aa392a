#pragma once
// ProtoBytesType: a hand-written Fast DDS TopicDataType whose samples are opaque byte strings
// (serialized protobuf messages). No IDL and no fastddsgen: the bytes are copied into the RTPS
// payload as a CDR `sequence<octet>` (proto/dds/cdr_bytes.h), which is what the IDL
// `struct Envelope { sequence<octet> bytes; };` would produce, so generic DDS tools can still
// display the samples.
//
// This header includes Fast DDS and may only be included from proto/dds/*.cpp.

#include <cstdint>
#include <vector>

#include <fastdds/dds/topic/TopicDataType.hpp>

#include "proto/dds/cdr_bytes.h"

namespace poseforest::proto::dds {

/// The sample type handed to DataWriter::write / DataReader::take.
struct ProtoBytesSample {
  std::vector<uint8_t> bytes;
};

class ProtoBytesType : public eprosima::fastdds::dds::TopicDataType {
 public:
  /// Largest sample, bytes (Publish refuses larger ones; larger incoming payloads are cut).
  static constexpr uint32_t kMaxBytes = kMaxSampleBytes;

  ProtoBytesType();

  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override;
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override;
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override;
  void* createData() override;
  void deleteData(void* data) override;
  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool force_md5 = false) override;
  bool is_bounded() const override { return false; }
  bool is_plain() const override { return false; }
};

}  // namespace poseforest::proto::dds
