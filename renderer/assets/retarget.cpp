#include "renderer/assets/retarget.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poseforest::renderer::assets {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;
using J = SkelJoint;

constexpr int I(J j) { return int(j); }

/// Left-side names -> both sides by substitution.
void AddSides(std::vector<std::pair<J, std::vector<std::string>>>& out, J left, J right,
              std::vector<std::string> left_names, const std::string& l, const std::string& r) {
  std::vector<std::string> right_names;
  for (const auto& n : left_names) {
    std::string s = n;
    size_t pos = s.find(l);
    if (pos != std::string::npos) s.replace(pos, l.size(), r);
    right_names.push_back(s);
  }
  out.push_back({left, std::move(left_names)});
  out.push_back({right, std::move(right_names)});
}

RigNameMap Build(std::string family, std::vector<std::pair<J, std::vector<std::string>>> centre,
                 const std::array<std::vector<std::string>, 9>& left, const std::string& l,
                 const std::string& r) {
  std::vector<std::pair<J, std::vector<std::string>>> e = std::move(centre);
  const J lj[9] = {J::kLCollar, J::kLShoulder, J::kLElbow, J::kLWrist, J::kLHandTip,
                   J::kLHip,    J::kLKnee,     J::kLAnkle, J::kLToe};
  const J rj[9] = {J::kRCollar, J::kRShoulder, J::kRElbow, J::kRWrist, J::kRHandTip,
                   J::kRHip,    J::kRKnee,     J::kRAnkle, J::kRToe};
  for (int k = 0; k < 9; ++k) AddSides(e, lj[k], rj[k], left[size_t(k)], l, r);
  RigNameMap m;
  m.family = std::move(family);
  for (const auto& [j, names] : e) m.names[size_t(I(j))] = names;
  return m;
}

std::vector<RigNameMap> BuildMocapMaps() {
  std::vector<RigNameMap> maps;
  maps.push_back(Build("cmu_cgspeed",
                       {{J::kPelvis, {"Hips"}},
                        {J::kSpine, {"Spine"}},
                        {J::kChest, {"Spine1"}},
                        {J::kNeck, {"Neck1", "Neck"}},
                        {J::kHead, {"Head"}},
                        {J::kHeadTop, {"Head_End"}}},
                       {{{"LeftShoulder"},
                         {"LeftArm"},
                         {"LeftForeArm"},
                         {"LeftHand"},
                         {"LFingers_End", "LFingers", "LeftFingerBase_End", "LeftFingerBase"},
                         {"LeftUpLeg"},
                         {"LeftLeg"},
                         {"LeftFoot"},
                         {"LeftToeBase"}}},
                       "Left", "Right"));
  // The L prefix of cgspeed's finger joints ("LFingers") needs its own substitution.
  maps.back().names[size_t(I(J::kRHandTip))] = {"RFingers_End", "RFingers", "RightFingerBase_End",
                                                "RightFingerBase"};
  maps.push_back(Build("reallusion_cc3",
                       {{J::kPelvis, {"CC_Base_Hip"}},
                        {J::kSpine, {"CC_Base_Waist"}},
                        {J::kChest, {"CC_Base_Spine02", "CC_Base_Spine01"}},
                        {J::kNeck, {"CC_Base_NeckTwist01"}},
                        {J::kHead, {"CC_Base_Head"}},
                        {J::kHeadTop, {}}},
                       {{{"CC_Base_L_Clavicle"},
                         {"CC_Base_L_Upperarm"},
                         {"CC_Base_L_Forearm"},
                         {"CC_Base_L_Hand"},
                         {"CC_Base_L_Mid3_End", "CC_Base_L_Mid3", "CC_Base_L_Mid1"},
                         {"CC_Base_L_Thigh"},
                         {"CC_Base_L_Calf"},
                         {"CC_Base_L_Foot"},
                         {"CC_Base_L_ToeBase"}}},
                       "_L_", "_R_"));
  maps.push_back(Build("bandai_namco",
                       {{J::kPelvis, {"Hips"}},
                        {J::kSpine, {"Spine"}},
                        {J::kChest, {"Chest"}},
                        {J::kNeck, {"Neck"}},
                        {J::kHead, {"Head"}},
                        {J::kHeadTop, {"Head_End"}}},
                       {{{"Shoulder_L"},
                         {"UpperArm_L"},
                         {"LowerArm_L"},
                         {"Hand_L"},
                         {"Hand_L_End"},
                         {"UpperLeg_L"},
                         {"LowerLeg_L"},
                         {"Foot_L"},
                         {"Toes_L"}}},
                       "_L", "_R"));
  maps.push_back(Build("biovision",
                       {{J::kPelvis, {"Hips"}},
                        {J::kSpine, {"Ab"}},
                        {J::kChest, {"Chest"}},
                        {J::kNeck, {"Neck"}},
                        {J::kHead, {"Head"}},
                        {J::kHeadTop, {"Head_End"}}},
                       {{{"LeftCollar"},
                         {"LeftShoulder"},
                         {"LeftElbow"},
                         {"LeftWrist"},
                         {"LeftWrist_End"},
                         {"LeftHip"},
                         {"LeftKnee"},
                         {"LeftAnkle"},
                         {"LeftToes", "LeftToe"}}},
                       "Left", "Right"));
  return maps;
}

