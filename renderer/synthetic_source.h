#pragma once
// SyntheticRenderer: renders labelled synthetic depth frames in memory, as a pure function of
// (seed, index). Use one instance per thread (it owns an EGL/GLES context). Create returns with
// the context released, so an instance may be created on one thread and used on another; after
// that its context stays current on the rendering thread (re-binding every frame would cost
// ~0.5 ms on llvmpipe). To move an instance to another thread later, call ReleaseContext() on
// the old thread first; otherwise Render returns an error saying so. The training engine and
// the `poseforest render` command call exactly this API.

#include <cstdint>
#include <memory>
#include <string>

#include "renderer/scene.h"
#include "runtime/core/result.h"

namespace poseforest::renderer {

class EglRenderer;

/// Turns a pose about the vertical (through the root) so the person faces +Z: the facing
/// direction is (left hip - right hip + left shoulder - right shoulder) x up, horizontally.
/// The scene applies its own rotation afterwards.
void FaceForward(const SkelPositions& rest, Pose* pose);

class SyntheticRenderer {
 public:
  /// Creates the GL context, builds the procedural body family and uploads every body once.
  /// Fails (Status, never aborts) when no EGL display/context is available or the config is
  /// invalid (the message says which field).
  static core::Result<std::unique_ptr<SyntheticRenderer>> Create(const SceneConfig& config);
  ~SyntheticRenderer();
  SyntheticRenderer(const SyntheticRenderer&) = delete;
  SyntheticRenderer& operator=(const SyntheticRenderer&) = delete;

  /// Renders frame `index` of the stream `seed`. The same (seed, index) gives a byte-identical
  /// frame on the same renderer (and on any renderer with the same config and GL driver).
  core::Result<RenderedFrame> Render(uint64_t seed, uint64_t index);

  /// Releases the GL context from the calling thread so another thread may render next.
  void ReleaseContext();

  /// The scene that Render(seed, index) draws (people, poses, camera, mirroring).
  SceneSample Sample(uint64_t seed, uint64_t index) const;
  /// Renders an explicit scene (tests, docs). Noise uses scene.noise_key.
  core::Result<RenderedFrame> RenderScene(const SceneSample& scene);

  const SceneConfig& config() const { return config_; }
  /// Bodies in use (procedural family first, then config.bodies).
  const std::vector<BodyMesh>& bodies() const { return bodies_; }
  /// GL_RENDERER / GL_VERSION of the context, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
  std::string GlRendererString() const;

  /// CPU time of the calling thread in each stage since creation (milliseconds, summed over
  /// frames). With LP_NUM_THREADS=0, llvmpipe does all its work on the calling thread.
  struct StageTimes {
    double pose_ms = 0, draw_ms = 0, readback_ms = 0, post_ms = 0;
    uint64_t frames = 0;
  };
  const StageTimes& stage_times() const { return times_; }
  /// Waits for the GPU after drawing so draw and readback times are told apart (profiling only;
  /// slightly slower).
  void set_profile_stages(bool on) { profile_stages_ = on; }

 private:
  explicit SyntheticRenderer(const SceneConfig& config);

  SceneConfig config_;
  std::vector<BodyMesh> bodies_;
  std::vector<int> gpu_mesh_;  ///< EglRenderer mesh handle per body
  /// Per body: 1 when its rest pose is not the canonical T-pose, so sampled poses go through
  /// assets::AdaptPose (NeedsPoseAdaptation in scene_assets.h).
  std::vector<char> adapt_pose_;
  std::unique_ptr<EglRenderer> gl_;
  StageTimes times_;
  bool profile_stages_ = false;
  core::DepthImage clutter_depth_;  ///< RayCastClutter's output, reused across frames
};

}  // namespace poseforest::renderer
