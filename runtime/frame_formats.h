#pragma once
// The depth file formats' shared pieces (frame_formats.cpp), for the frame sources
// (frame_source.cpp): not a public API.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "runtime/core/depth_image.h"
#include "runtime/core/result.h"
#include "runtime/frame_source.h"

namespace poseforest::runtime::detail {

// Reads a whole file with read(2) until end of file: works on regular files, FIFOs and
// /dev/stdin alike (no seeking).
core::Result<std::vector<uint8_t>> ReadAll(const std::string& path);

bool StartsWith(const std::vector<uint8_t>& b, std::string_view s);

/// The raw frame size: FrameSourceOptions::raw_width/raw_height, else the camera's.
int RawWidth(const FrameSourceOptions& o);
int RawHeight(const FrameSourceOptions& o);

/// Multiplies every depth by scale_mm (rounded, saturated at 65535).
void ApplyDepthScale(core::DepthImage* depth, double scale_mm);

// Frames held by one .npy: uint16 mm or float32 metres, [H,W] or [N,H,W].
core::Result<std::vector<core::DepthImage>> DecodeNpyFrames(const std::vector<uint8_t>& bytes,
                                                            const std::string& path, double depth_scale_mm);

}  // namespace poseforest::runtime::detail