std::vector<RigNameMap> BuildMeshMaps() {
  std::vector<RigNameMap> maps;
  maps.push_back(Build("makehuman_default",
                       // MakeHuman's `root` bone starts behind the pelvis; spine05 starts between the hips.
                       {{J::kPelvis, {"spine05"}},
                        {J::kSpine, {"spine03"}},
                        {J::kChest, {"spine01"}},
                        {J::kNeck, {"neck01"}},
                        {J::kHead, {"head"}},
                        {J::kHeadTop, {"head@tail"}}},
                       {{{"clavicle.L"},
                         {"upperarm01.L"},
                         {"lowerarm01.L"},
                         {"wrist.L"},
                         {"finger3-3.L@tail"},
                         {"upperleg01.L"},
                         {"lowerleg01.L"},
                         {"foot.L"},
                         {"toe3-1.L", "toe1-1.L"}}},
                       ".L", ".R"));
  maps.push_back(Build("mixamo",
                       {{J::kPelvis, {"Hips"}},
                        {J::kSpine, {"Spine"}},
                        {J::kChest, {"Spine2", "Spine1"}},
                        {J::kNeck, {"Neck"}},
                        {J::kHead, {"Head"}},
                        {J::kHeadTop, {"HeadTop_End"}}},
                       {{{"LeftShoulder"},
                         {"LeftArm"},
                         {"LeftForeArm"},
                         {"LeftHand"},
                         {"LeftHandMiddle4"},
                         {"LeftUpLeg"},
                         {"LeftLeg"},
                         {"LeftFoot"},
                         {"LeftToeBase"}}},
                       "Left", "Right"));
  maps.push_back(Build("quaternius",
                       {{J::kPelvis, {"Hips"}},
                        {J::kSpine, {"Abdomen"}},
                        {J::kChest, {"Chest", "Torso"}},
                        {J::kNeck, {"Neck"}},
                        {J::kHead, {"Head"}},
                        {J::kHeadTop, {}}},
                       {{{"Shoulder.L"},
                         {"UpperArm.L"},
                         {"LowerArm.L"},
                         {"Wrist.L", "Fist.L"},
                         {},
                         {"UpperLeg.L"},
                         {"LowerLeg.L"},
                         {"Foot.L"},
                         {"Toes.L", "Toe.L"}}},
                       ".L", ".R"));
  maps.push_back(Build("cesium_man",
                       {{J::kPelvis, {"Skeleton_torso_joint_1"}},
                        {J::kSpine, {"Skeleton_torso_joint_2"}},
                        {J::kChest, {"torso_joint_3"}},
                        {J::kNeck, {"Skeleton_neck_joint_1"}},
                        {J::kHead, {"Skeleton_neck_joint_2"}},
                        {J::kHeadTop, {}}},
                       {{{},
                         {"Skeleton_arm_joint_L__4_"},
                         {"Skeleton_arm_joint_L__3_"},
                         {"Skeleton_arm_joint_L__2_"},
                         {},
                         {"leg_joint_L_1"},
                         {"leg_joint_L_2"},
                         {"leg_joint_L_3"},
                         {"leg_joint_L_5"}}},
                       "_L", "_R"));
  // CesiumMan's right arm chain is named differently from its left one.
  auto& c = maps.back().names;
  c[size_t(I(J::kRShoulder))] = {"Skeleton_arm_joint_R"};
  c[size_t(I(J::kRElbow))] = {"Skeleton_arm_joint_R__2_"};
  c[size_t(I(J::kRWrist))] = {"Skeleton_arm_joint_R__3_"};
  return maps;
}

