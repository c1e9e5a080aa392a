#pragma once
// Mocap poses and MakeHuman bodies for a SceneConfig: the glue between renderer/assets (pose
// libraries, the MakeHuman kit) and the scene sampler, shared by `poseforest render` and the
// training workers (engine/image_source.cpp), so both select clips and build bodies the same way.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/pose_library.h"
#include "renderer/body.h"
#include "renderer/skeleton.h"
#include "runtime/core/result.h"

namespace poseforest::renderer {

/// Which clips of a pose library a scene draws poses from (clip-level split, see
/// assets::IsTestClip: a clip is a test clip when a hash of (clip name, split seed) falls below
/// the test fraction).
enum class ClipSet { kAll, kTrain, kTest };

/// "all", "train", "test".
const char* ClipSetName(ClipSet set);

/// A pose library file and the clips to use from it.
struct PoseSelection {
  std::filesystem::path library;  ///< a .pfposes file (poseforest-poselib build)
  ClipSet clips = ClipSet::kAll;
  double test_fraction = 0.2;  ///< share of clips in the test set, [0, 1]
  uint64_t split_seed = 0;     ///< seed of the clip split hash
};

/// Poses of `library` whose clip is in `set`, in library order. `clip_names`, when given,
/// receives the names of the selected clips that contributed at least one pose (sorted).
std::vector<Pose> SelectLibraryPoses(const assets::PoseLibrary& library, ClipSet set, double test_fraction,
                                     uint64_t split_seed, std::vector<std::string>* clip_names = nullptr);

/// Loads selection.library and keeps the poses of the selected clips. Errors: a missing or
/// unreadable library (the loader's error, naming the file); test_fraction outside [0, 1]
/// (kInvalidArgument); an empty selection (kInvalidArgument naming the file, the clip set, the
/// split and how many of its clips were selected).
core::Result<std::shared_ptr<const std::vector<Pose>>> LoadPoseSelection(const PoseSelection& selection);

/// One body per assets::MakeHumanPresets() entry (18, child to heavy adult) from the hm08 kit
/// folder, each labelled with LabelBodyParts + RefinePartBoundaries (so SyntheticRenderer::Create
/// does not label them again). Their rest pose is MakeHuman's A-pose: the renderer adapts poses
/// to it (see SceneConfig::bodies). Errors: the kit loader's (naming the file).
core::Result<std::vector<BodyMesh>> MakeHumanPresetBodies(const std::filesystem::path& kit_dir);

/// MakeHuman bodies beyond the 18 presets: continuously sampled shapes, and clothes,
/// hair and shoes. Every body is a pure function of these options and the kit (and the clothes
/// folder), so every worker of a job builds the identical set.
struct MakeHumanBodyOptions {
  /// Bodies sampled continuously over the macro targets (assets::SampleMakeHumanParams), after
  /// the presets; body k (k = 0.. over presets then sampled bodies) draws from its own random
  /// stream of `seed`.
  int sampled_bodies = 0;
  uint64_t seed = 1;
  /// Share of the bodies (presets and sampled, each decided by its own stream) that wear an
  /// outfit, hair and shoes from clothes_dir (assets::DrawOutfit). 0 = none.
  double clothed_share = 0.0;
  std::filesystem::path clothes_dir;  ///< MakeHuman .mhclo proxies; needed when clothed_share > 0
};

/// The 18 presets then options.sampled_bodies sampled bodies, dressed as the options say, each
/// labelled (LabelBodyParts + RefinePartBoundaries; clothes take the part of the body vertex
/// beneath them, see AssembleDressedBody). Errors: the kit's and the wardrobe's loaders (naming
/// the file); options out of range (kInvalidArgument).
core::Result<std::vector<BodyMesh>> MakeHumanBodies(const std::filesystem::path& kit_dir,
                                                    const MakeHumanBodyOptions& options);

/// One labelled mesh from a dressed body: the body labelled as MakeHumanPresetBodies does, then
/// each proxy appended with the part of its body_vertex (outfits and shoes then get
/// RefinePartBoundaries like the skin; hair and hats do not). The result is an open mesh (the
/// renderer draws it without back-face culling, so open sleeves and hems do not turn
/// see-through).
/// The skin under the clothes stays by default: where it pokes through a tight garment the depth
/// test shows the outer of two surfaces ~1 cm apart, labelled with the same part. With
/// hide_covered_skin, body triangles whose three vertices an outfit's delete_verts lists are
/// removed (MakeHuman's way, fewer triangles), but the skin-tight outfits (female_casualsuit01,
/// female_sportsuit01) then leave 1-pixel holes along the silhouette and few-mm dents where the
/// garment dips under the skin (tests/renderer/test_makehuman_clothes_render.cpp).
BodyMesh AssembleDressedBody(assets::DressedMakeHuman dressed, bool hide_covered_skin = false);

/// True when `rest` differs from the canonical reference T-pose (assets::ReferenceRestJoints())
/// by more than `max_angle_deg` in the direction of any bone (e.g. MakeHuman's A-pose: arms
/// about 45-60 degrees down). Poses (library or procedural, made for the T-pose) must then be
/// passed through assets::AdaptPose before posing such a body. The default tolerance leaves
/// T-pose bodies of other proportions alone (the procedural family's feet are ~10 deg off).
bool NeedsPoseAdaptation(const SkelPositions& rest, double max_angle_deg = 20.0);

}  // namespace poseforest::renderer
