// PNG codec and depth-file tests. Independent checks use Python 3's zlib (the reference zlib):
// it writes PNGs with every colour type / bit depth / compression level for our decoder, and
// verifies the PNGs our encoder writes. python3 is required: if it is missing the tests fail.

#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "runtime/core/crc32.h"
#include "runtime/image_io.h"
#include "tests/support/paths.h"

namespace fs = std::filesystem;
using poseforest::core::ErrorCode;
using namespace poseforest::runtime;

namespace {

std::vector<uint8_t> ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void WriteBytes(const fs::path& p, const std::vector<uint8_t>& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
  REQUIRE(out.good());
}

void WriteText(const fs::path& p, const std::string& s) {
  std::ofstream out(p);
  out << s;
  REQUIRE(out.good());
}

/// Runs python3 with a script and arguments; returns the exit status (non-zero if python3 is
/// missing, so the calling test fails instead of skipping).
int RunPython(const fs::path& script, const std::string& args) {
  const std::string cmd = "python3 '" + script.string() + "' " + args;
  const int rc = std::system(cmd.c_str());
  return rc;
}

/// Random samples with local structure (a gradient plus noise, some flat runs), so that the
/// filters and LZ77 matches are exercised, not only literals.
template <typename T>
std::vector<T> StructuredImage(int w, int h, int c, uint32_t seed, uint32_t max_value) {
  std::mt19937 rng(seed);
  std::vector<T> v(size_t(w) * h * c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) {
        uint32_t s = uint32_t(x * (k + 1) * 3 + y * 5 + k * 40) + rng() % 4;
        if ((x / 16 + y / 8) % 3 == 0) s = max_value / 2;  // flat regions
        v[(size_t(y) * w + x) * c + k] = T(s % (max_value + 1));
      }
  return v;
}

template <typename T>
std::vector<T> RandomImage(int w, int h, int c, uint32_t seed, uint32_t max_value) {
  std::mt19937 rng(seed);
  std::vector<T> v(size_t(w) * h * c);
  for (auto& s : v) s = T(rng() % (max_value + 1));
  return v;
}

struct Chunk {
  std::string type;
  std::vector<uint8_t> data;
};

uint32_t Be32(const uint8_t* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | uint32_t(p[3]);
}
void PutBe32(std::vector<uint8_t>& o, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) o.push_back(uint8_t(v >> s));
}

/// Splits a well-formed PNG into chunks (test helper; assumes valid input).
std::vector<Chunk> Chunks(const std::vector<uint8_t>& png) {
  std::vector<Chunk> out;
  size_t pos = 8;
  while (pos + 12 <= png.size()) {
    const uint32_t len = Be32(&png[pos]);
    Chunk c;
    c.type.assign(reinterpret_cast<const char*>(&png[pos + 4]), 4);
    c.data.assign(png.begin() + long(pos) + 8, png.begin() + long(pos) + 8 + len);
    out.push_back(std::move(c));
    pos += 12 + len;
  }
  return out;
}

/// Builds a PNG with correct CRCs from chunks.
std::vector<uint8_t> Assemble(const std::vector<Chunk>& chunks) {
  std::vector<uint8_t> o = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  for (const auto& c : chunks) {
    PutBe32(o, uint32_t(c.data.size()));
    const size_t start = o.size();
    o.insert(o.end(), c.type.begin(), c.type.end());
    o.insert(o.end(), c.data.begin(), c.data.end());
    PutBe32(o, poseforest::core::Crc32(&o[start], c.data.size() + 4));
  }
  return o;
}

/// The zlib stream of a PNG (all IDAT data).
std::vector<uint8_t> ZlibStream(const std::vector<uint8_t>& png) {
  std::vector<uint8_t> z;
  for (const auto& c : Chunks(png))
    if (c.type == "IDAT") z.insert(z.end(), c.data.begin(), c.data.end());
  return z;
}

/// `png` with its IDAT data replaced by `z` (one chunk, valid CRC), so that the inflater, not
/// the chunk CRC, must catch whatever is wrong with `z`.
std::vector<uint8_t> WithZlibStream(const std::vector<uint8_t>& png, const std::vector<uint8_t>& z) {
  std::vector<Chunk> out;
  bool placed = false;
  for (auto& c : Chunks(png)) {
    if (c.type == "IDAT") {
      if (!placed) out.push_back({"IDAT", z});
      placed = true;
    } else {
      out.push_back(c);
    }
  }
  return Assemble(out);
}

std::vector<uint8_t> Ihdr(uint32_t w, uint32_t h, uint8_t depth, uint8_t colour, uint8_t interlace = 0) {
  std::vector<uint8_t> d;
  PutBe32(d, w);
  PutBe32(d, h);
  d.insert(d.end(), {depth, colour, 0, 0, interlace});
  return d;
}

