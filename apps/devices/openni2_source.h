#pragma once
// The OpenNI2 frame back end: `openni2:` (the first device), `openni2:URI` (a device URI) and
// `openni2:FILE.oni` (a recording) sources. An optional target (poseforest_openni2), built when
// pkg-config finds libopenni2; the runtime library never includes OpenNI2's headers.

#include <string>

namespace poseforest::apps::devices {

/// Registers the "openni2" scheme with the frame sources (runtime/frame_source.h).
void RegisterOpenNi2BackEnd();

/// One line per device OpenNI2 enumerates, or a sentence saying there is none (and why, if
/// OpenNI2 could not start).
std::string ListOpenNi2Devices();

}  // namespace poseforest::apps::devices
