// Core: taxonomy, camera reprojection, the depth feature (eq. 1) and the counter-based RNG.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <set>

#include <sys/resource.h>

#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/crc32.h"
#include "runtime/core/feature.h"
#include "runtime/core/malloc_tuning.h"
#include "runtime/core/rng.h"
#include "tests/support/synthetic.h"

using namespace poseforest;

TEST_CASE("taxonomy: 31 parts with unique names and colours, mirror map is an involution", "[core]") {
  std::set<std::string_view> names;
  std::set<std::tuple<int, int, int>> colours;
  for (int p = 0; p < core::kNumParts; ++p) {
    names.insert(core::PartName(p));
    const auto c = core::PartColour(p);
    colours.insert({c.r, c.g, c.b});
    CHECK(core::MirrorPart(core::MirrorPart(p)) == p);
    CHECK(core::PartFromName(core::PartName(p)) == p);
    // Mirroring swaps the L/R prefix letter and keeps the rest of the name.
    const std::string a(core::PartName(p)), b(core::PartName(core::MirrorPart(p)));
    // (Built with append: GCC 12 warns falsely (-Wrestrict) on "R" + std::string.)
    std::string swapped = a;
    if (a[0] == 'L' || a[0] == 'R') swapped[0] = a[0] == 'L' ? 'R' : 'L';
    if (swapped != a) CHECK(b == swapped);
    else CHECK(core::MirrorPart(p) == p);
  }
  CHECK(names.size() == 31);
  CHECK(colours.size() == 31);
  CHECK(colours.count({0, 0, 0}) == 0);  // background colour is not a part colour
  CHECK(core::MirrorPart(int(core::Part::kLUHead)) == int(core::Part::kRUHead));
  CHECK(core::MirrorPart(int(core::Part::kNeck)) == int(core::Part::kNeck));
  CHECK_FALSE(core::PartFromName("nose").has_value());
}

TEST_CASE("taxonomy: 16 joints, each fed by parts, head merges the four head parts", "[core]") {
  std::set<int> used;
  for (int j = 0; j < core::kNumJoints; ++j) {
    const auto& parts = core::JointParts(j);
    CHECK_FALSE(parts.empty());
    CHECK(core::MirrorJoint(core::MirrorJoint(j)) == j);
    for (int p : parts) {
      CHECK(p >= 0);
      CHECK(p < core::kNumParts);
      used.insert(p);
      // The mirror joint is fed by the mirror parts.
      const auto& mp = core::JointParts(core::MirrorJoint(j));
      CHECK(std::find(mp.begin(), mp.end(), core::MirrorPart(p)) != mp.end());
    }
  }
  CHECK(core::JointParts(int(core::Joint::kHead)).size() == 4);
  CHECK(core::JointName(int(core::Joint::kLElbow)) == "L_elbow");
  CHECK(used.size() == 4 + 1 + 2 * 7);  // head parts, neck, and 7 per side
}

TEST_CASE("camera: pixel -> 3D -> pixel round trip", "[core]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  CHECK(cam.width == 640);
  CHECK(cam.height == 480);
  for (int y = 0; y < cam.height; y += 37) {
    for (int x = 0; x < cam.width; x += 41) {
      for (uint16_t d : {uint16_t(500), uint16_t(2345), uint16_t(8000)}) {
        const Eigen::Vector3d p = cam.PixelToPoint(x, y, d);
        CHECK(p.z() == Approx(d * 1e-3));
        const Eigen::Vector2d uv = cam.Project(p);
        CHECK(uv.x() == Approx(x).margin(1e-9));
        CHECK(uv.y() == Approx(y).margin(1e-9));
      }
    }
  }
  // The principal point looks straight ahead; a pixel to the right is at positive x.
  CHECK(cam.Unproject(cam.cx, cam.cy, 2.0).head<2>().norm() == Approx(0).margin(1e-12));
  CHECK(cam.PixelToPoint(639, 240, 1000).x() > 0);
  CHECK(cam.PixelToPoint(320, 479, 1000).y() > 0);  // y down
}

TEST_CASE("feature: probes off the image or on background read the constant", "[core][feature]") {
  core::DepthImage img(8, 6, 1000);
  img.at(5, 2) = 0;
  core::FeatureConstants c;
  const float scale = core::PixelScale(1000, c.offset_unit);  // 1000 mm: 1 pixel per pixel*m
  CHECK(scale == Approx(c.offset_unit));
  const int16_t one = int16_t(std::lround(1.0f / c.offset_unit));  // one pixel*m
  core::FeatureOffsets f{int16_t(2 * one), 0, 0, 0};                // u: 2 px right; v: the pixel itself
  CHECK(core::FeatureResponse(img, 3, 2, f, c) == c.background_mm - 1000);  // (5,2) is a hole
  CHECK(core::FeatureResponse(img, 1, 2, f, c) == 0);                       // (3,2) is body
  CHECK(core::FeatureResponse(img, 7, 0, f, c) == c.background_mm - 1000);  // off the right edge
  core::FeatureOffsets up{0, int16_t(-10 * one), 0, 0};
  CHECK(core::FeatureResponse(img, 0, 0, up, c) == c.background_mm - 1000);  // off the top
}

