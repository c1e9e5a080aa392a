#include "runtime/frame_formats.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>

#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"

// The depth file formats: .npy (ParseNpyHeader, WriteDepthNpy), PCL's .pcd (ParsePcdDepth),
// 16-bit PNG and raw frames (ReadDepthFile).

namespace poseforest::runtime {

using core::ErrorCode;
using core::Result;
using core::Status;
namespace fs = std::filesystem;

namespace detail {

Result<std::vector<uint8_t>> ReadAll(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    return Status(
        err == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo,
        path + (err == ENOENT ? ": no such file" : ": cannot open: " + std::string(std::strerror(err))));
  }
  std::vector<uint8_t> out;
  uint8_t buf[1 << 16];
  while (true) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string err = std::strerror(errno);
      ::close(fd);
      return Status(ErrorCode::kIo, path + ": read failed: " + err);
    }
    if (n == 0) break;
    out.insert(out.end(), buf, buf + n);
  }
  ::close(fd);
  return out;
}

bool StartsWith(const std::vector<uint8_t>& b, std::string_view s) {
  return b.size() >= s.size() && std::memcmp(b.data(), s.data(), s.size()) == 0;
}

int RawWidth(const FrameSourceOptions& o) {
  return o.raw_width > 0 ? o.raw_width : o.camera.intrinsics.width;
}
int RawHeight(const FrameSourceOptions& o) {
  return o.raw_height > 0 ? o.raw_height : o.camera.intrinsics.height;
}

void ApplyDepthScale(core::DepthImage* depth, double scale_mm) {
  if (scale_mm == 1.0) return;
  for (uint16_t& d : depth->pixels) d = uint16_t(std::min(65535.0, std::round(double(d) * scale_mm)));
}

Result<std::vector<core::DepthImage>> DecodeNpyFrames(const std::vector<uint8_t>& bytes,
                                                      const std::string& path, double depth_scale_mm) {
  auto h = ParseNpyHeader(bytes, path);
  if (!h.ok()) return h.status();
  const int64_t n = h->shape.size() == 3 ? h->shape[0] : 1;
  const int64_t rows = h->shape[h->shape.size() - 2], cols = h->shape.back();
  const size_t elem = h->descr == "<u2" ? 2 : 4;
  const uint64_t need = uint64_t(n) * uint64_t(rows) * uint64_t(cols) * elem;
  if (bytes.size() - h->data_offset < need)
    return Status(ErrorCode::kDataLoss, path + ": .npy of shape " + std::to_string(n) + "x" +
                                            std::to_string(rows) + "x" + std::to_string(cols) + " needs " +
                                            std::to_string(need) + " bytes of data but holds " +
                                            std::to_string(bytes.size() - h->data_offset) + " (truncated)");
  std::vector<core::DepthImage> frames;
  const uint8_t* p = bytes.data() + h->data_offset;
  for (int64_t f = 0; f < n; ++f) {
    core::DepthImage d{int(cols), int(rows)};
    for (size_t i = 0; i < d.pixels.size(); ++i, p += elem) {
      if (elem == 2) {
        d.pixels[i] = uint16_t(p[0] | p[1] << 8);
      } else {
        float m;
        std::memcpy(&m, p, 4);
        // Metres to mm; NaN, inf, <= 0 and beyond 65.535 m are "no reading".
        d.pixels[i] =
            (std::isfinite(m) && m > 0 && m < 65.535f) ? uint16_t(std::lround(double(m) * 1000.0)) : 0;
      }
    }
    if (elem == 2) ApplyDepthScale(&d, depth_scale_mm);
    frames.push_back(std::move(d));
  }
  return frames;
}

}  // namespace detail

