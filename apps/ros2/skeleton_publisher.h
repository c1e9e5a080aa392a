#pragma once
// `poseforest live --dds`: skeletons on DDS as a ROS 2 node using Fast DDS reads them, unchanged
// (rmw_fastrtps naming: topic "rt/" + the ROS topic, type "pkg::msg::dds_::Type_"; CDR payloads,
// ros2_messages.h):
//   rt/<prefix>/skeletons  poseforest_msgs::msg::dds_::Skeletons_    (msg/Skeletons.msg)
//   rt/<prefix>/markers    visualization_msgs::msg::dds_::MarkerArray_  (RViz: joints and bones)
// Reliable, keep-last 100, transient-local (a subscriber that joins late gets the latest frames,
// as a latched ROS topic). An optional target (Fast DDS); never linked into the runtime library.
// This header shows no DDS type.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "apps/ros2/ros2_messages.h"
#include "runtime/core/result.h"

namespace poseforest::apps::ros2 {

struct DdsOptions {
  int domain = 0;                           ///< DDS domain (ROS_DOMAIN_ID)
  std::string topic_prefix = "poseforest";  ///< ROS topics /<prefix>/skeletons and /<prefix>/markers
  std::string frame_id = "camera_depth_optical_frame";  ///< header.frame_id
};

class SkeletonPublisher {
 public:
  static core::Result<std::unique_ptr<SkeletonPublisher>> Create(const DdsOptions& options);
  ~SkeletonPublisher();
  /// Publishes one frame on both topics; false if a write failed.
  bool Publish(int64_t index, double time_s, const std::string& source,
               const std::vector<runtime::Skeleton>& skeletons);
  /// Waits up to `seconds` until at least `count` subscribers matched each topic.
  bool WaitForSubscribers(int count, double seconds);
  /// Waits up to `seconds` until every matched subscriber acknowledged what was published.
  bool Flush(double seconds);
  std::string Describe() const;

 private:
  struct Impl;
  explicit SkeletonPublisher(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A subscriber that keeps the serialized samples as they came off the wire (encapsulation header
/// included), for tests and tools that decode them with another implementation.
class RawSampleCapture {
 public:
  /// Subscribes to `topic` (DDS name, e.g. "rt/poseforest/markers") with type name `type_name`;
  /// reliable, transient-local, keep-all.
  static core::Result<std::unique_ptr<RawSampleCapture>> Create(int domain, const std::string& topic,
                                                                const std::string& type_name);
  ~RawSampleCapture();
  /// Waits until `count` samples arrived or `seconds` passed; returns the samples so far.
  std::vector<std::vector<uint8_t>> Wait(size_t count, double seconds);

 private:
  struct Impl;
  explicit RawSampleCapture(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace poseforest::apps::ros2