Eigen::Vector3d P(const SkelPositions& s, J j) { return s[size_t(I(j))]; }

/// Orthonormal frame (columns x, y, z) with y exactly along `primary` and x from `secondary`.
/// Returns false when degenerate.
bool FrameFrom(const Eigen::Vector3d& primary, const Eigen::Vector3d& secondary, Eigen::Matrix3d* f) {
  if (primary.norm() < 1e-9) return false;
  const Eigen::Vector3d y = primary.normalized();
  Eigen::Vector3d x = secondary - secondary.dot(y) * y;
  if (x.norm() < 1e-9) return false;
  x.normalize();
  const Eigen::Vector3d z = x.cross(y);
  f->col(0) = x;
  f->col(1) = y;
  f->col(2) = z;
  return true;
}

Eigen::Quaterniond SwingBetween(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  if (from.norm() < 1e-9 || to.norm() < 1e-9) return Eigen::Quaterniond::Identity();
  return Eigen::Quaterniond::FromTwoVectors(from, to);
}

}  // namespace

const std::vector<RigNameMap>& MocapNameMaps() {
  static const std::vector<RigNameMap> maps = BuildMocapMaps();
  return maps;
}

const std::vector<RigNameMap>& MeshRigNameMaps() {
  static const std::vector<RigNameMap> maps = BuildMeshMaps();
  return maps;
}

std::string_view StripRigPrefix(std::string_view name) {
  const size_t p = name.find_last_of(":|");
  return p == std::string_view::npos ? name : name.substr(p + 1);
}

bool IsRequiredJoint(int joint) {
  switch (J(joint)) {
    case J::kSpine:
    case J::kHeadTop:
    case J::kLCollar:
    case J::kRCollar:
    case J::kLHandTip:
    case J::kRHandTip:
    case J::kLToe:
    case J::kRToe:
      return false;
    default:
      return true;
  }
}

Result<RigNameMap> BoneMapFromPairs(const std::vector<std::pair<std::string, std::string>>& pairs,
                                    const std::string& family) {
  RigNameMap map;
  map.family = family;
  for (const auto& [joint, bone] : pairs) {
    int j = -1;
    for (int k = 0; k < kNumSkelJoints; ++k)
      if (SkelJointName(k) == joint) j = k;
    if (j < 0) {
      std::string known;
      for (int k = 0; k < kNumSkelJoints; ++k) known += (k ? ", " : "") + std::string(SkelJointName(k));
      return Status(ErrorCode::kInvalidArgument, "unknown canonical joint '" + joint + "' (known: " + known + ")");
    }
    if (bone.empty()) return Status(ErrorCode::kInvalidArgument, "joint '" + joint + "': empty bone name");
    map.names[size_t(j)].push_back(bone);
  }
  return map;
}

Result<std::array<int, kNumSkelJoints>> ResolveJoints(const std::vector<std::string>& names,
                                                      const std::vector<RigNameMap>& maps,
                                                      const std::string& source, std::string* family) {
  std::array<int, kNumSkelJoints> best{};
  best.fill(-1);
  int best_required = -1;
  std::string best_family;
  for (const auto& m : maps) {
    std::array<int, kNumSkelJoints> idx{};
    idx.fill(-1);
    int required = 0;
    for (int j = 0; j < kNumSkelJoints; ++j) {
      for (const auto& cand : m.names[size_t(j)]) {
        for (size_t i = 0; i < names.size() && idx[size_t(j)] < 0; ++i)
          if (StripRigPrefix(names[i]) == cand) idx[size_t(j)] = int(i);
        if (idx[size_t(j)] >= 0) break;
      }
      // Score: required joints first, then any mapped joint (ties go to the fuller map).
      if (idx[size_t(j)] >= 0) required += IsRequiredJoint(j) ? 100 : 1;
    }
    if (required > best_required) best_required = required, best = idx, best_family = m.family;
  }
  std::string missing;
  for (int j = 0; j < kNumSkelJoints; ++j) {
    if (IsRequiredJoint(j) && best[size_t(j)] < 0) {
      if (!missing.empty()) missing += ", ";
      missing += std::string(SkelJointName(j));
      std::string wanted;
      for (const auto& m : maps)
        if (m.family == best_family)
          for (const auto& c : m.names[size_t(j)]) wanted += (wanted.empty() ? "" : "|") + c;
      if (!wanted.empty()) missing += " (" + wanted + ")";
    }
  }
  if (!missing.empty()) {
    std::string known;
    for (const auto& m : maps) known += (known.empty() ? "" : ", ") + m.family;
    return Status(ErrorCode::kInvalidArgument,
                  source + ": unknown skeleton: no name map (" + known + ") finds the canonical joints " +
                      missing + (best_family.empty() ? "" : "; closest map: " + best_family));
  }
  if (family) *family = best_family;
  return best;
}

