#include "renderer/procedural_body.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numbers>

#include "renderer/part_labels.h"
#include "runtime/core/result.h"
#include "runtime/core/rng.h"

namespace poseforest::renderer {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using J = SkelJoint;

constexpr int Idx(J j) { return int(j); }

double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

/// One bone of a weighting chain: vertices near it follow `joint`.
struct ChainBone {
  int joint;
  Vector3d a, b;  ///< segment, metres
};

/// Linear-blend weights of a point from the nearest bone of a chain: 1 on that bone, blended
/// 50/50 with the neighbouring bone exactly at the shared joint, fading over `blend_m`.
SkinInfluence ChainWeights(const Vector3d& p, const std::vector<ChainBone>& chain, double blend_m) {
  size_t best = 0;
  double best_d = 1e30, best_t = 0;
  for (size_t k = 0; k < chain.size(); ++k) {
    const Vector3d ab = chain[k].b - chain[k].a;
    const double len2 = std::max(ab.squaredNorm(), 1e-12);
    const double t = std::clamp((p - chain[k].a).dot(ab) / len2, 0.0, 1.0);
    const double d = (chain[k].a + t * ab - p).norm();
    if (d < best_d - 1e-9) best_d = d, best = k, best_t = t;
  }
  const double len = (chain[best].b - chain[best].a).norm();
  double w_prev = 0, w_next = 0;
  if (best > 0) w_prev = 0.5 * (1.0 - SmoothStep(best_t * len / blend_m));
  if (best + 1 < chain.size()) w_next = 0.5 * (1.0 - SmoothStep((1.0 - best_t) * len / blend_m));
  SkinInfluence s;
  int n = 0;
  auto add = [&](int joint, double w) {
    if (w <= 1e-4) return;
    s.joint[size_t(n)] = uint8_t(joint);
    s.weight[size_t(n)] = float(w);
    ++n;
  };
  add(chain[best].joint, 1.0 - w_prev - w_next);
  if (best > 0) add(chain[best - 1].joint, w_prev);
  if (best + 1 < chain.size()) add(chain[best + 1].joint, w_next);
  float sum = 0;
  for (float w : s.weight) sum += w;
  for (float& w : s.weight) w /= sum;
  return s;
}

/// A lofted primitive: rings of a superellipse (half-axes radii(s) along u, v) centred on the
/// segment a->b (plus offset(s) in the u, v plane), closed by elliptical caps of length
/// cap_a / cap_b metres beyond a and b.
struct Loft {
  Vector3d a, b;
  Vector3d u;  ///< first cross-section axis (made perpendicular to the segment)
  std::function<Vector2d(double)> radii;
  std::function<Vector2d(double)> offset = [](double) { return Vector2d(0, 0); };
  double exponent = 2.0;  ///< 2 = ellipse, larger = boxier
  double cap_a = 0, cap_b = 0;
  std::vector<ChainBone> chain;
  double blend_m = 0.05;
};

void AddLoft(const Loft& loft, const BodyResolution& res, BodyMesh* mesh) {
  Vector3d axis = loft.b - loft.a;
  const double len = axis.norm();
  axis = len > 1e-9 ? Vector3d(axis / len) : Vector3d::UnitY();
  const Vector3d u = (loft.u - loft.u.dot(axis) * axis).normalized();
  const Vector3d v = axis.cross(u);
  const int m = res.segments;
  const int body_rings = std::max(2, int(std::ceil(len * res.rings_per_m)) + 1);
  // Caps get rings in proportion to their length (the head is all cap), at least 3.
  auto cap_rings_for = [&](double cap_len) {
    return std::max(3, int(std::ceil(cap_len * res.rings_per_m * 1.4)));
  };
  const int cap_rings_a = cap_rings_for(loft.cap_a), cap_rings_b = cap_rings_for(loft.cap_b);

  struct Ring {
    Vector3d centre;
    Vector2d r;
  };
  std::vector<Ring> rings;
  auto ring_at = [&](double s, double along_extra, double shrink) {
    const Vector2d r = loft.radii(s) * shrink;
    const Vector2d o = loft.offset(s);
    rings.push_back({loft.a + axis * (s * len + along_extra) + u * o.x() + v * o.y(), r});
  };
  // Cap at a (from near the pole to the body), body, cap at b.
  for (int k = cap_rings_a - 1; k >= 1; --k) {
    const double phi = 0.5 * std::numbers::pi * k / cap_rings_a;
    ring_at(0.0, -loft.cap_a * std::sin(phi), std::cos(phi));
  }
  for (int k = 0; k < body_rings; ++k) ring_at(double(k) / (body_rings - 1), 0.0, 1.0);
  for (int k = 1; k < cap_rings_b; ++k) {
    const double phi = 0.5 * std::numbers::pi * k / cap_rings_b;
    ring_at(1.0, loft.cap_b * std::sin(phi), std::cos(phi));
  }

  const uint32_t base = uint32_t(mesh->vertices.size());
  auto superellipse = [&](double t, double e) {
    const double c = std::cos(t), s = std::sin(t);
    return Vector2d(std::copysign(std::pow(std::abs(c), 2.0 / e), c),
                    std::copysign(std::pow(std::abs(s), 2.0 / e), s));
  };
  std::vector<Vector3d> pts;
  pts.push_back(loft.a - axis * loft.cap_a + u * loft.offset(0).x() + v * loft.offset(0).y());
  for (const Ring& ring : rings) {
    for (int i = 0; i < m; ++i) {
      const Vector2d q = superellipse(2.0 * std::numbers::pi * i / m, loft.exponent);
      pts.push_back(ring.centre + u * (q.x() * ring.r.x()) + v * (q.y() * ring.r.y()));
    }
  }
  pts.push_back(loft.b + axis * loft.cap_b + u * loft.offset(1).x() + v * loft.offset(1).y());

  std::vector<std::array<uint32_t, 3>> tris;
  const uint32_t nr = uint32_t(rings.size());
  const uint32_t first_pole = 0, last_pole = 1 + nr * uint32_t(m);
  auto ring_v = [&](uint32_t r, int i) { return 1 + r * uint32_t(m) + uint32_t((i + m) % m); };
  for (int i = 0; i < m; ++i) tris.push_back({first_pole, ring_v(0, i + 1), ring_v(0, i)});
  for (uint32_t r = 0; r + 1 < nr; ++r) {
    for (int i = 0; i < m; ++i) {
      tris.push_back({ring_v(r, i), ring_v(r, i + 1), ring_v(r + 1, i + 1)});
      tris.push_back({ring_v(r, i), ring_v(r + 1, i + 1), ring_v(r + 1, i)});
    }
  }
  for (int i = 0; i < m; ++i) tris.push_back({last_pole, ring_v(nr - 1, i), ring_v(nr - 1, i + 1)});

  // Orientation: make the signed volume positive (CCW seen from outside).
  double volume = 0;
  for (const auto& t : tris) volume += pts[t[0]].dot(pts[t[1]].cross(pts[t[2]]));
  if (volume < 0) {
    for (auto& t : tris) std::swap(t[1], t[2]);
  }
  for (const Vector3d& p : pts) {
    mesh->vertices.push_back(p.cast<float>());
    mesh->skin.push_back(ChainWeights(p, loft.chain, loft.blend_m));
  }
  for (const auto& t : tris) mesh->triangles.push_back({base + t[0], base + t[1], base + t[2]});
}

/// Piecewise-linear interpolation of key values at increasing s.
Vector2d Keyframes(double s, const std::vector<std::pair<double, Vector2d>>& keys) {
  if (s <= keys.front().first) return keys.front().second;
  for (size_t k = 1; k < keys.size(); ++k) {
    if (s <= keys[k].first) {
      const double t = (s - keys[k - 1].first) / (keys[k].first - keys[k - 1].first);
      const double w = SmoothStep(t);
      return (1 - w) * keys[k - 1].second + w * keys[k].second;
    }
  }
  return keys.back().second;
}

}  // namespace

