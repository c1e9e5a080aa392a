// People segmentation: a real Kinect point cloud of a person in a room comes out as one person,
// the real pre-segmented frames pass unchanged, and synthetic cluttered scenes (floor, walls,
// boxes, people touching at different depths) come out as their people with high IoU.
#include <catch2/catch.hpp>
#include <filesystem>

#include "runtime/frame_source.h"
#include "runtime/segmentation.h"
#include "tests/support/paths.h"
#include "tests/support/scene.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
namespace fs = std::filesystem;

namespace {

std::vector<std::string> RealFrames() {
  std::vector<std::string> out;
  const fs::path dir = testing::DataDir() / "real/skeltrack_kinect_depth";
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().filename().string().rfind("depth-data-", 0) == 0) out.push_back(e.path().string());
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

TEST_CASE("person.pcd (a real Kinect cloud of a person in a room) comes out as exactly one person",
          "[segmentation][data]") {
  const fs::path pcd = testing::DataDir() / "real/pcl_person_pcd/person.pcd";
  REQUIRE(fs::exists(pcd));
  auto depth = runtime::ReadPcdDepth(pcd.string());
  REQUIRE(depth.ok());
  REQUIRE(depth->width == 640);
  REQUIRE(depth->height == 480);
  const int valid = core::CountForeground(*depth);
  CHECK(valid > 200000);  // a raw frame: the room is there
  runtime::SegmentationResult seg;
  runtime::SegmentPeople(*depth, core::CameraIntrinsics::KinectV1(), {}, &seg);
  CHECK_FALSE(seg.presegmented);
  INFO("components " << seg.components << ", people " << seg.people.size());
  for (const auto& p : seg.people)
    INFO("person " << p.label << ": " << p.pixels << " px, box " << p.x0 << "," << p.y0 << "-" << p.x1 << ","
                   << p.y1 << ", height " << p.height_m << " m, width " << p.width_m << " m, depth "
                   << p.mean_depth_m);
  REQUIRE(seg.people.size() == 1);
  const auto& p = seg.people[0];
  // The person: head and shoulders in the lower middle of the frame, nearest thing in view
  // (about 0.6-1.2 m), the room behind at 2-3.8 m.
  CHECK(p.mean_depth_m < 1.3);
  CHECK(p.x0 > 60);
  CHECK(p.x1 < 420);
  CHECK(p.y0 > 120);
  CHECK(p.y0 < 220);
  CHECK(p.y1 >= 470);  // down to the bottom of the frame (its last rows hold no readings)
  CHECK(p.pixels > 40000);
  // The room is gone: every kept pixel is near.
  int far = 0;
  for (uint16_t d : seg.depth.pixels) far += d > 1600;
  CHECK(far == 0);
}

TEST_CASE("the 9 real Kinect frames (already segmented) come out unchanged", "[segmentation][data]") {
  const auto frames = RealFrames();
  REQUIRE(frames.size() == 9);
  runtime::FrameSourceOptions fo;
  for (const auto& path : frames) {
    auto depth = runtime::ReadDepthFile(path, fo);
    REQUIRE(depth.ok());
    runtime::SegmentationResult seg;
    runtime::SegmentPeople(*depth, core::CameraIntrinsics::KinectV1(), {}, &seg);
    INFO(path);
    CHECK(seg.presegmented);
    CHECK(seg.depth.pixels == depth->pixels);
    REQUIRE(seg.people.size() == 1);
    CHECK(seg.people[0].pixels == core::CountForeground(*depth));
  }
}

TEST_CASE("a cluttered scene: floor, walls, a box and two people touching at different depths",
          "[segmentation]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  // Two standing figures (feet 0.98 m below the camera's height) that overlap in the image: the
  // near one at 2.0 m, the far one at 2.7 m, 0.55 m to its right.
  const auto near_person = testing::MakePersonDepth(2.0, 640, 480, -0.25, 0.0);
  const auto far_person = testing::MakePersonDepth(2.7, 640, 480, 0.45, 0.0);
  testing::ClutterSpec spec;
  spec.floor_y_m = 0.98;
  spec.back_wall_z_m = 4.2;
  spec.side_wall_x_m = -1.9;
  spec.boxes.push_back({{0.7, 0.58, 3.0}, {1.4, 0.98, 3.5}});    // a low wide box on the floor
  spec.boxes.push_back({{-1.5, 0.18, 3.4}, {-1.0, 0.98, 3.8}});  // a taller one by the wall
  const auto scene = testing::ComposeScene(cam, spec, {near_person, far_person});
  // The two people touch in the image.
  int touching = 0;
  for (int y = 0; y < 480; ++y)
    for (int x = 1; x < 640; ++x)
      touching += (scene.truth.at(x - 1, y) == 1 && scene.truth.at(x, y) == 2) ||
                  (scene.truth.at(x - 1, y) == 2 && scene.truth.at(x, y) == 1);
  REQUIRE(touching > 20);

  runtime::SegmentationResult seg;
  runtime::SegmentPeople(scene.depth, cam, {}, &seg);
  CHECK_FALSE(seg.presegmented);
  REQUIRE(seg.floor.has_value());
  // The fitted floor is y = 0.98: normal (0, 1, 0), offset -0.98.
  CHECK((*seg.floor)[1] > 0.99);
  CHECK((*seg.floor)[3] == Approx(-0.98).margin(0.02));
  REQUIRE(seg.people.size() == 2);
  // Largest first: the near person.
  const double iou_near = runtime::MaskIoU(seg.labels, 1, scene.truth, 1);
  const double iou_far = runtime::MaskIoU(seg.labels, 2, scene.truth, 2);
  INFO("IoU near " << iou_near << ", far " << iou_far);
  CHECK(iou_near > 0.95);
  CHECK(iou_far > 0.93);
  CHECK(seg.people[0].mean_depth_m < seg.people[1].mean_depth_m);
  // Everything else is at the background value (0), so probes read the feature's background.
  int kept_outside = 0;
  for (size_t i = 0; i < seg.depth.pixels.size(); ++i)
    kept_outside += seg.labels.pixels[i] == 0 && seg.depth.pixels[i] != 0;
  CHECK(kept_outside == 0);

  SECTION("a given floor plane gives the same people") {
    runtime::SegmentationOptions o;
    o.floor_plane = Eigen::Vector4d(0, 1, 0, -0.98);
    runtime::SegmentationResult given;
    runtime::SegmentPeople(scene.depth, cam, o, &given);
    REQUIRE(given.people.size() == 2);
    CHECK(runtime::MaskIoU(given.labels, 1, scene.truth, 1) > 0.95);
  }
  SECTION("without the depth test the two people merge into one component") {
    runtime::SegmentationOptions o;
    o.jump_mm = 100000;
    o.max_width_m = 5;
    runtime::SegmentationResult merged;
    runtime::SegmentPeople(scene.depth, cam, o, &merged);
    CHECK(merged.people.size() < 2);
  }
  SECTION("deterministic: the same frame gives the same masks") {
    runtime::SegmentationResult again;
    runtime::SegmentPeople(scene.depth, cam, {}, &again);
    CHECK(again.labels.pixels == seg.labels.pixels);
  }
}

TEST_CASE("pre-segmented input is detected, and the flag forces either way", "[segmentation]") {
  const auto cam = core::CameraIntrinsics::KinectV1();
  const auto person = testing::MakePersonDepth(2.5);
  runtime::SegmentationResult seg;
  runtime::SegmentPeople(person, cam, {}, &seg);
  CHECK(seg.presegmented);
  CHECK(seg.depth.pixels == person.pixels);

  testing::ClutterSpec spec;
  spec.floor_y_m = 0.98;
  const auto scene = testing::ComposeScene(cam, spec, {person});
  runtime::SegmentationOptions force;
  force.presegmented = true;
  runtime::SegmentPeople(scene.depth, cam, force, &seg);
  CHECK(seg.presegmented);
  CHECK(seg.depth.pixels == scene.depth.pixels);
  // A person lying on the ground, alone (pre-segmented renders have such poses): its top is a
  // horizontal surface receding 1.7 m, but it is no floor (too narrow), so the frame passes.
  testing::ClutterSpec lying;
  lying.floor_y_m = 0, lying.back_wall_z_m = 0, lying.side_wall_x_m = 0;
  lying.boxes.push_back({{-0.25, 0.75, 2.0}, {0.25, 1.0, 3.7}});
  const auto body = testing::ComposeScene(cam, lying, {});
  REQUIRE(core::CountForeground(body.depth) > 5000);
  runtime::SegmentPeople(body.depth, cam, {}, &seg);
  CHECK(seg.presegmented);
  CHECK(seg.depth.pixels == body.depth.pixels);
  runtime::SegmentationOptions narrow_floor;
  narrow_floor.floor_min_width_m = 0.1;  // the old rule: then it would be taken for a floor
  runtime::SegmentPeople(body.depth, cam, narrow_floor, &seg);
  CHECK_FALSE(seg.presegmented);

  force.presegmented = false;
  runtime::SegmentPeople(person, cam, force, &seg);
  CHECK_FALSE(seg.presegmented);
  REQUIRE(seg.people.size() == 1);
  CHECK(runtime::MaskIoU(seg.labels, 1, scene.truth, 1) > 0.97);
}
