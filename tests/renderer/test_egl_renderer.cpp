// The headless EGL renderer against geometry with known answers: exact depth of planes, box
// silhouettes on the pixels core::CameraIntrinsics::Project predicts, flat labels.
#include <catch2/catch.hpp>
#include <cmath>
#include <iostream>

#include "renderer/egl_renderer.h"
#include "runtime/core/body_parts.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

/// A mesh rigidly attached to joint 0 (identity matrices draw it where it is, camera frame).
BodyMesh RigidMesh(std::vector<Eigen::Vector3f> vertices, std::vector<std::array<uint32_t, 3>> triangles,
                   uint8_t part) {
  BodyMesh m;
  m.name = "test";
  m.vertices = std::move(vertices);
  m.triangles = std::move(triangles);
  SkinInfluence s;
  s.joint = {0, 0, 0, 0};
  s.weight = {1, 0, 0, 0};
  m.skin.assign(m.vertices.size(), s);
  m.part.assign(m.vertices.size(), part);
  return m;
}

BodyMesh Box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, uint8_t part) {
  std::vector<Eigen::Vector3f> v;
  for (int i = 0; i < 8; ++i) {
    v.emplace_back(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(), i & 4 ? hi.z() : lo.z());
  }
  std::vector<std::array<uint32_t, 3>> t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                                            {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return RigidMesh(v, t, part);
}

JointMatrices Identity() {
  JointMatrices m;
  for (auto& x : m) x = Eigen::Matrix<float, 3, 4>::Identity();
  return m;
}

std::unique_ptr<EglRenderer> MakeRenderer(
    const core::CameraIntrinsics& cam = core::CameraIntrinsics::KinectV1()) {
  auto r = EglRenderer::Create(cam);
  if (!r.ok()) FAIL("EGL renderer: " << r.status().ToString());
  static bool printed = false;
  if (!printed) {
    std::cout << "GL_RENDERER: " << (*r)->gl_renderer() << "\nGL_VERSION: " << (*r)->gl_version()
              << std::endl;
    printed = true;
  }
  return std::move(r).value();
}

/// Convex hull (counter-clockwise) of 2D points, monotone chain.
std::vector<Eigen::Vector2d> Hull(std::vector<Eigen::Vector2d> p) {
  std::sort(p.begin(), p.end(),
            [](auto& a, auto& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  std::vector<Eigen::Vector2d> h(2 * p.size());
  size_t k = 0;
  auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

/// Signed distance (pixels) of q inside a CCW convex polygon: > 0 inside.
double InsideDistance(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& q) {
  double d = 1e30;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d a = poly[i], b = poly[(i + 1) % poly.size()];
    const Eigen::Vector2d e = (b - a).normalized();
    d = std::min(d, e.x() * (q - a).y() - e.y() * (q - a).x());
  }
  return d;
}

}  // namespace

TEST_CASE("a fronto-parallel plane renders at its exact depth with its label", "[egl]") {
  auto r = MakeRenderer();
  const float z = 2.0f;
  auto handle =
      r->UploadMesh(RigidMesh({{-3, -3, z}, {3, -3, z}, {3, 3, z}, {-3, 3, z}}, {{0, 1, 2}, {0, 2, 3}}, 5));
  REQUIRE(handle.ok());
  REQUIRE(r->BeginFrame().ok());
  r->Draw(*handle, Identity(), false);
  core::DepthImage depth;
  core::LabelImage labels;
  REQUIRE(r->ReadFrame(&depth, &labels).ok());
  REQUIRE(depth.width == 640);
  REQUIRE(depth.height == 480);
  for (size_t i = 0; i < depth.pixels.size(); ++i) {
    REQUIRE(depth.pixels[i] == 2000);
    REQUIRE(labels.pixels[i] == 5);
  }
  // Empty frame: background everywhere.
  REQUIRE(r->BeginFrame().ok());
  REQUIRE(r->ReadFrame(&depth, &labels).ok());
  CHECK(core::CountForeground(depth) == 0);
  CHECK(labels.pixels[12345] == core::kBackgroundLabel);
}

TEST_CASE("a slanted plane renders the ray-plane depth at every pixel (+-1 mm)", "[egl]") {
  auto r = MakeRenderer();
  // Plane z = 2.5 + 0.4 x + 0.2 y (metres), camera frame.
  auto zf = [](float x, float y) { return 2.5f + 0.4f * x + 0.2f * y; };
  std::vector<Eigen::Vector3f> v = {
      {-2, -2, zf(-2, -2)}, {2, -2, zf(2, -2)}, {2, 2, zf(2, 2)}, {-2, 2, zf(-2, 2)}};
  auto handle = r->UploadMesh(RigidMesh(v, {{0, 1, 2}, {0, 2, 3}}, 9));
  REQUIRE(handle.ok());
  REQUIRE(r->BeginFrame().ok());
  r->Draw(*handle, Identity(), false);
  core::DepthImage depth;
  core::LabelImage labels;
  REQUIRE(r->ReadFrame(&depth, &labels).ok());
  const core::CameraIntrinsics cam = r->camera();
  int worst = 0;
  for (int y = 0; y < cam.height; y += 3) {
    for (int x = 0; x < cam.width; x += 3) {
      // Ray through the pixel centre: (a, b, 1) t with a = (x - cx)/fx; z = 2.5/(1 - 0.4a - 0.2b).
      const double a = (x - cam.cx) / cam.fx, b = (y - cam.cy) / cam.fy;
      const double z_mm = 2500.0 / (1.0 - 0.4 * a - 0.2 * b);
      worst = std::max(worst, int(std::abs(depth.at(x, y) - z_mm) + 0.5));
    }
  }
  CHECK(worst <= 1);
}

TEST_CASE("box silhouettes land on the pixels CameraIntrinsics::Project predicts", "[egl]") {
  // A non-centred principal point, to catch any assumption that cx = (w - 1) / 2.
  core::CameraIntrinsics cam = core::CameraIntrinsics::KinectV1();
  cam.cx = 331.25;
  cam.cy = 228.8;
  auto r = MakeRenderer(cam);
  struct Case {
    Eigen::Vector3f lo, hi;
  };
  const Case cases[] = {{{0.113f, -0.207f, 2.4f}, {0.4571f, 0.1013f, 2.5f}},
                        {{-0.9317f, 0.2119f, 1.8f}, {-0.6093f, 0.5561f, 2.3f}},
                        {{-0.0521f, -0.0497f, 3.9f}, {0.0533f, 0.0609f, 4.0f}}};
  for (const Case& c : cases) {
    auto handle = r->UploadMesh(Box(c.lo, c.hi, 17));
    REQUIRE(handle.ok());
    REQUIRE(r->BeginFrame().ok());
    r->Draw(*handle, Identity(), false);
    core::DepthImage depth;
    core::LabelImage labels;
    REQUIRE(r->ReadFrame(&depth, &labels).ok());
    std::vector<Eigen::Vector2d> corners, front;
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p(i & 1 ? c.hi.x() : c.lo.x(), i & 2 ? c.hi.y() : c.lo.y(),
                              i & 4 ? c.hi.z() : c.lo.z());
      corners.push_back(cam.Project(p));
      if (!(i & 4)) front.push_back(cam.Project(p));
    }
    const auto hull = Hull(corners), front_hull = Hull(front);
    int checked = 0, wrong = 0, wrong_depth = 0, inside = 0;
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        const double d = InsideDistance(hull, Eigen::Vector2d(x, y));
        if (std::abs(d) < 0.02) continue;  // a pixel centre on the edge: tie rules decide
        ++checked;
        const bool fg = depth.at(x, y) != 0;
        if (fg != (d > 0)) ++wrong;
        if (fg && labels.at(x, y) != 17) ++wrong;
        if (d > 0) ++inside;
        if (InsideDistance(front_hull, Eigen::Vector2d(x, y)) > 0.02 &&
            depth.at(x, y) != uint16_t(std::lround(c.lo.z() * 1000.0))) {
          ++wrong_depth;
        }
      }
    }
    INFO("box " << c.lo.transpose() << " .. " << c.hi.transpose() << ": " << inside << " pixels inside");
    CHECK(inside > 100);
    CHECK(wrong == 0);
    CHECK(wrong_depth == 0);
  }
}

