#include "renderer/pose_sampler.h"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "runtime/core/rng.h"

namespace poseforest::renderer {
namespace {

using Eigen::AngleAxisd;
using Eigen::Quaterniond;
using Eigen::Vector3d;
using J = SkelJoint;

constexpr double kDeg = std::numbers::pi / 180.0;

Quaterniond Rx(double deg) { return Quaterniond(AngleAxisd(deg * kDeg, Vector3d::UnitX())); }
Quaterniond Ry(double deg) { return Quaterniond(AngleAxisd(deg * kDeg, Vector3d::UnitY())); }
Quaterniond Rz(double deg) { return Quaterniond(AngleAxisd(deg * kDeg, Vector3d::UnitZ())); }

/// Swing the rest bone direction onto `dir`, then twist about `dir` by twist_deg.
Quaterniond SwingTwist(const Vector3d& rest_dir, const Vector3d& dir, double twist_deg) {
  const Quaterniond swing = Quaterniond::FromTwoVectors(rest_dir, dir.normalized());
  return Quaterniond(AngleAxisd(twist_deg * kDeg, dir.normalized())) * swing;
}

// The pose family (0 standing, 1 walking, 2 crouching, 3 kicking, 4 legs apart, 5 free), drawn
// with the config's weights.
int ChooseFamily(core::RngStream& rng, const PoseSamplerConfig& cfg) {
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  const double total =
      cfg.p_standing + cfg.p_walking + cfg.p_crouching + cfg.p_kicking + cfg.p_wide + cfg.p_free;
  double r = U(0.0, total);
  int family = 0;
  for (double p : {cfg.p_standing, cfg.p_walking, cfg.p_crouching, cfg.p_kicking, cfg.p_wide, cfg.p_free}) {
    if (r < p) break;
    r -= p;
    ++family;
  }
  family = std::min(family, 5);
  return family;
}

// Hip, knee and pelvis-lean angles, degrees, per side (0 = left).
struct LegAngles {
  double hip_flex[2];  ///< + = thigh forward
  double hip_abd[2];   ///< + = outward
  double knee[2];
  double lean;  ///< + = pelvis leans forward
};

// The leg angles of a pose of `family`: a standing spread, then the family's own.
LegAngles SampleLegAngles(core::RngStream& rng, int family) {
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  // Braced initialisers are evaluated in order: the draws keep their order.
  LegAngles g{{U(-10, 20), U(-10, 20)}, {U(-5, 12), U(-5, 12)}, {U(0, 20), U(0, 20)}, U(-8, 12)};
  double* hip_flex = g.hip_flex;
  double* hip_abd = g.hip_abd;
  double* knee = g.knee;
  double& lean = g.lean;
  switch (family) {
    case 1: {  // walking / running
      const int front = int(rng.UniformInt(2));
      hip_flex[front] = U(10, 55);
      hip_flex[1 - front] = U(-30, 0);
      knee[front] = U(0, 70);
      knee[1 - front] = U(10, 100);
      lean = U(0, 20);
      break;
    }
    case 2: {  // crouching / squatting / sitting
      const double f = U(50, 110);
      hip_flex[0] = f + U(-10, 10);
      hip_flex[1] = f + U(-10, 10);
      knee[0] = std::min(145.0, f + U(0, 40));
      knee[1] = std::min(145.0, f + U(0, 40));
      hip_abd[0] = U(0, 25);
      hip_abd[1] = U(0, 25);
      lean = U(10, 45);
      break;
    }
    case 3: {  // kicking / leg raised (forward or sideways)
      const int leg = int(rng.UniformInt(2));
      hip_flex[leg] = U(20, 100);
      hip_abd[leg] = U(-5, 45);
      knee[leg] = U(0, 90);
      break;
    }
    case 4:  // legs apart
      hip_abd[0] = U(10, 40);
      hip_abd[1] = U(10, 40);
      knee[0] = U(0, 35);
      knee[1] = U(0, 35);
      break;
    case 5:
      for (int s = 0; s < 2; ++s) {
        hip_flex[s] = U(-30, 110);
        hip_abd[s] = U(-15, 45);
        knee[s] = U(0, 140);
      }
      lean = U(-15, 45);
      break;
    default:
      break;
  }
  return g;
}

using LocalRotations = std::array<Quaterniond, kNumSkelJoints>;

void SetLegRotations(core::RngStream& rng, const LegAngles& g, LocalRotations& local) {
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  auto L = [&](J j) -> Quaterniond& { return local[size_t(int(j))]; };
  const double* hip_flex = g.hip_flex;
  const double* hip_abd = g.hip_abd;
  const double* knee = g.knee;
  const double lean = g.lean;
  // Legs. Thigh rest direction is -Y; hip flexion is measured from the vertical, so the pelvis
  // lean (which turns the legs back with it) is added back. Flexion turns it towards +Z (rotation about X by
  // -angle), abduction towards the side; knee flexion turns the shin back (+angle about X).
  for (int s = 0; s < 2; ++s) {
    const double sx = s == 0 ? 1.0 : -1.0;  // left = +X
    const J hip = s == 0 ? J::kLHip : J::kRHip;
    const J kn = s == 0 ? J::kLKnee : J::kRKnee;
    const J an = s == 0 ? J::kLAnkle : J::kRAnkle;
    L(hip) = Rz(sx * hip_abd[s]) * Rx(-(hip_flex[s] + lean)) * Ry(sx * U(-20, 30));
    L(kn) = Rx(knee[s]);
    L(an) = Rx(U(-25, 25)) * Rz(U(-10, 10));
  }
}

void SetArmRotations(core::RngStream& rng, const PoseSamplerConfig& cfg, LocalRotations& local) {
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  auto L = [&](J j) -> Quaterniond& { return local[size_t(int(j))]; };
  // Arms. Upper arm rest direction is +-X (T-pose). Sample a direction: elevation e (up +) and
  // azimuth a (forward +), then a twist; the elbow only flexes (forearm turns forward/up).
  for (int s = 0; s < 2; ++s) {
    const double sx = s == 0 ? 1.0 : -1.0;
    const J collar = s == 0 ? J::kLCollar : J::kRCollar;
    const J sh = s == 0 ? J::kLShoulder : J::kRShoulder;
    const J el = s == 0 ? J::kLElbow : J::kRElbow;
    const J wr = s == 0 ? J::kLWrist : J::kRWrist;
    const bool relaxed = rng.Uniform01() < cfg.p_arms_relaxed;
    const double e = relaxed ? U(-82, -45) : U(-82, 85);
    const double a = relaxed ? U(-15, 45) : U(-35, 110);
    const Vector3d rest_dir(sx, 0, 0);
    const Vector3d dir(sx * std::cos(e * kDeg) * std::cos(a * kDeg), std::sin(e * kDeg),
                       std::cos(e * kDeg) * std::sin(a * kDeg));
    L(collar) = Rz(sx * U(-5, 12)) * Ry(sx * U(-8, 8));  // shrug / protract
    L(sh) = SwingTwist(rest_dir, dir, U(-40, 40));
    const double flex = relaxed ? U(0, 70) : U(0, 145);
    // Flexion axis: the forearm turns towards +Z in the upper arm's frame (about -Y on the left).
    L(el) = SwingTwist(rest_dir, Vector3d(sx * std::cos(flex * kDeg), 0, std::sin(flex * kDeg)), U(-30, 30));
    L(wr) = Ry(sx * U(-30, 30)) * Rz(U(-40, 40));
  }
}

}  // namespace

Pose SampleProceduralPose(uint64_t seed, uint64_t index, const PoseSamplerConfig& cfg) {
  core::RngStream rng(core::CounterRng(seed, 0x9053, index, 0x5A3B1E));
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };

