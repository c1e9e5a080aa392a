#pragma once
// A body generated in code, no files: overlapping lofted primitives (superelliptic tubes with
// rounded caps, ellipsoids) around the canonical skeleton, skinned with smooth linear-blend
// weights along each limb chain, in the rest T-pose of skeleton.h (metres, Y up, facing +Z,
// left = +X, feet on y = 0). Part labels come from LabelBodyParts (renderer/part_labels.h).

#include <cstdint>
#include <string>
#include <vector>

#include "renderer/body.h"

namespace poseforest::renderer {

/// Shape parameters of a procedural body. Ratios are 1 for an average adult.
struct BodyShape {
  std::string name = "adult";
  double height_m = 1.75;       ///< standing height, metres (0.9 .. 2.1)
  double girth = 1.0;           ///< width/depth of trunk and limbs (0.7 slim .. 1.7 heavy)
  double belly = 0.0;           ///< extra abdominal depth (0 .. 1)
  double child = 0.0;           ///< 0 adult .. 1 small child (bigger head, shorter legs/arms)
  double female = 0.0;          ///< 0 .. 1: wider hips, narrower shoulders, chest
  double leg_ratio = 1.0;       ///< leg length relative to the average proportion
  double arm_ratio = 1.0;       ///< arm length relative to the average proportion
  double shoulder_ratio = 1.0;  ///< shoulder width relative to the average proportion
  double hair = 0.0;            ///< 0 short/none .. 1 voluminous; > 0.6 adds long hair down the back
  double clothing = 0.0;        ///< 0 tight .. 1 loose: inflates trunk and limbs (not hands/feet)
};

/// Mesh density. The default gives about 10k triangles after part-boundary refinement: 12-gon
/// cross-sections (1.7 mm from a true circle on a 5 cm limb) and rings every 2.9 cm. Rendering
/// time is about proportional to the triangle count (see bench/render).
struct BodyResolution {
  int segments = 12;          ///< vertices around each ring
  double rings_per_m = 35.0;  ///< rings per metre along each primitive (at least 2, plus caps)
};

/// Number of base shapes in the family (child .. heavy adult).
inline constexpr int kNumProceduralShapes = 16;

/// Base shape `i` of the family, 0 <= i < kNumProceduralShapes.
BodyShape ProceduralBaseShape(int i);

/// A base shape with small random variation (height +-3%, girth +-8%, limb ratios +-3%) and a
/// random hairstyle and clothing looseness, a pure function of (seed, variant). Variant 0 is the
/// base shape itself.
BodyShape VaryShape(const BodyShape& base, uint64_t seed, uint64_t variant);

/// Rest joint positions for a shape (metres, body frame, feet on y = 0).
SkelPositions ProceduralSkeleton(const BodyShape& shape);

/// The closed, skinned and part-labelled mesh for a shape.
BodyMesh MakeProceduralBody(const BodyShape& shape, const BodyResolution& res = {});

}  // namespace poseforest::renderer
