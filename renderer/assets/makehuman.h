#pragma once
// MakeHuman 1.1 ("hm08") bodies from the CC0 kit in
// /work/shared/data/meshes/makehuman_hm08_kit: base.obj (group `body` only), macro targets
// weighted like MakeHuman's macro modifiers, joints from rigs/default.mhskel, skin weights from
// rigs/default_weights.mhw folded onto the canonical skeleton.
//
// Output frame: the canonical body frame (metres, Y up, faces +Z, left = +X; the hm08 mesh is
// already oriented that way, in decimetres), translated so the lowest vertex is at y = 0 and
// the pelvis is at x = z = 0. The rest pose is MakeHuman's A-pose (arms about 45 degrees down),
// not a T-pose: retargeting (retarget.h) works from any rest pose. `part` is left empty.
//
// Macro weights (MakeHuman apps/humanmodifier.py, MacroModifier):
//   gender g in [0,1] (0 female, 1 male): female = 1-g, male = g;
//   age a in [0,1]: a < 0.5: baby = max(0, 1 - a/0.1875), young = max(0, (a-0.1875)/0.3125),
//     child = max(0, min(1, a/0.1875) - young), old = 0;  a >= 0.5: old = 2a-1, young = 1-old.
//     (a = 0 is 1 year, 0.1875 is 11 years, 0.5 is 25 years, 1 is 90 years);
//   muscle m, weight w in [0,1]: min = max(0, 1-2x), max = max(0, 2x-1), average = 1-min-max;
//   race: African, Asian, Caucasian each 1/3 (averaged).
// Target {race}-{gender}-{age} weighs race*gender*age;
// universal-{gender}-{age}-{muscle}muscle-{weight}weight weighs gender*age*muscle*weight.
// Height and proportion targets are not in the kit: `height_scale` scales uniformly.

#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "renderer/assets/mhclo.h"
#include "renderer/assets/rig.h"
#include "renderer/body.h"
#include "runtime/core/result.h"
#include "runtime/core/rng.h"

namespace poseforest::renderer::assets {

/// Macro parameters of a MakeHuman body (MakeHuman slider values, all in [0, 1]).
struct MakeHumanParams {
  std::string name = "average";
  double gender = 0.5;        ///< 0 female .. 1 male
  double age = 0.5;           ///< 0 = 1 year, 0.1875 = 11, 0.5 = 25, 1 = 90 years
  double muscle = 0.5;        ///< 0 min .. 1 max
  double weight = 0.5;        ///< 0 min .. 1 max
  double height_scale = 1.0;  ///< uniform scale after the targets (stands in for height targets)
};

/// MakeHuman age slider value for an age in years (1..90).
double MakeHumanAgeFromYears(double years);

/// At least 15 presets from child to heavy and old adults, male and female.
const std::vector<MakeHumanParams>& MakeHumanPresets();

/// Small random height/weight variation of a preset (paper sec. 2.3): height_scale * (1 +
/// N(0, 0.03)) clamped to +-8 %, weight + N(0, 0.06) clamped to [0, 1]. Deterministic in `rng`.
MakeHumanParams VaryMakeHuman(const MakeHumanParams& base, core::RngStream& rng);

/// A continuously sampled body (more varied than the 18 presets): macro values drawn from an adult-heavy population
/// (about 12 % children 6-12 years, 10 % teens 13-17, 63 % adults 18-64, 15 % 65-90; mostly
/// clearly male or female, 10 % anywhere between; weight and muscle spread over the whole range,
/// heavier and less muscular with age) and a height_scale that brings MakeHuman's short child
/// targets to typical heights, with +-4 % (1 sigma) individual variation. Deterministic in `rng`.
MakeHumanParams SampleMakeHumanParams(core::RngStream& rng);

/// A proxy (garment, hair, hat, shoes) fitted to a MakeHuman body, in the body's frame (metres,
/// rest pose), skinned with the base mesh's rig weights mixed through the proxy's binding
/// (MakeHuman's Proxy.getVertexWeights), folded onto the canonical skeleton.
struct FittedProxy {
  std::string name;
  ProxyKind kind = ProxyKind::kOutfit;
  std::vector<Eigen::Vector3f> vertices;           ///< metres, body frame
  std::vector<std::array<uint32_t, 3>> triangles;  ///< indices into vertices
  std::vector<SkinInfluence> skin;                 ///< one per vertex
  /// Per vertex: the body vertex beneath it (index into the body's vertices): the body vertex
  /// nearest (in the neutral base mesh) to its heaviest bound base vertex. It takes that vertex's
  /// part label, so clothes are labelled as the body part they cover.
  std::vector<uint32_t> body_vertex;
};

/// A body with proxies fitted to it. body is exactly what Build gives for the same params except
/// that body and proxies are lifted together onto the floor (shoes' soles at y = 0).
struct DressedMakeHuman {
  BodyMesh body;                     ///< part empty
  std::vector<FittedProxy> proxies;  ///< in the order given
  /// Per body vertex: 1 when an outfit's delete_verts hides it (shoes' are not used: their soles
  /// leave the heel's edge open).
  std::vector<char> covered;
};

/// One outfit for a body, drawn from `rng`: an outfit (mostly of the body's gender: 80 %), a
/// hairstyle (long styles mostly on female bodies; 10 % of male bodies bald), a hat (7 %) and
/// shoes (92 %). Pointers into `wardrobe`.
std::vector<const MhcloProxy*> DrawOutfit(const MakeHumanWardrobe& wardrobe, const MakeHumanParams& params,
                                          core::RngStream& rng);

/// The loaded kit (base mesh, rig, weights; targets are read on first use and cached).
/// Thread-compatible: Build() is const but fills the target cache under a mutex.
class MakeHumanKit {
 public:
  /// Loads `kit_dir` (the makehuman_hm08_kit folder). Errors name the file (and line for OBJ).
  static core::Result<std::unique_ptr<MakeHumanKit>> Load(const std::filesystem::path& kit_dir);
  ~MakeHumanKit();

  /// Builds a body. Errors: a missing or malformed target file.
  core::Result<BodyMesh> Build(const MakeHumanParams& params) const;

  /// Builds a body and fits `proxies` to it (MakeHuman's proxy fitting on the morphed base mesh,
  /// helper vertices included). Errors: Build's.
  core::Result<DressedMakeHuman> BuildDressed(const MakeHumanParams& params,
                                              const std::vector<const MhcloProxy*>& proxies) const;

  /// Number of vertices of the `body` group (the output's vertex count).
  size_t body_vertex_count() const;
  /// Number of vertices of base.obj, helpers included (19,158 for hm08): the bound of proxy indices.
  size_t base_vertex_count() const;

  struct Impl;

 private:
  MakeHumanKit();
  std::unique_ptr<Impl> impl_;
};

/// Height of a body: max vertex y - min vertex y (m).
double BodyHeight(const BodyMesh& body);
/// Width of a body: max vertex x - min vertex x at the waist (pelvis..spine height band) (m).
double WaistWidth(const BodyMesh& body);

}  // namespace poseforest::renderer::assets