BodyShape ProceduralBaseShape(int i) {
  POSEFOREST_CHECK(i >= 0 && i < kNumProceduralShapes);
  // name, height, girth, belly, child, female, leg, arm, shoulder
  static const std::array<BodyShape, kNumProceduralShapes> kShapes = {{
      {"child-small", 1.05, 1.00, 0.2, 1.00, 0.5, 1.00, 1.00, 1.00},
      {"child", 1.22, 0.95, 0.1, 0.80, 0.3, 1.00, 1.00, 1.00},
      {"child-chubby", 1.35, 1.25, 0.6, 0.55, 0.6, 0.98, 1.00, 1.00},
      {"teen-slim", 1.52, 0.82, 0.0, 0.30, 0.0, 1.04, 1.02, 0.95},
      {"teen-girl", 1.60, 0.88, 0.0, 0.15, 1.0, 1.02, 1.00, 0.95},
      {"woman-petite", 1.55, 0.85, 0.0, 0.00, 1.0, 0.98, 0.98, 0.96},
      {"woman", 1.66, 1.00, 0.1, 0.00, 1.0, 1.00, 1.00, 1.00},
      {"woman-heavy", 1.68, 1.40, 0.7, 0.00, 1.0, 0.97, 1.00, 1.02},
      {"woman-tall", 1.80, 0.90, 0.0, 0.00, 1.0, 1.05, 1.02, 1.00},
      {"woman-curvy", 1.62, 1.22, 0.3, 0.00, 1.0, 0.98, 0.98, 0.98},
      {"man-stocky", 1.66, 1.22, 0.3, 0.00, 0.0, 0.95, 0.98, 1.08},
      {"man", 1.76, 1.00, 0.1, 0.00, 0.0, 1.00, 1.00, 1.00},
      {"man-athletic", 1.82, 1.08, 0.0, 0.00, 0.0, 1.02, 1.02, 1.12},
      {"man-heavy", 1.84, 1.50, 1.0, 0.00, 0.0, 0.98, 1.00, 1.05},
      {"man-tall-slim", 1.96, 0.85, 0.0, 0.00, 0.0, 1.06, 1.04, 0.98},
      {"man-big-belly", 1.72, 1.35, 0.9, 0.00, 0.0, 0.96, 1.04, 1.02},
  }};
  BodyShape s = kShapes[size_t(i)];
  s.hair = 0.15 + 0.55 * s.female;  // women: long hair by default
  s.clothing = 0.3;
  return s;
}

