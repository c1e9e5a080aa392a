#pragma once
// The frame-source options shared by the commands that read depth frames (infer, frames):
// --camera, --fx/--fy/--cx/--cy, --depth-scale, --raw-size, --fps.

#include "apps/commands/args.h"
#include "runtime/core/result.h"
#include "runtime/frame_source.h"

namespace poseforest::apps::commands {

/// Value options ParseFrameSourceOptions reads.
inline constexpr const char* kFrameSourceValueOptions[] = {"camera", "fx",          "fy",       "cx",
                                                           "cy",     "depth-scale", "raw-size", "fps"};

/// The camera model of --camera PRESET and --fx/--fy/--cx/--cy on top (--fx alone sets both
/// focal lengths; a preset with explicit values is named "PRESET+custom"); `given` says whether
/// any of these options was present. Errors name the option.
core::Status ParseCameraOptions(const Args& args, runtime::CameraModel* out, bool* given = nullptr);

/// Fills `out` from the parsed arguments; errors name the option.
core::Status ParseFrameSourceOptions(const Args& args, runtime::FrameSourceOptions* out);

/// A number option within [lo, hi]; `fallback` when absent; the error names the option.
core::Result<double> GetDouble(const Args& args, const std::string& name, double fallback, double lo,
                               double hi);

}  // namespace poseforest::apps::commands
