#include "renderer/scene_assets.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <sstream>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/retarget.h"
#include "renderer/part_labels.h"
#include "runtime/core/rng.h"

namespace poseforest::renderer {

using core::ErrorCode;
using core::Status;

const char* ClipSetName(ClipSet set) {
  switch (set) {
    case ClipSet::kTrain:
      return "train";
    case ClipSet::kTest:
      return "test";
    case ClipSet::kAll:
      break;
  }
  return "all";
}

std::vector<Pose> SelectLibraryPoses(const assets::PoseLibrary& library, ClipSet set, double test_fraction,
                                     uint64_t split_seed, std::vector<std::string>* clip_names) {
  // Decide per clip once (the hash is per clip name, not per pose).
  std::vector<char> keep(library.clips.size(), 0);
  for (size_t c = 0; c < library.clips.size(); ++c) {
    const bool test = assets::IsTestClip(library.clips[c], test_fraction, split_seed);
    keep[c] = set == ClipSet::kAll || (set == ClipSet::kTest) == test;
  }
  std::vector<Pose> out;
  std::set<std::string> used;
  for (size_t i = 0; i < library.poses.size(); ++i) {
    const uint32_t clip = i < library.sources.size() ? library.sources[i].clip : 0;
    if (clip >= keep.size() || !keep[clip]) continue;
    out.push_back(library.poses[i]);
    if (clip_names) used.insert(library.clips[clip]);
  }
  if (clip_names) clip_names->assign(used.begin(), used.end());
  return out;
}

core::Result<std::shared_ptr<const std::vector<Pose>>> LoadPoseSelection(const PoseSelection& selection) {
  if (!(selection.test_fraction >= 0 && selection.test_fraction <= 1)) {
    std::ostringstream s;
    s << selection.library.string() << ": test fraction " << selection.test_fraction << " must be in [0, 1]";
    return Status(ErrorCode::kInvalidArgument, s.str());
  }
  auto lib = assets::LoadPoseLibrary(selection.library);
  if (!lib.ok()) return lib.status();
  std::vector<std::string> names;
  auto poses = std::make_shared<std::vector<Pose>>(
      SelectLibraryPoses(*lib, selection.clips, selection.test_fraction, selection.split_seed, &names));
  if (poses->empty()) {
    std::ostringstream s;
    s << selection.library.string() << ": no poses in the " << ClipSetName(selection.clips) << " clips ("
      << names.size() << " of " << lib->clips.size() << " clips selected with test fraction "
      << selection.test_fraction << ", split seed " << selection.split_seed
      << "); use other clips, another test fraction or split seed, or a bigger library";
    return Status(ErrorCode::kInvalidArgument, s.str());
  }
  return std::shared_ptr<const std::vector<Pose>>(std::move(poses));
}

core::Result<std::vector<BodyMesh>> MakeHumanPresetBodies(const std::filesystem::path& kit_dir) {
  return MakeHumanBodies(kit_dir, MakeHumanBodyOptions{});
}

BodyMesh AssembleDressedBody(assets::DressedMakeHuman dressed, bool hide_covered_skin) {
  BodyMesh body = std::move(dressed.body);
  LabelBodyParts(body);  // the same labelling SyntheticRenderer::Create would apply
  if (hide_covered_skin && !dressed.proxies.empty()) {
    std::erase_if(body.triangles, [&](const std::array<uint32_t, 3>& t) {
      return dressed.covered[t[0]] && dressed.covered[t[1]] && dressed.covered[t[2]];
    });
  }
  RefinePartBoundaries(body, 2);
  for (assets::FittedProxy& p : dressed.proxies) {
    BodyMesh g;
    g.vertices = std::move(p.vertices);
    g.triangles = std::move(p.triangles);
    g.skin = std::move(p.skin);
    g.rest_joints = body.rest_joints;
    g.part.reserve(p.body_vertex.size());
    for (uint32_t b : p.body_vertex) g.part.push_back(body.part[b]);
    // Smooth part boundaries on clothes and shoes as on the skin: their own skin weights put the
    // split points where the body's labelling would. Not on hair and hats: their weights follow
    // the head while long hair lies over the back (labelled torso), so split points would come
    // out as slivers of head.
    if (p.kind == assets::ProxyKind::kOutfit || p.kind == assets::ProxyKind::kShoes) RefinePartBoundaries(g, 2);
    const uint32_t first = uint32_t(body.vertices.size());
    body.vertices.insert(body.vertices.end(), g.vertices.begin(), g.vertices.end());
    body.skin.insert(body.skin.end(), g.skin.begin(), g.skin.end());
    body.part.insert(body.part.end(), g.part.begin(), g.part.end());
    for (const auto& t : g.triangles) body.triangles.push_back({first + t[0], first + t[1], first + t[2]});
    body.name += "+" + p.name;
  }
  return body;
}

core::Result<std::vector<BodyMesh>> MakeHumanBodies(const std::filesystem::path& kit_dir,
                                                    const MakeHumanBodyOptions& options) {
  if (options.sampled_bodies < 0 || options.sampled_bodies > 10000)
    return Status(ErrorCode::kInvalidArgument, "MakeHuman bodies: sampled_bodies " +
                                                   std::to_string(options.sampled_bodies) + " must be in 0..10000");
  if (!(options.clothed_share >= 0 && options.clothed_share <= 1))
    return Status(ErrorCode::kInvalidArgument, "MakeHuman bodies: clothed_share must be in 0..1");
  auto kit = assets::MakeHumanKit::Load(kit_dir);
  if (!kit.ok()) return kit.status();
  assets::MakeHumanWardrobe wardrobe;
  if (options.clothed_share > 0) {
    auto loaded = assets::LoadMakeHumanWardrobe(options.clothes_dir, (*kit)->base_vertex_count());
    if (!loaded.ok()) return loaded.status();
    wardrobe = std::move(loaded).value();
  }
  const auto& presets = assets::MakeHumanPresets();
  const size_t total = presets.size() + size_t(options.sampled_bodies);
  std::vector<BodyMesh> bodies;
  bodies.reserve(total);
  constexpr uint64_t kBodyStream = 0xB0D1E5;  // body k: shape from stream 0, outfit from stream 1
  for (size_t k = 0; k < total; ++k) {
    assets::MakeHumanParams params;
    if (k < presets.size()) {
      params = presets[k];
    } else {
      core::RngStream shape_rng(core::CounterRng(options.seed, kBodyStream, k, 0));
      params = assets::SampleMakeHumanParams(shape_rng);
      params.name = std::to_string(k - presets.size()) + "-" + params.name;
    }
    std::vector<const assets::MhcloProxy*> outfit;
    if (options.clothed_share > 0) {
      core::RngStream outfit_rng(core::CounterRng(options.seed, kBodyStream, k, 1));
      if (outfit_rng.Uniform01() < options.clothed_share) outfit = assets::DrawOutfit(wardrobe, params, outfit_rng);
    }
    auto dressed = (*kit)->BuildDressed(params, outfit);
    if (!dressed.ok()) return dressed.status();
    bodies.push_back(AssembleDressedBody(std::move(dressed).value()));
  }
  return bodies;
}

bool NeedsPoseAdaptation(const SkelPositions& rest, double max_angle_deg) {
  const SkelPositions& ref = assets::ReferenceRestJoints();
  const double min_cos = std::cos(max_angle_deg * std::numbers::pi / 180.0);
  for (int j = 1; j < kNumSkelJoints; ++j) {
    const int p = kSkelParent[size_t(j)];
    const Eigen::Vector3d a = rest[size_t(j)] - rest[size_t(p)];
    const Eigen::Vector3d b = ref[size_t(j)] - ref[size_t(p)];
    // Very short bones (collars sitting on the spine) have no reliable direction.
    if (a.norm() < 0.02 || b.norm() < 0.02) continue;
    if (a.normalized().dot(b.normalized()) < min_cos) return true;
  }
  return false;
}

}  // namespace poseforest::renderer
