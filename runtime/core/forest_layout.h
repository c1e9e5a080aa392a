#pragma once
// The forest file's layout constants (runtime/FORMAT.md is the prose version of this block),
// shared by the writer (forest_format.cpp) and the reader (forest_parse.cpp). Internal.

#include <cstdint>
#include <string>

#include "runtime/core/body_parts.h"

namespace poseforest::core::detail {

// Layout constants; runtime/FORMAT.md is the prose version of this block.
constexpr uint8_t kMagic[8] = {0x89, 'P', 'F', 'F', '\r', '\n', 0x1A, '\n'};
constexpr uint32_t kEndianMarker = 0x0A0B0C0Du;
constexpr uint32_t kHeaderSize = 64;
constexpr uint32_t kTrailerMagic = 0x444E4650u;  // "PFND"
constexpr uint32_t kTrailerSize = 8;
constexpr uint32_t kSectionHeaderSize = 16;
constexpr uint32_t kFlagRequired = 1;
constexpr uint32_t kLeafEncodingU8Sum255 = 1;
constexpr uint32_t kMetaFixedSize = 32;
constexpr uint32_t kTreeFixedSize = 16;

constexpr uint32_t Tag(const char (&s)[5]) {
  return uint32_t(uint8_t(s[0])) | uint32_t(uint8_t(s[1])) << 8 | uint32_t(uint8_t(s[2])) << 16 |
         uint32_t(uint8_t(s[3])) << 24;
}
constexpr uint32_t kTagMeta = Tag("META");
constexpr uint32_t kTagTree = Tag("TREE");
constexpr uint32_t kTagJointParams = Tag("JPAR");      // mean shift (1.1: both methods)
constexpr uint32_t kTagFastJointParams = Tag("JPFC");  // the fast clustering (1.2)
constexpr uint32_t kTagFocal = Tag("FOCL");            // training camera's focal lengths (1.3)
constexpr uint32_t kTagCalibration = Tag("JCAL");      // joint confidence calibration (1.4)
constexpr uint32_t kTagOffsetVotes = Tag("JVOT");      // offset votes (1.5)
constexpr uint32_t kTagTracking = Tag("JTRK");         // learned tracking decision (1.6)
constexpr uint32_t kTagTrackingFit = Tag("JTFT");      // the skeleton fit JTRK was fitted on (1.7)
constexpr uint32_t kTagTrackingSeen = Tag("JSEE");     // the seen decision beside JTRK (1.8)
constexpr uint32_t kTagProbeEdge = Tag("PEDG");        // probes past the edge read it (1.9, required)
// PEDG: u32 edge (ProbeEdge: 1 = clamp; written only then), u32 reserved zero.
constexpr uint32_t kProbeEdgeSize = 8;
// JTFT: u32 fit (TrackingFit: 1 = kinematic; written only then), u32 reserved zero.
constexpr uint32_t kTrackingFitSize = 8;
// JTRK: u32 joints, u32 cues, u32 samples, joints x f32 intercept, joints x f32 slope, cues x f32.
// JSEE: u32 joints, u32 cues, joints x f32 intercept, joints x f32 slope, cues x f32.
// JVOT: u32 trees, u32 joints, f32 max offset, joints x f32 bandwidth, u32 calibration bins.
constexpr uint32_t kVotesHeadSize = 16 + 4 * uint32_t(kNumJoints);
constexpr uint32_t kVoteSize = 8;  // i16 dx, dy, dz (mm), u8 joint, u8 weight

inline std::string TagName(uint32_t tag) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = char((tag >> (8 * i)) & 0xFF);
    s += (c >= 32 && c < 127) ? c : '?';
  }
  return s;
}
}  // namespace poseforest::core::detail