TEST_CASE("each triangle takes one label and joint matrices place the mesh", "[egl]") {
  auto r = MakeRenderer();
  // Two triangles of a quad with different labels; the mesh is drawn through joint 3's matrix.
  BodyMesh m = RigidMesh({{-0.5f, -0.5f, 0}, {0.5f, -0.5f, 0}, {0.5f, 0.5f, 0}, {-0.5f, 0.5f, 0}},
                         {{0, 1, 2}, {0, 2, 3}}, 0);
  for (auto& s : m.skin) s.joint[0] = 3;
  m.part = {4, 4, 4, 20};  // triangle 0: all 4; triangle 1: parts 4, 4, 20 -> majority 4
  auto handle = r->UploadMesh(m);
  REQUIRE(handle.ok());
  JointMatrices mats;
  for (auto& x : mats) x.setZero();  // any other joint would collapse the mesh
  mats[3] = Eigen::Matrix<float, 3, 4>::Identity();
  mats[3](2, 3) = 3.0f;  // push 3 m forward
  REQUIRE(r->BeginFrame().ok());
  r->Draw(*handle, mats, false);
  core::DepthImage depth;
  core::LabelImage labels;
  REQUIRE(r->ReadFrame(&depth, &labels).ok());
  int fg = 0;
  for (size_t i = 0; i < labels.pixels.size(); ++i) {
    if (depth.pixels[i] == 0) continue;
    ++fg;
    REQUIRE(depth.pixels[i] == 3000);
    REQUIRE(labels.pixels[i] == 4);
  }
  // The 1 m square at 3 m covers about (575.8 / 3)^2 pixels.
  CHECK(fg == Approx(575.8 * 575.8 / 9.0).epsilon(0.02));
  // Mirrored labels: part 4 (neck) maps to itself, so use part 15 (L_hand) -> R_hand.
  m.part = {15, 15, 15, 15};
  auto h2 = r->UploadMesh(m);
  REQUIRE(h2.ok());
  REQUIRE(r->BeginFrame().ok());
  r->Draw(*h2, mats, true);
  REQUIRE(r->ReadFrame(&depth, &labels).ok());
  CHECK(labels.at(320, 240) == uint8_t(core::Part::kRHand));
}

TEST_CASE("bad meshes are refused with a message naming them", "[egl]") {
  auto r = MakeRenderer();
  BodyMesh m = Box({0, 0, 1}, {1, 1, 2}, 3);
  m.name = "broken-box";
  m.part.pop_back();
  auto h = r->UploadMesh(m);
  REQUIRE_FALSE(h.ok());
  CHECK(h.status().message().find("broken-box") != std::string::npos);
  BodyMesh m2 = Box({0, 0, 1}, {1, 1, 2}, 3);
  m2.triangles[0][1] = 99;
  CHECK_FALSE(r->UploadMesh(m2).ok());
}
