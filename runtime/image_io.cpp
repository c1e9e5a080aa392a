#include "runtime/image_io.h"

// PNG through libspng (which inflates and deflates with zlib). libspng validates chunk order,
// lengths, CRCs, the zlib stream and the filters against the buffers; a corrupt or truncated
// file gives a DataLoss Status naming the file and libspng's reason, never a crash or a read
// past the input. What is ours: the size limits, the refusal of interlaced images, and how
// each colour type maps to PngImage's samples.

#include <spng.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "runtime/core/forest_format.h"

namespace poseforest::runtime {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;

constexpr std::array<uint8_t, 8> kPngSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
/// Largest width or height we accept, in pixels.
constexpr uint32_t kMaxDimension = 32768;
/// Largest width * height we accept, in pixels (2^28: 256 Mpixel).
constexpr uint64_t kMaxPixels = uint64_t(1) << 28;
/// Deflate cannot expand better than ~1032:1 (a 258-byte match coded in 2 bits), so a file
/// shorter than this fraction of its filtered image is truncated; refusing it before decoding
/// keeps a tiny hostile file from making us allocate gigabytes.
constexpr uint64_t kMaxDeflateRatio = 1033;

struct SpngFree {
  void operator()(spng_ctx* ctx) const { spng_ctx_free(ctx); }
};
using SpngContext = std::unique_ptr<spng_ctx, SpngFree>;

Status DataLoss(const std::string& source, const std::string& what) {
  return Status(ErrorCode::kDataLoss, source + ": " + what);
}

Status SpngError(const std::string& source, const char* stage, int error) {
  if (error == SPNG_IO_EOF || error == SPNG_EOF)
    return DataLoss(source, std::string("truncated: the file ends in the ") + stage);
  return DataLoss(source, std::string(stage) + ": " + spng_strerror(error));
}

/// The IEND chunk, CRC included: libspng stops at its type and does not read the CRC.
constexpr std::array<uint8_t, 12> kIendChunk = {0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xAE, 0x42, 0x60, 0x82};

std::vector<uint8_t> EncodePngBytes(int width, int height, int channels, int bit_depth, const void* samples,
                                    size_t bytes) {
  static constexpr uint8_t kColourType[5] = {0, SPNG_COLOR_TYPE_GRAYSCALE, SPNG_COLOR_TYPE_GRAYSCALE_ALPHA,
                                             SPNG_COLOR_TYPE_TRUECOLOR, SPNG_COLOR_TYPE_TRUECOLOR_ALPHA};
  SpngContext ctx(spng_ctx_new(SPNG_CTX_ENCODER));
  POSEFOREST_CHECK_MSG(ctx != nullptr, "spng_ctx_new failed (out of memory)");
  spng_ihdr ihdr{};
  ihdr.width = uint32_t(width);
  ihdr.height = uint32_t(height);
  ihdr.bit_depth = uint8_t(bit_depth);
  ihdr.color_type = kColourType[channels];
  int err = spng_set_option(ctx.get(), SPNG_ENCODE_TO_BUFFER, 1);
  if (err == 0) err = spng_set_ihdr(ctx.get(), &ihdr);
  // SPNG_FMT_PNG: samples in the PNG's layout, 16-bit ones host-endian.
  if (err == 0) err = spng_encode_image(ctx.get(), samples, bytes, SPNG_FMT_PNG, SPNG_ENCODE_FINALIZE);
  size_t size = 0;
  void* png = err == 0 ? spng_get_png_buffer(ctx.get(), &size, &err) : nullptr;
  // The arguments were checked, so only memory can fail here.
  POSEFOREST_CHECK_MSG(err == 0 && png != nullptr, "libspng failed to encode a PNG");
  std::vector<uint8_t> out(static_cast<const uint8_t*>(png), static_cast<const uint8_t*>(png) + size);
  std::free(png);
  return out;
}

void CheckEncodeArgs(int width, int height, int channels, size_t samples) {
  POSEFOREST_CHECK_MSG(
      width > 0 && height > 0 && uint32_t(width) <= kMaxDimension && uint32_t(height) <= kMaxDimension,
      "PNG dimensions must be 1..32768");
  POSEFOREST_CHECK_MSG(uint64_t(width) * uint64_t(height) <= kMaxPixels, "PNG must have <= 2^28 pixels");
  POSEFOREST_CHECK_MSG(channels >= 1 && channels <= 4, "PNG channels must be 1..4");
  POSEFOREST_CHECK_MSG(samples == size_t(width) * size_t(height) * size_t(channels),
                       "sample count != width * height * channels");
}

/// What a caller accepts, checked from the header before anything is decoded.
enum class PngKind { kAny, kDepth, kLabels };

/// DecodePng; a `kind` other than kAny refuses anything but its colour type and bit depth from
/// the header, undecoded.
Result<PngImage> DecodePngImpl(std::span<const uint8_t> bytes, const std::string& source, PngKind kind) {
  if (bytes.size() < kPngSignature.size() ||
      !std::equal(kPngSignature.begin(), kPngSignature.end(), bytes.begin()))
    return DataLoss(source, "not a PNG file (bad signature)");
  SpngContext ctx(spng_ctx_new(0));
  if (ctx == nullptr) return Status(ErrorCode::kInternal, source + ": spng_ctx_new failed (out of memory)");
  if (int err = spng_set_png_buffer(ctx.get(), bytes.data(), bytes.size()))
    return SpngError(source, "PNG", err);

  spng_ihdr ihdr{};
  if (int err = spng_get_ihdr(ctx.get(), &ihdr)) return SpngError(source, "IHDR", err);
  const uint32_t width = ihdr.width, height = ihdr.height;
  if (width > kMaxDimension || height > kMaxDimension || uint64_t(width) * height > kMaxPixels) {
    return Status(ErrorCode::kInvalidArgument, source + ": image " + std::to_string(width) + "x" +
                                                   std::to_string(height) +
                                                   " is too large (limits: 32768 per side, 2^28 pixels)");
  }
  const int colour_type = ihdr.color_type, bit_depth = ihdr.bit_depth;
  const int channels_in = colour_type == SPNG_COLOR_TYPE_TRUECOLOR         ? 3
                          : colour_type == SPNG_COLOR_TYPE_GRAYSCALE_ALPHA ? 2
                          : colour_type == SPNG_COLOR_TYPE_TRUECOLOR_ALPHA ? 4
                                                                           : 1;
  const int wanted_depth = kind == PngKind::kDepth ? 16 : kind == PngKind::kLabels ? 8 : 0;
  if (wanted_depth != 0 && (colour_type != SPNG_COLOR_TYPE_GRAYSCALE || bit_depth != wanted_depth)) {
    return Status(
        ErrorCode::kInvalidArgument,
        source +
            (kind == PngKind::kDepth ? ": a depth image must be a 16-bit greyscale PNG in millimetres"
                                     : ": a label image must be an 8-bit greyscale PNG of raw values") +
            "; this one has " + std::to_string(channels_in) + " channel(s) of " + std::to_string(bit_depth) +
            "-bit samples" + (colour_type == SPNG_COLOR_TYPE_INDEXED ? " (a palette)" : ""));
  }
  if (ihdr.interlace_method != SPNG_INTERLACE_NONE) {
    return Status(ErrorCode::kUnimplemented,
                  source + ": interlaced (Adam7) PNG is not supported; re-save it non-interlaced");
  }
  const uint64_t rowbytes = (uint64_t(width) * uint64_t(channels_in) * uint64_t(bit_depth) + 7) / 8;
  if (uint64_t(height) * (rowbytes + 1) > uint64_t(bytes.size()) * kMaxDeflateRatio + 64) {
    return DataLoss(source, "the file (" + std::to_string(bytes.size()) + " bytes) is far too short for a " +
                                std::to_string(width) + "x" + std::to_string(height) + " image");
  }

  // What PngImage holds: palette images expand to RGB (RGBA with a tRNS chunk), 1/2/4-bit grey
  // to 8 bits scaled to 0..255; everything else keeps its channels and depth. A tRNS colour key
  // of a grey or RGB image is not applied: our images carry no transparency.
  PngImage img;
  img.width = int(width);
  img.height = int(height);
  int fmt = SPNG_FMT_PNG, flags = 0;
  img.channels = channels_in;
  img.bit_depth = bit_depth == 16 ? 16 : 8;
  if (colour_type == SPNG_COLOR_TYPE_INDEXED) {
    spng_trns trns{};
    const int trns_err = spng_get_trns(ctx.get(), &trns);  // reads the chunks up to IDAT
    if (trns_err != 0 && trns_err != SPNG_ECHUNKAVAIL) return SpngError(source, "palette image", trns_err);
    const bool has_trns = trns_err == 0;
    fmt = has_trns ? SPNG_FMT_RGBA8 : SPNG_FMT_RGB8;
    flags = has_trns ? SPNG_DECODE_TRNS : 0;
    img.channels = has_trns ? 4 : 3;
  } else if (colour_type == SPNG_COLOR_TYPE_GRAYSCALE && bit_depth < 8) {
    fmt = SPNG_FMT_G8;
  }
  size_t size = 0;
  if (int err = spng_decoded_image_size(ctx.get(), fmt, &size)) return SpngError(source, "IHDR", err);
  void* out = nullptr;
  if (img.bit_depth == 16) {
    img.samples16.resize(size / 2);
    out = img.samples16.data();
  } else {
    img.samples8.resize(size);
    out = img.samples8.data();
  }
  if (int err = spng_decode_image(ctx.get(), out, size, fmt, flags))
    return SpngError(source, "image data (IDAT)", err);
  // The chunks after the image, up to IEND: a file cut short there is truncated too.
  const int err = spng_decode_chunks(ctx.get());
  if (err == SPNG_IO_EOF || err == SPNG_EOF ||
      (err == 0 &&
       std::search(bytes.begin(), bytes.end(), kIendChunk.begin(), kIendChunk.end()) == bytes.end()))
    return DataLoss(source, "truncated: the file ends before the end of its IEND chunk");
  if (err != 0) return SpngError(source, "chunks after the image data", err);
  return img;
}
}  // namespace

