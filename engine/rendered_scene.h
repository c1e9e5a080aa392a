#pragma once
// The scene a rendered source draws from (SourceSpec -> renderer::SceneConfig): shared by the
// training sources (image_source.cpp) and the evaluation sets (engine/evaluation.cpp), so
// a job's test set renders the same kinds of people, bodies in the same order, as its training
// frames. Only for targets built with the renderer (POSEFOREST_HAS_RENDERER).

#include "engine/job_spec.h"
#include "renderer/scene.h"
#include "runtime/core/result.h"

namespace poseforest::engine {

/// Fills `scene` from a rendered `spec`: yaw range, 1..max_people people, the noise switch,
/// distances (m), the pose library's selected poses, and the bodies: the procedural family when
/// spec.procedural_bodies, then the 18 MakeHuman presets (and spec.makehuman_sampled_bodies
/// sampled ones, a share of them clothed: renderer::MakeHumanBodies), then spec.body_meshes in
/// job order.
/// Poses and bodies are loaded once per process (cached by file path, size and modification
/// time) and copied from there. Errors are the loaders', naming the file.
core::Status ApplySceneOptions(const SourceSpec& spec, renderer::SceneConfig* scene);

}  // namespace poseforest::engine
