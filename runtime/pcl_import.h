#pragma once
// Import of the Point Cloud Library's trained body-part trees (pcl::gpu::people, the
// open-source Shotton-style detector by Buys et al.) into the poseforest format, as a
// cross-check of our feature and classifier against an independently trained forest.
//
// PCL's text format (one tree per file): line 1 the height H; then 2^H - 1 split nodes
// "du1 dv1 du2 dv2 thresh" (int16), breadth first, node n's children at 2n+1 (test false) and
// 2n+2 (test true), test = d(x + u*1000/d) - d(x + v*1000/d) > thresh; then 2^H leaf labels.
// With offset_unit = 1 pixel*m our feature computes the same offsets (1000/d(mm) = 1/d(m));
// PCL's "> thresh" becomes our "go left if f < thresh + 0.5" for integer f. Two differences
// remain and are measured by the tests: PCL truncates probe coordinates (CUDA texture point
// sampling) where we round to nearest, and PCL clamps probes at the image border where we read
// the background constant. PCL's background is 65535, which becomes our background constant.

#include <string_view>
#include <string>
#include <vector>

#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::runtime {

/// PCL's 25 body-part labels (label_common.h), in label order: Lfoot, Lleg, Lknee, ...
const std::vector<std::string>& PclPartNames();

/// Parses one PCL tree file's text into `forest` (appending a tree). `source` names it in errors.
core::Status AppendPclTree(std::string_view text, const std::string& source, core::Forest* forest);

/// Reads PCL tree files (plain text, or .bz2 decompressed through the `bzip2` program) into
/// one forest with PCL's part table, background 65535 mm and offset unit 1 pixel*m.
core::Result<core::Forest> ImportPclTrees(const std::vector<std::string>& paths);

}  // namespace poseforest::runtime