Result<PngImage> DecodePng(std::span<const uint8_t> bytes, const std::string& source) {
  return DecodePngImpl(bytes, source, PngKind::kAny);
}

Result<core::LabelImage> DecodeLabelPng(std::span<const uint8_t> bytes, const std::string& source) {
  auto png = DecodePngImpl(bytes, source, PngKind::kLabels);
  if (!png.ok()) return png.status();
  core::LabelImage labels(png->width, png->height);
  labels.pixels = std::move(png->samples8);
  return labels;
}

Result<core::DepthImage> DecodeDepthPng(std::span<const uint8_t> bytes, const std::string& source) {
  auto png = DecodePngImpl(bytes, source, PngKind::kDepth);
  if (!png.ok()) return png.status();
  core::DepthImage depth;
  depth.width = png->width;
  depth.height = png->height;
  depth.pixels = std::move(png->samples16);
  return depth;
}

std::vector<uint8_t> EncodePng8(int width, int height, int channels, std::span<const uint8_t> samples) {
  CheckEncodeArgs(width, height, channels, samples.size());
  return EncodePngBytes(width, height, channels, 8, samples.data(), samples.size());
}

std::vector<uint8_t> EncodePng16(int width, int height, int channels, std::span<const uint16_t> samples) {
  CheckEncodeArgs(width, height, channels, samples.size());
  return EncodePngBytes(width, height, channels, 16, samples.data(), samples.size() * 2);
}