double LegLength(const SkelPositions& s) {
  const double l = (P(s, J::kLKnee) - P(s, J::kLHip)).norm() + (P(s, J::kLAnkle) - P(s, J::kLKnee)).norm();
  const double r = (P(s, J::kRKnee) - P(s, J::kRHip)).norm() + (P(s, J::kRAnkle) - P(s, J::kRKnee)).norm();
  return 0.5 * (l + r);
}

Eigen::Vector3d FacingDirection(const SkelPositions& s) {
  Eigen::Vector3d left = Eigen::Vector3d::Zero();
  const Eigen::Vector3d hips = P(s, J::kLHip) - P(s, J::kRHip);
  const Eigen::Vector3d shoulders = P(s, J::kLShoulder) - P(s, J::kRShoulder);
  if (hips.norm() > 1e-9) left += hips.normalized();
  if (shoulders.norm() > 1e-9) left += shoulders.normalized();
  left.y() = 0;
  if (left.norm() < 1e-9) return Eigen::Vector3d::UnitZ();
  left.normalize();
  return left.cross(Eigen::Vector3d::UnitY()).normalized();
}

Result<CanonicalTracks> ExtractCanonicalTracks(const BvhClip& clip) {
  std::vector<std::string> names;
  names.reserve(clip.joints.size());
  // A zero-length End Site (Bandai Namco's Head_End in some clips, CC3's finger ends) says
  // nothing about direction: hide it so the estimate is used instead.
  for (const auto& j : clip.joints)
    names.push_back(j.end_site && j.offset.norm() * clip.unit_to_m < 0.005 ? j.name + "#degenerate" : j.name);
  CanonicalTracks tracks;
  tracks.source = clip.source;
  auto resolved = ResolveJoints(names, MocapNameMaps(), clip.source, &tracks.family);
  if (!resolved.ok()) return resolved.status();
  const auto& idx = *resolved;
  tracks.frames.resize(size_t(clip.num_frames));
  double floor = std::numeric_limits<double>::infinity();
  std::vector<Eigen::Vector3d> world;
  for (int f = 0; f < clip.num_frames; ++f) {
    ForwardKinematics(clip, f, &world, nullptr);
    SkelPositions& s = tracks.frames[size_t(f)];
    for (int j = 0; j < kNumSkelJoints; ++j)
      if (idx[size_t(j)] >= 0) s[size_t(j)] = world[size_t(idx[size_t(j)])];
    // Estimates for optional joints the family lacks.
    auto has = [&](J j) { return idx[size_t(I(j))] >= 0; };
    if (!has(J::kSpine)) s[size_t(I(J::kSpine))] = 0.5 * (P(s, J::kPelvis) + P(s, J::kChest));
    if (!has(J::kHeadTop)) {
      const Eigen::Vector3d d = P(s, J::kHead) - P(s, J::kNeck);
      s[size_t(I(J::kHeadTop))] =
          P(s, J::kHead) + (d.norm() > 1e-9 ? d.normalized() * 0.2 : Eigen::Vector3d(0, 0.2, 0));
    }
    for (auto [collar, shoulder] :
         {std::pair{J::kLCollar, J::kLShoulder}, std::pair{J::kRCollar, J::kRShoulder}})
      if (!has(collar)) s[size_t(I(collar))] = P(s, J::kNeck) + (P(s, shoulder) - P(s, J::kNeck)) / 3.0;
    for (auto [tip, wrist, elbow] :
         {std::tuple{J::kLHandTip, J::kLWrist, J::kLElbow}, std::tuple{J::kRHandTip, J::kRWrist, J::kRElbow}})
      if (!has(tip)) s[size_t(I(tip))] = P(s, wrist) + 0.7 * (P(s, wrist) - P(s, elbow));
    const Eigen::Vector3d fwd = FacingDirection(s);
    for (auto [toe, ankle] : {std::pair{J::kLToe, J::kLAnkle}, std::pair{J::kRToe, J::kRAnkle}})
      if (!has(toe)) s[size_t(I(toe))] = P(s, ankle) + 0.14 * fwd - Eigen::Vector3d(0, 0.05, 0);
    for (J j : {J::kLAnkle, J::kRAnkle, J::kLToe, J::kRToe}) floor = std::min(floor, P(s, j).y());
  }
  if (!tracks.frames.empty()) tracks.leg_length_m = LegLength(tracks.frames[0]);
  tracks.floor_y_m = std::isfinite(floor) ? floor : 0.0;
  if (clip.num_frames > 0 && !(tracks.leg_length_m > 1e-3))
    return Status(ErrorCode::kDataLoss, clip.source + ": degenerate skeleton (zero leg length)");
  return tracks;
}

