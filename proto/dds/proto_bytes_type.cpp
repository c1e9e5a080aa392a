#include "proto/dds/proto_bytes_type.h"

#include "proto/dds/cdr_bytes.h"
#include "proto/dds/topics.h"

namespace poseforest::proto::dds {

ProtoBytesType::ProtoBytesType() {
  setName(kEnvelopeTypeName);
  // Initial payload size of preallocated pools; larger samples grow them (the endpoints use
  // PREALLOCATED_WITH_REALLOC memory). Small, so keep-all histories do not reserve much.
  m_typeSize = 4096 + kCdrHeaderBytes;
  m_isGetKeyDefined = false;
  auto_fill_type_object(false);
  auto_fill_type_information(false);
}

bool ProtoBytesType::serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) {
  const auto& bytes = static_cast<ProtoBytesSample*>(data)->bytes;
  if (bytes.size() > kMaxBytes) return false;
  const uint32_t total = kCdrHeaderBytes + static_cast<uint32_t>(bytes.size());
  if (payload->max_size < total) payload->reserve(total);
  if (payload->max_size < total) return false;
  EncodeCdrBytes(bytes, payload->data);
  payload->encapsulation = CDR_LE;
  payload->length = total;
  return true;
}

bool ProtoBytesType::deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) {
  auto& bytes = static_cast<ProtoBytesSample*>(data)->bytes;
  bytes.clear();
  if (payload->data == nullptr || payload->length == 0) return true;  // empty: the gate drops it
  // Malformed payloads are delivered raw (see DecodeCdrBytes): dropped and blamed by the gate.
  (void)DecodeCdrBytes({payload->data, payload->length}, &bytes);
  return true;
}

std::function<uint32_t()> ProtoBytesType::getSerializedSizeProvider(void* data) {
  return [data]() -> uint32_t {
    return kCdrHeaderBytes + static_cast<uint32_t>(static_cast<ProtoBytesSample*>(data)->bytes.size());
  };
}

void* ProtoBytesType::createData() { return new ProtoBytesSample(); }

void ProtoBytesType::deleteData(void* data) { delete static_cast<ProtoBytesSample*>(data); }

bool ProtoBytesType::getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) { return false; }

}  // namespace poseforest::proto::dds