namespace {

using detail::ApplyDepthScale;
using detail::DecodeNpyFrames;
using detail::RawHeight;
using detail::RawWidth;
using detail::ReadAll;
using detail::StartsWith;

// LZF decompression (liblzf's format, as PCL's binary_compressed uses): literal runs
// (ctrl < 32: ctrl + 1 bytes) and back references (len = ctrl >> 5, +7 extension byte; offset
// 13 bits). Every read and write is bounds-checked.
bool LzfDecompress(const uint8_t* in, size_t in_len, uint8_t* out, size_t out_len) {
  size_t ip = 0, op = 0;
  while (ip < in_len) {
    const unsigned ctrl = in[ip++];
    if (ctrl < 32) {
      const size_t len = ctrl + 1;
      if (ip + len > in_len || op + len > out_len) return false;
      std::memcpy(out + op, in + ip, len);
      ip += len;
      op += len;
    } else {
      size_t len = ctrl >> 5;
      if (len == 7) {
        if (ip >= in_len) return false;
        len += in[ip++];
      }
      if (ip >= in_len) return false;
      const size_t back = ((ctrl & 0x1F) << 8) + in[ip++] + 1;
      len += 2;
      if (back > op || op + len > out_len) return false;
      for (size_t i = 0; i < len; ++i, ++op) out[op] = out[op - back];
    }
  }
  return op == out_len;
}

}  // namespace

Result<NpyHeader> ParseNpyHeader(const std::vector<uint8_t>& b, const std::string& source) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, source + ": " + what); };
  if (!StartsWith(b, "\x93NUMPY")) return bad("not a .npy file (no \\x93NUMPY magic)");
  if (b.size() < 10) return bad(".npy header truncated");
  const int major = b[6];
  size_t header_len = 0, start = 0;
  if (major == 1) {
    header_len = size_t(b[8] | b[9] << 8);
    start = 10;
  } else if (major == 2 || major == 3) {
    if (b.size() < 12) return bad(".npy header truncated");
    header_len = size_t(b[8]) | size_t(b[9]) << 8 | size_t(b[10]) << 16 | size_t(b[11]) << 24;
    start = 12;
  } else {
    return bad(".npy format version " + std::to_string(major) + "." + std::to_string(b[7]) +
               " is not 1, 2 or 3");
  }
  if (b.size() - start < header_len)
    return bad(".npy header of " + std::to_string(header_len) + " bytes is truncated");
  const std::string h(reinterpret_cast<const char*>(b.data() + start), header_len);
  // The header is a Python dict literal: {'descr': '<u2', 'fortran_order': False, 'shape': (480, 640), }
  auto value_of = [&](const std::string& key) -> std::optional<std::string> {
    for (const char q : {'\'', '"'}) {
      const std::string k = std::string(1, q) + key + std::string(1, q);
      const size_t at = h.find(k);
      if (at == std::string::npos) continue;
      size_t p = h.find(':', at + k.size());
      if (p == std::string::npos) return std::nullopt;
      ++p;
      while (p < h.size() && h[p] == ' ') ++p;
      if (p >= h.size()) return std::nullopt;
      size_t end;
      if (h[p] == '\'' || h[p] == '"') {
        end = h.find(h[p], p + 1);
        if (end == std::string::npos) return std::nullopt;
        return h.substr(p + 1, end - p - 1);
      }
      if (h[p] == '(') {
        end = h.find(')', p);
        if (end == std::string::npos) return std::nullopt;
        return h.substr(p, end - p + 1);
      }
      end = h.find_first_of(",}", p);
      return h.substr(p, end == std::string::npos ? std::string::npos : end - p);
    }
    return std::nullopt;
  };
  const auto descr = value_of("descr"), fortran = value_of("fortran_order"), shape = value_of("shape");
  if (!descr || !fortran || !shape)
    return bad(".npy header is not a dict with descr, fortran_order and shape: " + h);
  NpyHeader out;
  out.descr = *descr;
  if (out.descr == "|u2" || out.descr == "=u2") out.descr = "<u2";  // single-byte order marks on LE hosts
  if (out.descr != "<u2" && out.descr != "<f4")
    return Status(ErrorCode::kInvalidArgument,
                  source + ": .npy holds dtype '" + *descr +
                      "'; depth must be uint16 millimetres ('<u2') or float32 metres ('<f4')");
  if (fortran->find("False") == std::string::npos)
    return Status(ErrorCode::kInvalidArgument,
                  source + ": .npy is in Fortran order; save it C-ordered (np.ascontiguousarray)");
  // Shape "(480, 640)" or "(3, 480, 640)".
  std::string s = *shape;
  for (char& c : s)
    if (c == '(' || c == ')' || c == ',') c = ' ';
  size_t pos = 0;
  while (true) {
    while (pos < s.size() && s[pos] == ' ') ++pos;
    if (pos >= s.size()) break;
    size_t end = pos;
    while (end < s.size() && s[end] != ' ') ++end;
    const std::string tok = s.substr(pos, end - pos);
    char* e = nullptr;
    const long long v = std::strtoll(tok.c_str(), &e, 10);
    if (*e != '\0' || v < 0 || v > (1 << 20)) return bad(".npy shape " + *shape + " is not a tuple of sizes");
    out.shape.push_back(v);
    pos = end;
  }
  if (out.shape.size() != 2 && out.shape.size() != 3)
    return Status(
        ErrorCode::kInvalidArgument,
        source + ": .npy of shape " + *shape + "; depth must be [height, width] or [frames, height, width]");
  for (int64_t v : out.shape)
    if (v == 0)
      return Status(ErrorCode::kInvalidArgument, source + ": .npy of shape " + *shape + " is empty");
  out.data_offset = start + header_len;
  return out;
}

