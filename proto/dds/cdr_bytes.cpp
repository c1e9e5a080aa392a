#include "proto/dds/cdr_bytes.h"

#include <algorithm>
#include <cstring>

namespace poseforest::proto::dds {

void EncodeCdrBytes(std::span<const uint8_t> bytes, uint8_t* out) {
  const uint32_t n = static_cast<uint32_t>(bytes.size());
  out[0] = 0x00;
  out[1] = 0x01;
  out[2] = 0x00;
  out[3] = 0x00;
  out[4] = static_cast<uint8_t>(n);
  out[5] = static_cast<uint8_t>(n >> 8);
  out[6] = static_cast<uint8_t>(n >> 16);
  out[7] = static_cast<uint8_t>(n >> 24);
  if (n) std::memcpy(out + kCdrHeaderBytes, bytes.data(), n);
}

bool DecodeCdrBytes(std::span<const uint8_t> payload, std::vector<uint8_t>* bytes) {
  const uint8_t* p = payload.data();
  const size_t len = payload.size();
  bool ok = len >= kCdrHeaderBytes && p[0] == 0x00 && (p[1] == 0x00 || p[1] == 0x01) && p[2] == 0 && p[3] == 0;
  uint32_t n = 0;
  if (ok) {
    n = p[1] == 0x01 ? (uint32_t(p[4]) | uint32_t(p[5]) << 8 | uint32_t(p[6]) << 16 | uint32_t(p[7]) << 24)
                     : (uint32_t(p[7]) | uint32_t(p[6]) << 8 | uint32_t(p[5]) << 16 | uint32_t(p[4]) << 24);
    ok = n <= len - kCdrHeaderBytes && n <= kMaxSampleBytes;
  }
  if (ok) {
    bytes->assign(p + kCdrHeaderBytes, p + kCdrHeaderBytes + n);
  } else {
    bytes->assign(p, p + std::min<size_t>(len, kMaxSampleBytes));
  }
  return ok;
}

}  // namespace poseforest::proto::dds
