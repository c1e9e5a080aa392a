#pragma once
// The option groups of the commands that read or make depth frames, declared once: the camera
// (--camera, --fx/--fy/--cx/--cy: render, infer, frames, live), the frame source on top
// (--depth-scale, --raw-size, --fps: infer, frames, live) and the people segmentation
// (--segment, --floor, --near, --far: infer, live).

#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "runtime/core/result.h"
#include "runtime/frame_source.h"
#include "runtime/segmentation.h"

namespace poseforest::apps::commands {

/// The camera options as given; nullopt: not given.
struct CameraFlags {
  std::optional<std::string> camera;
  std::optional<double> fx, fy, cx, cy;  ///< pixels
  bool given() const { return camera || fx || fy || cx || cy; }
};

/// Declares --camera and --fx/--fy/--cx/--cy on `app` (group "camera"), bound to `out`.
void AddCameraOptions(CLI::App& app, CameraFlags* out);

/// The camera model of --camera PRESET (default kinect-v1) and --fx/--fy/--cx/--cy on top (--fx
/// alone sets both focal lengths; a preset with explicit values is named "PRESET+custom").
/// An unknown preset is an error naming --camera.
core::Result<runtime::CameraModel> CameraFromFlags(const CameraFlags& flags);

/// The frame-source options as given: the camera and how raw frames are read and paced.
struct FrameSourceFlags {
  CameraFlags camera;
  double depth_scale = 1.0;  ///< millimetres per raw depth unit
  std::optional<std::string> raw_size;  ///< "WxH", checked by the declaration
  double fps = 0.0;  ///< at most this many frames per second; 0: as fast as they come
};

/// Declares the camera options and --depth-scale, --raw-size, --fps on `app`, bound to `out`.
void AddFrameSourceOptions(CLI::App& app, FrameSourceFlags* out);

/// runtime::FrameSourceOptions from the flags; errors name the option.
core::Result<runtime::FrameSourceOptions> FrameSourceFromFlags(const FrameSourceFlags& flags);

/// The segmentation options as given.
struct SegmentationFlags {
  std::string segment = "auto";        ///< auto, on or off (checked by the declaration)
  std::optional<std::string> floor;    ///< "A,B,C,D"
  std::optional<double> near, far;     ///< metres; default: runtime::SegmentationOptions'
};

/// Declares --segment, --floor, --near and --far on `app` (group "segmentation"), bound to `out`.
void AddSegmentationOptions(CLI::App& app, SegmentationFlags* out);

/// Sets `out`'s floor plane and depth band from the flags (the mode is the command's to read);
/// errors name the option.
core::Status SegmentationFromFlags(const SegmentationFlags& flags, runtime::SegmentationOptions* out);

}  // namespace poseforest::apps::commands