// Writes PNG fixtures with Python's zlib, plus the samples a decoder must produce (8-bit as
// bytes, 16-bit as little-endian uint16), and a manifest "name width height channels depth".
constexpr const char* kPythonWriter = R"PY(
import os, random, struct, sys, zlib
out = sys.argv[1]
rng = random.Random(20110620)
manifest = []

def chunk(t, d):
    return struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d) & 0xffffffff)

def paeth(a, b, c):
    p = a + b - c; pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)

def filt(rows, bpp, mode):
    res = bytearray(); prev = bytes(len(rows[0]))
    for r in rows:
        ft = rng.randrange(5) if mode is None else mode
        o = bytearray(len(r))
        for i in range(len(r)):
            a = r[i - bpp] if i >= bpp else 0; b = prev[i]; c = prev[i - bpp] if i >= bpp else 0
            pred = [0, a, b, (a + b) >> 1, paeth(a, b, c)][ft]
            o[i] = (r[i] - pred) & 255
        res.append(ft); res += o; prev = r
    return bytes(res)

def pack(vals, depth):
    if depth == 8: return bytes(vals)
    if depth == 16: return b''.join(struct.pack('>H', v) for v in vals)
    bits = ''.join(format(v, '0%db' % depth) for v in vals)
    bits += '0' * (-len(bits) % 8)
    return bytes(int(bits[i:i + 8], 2) for i in range(0, len(bits), 8))

def write(name, w, h, ctype, depth, rows_vals, expected, ch, exp_depth, level=6, strategy=None,
          plte=None, trns=None, split=None, extra=False, fmode=None):
    chans = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[ctype]
    bpp = max(1, chans * depth // 8)
    rows = [pack(r, depth) for r in rows_vals]
    raw = filt(rows, bpp, fmode)
    if strategy is None:
        z = zlib.compress(raw, level)
    else:
        co = zlib.compressobj(level, zlib.DEFLATED, 15, 8, strategy)
        z = co.compress(raw) + co.flush()
    png = b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, depth, ctype, 0, 0, 0))
    if extra: png += chunk(b'tEXt', b'Comment\x00written by test_image_io')
    if plte is not None: png += chunk(b'PLTE', bytes(sum(plte, [])))
    if trns is not None: png += chunk(b'tRNS', bytes(trns))
    pieces = [z] if split is None else [z[i:i + split] for i in range(0, len(z), split)]
    for p in pieces: png += chunk(b'IDAT', p)
    if extra: png += chunk(b'tIME', bytes([7, 219, 6, 20, 12, 0, 0]))
    png += chunk(b'IEND', b'')
    open(os.path.join(out, name + '.png'), 'wb').write(png)
    if exp_depth == 16: e = b''.join(struct.pack('<H', v) for v in expected)
    else: e = bytes(expected)
    open(os.path.join(out, name + '.raw'), 'wb').write(e)
    manifest.append('%s %d %d %d %d' % (name, w, h, ch, exp_depth))

def smooth(w, h, chans, maxv):
    return [[min(maxv, (x * 7 + y * 3 + k * 50 + rng.randrange(3)) % (maxv + 1)) for x in range(w) for k in range(chans)] for y in range(h)]

def flat(rows): return [v for r in rows for v in r]

# Compression levels 0 (stored), 1, 6, 9 and the fixed / Huffman-only / RLE strategies.
img = smooth(37, 23, 3, 255)
for lvl in (0, 1, 6, 9):
    write('rgb8_level%d' % lvl, 37, 23, 2, 8, img, flat(img), 3, 8, level=lvl)
for sname, s in (('fixed', zlib.Z_FIXED), ('huffman', zlib.Z_HUFFMAN_ONLY), ('rle', zlib.Z_RLE)):
    write('rgb8_' + sname, 37, 23, 2, 8, img, flat(img), 3, 8, strategy=s)
# Each filter type on its own.
for f in range(5):
    write('rgb8_filter%d' % f, 37, 23, 2, 8, img, flat(img), 3, 8, fmode=f)
