#pragma once
// Image files for the runtime: PNG through libspng (over zlib), and raw uint16 depth frames.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/result.h"

namespace poseforest::runtime {

/// A decoded PNG: 8- or 16-bit samples, 1 (grey), 2 (grey+alpha), 3 (RGB) or 4 (RGBA) channels.
/// 16-bit samples are stored as native uint16 in `samples16`, 8-bit ones in `samples8`.
struct PngImage {
  int width = 0, height = 0;
  int channels = 0;
  int bit_depth = 0;  ///< 8 or 16 after decoding (1/2/4-bit and palette images expand to 8)
  std::vector<uint8_t> samples8;
  std::vector<uint16_t> samples16;
};

/// Decodes a PNG from memory (all colour types, bit depths and filters; interlaced images are
/// refused with a clear error). `source` names the file in errors. Palette indices beyond the
/// palette read as black, and data after the last scanline is ignored (as libpng does).
core::Result<PngImage> DecodePng(std::span<const uint8_t> bytes, const std::string& source);
/// A depth PNG (16-bit greyscale, millimetres) from memory: any other colour type or bit depth
/// is refused from its header, before the image is decoded (a 1-bit palette image of a few KiB
/// would otherwise expand to up to 1 GiB of RGBA first).
core::Result<core::DepthImage> DecodeDepthPng(std::span<const uint8_t> bytes, const std::string& source);
/// A label or person-mask PNG (8-bit greyscale of raw values) from memory: any other colour type
/// or bit depth is refused from its header, before the image is decoded, as DecodeDepthPng does.
core::Result<core::LabelImage> DecodeLabelPng(std::span<const uint8_t> bytes, const std::string& source);
/// Encodes `samples` (row-major, width*height*channels values) as a PNG (zlib-compressed).
std::vector<uint8_t> EncodePng8(int width, int height, int channels, std::span<const uint8_t> samples);
std::vector<uint8_t> EncodePng16(int width, int height, int channels, std::span<const uint16_t> samples);

/// Reads a depth image in millimetres: a 16-bit greyscale PNG, or a raw little-endian uint16
/// file of exactly width*height*2 bytes (the Kinect frames in shared/data/real are 640x480).
/// Files whose first bytes are the PNG signature are read as PNG, others as raw.
core::Result<core::DepthImage> ReadDepthImage(const std::string& path, int raw_width = 640, int raw_height = 480);

/// Writes depth (mm) as a 16-bit greyscale PNG.
core::Status WriteDepthPng(const std::string& path, const core::DepthImage& depth);
/// Writes a label image as 8-bit greyscale PNG of raw label values (255 = background).
core::Status WriteLabelPng(const std::string& path, const core::LabelImage& labels);
/// Writes a label image as an RGB picture using the part colours (background black).
core::Status WriteLabelColourPng(const std::string& path, const core::LabelImage& labels);
/// Writes an 8-bit RGB image (width*height*3 samples).
core::Status WriteRgbPng(const std::string& path, int width, int height, std::span<const uint8_t> rgb);

}  // namespace poseforest::runtime
