// SyntheticRenderer: the procedural family in a front T-pose shows all 31 parts, frames are a
// pure function of (seed, index), mirroring swaps labels and joints, visibility is sensible.
#include <catch2/catch.hpp>
#include <cmath>
#include <iostream>
#include <thread>

#include "renderer/procedural_body.h"
#include "renderer/synthetic_source.h"
#include "runtime/core/body_parts.h"

using namespace poseforest;
using namespace poseforest::renderer;

namespace {

SceneConfig SmallConfig() {
  SceneConfig c;
  c.variants_per_shape = 1;
  return c;
}

std::unique_ptr<SyntheticRenderer> Make(const SceneConfig& c) {
  auto r = SyntheticRenderer::Create(c);
  if (!r.ok()) FAIL("SyntheticRenderer: " << r.status().ToString());
  return std::move(r).value();
}

/// Body `body` in the rest T-pose, `dist` metres in front of a level camera at 1 m height,
/// rotated by yaw degrees (0 = facing the camera).
SceneSample FrontScene(int body, double yaw_deg, double dist = 3.0) {
  SceneSample s;
  PersonPlacement p;
  p.body = body;
  Eigen::Isometry3d world_from_body = Eigen::Isometry3d::Identity();
  world_from_body.translate(Eigen::Vector3d(0, 0, -dist));
  world_from_body.rotate(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.rotate(Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()));
  camera_from_world.translate(Eigen::Vector3d(0, -1.0, 0));
  p.camera_from_body = camera_from_world * world_from_body;
  s.people.push_back(p);
  return s;
}

std::vector<int> PartCounts(const core::LabelImage& labels) {
  std::vector<int> c(core::kNumParts, 0);
  for (uint8_t l : labels.pixels) {
    if (l != core::kBackgroundLabel) c[l]++;
  }
  return c;
}

}  // namespace

TEST_CASE("front and back T-pose renders of the procedural family contain all 31 parts", "[egl]") {
  SceneConfig config = SmallConfig();
  config.noise.enabled = false;
  auto r = Make(config);
  std::cout << "GL: " << r->GlRendererString() << std::endl;
  REQUIRE(r->bodies().size() == size_t(kNumProceduralShapes));
  for (int b = 0; b < kNumProceduralShapes; ++b) {
    // The front shows the whole body; together with the back every part has area.
    auto front = r->RenderScene(FrontScene(b, 0));
    auto back = r->RenderScene(FrontScene(b, 180));
    REQUIRE(front.ok());
    REQUIRE(back.ok());
    const auto cf = PartCounts(front->labels), cb = PartCounts(back->labels);
    for (int p = 0; p < core::kNumParts; ++p) {
      INFO(r->bodies()[size_t(b)].name << ": " << core::PartName(p) << " front " << cf[size_t(p)] << " back "
                                       << cb[size_t(p)]);
      CHECK(cf[size_t(p)] + cb[size_t(p)] >= 15);
    }
    // Facing the camera, the person's left is on the image's right (u > cx).
    double lu = 0, ru = 0;
    int ln = 0, rn = 0;
    for (int y = 0; y < 480; ++y) {
      for (int x = 0; x < 640; ++x) {
        const uint8_t l = front->labels.at(x, y);
        if (l == uint8_t(core::Part::kLHand)) lu += x, ++ln;
        if (l == uint8_t(core::Part::kRHand)) ru += x, ++rn;
      }
    }
    REQUIRE(ln > 0);
    REQUIRE(rn > 0);
    CHECK(lu / ln > 319.5);
    CHECK(ru / rn < 319.5);
    // Every joint of a front T-pose is visible, and projects onto the body near its part.
    for (int j = 0; j < core::kNumJoints; ++j) {
      INFO(r->bodies()[size_t(b)].name << " joint " << core::JointName(j) << " at "
                                       << front->joints[0][size_t(j)].transpose());
      CHECK(front->visible[0][size_t(j)]);
    }
    const Eigen::Vector2d head_uv = config.camera.Project(front->joints[0][0].cast<double>());
    const uint8_t head_label = front->labels.at(int(std::lround(head_uv.x())), int(std::lround(head_uv.y())));
    CHECK(head_label <= uint8_t(core::Part::kRWHead));
  }
}

