#pragma once
// Kernel selection of the classifier, for its tests and benchmark only (not a public API).

#include "runtime/classifier.h"

namespace poseforest::runtime::detail {

/// Which traversal kernel to run. kAuto picks the fastest one compiled in.
enum class Kernel { kAuto = 0, kPortable = 1, kAvx512 = 2, kAvx2 = 3 };

/// True if `kernel` is compiled into this build.
bool KernelAvailable(Kernel kernel);

/// Classifier::Classify with an explicit kernel (an unavailable one falls back to kPortable).
void ClassifyWithKernel(const core::Forest& forest, const core::DepthImage& depth, const ClassifyOptions& options,
                        Kernel kernel, Classification* out);

}  // namespace poseforest::runtime::detail