TEST_CASE("feature: with ProbeEdge::kClamp a probe past the edge reads the pixel on the edge",
          "[core][feature]") {
  // Depth 1000 + 10 x + 100 y: every pixel its own value.
  core::DepthImage img(8, 6, 0);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) img.at(x, y) = uint16_t(1000 + 10 * x + 100 * y);
  img.at(7, 2) = 0;  // a hole on the right edge
  core::FeatureConstants c;
  c.edge = core::ProbeEdge::kClamp;
  const uint16_t* d = img.data();
  CHECK(core::ProbeDepth(d, 8, 6, 3, 4, c.background_mm, c.edge) == 1000 + 30 + 400);    // inside: as before
  CHECK(core::ProbeDepth(d, 8, 6, 12, 1, c.background_mm, c.edge) == 1000 + 70 + 100);   // right: (7, 1)
  CHECK(core::ProbeDepth(d, 8, 6, -5, 3, c.background_mm, c.edge) == 1000 + 0 + 300);    // left: (0, 3)
  CHECK(core::ProbeDepth(d, 8, 6, 4, -100, c.background_mm, c.edge) == 1000 + 40);       // top: (4, 0)
  CHECK(core::ProbeDepth(d, 8, 6, 99, 99, c.background_mm, c.edge) == 1000 + 70 + 500);  // a corner: (7, 5)
  // The edge pixel is a hole: it reads as background does.
  CHECK(core::ProbeDepth(d, 8, 6, 30, 2, c.background_mm, c.edge) == c.background_mm);
  // The paper's rule on the same probes.
  CHECK(core::ProbeDepth(d, 8, 6, 12, 1, c.background_mm, core::ProbeEdge::kBackground) == c.background_mm);
  CHECK(core::ProbeDepth(d, 8, 6, 3, 4, c.background_mm, core::ProbeEdge::kBackground) == 1000 + 30 + 400);
  // Through eq. 1: u two pixels right of a pixel on the right edge reads that pixel, so f = 0.
  const int16_t one = int16_t(std::lround(1.0f / c.offset_unit));
  core::FeatureOffsets f{int16_t(2 * one), 0, 0, 0};
  img.at(7, 0) = 1000;  // (7, 0) at 1000 mm: one pixel per pixel*m there
  CHECK(core::FeatureResponse(img, 7, 0, f, c) == 0);
  c.edge = core::ProbeEdge::kBackground;
  CHECK(core::FeatureResponse(img, 7, 0, f, c) == c.background_mm - 1000);
}

TEST_CASE("feature: offsets scale with 1/depth and round halves up", "[core][feature]") {
  CHECK(core::RoundOffset(0.49f) == 0);
  CHECK(core::RoundOffset(0.5f) == 1);
  CHECK(core::RoundOffset(-0.5f) == 0);
  CHECK(core::RoundOffset(-0.51f) == -1);
  CHECK(core::RoundOffset(-7.5f) == -7);
  CHECK(core::RoundOffset(123.4f) == 123);
  core::FeatureConstants c;
  // 64 pixel*m at 2 m is 32 pixels, at 4 m 16 pixels.
  const int16_t u = int16_t(std::lround(64 / c.offset_unit));
  CHECK(core::RoundOffset(float(u) * core::PixelScale(2000, c.offset_unit)) == 32);
  CHECK(core::RoundOffset(float(u) * core::PixelScale(4000, c.offset_unit)) == 16);
}

TEST_CASE("feature: the same body further away gives the same responses (depth invariance)", "[core][feature]") {
  // One figure at 2 m and at 4 m. For the same body point (found through the camera model)
  // and the same feature, eq. 1 must give the same response up to pixel rounding, whenever the
  // probes land on the same kind of surface at both distances (a background probe reads the
  // constant, which is deliberately not invariant).
  const core::FeatureConstants c;
  const auto cam = core::CameraIntrinsics::KinectV1();
  const auto near = testing::MakePersonDepth(2.0), far = testing::MakePersonDepth(4.0);
  core::RngStream rng(core::CounterRng(99));
  std::vector<std::pair<int, int>> foreground;
  for (int y = 0; y < far.height; ++y)
    for (int x = 0; x < far.width; ++x)
      if (far.at(x, y) != 0) foreground.emplace_back(x, y);
  REQUIRE(foreground.size() > 5000);
  int compared = 0, close = 0;
  for (int k = 0; k < 4000; ++k) {
    // A body point in metres on the body plane, via a random foreground pixel of the far image.
    const auto [fx, fy] = foreground[rng.UniformInt(uint32_t(foreground.size()))];
    const Eigen::Vector3d on_plane_far = cam.Unproject(fx, fy, 4.0);
    const Eigen::Vector2d uv_near = cam.Project({on_plane_far.x(), on_plane_far.y(), 2.0});
    const int nx = int(std::lround(uv_near.x())), ny = int(std::lround(uv_near.y()));
    if (!near.InBounds(nx, ny) || near.at(nx, ny) == 0) continue;
    const int m = int(std::lround(60 / c.offset_unit));
    core::FeatureOffsets f{int16_t(rng.UniformIntIn(-m, m)), int16_t(rng.UniformIntIn(-m, m)),
                           int16_t(rng.UniformIntIn(-m, m)), int16_t(rng.UniformIntIn(-m, m))};
    const int32_t r_near = core::FeatureResponse(near, nx, ny, f, c);
    const int32_t r_far = core::FeatureResponse(far, fx, fy, f, c);
    const bool bg_near = std::abs(r_near) > 3000, bg_far = std::abs(r_far) > 3000;
    if (bg_near != bg_far) continue;  // a probe crossed the silhouette at one distance only
    ++compared;
    if (std::abs(r_near - r_far) <= 25 || (bg_near && std::abs(std::abs(r_near - r_far) - 2000) <= 25)) ++close;
  }
  INFO("compared " << compared << ", close " << close);
  REQUIRE(compared > 1000);
  CHECK(double(close) / compared > 0.95);
}