TEST_CASE("Render(seed, index) is deterministic, across calls and renderer instances", "[egl]") {
  SceneConfig config = SmallConfig();
  config.min_people = 1;
  config.max_people = 3;
  auto a = Make(config);
  auto b = Make(config);
  int differing = 0;
  for (uint64_t i = 0; i < 6; ++i) {
    auto f1 = a->Render(77, i);
    auto f2 = a->Render(77, i);
    auto f3 = b->Render(77, i);
    REQUIRE(f1.ok());
    REQUIRE(f2.ok());
    REQUIRE(f3.ok());
    CHECK(f1->depth.pixels == f2->depth.pixels);
    CHECK(f1->labels.pixels == f2->labels.pixels);
    CHECK(f1->depth.pixels == f3->depth.pixels);
    CHECK(f1->labels.pixels == f3->labels.pixels);
    REQUIRE(f1->joints.size() == f3->joints.size());
    for (size_t p = 0; p < f1->joints.size(); ++p) {
      for (int j = 0; j < core::kNumJoints; ++j) CHECK(f1->joints[p][size_t(j)] == f3->joints[p][size_t(j)]);
      CHECK(f1->visible[p] == f3->visible[p]);
    }
    auto other = a->Render(78, i);
    REQUIRE(other.ok());
    differing += other->depth.pixels != f1->depth.pixels;
  }
  CHECK(differing == 6);
}

TEST_CASE("mirroring flips the image, swaps labels through MirrorPart and joints through MirrorJoint",
          "[egl]") {
  SceneConfig config = SmallConfig();
  config.noise.enabled = false;
  auto r = Make(config);
  for (uint64_t i = 0; i < 4; ++i) {
    SceneSample s = r->Sample(5, i);
    s.mirrored = false;
    auto plain = r->RenderScene(s);
    s.mirrored = true;
    auto mirrored = r->RenderScene(s);
    REQUIRE(plain.ok());
    REQUIRE(mirrored.ok());
    int fg = 0, agree = 0;
    for (int y = 0; y < 480; ++y) {
      for (int x = 0; x < 640; ++x) {
        const uint8_t a = plain->labels.at(639 - x, y), b = mirrored->labels.at(x, y);
        if (a == core::kBackgroundLabel && b == core::kBackgroundLabel) continue;
        ++fg;
        agree += a != core::kBackgroundLabel && b == uint8_t(core::MirrorPart(a)) &&
                 plain->depth.at(639 - x, y) == mirrored->depth.at(x, y);
      }
    }
    INFO("frame " << i << ": " << agree << " of " << fg << " foreground pixels agree");
    CHECK(fg > 500);
    CHECK(agree >= 0.995 * fg);  // only pixel centres exactly on an edge may differ
    for (int j = 0; j < core::kNumJoints; ++j) {
      const Eigen::Vector3f p = plain->joints[0][size_t(core::MirrorJoint(j))];
      const Eigen::Vector3f q = mirrored->joints[0][size_t(j)];
      CHECK(q.x() == Approx(-p.x()).margin(1e-5));
      CHECK(q.y() == Approx(p.y()).margin(1e-5));
      CHECK(q.z() == Approx(p.z()).margin(1e-5));
    }
  }
}

TEST_CASE("sampled scenes: people in range, visibility, noise on", "[egl]") {
  SceneConfig config = SmallConfig();
  config.min_people = 2;
  config.max_people = 3;
  auto r = Make(config);
  int frames_with_pixels = 0, visible = 0, total = 0;
  for (uint64_t i = 0; i < 10; ++i) {
    const SceneSample s = r->Sample(3, i);
    REQUIRE(s.people.size() >= 2);
    REQUIRE(s.people.size() <= 3);
    auto f = r->Render(3, i);
    REQUIRE(f.ok());
    REQUIRE(f->joints.size() == s.people.size());
    frames_with_pixels += core::CountForeground(f->depth) > 1000;
    for (size_t p = 0; p < f->joints.size(); ++p) {
      const double z = f->joints[p][0].z();
      CHECK(z > config.min_distance_m - 1.0);
      CHECK(z < config.max_distance_m + 1.0);
      for (bool v : f->visible[p]) visible += v, ++total;
    }
    for (size_t k = 0; k < f->depth.pixels.size(); ++k) {
      REQUIRE((f->depth.pixels[k] == 0) == (f->labels.pixels[k] == core::kBackgroundLabel));
    }
  }
  CHECK(frames_with_pixels >= 9);
  CHECK(visible > total / 3);  // many joints visible,
  CHECK(visible < total);      // but occlusion and cropping hide some
  // A person far outside the frustum: nothing rendered, nothing visible.
  SceneSample off = FrontScene(0, 0);
  off.people[0].camera_from_body.pretranslate(Eigen::Vector3d(20, 0, 0));
  auto f = r->RenderScene(off);
  REQUIRE(f.ok());
  CHECK(core::CountForeground(f->depth) == 0);
  for (bool v : f->visible[0]) CHECK_FALSE(v);
}

