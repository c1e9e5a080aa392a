#include "renderer/assets/bvh.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "runtime/core/forest_format.h"

namespace poseforest::renderer::assets {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;

constexpr double kPi = 3.14159265358979323846;
constexpr double kCgspeedUnitM = 0.056444;  // CMU FAQ: (1/0.45) * 2.54 cm

/// Splits text into lines (LF or CRLF), keeping 1-based line numbers.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}
  bool Next(std::string_view* line) {
    if (pos_ >= text_.size()) return false;
    size_t end = text_.find('\n', pos_);
    if (end == std::string_view::npos) end = text_.size();
    std::string_view l = text_.substr(pos_, end - pos_);
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    pos_ = end + 1;
    ++line_no_;
    *line = l;
    return true;
  }
  int line_no() const { return line_no_; }

 private:
  std::string_view text_;
  size_t pos_ = 0;
  int line_no_ = 0;
};

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

std::vector<std::string_view> SplitWords(std::string_view line) {
  std::vector<std::string_view> words;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && IsSpace(line[i])) ++i;
    size_t j = i;
    while (j < line.size() && !IsSpace(line[j])) ++j;
    if (j > i) words.push_back(line.substr(i, j - i));
    i = j;
  }
  return words;
}

bool ParseDouble(std::string_view w, double* out) {
  if (!w.empty() && w.front() == '+') w.remove_prefix(1);
  if (w.empty()) return false;
  const char* end = w.data() + w.size();
  auto [ptr, ec] = std::from_chars(w.data(), end, *out);
  return ec == std::errc() && ptr == end && std::isfinite(*out);
}

struct Token {
  std::string_view text;
  int line;
};

Status Malformed(const std::string& source, int line, const std::string& what) {
  return Status(ErrorCode::kDataLoss, source + ":" + std::to_string(line) + ": " + what);
}

Eigen::Matrix3d AxisRotation(BvhChannel c, double degrees) {
  const double r = degrees * kPi / 180.0;
  switch (c) {
    case BvhChannel::kXrot:
      return Eigen::AngleAxisd(r, Eigen::Vector3d::UnitX()).toRotationMatrix();
    case BvhChannel::kYrot:
      return Eigen::AngleAxisd(r, Eigen::Vector3d::UnitY()).toRotationMatrix();
    case BvhChannel::kZrot:
      return Eigen::AngleAxisd(r, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    default:
      return Eigen::Matrix3d::Identity();
  }
}

bool HasJoint(const std::vector<BvhJoint>& joints, std::string_view name) {
  for (const auto& j : joints)
    if (j.name == name) return true;
  return false;
}

/// Rest leg length (hip -> knee -> ankle offsets), file units; 0 when no leg is found.
double RestLegLength(const std::vector<BvhJoint>& joints) {
  // Longest chain of 2 consecutive offsets below a joint whose name mentions a left leg part.
  double best = 0;
  for (size_t i = 0; i < joints.size(); ++i) {
    const auto& j = joints[i];
    if (j.parent < 0) continue;
    const auto& p = joints[size_t(j.parent)];
    if (p.parent < 0) continue;
    // j = knee-ish (child of hip-ish): thigh = |j.offset|, shin = |child.offset|.
    std::string lower;
    for (char c : p.name) lower += char(std::tolower(static_cast<unsigned char>(c)));
    const bool hipish =
        (lower.find("upleg") != std::string::npos || lower.find("thigh") != std::string::npos ||
         lower.find("upperleg") != std::string::npos || lower.find("lefthip") != std::string::npos ||
         lower == "l_hip" || lower.find("hip_l") != std::string::npos);
    if (!hipish) continue;
    for (size_t k = 0; k < joints.size(); ++k) {
      if (joints[k].parent != int(i)) continue;
      best = std::max(best, j.offset.norm() + joints[k].offset.norm());
    }
  }
  return best;
}

double GuessUnit(const std::vector<BvhJoint>& joints) {
  const double leg = RestLegLength(joints);
  if (leg <= 0) return 0.01;  // cm is by far the most common BVH unit
  const double candidates[] = {0.001, 0.01, 0.0254, kCgspeedUnitM, 1.0};
  double best = 0.01, best_err = 1e30;
  for (double s : candidates) {
    const double err = std::abs(std::log(leg * s / 0.85));  // adult hip->ankle ~ 0.85 m
    if (err < best_err) best_err = err, best = s;
  }
  return best;
}

}  // namespace