core::Status WriteDepthNpy(const std::string& path, const std::vector<core::DepthImage>& frames) {
  if (frames.empty()) return {ErrorCode::kInvalidArgument, path + ": no frames to write"};
  const int w = frames[0].width, h = frames[0].height;
  std::string header = "{'descr': '<u2', 'fortran_order': False, 'shape': (";
  if (frames.size() > 1) header += std::to_string(frames.size()) + ", ";
  header += std::to_string(h) + ", " + std::to_string(w) + "), }";
  while ((10 + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::vector<uint8_t> bytes = {
      0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, uint8_t(header.size() & 0xFF), uint8_t(header.size() >> 8)};
  bytes.insert(bytes.end(), header.begin(), header.end());
  for (const auto& f : frames) {
    if (f.width != w || f.height != h)
      return {ErrorCode::kInvalidArgument, path + ": frames of different sizes"};
    for (uint16_t d : f.pixels) {
      bytes.push_back(uint8_t(d & 0xFF));
      bytes.push_back(uint8_t(d >> 8));
    }
  }
  return core::WriteFileAtomic(path, bytes);
}

Result<core::DepthImage> ReadPcdDepth(const std::string& path) {
  auto bytes = ReadAll(path);
  if (!bytes.ok()) return bytes.status();
  return ParsePcdDepth(*bytes, path);
}

namespace {

/// What a PCD header says, and where its data starts.
struct PcdHeader {
  std::vector<std::string> fields;
  std::vector<int> sizes, counts;
  std::vector<char> types;
  int64_t width = 0, height = 0, points = -1;
  std::string data;
  size_t pos = 0;  ///< the data's first byte
};

/// The header lines up to DATA (errors as ParsePcdDepth's).
Result<PcdHeader> ReadPcdHeader(std::span<const uint8_t> b, const std::string& path) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  PcdHeader hd;
  std::vector<std::string>& fields = hd.fields;
  std::vector<int>& sizes = hd.sizes;
  std::vector<int>& counts = hd.counts;
  std::vector<char>& types = hd.types;
  int64_t& width = hd.width;
  int64_t& height = hd.height;
  int64_t& points = hd.points;
  std::string& data = hd.data;
  size_t& pos = hd.pos;
  while (pos < b.size() && data.empty()) {
    size_t end = pos;
    while (end < b.size() && b[end] != '\n') ++end;
    if (end >= b.size()) return bad("PCD header has no DATA line (truncated?)");
    std::string line(reinterpret_cast<const char*>(b.data() + pos), end - pos);
    pos = end + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> tok;
    size_t p = 0;
    while (p < line.size()) {
      while (p < line.size() && line[p] == ' ') ++p;
      size_t q = p;
      while (q < line.size() && line[q] != ' ') ++q;
      if (q > p) tok.push_back(line.substr(p, q - p));
      p = q;
    }
    if (tok.empty()) continue;
    const std::string& key = tok[0];
    auto ints = [&](std::vector<int>* out) {
      for (size_t i = 1; i < tok.size(); ++i) out->push_back(std::atoi(tok[i].c_str()));
    };
    if (key == "FIELDS")
      fields.assign(tok.begin() + 1, tok.end());
    else if (key == "SIZE")
      ints(&sizes);
    else if (key == "COUNT")
      ints(&counts);
    else if (key == "TYPE")
      for (size_t i = 1; i < tok.size(); ++i) types.push_back(tok[i].empty() ? '?' : tok[i][0]);
    else if (key == "WIDTH" && tok.size() > 1)
      width = std::atoll(tok[1].c_str());
    else if (key == "HEIGHT" && tok.size() > 1)
      height = std::atoll(tok[1].c_str());
    else if (key == "POINTS" && tok.size() > 1)
      points = std::atoll(tok[1].c_str());
    else if (key == "DATA" && tok.size() > 1)
      data = tok[1];
  }
  if (data.empty()) return bad("PCD header has no DATA line");
  return hd;
}

/// Metres to mm; NaN, inf, <= 0 and beyond 65.535 m are "no reading".
uint16_t PcdMetresToMm(float z) {
  return (std::isfinite(z) && z > 0 && z < 65.535f) ? uint16_t(std::lround(double(z) * 1000.0)) : 0;
}

/// Where a point's x, y and z are: field numbers (x, y: -1 when absent or not a float), byte
/// offsets within a point (binary) and sizes (4: float32, 8: float64, as PCL writes doubles).
struct PcdFieldIndex {
  int x = -1, y = -1, z = -1;
  int x_offset = 0, y_offset = 0, z_offset = 0;
  int x_size = 4, y_size = 4, z_size = 4;
};

/// A float32 or float64 value (`size` 4 or 8) at `p`, as a float.
float PcdFloat(const uint8_t* p, int size) {
  if (size == 8) {
    double v;
    std::memcpy(&v, p, 8);
    return float(v);
  }
  float v;
  std::memcpy(&v, p, 4);
  return v;
}

/// Sums for fitting the cloud's pinhole projection, u = fx x/z + cx and v = fy y/z + cy, by least
/// squares over the points with finite x, y and z > 0 (an organized cloud's point i is pixel
/// (i % width, i / width)).
struct PcdXy {
  int width = 1;
  // Per axis: n, sum a, sum a^2, sum p, sum p^2, sum a p (a = x/z or y/z; p = u or v).
  double n = 0, sa[2] = {0, 0}, saa[2] = {0, 0}, sp[2] = {0, 0}, spp[2] = {0, 0}, sap[2] = {0, 0};
  void Set(size_t i, float x, float y, float z) {
    if (!(std::isfinite(x) && std::isfinite(y) && std::isfinite(z) && z > 0)) return;
    const double a[2] = {double(x) / double(z), double(y) / double(z)};
    const double p[2] = {double(i % size_t(width)), double(i / size_t(width))};
    n += 1;
    for (int k = 0; k < 2; ++k) {
      sa[k] += a[k], saa[k] += a[k] * a[k], sp[k] += p[k], spp[k] += p[k] * p[k], sap[k] += a[k] * p[k];
    }
  }
};

/// DATA ascii: every point's fields in order.
Status ReadPcdAscii(std::span<const uint8_t> b, const PcdHeader& hd, const PcdFieldIndex& fi,
                    const std::string& path, core::DepthImage& depth, PcdXy& xy) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  const std::vector<std::string>& fields = hd.fields;
  const std::vector<int>& counts = hd.counts;
  const size_t pos = hd.pos;
  const size_t n = depth.pixels.size();
  auto to_mm = PcdMetresToMm;
  std::string text(reinterpret_cast<const char*>(b.data() + pos), b.size() - pos);
  size_t p = 0;
  for (size_t i = 0; i < n; ++i) {
    float z = 0, x = std::nanf(""), y = std::nanf("");
    for (size_t f = 0; f < fields.size(); ++f) {
      for (int c = 0; c < counts[f]; ++c) {
        while (p < text.size() && (text[p] == ' ' || text[p] == '\n' || text[p] == '\r')) ++p;
        if (p >= text.size())
          return bad("PCD ascii data ends at point " + std::to_string(i) + " of " + std::to_string(n));
        char* e = nullptr;
        const float v = std::strtof(text.c_str() + p, &e);
        if (e == text.c_str() + p) {
          // "nan" is handled by strtof; anything else is corrupt.
          return bad("PCD ascii value at point " + std::to_string(i) + " is not a number");
        }
        p = size_t(e - text.c_str());
        if (int(f) == fi.z) z = v;
        if (int(f) == fi.x) x = v;
        if (int(f) == fi.y) y = v;
      }
    }
    depth.pixels[i] = to_mm(z);
    xy.Set(i, x, y, z);
  }
  return Status::Ok();
}

/// DATA binary: points of point_size bytes, z at z_offset in each.
Status ReadPcdBinary(std::span<const uint8_t> b, const PcdHeader& hd, int point_size, const PcdFieldIndex& fi,
                     const std::string& path, core::DepthImage& depth, PcdXy& xy) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  const size_t pos = hd.pos;
  const size_t n = depth.pixels.size();
  auto to_mm = PcdMetresToMm;
  if (b.size() - pos < n * size_t(point_size))
    return bad("PCD binary data holds " + std::to_string(b.size() - pos) + " bytes, " +
               std::to_string(n * size_t(point_size)) + " expected (truncated)");
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* point = b.data() + pos + i * size_t(point_size);
    const float z = PcdFloat(point + size_t(fi.z_offset), fi.z_size);
    const float x = fi.x >= 0 ? PcdFloat(point + size_t(fi.x_offset), fi.x_size) : std::nanf("");
    const float y = fi.y >= 0 ? PcdFloat(point + size_t(fi.y_offset), fi.y_size) : std::nanf("");
    depth.pixels[i] = to_mm(z);
    xy.Set(i, x, y, z);
  }
  return Status::Ok();
}

