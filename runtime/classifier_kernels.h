#pragma once
// The classifier's kernels (classifier.cpp runs them over chunks of the foreground pixels): a
// tree walk per instruction set and the combination of the trees' leaves into sums and labels.
// For the classifier only (not a public API).

#include <cstddef>
#include <cstdint>

#include "runtime/classifier.h"
#include "runtime/core/forest.h"

// Kernels are chosen at compile time from the target (the project builds with -march=native);
// the portable one always exists and is what other architectures run.
#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__) && defined(__BMI2__)
#define POSEFOREST_CLASSIFIER_AVX512 1
#endif
#if defined(__AVX2__) && defined(__BMI2__)
#define POSEFOREST_CLASSIFIER_AVX2 1
#endif

namespace poseforest::runtime::detail {


/// Foreground pixels per unit of work: one thread walks every tree over them, then combines.
constexpr int kChunk = 1024;
/// Slack after every per-pixel array: vector loads read up to 16 entries past the end.
constexpr int kPad = 16;
/// Vectors of 8 traversals interleaved by the AVX2 kernel (2 to 4 measure the same).
constexpr int kAvx2Groups = 4;
/// Traversals interleaved by the portable kernel (16: 20% slower; 64: the same as 32).
constexpr int kPortableLanes = 32;
/// Vectors of 16 traversals interleaved by the AVX-512 kernel: 2 hide the load latency
/// (1 is 1.5x slower; 3 and 4 measure the same as 2).
constexpr int kAvx512Groups = 2;


/// What a traversal kernel reads.
struct FrameView {
  int width = 0, height = 0;
  uint16_t background_mm = 0;
  /// Probes beyond the image read the pixel on its edge (core::ProbeEdge::kClamp) instead of
  /// background_mm: the kernels' kClamp must equal it.
  bool clamp = false;
  const uint16_t* probe = nullptr;
  const int32_t* xb = nullptr;
  const int32_t* yb = nullptr;
  const float* scale = nullptr;
};

/// Walks one tree for the first `end` pixels of `f` with kLanes traversals interleaved;
/// writes pixel i's leaf index to out[i]. The root must be a split node. (kPortableLanes)
/// kClamp: f.clamp (the forest's probe edge), a template argument so that the paper's rule
/// pays nothing for the other.
template <int kLanes, bool kClamp>
void TraversePortable(const core::Node* nodes, const FrameView& f, int end, uint32_t* out);

/// Sums leaf rows over trees and takes the argmax for `count` foreground pixels whose leaf
/// in tree t is leaves[t * leaves_stride + i] and whose linear index is pixel[i]. The sums
/// also go to fg_sums[i * stride...] unless it is null (the compact foreground output).
void CombinePortable(const core::Forest& forest, const uint32_t* leaves, size_t leaves_stride,
                     const uint32_t* pixel, int count, uint16_t* fg_sums, Classification* out);

#ifdef POSEFOREST_CLASSIFIER_AVX512
/// TraversePortable (end <= kChunk) with kGroups vectors of 16 lanes interleaved (kAvx512Groups).
template <int kGroups, bool kClamp>
void TraverseAvx512(const core::Node* nodes, const FrameView& f, int end, uint32_t* out);

/// CombinePortable for 16 < stride <= 32 (the 31-part taxonomy), AVX-512BW.
void CombineAvx512Stride32(const core::Forest& forest, const uint32_t* leaves, size_t leaves_stride,
                           const uint32_t* pixel, int count, uint16_t* fg_sums, Classification* out);
#endif

#ifdef POSEFOREST_CLASSIFIER_AVX2
/// TraverseAvx512 for AVX2 machines: kGroups vectors of 8 lanes (kAvx2Groups).
template <int kGroups, bool kClamp>
void TraverseAvx2(const core::Node* nodes, const FrameView& f, int end, uint32_t* out);
#endif

}  // namespace poseforest::runtime::detail
