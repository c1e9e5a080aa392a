#pragma once
// Frame sources: one interface over everything a depth frame can come from - files (16-bit PNG,
// raw uint16, .npy, organized .pcd), folders and globs (sorted), raw frames on stdin (no seeking:
// a pipe works), and device back ends (libfreenect, OpenNI2: optional targets, registered at
// configure time). Each frame carries its depth in millimetres, a timestamp, its camera model and
// where it came from, so a bad one can be named and skipped.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "runtime/camera_model.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/result.h"

namespace poseforest::runtime {

/// One depth frame.
struct Frame {
  core::DepthImage depth;  ///< millimetres, 0 = no reading
  double timestamp_s = 0;  ///< seconds: the device's clock, else index / fps, else time since open
  CameraModel camera;      ///< the model the frame was checked against
  std::string source;      ///< file path, "stdin", "freenect:0", ...
  int64_t index = 0;       ///< 0-based position in its source's sequence
  /// "SOURCE frame N" for messages (for a file: the path alone).
  std::string Name() const;
};

/// A sequence of frames. Next() returns true with a frame, false at the end of the stream, or an
/// error for one bad frame (truncated, wrong size, unreadable), whose message names the source
/// and the frame. After a bad frame the caller may call Next() again for the following one; a
/// source that cannot go on (a device lost, a pipe cut mid-frame) reports it once and then ends.
/// A reader gives up on a source after this many bad frames in a row (a stream that only ever
/// yields bad frames would otherwise never end).
inline constexpr int kMaxConsecutiveBadFrames = 100;

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  [[nodiscard]] virtual core::Result<bool> Next(Frame* frame) = 0;
  /// What this source reads, for messages ("3 files", "stdin, raw 640x480", "freenect:0").
  virtual std::string Describe() const = 0;
};

struct FrameSourceOptions {
  CameraModel camera;         ///< frames of another size are refused naming both
  bool camera_given = false;  ///< false: the default model; a .pcd sized otherwise is then taken as is
  double fps = 0;             ///< > 0: deliver at most this many frames per second (sleeps)
  /// The pacing's clock and sleep (tests inject a fake clock); empty: steady_clock and
  /// std::this_thread::sleep_until.
  std::function<std::chrono::steady_clock::time_point()> pace_now;
  std::function<void(std::chrono::steady_clock::time_point)> pace_sleep_until;
  /// Raw uint16 frames are this size (default: the camera's).
  int raw_width = 0, raw_height = 0;
};

/// Opens a source from its spec:
///   FILE              a depth PNG, a raw frame, a .npy (uint16 mm or float32 m; [H,W] or
///                     [N,H,W]), an organized .pcd (x y z float32 metres, NaN = none)
///   FOLDER            every regular non-hidden frame file in it, sorted by name (files that
///                     are not frames are left out: ExpandFrameFiles)
///   PATTERN           a glob (*, ?, [...]), matches sorted by name
///   -                 raw uint16 little-endian frames on stdin, back to back
///   freenect:N        Kinect v1 number N through libfreenect (if built in)
///   openni2:URI       an OpenNI2 device or .oni file (if built in); openni2: the first device
/// Errors (no such file, empty folder, a back end not built in) name the spec.
core::Result<std::unique_ptr<FrameSource>> OpenFrameSource(const std::string& spec,
                                                           const FrameSourceOptions& options);

/// Several specs one after the other (infer's positional arguments).
core::Result<std::unique_ptr<FrameSource>> OpenFrameSources(const std::vector<std::string>& specs,
                                                            const FrameSourceOptions& options);

/// A device back end registers a URI scheme ("freenect", "openni2") at static-init time; the
/// optional targets do this, so the runtime library itself needs none of their headers.
using FrameSourceFactory = std::function<core::Result<std::unique_ptr<FrameSource>>(
    const std::string& rest, const FrameSourceOptions&)>;
struct BackEndInfo {
  std::string scheme;    ///< "freenect"
  std::string describe;  ///< "libfreenect 0.5 (Kinect v1)"
  /// Lists devices for `--version` / `infer --list-devices`: a line per device, or a sentence
  /// saying there is none.
  std::function<std::string()> list_devices;
};
bool RegisterFrameBackEnd(const BackEndInfo& info, FrameSourceFactory factory);
/// The back ends built into this program, in registration order.
std::vector<BackEndInfo> FrameBackEnds();

// --- Building blocks, public for tests and back ends --------------------------------------------

/// Reads one depth file (PNG, raw of raw_width x raw_height, .npy with one frame, organized
/// .pcd) into millimetres, applying depth_scale_mm to raw and PNG values. Errors name the path.
core::Result<core::DepthImage> ReadDepthFile(const std::string& path, const FrameSourceOptions& options);

/// A parsed .npy header: dtype ('<u2' or '<f4'), shape, and where the data starts.
struct NpyHeader {
  std::string descr;
  std::vector<int64_t> shape;
  size_t data_offset = 0;
};
/// Parses a NumPy .npy header (format 1.0, 2.0 or 3.0). Only little-endian uint16 and float32,
/// C order, 2 or 3 dimensions are accepted; anything else is an error naming the file and what it
/// holds.
core::Result<NpyHeader> ParseNpyHeader(const std::vector<uint8_t>& bytes, const std::string& source);

/// Writes frames as a .npy: uint16 millimetres, shape [H,W] for one frame or [N,H,W].
core::Status WriteDepthNpy(const std::string& path, const std::vector<core::DepthImage>& frames);

/// Reads an organized PCD point cloud (ASCII, binary or binary_compressed; fields x y z float32
/// metres, NaN = invalid) into a depth image in mm (z). Errors name the file.
core::Result<core::DepthImage> ReadPcdDepth(const std::string& path);
/// The same from bytes in memory; `source` names them in errors.
core::Result<core::DepthImage> ParsePcdDepth(std::span<const uint8_t> bytes, const std::string& source);

/// An organized PCD cloud as a depth frame, with the projection its points were made with: the
/// pinhole camera (fx, fy, cx, cy; the cloud's size) fitted by least squares to x/z, y/z against
/// the pixel, when the points fit one to within 0.5 px rms (a cloud moved out of the camera
/// frame does not). PCL's person.pcd: fx = fy = 525, cx 319.5, cy 239.5.
struct PcdFrame {
  core::DepthImage depth;
  std::optional<core::CameraIntrinsics> intrinsics;  ///< absent: no x, y, too few points, no fit
  double fit_rms_px = 0;                             ///< the fit's rms residual, pixels
};
core::Result<PcdFrame> ParsePcdFrame(std::span<const uint8_t> bytes, const std::string& source);
core::Result<PcdFrame> ReadPcdFrame(const std::string& path);

/// Expands a folder or glob into sorted file paths (the FOLDER / PATTERN rules above). A folder
/// leaves out files that are not frames: poseforest's own outputs (infer's <name>.parts.png,
/// .labels.png, .mask.png, .pose.png, .probs.npy; render's camera.txt, labels_N.png, joints_N.json,
/// montage.png), text, document and archive extensions (.txt, .md, .json, ...), and capitals-only
/// names without an extension (COPYING, README); their names go to `not_frames` (sorted). A glob
/// keeps every file it matches: the user chose them.
core::Result<std::vector<std::string>> ExpandFrameFiles(const std::string& spec,
                                                        std::vector<std::string>* not_frames = nullptr);

/// Whether a file of this name in a FOLDER source is left out as not a frame (above).
bool IsNotAFrameFile(const std::string& name);

}  // namespace poseforest::runtime
