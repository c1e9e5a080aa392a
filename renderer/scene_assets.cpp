#include "renderer/scene_assets.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <sstream>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/retarget.h"
#include "renderer/part_labels.h"

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
  auto kit = assets::MakeHumanKit::Load(kit_dir);
  if (!kit.ok()) return kit.status();
  std::vector<BodyMesh> bodies;
  for (const assets::MakeHumanParams& params : assets::MakeHumanPresets()) {
    auto body = (*kit)->Build(params);
    if (!body.ok()) return body.status();
    if (body->part.empty()) {  // the same labelling SyntheticRenderer::Create would apply
      LabelBodyParts(*body);
      RefinePartBoundaries(*body, 2);
    }
    bodies.push_back(std::move(body).value());
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