BodyShape VaryShape(const BodyShape& base, uint64_t seed, uint64_t variant) {
  if (variant == 0) return base;
  core::RngStream rng(core::CounterRng(seed, 0x5A4E, variant, 0xB0D7));
  BodyShape s = base;
  s.name = base.name + "~" + std::to_string(variant);
  s.height_m *= rng.UniformIn(0.97, 1.03);
  s.girth *= rng.UniformIn(0.92, 1.08);
  s.belly = std::clamp(s.belly + rng.UniformIn(-0.15, 0.15), 0.0, 1.0);
  s.leg_ratio *= rng.UniformIn(0.97, 1.03);
  s.arm_ratio *= rng.UniformIn(0.97, 1.03);
  s.shoulder_ratio *= rng.UniformIn(0.96, 1.04);
  s.hair = std::clamp(base.hair + rng.UniformIn(-0.4, 0.6) * (0.6 + 0.4 * base.female), 0.0, 1.0);
  s.clothing = rng.UniformIn(0.0, 1.0);
  return s;
}

SkelPositions ProceduralSkeleton(const BodyShape& shape) {
  const double h = shape.height_m, c = shape.child, f = shape.female;
  const double head_frac = 0.13 + 0.06 * c;  // chin to top of head, fraction of height
  const double y_head = h * (1.0 - 0.8 * head_frac);
  const double y_neck = h * (1.0 - head_frac - 0.04);
  const double y_hip = h * (0.50 - 0.05 * c) * shape.leg_ratio;
  const double y_pelvis = y_hip + 0.02 * h;
  const double sw = h * (0.105 - 0.01 * f - 0.012 * c) * shape.shoulder_ratio;
  const double hw = h * (0.052 + 0.006 * f) * std::pow(shape.girth, 0.3);
  const double arm_scale = h * shape.arm_ratio * (1.0 - 0.08 * c);
  SkelPositions p;
  auto set = [&](J j, double x, double y, double z) { p[size_t(Idx(j))] = Vector3d(x, y, z); };
  set(J::kPelvis, 0, y_pelvis, 0);
  set(J::kSpine, 0, y_pelvis + 0.33 * (y_neck - y_pelvis), -0.01 * h);
  set(J::kChest, 0, y_pelvis + 0.70 * (y_neck - y_pelvis), -0.012 * h);
  set(J::kNeck, 0, y_neck, -0.012 * h);
  set(J::kHead, 0, y_head, -0.004 * h);
  set(J::kHeadTop, 0, h, 0);
  for (int side = 0; side < 2; ++side) {
    const double sx = side == 0 ? 1.0 : -1.0;  // left = +X
    const J collar = side == 0 ? J::kLCollar : J::kRCollar;
    const J shoulder = side == 0 ? J::kLShoulder : J::kRShoulder;
    const J elbow = side == 0 ? J::kLElbow : J::kRElbow;
    const J wrist = side == 0 ? J::kLWrist : J::kRWrist;
    const J tip = side == 0 ? J::kLHandTip : J::kRHandTip;
    const double ys = y_neck - 0.012 * h;
    double x = 0.22 * sw;
    set(collar, sx * x, y_neck - 0.008 * h, -0.006 * h);
    x = sw;
    set(shoulder, sx * x, ys, -0.01 * h);
    x += 0.186 * arm_scale;
    set(elbow, sx * x, ys, -0.012 * h);
    x += 0.146 * arm_scale;
    set(wrist, sx * x, ys, -0.01 * h);
    x += 0.108 * h * (1.0 - 0.05 * c);
    set(tip, sx * x, ys, -0.01 * h);

    const J hip = side == 0 ? J::kLHip : J::kRHip;
    const J knee = side == 0 ? J::kLKnee : J::kRKnee;
    const J ankle = side == 0 ? J::kLAnkle : J::kRAnkle;
    const J toe = side == 0 ? J::kLToe : J::kRToe;
    set(hip, sx * hw, y_hip, 0);
    set(knee, sx * hw * 0.95, y_hip * 0.54, 0.004 * h);
    set(ankle, sx * hw * 0.9, y_hip * 0.08, -0.004 * h);
    set(toe, sx * hw * 0.95, 0.012 * h, 0.115 * h);
  }
  return p;
}

