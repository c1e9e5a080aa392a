#pragma once
// The libfreenect frame back end (Kinect v1): `freenect:N[,timeout=S]` sources. An optional
// target (poseforest_freenect), built when pkg-config finds libfreenect; the runtime library
// itself never includes libfreenect's headers.

#include <string>

namespace poseforest::apps::devices {

/// Registers the "freenect" scheme with the frame sources (runtime/frame_source.h).
void RegisterFreenectBackEnd();

/// "libfreenect: N device(s)" or a sentence saying there is none.
std::string ListFreenectDevices();

}  // namespace poseforest::apps::devices