  // Local rotations (in the parent's frame; the rest frames are all aligned with the body).
  LocalRotations local;
  local.fill(Quaterniond::Identity());
  auto L = [&](J j) -> Quaterniond& { return local[size_t(int(j))]; };

  // Choose the family.
  const int family = ChooseFamily(rng, cfg);
  const bool free = family == 5;

  // Trunk: pelvis lean, spine and chest bend/side-bend/twist, neck and head.
  const LegAngles legs = SampleLegAngles(rng, family);
  const double lean = legs.lean;
  L(J::kPelvis) = Ry(U(-15, 15)) * Rx(lean) * Rz(U(-6, 6));
  L(J::kSpine) = Ry(U(-20, 20)) * Rx(U(-10, free ? 35 : 20)) * Rz(U(-12, 12));
  L(J::kChest) = Ry(U(-15, 15)) * Rx(U(-10, 15)) * Rz(U(-8, 8));
  L(J::kNeck) = Ry(U(-20, 20)) * Rx(U(-15, 25)) * Rz(U(-10, 10));
  L(J::kHead) = Ry(U(-45, 45)) * Rx(U(-25, 30)) * Rz(U(-15, 15));

  SetLegRotations(rng, legs, local);
  SetArmRotations(rng, cfg, local);

  Pose pose;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const int p = kSkelParent[size_t(j)];
    pose.rotation[size_t(j)] =
        (p < 0 ? local[size_t(j)] : pose.rotation[size_t(p)] * local[size_t(j)]).normalized();
  }
  return pose;
}