TEST_CASE("invalid scene configs are refused with the field named", "[egl]") {
  SceneConfig c;
  c.min_distance_m = 5;
  c.max_distance_m = 2;
  auto r = SyntheticRenderer::Create(c);
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().message().find("distance") != std::string::npos);
  SceneConfig c2;
  c2.max_people = 0;
  CHECK_FALSE(SyntheticRenderer::Create(c2).ok());
}

TEST_CASE("a renderer created on one thread renders on another, and can be handed back", "[egl]") {
  SceneConfig config = SmallConfig();
  auto r = Make(config);  // created here, context released by Create
  core::Result<RenderedFrame> on_thread = core::Status(core::ErrorCode::kInternal, "not run");
  std::thread t([&] {
    on_thread = r->Render(9, 1);
    r->ReleaseContext();
  });
  t.join();
  REQUIRE(on_thread.ok());
  auto here = r->Render(9, 1);
  REQUIRE(here.ok());
  CHECK(here->depth.pixels == on_thread->depth.pixels);
  CHECK(here->labels.pixels == on_thread->labels.pixels);
  // Without the hand-over, the other thread gets a clear error instead of a crash.
  core::Result<RenderedFrame> refused = core::Status(core::ErrorCode::kInternal, "not run");
  std::thread t2([&] { refused = r->Render(9, 2); });
  t2.join();
  REQUIRE_FALSE(refused.ok());
  CHECK(refused.status().message().find("ReleaseContext") != std::string::npos);
}

TEST_CASE("supplied poses and bodies are used; unlabelled bodies get labelled", "[egl]") {
  SceneConfig config;
  config.use_procedural_bodies = false;
  BodyMesh custom = MakeProceduralBody(ProceduralBaseShape(3));
  custom.name = "custom-unlabelled";
  custom.part.clear();
  config.bodies.push_back(custom);
  Pose arms_up;  // both upper arms straight up (rotation of +-X onto +Y)
  arms_up.rotation[size_t(int(SkelJoint::kLShoulder))] =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY());
  arms_up.rotation[size_t(int(SkelJoint::kRShoulder))] =
      Eigen::Quaterniond::FromTwoVectors(-Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY());
  arms_up.rotation[size_t(int(SkelJoint::kLElbow))] = arms_up.rotation[size_t(int(SkelJoint::kLShoulder))];
  arms_up.rotation[size_t(int(SkelJoint::kRElbow))] = arms_up.rotation[size_t(int(SkelJoint::kRShoulder))];
  arms_up.rotation[size_t(int(SkelJoint::kLWrist))] = arms_up.rotation[size_t(int(SkelJoint::kLShoulder))];
  arms_up.rotation[size_t(int(SkelJoint::kRWrist))] = arms_up.rotation[size_t(int(SkelJoint::kRShoulder))];
  const bool shared = GENERATE(false, true);
  if (shared) {
    config.shared_poses = std::make_shared<const std::vector<Pose>>(std::vector<Pose>{arms_up});
  } else {
    config.poses = {arms_up};
  }
  config.mirror_probability = 0;
  config.camera_roll_deg = 0;
  auto r = Make(config);
  REQUIRE(r->bodies().size() == 1);
  CHECK(r->bodies()[0].name == "custom-unlabelled");
  REQUIRE(r->bodies()[0].part.size() == r->bodies()[0].vertices.size());
  for (uint64_t i = 0; i < 5; ++i) {
    auto f = r->Render(1, i);
    REQUIRE(f.ok());
    // Hands above the head in the image (camera roll 0, small pitch): smaller v.
    const auto& j = f->joints[0];
    const Eigen::Vector2d head = config.camera.Project(j[size_t(int(core::Joint::kHead))].cast<double>());
    const Eigen::Vector2d lhand = config.camera.Project(j[size_t(int(core::Joint::kLHand))].cast<double>());
    const Eigen::Vector2d rhand = config.camera.Project(j[size_t(int(core::Joint::kRHand))].cast<double>());
    CHECK(lhand.y() < head.y());
    CHECK(rhand.y() < head.y());
  }
}

TEST_CASE("people in one frame stand apart on the floor", "[egl]") {
  SceneConfig config = SmallConfig();
  config.min_people = config.max_people = 3;
  auto r = Make(config);
  int close = 0;
  for (uint64_t i = 0; i < 100; ++i) {
    const SceneSample s = r->Sample(4, i);
    REQUIRE(s.people.size() == 3);
    for (size_t a = 0; a < 3; ++a) {
      for (size_t b = a + 1; b < 3; ++b) {
        // Pelvis positions in the camera frame; the floor distance is at least ~0.7 m.
        const Eigen::Vector3d pa = s.people[a].camera_from_body.translation();
        const Eigen::Vector3d pb = s.people[b].camera_from_body.translation();
        close += (pa - pb).norm() < 0.6;
      }
    }
  }
  CHECK(close <= 3);  // only when 8 retries all failed
}

