#pragma once
// Procedural poses: random, anatomically plausible bone rotations within per-joint limits
// (swing of the bone direction + twist about it), used when no mocap is supplied. Each pose is
// a pure function of (seed, index).

#include <cstdint>

#include "renderer/skeleton.h"

namespace poseforest::renderer {

/// Mixture of pose families; the probabilities are normalized.
struct PoseSamplerConfig {
  double p_standing = 0.35;     ///< upright, legs nearly straight
  double p_walking = 0.25;      ///< one leg forward, one back, knees bent
  double p_crouching = 0.12;    ///< hips and knees strongly flexed
  double p_kicking = 0.10;      ///< one leg raised
  double p_wide = 0.10;         ///< legs apart
  double p_free = 0.08;         ///< every joint independent within its full limits
  double p_arms_relaxed = 0.4;  ///< chance that an arm hangs near the body
};

/// A random pose with identity root translation (the scene grounds the feet). Rotations are
/// body-frame (see Pose); the person stays facing roughly +Z (the scene adds the yaw).
Pose SampleProceduralPose(uint64_t seed, uint64_t index, const PoseSamplerConfig& config = {});

/// Re-poses one or both arms of `pose` (body-frame rotations of a T-pose skeleton, as
/// SampleProceduralPose makes and pose libraries hold) as a pure function of (seed, index): the
/// upper arm reaching forward, toward or across the camera side of the body (the person faces
/// +Z), or folded so the hand comes near the face, chest or other shoulder; elbow flexion and
/// wrist within the procedural sampler's joint limits. The trunk, head and legs are kept; the arm
/// follows its collar, so a twisted chest carries it along.
void PerturbArms(uint64_t seed, uint64_t index, Pose* pose);

/// Leans the upper body of `pose` as a pure function of (seed, index): everything from the spine
/// up (spine, chest, neck, head, both arms) turns about the spine joint, 5 to 35 degrees forward
/// (over a desk, toward a screen) or up to 15 degrees back, and up to 15 degrees to either side.
/// Bone lengths and the arms' pose relative to the chest are kept; pelvis and legs are untouched.
void LeanTrunk(uint64_t seed, uint64_t index, Pose* pose);

/// Sits `pose` down as a pure function of (seed, index): both thighs flexed 65 to 100 degrees
/// from the pelvis's vertical (a chair, a sofa, a desk), 0 to 12 degrees apart, the knees flexed
/// 60 to 105 degrees, the feet near flat; pelvis, trunk and arms untouched. No chair is drawn:
/// the scene grounds the lowest point, so the person sits on nothing a depth camera would see
/// (the seat is background to the forest either way).
void SitDown(uint64_t seed, uint64_t index, Pose* pose);

}  // namespace poseforest::renderer