# Large enough for several deflate blocks, in 1000-byte IDAT chunks, with ancillary chunks.
big = [[rng.randrange(256) if rng.random() < 0.3 else (x + y) & 255 for x in range(300 * 3)] for y in range(200)]
write('rgb8_big_split', 300, 200, 2, 8, big, flat(big), 3, 8, level=9, split=1000, extra=True)
t = smooth(5, 4, 3, 255)
write('rgb8_tiny_idats', 5, 4, 2, 8, t, flat(t), 3, 8, split=1)
# Greyscale 1/2/4/8/16, odd widths so sub-byte rows end mid-byte.
for depth in (1, 2, 4, 8, 16):
    for w in (1, 13):
        maxv = (1 << depth) - 1
        vals = [[rng.randrange(maxv + 1) for _ in range(w)] for _ in range(9)]
        if depth < 8: exp = [v * (255 // maxv) for v in flat(vals)]
        else: exp = flat(vals)
        write('grey%d_w%d' % (depth, w), w, 9, 0, depth, vals, exp, 1, 16 if depth == 16 else 8)
# Grey+alpha, RGB, RGBA at 8 and 16 bits.
for ctype, chans in ((4, 2), (2, 3), (6, 4)):
    for depth in (8, 16):
        vals = smooth(11, 6, chans, (1 << depth) - 1)
        write('c%d_%d' % (ctype, depth), 11, 6, ctype, depth, vals, flat(vals), chans, depth, level=rng.choice([1, 6, 9]))
# Palette images at 1/2/4/8 bits, with and without tRNS (shorter than the palette).
for depth in (1, 2, 4, 8):
    n = min(1 << depth, 200)
    pal = [[rng.randrange(256) for _ in range(3)] for _ in range(n)]
    idx = [[rng.randrange(n) for _ in range(7)] for _ in range(5)]
    rgb = [c for i in flat(idx) for c in pal[i]]
    write('pal%d' % depth, 7, 5, 3, depth, idx, rgb, 3, 8, plte=pal)
    alpha = [rng.randrange(256) for _ in range(max(1, n // 2))]
    rgba = [c for i in flat(idx) for c in pal[i] + [alpha[i] if i < len(alpha) else 255]]
    write('pal%d_trns' % depth, 7, 5, 3, depth, idx, rgba, 4, 8, plte=pal, trns=alpha)
open(os.path.join(out, 'manifest.txt'), 'w').write('\n'.join(manifest) + '\n')
# An interlaced image (refused by design).
png = b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', 4, 4, 8, 0, 0, 0, 1))
png += chunk(b'IDAT', zlib.compress(bytes(40))) + chunk(b'IEND', b'')
open(os.path.join(out, 'interlaced.png'), 'wb').write(png)
)PY";

}  // namespace

TEST_CASE("PNG round trip: all channel counts, 8 and 16 bits, odd sizes", "[image_io][png]") {
  const std::vector<std::pair<int, int>> sizes = {{1, 1}, {3, 7}, {640, 480}};
  uint32_t seed = 1;
  for (auto [w, h] : sizes) {
    for (int c = 1; c <= 4; ++c) {
      for (bool structured : {false, true}) {
        CAPTURE(w, h, c, structured);
        auto s8 = structured ? StructuredImage<uint8_t>(w, h, c, seed++, 255)
                             : RandomImage<uint8_t>(w, h, c, seed++, 255);
        auto png8 = EncodePng8(w, h, c, s8);
        auto d8 = DecodePng(png8, "mem8.png");
        REQUIRE(d8.ok());
        CHECK(d8->width == w);
        CHECK(d8->height == h);
        CHECK(d8->channels == c);
        CHECK(d8->bit_depth == 8);
        CHECK(d8->samples16.empty());
        CHECK(d8->samples8 == s8);

        auto s16 = structured ? StructuredImage<uint16_t>(w, h, c, seed++, 65535)
                              : RandomImage<uint16_t>(w, h, c, seed++, 65535);
        auto png16 = EncodePng16(w, h, c, s16);
        auto d16 = DecodePng(png16, "mem16.png");
        REQUIRE(d16.ok());
        CHECK(d16->channels == c);
        CHECK(d16->bit_depth == 16);
        CHECK(d16->samples8.empty());
        CHECK(d16->samples16 == s16);
      }
    }
  }
}

TEST_CASE("PNG encoder compresses label and depth pictures", "[image_io][png]") {
  // A 640x480 label picture: background with a few blobs of parts. Must be far below raw size.
  poseforest::core::LabelImage labels(640, 480, poseforest::core::kBackgroundLabel);
  for (int y = 100; y < 400; ++y)
    for (int x = 250; x < 390; ++x) labels.at(x, y) = uint8_t((y / 20 + x / 35) % 31);
  auto png = EncodePng8(640, 480, 1, labels.pixels);
  INFO("label PNG bytes: " << png.size());
  CHECK(png.size() < 8000);
  // Constant image: the zlib stream is tiny.
  std::vector<uint8_t> flat(640 * 480 * 3, 77);
  CHECK(EncodePng8(640, 480, 3, flat).size() < 2000);
  // Random data does not blow up (stored blocks cap the overhead).
  auto noise = RandomImage<uint8_t>(200, 100, 3, 99, 255);
  CHECK(EncodePng8(200, 100, 3, noise).size() < noise.size() + noise.size() / 50 + 200);
}

TEST_CASE("PNG decoder reads PNGs written with Python's zlib", "[image_io][png][python]") {
  const fs::path dir = poseforest::testing::ScratchDir("png-python-in");
  WriteText(dir / "writer.py", kPythonWriter);
  REQUIRE(RunPython(dir / "writer.py", "'" + dir.string() + "'") == 0);
  std::ifstream manifest(dir / "manifest.txt");
  REQUIRE(manifest.good());
  std::string line;
  int cases = 0;
  while (std::getline(manifest, line)) {
    if (line.empty()) continue;
    std::istringstream ss(line);
    std::string name;
    int w = 0, h = 0, c = 0, depth = 0;
    ss >> name >> w >> h >> c >> depth;
    CAPTURE(name);
    const auto bytes = ReadBytes(dir / (name + ".png"));
    const auto want = ReadBytes(dir / (name + ".raw"));
    auto img = DecodePng(bytes, name + ".png");
    INFO((img.ok() ? std::string("ok") : img.status().ToString()));
    REQUIRE(img.ok());
    CHECK(img->width == w);
    CHECK(img->height == h);
    CHECK(img->channels == c);
    CHECK(img->bit_depth == depth);
    if (depth == 8) {
      CHECK(img->samples8 == want);
    } else {
      std::vector<uint16_t> w16(want.size() / 2);
      for (size_t i = 0; i < w16.size(); ++i) w16[i] = uint16_t(want[2 * i] | want[2 * i + 1] << 8);
      CHECK(img->samples16 == w16);
    }
    ++cases;

    // Damage the reference zlib streams (stored, fixed and dynamic blocks) behind valid chunk
    // CRCs: the inflater must report errors, never crash or read out of bounds.
    const auto z = ZlibStream(bytes);
    std::mt19937 rng{uint32_t(cases)};
    for (int t = 0; t < 60; ++t) {
      auto bad = z;
      if (t % 3 == 0) {
        bad.resize(rng() % z.size());
      } else {
        for (int f = 0; f < 1 + t % 3; ++f) bad[rng() % bad.size()] ^= uint8_t(1 + rng() % 255);
      }
      auto r = DecodePng(WithZlibStream(bytes, bad), name + "-damaged.png");
      if (!r.ok()) CHECK_THAT(r.status().message(), Catch::StartsWith(name + "-damaged.png: "));
      if (t % 3 == 0 && r.ok()) {
        // libspng stops reading once every scanline is in: a stream cut in its last bytes
        // (end of the final block, Adler-32) still gives the image, and exactly the image.
        INFO("cut at " << bad.size() << " of " << z.size());
        CHECK(r->samples8 == img->samples8);
        CHECK(r->samples16 == img->samples16);
      }
    }
  }
  CHECK(cases == 38);

  auto interlaced = DecodePng(ReadBytes(dir / "interlaced.png"), "interlaced.png");
  REQUIRE_FALSE(interlaced.ok());
  CHECK(interlaced.status().code() == ErrorCode::kUnimplemented);
  CHECK_THAT(interlaced.status().message(),
             Catch::Contains("interlaced.png") && Catch::Contains("nterlaced"));
  fs::remove_all(dir);
}

TEST_CASE("Truncated and corrupted PNGs give errors, never crash", "[image_io][png][corrupt]") {
  auto samples = StructuredImage<uint8_t>(13, 11, 3, 42, 255);
  const auto png = EncodePng8(13, 11, 3, samples);
  REQUIRE(DecodePng(png, "small.png").ok());

  SECTION("every truncation of the file") {
    for (size_t n = 0; n < png.size(); ++n) {
      std::vector<uint8_t> cut(png.begin(), png.begin() + long(n));
      auto r = DecodePng(cut, "cut.png");
      CAPTURE(n);
      REQUIRE_FALSE(r.ok());
      CHECK(r.status().code() == ErrorCode::kDataLoss);
      CHECK_THAT(r.status().message(), Catch::StartsWith("cut.png: "));
    }
  }
  SECTION("every truncation of the zlib stream, with valid chunk CRCs") {
    const auto z = ZlibStream(png);
    for (size_t n = 0; n < z.size(); ++n) {
      auto r =
          DecodePng(WithZlibStream(png, std::vector<uint8_t>(z.begin(), z.begin() + long(n))), "cutz.png");
      CAPTURE(n, z.size());
      if (r.ok()) {
        // libspng stops reading once every scanline is in: only a stream cut in its last bytes
        // (end of the final block, Adler-32) may still decode, and then to exactly the image.
        CHECK(n + 8 >= z.size());
        CHECK(r->samples8 == samples);
      } else {
        CHECK_THAT(r.status().message(), Catch::StartsWith("cutz.png: "));
      }
    }
  }
  SECTION("every single-byte flip is caught (signature or CRC)") {
    std::mt19937 rng(3);
    for (size_t i = 0; i < png.size(); ++i) {
      auto bad = png;
      bad[i] ^= uint8_t(1 + rng() % 255);
      CAPTURE(i);
      REQUIRE_FALSE(DecodePng(bad, "flip.png").ok());
    }
  }
  SECTION("random damage inside the zlib stream, with valid chunk CRCs") {
    // Exercises the inflater's own bounds checks: results may decode (rarely) but never crash.
    std::mt19937 rng(11);
    const auto z = ZlibStream(png);
    int errors = 0;
    const int trials = 3000;
    for (int t = 0; t < trials; ++t) {
      auto bad = z;
      const int flips = 1 + int(rng() % 4);
      for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] ^= uint8_t(1 + rng() % 255);
      auto r = DecodePng(WithZlibStream(png, bad), "damaged.png");
      if (!r.ok()) {
        ++errors;
        CHECK_THAT(r.status().message(), Catch::StartsWith("damaged.png: "));
      } else {
        CHECK(r->samples8.size() == samples.size());
      }
    }
    CHECK(errors > trials * 9 / 10);
  }
  SECTION("random garbage after a valid zlib header") {
    std::mt19937 rng(12);
    for (int t = 0; t < 2000; ++t) {
      std::vector<uint8_t> z = {0x78, 0x9C};
      const size_t n = 1 + rng() % 200;
      for (size_t i = 0; i < n; ++i) z.push_back(uint8_t(rng()));
      auto r = DecodePng(WithZlibStream(png, z), "garbage.png");
      REQUIRE_FALSE(r.ok());
    }
  }
}

TEST_CASE("PNG header and palette validation", "[image_io][png]") {
  auto grey = std::vector<uint8_t>{0, 1, 2, 3, 4, 5};
  const auto base = EncodePng8(3, 2, 1, grey);
  const auto z = ZlibStream(base);
  auto with_ihdr = [&](std::vector<uint8_t> ihdr) {
    return Assemble({{"IHDR", std::move(ihdr)}, {"IDAT", z}, {"IEND", {}}});
  };
  auto expect_error = [](const std::vector<uint8_t>& png, const std::string& needle) {
    auto r = DecodePng(png, "hdr.png");
    CAPTURE(needle);
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(), Catch::StartsWith("hdr.png: ") && Catch::Contains(needle));
  };
  expect_error(with_ihdr(Ihdr(40000, 2, 8, 0)), "too large");
  expect_error(with_ihdr(Ihdr(20000, 20000, 8, 0)), "too large");
  expect_error(with_ihdr(Ihdr(0, 2, 8, 0)), "invalid image width");
  expect_error(with_ihdr(Ihdr(3, 2, 3, 0)), "bit depth");
  expect_error(with_ihdr(Ihdr(3, 2, 4, 2)), "bit depth");
  expect_error(with_ihdr(Ihdr(3, 2, 16, 3)), "bit depth");
  expect_error(with_ihdr(Ihdr(3, 2, 8, 5)), "color type");
  expect_error(with_ihdr(Ihdr(3, 2, 8, 0, 1)), "nterlaced");
  expect_error(Assemble({{"IDAT", z}, {"IEND", {}}}), "IHDR");
  expect_error(Assemble({{"IHDR", Ihdr(3, 2, 8, 0)}, {"IEND", {}}}), "IDAT");
  expect_error(Assemble({{"IHDR", Ihdr(3, 2, 8, 0)}, {"IDAT", z}}), "IEND");
  expect_error(Assemble({{"IHDR", Ihdr(3, 2, 8, 0)}, {"ABCD", {1}}, {"IDAT", z}, {"IEND", {}}}), "critical");
  // Wrong image size for the data: the inflated stream is too short. (Data after the last
  // scanline is ignored, as libpng and libspng do.)
  expect_error(with_ihdr(Ihdr(3, 3, 8, 0)), "IDAT");
  // Palette: the grey values 0..5 read as indices into a palette.
  const std::vector<uint8_t> pal6 = {10, 11, 12, 20, 21, 22, 30, 31, 32, 40, 41, 42, 50, 51, 52, 60, 61, 62};
  auto pal_png = Assemble({{"IHDR", Ihdr(3, 2, 8, 3)}, {"PLTE", pal6}, {"IDAT", z}, {"IEND", {}}});
  auto p = DecodePng(pal_png, "pal.png");
  REQUIRE(p.ok());
  CHECK(p->channels == 3);
  CHECK(p->samples8 == pal6);
  auto pal_trns =
      Assemble({{"IHDR", Ihdr(3, 2, 8, 3)}, {"PLTE", pal6}, {"tRNS", {0, 128}}, {"IDAT", z}, {"IEND", {}}});
  auto pt = DecodePng(pal_trns, "palt.png");
  REQUIRE(pt.ok());
  CHECK(pt->channels == 4);
  CHECK(pt->samples8 == std::vector<uint8_t>{10, 11, 12, 0,   20, 21, 22, 128, 30, 31, 32, 255,
                                             40, 41, 42, 255, 50, 51, 52, 255, 60, 61, 62, 255});
  const std::vector<uint8_t> pal2(pal6.begin(), pal6.begin() + 6);
  // Indices beyond the palette read as black, as in libpng and libspng (whose palette table
  // has 256 entries, zero beyond those the file gives).
  auto beyond = DecodePng(Assemble({{"IHDR", Ihdr(3, 2, 8, 3)}, {"PLTE", pal2}, {"IDAT", z}, {"IEND", {}}}),
                          "beyond.png");
  REQUIRE(beyond.ok());
  CHECK(beyond->samples8 == std::vector<uint8_t>{10, 11, 12, 20, 21, 22, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0});
  expect_error(Assemble({{"IHDR", Ihdr(3, 2, 8, 3)}, {"IDAT", z}, {"IEND", {}}}), "PLTE");
  expect_error(Assemble({{"IHDR", Ihdr(3, 2, 8, 3)}, {"PLTE", {1, 2}}, {"IDAT", z}, {"IEND", {}}}),
               "chunk length");
}

TEST_CASE("Unknown filter type is an error", "[image_io][png]") {
  // One 8-pixel grey row whose filter byte is 7, in a hand-made stored zlib block.
  std::vector<uint8_t> bytes = {7, 1, 2, 3, 4, 5, 6, 7, 8};
  std::vector<uint8_t> z = {0x78, 0x01, 0x01, 9, 0, uint8_t(~9), 0xFF};
  z.insert(z.end(), bytes.begin(), bytes.end());
  uint32_t a = 1, b = 0;
  for (uint8_t v : bytes) {
    a = (a + v) % 65521;
    b = (b + a) % 65521;
  }
  PutBe32(z, b << 16 | a);
  auto png = Assemble({{"IHDR", Ihdr(8, 1, 8, 0)}, {"IDAT", z}, {"IEND", {}}});
  auto r = DecodePng(png, "filter.png");
  REQUIRE_FALSE(r.ok());
  CHECK_THAT(r.status().message(), Catch::Contains("invalid scanline filter"));
  // Same stream with filter byte 0 decodes (proves the hand-made stream is valid).
  bytes[0] = 0;
  z = {0x78, 0x01, 0x01, 9, 0, uint8_t(~9), 0xFF};
  z.insert(z.end(), bytes.begin(), bytes.end());
  a = 1, b = 0;
  for (uint8_t v : bytes) {
    a = (a + v) % 65521;
    b = (b + a) % 65521;
  }
  PutBe32(z, b << 16 | a);
  auto ok = DecodePng(Assemble({{"IHDR", Ihdr(8, 1, 8, 0)}, {"IDAT", z}, {"IEND", {}}}), "filter0.png");
  REQUIRE(ok.ok());
  CHECK(ok->samples8 == std::vector<uint8_t>(bytes.begin() + 1, bytes.end()));
}

TEST_CASE("ReadDepthImage reads the real Kinect frames", "[image_io][depth]") {
  const fs::path dir = poseforest::testing::DataDir() / "real" / "skeltrack_kinect_depth";
  int frames = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().filename().string().rfind("depth-data-", 0) != 0) continue;
    CAPTURE(entry.path().string());
    auto depth = ReadDepthImage(entry.path().string());
    INFO((depth.ok() ? std::string("ok") : depth.status().ToString()));
    REQUIRE(depth.ok());
    CHECK(depth->width == 640);
    CHECK(depth->height == 480);
    const int fg = poseforest::core::CountForeground(*depth);
    CHECK(fg > 640 * 480 / 20);  // a person fills a good part of the frame
    CHECK(fg < 640 * 480 / 2);   // background already removed: many zeros
    int plausible = 0;
    for (uint16_t d : depth->pixels) plausible += d >= 500 && d <= 4000;
    CHECK(plausible == fg);  // Kinect v1 range, mm; a byte-order mistake would put them >> 4000
    ++frames;
  }
  CHECK(frames == 9);
}

