#pragma once
// Forest file format v1 (.pff, "poseforest forest"), minor version 9: reading and writing. The layout is
// documented in runtime/FORMAT.md; keep the two in step.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::core {

inline constexpr uint16_t kFormatMajor = 1;
/// 1.1 added the optional JPAR section (joint-proposal parameters); 1.0 readers skip it.
/// 1.2 added the optional JPFC section (the fast clustering's own parameters; JPAR is then mean
/// shift's); 1.1 readers skip it and run both methods with JPAR, as they did.
/// 1.3 added the optional FOCL section (the training camera's focal lengths, pixels); older files
/// mean the Kinect v1 (575.8 px), older readers skip it.
/// 1.4 added the optional JCAL section (joint confidence calibration); older readers skip it.
/// 1.5 added the optional JVOT section (per-leaf offset votes to the joints); older readers skip it.
/// 1.6 added the optional JTRK section (the learned tracking decision); older readers skip it.
/// 1.7 added the optional JTFT section (which skeleton fit JTRK was fitted on, written when it is
/// the kinematic fit); older readers skip it, and a JTRK without it was fitted on the greedy fit.
/// 1.8 added the optional JSEE section (the tracking decision's seen model: a joint is tracked
/// when the camera likely sees it); older readers skip it and track by P(within 0.1 m).
/// 1.9 added the REQUIRED PEDG section (probes beyond the image's edge read the edge,
/// ProbeEdge::kClamp; written only then): an older reader refuses such a forest, whose trees it
/// would evaluate wrongly; a file without it probes as the paper does.
/// Every file is written with the newest minor version, whichever optional sections it holds.
inline constexpr uint16_t kFormatMinor = 9;

/// Serializes a forest (which must pass ValidateForest) to the v1 byte layout.
std::vector<uint8_t> SerializeForest(const Forest& forest);

/// Parses and fully validates a forest from bytes. `source` names the file/message in errors.
/// Never crashes on any input: every size, index and value is checked before use.
Result<Forest> ParseForest(std::span<const uint8_t> bytes, const std::string& source);

/// Reads and parses a forest file.
Result<Forest> LoadForest(const std::string& path);

/// Writes a forest file atomically (temporary file + rename), so a crash never leaves a
/// half-written forest under `path`.
Status SaveForest(const Forest& forest, const std::string& path);

/// OK when `path` is a file this process may read (error names the path): kNotFound when it does
/// not exist, kInvalidArgument when it is a folder, kIo when it cannot be read. For readers that
/// hand the path on (a decompressor); ReadFileBytes checks the same.
Status CheckReadableFile(const std::string& path);
/// Reads a whole file into memory (errors as CheckReadableFile's).
Result<std::vector<uint8_t>> ReadFileBytes(const std::string& path);
/// ReadFileBytes as text.
Result<std::string> ReadFileText(const std::string& path);
/// Writes bytes to `path` atomically (temporary file in the same folder + rename).
Status WriteFileAtomic(const std::string& path, std::span<const uint8_t> bytes);

}  // namespace poseforest::core
