#pragma once
// Rigged, skinned meshes through Assimp (glTF/GLB, FBX, Collada, ...) as canonical BodyMesh.
//
// * Geometry: every mesh that has bones is skinned with the scene's node pose (for the staged
//   files that is the bind pose): v = sum_b w_b * Global(b) * Offset(b) * v_mesh, so node
//   transforms (Casual_Female's rotated, scaled root) are applied; meshes without bones are
//   skipped (they are props: eyes, hair cards). A file whose meshes have no bones is an error.
// * Rest joints: the mapped bones' heads, Global(b) * origin, in the same frame.
// * Bones map through MeshRigNameMaps() (retarget.h: makehuman_default, mixamo, quaternius,
//   cesium_man; "mixamorig:" style prefixes are stripped); rig bones fold onto the canonical
//   joint of their nearest mapped ancestor (rig.h). Non-deforming bones (pole targets, bones
//   with no weight) carry no weight and so drop out.
// * Orientation: up = pelvis -> neck, left = hips and shoulders line, snapped to the nearest
//   axis permutation and rotated to the canonical frame (Y up, facing +Z, left = +X).
// * Units: the metre scale is picked from {1, 0.1, 0.01, 0.001} so the height lands in
//   0.5 .. 2.6 m (MakeHumanModel.fbx is in decimetres); when none does (Quaternius'
//   Casual_Female is 3.2 units tall), the body is scaled to `fallback_height_m`.
// * Translation: lowest vertex at y = 0, pelvis above x = z = 0. `part` is left empty.

#include <filesystem>

#include "renderer/assets/retarget.h"
#include "renderer/body.h"
#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

struct MeshLoadOptions {
  bool include_unskinned = false;  ///< also keep meshes without bones (rigidly on the nearest joint)
  double fallback_height_m = 1.7;  ///< height (m) for files in no metric unit; <= 0: error instead
  /// Name maps tried with MeshRigNameMaps() (winning ties): a job's bone map for a rig no built-in
  /// map knows (BoneMapFromPairs in retarget.h).
  std::vector<RigNameMap> bone_maps;
};

/// Loads a rigged mesh. Errors (all naming the file): kNotFound / kIo (Assimp's message
/// included) when it cannot be read; kInvalidArgument for a mesh without bones, unknown bone
/// names (listed, with the canonical joints missing), or a rig that lacks required joints.
core::Result<BodyMesh> LoadRiggedMesh(const std::filesystem::path& path, const MeshLoadOptions& options = {});

}  // namespace poseforest::renderer::assets