Result<core::DepthImage> ReadDepthImage(const std::string& path, int raw_width, int raw_height) {
  auto bytes = core::ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  const std::vector<uint8_t>& b = *bytes;
  if (b.size() >= kPngSignature.size() && std::equal(kPngSignature.begin(), kPngSignature.end(), b.begin())) {
    return DecodeDepthPng(b, path);
  }
  if (raw_width <= 0 || raw_height <= 0) {
    return Status(ErrorCode::kInvalidArgument, path + ": raw depth size " + std::to_string(raw_width) + "x" +
                                                   std::to_string(raw_height) + " is not positive");
  }
  const uint64_t expected = uint64_t(raw_width) * uint64_t(raw_height) * 2;
  if (b.size() != expected) {
    return Status(ErrorCode::kInvalidArgument,
                  path + ": not a PNG, and as a raw " + std::to_string(raw_width) + "x" +
                      std::to_string(raw_height) + " uint16 depth frame it should be " +
                      std::to_string(expected) + " bytes, but it is " + std::to_string(b.size()) + " bytes");
  }
  core::DepthImage depth(raw_width, raw_height);
  for (size_t i = 0; i < depth.pixels.size(); ++i) depth.pixels[i] = uint16_t(b[2 * i] | b[2 * i + 1] << 8);
  return depth;
}