/// DATA binary_compressed: LZF, fields one after the other.
Status ReadPcdCompressed(std::span<const uint8_t> b, const PcdHeader& hd, const PcdFieldIndex& fi,
                         int point_size, const std::string& path, core::DepthImage& depth, PcdXy& xy) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  const std::vector<int>& sizes = hd.sizes;
  const std::vector<int>& counts = hd.counts;
  const size_t pos = hd.pos;
  const size_t n = depth.pixels.size();
  auto to_mm = PcdMetresToMm;
  if (b.size() - pos < 8) return bad("PCD binary_compressed sizes missing (truncated)");
  uint32_t csize, usize;
  std::memcpy(&csize, b.data() + pos, 4);
  std::memcpy(&usize, b.data() + pos + 4, 4);
  if (usize != n * size_t(point_size))
    return bad("PCD uncompressed size " + std::to_string(usize) + " != points x point size");
  if (b.size() - pos - 8 < csize) return bad("PCD compressed data truncated");
  std::vector<uint8_t> raw(usize);
  if (!LzfDecompress(b.data() + pos + 8, csize, raw.data(), raw.size()))
    return bad("PCD LZF data is corrupt");
  // binary_compressed stores the fields one after the other (all x, then all y, ...).
  auto field_start = [&](int field) {
    size_t start = 0;
    for (int f = 0; f < field; ++f) start += size_t(sizes[size_t(f)]) * size_t(counts[size_t(f)]) * n;
    return start;
  };
  const size_t z_start = field_start(fi.z);
  const size_t x_start = fi.x >= 0 ? field_start(fi.x) : 0, y_start = fi.y >= 0 ? field_start(fi.y) : 0;
  for (size_t i = 0; i < n; ++i) {
    const float z = PcdFloat(raw.data() + z_start + i * size_t(fi.z_size), fi.z_size);
    const float x =
        fi.x >= 0 ? PcdFloat(raw.data() + x_start + i * size_t(fi.x_size), fi.x_size) : std::nanf("");
    const float y =
        fi.y >= 0 ? PcdFloat(raw.data() + y_start + i * size_t(fi.y_size), fi.y_size) : std::nanf("");
    depth.pixels[i] = to_mm(z);
    xy.Set(i, x, y, z);
  }
  return Status::Ok();
}

}  // namespace

