#pragma once
// The RTPS payload layout of one poseforest sample, separate from Fast DDS so it can be tested:
// CDR encapsulation header {0x00, 0x01 (little endian), 0x00, 0x00}, uint32 length, the bytes —
// the same layout as the IDL `struct Envelope { sequence<octet> bytes; };`.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace poseforest::proto::dds {

inline constexpr uint32_t kCdrHeaderBytes = 8;  ///< encapsulation (4) + sequence length (4)
inline constexpr uint32_t kMaxSampleBytes = 256u << 20;

/// Writes the payload of `bytes` into `out` (which must hold kCdrHeaderBytes + bytes.size()).
void EncodeCdrBytes(std::span<const uint8_t> bytes, uint8_t* out);

/// Reads a payload. A well-formed one (either endianness) yields its bytes and true; anything
/// else yields the raw payload (cut at kMaxSampleBytes) and false, so that the MessageGate can
/// drop it and blame its writer instead of Fast DDS discarding it silently.
bool DecodeCdrBytes(std::span<const uint8_t> payload, std::vector<uint8_t>* bytes);

}  // namespace poseforest::proto::dds
