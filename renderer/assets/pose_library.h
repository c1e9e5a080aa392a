#pragma once
// Pose libraries: mocap clips retargeted to canonical poses, thinned by the paper's
// 'furthest neighbour' clustering (Shotton et al. 2011, sec. 2.2), and stored in a small
// binary file so the thinning runs once.
//
// Pose distance: max over the 24 canonical joints of the Euclidean distance between the two
// poses applied to ReferenceRestJoints() (retarget.h), each centred on its pelvis (m).
// Subsampling: poses are visited in order; a pose is kept when it is at least `min_distance`
// from every pose kept so far. So kept poses are pairwise >= min_distance apart, and every
// dropped pose is within min_distance of a kept one.
//
// File layout (`.pfposes`, little-endian, the CRC covers every byte before it):
//   char[8]  magic "PFPOSES\0"
//   u32      format major (1), u32 format minor (0)
//   u32      endianness marker 0x01020304
//   u32      clip count C, u32 pose count N
//   f64      min_distance_m used to build it (0 = not thinned)
//   C times: u32 name length, name bytes (UTF-8 clip name, usually the file stem)
//   N times: u32 clip index, u32 frame, f32 root_translation[3] (m), f32 quaternion[24][4] (w x y z)
//   u32      CRC-32 (core::Crc32)
// A file of another major version is refused (kVersionMismatch naming both versions).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "renderer/assets/retarget.h"
#include "renderer/skeleton.h"
#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

inline constexpr uint32_t kPoseLibraryMajor = 1;
inline constexpr uint32_t kPoseLibraryMinor = 0;

/// Where a pose came from.
struct PoseSource {
  uint32_t clip = 0;   ///< index into PoseLibrary::clips
  uint32_t frame = 0;  ///< frame within the clip (after dropping reference frames)
};

/// Poses are stored for ReferenceRestJoints() (retarget.h). To pose a body whose rest pose
/// differs (MakeHuman's A-pose, a mesh's bind pose), pass each pose through
/// AdaptPose(pose, body.rest_joints) first.
struct PoseLibrary {
  std::vector<std::string> clips;   ///< clip names (file stems)
  std::vector<Pose> poses;          ///< canonical poses (retargeted to ReferenceRestJoints)
  std::vector<PoseSource> sources;  ///< one per pose
  double min_distance_m = 0;        ///< the subsampling threshold used (0 = none)
};

/// Pelvis-centred joint positions (m) of `pose` on `rest`, as 72 floats (x, y, z per joint).
std::array<float, 3 * kNumSkelJoints> PoseSignature(const Pose& pose,
                                                    const SkelPositions& rest = ReferenceRestJoints());

/// max_j |a_j - b_j| for two signatures (m).
double PoseDistance(const std::array<float, 3 * kNumSkelJoints>& a,
                    const std::array<float, 3 * kNumSkelJoints>& b);

/// Greedy threshold ('furthest neighbour') subsampling; returns the indices kept, ascending.
std::vector<size_t> SubsamplePoses(const std::vector<std::array<float, 3 * kNumSkelJoints>>& signatures,
                                   double min_distance_m);

/// Same, on poses (signatures on ReferenceRestJoints()).
std::vector<size_t> SubsamplePoses(const std::vector<Pose>& poses, double min_distance_m);

/// The BVH files named by `inputs`: files as given, folders searched recursively for *.bvh,
/// following linked folders but never into an ancestor (sorted by path so the order is
/// deterministic; a file reached by two paths once, under the first). Errors: a missing input,
/// or a folder without any .bvh file (kNotFound).
core::Result<std::vector<std::filesystem::path>> CollectBvhFiles(
    const std::vector<std::filesystem::path>& inputs);

/// Clip-level train/test split: a clip is in the test set when a hash of (its file stem, seed)
/// falls below test_fraction. Deterministic, independent of the order and of the other clips.
bool IsTestClip(const std::string& clip_name, double test_fraction, uint64_t seed = 0);

struct ClipSplit {
  std::vector<std::filesystem::path> train, test;
};
ClipSplit SplitClips(const std::vector<std::filesystem::path>& files, double test_fraction,
                     uint64_t seed = 0);

struct BuildOptions {
  double min_distance_m = 0.05;  ///< 0 keeps every frame
  RetargetOptions retarget;      ///< facing per frame by default
  int max_frames_per_clip = -1;  ///< -1 = all
  /// Called after each clip: (clip index, clip count, file, frames read, poses so far).
  std::function<void(size_t, size_t, const std::filesystem::path&, size_t, size_t)> progress;
};

/// Loads, retargets (onto ReferenceRestJoints) and subsamples the clips. Any clip that fails
/// to load fails the build with that clip's error.
core::Result<PoseLibrary> BuildPoseLibrary(const std::vector<std::filesystem::path>& files,
                                           const BuildOptions& options = {});

/// Serialises to bytes / parses bytes (`source` names the data in errors).
std::vector<uint8_t> SerializePoseLibrary(const PoseLibrary& library);
core::Result<PoseLibrary> ParsePoseLibrary(const std::vector<uint8_t>& bytes, const std::string& source);

core::Status SavePoseLibrary(const PoseLibrary& library, const std::filesystem::path& path);
core::Result<PoseLibrary> LoadPoseLibrary(const std::filesystem::path& path);

}  // namespace poseforest::renderer::assets
