#include "runtime/image_io.h"

#include "runtime/core/forest_format.h"

// PNG (ISO/IEC 15948, RFC 2083) over zlib (RFC 1950) and deflate (RFC 1951), written here so
// the runtime needs no zlib/libpng. Decoding validates every length, code and distance against
// the buffers: a corrupt or truncated file gives a DataLoss Status naming the file, never a
// crash or a read past the input.

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string_view>

#include "runtime/core/crc32.h"

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
/// Deflate cannot expand better than ~1032:1 (a 258-byte match coded in 2 bits), so an IDAT
/// stream shorter than this fraction of the image is truncated; refusing it early keeps a tiny
/// hostile file from making us allocate gigabytes.
constexpr uint64_t kMaxDeflateRatio = 1033;
/// IDAT chunk size our encoder writes, in bytes.
constexpr size_t kIdatChunkSize = size_t(1) << 18;

uint32_t ReadBe32(const uint8_t* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | uint32_t(p[3]);
}

void PutBe32(std::vector<uint8_t>& out, uint32_t v) {
  out.push_back(uint8_t(v >> 24));
  out.push_back(uint8_t(v >> 16));
  out.push_back(uint8_t(v >> 8));
  out.push_back(uint8_t(v));
}

uint32_t Adler32(const uint8_t* data, size_t size) {
  uint32_t a = 1, b = 0;
  while (size > 0) {
    // 5552 is the largest n for which b cannot overflow 32 bits before the modulo (zlib's NMAX).
    size_t n = std::min<size_t>(size, 5552);
    size -= n;
    for (; n >= 4; n -= 4, data += 4) {
      a += data[0];
      b += a;
      a += data[1];
      b += a;
      a += data[2];
      b += a;
      a += data[3];
      b += a;
    }
    while (n--) {
      a += *data++;
      b += a;
    }
    a %= 65521;
    b %= 65521;
  }
  return b << 16 | a;
}

// ---------------------------------------------------------------------------------------------
// Deflate tables (RFC 1951 section 3.2.5).

constexpr std::array<uint16_t, 29> kLengthBase = {3,  4,  5,  6,   7,   8,   9,   10,  11, 13,
                                                  15, 17, 19, 23,  27,  31,  35,  43,  51, 59,
                                                  67, 83, 99, 115, 131, 163, 195, 227, 258};