TEST_CASE("rng: draws are pure functions of (seed, tree, node, stream, index)", "[core][rng]") {
  const core::CounterRng a(42, 1, 7, 3), b(42, 1, 7, 3);
  for (uint64_t i = 0; i < 100; ++i) CHECK(a.Bits(i) == b.Bits(i));
  // Any change of key changes the stream.
  for (const core::CounterRng& other : {core::CounterRng(43, 1, 7, 3), core::CounterRng(42, 2, 7, 3),
                                        core::CounterRng(42, 1, 8, 3), core::CounterRng(42, 1, 7, 4)}) {
    int same = 0;
    for (uint64_t i = 0; i < 100; ++i) same += a.Bits(i) == other.Bits(i);
    CHECK(same == 0);
  }
  // Moments of uniform and normal draws.
  double sum = 0, sum2 = 0, nsum = 0, nsum2 = 0;
  const int n = 200000;
  int counts[10] = {};
  for (int i = 0; i < n; ++i) {
    const double u = a.Uniform01(uint64_t(i));
    REQUIRE(u >= 0.0);
    REQUIRE(u < 1.0);
    sum += u;
    sum2 += u * u;
    const double g = a.Normal(uint64_t(i));
    nsum += g;
    nsum2 += g * g;
    counts[a.UniformInt(uint64_t(i), 10)]++;
  }
  CHECK(sum / n == Approx(0.5).margin(0.005));
  CHECK(sum2 / n - (sum / n) * (sum / n) == Approx(1.0 / 12).margin(0.002));
  CHECK(nsum / n == Approx(0.0).margin(0.01));
  CHECK(nsum2 / n == Approx(1.0).margin(0.02));
  for (int c : counts) CHECK(std::abs(c - n / 10) < 1000);
  for (int i = 0; i < 1000; ++i) {
    const int v = a.UniformIntIn(uint64_t(i), -3, 3);
    CHECK(v >= -3);
    CHECK(v <= 3);
  }
  core::RngStream s(a, 5);
  CHECK(s.Bits() == a.Bits(5));
  CHECK(s.position() == 6);
}

TEST_CASE("crc32 matches the standard check value", "[core]") {
  const char* check = "123456789";
  CHECK(core::Crc32(check, 9) == 0xCBF43926u);
  // Incremental = one-shot, across the 8-byte fast path boundary.
  std::vector<uint8_t> data(1000);
  for (size_t i = 0; i < data.size(); ++i) data[i] = uint8_t(i * 31 + 7);
  const uint32_t whole = core::Crc32(data.data(), data.size());
  CHECK(core::Crc32(data.data() + 13, data.size() - 13, core::Crc32(data.data(), 13)) == whole);
}

namespace {
long MinorFaults() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}
}  // namespace

TEST_CASE("KeepFreedMemory: a freed 8 MiB block is reused without faulting its pages in again", "[core][malloc]") {
  // With glibc's defaults the first 8 MiB block is an mmap of its own and goes back on free;
  // the second comes from a heap grown for it (its pages fault in again). With the settings,
  // only the first round faults. (The test process has made no large allocation before.)
  REQUIRE(core::KeepFreedMemory());
  REQUIRE(core::KeepFreedMemory());  // a second call changes nothing and says the same
  constexpr size_t kBytes = 8u << 20, kPages = kBytes / 4096;
  long faults[3] = {};
  for (long& f : faults) {
    const long before = MinorFaults();
    auto* p = static_cast<unsigned char*>(std::malloc(kBytes));
    REQUIRE(p != nullptr);
    std::memset(p, 0x5a, kBytes);
    asm volatile("" : : "r"(p) : "memory");  // the block is used: the compiler keeps malloc/free
    std::free(p);
    f = MinorFaults() - before;
  }
  INFO("minor faults per round: " << faults[0] << ", " << faults[1] << ", " << faults[2]);
  CHECK(faults[1] < long(kPages / 10));
  CHECK(faults[2] < long(kPages / 10));
}