TEST_CASE("ReadDepthImage errors name the file", "[image_io][depth]") {
  const fs::path dir = poseforest::testing::ScratchDir("depth-errors");
  const std::string wrong = (dir / "wrong-size.raw").string();
  WriteBytes(wrong, std::vector<uint8_t>(1001, 1));
  auto r = ReadDepthImage(wrong);
  REQUIRE_FALSE(r.ok());
  CHECK_THAT(r.status().message(),
             Catch::Contains(wrong) && Catch::Contains("614400") && Catch::Contains("1001"));

  // The same bytes as a 25x20 raw frame (1000 bytes) are fine once the size fits.
  WriteBytes(wrong, std::vector<uint8_t>(1000, 1));
  auto small = ReadDepthImage(wrong, 25, 20);
  REQUIRE(small.ok());
  CHECK(small->pixels == std::vector<uint16_t>(500, 0x0101));

  auto missing = ReadDepthImage((dir / "nope.png").string());
  REQUIRE_FALSE(missing.ok());
  CHECK(missing.status().code() == ErrorCode::kNotFound);
  CHECK_THAT(missing.status().message(), Catch::Contains("nope.png"));

  // An 8-bit PNG is refused: depth must be 16-bit grey in mm.
  const std::string grey8 = (dir / "grey8.png").string();
  WriteBytes(grey8, EncodePng8(4, 4, 1, std::vector<uint8_t>(16, 9)));
  auto g = ReadDepthImage(grey8);
  REQUIRE_FALSE(g.ok());
  CHECK_THAT(g.status().message(), Catch::Contains(grey8) && Catch::Contains("16-bit greyscale"));

  // A 1-bit palette PNG with transparency of 16384 x 16384 pixels would decode to 1 GiB of RGBA:
  // a depth reader refuses it from its header, before decoding (the message says what it is).
  const auto z = ZlibStream(EncodePng8(3, 2, 1, std::vector<uint8_t>(6, 0)));
  const auto bomb = Assemble({{"IHDR", Ihdr(16384, 16384, 1, 3)},
                              {"PLTE", {0, 0, 0, 255, 255, 255}},
                              {"tRNS", {0}},
                              {"IDAT", z},
                              {"IEND", {}}});
  auto direct = DecodeDepthPng(bomb, "bomb.png");
  REQUIRE_FALSE(direct.ok());
  CHECK_THAT(
      direct.status().message(),
      Catch::Equals("bomb.png: a depth image must be a 16-bit greyscale PNG in millimetres; this one has 1 "
                    "channel(s) of 1-bit samples (a palette)"));
  const std::string bomb_path = (dir / "bomb.png").string();
  WriteBytes(bomb_path, bomb);
  auto read_bomb = ReadDepthImage(bomb_path);
  REQUIRE_FALSE(read_bomb.ok());
  CHECK_THAT(read_bomb.status().message(), Catch::Contains(bomb_path) && Catch::Contains("(a palette)"));
  // A 16-bit greyscale PNG decodes as before.
  auto depth16 =
      DecodeDepthPng(EncodePng16(3, 2, 1, std::vector<uint16_t>{1, 2, 3, 400, 500, 65535}), "d.png");
  REQUIRE(depth16.ok());
  CHECK(depth16->pixels == std::vector<uint16_t>{1, 2, 3, 400, 500, 65535});

  // Label and mask PNGs: 8-bit greyscale only, refused from the header the same way.
  auto labels = DecodeLabelPng(EncodePng8(3, 2, 1, std::vector<uint8_t>{0, 1, 30, 255, 7, 9}), "l.png");
  REQUIRE(labels.ok());
  CHECK(labels->width == 3);
  CHECK(labels->height == 2);
  CHECK(labels->pixels == std::vector<uint8_t>{0, 1, 30, 255, 7, 9});
  auto label_bomb = DecodeLabelPng(bomb, "bomb.png");
  REQUIRE_FALSE(label_bomb.ok());
  CHECK(label_bomb.status().code() == ErrorCode::kInvalidArgument);
  CHECK_THAT(
      label_bomb.status().message(),
      Catch::Equals("bomb.png: a label image must be an 8-bit greyscale PNG of raw values; this one has 1 "
                    "channel(s) of 1-bit samples (a palette)"));
  auto label16 = DecodeLabelPng(EncodePng16(2, 2, 1, std::vector<uint16_t>(4, 3)), "l16.png");
  REQUIRE_FALSE(label16.ok());
  CHECK_THAT(label16.status().message(), Catch::Contains("this one has 1 channel(s) of 16-bit samples"));
  auto label_rgb = DecodeLabelPng(EncodePng8(2, 2, 3, std::vector<uint8_t>(12, 3)), "rgb.png");
  REQUIRE_FALSE(label_rgb.ok());
  CHECK_THAT(label_rgb.status().message(), Catch::Contains("this one has 3 channel(s) of 8-bit samples"));
  // A corrupt label PNG gives libspng's DataLoss, naming the file.
  auto corrupt = EncodePng8(4, 4, 1, std::vector<uint8_t>(16, 2));
  corrupt[corrupt.size() - 20] ^= 0x55;
  auto corrupt_labels = DecodeLabelPng(corrupt, "c.png");
  REQUIRE_FALSE(corrupt_labels.ok());
  CHECK(corrupt_labels.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(corrupt_labels.status().message(), Catch::StartsWith("c.png: "));

  // A corrupt PNG depth file names the file.
  auto png = EncodePng16(4, 4, 1, std::vector<uint16_t>(16, 1200));
  png[png.size() - 20] ^= 0x55;
  const std::string bad = (dir / "bad.png").string();
  WriteBytes(bad, png);
  auto b = ReadDepthImage(bad);
  REQUIRE_FALSE(b.ok());
  CHECK(b.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(b.status().message(), Catch::Contains(bad));
  fs::remove_all(dir);
}

TEST_CASE("Image writers round trip and write atomically", "[image_io][write]") {
  const fs::path dir = poseforest::testing::ScratchDir("image-writers");
  using poseforest::core::DepthImage;
  using poseforest::core::LabelImage;

  DepthImage depth(33, 17);
  for (size_t i = 0; i < depth.pixels.size(); ++i) depth.pixels[i] = uint16_t(i % 5 == 0 ? 0 : 700 + i * 13);
  const std::string dpath = (dir / "depth.png").string();
  REQUIRE(WriteDepthPng(dpath, depth).ok());
  auto back = ReadDepthImage(dpath);
  REQUIRE(back.ok());
  CHECK(back->width == 33);
  CHECK(back->height == 17);
  CHECK(back->pixels == depth.pixels);

  LabelImage labels(40, 3, poseforest::core::kBackgroundLabel);
  for (int x = 0; x < 40; ++x) labels.at(x, 1) = uint8_t(x);  // parts 0..30, then 31..39 (invalid)
  labels.at(0, 2) = 200;
  const std::string lpath = (dir / "labels.png").string();
  REQUIRE(WriteLabelPng(lpath, labels).ok());
  auto lb = DecodePng(ReadBytes(lpath), lpath);
  REQUIRE(lb.ok());
  CHECK(lb->channels == 1);
  CHECK(lb->bit_depth == 8);
  CHECK(lb->samples8 == labels.pixels);

  const std::string cpath = (dir / "labels_colour.png").string();
  REQUIRE(WriteLabelColourPng(cpath, labels).ok());
  auto col = DecodePng(ReadBytes(cpath), cpath);
  REQUIRE(col.ok());
  REQUIRE(col->channels == 3);
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 40; ++x) {
      const int label = labels.at(x, y);
      const auto want = label < poseforest::core::kNumParts ? poseforest::core::PartColour(label)
                                                            : poseforest::core::kBackgroundColour;
      const size_t i = (size_t(y) * 40 + x) * 3;
      CAPTURE(x, y, label);
      CHECK(col->samples8[i] == want.r);
      CHECK(col->samples8[i + 1] == want.g);
      CHECK(col->samples8[i + 2] == want.b);
    }
  }

  auto rgb = StructuredImage<uint8_t>(21, 9, 3, 8, 255);
  const std::string rpath = (dir / "rgb.png").string();
  REQUIRE(WriteRgbPng(rpath, 21, 9, rgb).ok());
  auto rb = DecodePng(ReadBytes(rpath), rpath);
  REQUIRE(rb.ok());
  CHECK(rb->samples8 == rgb);
  CHECK_FALSE(WriteRgbPng(rpath, 21, 9, std::span<const uint8_t>(rgb.data(), 10)).ok());

  // Overwriting works and leaves no temporary files behind.
  REQUIRE(WriteRgbPng(rpath, 21, 9, rgb).ok());
  int files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++files;
  CHECK(files == 4);

  const std::string nowhere = (dir / "no-such-folder" / "x.png").string();
  auto st = WriteRgbPng(nowhere, 21, 9, rgb);
  REQUIRE_FALSE(st.ok());
  CHECK(st.code() == ErrorCode::kIo);
  CHECK_THAT(st.message(), Catch::Contains(nowhere));
  fs::remove_all(dir);
}
