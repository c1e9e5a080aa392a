#include "apps/ros2/ros2_messages.h"

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "runtime/visualize.h"

namespace poseforest::apps::ros2 {
namespace {

namespace fcdr = eprosima::fastcdr;
using runtime::JointState;
using runtime::PersonColour;
using runtime::SkeletonBones;
using runtime::SkeletonJoint;
using runtime::StateOf;

// XCDR1 little endian through Fast CDR (the library rmw_fastrtps itself encodes with): its
// DDS_CDR mode writes the 4-byte encapsulation header and aligns each field to its size from the
// first byte after it. Fast CDR skips alignment padding without writing it, so Encode writes
// twice: once into a growing buffer to learn the length, then into zeroed memory of that length,
// so the padding is zeros and the bytes depend on the message alone.
class Cdr {
 public:
  explicit Cdr(fcdr::FastBuffer& buffer) : cdr_(buffer, fcdr::Cdr::LITTLE_ENDIANNESS, fcdr::Cdr::DDS_CDR) {
    cdr_.serialize_encapsulation();
  }
  template <typename T>
  void Put(T v) {
    cdr_.serialize(v);
  }
  void Bool(bool v) { cdr_.serialize(v); }
  void String(const std::string& s) { cdr_.serialize(s); }
  void Header(const FrameStamp& st) {
    // builtin_interfaces/Time from time_s (floor, so nanosec is in [0, 1e9)).
    const double sec = std::floor(st.time_s);
    Put(int32_t(sec));
    Put(uint32_t(std::min(999999999.0, std::round((st.time_s - sec) * 1e9))));
    String(st.frame_id);
  }
  size_t length() const { return cdr_.getSerializedDataLength(); }

 private:
  fcdr::Cdr cdr_;
};

template <typename Write>
std::vector<uint8_t> Encode(Write&& write) {
  fcdr::FastBuffer growing;
  Cdr sizing(growing);
  write(sizing);
  std::vector<uint8_t> out(sizing.length(), 0);
  fcdr::FastBuffer fixed(reinterpret_cast<char*>(out.data()), out.size());
  Cdr c(fixed);
  write(c);
  return out;
}
static_assert(sizeof(double) == 8 && sizeof(float) == 4);

}  // namespace

std::vector<uint8_t> EncodeSkeletons(const FrameStamp& stamp,
                                     const std::vector<runtime::Skeleton>& skeletons) {
  return Encode([&](Cdr& c) {
    c.Header(stamp);
    c.Put(int64_t(stamp.index));
    c.Put(double(stamp.time_s));
    c.String(stamp.source);
    c.Put(uint32_t(skeletons.size()));
    for (const runtime::Skeleton& s : skeletons) {
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
  });
}

std::vector<uint8_t> EncodeMarkerArray(const FrameStamp& stamp,
                                       const std::vector<runtime::Skeleton>& skeletons) {
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
  for (const runtime::Skeleton& s : skeletons) {
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
  return Encode([&](Cdr& c) {
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
  });
}

}  // namespace poseforest::apps::ros2
