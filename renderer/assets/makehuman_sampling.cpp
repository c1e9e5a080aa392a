#include "renderer/assets/makehuman.h"

// The MakeHuman bodies a scene draws from: the presets, their random variation, continuously
// sampled shapes and outfits; and the body measures used to check them. The kit itself
// (loading, morphing, dressing) is in makehuman.cpp.

#include <algorithm>
#include <cstdio>
#include <limits>

namespace poseforest::renderer::assets {

double MakeHumanAgeFromYears(double years) {
  years = std::clamp(years, 1.0, 90.0);
  if (years < 11) return 0.1875 * (years - 1) / 10.0;
  if (years < 25) return 0.1875 + 0.3125 * (years - 11) / 14.0;
  return 0.5 + 0.5 * (years - 25) / 65.0;
}

const std::vector<MakeHumanParams>& MakeHumanPresets() {
  static const std::vector<MakeHumanParams> presets = [] {
    auto P = [](const char* name, double gender, double years, double muscle, double weight, double height) {
      MakeHumanParams p;
      p.name = name;
      p.gender = gender;
      p.age = MakeHumanAgeFromYears(years);
      p.muscle = muscle;
      p.weight = weight;
      p.height_scale = height;
      return p;
    };
    return std::vector<MakeHumanParams>{
        // MakeHuman's child targets without its height modifier come out short for their age,
        // so children get a height_scale towards typical heights (~1.28, 1.45, 1.60 m).
        P("girl-8", 0.0, 8, 0.5, 0.5, 1.17),
        P("boy-8", 1.0, 8, 0.5, 0.5, 1.12),
        P("girl-11-thin", 0.0, 11, 0.4, 0.25, 1.15),
        P("boy-11-heavy", 1.0, 11, 0.5, 0.85, 1.08),
        P("girl-14", 0.0, 14, 0.5, 0.5, 1.15),
        P("boy-14", 1.0, 14, 0.55, 0.5, 1.12),
        P("female-young-thin", 0.0, 25, 0.4, 0.15, 1.0),
        P("female-young-average", 0.0, 25, 0.5, 0.5, 1.0),
        P("female-young-heavy", 0.0, 30, 0.45, 0.95, 0.98),
        P("female-athletic-tall", 0.0, 28, 0.85, 0.45, 1.05),
        P("male-young-thin", 1.0, 25, 0.45, 0.15, 1.0),
        P("male-young-average", 1.0, 25, 0.5, 0.5, 1.02),
        P("male-young-heavy", 1.0, 35, 0.5, 1.0, 1.0),
        P("male-muscular-tall", 1.0, 28, 1.0, 0.6, 1.07),
        P("androgynous-short", 0.5, 30, 0.5, 0.5, 0.93),
        P("female-old", 0.0, 75, 0.35, 0.6, 0.96),
        P("male-old", 1.0, 75, 0.35, 0.55, 0.97),
        P("male-old-heavy", 1.0, 65, 0.4, 0.9, 0.98),
    };
  }();
  return presets;
}

MakeHumanParams VaryMakeHuman(const MakeHumanParams& base, core::RngStream& rng) {
  MakeHumanParams p = base;
  p.height_scale = base.height_scale * (1.0 + std::clamp(0.03 * rng.Normal(), -0.08, 0.08));
  p.weight = std::clamp(base.weight + 0.06 * rng.Normal(), 0.0, 1.0);
  p.name = base.name + "~var";
  return p;
}

MakeHumanParams SampleMakeHumanParams(core::RngStream& rng) {
  MakeHumanParams p;
  const double g = rng.Uniform01(), gv = rng.Uniform01();
  p.gender = g < 0.1 ? gv : g < 0.55 ? 0.2 * gv : 0.8 + 0.2 * gv;
  const double a = rng.Uniform01(), av = rng.Uniform01();
  const double years = a < 0.12 ? 6 + 7 * av : a < 0.22 ? 13 + 5 * av : a < 0.85 ? 18 + 47 * av : 65 + 25 * av;
  p.age = MakeHumanAgeFromYears(years);
  const double adult = std::clamp((years - 18) / 40, 0.0, 1.0), old = std::clamp((years - 50) / 40, 0.0, 1.0);
  p.weight = std::clamp(0.42 + 0.12 * adult + 0.22 * rng.Normal(), 0.0, 1.0);
  p.muscle = std::clamp(0.5 - 0.15 * old + 0.2 * rng.Normal(), 0.0, 1.0);
  // MakeHuman's child and teen targets come out short without its height modifier (see the
  // presets): bring them to typical heights, and old bodies a little down.
  const double young_scale = 1.11 + 0.05 * (1 - p.gender);
  const double base = years <= 14   ? young_scale
                      : years < 20  ? young_scale + (1.0 - young_scale) * (years - 14) / 6
                      : years <= 60 ? 1.0
                                    : 1.0 - 0.04 * (years - 60) / 30;
  p.height_scale = base * (1 + std::clamp(0.04 * rng.Normal(), -0.1, 0.1));
  char name[48];
  std::snprintf(name, sizeof name, "sampled-%s%d", p.gender < 0.5 ? "f" : "m", int(years));
  p.name = name;
  return p;
}

std::vector<const MhcloProxy*> DrawOutfit(const MakeHumanWardrobe& wardrobe, const MakeHumanParams& params,
                                          core::RngStream& rng) {
  const bool female = params.gender < 0.5;
  // A proxy from `list`: with probability `prefer_share` one whose name starts with one of
  // `preferred` (when the wardrobe has any), else any.
  auto pick = [&](const std::vector<std::shared_ptr<const MhcloProxy>>& list,
                  std::initializer_list<const char*> preferred, double prefer_share) -> const MhcloProxy* {
    if (list.empty()) return nullptr;
    std::vector<const MhcloProxy*> pref, all;
    for (const auto& p : list) {
      all.push_back(p.get());
      for (const char* name : preferred)
        if (p->name.rfind(name, 0) == 0) {
          pref.push_back(p.get());
          break;
        }
    }
    const bool use_pref = rng.Uniform01() < prefer_share && !pref.empty();
    const auto& from = use_pref ? pref : all;
    return from[rng.UniformInt(uint32_t(from.size()))];
  };
  std::vector<const MhcloProxy*> out;
  if (const MhcloProxy* o = female ? pick(wardrobe.outfits, {"female"}, 0.8) : pick(wardrobe.outfits, {"male"}, 0.8))
    out.push_back(o);
  const bool bald = !female && rng.Uniform01() < 0.1;
  const MhcloProxy* hair =
      female ? pick(wardrobe.hair, {"long", "ponytail", "braid", "bob", "short03"}, 0.75)
             : pick(wardrobe.hair, {"short01", "short02", "short04", "afro"}, 0.85);
  if (hair && !bald) out.push_back(hair);
  if (rng.Uniform01() < 0.07)
    if (const MhcloProxy* hat = pick(wardrobe.hats, {}, 0.0)) out.push_back(hat);
  if (rng.Uniform01() < 0.92)
    if (const MhcloProxy* shoes = pick(wardrobe.shoes, {}, 0.0)) out.push_back(shoes);
  return out;
}

double BodyHeight(const BodyMesh& body) {
  if (body.vertices.empty()) return 0;
  float lo = body.vertices[0].y(), hi = lo;
  for (const auto& v : body.vertices) lo = std::min(lo, v.y()), hi = std::max(hi, v.y());
  return double(hi - lo);
}

double WaistWidth(const BodyMesh& body) {
  const double y0 = body.rest_joints[size_t(SkelJoint::kPelvis)].y();
  const double y1 = body.rest_joints[size_t(SkelJoint::kChest)].y();
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t v = 0; v < body.vertices.size(); ++v) {
    const auto& x = body.vertices[v];
    if (x.y() < y0 || x.y() > y1) continue;
    // Torso only: the arms hang beside the waist in the A-pose.
    if (v < body.skin.size()) {
      const auto& s = body.skin[v];
      const int j = s.joint[0];
      if (j != int(SkelJoint::kPelvis) && j != int(SkelJoint::kSpine) && j != int(SkelJoint::kChest))
        continue;
    }
    lo = std::min(lo, x.x());
    hi = std::max(hi, x.x());
  }
  return hi > lo ? double(hi - lo) : 0.0;
}

}  // namespace poseforest::renderer::assets