Result<PcdFrame> ParsePcdFrame(std::span<const uint8_t> b, const std::string& path) {
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  auto header = ReadPcdHeader(b, path);
  if (!header.ok()) return header.status();
  PcdHeader& hd = *header;
  const std::vector<std::string>& fields = hd.fields;
  const std::vector<int>& sizes = hd.sizes;
  std::vector<int>& counts = hd.counts;
  const std::vector<char>& types = hd.types;
  const int64_t width = hd.width, height = hd.height, points = hd.points;
  const std::string& data = hd.data;
  if (counts.empty()) counts.assign(fields.size(), 1);
  if (fields.empty() || sizes.size() != fields.size() || types.size() != fields.size() ||
      counts.size() != fields.size())
    return bad("PCD header's FIELDS, SIZE, TYPE and COUNT disagree");
  if (width <= 0 || height <= 1 || width > 16384 || height > 16384)
    return Status(ErrorCode::kInvalidArgument,
                  path + ": PCD cloud is " + std::to_string(width) + "x" + std::to_string(height) +
                      "; only organized clouds (HEIGHT > 1, one point per pixel) are depth frames");
  if (points >= 0 && points != width * height)
    return bad("PCD POINTS " + std::to_string(points) + " != WIDTH x HEIGHT");
  PcdFieldIndex fi;
  // Every field's SIZE is 1, 2, 4 or 8 bytes and its COUNT 1 to kMaxPcdCount (PCL's own types;
  // a histogram field such as FPFH's has a COUNT of 33), so the byte offsets below stay inside a
  // point of at most 64 KiB.
  constexpr int kMaxPcdCount = 8192;
  int point_size = 0, values_per_point = 0;
  for (size_t i = 0; i < fields.size(); ++i) {
    if (sizes[i] != 1 && sizes[i] != 2 && sizes[i] != 4 && sizes[i] != 8)
      return bad("PCD field '" + fields[i] + "' has SIZE " + std::to_string(sizes[i]) +
                 " (1, 2, 4 or 8 bytes)");
    if (counts[i] < 1 || counts[i] > kMaxPcdCount)
      return bad("PCD field '" + fields[i] + "' has COUNT " + std::to_string(counts[i]) + " (1 to " +
                 std::to_string(kMaxPcdCount) + ")");
    if (point_size + sizes[i] * counts[i] > 65536) return bad("PCD points are larger than 64 KiB");
    const bool is_float = (sizes[i] == 4 || sizes[i] == 8) && types[i] == 'F' && counts[i] == 1;
    if (fields[i] == "z") fi.z = int(i), fi.z_offset = point_size, fi.z_size = sizes[i];
    if (fields[i] == "x" && is_float) fi.x = int(i), fi.x_offset = point_size, fi.x_size = sizes[i];
    if (fields[i] == "y" && is_float) fi.y = int(i), fi.y_offset = point_size, fi.y_size = sizes[i];
    point_size += sizes[i] * counts[i];
    values_per_point += counts[i];
  }
  const int zi = fi.z;
  if (zi < 0 || (sizes[size_t(zi)] != 4 && sizes[size_t(zi)] != 8) || types[size_t(zi)] != 'F' ||
      counts[size_t(zi)] != 1)
    return Status(ErrorCode::kInvalidArgument,
                  path + ": PCD has no float32 or float64 'z' field (metres) to read depth from");
  // The data must be able to hold every point before the image is allocated: a header of a few
  // bytes may declare 16384 x 16384 points (half a GiB of depth).
  if (data == "ascii" || data == "binary" || data == "binary_compressed") {
    const uint64_t n = uint64_t(width) * uint64_t(height), left = b.size() - hd.pos;
    // ascii: each value takes at least one character and one separator (the last none);
    // binary_compressed: LZF gives at most 88 bytes per input byte (a 3-byte back-reference of
    // 264), so the compressed data cannot be shorter than the points / 88.
    const uint64_t need = data == "ascii"    ? n * uint64_t(values_per_point) * 2 - 1
                          : data == "binary" ? n * uint64_t(point_size)
                                             : 8 + n * uint64_t(point_size) / 88;
    if (left < need)
      return bad("PCD " + data + " data holds " + std::to_string(left) + " bytes, too few for " +
                 std::to_string(n) + " points of " + std::to_string(point_size) + " bytes (truncated)");
  }
  PcdFrame frame;
  frame.depth = core::DepthImage{int(width), int(height)};
  PcdXy xy;
  xy.width = int(width);
  if (data == "ascii") {
    POSEFOREST_RETURN_IF_ERROR(ReadPcdAscii(b, hd, fi, path, frame.depth, xy));
  } else if (data == "binary") {
    POSEFOREST_RETURN_IF_ERROR(ReadPcdBinary(b, hd, point_size, fi, path, frame.depth, xy));
  } else if (data == "binary_compressed") {
    POSEFOREST_RETURN_IF_ERROR(ReadPcdCompressed(b, hd, fi, point_size, path, frame.depth, xy));
  } else {
    return bad("PCD DATA '" + data + "' is not ascii, binary or binary_compressed");
  }
  // The projection the points were made with, if they fit a pinhole camera (camera frame: x
  // right, y down, z forward) to within half a pixel; a cloud moved into another frame does not.
  if (xy.n >= 16) {
    double f[2], c[2], sse = 0;
    bool ok = true;
    for (int k = 0; k < 2; ++k) {
      const double var_a = xy.saa[k] - xy.sa[k] * xy.sa[k] / xy.n;
      const double cov = xy.sap[k] - xy.sa[k] * xy.sp[k] / xy.n;
      const double var_p = xy.spp[k] - xy.sp[k] * xy.sp[k] / xy.n;
      ok = ok && var_a > 1e-12 && var_p > 0;
      f[k] = ok ? cov / var_a : 0;
      c[k] = ok ? (xy.sp[k] - f[k] * xy.sa[k]) / xy.n : 0;
      sse += ok ? std::max(0.0, var_p - f[k] * cov) : 0;
    }
    frame.fit_rms_px = std::sqrt(sse / (2 * xy.n));
    if (ok && f[0] > 1 && f[1] > 1 && frame.fit_rms_px <= 0.5) {
      core::CameraIntrinsics in;
      in.width = int(width), in.height = int(height);
      in.fx = f[0], in.fy = f[1], in.cx = c[0], in.cy = c[1];
      frame.intrinsics = in;
    }
  }
  return frame;
}