Pose RetargetPositions(const SkelPositions& src_in, const SkelPositions& rest, const Eigen::Quaterniond& yaw,
                       double root_y, const Eigen::Vector2d& root_xz) {
  SkelPositions src;
  for (int j = 0; j < kNumSkelJoints; ++j) src[size_t(j)] = yaw * src_in[size_t(j)];
  std::array<Eigen::Quaterniond, kNumSkelJoints> g;
  for (auto& q : g) q = Eigen::Quaterniond::Identity();

  auto frame_rotation = [&](J j, J primary_child, J sec_a, J sec_b, const Eigen::Quaterniond& fallback) {
    Eigen::Matrix3d fr, fs;
    const bool ok_r = FrameFrom(P(rest, primary_child) - P(rest, j), P(rest, sec_a) - P(rest, sec_b), &fr);
    const bool ok_s = FrameFrom(P(src, primary_child) - P(src, j), P(src, sec_a) - P(src, sec_b), &fs);
    if (!ok_r || !ok_s) return fallback;
    return Eigen::Quaterniond(fs * fr.transpose()).normalized();
  };

  for (int j = 0; j < kNumSkelJoints; ++j) {
    const int p = kSkelParent[size_t(j)];
    const Eigen::Quaterniond parent = p < 0 ? Eigen::Quaterniond::Identity() : g[size_t(p)];
    if (J(j) == J::kPelvis) {
      g[size_t(j)] = frame_rotation(J::kPelvis, J::kSpine, J::kLHip, J::kRHip, parent);
      continue;
    }
    if (J(j) == J::kChest) {
      // The collar line moves rigidly with the chest in most rigs; where the collars sit on the
      // spine (cgspeed CMU) the shoulder line stands in.
      const bool collars = (P(rest, J::kLCollar) - P(rest, J::kRCollar)).norm() > 0.02 &&
                           (P(src, J::kLCollar) - P(src, J::kRCollar)).norm() > 0.02;
      g[size_t(j)] = collars ? frame_rotation(J::kChest, J::kNeck, J::kLCollar, J::kRCollar, parent)
                             : frame_rotation(J::kChest, J::kNeck, J::kLShoulder, J::kRShoulder, parent);
      continue;
    }
    int child = -1;
    for (int c = 0; c < kNumSkelJoints; ++c)
      if (kSkelParent[size_t(c)] == j) {
        child = c;
        break;
      }
    if (child < 0) {
      g[size_t(j)] = parent;  // leaf: follows its parent
      continue;
    }
    const Eigen::Vector3d d_rest = parent * (rest[size_t(child)] - rest[size_t(j)]);
    const Eigen::Vector3d d_src = src[size_t(child)] - src[size_t(j)];
    g[size_t(j)] = (SwingBetween(d_rest, d_src) * parent).normalized();
  }
  Pose pose;
  pose.rotation = g;
  pose.root_translation = Eigen::Vector3d(root_xz.x(), root_y, root_xz.y());
  return pose;
}

namespace {
double LowestFootY(const SkelPositions& s) {
  double y = std::numeric_limits<double>::infinity();
  for (J j : {J::kLAnkle, J::kRAnkle, J::kLToe, J::kRToe}) y = std::min(y, P(s, j).y());
  return y;
}
}  // namespace

