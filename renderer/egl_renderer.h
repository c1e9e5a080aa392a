#pragma once
// Headless OpenGL ES 3 rendering of skinned bodies into linear depth (mm) + part labels.
//
// Display: EGL_PLATFORM_SURFACELESS_MESA (Mesa llvmpipe / any Mesa GPU driver), else an EGL
// device (EGL_EXT_platform_device: NVIDIA headless), else the default display. One context per
// EglRenderer; use each renderer from one thread at a time: calls make its context current on
// the calling thread when needed, and ReleaseCurrent() hands it over to another thread (Create
// returns with the context released). Skinning runs in the vertex shader with per-joint 3x4
// matrices.
//
// Projection: exactly core::CameraIntrinsics. A point projecting to (u, v) = (fx X/Z + cx,
// fy Y/Z + cy) covers the pixel whose centre is (u, v) = (column, row): pixel centres are at
// integer (u, v), and row 0 is the top of the image (we render rows top-down, no flip needed).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "renderer/body.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/result.h"

namespace poseforest::renderer {

/// camera_from_rest transform per skeleton joint (rows of a 3x4 matrix; metres).
using JointMatrices = std::array<Eigen::Matrix<float, 3, 4>, kNumSkelJoints>;

class EglRenderer {
 public:
  /// Creates a display + GLES 3 context and an offscreen framebuffer of camera.width x height.
  /// Depth planes are near_m..far_m metres (beyond 65.535 m depth saturates).
  static core::Result<std::unique_ptr<EglRenderer>> Create(const core::CameraIntrinsics& camera,
                                                           double near_m = 0.1, double far_m = 30.0);
  ~EglRenderer();
  EglRenderer(const EglRenderer&) = delete;
  EglRenderer& operator=(const EglRenderer&) = delete;

  /// GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)".
  const std::string& gl_renderer() const { return gl_renderer_; }
  /// GL_VERSION and the EGL platform used, e.g. "OpenGL ES 3.2 Mesa 22.3.6 [surfaceless]".
  const std::string& gl_version() const { return gl_version_; }

  /// Uploads a mesh once (rest vertices, skin, part per vertex); returns its handle. Each
  /// triangle takes one part (flat shading): the majority of its vertices' parts.
  core::Result<int> UploadMesh(const BodyMesh& mesh);

  /// Starts a frame: depth 0 / background label everywhere.
  core::Status BeginFrame();
  /// Draws mesh `handle` with per-joint camera_from_rest matrices. mirror_labels swaps every
  /// part through core::MirrorPart (use with mirrored geometry). `person` (0..255) is written to
  /// the person image ReadFrame can return (0 = no person: use 1-based ids).
  void Draw(int handle, const JointMatrices& camera_from_rest, bool mirror_labels, int person = 0);
  /// Makes this renderer's context current on the calling thread (done by every call that needs
  /// it). Fails if the context is still current on another thread.
  core::Status MakeCurrent();
  /// Releases the context from the calling thread, so another thread may use this renderer.
  void ReleaseCurrent();
  /// Waits for the GPU (only for profiling: ReadFrame synchronizes anyway).
  void Finish();
  /// Reads the frame back: depth in mm (rounded linear camera z; 0 = nothing) and labels, and
  /// when `people` is given the `person` of the nearest draw per pixel (0 = none).
  /// A GL error (e.g. out of memory) is returned as a Status.
  core::Status ReadFrame(core::DepthImage* depth, core::LabelImage* labels,
                         core::LabelImage* people = nullptr);

  const core::CameraIntrinsics& camera() const { return camera_; }

 private:
  struct Impl;
  explicit EglRenderer(std::unique_ptr<Impl> impl, const core::CameraIntrinsics& camera);

  std::unique_ptr<Impl> impl_;
  core::CameraIntrinsics camera_;
  std::string gl_renderer_, gl_version_;
  std::vector<uint8_t> readback_;
};

/// The OpenGL clip-from-camera matrix for these intrinsics (rows top-down, see above).
Eigen::Matrix4f ProjectionMatrix(const core::CameraIntrinsics& camera, double near_m, double far_m);

}  // namespace poseforest::renderer