TEST_CASE("upper-body framing: close camera, the frame cuts the body; off frames unchanged", "[egl]") {
  SceneConfig classic = SmallConfig();
  SceneConfig upper = classic;
  upper.framing.upper_body_share = 1.0;
  SceneConfig half = classic;
  half.framing.upper_body_share = 0.5;
  auto rc = Make(classic), ru = Make(upper), rh = Make(half);
  const int n = 24;
  int head_seen = 0, knees_out = 0, classic_knees_out = 0, same_as_classic = 0;
  for (uint64_t i = 0; i < n; ++i) {
    const SceneSample su = ru->Sample(5, i);
    const Eigen::Vector3d pelvis = su.people[0].camera_from_body.translation();
    const double ground = std::hypot(pelvis.x(), pelvis.z());  // roughly the distance drawn
    CHECK(ground > upper.framing.upper_body_min_distance_m - 0.3);
    CHECK(ground < upper.framing.upper_body_max_distance_m + 0.6);
    auto fu = ru->Render(5, i), fc = rc->Render(5, i), fh = rh->Render(5, i);
    REQUIRE(fu.ok());
    REQUIRE(fc.ok());
    REQUIRE(fh.ok());
    const auto& vis = fu->visible[0];
    head_seen += vis[size_t(core::Joint::kHead)] || vis[size_t(core::Joint::kNeck)];
    knees_out += !vis[size_t(core::Joint::kLKnee)] && !vis[size_t(core::Joint::kRKnee)];
    classic_knees_out += !fc->visible[0][size_t(core::Joint::kLKnee)] && !fc->visible[0][size_t(core::Joint::kRKnee)];
    // A frame the 0.5 share did not frame on the upper body is the classic frame, byte for byte.
    same_as_classic += fh->depth.pixels == fc->depth.pixels && fh->labels.pixels == fc->labels.pixels;
  }
  INFO("head seen " << head_seen << ", knees out " << knees_out << " (classic " << classic_knees_out
                    << "), half-share frames identical to classic " << same_as_classic);
  CHECK(head_seen >= n * 3 / 4);
  CHECK(knees_out >= n / 2);
  CHECK(classic_knees_out <= n / 4);
  CHECK(same_as_classic >= n / 4);
  CHECK(same_as_classic <= n * 3 / 4);
}

TEST_CASE("arm re-posing: a share of people; the others render as before", "[egl]") {
  SceneConfig classic = SmallConfig();
  SceneConfig arms = classic;
  arms.arm_pose_share = 0.5;
  auto rc = Make(classic), ra = Make(arms);
  int same = 0;
  const int n = 20;
  for (uint64_t i = 0; i < n; ++i) {
    auto fa = ra->Render(8, i), fc = rc->Render(8, i);
    REQUIRE(fa.ok());
    REQUIRE(fc.ok());
    same += fa->depth.pixels == fc->depth.pixels;
    // The trunk and the legs keep their pose (the camera may aim differently: raised hands
    // change the person's top, which sets the pitch): distances among them are unchanged.
    auto apart = [](const auto& joints, core::Joint a, core::Joint b) {
      return (joints[size_t(a)] - joints[size_t(b)]).norm();
    };
    for (auto [a, b] : {std::pair{core::Joint::kNeck, core::Joint::kLKnee}, std::pair{core::Joint::kHead, core::Joint::kRFoot},
                        std::pair{core::Joint::kLShoulder, core::Joint::kRAnkle}})
      CHECK(apart(fa->joints[0], a, b) == Approx(apart(fc->joints[0], a, b)).margin(1e-4));
  }
  INFO(same << " of " << n << " frames unchanged");
  CHECK(same >= n / 5);
  CHECK(same <= n * 4 / 5);
}