std::vector<Pose> RetargetTracks(const CanonicalTracks& tracks, const SkelPositions& rest,
                                 const RetargetOptions& options) {
  std::vector<Pose> poses;
  poses.reserve(tracks.frames.size());
  if (tracks.frames.empty()) return poses;
  const double scale = LegLength(rest) / tracks.leg_length_m;
  const double rest_floor = LowestFootY(rest);

  auto yaw_for = [](const SkelPositions& s) {
    const Eigen::Vector3d f = FacingDirection(s);
    return Eigen::Quaterniond::FromTwoVectors(f, Eigen::Vector3d::UnitZ());
  };
  const Eigen::Quaterniond first_yaw = yaw_for(tracks.frames[0]);
  const Eigen::Vector3d first_pelvis = P(tracks.frames[0], J::kPelvis);
  for (const auto& s : tracks.frames) {
    const Eigen::Quaterniond yaw = options.facing == FacingMode::kPerFrame ? yaw_for(s) : first_yaw;
    Eigen::Vector2d xz = Eigen::Vector2d::Zero();
    if (options.keep_horizontal_translation) {
      Eigen::Vector3d d = first_yaw * (P(s, J::kPelvis) - first_pelvis);
      xz = scale * Eigen::Vector2d(d.x(), d.z());
    }
    Pose pose = RetargetPositions(s, rest, yaw, 0.0, xz);
    // Vertical: the lowest foot joint is as high above the target's floor as the source's is
    // above its floor (scaled), so feet that touch the ground keep touching it.
    const double posed_low = LowestFootY(PoseJoints(rest, pose));
    pose.root_translation.y() = scale * (LowestFootY(s) - tracks.floor_y_m) - (posed_low - rest_floor);
    poses.push_back(pose);
  }
  return poses;
}

Pose AdaptPose(const Pose& pose, const SkelPositions& to_rest, const SkelPositions& from_rest) {
  const SkelPositions posed = PoseJoints(from_rest, pose);
  const double scale = LegLength(to_rest) / LegLength(from_rest);
  const Eigen::Vector2d xz(scale * pose.root_translation.x(), scale * pose.root_translation.z());
  Pose out = RetargetPositions(posed, to_rest, Eigen::Quaterniond::Identity(), 0.0, xz);
  const double low = LowestFootY(PoseJoints(to_rest, out));
  out.root_translation.y() =
      scale * (LowestFootY(posed) - LowestFootY(from_rest)) - (low - LowestFootY(to_rest));
  return out;
}

Pose AdaptPose(const Pose& pose, const SkelPositions& to_rest) {
  return AdaptPose(pose, to_rest, ReferenceRestJoints());
}

Result<std::vector<Pose>> RetargetClip(const BvhClip& clip, const SkelPositions& target_rest,
                                       const RetargetOptions& options) {
  auto tracks = ExtractCanonicalTracks(clip);
  if (!tracks.ok()) return tracks.status();
  return RetargetTracks(*tracks, target_rest, options);
}

const SkelPositions& ReferenceRestJoints() {
  static const SkelPositions joints = [] {
    SkelPositions s;
    auto set = [&](J j, double x, double y, double z) { s[size_t(I(j))] = Eigen::Vector3d(x, y, z); };
    // Adult proportions (about 1.75 m), T-pose, feet on y = 0.
    set(J::kPelvis, 0, 0.95, 0);
    set(J::kSpine, 0, 1.10, -0.01);
    set(J::kChest, 0, 1.30, -0.02);
    set(J::kNeck, 0, 1.47, -0.02);
    set(J::kHead, 0, 1.58, 0);
    set(J::kHeadTop, 0, 1.75, 0);
    for (int side : {+1, -1}) {
      const bool l = side > 0;
      set(l ? J::kLCollar : J::kRCollar, side * 0.03, 1.43, 0);
      set(l ? J::kLShoulder : J::kRShoulder, side * 0.18, 1.43, -0.02);
      set(l ? J::kLElbow : J::kRElbow, side * 0.47, 1.43, -0.02);
      set(l ? J::kLWrist : J::kRWrist, side * 0.73, 1.43, -0.02);
      set(l ? J::kLHandTip : J::kRHandTip, side * 0.91, 1.43, -0.02);
      set(l ? J::kLHip : J::kRHip, side * 0.09, 0.92, 0);
      set(l ? J::kLKnee : J::kRKnee, side * 0.09, 0.50, 0.01);
      set(l ? J::kLAnkle : J::kRAnkle, side * 0.09, 0.08, -0.02);
      set(l ? J::kLToe : J::kRToe, side * 0.09, 0.02, 0.13);
    }
    return s;
  }();
  return joints;
}

}  // namespace poseforest::renderer::assets