namespace {

// The shape's skeleton and the scales every part of the body is built from.
struct BodyScales {
  const BodyShape& shape;
  SkelPositions sk;
  double h, k, g, gs, c, f, blend, cloth_trunk, cloth_limb;
  Vector3d P(J j) const { return sk[size_t(Idx(j))]; }
};

// Torso: a superelliptic loft from the crotch to the shoulders.
void AddTorso(const BodyScales& b, const BodyResolution& res, BodyMesh* mesh) {
  const BodyShape& shape = b.shape;
  auto P = [&b](J j) { return b.P(j); };
  const double h = b.h, k = b.k, g = b.g, c = b.c, f = b.f, cloth_trunk = b.cloth_trunk;
  const double y0 = P(J::kLHip).y() - 0.055 * h;
  const double y1 = P(J::kLShoulder).y() + 0.012 * h;
  const double yp = P(J::kPelvis).y(), ysp = P(J::kSpine).y(), ych = P(J::kChest).y();
  const double span = y1 - y0;
  auto at = [&](double y) { return (y - y0) / span; };
  const double shoulder_half = std::abs(P(J::kLShoulder).x()) + 0.01 * k;
  const double hip_w = (0.155 + 0.025 * f) * k * std::pow(g, 0.85) * (1.0 - 0.05 * c) * cloth_trunk;
  const double waist_w = (0.135 + 0.005 * f) * k * g * cloth_trunk;
  const double chest_w = (0.155 - 0.01 * f) * k * std::pow(g, 0.8) * shape.shoulder_ratio * cloth_trunk;
  const double hip_d = 0.100 * k * g * cloth_trunk,
               waist_d = (0.095 + 0.05 * shape.belly) * k * g * cloth_trunk;
  const double chest_d = (0.105 + 0.012 * f) * k * std::pow(g, 0.9) * cloth_trunk;
  const std::vector<std::pair<double, Vector2d>> radii = {
      {0.0, {hip_w * 0.82, hip_d * 0.85}},
      {at(yp), {hip_w, hip_d}},
      {at(ysp), {waist_w, waist_d}},
      {at(ych), {chest_w, chest_d}},
      {0.88, {std::max(shoulder_half * 0.98, chest_w), chest_d * 0.85}},
      {1.0, {std::max(shoulder_half * 0.92, chest_w * 0.9), chest_d * 0.7}},
  };
  const std::vector<std::pair<double, Vector2d>> offsets = {
      {0.0, {0, -0.01 * k}},
      {at(yp), {0, -0.012 * k * g}},
      {at(ysp), {0, (0.01 + 0.04 * shape.belly) * k * g}},
      {at(ych), {0, 0.004 * k}},
      {1.0, {0, -0.012 * k}},
  };
  Loft torso;
  torso.a = {0, y0, 0};
  torso.b = {0, y1, 0};
  torso.u = -Vector3d::UnitX();  // so that v = axis x u = +Z (forward): offsets are forward
  torso.radii = [radii](double s) { return Keyframes(s, radii); };
  torso.offset = [offsets](double s) { return Keyframes(s, offsets); };
  torso.exponent = 2.4;
  torso.cap_a = 0.06 * k;
  torso.cap_b = 0.05 * k;
  torso.chain = {{Idx(J::kPelvis), P(J::kPelvis), P(J::kSpine)},
                 {Idx(J::kSpine), P(J::kSpine), P(J::kChest)},
                 {Idx(J::kChest), P(J::kChest), P(J::kNeck)}};
  torso.blend_m = 0.08 * k;
  AddLoft(torso, res, mesh);
}

// Neck, head and hair.
void AddNeckAndHead(const BodyScales& b, const BodyResolution& res, BodyMesh* mesh) {
  const BodyShape& shape = b.shape;
  auto P = [&b](J j) { return b.P(j); };
  const double k = b.k, g = b.g, gs = b.gs, c = b.c;
  const double r = 0.054 * k * gs * (1.0 - 0.1 * c);
  Loft neck;
  neck.a = P(J::kNeck) - Vector3d(0, 0.02 * k, 0);
  neck.b = P(J::kHead);
  neck.u = Vector3d::UnitX();
  neck.radii = [r](double) { return Vector2d(r, r * 1.05); };
  neck.cap_a = neck.cap_b = r;
  neck.chain = {{Idx(J::kChest), P(J::kChest), P(J::kNeck)},
                {Idx(J::kNeck), P(J::kNeck), P(J::kHead)},
                {Idx(J::kHead), P(J::kHead), P(J::kHeadTop)}};
  neck.blend_m = 0.03 * k;
  AddLoft(neck, res, mesh);

  const double head_h = P(J::kHeadTop).y() - P(J::kHead).y();
  const double ry = 0.625 * head_h;  // reaches below the skull base (chin)
  const Vector3d centre(0, P(J::kHeadTop).y() - ry, 0.012 * k);
  const double rx = ry * 0.68 * std::pow(g, 0.15), rz = ry * 0.85 * std::pow(g, 0.15);
  Loft head;
  head.a = centre - Vector3d(0, 1e-4, 0);
  head.b = centre + Vector3d(0, 1e-4, 0);
  head.u = Vector3d::UnitX();
  head.radii = [rx, rz](double) { return Vector2d(rx, rz); };
  head.cap_a = head.cap_b = ry;
  head.chain = {{Idx(J::kNeck), P(J::kNeck), P(J::kHead)}, {Idx(J::kHead), P(J::kHead), P(J::kHeadTop)}};
  head.blend_m = 0.025 * k;
  AddLoft(head, res, mesh);

  // Hair: a cap over the top and back of the skull (never in front of the face), and long
  // hair down the back for hair > 0.6. Skinned to the head, so it is labelled as head.
  const double hv = shape.hair;
  if (hv > 0.05) {
    Loft hair = head;
    const Vector3d hc = centre + Vector3d(0, 0.06 * ry, -0.22 * rz);
    const double hrx = rx * (1.04 + 0.12 * hv), hry = ry * (0.98 + 0.06 * hv), hrz = rz * (0.95 + 0.15 * hv);
    hair.a = hc - Vector3d(0, 1e-4, 0);
    hair.b = hc + Vector3d(0, 1e-4, 0);
    hair.radii = [hrx, hrz](double) { return Vector2d(hrx, hrz); };
    hair.cap_a = hair.cap_b = hry;
    AddLoft(hair, res, mesh);
  }
  if (hv > 0.6) {
    const double len = (0.12 + 0.25 * (hv - 0.6)) * k;  // below the skull, down the back
    Loft tail;
    tail.a = centre + Vector3d(0, -0.1 * ry, -0.55 * rz);
    tail.b = tail.a + Vector3d(0, -len, -0.02 * k);
    tail.u = Vector3d::UnitX();
    const double w = rx * 0.9, d = 0.35 * rz;
    tail.radii = [w, d](double s) { return Vector2d(w * (1.0 - 0.15 * s), d * (1.0 - 0.4 * s)); };
    tail.cap_a = d;
    tail.cap_b = 0.02 * k;
    tail.chain = {{Idx(J::kHead), P(J::kHead), P(J::kHeadTop)}};
    tail.blend_m = 0.02 * k;
    AddLoft(tail, res, mesh);
  }
}

// One arm (`left` or right): shoulder pad, upper arm, forearm, hand.
void AddArm(const BodyScales& b, bool left, const BodyResolution& res, BodyMesh* mesh) {
  auto P = [&b](J j) { return b.P(j); };
  const double k = b.k, g = b.g, gs = b.gs, c = b.c, f = b.f, blend = b.blend, cloth_limb = b.cloth_limb;
  const J collar = left ? J::kLCollar : J::kRCollar;
  const J shoulder = left ? J::kLShoulder : J::kRShoulder;
  const J elbow = left ? J::kLElbow : J::kRElbow;
  const J wrist = left ? J::kLWrist : J::kRWrist;
  const J tip = left ? J::kLHandTip : J::kRHandTip;
  const std::vector<ChainBone> chain = {{Idx(J::kChest), P(J::kChest), P(collar)},
                                        {Idx(collar), P(collar), P(shoulder)},
                                        {Idx(shoulder), P(shoulder), P(elbow)},
                                        {Idx(elbow), P(elbow), P(wrist)},
                                        {Idx(wrist), P(wrist), P(tip)}};
  const double r_sh = 0.052 * k * g * (1.0 - 0.06 * f) * cloth_limb,
               r_el = 0.038 * k * std::pow(g, 0.8) * cloth_limb;
  const double r_wr = 0.028 * k * std::pow(g, 0.6);
  {
    Loft l;  // shoulder pad over the collar bone, merges arm and torso
    l.a = P(collar);
    l.b = P(shoulder);
    l.u = Vector3d::UnitZ();
    l.radii = [&](double s) { return Vector2d(0.05 * k * g, (0.035 + 0.02 * s) * k * g); };
    l.cap_a = 0.03 * k;
    l.cap_b = 0.05 * k * g;
    l.chain = chain;
    l.blend_m = blend;
    AddLoft(l, res, mesh);
  }
  {
    Loft l;  // upper arm, biceps bulge a third of the way down
    l.a = P(shoulder);
    l.b = P(elbow);
    l.u = Vector3d::UnitZ();
    l.radii = [=](double s) {
      const double r = r_sh + (r_el - r_sh) * s + 0.006 * k * g * std::sin(std::numbers::pi * s);
      return Vector2d(r, r * 0.95);
    };
    l.cap_a = r_sh;
    l.cap_b = r_el;
    l.chain = chain;
    l.blend_m = blend;
    AddLoft(l, res, mesh);
  }
  {
    Loft l;  // forearm
    l.a = P(elbow);
    l.b = P(wrist);
    l.u = Vector3d::UnitZ();
    l.radii = [=](double s) {
      const double r = r_el + (r_wr - r_el) * s + 0.005 * k * g * std::sin(std::numbers::pi * s * 0.8);
      return Vector2d(r * (1.0 + 0.25 * s), r * (1.0 - 0.2 * s));
    };
    l.cap_a = r_el;
    l.cap_b = r_wr;
    l.chain = chain;
    l.blend_m = blend;
    AddLoft(l, res, mesh);
  }
  {
    Loft l;  // hand: a flattened mitten (palm down in the T-pose)
    const Vector3d dir = (P(tip) - P(wrist)).normalized();
    const double hand_len = (P(tip) - P(wrist)).norm();
    l.a = P(wrist) + dir * 0.15 * hand_len;
    l.b = P(tip) - dir * 0.2 * hand_len;
    l.u = Vector3d::UnitZ();
    const double hw = 0.042 * k * gs * (1.0 - 0.1 * c), ht = 0.016 * k * gs;
    l.radii = [=](double s) {
      return Vector2d(hw * (0.85 + 0.15 * std::sin(std::numbers::pi * (0.3 + 0.7 * s))), ht);
    };
    l.exponent = 2.6;
    l.cap_a = 0.15 * hand_len;
    l.cap_b = 0.2 * hand_len;
    l.chain = chain;
    l.blend_m = 0.03 * k;
    AddLoft(l, res, mesh);
  }
}

// One leg (`left` or right): thigh, shin, foot.
void AddLeg(const BodyScales& b, bool left, const BodyResolution& res, BodyMesh* mesh) {
  auto P = [&b](J j) { return b.P(j); };
  const double k = b.k, g = b.g, gs = b.gs, f = b.f, blend = b.blend, cloth_limb = b.cloth_limb;
  const J hip = left ? J::kLHip : J::kRHip;
  const J knee = left ? J::kLKnee : J::kRKnee;
  const J ankle = left ? J::kLAnkle : J::kRAnkle;
  const J toe = left ? J::kLToe : J::kRToe;
  const std::vector<ChainBone> chain = {{Idx(J::kPelvis), P(J::kPelvis), P(hip)},
                                        {Idx(hip), P(hip), P(knee)},
                                        {Idx(knee), P(knee), P(ankle)},
                                        {Idx(ankle), P(ankle), P(toe)}};
  // Thighs may touch but not cross the midline (heavy shapes have wider hips instead).
  const double hip_half = std::abs(P(hip).x());
  const double r_hip = std::min((0.088 + 0.008 * f) * k * g * cloth_limb, hip_half + 0.008 * k);
  const double r_knee = 0.054 * k * std::pow(g, 0.8) * cloth_limb;
  const double r_ank = 0.036 * k * std::pow(g, 0.6);
  {
    Loft l;  // thigh
    l.a = P(hip);
    l.b = P(knee);
    l.u = Vector3d::UnitX();
    l.radii = [=](double s) {
      const double r = r_hip + (r_knee - r_hip) * s;
      return Vector2d(r, r * 1.02);
    };
    const double sx = left ? 1.0 : -1.0;
    l.offset = [=](double s) { return Vector2d(sx * 0.01 * k * (1.0 - s), 0.0); };
    l.cap_a = r_hip;
    l.cap_b = r_knee;
    l.chain = chain;
    l.blend_m = blend * 1.2;
    AddLoft(l, res, mesh);
  }
  {
    Loft l;  // shin with a calf bulge at the back
    l.a = P(knee);
    l.b = P(ankle);
    l.u = Vector3d::UnitX();
    l.radii = [=](double s) {
      const double r = r_knee + (r_ank - r_knee) * s;
      const double calf = 0.012 * k * g * std::sin(std::numbers::pi * std::min(1.0, s * 1.6));
      return Vector2d(r + 0.4 * calf, r + calf);
    };
    l.offset = [=](double s) {
      return Vector2d(0.0, -0.008 * k * g * std::sin(std::numbers::pi * std::min(1.0, s * 1.6)));
    };
    l.cap_a = r_knee;
    l.cap_b = r_ank;
    l.chain = chain;
    l.blend_m = blend;
    AddLoft(l, res, mesh);
  }
  {
    Loft l;  // foot: a boxy loft from heel to toe, sole on y = 0
    const Vector3d a = P(ankle), t = P(toe);
    const double fw = 0.044 * k * gs;
    const double heel_z = a.z() - 0.045 * k;
    const double top = a.y() + 0.012 * k;
    l.a = {a.x(), 0.0, heel_z + 0.03 * k};
    l.b = {t.x(), 0.0, t.z() - 0.025 * k};
    l.u = Vector3d::UnitX();
    l.radii = [=](double s) { return Vector2d(fw * (0.8 + 0.25 * s), 0.5 * top * (1.0 - 0.6 * s)); };
    l.offset = [=](double s) { return Vector2d(0.0, 0.5 * top * (1.0 - 0.6 * s)); };
    // Rings are in the (x, y) plane; for a loft along z, v = axis x u = +Y. Keep it that way.
    l.exponent = 3.0;
    l.cap_a = 0.03 * k;
    l.cap_b = 0.025 * k;
    l.chain = chain;
    l.blend_m = 0.03 * k;
    AddLoft(l, res, mesh);
  }
}

}  // namespace