constexpr std::array<uint8_t, 29> kLengthExtra = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                                  2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
constexpr std::array<uint16_t, 30> kDistBase = {
    1,   2,   3,   4,   5,   7,    9,    13,   17,   25,   33,   49,   65,    97,    129,
    193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
constexpr std::array<uint8_t, 30> kDistExtra = {0, 0, 0, 0, 1, 1, 2, 2,  3,  3,  4,  4,  5,  5,  6,
                                                6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
constexpr std::array<uint8_t, 19> kCodeLengthOrder = {16, 17, 18, 0, 8,  7, 9,  6, 10, 5,
                                                      11, 4,  12, 3, 13, 2, 14, 1, 15};
constexpr int kNumLitLen = 288;  // 286 usable + 2 reserved (present in the fixed code)
constexpr int kNumDist = 30;
constexpr int kMaxCodeBits = 15;

uint32_t ReverseBits(uint32_t code, int len) {
  uint32_t r = 0;
  for (int i = 0; i < len; ++i, code >>= 1) r = (r << 1) | (code & 1);
  return r;
}

// ---------------------------------------------------------------------------------------------
// Inflate

/// LSB-first bit reader over a bounded buffer. Past the end it feeds zero bits and remembers
/// it did; `overran()` turns true as soon as any such bit is consumed.
class BitReader {
 public:
  BitReader(const uint8_t* data, size_t size) : data_(data), size_(size) {}

  /// Ensures at least 57 bits (real or padding) are buffered.
  void Refill() {
    if (bitcnt_ > 56) return;
    if constexpr (std::endian::native == std::endian::little) {
      if (size_ - pos_ >= 8) {
        uint64_t word;
        std::memcpy(&word, data_ + pos_, 8);
        buf_ |= word << bitcnt_;
        pos_ += size_t(63 - bitcnt_) >> 3;
        bitcnt_ |= 56;
        return;
      }
    }
    while (bitcnt_ <= 56) {
      if (pos_ < size_) {
        buf_ |= uint64_t(data_[pos_++]) << bitcnt_;
      } else {
        padding_ += 8;
      }
      bitcnt_ += 8;
    }
  }
  /// The next n (<= 32) buffered bits; call Refill first.
  uint32_t Peek(int n) const { return uint32_t(buf_ & ((uint64_t(1) << n) - 1)); }
  void Consume(int n) {
    buf_ >>= n;
    bitcnt_ -= n;
    if (bitcnt_ < padding_) {
      overran_ = true;
      padding_ = bitcnt_;
    }
  }
  uint32_t Get(int n) {
    if (bitcnt_ < n) Refill();
    uint32_t v = Peek(n);
    Consume(n);
    return v;
  }
  bool overran() const { return overran_; }

  /// Skips to the next byte boundary and hands unread whole bytes back to the input, so that
  /// ReadBytes continues exactly there (stored blocks, the Adler-32 trailer).
  void AlignAndRewind() {
    Consume(bitcnt_ & 7);
    pos_ -= size_t(bitcnt_ - padding_) >> 3;
    buf_ = 0;
    bitcnt_ = 0;
    padding_ = 0;
  }
  /// After AlignAndRewind: copies n raw bytes; false if fewer remain.
  bool ReadBytes(uint8_t* dst, size_t n) {
    if (size_ - pos_ < n) return false;
    std::memcpy(dst, data_ + pos_, n);
    pos_ += n;
    return true;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  uint64_t buf_ = 0;
  int bitcnt_ = 0;
  int padding_ = 0;  // zero bits appended past the end, at the top of buf_
  bool overran_ = false;
};

/// Canonical Huffman decoder: a 10-bit lookup table for short codes, the canonical
/// count/symbol walk (as in zlib's puff.c) for longer ones.
struct HuffmanDecoder {
  static constexpr int kFastBits = 10;
  /// symbol | length << 9, or 0 when the code is longer than kFastBits (or unused).
  std::array<uint16_t, 1 << kFastBits> fast{};
  std::array<uint16_t, kMaxCodeBits + 1> count{};
  std::array<uint16_t, kNumLitLen> symbol{};

  /// False when the lengths over-subscribe the code space. Incomplete codes are accepted;
  /// decoding an unassigned code then fails.
  bool Build(const uint8_t* lengths, int n) {
    count.fill(0);
    for (int i = 0; i < n; ++i) ++count[lengths[i]];
    count[0] = 0;
    int left = 1;
    for (int len = 1; len <= kMaxCodeBits; ++len) {
      left = (left << 1) - count[len];
      if (left < 0) return false;
    }
    std::array<uint16_t, kMaxCodeBits + 2> offs{};
    for (int len = 1; len <= kMaxCodeBits; ++len) offs[len + 1] = offs[len] + count[len];
    std::array<uint32_t, kMaxCodeBits + 1> next_code{};
    uint32_t code = 0;
    for (int len = 1; len <= kMaxCodeBits; ++len) {
      code = (code + count[len - 1]) << 1;
      next_code[len] = code;
    }
    fast.fill(0);
    for (int sym = 0; sym < n; ++sym) {
      const int len = lengths[sym];
      if (len == 0) continue;
      symbol[offs[len]++] = uint16_t(sym);
      const uint32_t c = next_code[len]++;
      if (len <= kFastBits) {
        const uint16_t entry = uint16_t(sym | len << 9);
        for (uint32_t r = ReverseBits(c, len); r < (1u << kFastBits); r += 1u << len) fast[r] = entry;
      }
    }
    return true;
  }

  /// The next symbol, or -1 for a code that is not in the table. Needs >= 15 buffered bits.
  int Decode(BitReader& br) const {
    const uint32_t bits = br.Peek(kMaxCodeBits);
    if (const uint16_t e = fast[bits & ((1u << kFastBits) - 1)]; e != 0) {
      br.Consume(e >> 9);
      return e & 511;
    }
    int code = 0, first = 0, index = 0;
    for (int len = 1; len <= kMaxCodeBits; ++len) {
      code |= int(bits >> (len - 1)) & 1;
      const int n = count[len];
      if (code - first < n) {
        br.Consume(len);
        return symbol[index + code - first];
      }
      index += n;
      first = (first + n) << 1;
      code <<= 1;
    }
    return -1;
  }
};

const std::pair<HuffmanDecoder, HuffmanDecoder>& FixedDecoders() {
  static const auto tables = [] {
    std::pair<HuffmanDecoder, HuffmanDecoder> t;
    std::array<uint8_t, kNumLitLen> lit{};
    for (int i = 0; i < kNumLitLen; ++i) lit[i] = i < 144 ? 8 : i < 256 ? 9 : i < 280 ? 7 : 8;
    std::array<uint8_t, kNumDist> dist{};
    dist.fill(5);
    POSEFOREST_CHECK(t.first.Build(lit.data(), kNumLitLen));
    POSEFOREST_CHECK(t.second.Build(dist.data(), kNumDist));
    return t;
  }();
  return tables;
}

/// Reads the code lengths of a dynamic block into two decoders. Returns an error text or "".
std::string ReadDynamicTables(BitReader& br, HuffmanDecoder& litlen, HuffmanDecoder& dist) {
  const int hlit = int(br.Get(5)) + 257;
  const int hdist = int(br.Get(5)) + 1;
  const int hclen = int(br.Get(4)) + 4;
  if (hlit > 286 || hdist > 30) return "bad dynamic block header (too many codes)";
  std::array<uint8_t, 19> cl_lengths{};
  for (int i = 0; i < hclen; ++i) cl_lengths[kCodeLengthOrder[i]] = uint8_t(br.Get(3));
  HuffmanDecoder cl;
  if (!cl.Build(cl_lengths.data(), 19)) return "over-subscribed code-length code";
  std::array<uint8_t, 286 + 30> lengths{};
  int i = 0;
  while (i < hlit + hdist) {
    br.Refill();
    const int sym = cl.Decode(br);
    if (br.overran()) return "truncated (inside a code-length table)";
    if (sym < 0) return "invalid code-length code";
    if (sym < 16) {
      lengths[i++] = uint8_t(sym);
      continue;
    }
    int repeat = 0;
    uint8_t value = 0;
    if (sym == 16) {
      if (i == 0) return "code-length repeat with no previous length";
      value = lengths[i - 1];
      repeat = 3 + int(br.Get(2));
    } else if (sym == 17) {
      repeat = 3 + int(br.Get(3));
    } else {
      repeat = 11 + int(br.Get(7));
    }
    if (i + repeat > hlit + hdist) return "code-length repeat runs past the table";
    std::fill_n(lengths.begin() + i, repeat, value);
    i += repeat;
  }
  if (br.overran()) return "truncated (inside a code-length table)";
  if (lengths[256] == 0) return "dynamic block has no end-of-block code";
  if (!litlen.Build(lengths.data(), hlit)) return "over-subscribed literal/length code";
  if (!dist.Build(lengths.data() + hlit, hdist)) return "over-subscribed distance code";
  return "";
}

/// Decompresses a zlib stream into exactly out.size() bytes; returns an error text or "".
std::string ZlibInflate(std::span<const uint8_t> in, std::span<uint8_t> out) {
  if (in.size() < 2) return "zlib stream truncated (no header)";
  const uint8_t cmf = in[0], flg = in[1];
  if ((cmf & 15) != 8 || (cmf >> 4) > 7) return "zlib header: not deflate with a <= 32 KiB window";
  if ((uint32_t(cmf) << 8 | flg) % 31 != 0) return "zlib header check bits are wrong";
  if (flg & 0x20) return "zlib stream needs a preset dictionary";

  BitReader br(in.data() + 2, in.size() - 2);
  uint8_t* const obegin = out.data();
  uint8_t* const oend = out.data() + out.size();
  uint8_t* op = obegin;
  HuffmanDecoder dyn_litlen, dyn_dist;
  const std::string kTooMuch = "decompressed data is longer than the image needs";
  const std::string kTruncated = "compressed data truncated";

  bool final_block = false;
  while (!final_block) {
    br.Refill();
    final_block = br.Get(1) != 0;
    const uint32_t type = br.Get(2);
    if (br.overran()) return kTruncated;
    if (type == 0) {
      br.AlignAndRewind();
      if (br.overran()) return kTruncated;
      uint8_t hdr[4];
      if (!br.ReadBytes(hdr, 4)) return kTruncated;
      const uint32_t len = hdr[0] | uint32_t(hdr[1]) << 8;
      const uint32_t nlen = hdr[2] | uint32_t(hdr[3]) << 8;
      if ((len ^ 0xFFFF) != nlen) return "stored block length check failed";
      if (len > size_t(oend - op)) return kTooMuch;
      if (!br.ReadBytes(op, len)) return kTruncated;
      op += len;
      continue;
    }
    if (type == 3) return "invalid deflate block type 3";
    const HuffmanDecoder* litlen = &FixedDecoders().first;
    const HuffmanDecoder* dist = &FixedDecoders().second;
    if (type == 2) {
      if (std::string err = ReadDynamicTables(br, dyn_litlen, dyn_dist); !err.empty()) return err;
      litlen = &dyn_litlen;
      dist = &dyn_dist;
    }
    for (;;) {
      // One refill covers a literal/length code (15), its extra bits (5), a distance code (15)
      // and its extra bits (13): 48 <= 57.
      br.Refill();
      if (br.overran()) return kTruncated;
      const int sym = litlen->Decode(br);
      if (sym < 0) return "invalid literal/length code";
      if (sym < 256) {
        if (op == oend) return kTooMuch;
        *op++ = uint8_t(sym);
        continue;
      }
      if (sym == 256) break;
      const int li = sym - 257;
      if (li >= 29) return "invalid length symbol " + std::to_string(sym);
      const size_t len = kLengthBase[li] + br.Get(kLengthExtra[li]);
      const int ds = dist->Decode(br);
      if (ds < 0) return "invalid distance code";
      if (ds >= 30) return "invalid distance symbol " + std::to_string(ds);
      const size_t d = kDistBase[ds] + br.Get(kDistExtra[ds]);
      if (br.overran()) return kTruncated;
      if (d > size_t(op - obegin)) return "distance " + std::to_string(d) + " reaches before the start";
      if (len > size_t(oend - op)) return kTooMuch;
      const uint8_t* src = op - d;
      if (d >= len) {
        std::memcpy(op, src, len);
        op += len;
      } else {
        for (size_t k = 0; k < len; ++k) *op++ = src[k];
      }
    }
  }
  br.AlignAndRewind();
  if (br.overran()) return kTruncated;
  uint8_t trailer[4];
  if (!br.ReadBytes(trailer, 4)) return "zlib stream truncated (no Adler-32 checksum)";
  if (op != oend) {
    return "decompressed data too short: " + std::to_string(op - obegin) + " of " +
           std::to_string(out.size()) + " bytes";
  }
  if (ReadBe32(trailer) != Adler32(obegin, out.size())) return "Adler-32 checksum mismatch";
  return "";
}

// ---------------------------------------------------------------------------------------------
// Deflate

class BitWriter {
 public:
  explicit BitWriter(std::vector<uint8_t>& out) : out_(out) {}
  /// Appends the low n (<= 24) bits of v, LSB first.
  void Put(uint32_t v, int n) {
    buf_ |= uint64_t(v) << cnt_;
    cnt_ += n;
    if (cnt_ >= 32) {
      const uint32_t w = uint32_t(buf_);
      out_.push_back(uint8_t(w));
      out_.push_back(uint8_t(w >> 8));
      out_.push_back(uint8_t(w >> 16));
      out_.push_back(uint8_t(w >> 24));
      buf_ >>= 32;
      cnt_ -= 32;
    }
  }
  void AlignToByte() {
    while (cnt_ > 0) {
      out_.push_back(uint8_t(buf_));
      buf_ >>= 8;
      cnt_ -= 8;
    }
    buf_ = 0;
    cnt_ = 0;
  }

 private:
  std::vector<uint8_t>& out_;
  uint64_t buf_ = 0;
  int cnt_ = 0;
};

/// Optimal Huffman code lengths for `freq`, none longer than `limit` bits. Symbols with zero
/// frequency get length 0. At least two symbols always get a code, so the code is complete
/// (zlib rejects incomplete literal/length and code-length codes).
void BuildCodeLengths(const uint32_t* freq_in, int n, int limit, uint8_t* lengths) {
  std::vector<uint32_t> freq(freq_in, freq_in + n);
  int used = 0;
  for (int i = 0; i < n; ++i) used += freq[i] != 0;
  for (int i = 0; used < 2 && i < n; ++i) {
    if (freq[i] == 0) {
      freq[i] = 1;
      ++used;
    }
  }
  std::fill_n(lengths, n, uint8_t(0));
  // Two-queue Huffman construction; if the tree is too deep, flatten the frequencies and retry
  // (costs a fraction of a percent in size, and is rare).
  for (;;) {
    std::vector<std::pair<uint32_t, int>> leaves;
    for (int i = 0; i < n; ++i)
      if (freq[i]) leaves.emplace_back(freq[i], i);
    std::sort(leaves.begin(), leaves.end());
    const int m = int(leaves.size());
    std::vector<uint64_t> weight(2 * m - 1);
    std::vector<int> parent(2 * m - 1, -1);
    for (int i = 0; i < m; ++i) weight[i] = leaves[i].first;
    int leaf = 0, inner = m, next = m;
    auto take = [&]() {
      if (leaf < m && (inner >= next || weight[leaf] <= weight[inner])) return leaf++;
      return inner++;
    };
    while (next < 2 * m - 1) {
      const int a = take(), b = take();
      weight[next] = weight[a] + weight[b];
      parent[a] = parent[b] = next;
      ++next;
    }
    std::vector<int> depth(2 * m - 1, 0);
    int max_depth = 0;
    for (int i = 2 * m - 3; i >= 0; --i) {
      depth[i] = depth[parent[i]] + 1;
      if (i < m) max_depth = std::max(max_depth, depth[i]);
    }
    if (max_depth <= limit) {
      for (int i = 0; i < m; ++i) lengths[leaves[i].second] = uint8_t(depth[i]);
      return;
    }
    for (auto& f : freq)
      if (f) f = (f >> 1) | 1;
  }
}

/// Canonical codes (bit-reversed for LSB-first output) from lengths.
void CodesFromLengths(const uint8_t* lengths, int n, uint16_t* codes) {
  std::array<uint32_t, kMaxCodeBits + 2> count{}, next{};
  for (int i = 0; i < n; ++i) ++count[lengths[i]];
  count[0] = 0;
  uint32_t code = 0;
  for (int len = 1; len <= kMaxCodeBits; ++len) {
    code = (code + count[len - 1]) << 1;
    next[len] = code;
  }
  for (int i = 0; i < n; ++i)
    codes[i] = lengths[i] ? uint16_t(ReverseBits(next[lengths[i]]++, lengths[i])) : 0;
}

/// A literal (dist == 0, value in len) or a match (len 3..258, dist 1..32768).
struct Token {
  uint16_t len;
  uint16_t dist;
};

struct SymbolTables {
  std::array<uint8_t, 259> length_symbol{};  // match length -> index into kLengthBase
  std::array<uint8_t, 512> dist_small{};     // dist-1 < 512 -> distance symbol
  std::array<uint8_t, 256> dist_large{};     // (dist-1) >> 7 -> distance symbol
  SymbolTables() {
    for (int s = 0; s < 29; ++s)
      for (int l = kLengthBase[s]; l < kLengthBase[s] + (1 << kLengthExtra[s]) && l <= 258; ++l)
        length_symbol[l] = uint8_t(s);
    length_symbol[258] = 28;
    for (int s = 0; s < 30; ++s) {
      for (int d = kDistBase[s]; d < kDistBase[s] + (1 << kDistExtra[s]); ++d) {
        if (d - 1 < 512)
          dist_small[d - 1] = uint8_t(s);
        else
          dist_large[(d - 1) >> 7] = uint8_t(s);
      }
    }
  }
  int DistSymbol(int d) const { return d - 1 < 512 ? dist_small[d - 1] : dist_large[(d - 1) >> 7]; }
};

const SymbolTables& Symbols() {
  static const SymbolTables t;
  return t;
}

/// Emits one deflate block (dynamic, fixed or stored, whichever is smallest) for `tokens`,
/// which encode input bytes [raw_begin, raw_end).
void EmitBlock(BitWriter& bw, const std::vector<Token>& tokens, const uint8_t* raw_begin,
               const uint8_t* raw_end, bool final_block) {
  const SymbolTables& st = Symbols();
  std::array<uint32_t, kNumLitLen> lit_freq{};
  std::array<uint32_t, kNumDist> dist_freq{};
  for (const Token& t : tokens) {
    if (t.dist == 0) {
      ++lit_freq[t.len];
    } else {
      ++lit_freq[257 + st.length_symbol[t.len]];
      ++dist_freq[st.DistSymbol(t.dist)];
    }
  }
  lit_freq[256] = 1;

  std::array<uint8_t, kNumLitLen> lit_len{};
  std::array<uint8_t, kNumDist> dist_len{};
  BuildCodeLengths(lit_freq.data(), 286, kMaxCodeBits, lit_len.data());
  BuildCodeLengths(dist_freq.data(), kNumDist, kMaxCodeBits, dist_len.data());
  int hlit = 286, hdist = 30;
  while (hlit > 257 && lit_len[hlit - 1] == 0) --hlit;
  while (hdist > 1 && dist_len[hdist - 1] == 0) --hdist;

  // Run-length code the two length tables together (symbols 16/17/18, RFC 1951 3.2.7).
  std::array<uint8_t, 286 + 30> all{};
  std::copy_n(lit_len.begin(), hlit, all.begin());
  std::copy_n(dist_len.begin(), hdist, all.begin() + hlit);
  const int total = hlit + hdist;
  std::vector<std::pair<uint8_t, uint8_t>> rle;  // (symbol, extra bits value)
  for (int i = 0; i < total;) {
    const uint8_t v = all[i];
    int run = 1;
    while (i + run < total && all[i + run] == v) ++run;
    i += run;
    if (v == 0) {
      while (run >= 11) {
        const int r = std::min(run, 138);
        rle.emplace_back(18, uint8_t(r - 11));
        run -= r;
      }
      if (run >= 3) {
        rle.emplace_back(17, uint8_t(run - 3));
        run = 0;
      }
    } else {
      rle.emplace_back(v, 0);
      --run;
      while (run >= 3) {
        const int r = std::min(run, 6);
        rle.emplace_back(16, uint8_t(r - 3));
        run -= r;
      }
    }
    while (run-- > 0) rle.emplace_back(v, 0);
  }
  std::array<uint32_t, 19> cl_freq{};
  for (auto [s, e] : rle) ++cl_freq[s];
  std::array<uint8_t, 19> cl_len{};
  BuildCodeLengths(cl_freq.data(), 19, 7, cl_len.data());
  int hclen = 19;
  while (hclen > 4 && cl_len[kCodeLengthOrder[hclen - 1]] == 0) --hclen;

  // Sizes in bits of the three ways to code this block.
  uint64_t extra_bits = 0;
  for (int s = 0; s < 29; ++s) extra_bits += uint64_t(lit_freq[257 + s]) * kLengthExtra[s];
  for (int s = 0; s < 30; ++s) extra_bits += uint64_t(dist_freq[s]) * kDistExtra[s];
  uint64_t dyn_bits = 3 + 5 + 5 + 4 + 3 * uint64_t(hclen) + extra_bits;
  for (auto [s, e] : rle) dyn_bits += cl_len[s] + (s == 16 ? 2 : s == 17 ? 3 : s == 18 ? 7 : 0);
  uint64_t fixed_bits = 3 + extra_bits;
  for (int s = 0; s < 286; ++s) {
    dyn_bits += uint64_t(lit_freq[s]) * lit_len[s];
    fixed_bits += uint64_t(lit_freq[s]) * (s < 144 ? 8 : s < 256 ? 9 : s < 280 ? 7 : 8);
  }
  for (int s = 0; s < 30; ++s) {
    dyn_bits += uint64_t(dist_freq[s]) * dist_len[s];
    fixed_bits += uint64_t(dist_freq[s]) * 5;
  }
  const size_t raw_size = size_t(raw_end - raw_begin);
  const uint64_t stored_bits = (raw_size + 5 * std::max<size_t>(1, (raw_size + 65534) / 65535)) * 8 + 7;

  if (stored_bits <= dyn_bits && stored_bits <= fixed_bits) {
    size_t done = 0;
    do {
      const size_t n = std::min<size_t>(raw_size - done, 65535);
      const bool last = final_block && done + n == raw_size;
      bw.Put(last ? 1 : 0, 3);
      bw.AlignToByte();
      bw.Put(uint32_t(n), 16);
      bw.Put(uint32_t(n) ^ 0xFFFF, 16);
      for (size_t k = 0; k < n; ++k) bw.Put(raw_begin[done + k], 8);
      done += n;
    } while (done < raw_size);
    return;
  }

  std::array<uint16_t, kNumLitLen> lit_code{};
  std::array<uint16_t, kNumDist> dist_code{};
  if (fixed_bits < dyn_bits) {
    for (int s = 0; s < kNumLitLen; ++s) lit_len[s] = s < 144 ? 8 : s < 256 ? 9 : s < 280 ? 7 : 8;
    dist_len.fill(5);
    bw.Put(final_block ? 1 : 0, 1);
    bw.Put(1, 2);
  } else {
    bw.Put(final_block ? 1 : 0, 1);
    bw.Put(2, 2);
    bw.Put(uint32_t(hlit - 257), 5);
    bw.Put(uint32_t(hdist - 1), 5);
    bw.Put(uint32_t(hclen - 4), 4);
    for (int i = 0; i < hclen; ++i) bw.Put(cl_len[kCodeLengthOrder[i]], 3);
    std::array<uint16_t, 19> cl_code{};
    CodesFromLengths(cl_len.data(), 19, cl_code.data());
    for (auto [s, e] : rle) {
      bw.Put(cl_code[s], cl_len[s]);
      if (s == 16) bw.Put(e, 2);
      if (s == 17) bw.Put(e, 3);
      if (s == 18) bw.Put(e, 7);
    }
  }
  CodesFromLengths(lit_len.data(), kNumLitLen, lit_code.data());
  CodesFromLengths(dist_len.data(), kNumDist, dist_code.data());
  for (const Token& t : tokens) {
    if (t.dist == 0) {
      bw.Put(lit_code[t.len], lit_len[t.len]);
      continue;
    }
    const int ls = st.length_symbol[t.len];
    bw.Put(lit_code[257 + ls], lit_len[257 + ls]);
    bw.Put(uint32_t(t.len - kLengthBase[ls]), kLengthExtra[ls]);
    const int ds = st.DistSymbol(t.dist);
    bw.Put(dist_code[ds], dist_len[ds]);
    bw.Put(uint32_t(t.dist - kDistBase[ds]), kDistExtra[ds]);
  }
  bw.Put(lit_code[256], lit_len[256]);
}

/// Length of the common prefix of a and b, at most `limit`.
inline size_t MatchLength(const uint8_t* a, const uint8_t* b, size_t limit) {
  size_t n = 0;
  if constexpr (std::endian::native == std::endian::little) {
    while (n + 8 <= limit) {
      uint64_t x, y;
      std::memcpy(&x, a + n, 8);
      std::memcpy(&y, b + n, 8);
      if (const uint64_t diff = x ^ y; diff != 0) return n + size_t(std::countr_zero(diff) >> 3);
      n += 8;
    }
  }
  while (n < limit && a[n] == b[n]) ++n;
  return n;
}

/// zlib stream of `data`: LZ77 over a hash chain (greedy with one-step lazy evaluation),
/// then per block the smallest of dynamic Huffman, fixed Huffman or stored.
std::vector<uint8_t> ZlibDeflate(const uint8_t* data, size_t size) {
  constexpr int kHashBits = 16;
  constexpr size_t kWindowMask = 32767;
  // zlib's MAX_DIST: keeps candidates safely inside the 32 KiB window.
  constexpr size_t kMaxDistance = 32768 - 262;
  constexpr size_t kMinMatch = 3, kMaxMatch = 258;
  constexpr int kMaxChain = 8;
  constexpr size_t kNiceLength = 128;  // stop searching once a match is this long
  constexpr size_t kLazyLimit = 32;    // do not try a lazy match after one this long
  constexpr size_t kBlockTokens = 1 << 16;

  std::vector<uint8_t> out;
  out.reserve(size / 4 + 64);
  out.push_back(0x78);  // deflate, 32 KiB window
  out.push_back(0x9C);  // default level; (0x789C % 31 == 0)
  BitWriter bw(out);

  // Positions as uint32 (the encoder caps the image at 2^31 + 32 Ki bytes); kNone sorts above
  // every position, so the `nxt >= cand` test below also ends the chain there.
  constexpr uint32_t kNone = 0xFFFFFFFFu;
  POSEFOREST_CHECK(size < kNone);
  std::vector<uint32_t> head(size_t(1) << kHashBits, kNone);
  std::vector<uint32_t> prev(kWindowMask + 1, kNone);
  auto hash = [&](size_t p) {
    const uint32_t v = uint32_t(data[p]) | uint32_t(data[p + 1]) << 8 | uint32_t(data[p + 2]) << 16;
    return (v * 2654435761u) >> (32 - kHashBits);
  };
  auto insert = [&](size_t p) {
    const uint32_t h = hash(p);
    prev[p & kWindowMask] = head[h];
    head[h] = uint32_t(p);
  };
  // Longest match for position p among earlier positions (p itself not yet inserted).
  auto find = [&](size_t p, size_t& best_dist) -> size_t {
    const size_t limit = std::min(kMaxMatch, size - p);
    if (limit < kMinMatch) return 0;
    size_t best = kMinMatch - 1;
    uint32_t cand = head[hash(p)];
    for (int chain = kMaxChain; cand != kNone && chain > 0; --chain) {
      const size_t c = size_t(cand);
      if (p - c > kMaxDistance) break;
      if (data[c + best] == data[p + best] && data[c] == data[p]) {
        const size_t len = MatchLength(data + c, data + p, limit);
        if (len > best) {
          best = len;
          best_dist = p - c;
          if (len >= std::min(kNiceLength, limit)) break;
        }
      }
      const uint32_t nxt = prev[c & kWindowMask];
      if (nxt >= cand) break;
      cand = nxt;
    }
    return best >= kMinMatch ? best : 0;
  };

  std::vector<Token> tokens;
  tokens.reserve(kBlockTokens + 2);
  size_t block_start = 0;
  size_t p = 0;
  size_t pending_len = 0, pending_dist = 0;  // match found at p, not yet emitted
  bool have_pending = false;
  while (p < size) {
    size_t len = 0, dist = 0;
    if (have_pending) {
      len = pending_len;
      dist = pending_dist;
      have_pending = false;
    } else {
      len = find(p, dist);
    }
    if (len > 0 && len < kLazyLimit && p + 1 + kMinMatch <= size) {
      if (p + kMinMatch <= size) insert(p);
      size_t dist2 = 0;
      const size_t len2 = find(p + 1, dist2);
      if (len2 > len) {
        tokens.push_back({data[p], 0});
        ++p;
        pending_len = len2;
        pending_dist = dist2;
        have_pending = true;
      } else {
        tokens.push_back({uint16_t(len), uint16_t(dist)});
        for (size_t k = 1; k < len; ++k)
          if (p + k + kMinMatch <= size) insert(p + k);
        p += len;
      }
    } else if (len > 0) {
      tokens.push_back({uint16_t(len), uint16_t(dist)});
      for (size_t k = 0; k < len; ++k)
        if (p + k + kMinMatch <= size) insert(p + k);
      p += len;
    } else {
      tokens.push_back({data[p], 0});
      if (p + kMinMatch <= size) insert(p);
      ++p;
    }
    if (tokens.size() >= kBlockTokens && !have_pending && p < size) {
      EmitBlock(bw, tokens, data + block_start, data + p, false);
      tokens.clear();
      block_start = p;
    }
  }
  EmitBlock(bw, tokens, data + block_start, data + size, true);
  bw.AlignToByte();
  PutBe32(out, Adler32(data, size));
  return out;
}

// ---------------------------------------------------------------------------------------------
// PNG filters

inline uint8_t Paeth(uint8_t a, uint8_t b, uint8_t c) {
  const int pa = std::abs(int(b) - int(c));
  const int pb = std::abs(int(a) - int(c));
  const int pc = std::abs(int(a) + int(b) - 2 * int(c));
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

/// Reverses the filter of one row in place. `prior` is the previous reconstructed row (zeros
/// for the first). Returns false for an unknown filter type.
bool Unfilter(uint8_t type, uint8_t* row, const uint8_t* prior, size_t n, size_t bpp) {
  switch (type) {
    case 0:
      return true;
    case 1:
      for (size_t i = bpp; i < n; ++i) row[i] = uint8_t(row[i] + row[i - bpp]);
      return true;
    case 2:
      for (size_t i = 0; i < n; ++i) row[i] = uint8_t(row[i] + prior[i]);
      return true;
    case 3:
      for (size_t i = 0; i < n; ++i) {
        const int left = i >= bpp ? row[i - bpp] : 0;
        row[i] = uint8_t(row[i] + ((left + prior[i]) >> 1));
      }
      return true;
    case 4:
      for (size_t i = 0; i < bpp && i < n; ++i) row[i] = uint8_t(row[i] + prior[i]);
      for (size_t i = bpp; i < n; ++i)
        row[i] = uint8_t(row[i] + Paeth(row[i - bpp], prior[i], prior[i - bpp]));
      return true;
    default:
      return false;
  }
}

/// Filtered scanlines (one filter byte + row per line), choosing per row the filter with the
/// smallest sum of |signed residual| (the heuristic of the PNG spec, section 12.8). Each filter
/// is a separate branch-free loop so the compiler can vectorize it.
std::vector<uint8_t> FilterRows(const uint8_t* raw, int height, size_t rowbytes, size_t bpp) {
  std::vector<uint8_t> out(size_t(height) * (rowbytes + 1));
  std::vector<uint8_t> zero(rowbytes, 0);
  std::array<std::vector<uint8_t>, 5> cand;
  for (auto& c : cand) c.resize(rowbytes);
  auto cost_of = [rowbytes](const uint8_t* r) {
    uint32_t s = 0;
    for (size_t i = 0; i < rowbytes; ++i) {
      const int v = int8_t(r[i]);
      s += uint32_t(v < 0 ? -v : v);
    }
    return s;
  };
  for (int y = 0; y < height; ++y) {
    const uint8_t* cur = raw + size_t(y) * rowbytes;
    const uint8_t* up = y > 0 ? cur - rowbytes : zero.data();
    const size_t head = std::min(bpp, rowbytes);
    uint8_t* r1 = cand[1].data();
    uint8_t* r2 = cand[2].data();
    uint8_t* r3 = cand[3].data();
    uint8_t* r4 = cand[4].data();
    for (size_t i = 0; i < head; ++i) {
      r1[i] = cur[i];
      r2[i] = uint8_t(cur[i] - up[i]);
      r3[i] = uint8_t(cur[i] - (up[i] >> 1));
      r4[i] = uint8_t(cur[i] - up[i]);  // Paeth(0, b, 0) = b
    }
    for (size_t i = head; i < rowbytes; ++i) r1[i] = uint8_t(cur[i] - cur[i - bpp]);
    for (size_t i = head; i < rowbytes; ++i) r2[i] = uint8_t(cur[i] - up[i]);
    for (size_t i = head; i < rowbytes; ++i)
      r3[i] = uint8_t(cur[i] - ((int(cur[i - bpp]) + int(up[i])) >> 1));
    for (size_t i = head; i < rowbytes; ++i) {
      const int a = cur[i - bpp], b = up[i], c = up[i - bpp];
      const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
      const int pred = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
      r4[i] = uint8_t(cur[i] - pred);
    }
    std::array<uint32_t, 5> cost = {cost_of(cur), cost_of(r1), cost_of(r2), cost_of(r3), cost_of(r4)};
    const int best = int(std::min_element(cost.begin(), cost.end()) - cost.begin());
    uint8_t* dst = out.data() + size_t(y) * (rowbytes + 1);
    dst[0] = uint8_t(best);
    std::memcpy(dst + 1, best == 0 ? cur : cand[best].data(), rowbytes);
  }
  return out;
}

void PutChunk(std::vector<uint8_t>& png, const char* type, const uint8_t* data, size_t size) {
  PutBe32(png, uint32_t(size));
  const size_t start = png.size();
  png.insert(png.end(), type, type + 4);
  png.insert(png.end(), data, data + size);
  PutBe32(png, core::Crc32(png.data() + start, size + 4));
}

std::vector<uint8_t> EncodePngBytes(int width, int height, int channels, int bit_depth,
                                    const uint8_t* raw_be) {
  static constexpr uint8_t kColourType[5] = {0, 0, 4, 2, 6};
  const size_t bpp = size_t(channels) * size_t(bit_depth / 8);
  const size_t rowbytes = size_t(width) * bpp;
  const std::vector<uint8_t> filtered = FilterRows(raw_be, height, rowbytes, bpp);
  const std::vector<uint8_t> z = ZlibDeflate(filtered.data(), filtered.size());

  std::vector<uint8_t> png(kPngSignature.begin(), kPngSignature.end());
  png.reserve(z.size() + 64 + 12 * (z.size() / kIdatChunkSize));
  std::vector<uint8_t> ihdr;
  PutBe32(ihdr, uint32_t(width));
  PutBe32(ihdr, uint32_t(height));
  ihdr.push_back(uint8_t(bit_depth));
  ihdr.push_back(kColourType[channels]);
  ihdr.push_back(0);  // compression: deflate
  ihdr.push_back(0);  // filter method 0
  ihdr.push_back(0);  // not interlaced
  PutChunk(png, "IHDR", ihdr.data(), ihdr.size());
  for (size_t off = 0; off < z.size(); off += kIdatChunkSize)
    PutChunk(png, "IDAT", z.data() + off, std::min(kIdatChunkSize, z.size() - off));
  PutChunk(png, "IEND", nullptr, 0);
  return png;
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

// ---------------------------------------------------------------------------------------------
// Files

Status DataLoss(const std::string& source, const std::string& what) {
  return Status(ErrorCode::kDataLoss, source + ": " + what);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Public API

Result<PngImage> DecodePng(std::span<const uint8_t> bytes, const std::string& source) {
  if (bytes.size() < kPngSignature.size() ||
      !std::equal(kPngSignature.begin(), kPngSignature.end(), bytes.begin()))
    return DataLoss(source, "not a PNG file (bad signature)");

  uint32_t width = 0, height = 0;
  int bit_depth = 0, colour_type = -1;
  std::vector<uint8_t> palette;  // RGB triples
  std::vector<uint8_t> palette_alpha;
  std::vector<uint8_t> idat;
  bool seen_ihdr = false, seen_iend = false, seen_plte = false, idat_done = false;
  size_t pos = kPngSignature.size();
  while (!seen_iend) {
    if (bytes.size() - pos < 12) {
      return DataLoss(source, "truncated at byte " + std::to_string(pos) +
                                  (seen_ihdr ? " (no IEND chunk)" : " (no IHDR chunk)"));
    }
    const uint32_t length = ReadBe32(&bytes[pos]);
    const std::string type(reinterpret_cast<const char*>(&bytes[pos + 4]), 4);
    for (char ch : type) {
      if (!((ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z')))
        return DataLoss(source, "invalid chunk type at byte " + std::to_string(pos));
    }
    if (length > 0x7FFFFFFFu) return DataLoss(source, "chunk " + type + " has an invalid length");
    if (bytes.size() - pos - 12 < length) {
      return DataLoss(source, "truncated: chunk " + type + " at byte " + std::to_string(pos) + " needs " +
                                  std::to_string(length + 12) + " bytes, " +
                                  std::to_string(bytes.size() - pos) + " left");
    }
    const uint8_t* data = &bytes[pos + 8];
    const uint32_t stored_crc = ReadBe32(data + length);
    if (core::Crc32(&bytes[pos + 4], length + 4) != stored_crc)
      return DataLoss(source, "CRC mismatch in chunk " + type + " at byte " + std::to_string(pos));
    pos += 12 + size_t(length);

    if (!seen_ihdr && type != "IHDR") return DataLoss(source, "first chunk is " + type + ", not IHDR");
    if (type == "IHDR") {
      if (seen_ihdr) return DataLoss(source, "more than one IHDR chunk");
      if (length != 13) return DataLoss(source, "IHDR has length " + std::to_string(length) + ", not 13");
      seen_ihdr = true;
      width = ReadBe32(data);
      height = ReadBe32(data + 4);
      bit_depth = data[8];
      colour_type = data[9];
      if (width == 0 || height == 0) return DataLoss(source, "image has zero width or height");
      if (width > kMaxDimension || height > kMaxDimension || uint64_t(width) * height > kMaxPixels) {
        return Status(ErrorCode::kInvalidArgument, source + ": image " + std::to_string(width) + "x" +
                                                       std::to_string(height) +
                                                       " is too large (limits: 32768 per side, 2^28 pixels)");
      }
      bool combo_ok = false;
      switch (colour_type) {
        case 0:
          combo_ok = bit_depth == 1 || bit_depth == 2 || bit_depth == 4 || bit_depth == 8 || bit_depth == 16;
          break;
        case 3:
          combo_ok = bit_depth == 1 || bit_depth == 2 || bit_depth == 4 || bit_depth == 8;
          break;
        case 2:
        case 4:
        case 6:
          combo_ok = bit_depth == 8 || bit_depth == 16;
          break;
        default:
          return DataLoss(source, "invalid colour type " + std::to_string(colour_type));
      }
      if (!combo_ok) {
        return DataLoss(source, "invalid bit depth " + std::to_string(bit_depth) + " for colour type " +
                                    std::to_string(colour_type));
      }
      if (data[10] != 0) return DataLoss(source, "unknown compression method " + std::to_string(data[10]));
      if (data[11] != 0) return DataLoss(source, "unknown filter method " + std::to_string(data[11]));
      if (data[12] == 1) {
        return Status(ErrorCode::kUnimplemented,
                      source + ": interlaced (Adam7) PNG is not supported; re-save it non-interlaced");
      }
      if (data[12] != 0) return DataLoss(source, "unknown interlace method " + std::to_string(data[12]));
    } else if (type == "PLTE") {
      if (seen_plte) return DataLoss(source, "more than one PLTE chunk");
      if (!idat.empty()) return DataLoss(source, "PLTE after IDAT");
      if (colour_type == 0 || colour_type == 4) return DataLoss(source, "PLTE in a greyscale image");
      if (length == 0 || length % 3 != 0 || length > 768)
        return DataLoss(source,
                        "PLTE length " + std::to_string(length) + " is not 3..768 and a multiple of 3");
      seen_plte = true;
      palette.assign(data, data + length);
    } else if (type == "tRNS") {
      if (colour_type == 3) {
        if (!seen_plte) return DataLoss(source, "tRNS before PLTE");
        if (length > palette.size() / 3) return DataLoss(source, "tRNS has more entries than PLTE");
        palette_alpha.assign(data, data + length);
      }
      // A colour key for grey/RGB images is not applied: our images carry no transparency.
    } else if (type == "IDAT") {
      if (idat_done) return DataLoss(source, "IDAT chunks are not consecutive");
      idat.insert(idat.end(), data, data + length);
    } else if (type == "IEND") {
      seen_iend = true;
    } else if (type[0] >= 'A' && type[0] <= 'Z') {
      return DataLoss(source, "unknown critical chunk " + type);
    }
    if (type != "IDAT" && !idat.empty()) idat_done = true;
  }
  if (colour_type == 3 && !seen_plte) return DataLoss(source, "palette image without PLTE");
  if (idat.empty()) return DataLoss(source, "no IDAT chunk");

  const int channels_in = colour_type == 0   ? 1
                          : colour_type == 2 ? 3
                          : colour_type == 3 ? 1
                          : colour_type == 4 ? 2
                                             : 4;
  const size_t bits_per_pixel = size_t(channels_in) * size_t(bit_depth);
  const size_t rowbytes = (size_t(width) * bits_per_pixel + 7) / 8;
  const size_t bpp = std::max<size_t>(1, bits_per_pixel / 8);
  const uint64_t expected = uint64_t(height) * (rowbytes + 1);
  if (expected > uint64_t(idat.size()) * kMaxDeflateRatio + 64) {
    return DataLoss(source, "IDAT data (" + std::to_string(idat.size()) + " bytes) is far too short for a " +
                                std::to_string(width) + "x" + std::to_string(height) + " image");
  }
  std::vector<uint8_t> raw(expected);
  if (std::string err = ZlibInflate(idat, raw); !err.empty()) return DataLoss(source, "IDAT: " + err);

  std::vector<uint8_t> zero(rowbytes, 0);
  for (uint32_t y = 0; y < height; ++y) {
    uint8_t* line = raw.data() + size_t(y) * (rowbytes + 1);
    const uint8_t* prior = y > 0 ? line - rowbytes : zero.data();
    if (!Unfilter(line[0], line + 1, prior, rowbytes, bpp))
      return DataLoss(source,
                      "row " + std::to_string(y) + " has unknown filter type " + std::to_string(line[0]));
  }

  PngImage img;
  img.width = int(width);
  img.height = int(height);
  const size_t pixels = size_t(width) * height;
  if (colour_type == 3) {
    img.channels = palette_alpha.empty() ? 3 : 4;
    img.bit_depth = 8;
    img.samples8.resize(pixels * size_t(img.channels));
    const size_t entries = palette.size() / 3;
    uint8_t* dst = img.samples8.data();
    const unsigned mask = (1u << bit_depth) - 1;
    for (uint32_t y = 0; y < height; ++y) {
      const uint8_t* row = raw.data() + size_t(y) * (rowbytes + 1) + 1;
      for (uint32_t x = 0; x < width; ++x) {
        const size_t bit = size_t(x) * size_t(bit_depth);
        const unsigned idx = (row[bit >> 3] >> (8 - bit_depth - (bit & 7))) & mask;
        if (idx >= entries) {
          return DataLoss(source, "palette index " + std::to_string(idx) + " at (" + std::to_string(x) + "," +
                                      std::to_string(y) + ") is beyond the " + std::to_string(entries) +
                                      "-entry palette");
        }
        *dst++ = palette[3 * idx];
        *dst++ = palette[3 * idx + 1];
        *dst++ = palette[3 * idx + 2];
        if (img.channels == 4) *dst++ = idx < palette_alpha.size() ? palette_alpha[idx] : 255;
      }
    }
    return img;
  }
  img.channels = channels_in;
  const size_t samples_per_row = size_t(width) * size_t(channels_in);
  if (bit_depth == 16) {
    img.bit_depth = 16;
    img.samples16.resize(pixels * size_t(channels_in));
    for (uint32_t y = 0; y < height; ++y) {
      const uint8_t* row = raw.data() + size_t(y) * (rowbytes + 1) + 1;
      uint16_t* dst = img.samples16.data() + size_t(y) * samples_per_row;
      for (size_t i = 0; i < samples_per_row; ++i) dst[i] = uint16_t(row[2 * i] << 8 | row[2 * i + 1]);
    }
    return img;
  }
  img.bit_depth = 8;
  img.samples8.resize(pixels * size_t(channels_in));
  for (uint32_t y = 0; y < height; ++y) {
    const uint8_t* row = raw.data() + size_t(y) * (rowbytes + 1) + 1;
    uint8_t* dst = img.samples8.data() + size_t(y) * samples_per_row;
    if (bit_depth == 8) {
      std::memcpy(dst, row, samples_per_row);
      continue;
    }
    // 1/2/4-bit grey: scale to 0..255 like libpng's expand (1 -> 255 for 1-bit).
    const unsigned mask = (1u << bit_depth) - 1;
    const unsigned scale = 255 / mask;
    for (uint32_t x = 0; x < width; ++x) {
      const size_t bit = size_t(x) * size_t(bit_depth);
      dst[x] = uint8_t(((row[bit >> 3] >> (8 - bit_depth - (bit & 7))) & mask) * scale);
    }
  }
  return img;
}

std::vector<uint8_t> EncodePng8(int width, int height, int channels, std::span<const uint8_t> samples) {
  CheckEncodeArgs(width, height, channels, samples.size());
  return EncodePngBytes(width, height, channels, 8, samples.data());
}

std::vector<uint8_t> EncodePng16(int width, int height, int channels, std::span<const uint16_t> samples) {
  CheckEncodeArgs(width, height, channels, samples.size());
  std::vector<uint8_t> be(samples.size() * 2);
  for (size_t i = 0; i < samples.size(); ++i) {
    be[2 * i] = uint8_t(samples[i] >> 8);
    be[2 * i + 1] = uint8_t(samples[i]);
  }
  return EncodePngBytes(width, height, channels, 16, be.data());
}

Result<core::DepthImage> ReadDepthImage(const std::string& path, int raw_width, int raw_height) {
  auto bytes = core::ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  const std::vector<uint8_t>& b = *bytes;
  if (b.size() >= kPngSignature.size() && std::equal(kPngSignature.begin(), kPngSignature.end(), b.begin())) {
    auto png = DecodePng(b, path);
    if (!png.ok()) return png.status();
    if (png->channels != 1 || png->bit_depth != 16) {
      return Status(ErrorCode::kInvalidArgument,
                    path + ": a depth image must be a 16-bit greyscale PNG in millimetres; this one has " +
                        std::to_string(png->channels) + " channel(s) of " + std::to_string(png->bit_depth) +
                        "-bit samples");
    }
    core::DepthImage depth;
    depth.width = png->width;
    depth.height = png->height;
    depth.pixels = std::move(png->samples16);
    return depth;
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