std::string_view SkeletonFamilyName(SkeletonFamily family) {
  switch (family) {
    case SkeletonFamily::kCmuCgspeed:
      return "cmu_cgspeed";
    case SkeletonFamily::kReallusionCC3:
      return "reallusion_cc3";
    case SkeletonFamily::kBandaiNamco:
      return "bandai_namco";
    case SkeletonFamily::kBiovision:
      return "biovision";
    case SkeletonFamily::kUnknown:
      break;
  }
  return "unknown";
}

int BvhClip::FindJoint(std::string_view name) const {
  for (size_t i = 0; i < joints.size(); ++i)
    if (joints[i].name == name) return int(i);
  return -1;
}

SkeletonFamily DetectFamily(const std::vector<BvhJoint>& joints) {
  if (HasJoint(joints, "CC_Base_Hip") && HasJoint(joints, "CC_Base_L_Thigh"))
    return SkeletonFamily::kReallusionCC3;
  if (HasJoint(joints, "LHipJoint") && HasJoint(joints, "LeftUpLeg") && HasJoint(joints, "LowerBack"))
    return SkeletonFamily::kCmuCgspeed;
  if (HasJoint(joints, "UpperLeg_L") && HasJoint(joints, "LowerArm_L")) return SkeletonFamily::kBandaiNamco;
  if (HasJoint(joints, "LeftHip") && HasJoint(joints, "LeftKnee") && HasJoint(joints, "LeftElbow"))
    return SkeletonFamily::kBiovision;
  return SkeletonFamily::kUnknown;
}

void ForwardKinematics(const BvhClip& clip, int f, std::vector<Eigen::Vector3d>* positions,
                       std::vector<Eigen::Matrix3d>* rotations) {
  POSEFOREST_CHECK(f >= 0 && f < clip.num_frames);
  const double* values = clip.Frame(f);
  const size_t n = clip.joints.size();
  std::vector<Eigen::Vector3d> pos(n);
  std::vector<Eigen::Matrix3d> rot(n);
  for (size_t i = 0; i < n; ++i) {
    const BvhJoint& j = clip.joints[i];
    Eigen::Vector3d t = j.offset;
    Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
    for (size_t c = 0; c < j.channels.size(); ++c) {
      const double v = values[j.first_channel + int(c)];
      switch (j.channels[c]) {
        // Position channels replace the offset component (what every exporter of the staged
        // data means: the Bandai Namco and soccer files carry the rest offset in both).
        case BvhChannel::kXpos:
          t.x() = v;
          break;
        case BvhChannel::kYpos:
          t.y() = v;
          break;
        case BvhChannel::kZpos:
          t.z() = v;
          break;
        default:
          r = r * AxisRotation(j.channels[c], v);
          break;
      }
    }
    if (j.parent < 0) {
      pos[i] = t;
      rot[i] = r;
    } else {
      const size_t p = size_t(j.parent);
      pos[i] = pos[p] + rot[p] * t;
      rot[i] = rot[p] * r;
    }
  }
  for (size_t i = 0; i < n; ++i) {
    pos[i] = clip.world_fix * (pos[i] * clip.unit_to_m);
    rot[i] = clip.world_fix * rot[i];
  }
  if (positions) *positions = std::move(pos);
  if (rotations) *rotations = std::move(rot);
}

std::vector<Eigen::Vector3d> ForwardKinematics(const BvhClip& clip, int f) {
  std::vector<Eigen::Vector3d> pos;
  ForwardKinematics(clip, f, &pos, nullptr);
  return pos;
}