Status WriteDepthPng(const std::string& path, const core::DepthImage& depth) {
  if (depth.width <= 0 || depth.height <= 0 ||
      depth.pixels.size() != size_t(depth.width) * size_t(depth.height))
    return Status(ErrorCode::kInvalidArgument, path + ": depth image is empty or inconsistent");
  return core::WriteFileAtomic(path, EncodePng16(depth.width, depth.height, 1, depth.pixels));
}

Status WriteLabelPng(const std::string& path, const core::LabelImage& labels) {
  if (labels.width <= 0 || labels.height <= 0 ||
      labels.pixels.size() != size_t(labels.width) * size_t(labels.height))
    return Status(ErrorCode::kInvalidArgument, path + ": label image is empty or inconsistent");
  return core::WriteFileAtomic(path, EncodePng8(labels.width, labels.height, 1, labels.pixels));
}

Status WriteLabelColourPng(const std::string& path, const core::LabelImage& labels) {
  if (labels.width <= 0 || labels.height <= 0 ||
      labels.pixels.size() != size_t(labels.width) * size_t(labels.height))
    return Status(ErrorCode::kInvalidArgument, path + ": label image is empty or inconsistent");
  std::array<core::Rgb, 256> lut;
  for (int i = 0; i < 256; ++i) lut[i] = i < core::kNumParts ? core::PartColour(i) : core::kBackgroundColour;
  std::vector<uint8_t> rgb(labels.pixels.size() * 3);
  for (size_t i = 0; i < labels.pixels.size(); ++i) {
    const core::Rgb c = lut[labels.pixels[i]];
    rgb[3 * i] = c.r;
    rgb[3 * i + 1] = c.g;
    rgb[3 * i + 2] = c.b;
  }
  return core::WriteFileAtomic(path, EncodePng8(labels.width, labels.height, 3, rgb));
}

Status WriteRgbPng(const std::string& path, int width, int height, std::span<const uint8_t> rgb) {
  if (width <= 0 || height <= 0 || uint32_t(width) > kMaxDimension || uint32_t(height) > kMaxDimension ||
      rgb.size() != size_t(width) * size_t(height) * 3) {
    return Status(ErrorCode::kInvalidArgument, path + ": RGB image " + std::to_string(width) + "x" +
                                                   std::to_string(height) + " with " +
                                                   std::to_string(rgb.size()) + " samples is inconsistent");
  }
  return core::WriteFileAtomic(path, EncodePng8(width, height, 3, rgb));
}

}  // namespace poseforest::runtime