TEST_CASE("turned_share: a share of people take the wider heading range; the others are placed as before",
          "[egl]") {
  SceneConfig facing = SmallConfig();
  facing.rotation_range_deg = 0;  // everyone faces the camera
  SceneConfig mixed = facing;
  mixed.turned_share = 0.5;
  mixed.turned_range_deg = 180;
  SceneConfig off = facing;
  off.turned_range_deg = 180;  // the range alone changes nothing while the share is 0
  auto rf = Make(facing), rm = Make(mixed), ro = Make(off);
  const int n = 200;
  int turned = 0, behind = 0;
  double widest = 0;
  for (uint64_t i = 0; i < uint64_t(n); ++i) {
    const SceneSample f = rf->Sample(4, i), m = rm->Sample(4, i), o = ro->Sample(4, i);
    REQUIRE(f.people.size() == 1);
    REQUIRE(m.people.size() == 1);
    CHECK(o.people[0].camera_from_body.matrix() == f.people[0].camera_from_body.matrix());
    // The same camera and floor position either way (one draw of the main stream per heading):
    // the body's rotation relative to the facing one is its yaw about the vertical.
    CHECK(m.people[0].camera_from_body.translation().isApprox(f.people[0].camera_from_body.translation(), 1e-9));
    const Eigen::Matrix3d rel =
        f.people[0].camera_from_body.linear().transpose() * m.people[0].camera_from_body.linear();
    const double yaw = std::atan2(rel(0, 2), rel(0, 0)) * 180.0 / M_PI;
    CHECK(std::abs(rel(1, 1) - 1.0) < 1e-9);  // about the body's vertical only
    if (std::abs(yaw) > 1e-6) {
      ++turned;
      widest = std::max(widest, std::abs(yaw));
      behind += std::abs(yaw) > 90;
    } else {
      CHECK(m.people[0].camera_from_body.matrix() == f.people[0].camera_from_body.matrix());
    }
  }
  INFO(turned << " of " << n << " people turned, " << behind << " of them showing their back, widest " << widest);
  CHECK(turned >= n * 2 / 5);
  CHECK(turned <= n * 3 / 5);
  CHECK(behind >= turned / 3);
  CHECK(widest > 150);
  CHECK(widest <= 180);
  // Deterministic in (seed, index).
  CHECK(rm->Sample(4, 7).people[0].camera_from_body.matrix() == Make(mixed)->Sample(4, 7).people[0].camera_from_body.matrix());
  SceneConfig bad = mixed;
  bad.turned_share = -0.1;
  CHECK_FALSE(SyntheticRenderer::Create(bad).ok());
  bad = mixed;
  bad.turned_range_deg = 190;
  CHECK_FALSE(SyntheticRenderer::Create(bad).ok());
}

TEST_CASE("sitting and leaning: a share of people each; the others render as before", "[egl]") {
  SceneConfig classic = SmallConfig();
  SceneConfig sit = classic, lean = classic;
  sit.sit_share = 0.5;
  lean.lean_share = 0.5;
  auto rc = Make(classic), rs = Make(sit), rl = Make(lean);
  int same_sit = 0, same_lean = 0, knees_forward = 0;
  const int n = 20;
  for (uint64_t i = 0; i < n; ++i) {
    auto fc = rc->Render(9, i), fs = rs->Render(9, i), fl = rl->Render(9, i);
    REQUIRE(fc.ok());
    REQUIRE(fs.ok());
    REQUIRE(fl.ok());
    const bool s_same = fs->depth.pixels == fc->depth.pixels && fs->labels.pixels == fc->labels.pixels;
    const bool l_same = fl->depth.pixels == fc->depth.pixels && fl->labels.pixels == fc->labels.pixels;
    same_sit += s_same;
    same_lean += l_same;
    if (!s_same) {
      // Sat down: the knees come up toward the hips (thighs forward), so the hip-to-knee height
      // difference shrinks against the classic frame's.
      const auto& js = fs->joints[0];
      const auto& jc = fc->joints[0];
      auto drop = [](const auto& j) {  // mean vertical distance from the neck to the knees, camera y is down
        return 0.5 * ((j[size_t(core::Joint::kLKnee)] - j[size_t(core::Joint::kNeck)]).norm() +
                      (j[size_t(core::Joint::kRKnee)] - j[size_t(core::Joint::kNeck)]).norm());
      };
      knees_forward += drop(js) < drop(jc);
    }
  }
  INFO("sitting: " << same_sit << " of " << n << " frames unchanged, knees nearer the neck in " << knees_forward
                   << "; leaning: " << same_lean << " unchanged");
  CHECK(same_sit >= n / 5);
  CHECK(same_sit <= n * 4 / 5);
  CHECK(knees_forward >= (n - same_sit) * 3 / 4);
  CHECK(same_lean >= n / 5);
  CHECK(same_lean <= n * 4 / 5);
  // Shares outside [0, 1] are refused.
  SceneConfig bad = classic;
  bad.sit_share = 1.5;
  CHECK_FALSE(SyntheticRenderer::Create(bad).ok());
}