Result<core::DepthImage> ParsePcdDepth(std::span<const uint8_t> b, const std::string& path) {
  auto frame = ParsePcdFrame(b, path);
  if (!frame.ok()) return frame.status();
  return std::move(frame->depth);
}

Result<PcdFrame> ReadPcdFrame(const std::string& path) {
  auto bytes = ReadAll(path);
  if (!bytes.ok()) return bytes.status();
  return ParsePcdFrame(*bytes, path);
}

Result<core::DepthImage> ReadDepthFile(const std::string& path, const FrameSourceOptions& options) {
  if (fs::path(path).extension() == ".pcd") return ReadPcdDepth(path);
  auto bytes = ReadAll(path);
  if (!bytes.ok()) return bytes.status();
  if (StartsWith(*bytes, "\x93NUMPY")) {
    auto frames = DecodeNpyFrames(*bytes, path, options.camera.depth_scale_mm);
    if (!frames.ok()) return frames.status();
    if (frames->size() != 1)
      return Status(ErrorCode::kInvalidArgument, path + ": holds " + std::to_string(frames->size()) +
                                                     " frames; read it as a frame source for all of them");
    return std::move(frames->front());
  }
  core::DepthImage depth;
  static constexpr uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (bytes->size() >= 8 && std::memcmp(bytes->data(), kPng, 8) == 0) {
    auto png = DecodeDepthPng(*bytes, path);
    if (!png.ok()) return png.status();
    depth = std::move(*png);
  } else {
    const int w = RawWidth(options), h = RawHeight(options);
    const uint64_t expected = uint64_t(w) * uint64_t(h) * 2;
    if (bytes->size() != expected)
      return Status(bytes->size() < expected ? ErrorCode::kDataLoss : ErrorCode::kInvalidArgument,
                    path + ": not a PNG, .npy or .pcd, and as a raw " + std::to_string(w) + "x" +
                        std::to_string(h) + " uint16 depth frame it should be " + std::to_string(expected) +
                        " bytes, but it is " + std::to_string(bytes->size()) + " bytes" +
                        (bytes->size() < expected ? " (truncated?)" : ""));
    depth = core::DepthImage(w, h);
    const auto& b = *bytes;
    for (size_t i = 0; i < depth.pixels.size(); ++i) depth.pixels[i] = uint16_t(b[2 * i] | b[2 * i + 1] << 8);
  }
  ApplyDepthScale(&depth, options.camera.depth_scale_mm);
  return depth;
}

}  // namespace poseforest::runtime
