#pragma once
// CRC-32 (IEEE 802.3 / zlib / PNG polynomial), used by the forest format.

#include <cstddef>
#include <cstdint>

namespace poseforest::core {

/// Continues a CRC-32 over `size` bytes; start with crc = 0.
uint32_t Crc32(const void* data, size_t size, uint32_t crc = 0);

}  // namespace poseforest::core
