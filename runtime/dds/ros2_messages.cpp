#include "runtime/dds/ros2_messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "runtime/visualize.h"

namespace poseforest::runtime::ros2 {
namespace {

// XCDR1 little-endian writer: alignment counts from the first byte after the encapsulation
// header, as Fast CDR (and so rmw_fastrtps) does.
class Cdr {
 public:
  Cdr() : buf_{0x00, 0x01, 0x00, 0x00} {}  // CDR_LE, options 0
  void Align(size_t n) {
    while ((buf_.size() - 4) % n) buf_.push_back(0);
  }
  template <typename T>
  void Put(T v) {
    Align(sizeof(T));
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));  // little-endian host (x86-64, arm64)
    buf_.insert(buf_.end(), b, b + sizeof(T));
  }
  void Bool(bool v) { buf_.push_back(v ? 1 : 0); }
  void String(const std::string& s) {
    Put(uint32_t(s.size() + 1));
    buf_.insert(buf_.end(), s.begin(), s.end());
    buf_.push_back(0);
  }
  void Header(const FrameStamp& st) {
    // builtin_interfaces/Time from time_s (floor, so nanosec is in [0, 1e9)).
    const double sec = std::floor(st.time_s);
    Put(int32_t(sec));
    Put(uint32_t(std::min(999999999.0, std::round((st.time_s - sec) * 1e9))));
    String(st.frame_id);
  }
  std::vector<uint8_t>& bytes() { return buf_; }

 private:
  std::vector<uint8_t> buf_;
};
static_assert(sizeof(double) == 8 && sizeof(float) == 4);

}  // namespace

std::vector<uint8_t> EncodeSkeletons(const FrameStamp& stamp, const std::vector<Skeleton>& skeletons) {
  Cdr c;
  c.Header(stamp);
  c.Put(int64_t(stamp.index));
  c.Put(double(stamp.time_s));
  c.String(stamp.source);
  c.Put(uint32_t(skeletons.size()));
  for (const Skeleton& s : skeletons) {
    c.Put(int32_t(s.id));
    c.Put(int32_t(s.pixels));
    for (int k = 0; k < 3; ++k) c.Put(double(s.centroid_m[k]));
    c.Put(uint32_t(core::kNumJoints));
    for (int j = 0; j < core::kNumJoints; ++j) {
      const SkeletonJoint& joint = s.joints[size_t(j)];
      c.String(std::string(core::JointName(j)));
      c.Bool(joint.found);
      c.Bool(joint.tracked);
      c.Put(float(joint.confidence));
      for (int k = 0; k < 3; ++k) c.Put(joint.found ? double(joint.position_m[k]) : 0.0);
      for (int k = 0; k < 2; ++k) c.Put(joint.found ? float(joint.pixel[k]) : 0.0f);
      c.Put(uint8_t(StateOf(joint)));  // NOT_TRACKED, INFERRED, TRACKED: JointState's numbers
    }
  }
  return std::move(c.bytes());
}

std::vector<uint8_t> EncodeMarkerArray(const FrameStamp& stamp, const std::vector<Skeleton>& skeletons) {
  Cdr c;
  enum : int32_t { kLineList = 5, kSphereList = 7, kAdd = 0, kDeleteAll = 3 };
  struct Marker {
    int32_t id = 0, type = kSphereList, action = kAdd;
    double scale = 0;
    core::Rgb colour{0, 0, 0};
    float alpha = 1;
    std::vector<Eigen::Vector3f> points;
    const char* ns = kMarkerNamespace;
  };
  std::vector<Marker> markers;
  markers.push_back({0, kSphereList, kDeleteAll, 0, {0, 0, 0}, 1, {}});  // clears the previous frame's people
  for (const Skeleton& s : skeletons) {
    Marker joints{2 * s.id, kSphereList, kAdd, 0.04, PersonColour(s.id), 1, {}};
    Marker bones{2 * s.id + 1, kLineList, kAdd, 0.015, PersonColour(s.id), 1, {}};
    // Inferred joints: the person's colour halfway to light grey, translucent, smaller.
    const core::Rgb c = PersonColour(s.id);
    const core::Rgb pale{uint8_t((c.r + 200) / 2), uint8_t((c.g + 200) / 2), uint8_t((c.b + 200) / 2)};
    Marker inferred{2 * s.id, kSphereList, kAdd, 0.03, pale, 0.5f, {}, kInferredMarkerNamespace};
    for (const SkeletonJoint& j : s.joints)
      if (j.tracked)
        joints.points.push_back(j.position_m);
      else if (StateOf(j) == JointState::kInferred)
        inferred.points.push_back(j.position_m);
    for (const auto& [a, b] : SkeletonBones())
      if (s.joints[size_t(a)].tracked && s.joints[size_t(b)].tracked) {
        bones.points.push_back(s.joints[size_t(a)].position_m);
        bones.points.push_back(s.joints[size_t(b)].position_m);
      }
    markers.push_back(std::move(joints));
    markers.push_back(std::move(bones));
    // Only when there are some (forests without offset votes have none: no empty marker per person
    // and frame); the next frame's DELETEALL removes it.
    if (!inferred.points.empty()) markers.push_back(std::move(inferred));
  }
  c.Put(uint32_t(markers.size()));
  for (const Marker& m : markers) {
    c.Header(stamp);
    c.String(m.ns);
    c.Put(m.id);
    c.Put(m.type);
    c.Put(m.action);
    for (double v : {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0}) c.Put(v);  // pose: origin, identity
    for (int k = 0; k < 3; ++k) c.Put(m.scale);
    for (float v : {m.colour.r / 255.0f, m.colour.g / 255.0f, m.colour.b / 255.0f, m.alpha}) c.Put(v);
    c.Put(int32_t(0));  // lifetime: forever (the next frame's DELETEALL removes it)
    c.Put(uint32_t(0));
    c.Bool(false);  // frame_locked
    c.Put(uint32_t(m.points.size()));
    for (const auto& p : m.points)
      for (int k = 0; k < 3; ++k) c.Put(double(p[k]));
    c.Put(uint32_t(0));  // colors
    c.String("");        // texture_resource
    c.Header(stamp);     // texture: sensor_msgs/CompressedImage (empty)
    c.String("");        //   format
    c.Put(uint32_t(0));  //   data
    c.Put(uint32_t(0));  // uv_coordinates
    c.String("");        // text
    c.String("");        // mesh_resource
    c.String("");        // mesh_file.filename
    c.Put(uint32_t(0));  // mesh_file.data
    c.Bool(false);       // mesh_use_embedded_materials
  }
  return std::move(c.bytes());
}

}  // namespace poseforest::runtime::ros2
