#include "engine/real_frames.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "runtime/core/forest_format.h"

namespace poseforest::engine {
namespace {

namespace fs = std::filesystem;
using core::ErrorCode;
using core::Status;
using nlohmann::json;

constexpr int kLabelMarginPx = 3;  // a labelled pixel this close to a mask counts as on it
const int kMaskMarginPx = runtime::SkeletonOptions{}.mask_margin_px;  // as the skeleton's mask test

Status Bad(const std::string& path, const std::string& what) {
  return Status(ErrorCode::kDataLoss, path + ": " + what);
}

// The mask label within `margin` pixels of (u, v) that the pixel itself has, else any nearby.
bool OnMask(const core::LabelImage& masks, int label, double u, double v, int margin) {
  const int x0 = int(std::lround(u)), y0 = int(std::lround(v));
  for (int dy = -margin; dy <= margin; ++dy)
    for (int dx = -margin; dx <= margin; ++dx)
      if (masks.InBounds(x0 + dx, y0 + dy) && masks.at(x0 + dx, y0 + dy) == label) return true;
  return false;
}

double Median(std::vector<double> v) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

Eigen::Vector3d RealJointLabel::Target() const {
  const double n = surface_m.norm();
  return n > 0 ? Eigen::Vector3d(surface_m * (1.0 + kSurfaceToCentreM / n)) : surface_m;
}

core::Result<RealLabelSet> ReadRealLabels(const std::string& path) {
  auto text = core::ReadFileText(path);
  if (!text.ok()) return text.status();
  json doc;
  try {
    doc = json::parse(*text);
  } catch (const json::exception& e) {
    return Bad(path, std::string("not JSON: ") + e.what());
  }
  RealLabelSet set;
  const fs::path folder = fs::path(path).parent_path();
  try {
    if (!doc.is_object() || !doc.contains("camera") || !doc.contains("frames"))
      return Bad(path, "expected an object with \"camera\" and \"frames\"");
    const json& cam = doc.at("camera");
    core::CameraIntrinsics& k = set.camera.intrinsics;
    k.width = cam.at("width").get<int>(), k.height = cam.at("height").get<int>();
    k.fx = cam.at("fx").get<double>(), k.fy = cam.at("fy").get<double>();
    k.cx = cam.at("cx").get<double>(), k.cy = cam.at("cy").get<double>();
    set.camera.name = "custom";
    if (k.width <= 0 || k.height <= 0 || k.width > 16384 || k.height > 16384 || !(k.fx > 0) || !(k.fy > 0) ||
        !std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) || !std::isfinite(k.cy))
      return Bad(path, "camera: width, height, fx and fy must be positive and finite");
    if (!doc.at("frames").is_array() || doc.at("frames").empty()) return Bad(path, "\"frames\" is empty");
    for (const json& f : doc.at("frames")) {
      RealFrameLabels frame;
      frame.file = f.at("file").get<std::string>();
      if (frame.file.empty()) return Bad(path, "a frame has an empty \"file\"");
      frame.path = fs::path(frame.file).is_absolute() ? frame.file : (folder / frame.file).string();
      const std::string where = "frame " + frame.file + ": ";
      const json& joints = f.at("joints");
      if (!joints.is_object()) return Bad(path, where + "\"joints\" must be an object");
      for (const auto& [name, j] : joints.items()) {
        int index = -1;
        for (int q = 0; q < core::kNumJoints; ++q)
          if (core::JointName(q) == name) index = q;
        if (index < 0) return Bad(path, where + "unknown joint '" + name + "'");
        if (j.is_null()) continue;
        RealJointLabel label;
        const auto uv = j.at("uv").get<std::vector<double>>();
        const auto xyz = j.at("xyz_m").get<std::vector<double>>();
        if (uv.size() != 2 || xyz.size() != 3) return Bad(path, where + name + ": uv needs 2 numbers, xyz_m 3");
        label.uv = Eigen::Vector2d(uv[0], uv[1]);
        label.surface_m = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
        label.err_px = j.value("err_px", 0.0);
        label.occluded = j.value("occluded", false);
        if (!label.uv.allFinite() || !label.surface_m.allFinite() || !(label.surface_m.z() > 0))
          return Bad(path, where + name + ": uv and xyz_m must be finite, with z > 0");
        if (label.uv.x() < 0 || label.uv.y() < 0 || label.uv.x() >= k.width || label.uv.y() >= k.height)
          return Bad(path, where + name + ": uv lies outside the " + std::to_string(k.width) + "x" +
                               std::to_string(k.height) + " camera");
        frame.joints[size_t(index)] = label;
      }
      set.frames.push_back(std::move(frame));
    }
  } catch (const json::exception& e) {
    return Bad(path, std::string("malformed label file: ") + e.what());
  }
  return set;
}

Status WriteRealLabels(const std::string& path, const RealLabelSet& set) {
  const core::CameraIntrinsics& k = set.camera.intrinsics;
  json doc;
  doc["camera"] = {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"width", k.width}, {"height", k.height}};
  json names = json::array();
  for (int q = 0; q < core::kNumJoints; ++q) names.push_back(std::string(core::JointName(q)));
  doc["joint_names"] = names;
  json frames = json::array();
  for (const RealFrameLabels& f : set.frames) {
    json joints = json::object();
    for (int q = 0; q < core::kNumJoints; ++q) {
      const auto& l = f.joints[size_t(q)];
      const std::string name(core::JointName(q));
      if (!l) {
        joints[name] = nullptr;
        continue;
      }
      joints[name] = {{"uv", {l->uv.x(), l->uv.y()}},
                      {"err_px", l->err_px},
                      {"occluded", l->occluded},
                      {"xyz_m", {l->surface_m.x(), l->surface_m.y(), l->surface_m.z()}}};
    }
    frames.push_back({{"file", f.file}, {"joints", joints}});
  }
  doc["frames"] = frames;
  std::ofstream out(path);
  out << doc.dump(1) << "\n";
  if (!out) return Status(ErrorCode::kIo, path + ": cannot write");
  return Status::Ok();
}