void PerturbArms(uint64_t seed, uint64_t index, Pose* pose) {
  core::RngStream rng(core::CounterRng(seed, 0xA4A5, index, 0x7E4C));
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  const double which = rng.Uniform01();  // both arms, the left only, or the right only
  for (int s = 0; s < 2; ++s) {
    if ((s == 0 && which >= 0.7) || (s == 1 && which < 0.3)) continue;
    const double sx = s == 0 ? 1.0 : -1.0;
    const J collar = s == 0 ? J::kLCollar : J::kRCollar;
    const J sh = s == 0 ? J::kLShoulder : J::kRShoulder;
    const J el = s == 0 ? J::kLElbow : J::kRElbow;
    const J wr = s == 0 ? J::kLWrist : J::kRWrist;
    const J tip = s == 0 ? J::kLHandTip : J::kRHandTip;
    // Elevation e (up +) and azimuth a (0 = sideways as in the T-pose, 90 = straight forward,
    // beyond 90 = across the body), as SampleProceduralPose draws them, narrowed to the front.
    const bool reach = rng.Uniform01() < 0.5;
    const double e = reach ? U(-35, 50) : U(-70, 10);
    const double a = reach ? U(45, 110) : U(20, 100);
    const double flex = reach ? U(0, 70) : U(90, 145);  // the hand comes back to the face or body
    const Vector3d rest_dir(sx, 0, 0);
    const Vector3d dir(sx * std::cos(e * kDeg) * std::cos(a * kDeg), std::sin(e * kDeg),
                       std::cos(e * kDeg) * std::sin(a * kDeg));
    auto& R = pose->rotation;
    const Quaterniond tip_local = R[size_t(int(wr))].conjugate() * R[size_t(int(tip))];
    R[size_t(int(sh))] = (R[size_t(int(collar))] * SwingTwist(rest_dir, dir, U(-40, 40))).normalized();
    R[size_t(int(el))] =
        (R[size_t(int(sh))] *
         SwingTwist(rest_dir, Vector3d(sx * std::cos(flex * kDeg), 0, std::sin(flex * kDeg)), U(-30, 30)))
            .normalized();
    R[size_t(int(wr))] = (R[size_t(int(el))] * Ry(sx * U(-30, 30)) * Rz(U(-40, 40))).normalized();
    R[size_t(int(tip))] = (R[size_t(int(wr))] * tip_local).normalized();
  }
}

void LeanTrunk(uint64_t seed, uint64_t index, Pose* pose) {
  core::RngStream rng(core::CounterRng(seed, 0x1EA7, index, 0x7E4C));
  // Forward (+angle about X turns the trunk's up toward +Z, where the person faces) more often
  // than back; sideways about Z.
  const double forward = rng.Uniform01() < 0.8 ? rng.UniformIn(5, 35) : rng.UniformIn(-15, -5);
  const double side = rng.UniformIn(-15, 15);
  // The lean turns about the pelvis's frame (a pitched or turned pelvis keeps its own axes).
  const Quaterniond pelvis = pose->rotation[size_t(int(J::kPelvis))];
  const Quaterniond q = (pelvis * Rz(side) * Rx(forward) * pelvis.conjugate()).normalized();
  // The spine and every joint below it in the tree (parents come before children).
  std::array<bool, kNumSkelJoints> moved{};
  for (int j = 0; j < kNumSkelJoints; ++j) {
    const int p = kSkelParent[size_t(j)];
    moved[size_t(j)] = j == int(J::kSpine) || (p >= 0 && moved[size_t(p)]);
    if (moved[size_t(j)]) pose->rotation[size_t(j)] = (q * pose->rotation[size_t(j)]).normalized();
  }
}

void SitDown(uint64_t seed, uint64_t index, Pose* pose) {
  core::RngStream rng(core::CounterRng(seed, 0x517D, index, 0x7E4C));
  auto U = [&](double lo, double hi) { return rng.UniformIn(lo, hi); };
  auto& R = pose->rotation;
  const Quaterniond pelvis = R[size_t(int(J::kPelvis))];
  const double flex = U(65, 100);  // both thighs about alike: one seat
  for (int s = 0; s < 2; ++s) {
    const double sx = s == 0 ? 1.0 : -1.0;  // left = +X
    const J hip = s == 0 ? J::kLHip : J::kRHip;
    const J kn = s == 0 ? J::kLKnee : J::kRKnee;
    const J an = s == 0 ? J::kLAnkle : J::kRAnkle;
    const J toe = s == 0 ? J::kLToe : J::kRToe;
    const Quaterniond toe_local = R[size_t(int(an))].conjugate() * R[size_t(int(toe))];
    const double hip_flex = flex + U(-8, 8), knee = U(60, 105);
    // As SampleProceduralPose: flexion turns the thigh (rest -Y) toward +Z (about X by -angle),
    // abduction to the side, the knee turns the shin back (+angle about X).
    R[size_t(int(hip))] = (pelvis * Rz(sx * U(0, 12)) * Rx(-hip_flex) * Ry(sx * U(-10, 15))).normalized();
    R[size_t(int(kn))] = (R[size_t(int(hip))] * Rx(knee)).normalized();
    // The foot back near the pelvis's horizontal: undo the shin's tilt, within +-15 degrees.
    R[size_t(int(an))] = (R[size_t(int(kn))] * Rx(hip_flex - knee + U(-15, 15))).normalized();
    R[size_t(int(toe))] = (R[size_t(int(an))] * toe_local).normalized();
  }
}

}  // namespace poseforest::renderer
