#pragma once
// The ROS 2 messages `poseforest live --dds` publishes, encoded as rmw_fastrtps writes them: CDR
// (XCDR1, little endian) with its 4-byte encapsulation header, fields in .msg order, each aligned
// to its size from the start of the data (after the header). Encoded with Fast CDR (no DDS
// headers here); the transport is Fast DDS (skeleton_publisher.h).
//   poseforest_msgs/msg/Skeletons     msg/Skeletons.msg (+ Skeleton.msg, SkeletonJoint.msg)
//   visualization_msgs/msg/MarkerArray  ROS 2 Humble's definition: per person a SPHERE_LIST of the
//                                     tracked joints and a LINE_LIST of the bones between them,
//                                     in the person's colour, and a paler, smaller SPHERE_LIST
//                                     of its inferred joints (no bones), after one DELETEALL marker

#include <cstdint>
#include <string>
#include <vector>

#include "runtime/skeleton.h"

namespace poseforest::apps::ros2 {

inline constexpr const char* kSkeletonsTypeName = "poseforest_msgs::msg::dds_::Skeletons_";
inline constexpr const char* kMarkerArrayTypeName = "visualization_msgs::msg::dds_::MarkerArray_";
/// The markers' namespaces: tracked joints and bones; inferred joints (RViz lists them apart,
/// so either can be hidden).
inline constexpr const char* kMarkerNamespace = "poseforest";
inline constexpr const char* kInferredMarkerNamespace = "poseforest_inferred";

struct FrameStamp {
  int64_t index = 0;
  double time_s = 0;
  std::string source;
  std::string frame_id;  ///< header.frame_id (the camera's TF frame)
};

/// poseforest_msgs/msg/Skeletons, encapsulation header included. Each joint ends with its
/// `state` (uint8: SkeletonJoint.msg's NOT_TRACKED 0, INFERRED 1, TRACKED 2 = JointState).
std::vector<uint8_t> EncodeSkeletons(const FrameStamp& stamp,
                                     const std::vector<runtime::Skeleton>& skeletons);

/// visualization_msgs/msg/MarkerArray (Humble), encapsulation header included. Namespace
/// "poseforest"; person id k has markers 2k (tracked joints, SPHERE_LIST, 4 cm) and 2k+1 (bones
/// between tracked joints, LINE_LIST, 1.5 cm wide), coloured with PersonColour(k). A person with
/// inferred joints also has marker 2k in namespace "poseforest_inferred" (SPHERE_LIST, 3 cm,
/// PersonColour(k) halfway to light grey (200), alpha 0.5; no bones to them), after its bones.
std::vector<uint8_t> EncodeMarkerArray(const FrameStamp& stamp,
                                       const std::vector<runtime::Skeleton>& skeletons);

}  // namespace poseforest::apps::ros2