BodyMesh MakeProceduralBody(const BodyShape& shape, const BodyResolution& res) {
  BodyMesh mesh;
  mesh.name = "procedural:" + shape.name;
  const SkelPositions sk = ProceduralSkeleton(shape);
  mesh.rest_joints = sk;
  const double h = shape.height_m;
  const double k = h / 1.75;       // length scale
  const double g = shape.girth;    // girth scale
  const double gs = std::sqrt(g);  // for parts that fatten less (neck, hands, feet)
  const double c = shape.child, f = shape.female;
  const double blend = 0.045 * k;
  const double cloth_trunk = 1.0 + 0.08 * shape.clothing;  // loose clothes on the trunk
  const double cloth_limb = 1.0 + 0.12 * shape.clothing;   // and on upper arms and legs
  const BodyScales b{shape, sk, h, k, g, gs, c, f, blend, cloth_trunk, cloth_limb};

  AddTorso(b, res, &mesh);
  AddNeckAndHead(b, res, &mesh);
  for (int side = 0; side < 2; ++side) AddArm(b, side == 0, res, &mesh);
  for (int side = 0; side < 2; ++side) AddLeg(b, side == 0, res, &mesh);
  LabelBodyParts(mesh);
  RefinePartBoundaries(mesh, 2);
  return mesh;
}

}  // namespace poseforest::renderer