namespace {

// The channels of one CHANNELS line (the count, then that many names on the line) into `j`,
// numbered from `channel_count`, which it advances.
Status ParseChannels(const std::vector<Token>& tokens, size_t& t, const Token& tok, const std::string& source,
                     BvhJoint& j, int& channel_count) {
  auto at_end = [&] { return t >= tokens.size(); };
  double n = 0;
  if (at_end() || !ParseDouble(tokens[t].text, &n) || n < 0 || n > 6 || n != std::floor(n))
    return Malformed(source, tok.line, "CHANNELS needs a count 0..6");
  ++t;
  j.channels.clear();
  j.first_channel = channel_count;
  for (int k = 0; k < int(n); ++k) {
    if (at_end() || tokens[t].line != tok.line)
      return Malformed(source, tok.line,
                       "CHANNELS declares " + std::to_string(int(n)) + " channels but lists fewer");
    const std::string_view c = tokens[t++].text;
    BvhChannel ch;
    if (c == "Xposition")
      ch = BvhChannel::kXpos;
    else if (c == "Yposition")
      ch = BvhChannel::kYpos;
    else if (c == "Zposition")
      ch = BvhChannel::kZpos;
    else if (c == "Xrotation")
      ch = BvhChannel::kXrot;
    else if (c == "Yrotation")
      ch = BvhChannel::kYrot;
    else if (c == "Zrotation")
      ch = BvhChannel::kZrot;
    else
      return Malformed(source, tok.line, "unknown channel '" + std::string(c) + "'");
    j.channels.push_back(ch);
  }
  channel_count += int(n);
  return Status::Ok();
}

// The HIERARCHY section into clip.joints and clip.num_channels; the reader stops at MOTION.
Status ParseHierarchy(LineReader& reader, const std::string& source, BvhClip& clip) {
  std::string_view line;
  // --- HIERARCHY: tokenised across lines until MOTION. ---
  std::vector<Token> tokens;
  bool saw_motion = false;
  while (reader.Next(&line)) {
    auto words = SplitWords(line);
    if (!words.empty() && words[0] == "MOTION") {
      saw_motion = true;
      break;
    }
    for (auto w : words) tokens.push_back({w, reader.line_no()});
  }
  const int last_line = reader.line_no();
  size_t t = 0;
  auto at_end = [&] { return t >= tokens.size(); };
  auto here = [&] { return at_end() ? last_line : tokens[t].line; };
  if (at_end() || tokens[0].text != "HIERARCHY")
    return Malformed(source, here(), "expected HIERARCHY at the start of a BVH file");
  ++t;

  std::vector<int> stack;  // open joints
  int channel_count = 0;
  bool have_root = false;
  while (!at_end()) {
    const Token tok = tokens[t++];
    if (tok.text == "ROOT" || tok.text == "JOINT" || tok.text == "End") {
      BvhJoint j;
      if (tok.text == "End") {
        if (at_end() || tokens[t].text != "Site")
          return Malformed(source, tok.line, "expected 'Site' after 'End'");
        ++t;
        if (stack.empty()) return Malformed(source, tok.line, "End Site outside a joint");
        j.end_site = true;
        j.name = clip.joints[size_t(stack.back())].name + "_End";
      } else {
        if (at_end() || tokens[t].line != tok.line)
          return Malformed(source, tok.line, std::string(tok.text) + " without a name");
        j.name = std::string(tokens[t++].text);
        if (tok.text == "ROOT") {
          if (!stack.empty()) return Malformed(source, tok.line, "ROOT inside another joint");
          if (have_root) return Malformed(source, tok.line, "more than one ROOT (not supported)");
          have_root = true;
        } else if (stack.empty()) {
          return Malformed(source, tok.line, "JOINT " + j.name + " outside ROOT");
        }
      }
      j.parent = stack.empty() ? -1 : stack.back();
      if (at_end() || tokens[t].text != "{") return Malformed(source, here(), "expected '{' after " + j.name);
      ++t;
      clip.joints.push_back(std::move(j));
      stack.push_back(int(clip.joints.size()) - 1);
    } else if (tok.text == "OFFSET") {
      if (stack.empty()) return Malformed(source, tok.line, "OFFSET outside a joint");
      Eigen::Vector3d o;
      for (int k = 0; k < 3; ++k) {
        if (at_end() || tokens[t].line != tok.line)
          return Malformed(source, tok.line, "OFFSET needs 3 numbers");
        if (!ParseDouble(tokens[t].text, &o[k]))
          return Malformed(source, tok.line,
                           "OFFSET value '" + std::string(tokens[t].text) + "' is not a number");
        ++t;
      }
      clip.joints[size_t(stack.back())].offset = o;
    } else if (tok.text == "CHANNELS") {
      if (stack.empty()) return Malformed(source, tok.line, "CHANNELS outside a joint");
      BvhJoint& j = clip.joints[size_t(stack.back())];
      if (j.end_site) return Malformed(source, tok.line, "CHANNELS in an End Site");
      if (Status st = ParseChannels(tokens, t, tok, source, j, channel_count); !st.ok()) return st;
    } else if (tok.text == "}") {
      if (stack.empty()) return Malformed(source, tok.line, "unbalanced '}'");
      stack.pop_back();
    } else {
      return Malformed(source, tok.line, "unexpected '" + std::string(tok.text) + "' in HIERARCHY");
    }
  }
  if (!have_root) return Malformed(source, last_line, "no ROOT joint (truncated hierarchy?)");
  if (!stack.empty())
    return Malformed(
        source, last_line,
        "hierarchy ends inside joint " + clip.joints[size_t(stack.back())].name + " (truncated file?)");
  if (!saw_motion) return Malformed(source, last_line, "no MOTION section (truncated file?)");
  clip.num_channels = channel_count;
  return Status::Ok();
}

// The MOTION header: 'Frames: N' and 'Frame Time: seconds'.
Status ParseMotionHeader(LineReader& reader, const std::string& source, BvhClip& clip) {
  std::string_view line;
  // --- MOTION header ---
  auto next_nonempty = [&](std::vector<std::string_view>* words) {
    while (reader.Next(&line)) {
      *words = SplitWords(line);
      if (!words->empty()) return true;
    }
    return false;
  };
  std::vector<std::string_view> words;
  if (!next_nonempty(&words))
    return Malformed(source, reader.line_no(), "missing 'Frames:' after MOTION (truncated file?)");
  double frames_d = 0;
  if (words[0] == "Frames:" && words.size() == 2 && ParseDouble(words[1], &frames_d)) {
  } else if (words[0] == "Frames" && words.size() == 3 && words[1] == ":" &&
             ParseDouble(words[2], &frames_d)) {
  } else {
    return Malformed(source, reader.line_no(), "expected 'Frames: N'");
  }
  if (frames_d < 0 || frames_d != std::floor(frames_d) || frames_d > 1e8)
    return Malformed(source, reader.line_no(), "bad frame count");
  const int declared = int(frames_d);
  clip.declared_frames = declared;
  if (!next_nonempty(&words))
    return Malformed(source, reader.line_no(), "missing 'Frame Time:' (truncated file?)");
  {
    double ft = 0;
    const bool ok =
        words.size() == 3 && words[0] == "Frame" && words[1] == "Time:" && ParseDouble(words[2], &ft);
    if (!ok || !(ft > 0)) return Malformed(source, reader.line_no(), "expected 'Frame Time: seconds' (> 0)");
    clip.frame_time_s = ft;
  }
  return Status::Ok();
}

// The frames' channel values into clip.motion.
Status ParseFrames(LineReader& reader, const std::string& source, int declared, int channel_count,
                   BvhClip& clip) {
  // --- Frames: exactly `declared` lines ---
  clip.motion.resize(size_t(declared) * size_t(channel_count));
  for (int f = 0; f < declared; ++f) {
    std::string_view l;
    bool got = false;
    while (reader.Next(&l)) {
      // Blank lines between frames are skipped.
      if (l.find_first_not_of(" \t\r\f\v") != std::string_view::npos) {
        got = true;
        break;
      }
    }
    if (!got)
      return Malformed(source, reader.line_no(),
                       "file ends after " + std::to_string(f) + " of the " + std::to_string(declared) +
                           " frames declared (truncated file?)");
    double* out = clip.motion.data() + size_t(f) * size_t(channel_count);
    int k = 0;
    size_t i = 0;
    while (i < l.size()) {
      while (i < l.size() && IsSpace(l[i])) ++i;
      size_t j = i;
      while (j < l.size() && !IsSpace(l[j])) ++j;
      if (j == i) break;
      if (k >= channel_count)
        return Malformed(source, reader.line_no(),
                         "frame " + std::to_string(f) + " has more than the " +
                             std::to_string(channel_count) + " values expected");
      if (!ParseDouble(l.substr(i, j - i), &out[k]))
        return Malformed(source, reader.line_no(),
                         "value '" + std::string(l.substr(i, j - i)) + "' is not a number");
      ++k;
      i = j;
    }
    if (k != channel_count)
      return Malformed(source, reader.line_no(),
                       "frame " + std::to_string(f) + " has " + std::to_string(k) + " values, expected " +
                           std::to_string(channel_count));
  }
  return Status::Ok();
}

// Up axis: look at the root -> highest-in-hierarchy head-ish joint over a few frames (Z-up data
// gets clip.world_fix).
void DetectUpAxis(BvhClip& clip) {
  if (clip.num_frames <= 0) return;
  int head = -1;
  for (const char* name : {"CC_Base_Head", "Head", "head", "Neck", "CC_Base_NeckTwist01"}) {
    head = clip.FindJoint(name);
    if (head >= 0) break;
  }
  // Measured from the pelvis, not the root: Bandai Namco's joint_Root stays on the floor at
  // the origin while the hips walk metres away.
  int pelvis = 0;
  for (const char* name : {"Hips", "CC_Base_Hip", "hip", "pelvis", "Pelvis"}) {
    if (const int k = clip.FindJoint(name); k >= 0) {
      pelvis = k;
      break;
    }
  }
  if (head >= 0) {
    Eigen::Vector3d up_sum = Eigen::Vector3d::Zero();
    const int samples = std::min(clip.num_frames, 9);
    for (int s = 0; s < samples; ++s) {
      const int f = int((int64_t(s) * clip.num_frames) / samples);
      const auto p = ForwardKinematics(clip, f);
      const Eigen::Vector3d d = p[size_t(head)] - p[size_t(pelvis)];
      if (d.norm() > 0) up_sum += d.normalized();
    }
    // Z-up data (iClone RL_BoneRoot): rotate world by -90 degrees about X: (x, y, z) -> (x, z, -y).
    if (up_sum.z() > std::abs(up_sum.y()) && up_sum.z() > std::abs(up_sum.x())) {
      clip.z_up_input = true;
      clip.world_fix = Eigen::AngleAxisd(-kPi / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
    }
  }
}

// Units, reference frame and axes by skeleton family (BvhOptions::normalize).
void NormalizeClip(BvhClip& clip, int channel_count) {
  // Units.
  switch (clip.family) {
    case SkeletonFamily::kCmuCgspeed:
      clip.unit_to_m = kCgspeedUnitM;
      break;
    case SkeletonFamily::kReallusionCC3:
    case SkeletonFamily::kBandaiNamco:
      clip.unit_to_m = 0.01;
      break;
    default:
      clip.unit_to_m = GuessUnit(clip.joints);
      break;
  }
  // Reference frame.
  if (clip.family == SkeletonFamily::kCmuCgspeed && clip.num_frames > 1) {
    clip.motion.erase(clip.motion.begin(), clip.motion.begin() + channel_count);
    clip.num_frames -= 1;
    clip.dropped_leading_frames = 1;
  }
  for (const auto& j : clip.joints) {
    if (j.parent != 0) continue;
    const Eigen::Vector3d a = j.offset.cwiseAbs();
    // Only a genuine rest bone counts: Bandai Namco's hips carry position channels and an
    // offset that is the clip's start position.
    const bool has_pos = std::any_of(j.channels.begin(), j.channels.end(), [](BvhChannel c) {
      return c == BvhChannel::kXpos || c == BvhChannel::kYpos || c == BvhChannel::kZpos;
    });
    if (!has_pos && j.offset.norm() > 0 && a.z() > 0.9 * j.offset.norm()) clip.z_up_hierarchy = true;
    break;
  }
  DetectUpAxis(clip);
}

}  // namespace

Result<BvhClip> ParseBvh(std::string_view text, const std::string& source, const BvhOptions& options) {
  BvhClip clip;
  clip.source = source;
  LineReader reader(text);
  std::string_view line;

  if (Status st = ParseHierarchy(reader, source, clip); !st.ok()) return st;
  const int channel_count = clip.num_channels;
  if (Status st = ParseMotionHeader(reader, source, clip); !st.ok()) return st;
  const int declared = clip.declared_frames;
  if (Status st = ParseFrames(reader, source, declared, channel_count, clip); !st.ok()) return st;
  int first_trailing_line = 0;
  while (reader.Next(&line))
    if (line.find_first_not_of(" \t\r\f\v") != std::string_view::npos && clip.ignored_trailing_lines++ == 0)
      first_trailing_line = reader.line_no();
  // A stray line after the frames is tolerated (CMU's Boxing_Toes has one); more lines after them
  // than frames declared is a wrong 'Frames:' count, whose frames would be dropped silently.
  if (declared == 0)
    return Malformed(source, first_trailing_line > 0 ? first_trailing_line : reader.line_no(),
                     clip.ignored_trailing_lines > 0
                         ? "'Frames: 0', but " + std::to_string(clip.ignored_trailing_lines) +
                               " frame line(s) follow (a wrong frame count?)"
                         : std::string("'Frames: 0': the clip has no frames"));
  if (clip.ignored_trailing_lines > declared)
    return Malformed(
        source, first_trailing_line,
        std::to_string(clip.ignored_trailing_lines) + " non-blank lines after the " +
            std::to_string(declared) +
            " frames 'Frames:' declares, more than the frames themselves (a wrong frame count?)");
  clip.num_frames = declared;

  clip.family = DetectFamily(clip.joints);
  if (options.normalize) NormalizeClip(clip, channel_count);
  if (options.max_frames >= 0 && clip.num_frames > options.max_frames) {
    clip.num_frames = options.max_frames;
    clip.motion.resize(size_t(clip.num_frames) * size_t(channel_count));
  }
  return clip;
}

Result<BvhClip> LoadBvh(const std::filesystem::path& path, const BvhOptions& options) {
  auto text = core::ReadFileText(path.string());
  if (!text.ok()) return text.status();
  return ParseBvh(*text, path.string(), options);
}

}  // namespace poseforest::renderer::assets