int PickLabelledSkeleton(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame) {
  int best = -1, best_hits = 0, best_pixels = 0;
  for (size_t s = 0; s < frame.skeletons.size(); ++s) {
    const runtime::Skeleton& sk = frame.skeletons[s];
    int hits = 0;
    for (const auto& l : labels.joints)
      if (l && OnMask(frame.masks, sk.mask_label, l->uv.x(), l->uv.y(), kLabelMarginPx)) ++hits;
    if (hits > best_hits || (hits == best_hits && hits > 0 && sk.pixels > best_pixels))
      best = int(s), best_hits = hits, best_pixels = sk.pixels;
  }
  return best;
}

RealFrameOutcome ScoreRealFrame(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame, int skeleton) {
  RealFrameOutcome out;
  out.file = labels.file;
  out.skeleton = skeleton;
  const runtime::Skeleton* sk =
      skeleton >= 0 && size_t(skeleton) < frame.skeletons.size() ? &frame.skeletons[size_t(skeleton)] : nullptr;
  for (int q = 0; q < core::kNumJoints; ++q) {
    const auto& label = labels.joints[size_t(q)];
    RealJointOutcome& o = out.joints[size_t(q)];
    if (!label) continue;
    o.labelled = true;
    if (!sk) continue;
    const Eigen::Vector3d target = label->Target();
    const runtime::SkeletonJoint& j = sk->joints[size_t(q)];
    if (j.found && (j.position_m.cast<double>() - target).norm() <= kRealHitRadiusM) o.found_right = o.any_right = true;
    if (j.tracked) {
      o.tracked = true;
      o.error_m = (j.position_m.cast<double>() - target).norm();
      o.error_px = (j.pixel.cast<double>() - label->uv).norm();
      o.right = o.error_m <= kRealHitRadiusM;
    }
    for (const runtime::JointProposal& p : frame.proposals[size_t(q)]) {
      if (o.any_right) break;
      if (!OnMask(frame.masks, sk->mask_label, p.pixel.x(), p.pixel.y(), kMaskMarginPx)) continue;
      if ((p.position.cast<double>() - target).norm() <= kRealHitRadiusM) o.any_right = true;
    }
  }
  return out;
}

