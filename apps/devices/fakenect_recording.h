#pragma once
// fakenect recordings (libfreenect's record/replay format), written by the runtime itself so that
// tests and users can replay any depth frames through libfreenect's own API with fakenect's
// library in place (LD_LIBRARY_PATH=/usr/lib/<arch>/fakenect FAKENECT_PATH=DIR). The format, as
// libfreenect's fakenect/record.c writes it: a folder with INDEX.txt listing one file per line,
// depth frames named "d-<seconds>-<device timestamp>.pgm" holding the header
// "P5 640 480 65535\n" and 640x480 native-endian uint16 11-bit disparity values (2047 = none).
// Needs no libfreenect: a file format.

#include <cstdint>
#include <string>
#include <vector>

#include "runtime/core/depth_image.h"
#include "runtime/core/result.h"

namespace poseforest::apps::devices {

/// Kinect v1 raw 11-bit disparity of "no reading".
inline constexpr uint16_t kKinectNoDisparity = 2047;

/// Millimetres of a Kinect v1 11-bit disparity value, by the widely used fit
/// z[m] = 1 / (raw * -0.0030711016 + 3.3309495161) (valid for raw < 1084); 0 for no reading.
uint16_t KinectDisparityToMm(uint16_t raw);
/// The disparity value whose KinectDisparityToMm is nearest to `mm` (0 -> kKinectNoDisparity).
/// Depth quantization of the Kinect v1: a disparity step is about 3 mm at 1 m, 12 mm at 2 m.
uint16_t MmToKinectDisparity(uint16_t mm);

/// Writes 640x480 depth frames (mm) as a fakenect recording in `dir` (created; an existing
/// INDEX.txt is refused, like fakenect-record). Frames are `1 / fps` seconds apart from
/// `start_time_s` (fakenect replays at that pace); device timestamps advance by 60e6 / fps
/// ticks per frame (arbitrary units; fakenect passes them to the depth callback).
core::Status WriteFakenectRecording(const std::string& dir, const std::vector<core::DepthImage>& frames_mm,
                                    double fps = 30.0, double start_time_s = 1700000000.0);

/// One depth entry of a recording's INDEX.txt and whether its file is a complete frame.
struct FakenectEntry {
  std::string file;  ///< as listed in INDEX.txt
  bool ok = false;
  std::string problem;  ///< why not ("truncated: 1000 of 614417 bytes", "missing")
};
/// Reads a recording's INDEX.txt and checks every depth file (exists, a header line, then
/// exactly 640*480*2 bytes). Error if INDEX.txt cannot be read.
core::Result<std::vector<FakenectEntry>> CheckFakenectRecording(const std::string& dir);

}  // namespace poseforest::apps::devices
