#pragma once
// Body-part labels (the 31 parts of core::Part) for any skinned body, from its rest skeleton and
// skin weights. Definitions (see renderer/README.md): the dominant skinning joint decides the
// region (head, neck, torso, left/right arm, left/right leg); position along the limb decides
// the band (upper arm | elbow | lower arm | wrist | hand; upper leg | knee | lower leg | ankle |
// foot); the mid-sagittal plane decides left/right of head and torso; height decides upper/lower.

#include <cstdint>

#include "renderer/body.h"

namespace poseforest::renderer {

/// Band sizes as fractions of the body's own bone lengths (so children and adults agree).
struct PartBands {
  double elbow_half = 0.20;       ///< elbow band half-width, fraction of the forearm length
  double wrist_before = 0.16;     ///< wrist band extent up the forearm, fraction of the forearm
  double wrist_after = 0.22;      ///< wrist band extent into the hand, fraction of the hand length
  double knee_half = 0.14;        ///< knee band half-width, fraction of the shin length
  double ankle_above = 0.14;      ///< ankle band extent up the shin, fraction of the shin length
  double foot_below = 0.05;       ///< foot starts this far below the ankle, fraction of the shin
  double shoulder_radius = 0.38;  ///< shoulder ball radius, fraction of the upper arm length
};

/// Fills mesh.part (one core::Part per vertex) from mesh.rest_joints, mesh.vertices and
/// mesh.skin. Requires skin.size() == vertices.size() (checked).
void LabelBodyParts(BodyMesh& mesh, const PartBands& bands = {});

/// Splits every edge whose two vertices carry different parts at its midpoint (new vertices get
/// averaged skin weights and their own LabelPoint part), `levels` times. The renderer shades
/// each triangle with one part, so this shrinks the sawtooth along part boundaries by 2^levels
/// while keeping the mesh watertight (edges are split, not triangles: no T-junctions).
void RefinePartBoundaries(BodyMesh& mesh, int levels = 2, const PartBands& bands = {});

/// The part of one rest-pose point given its dominant skinning joint (a SkelJoint index).
uint8_t LabelPoint(const SkelPositions& rest, const Eigen::Vector3f& p, int dominant_joint,
                   const PartBands& bands = {});

}  // namespace poseforest::renderer