RealScore SummarizeReal(const std::vector<RealFrameOutcome>& frames) {
  using core::Joint;
  auto row = [&](const std::string& name, const std::vector<int>& joints) {
    RealScoreRow r;
    r.name = name;
    std::vector<double> px;
    for (const RealFrameOutcome& f : frames)
      for (int q : joints) {
        const RealJointOutcome& o = f.joints[size_t(q)];
        if (!o.labelled) continue;
        ++r.labelled;
        r.tracked += o.tracked, r.right += o.right, r.found_right += o.found_right, r.any_right += o.any_right;
        if (o.tracked) px.push_back(o.error_px);
      }
    r.median_error_px = Median(px);
    return r;
  };
  RealScore score;
  std::vector<int> all;
  for (int q = 0; q < core::kNumJoints; ++q) {
    RealScoreRow r = row(std::string(core::JointName(q)), {q});
    if (r.labelled == 0) continue;
    score.joints.push_back(r);
    all.push_back(q);
  }
  auto j = [](Joint x) { return int(x); };
  const std::vector<std::pair<std::string, std::vector<int>>> groups = {
      {"head, neck, shoulders", {j(Joint::kHead), j(Joint::kNeck), j(Joint::kLShoulder), j(Joint::kRShoulder)}},
      {"elbows", {j(Joint::kLElbow), j(Joint::kRElbow)}},
      {"wrists", {j(Joint::kLWrist), j(Joint::kRWrist)}},
      {"hands", {j(Joint::kLHand), j(Joint::kRHand)}},
      {"knees, ankles, feet",
       {j(Joint::kLKnee), j(Joint::kRKnee), j(Joint::kLAnkle), j(Joint::kRAnkle), j(Joint::kLFoot), j(Joint::kRFoot)}},
      {"elbows, wrists, hands",
       {j(Joint::kLElbow), j(Joint::kRElbow), j(Joint::kLWrist), j(Joint::kRWrist), j(Joint::kLHand), j(Joint::kRHand)}},
  };
  for (const auto& [name, joints] : groups) {
    RealScoreRow r = row(name, joints);
    if (r.labelled > 0) score.groups.push_back(r);
  }
  score.groups.push_back(row("all", all));
  return score;
}

std::string FormatRealScore(const RealScore& score) {
  std::ostringstream s;
  char line[256];
  std::snprintf(line, sizeof line, "%-24s %9s %8s %14s %10s %15s %18s\n", "joint", "labelled", "tracked",
                "within 0.10 m", "median px", "found within", "any within 0.10 m");
  s << line;
  auto put = [&](const RealScoreRow& r) {
    char px[32] = "-";
    if (r.median_error_px >= 0) std::snprintf(px, sizeof px, "%.1f", r.median_error_px);
    std::snprintf(line, sizeof line, "%-24s %9d %8d %6d (%.3f) %10s %7d (%.3f) %9d (%.3f)\n", r.name.c_str(),
                  r.labelled, r.tracked, r.right, r.right_fraction(), px, r.found_right,
                  r.labelled ? double(r.found_right) / r.labelled : 0.0, r.any_right, r.any_fraction());
    s << line;
  };
  for (const RealScoreRow& r : score.joints) put(r);
  s << "\n";
  for (const RealScoreRow& r : score.groups) put(r);
  s << "(found within: the skeleton's position of the joint, tracked or not; any within: that or any of the\n"
       " joint's proposals on the person: what the forest found, before the skeleton's rules)\n";
  return s.str();
}

runtime::RgbImage RealFramePicture(const RealFrameLabels& labels, const runtime::SkeletonFrame& frame,
                                   const RealFrameOutcome& outcome) {
  std::vector<runtime::Skeleton> shown;
  if (outcome.skeleton >= 0 && size_t(outcome.skeleton) < frame.skeletons.size())
    shown.push_back(frame.skeletons[size_t(outcome.skeleton)]);
  const core::DepthImage& depth = *frame.depth;
  runtime::RgbImage fig = runtime::SkeletonFigure(depth, frame.classification.labels, shown, 1);
  const float ox = float(depth.width) * 2;
  for (int q = 0; q < core::kNumJoints; ++q) {
    const auto& l = labels.joints[size_t(q)];
    if (!l) continue;
    const RealJointOutcome& o = outcome.joints[size_t(q)];
    const core::Rgb colour = o.right ? core::Rgb{40, 230, 40} : core::Rgb{255, 40, 40};
    const float u = float(l->uv.x()) + ox, v = float(l->uv.y());
    if (o.tracked) {
      const auto& p = shown.front().joints[size_t(q)].pixel;
      runtime::DrawLine(fig, u, v, p.x() + ox, p.y(), colour, 1);
    }
    // A cross: the label, distinct from the skeleton's discs.
    runtime::DrawLine(fig, u - 6, v - 6, u + 6, v + 6, colour, 2);
    runtime::DrawLine(fig, u - 6, v + 6, u + 6, v - 6, colour, 2);
  }
  const int right = [&] {
    int n = 0;
    for (const auto& o : outcome.joints) n += o.right;
    return n;
  }();
  int labelled = 0;
  for (const auto& o : outcome.joints) labelled += o.labelled;
  runtime::DrawText(fig, int(ox) + 8, depth.height - 20,
                    std::to_string(right) + "/" + std::to_string(labelled) + " RIGHT", {255, 255, 255}, 2);
  return fig;
}

}  // namespace poseforest::engine
