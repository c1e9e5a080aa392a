#include "runtime/skeleton.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>
#include <numbers>

namespace poseforest::runtime {

int Skeleton::tracked_joints() const {
  int n = 0;
  for (const auto& j : joints) n += j.tracked;
  return n;
}

const std::vector<std::pair<int, int>>& SkeletonBones() {
  using J = core::Joint;
  auto b = [](J a, J c) { return std::pair<int, int>(int(a), int(c)); };
  static const std::vector<std::pair<int, int>> bones = {
      b(J::kNeck, J::kHead),        b(J::kNeck, J::kLShoulder), b(J::kNeck, J::kRShoulder),
      b(J::kLShoulder, J::kLElbow), b(J::kLElbow, J::kLWrist),  b(J::kLWrist, J::kLHand),
      b(J::kRShoulder, J::kRElbow), b(J::kRElbow, J::kRWrist),  b(J::kRWrist, J::kRHand),
      b(J::kLShoulder, J::kLKnee),  b(J::kLKnee, J::kLAnkle),   b(J::kLAnkle, J::kLFoot),
      b(J::kRShoulder, J::kRKnee),  b(J::kRKnee, J::kRAnkle),   b(J::kRAnkle, J::kRFoot),
  };
  return bones;
}

std::pair<float, float> BoneLengthRange(int parent, int child) {
  using J = core::Joint;
  const auto p = J(parent), c = J(child);
  auto is = [&](J a, J b) { return (p == a && c == b); };
  if (is(J::kNeck, J::kHead)) return {0.08f, 0.45f};
  if (is(J::kNeck, J::kLShoulder) || is(J::kNeck, J::kRShoulder)) return {0.06f, 0.35f};
  if (is(J::kLShoulder, J::kLElbow) || is(J::kRShoulder, J::kRElbow)) return {0.12f, 0.5f};
  if (is(J::kLElbow, J::kLWrist) || is(J::kRElbow, J::kRWrist)) return {0.1f, 0.45f};
  if (is(J::kLWrist, J::kLHand) || is(J::kRWrist, J::kRHand)) return {0.0f, 0.25f};
  if (is(J::kLShoulder, J::kLKnee) || is(J::kRShoulder, J::kRKnee)) return {0.45f, 1.3f};
  if (is(J::kLKnee, J::kLAnkle) || is(J::kRKnee, J::kRAnkle)) return {0.2f, 0.65f};
  if (is(J::kLAnkle, J::kLFoot) || is(J::kRAnkle, J::kRFoot)) return {0.0f, 0.3f};
  return {0.0f, 1e9f};
}

std::optional<SkeletonFit> SkeletonFitFromName(std::string_view name) {
  if (name == "greedy") return SkeletonFit::kGreedy;
  if (name == "kinematic") return SkeletonFit::kKinematic;
  return std::nullopt;
}

std::string_view SkeletonFitName(SkeletonFit fit) { return fit == SkeletonFit::kKinematic ? "kinematic" : "greedy"; }

static_assert(int(SkeletonFit::kGreedy) == int(core::TrackingFit::kGreedy) &&
              int(SkeletonFit::kKinematic) == int(core::TrackingFit::kKinematic));

SkeletonFit ResolveSkeletonFit(const SkeletonOptions& options, const core::TrackingModel* tracking) {
  if (options.fit) return *options.fit;
  if (tracking && options.use_tracking_model) return SkeletonFit(tracking->fit);
  return SkeletonFit::kKinematic;
}

float TypicalBoneLength(int parent, int child) {
  using J = core::Joint;
  const auto p = J(parent), c = J(child);
  auto is = [&](J a, J b) { return (p == a && c == b); };
  // Evaluation joints (renderer EvalJoints): neck = middle of the neck, head = centre of the head,
  // hand = middle of wrist..hand tip, foot = middle of ankle..toe.
  if (is(J::kNeck, J::kHead)) return 0.17f;
  if (is(J::kNeck, J::kLShoulder) || is(J::kNeck, J::kRShoulder)) return 0.19f;
  if (is(J::kLShoulder, J::kLElbow) || is(J::kRShoulder, J::kRElbow)) return 0.28f;
  if (is(J::kLElbow, J::kLWrist) || is(J::kRElbow, J::kRWrist)) return 0.25f;
  if (is(J::kLWrist, J::kLHand) || is(J::kRWrist, J::kRHand)) return 0.08f;
  if (is(J::kLShoulder, J::kLKnee) || is(J::kRShoulder, J::kRKnee)) return 0.90f;
  if (is(J::kLKnee, J::kLAnkle) || is(J::kRKnee, J::kRAnkle)) return 0.42f;
  if (is(J::kLAnkle, J::kLFoot) || is(J::kRAnkle, J::kRFoot)) return 0.09f;
  return 0.0f;
}

namespace {

constexpr double kImpossible = -1e30;
constexpr double kMinConfidence = 1e-3;  // log of a calibrated 0 would end the fit
constexpr double kMissing = -20.0;       // below any candidate's log confidence (log 1e-3 = -6.9)

double Unary(const FitCandidates& cands, int j, int state) {
  // The fit chooses WHICH proposal (the tracked state is the candidate's own calibrated
  // confidence, as for the greedy pick): "missing" only where no candidate fits the bones.
  if (state == 0) return kMissing;
  const FitCandidate& c = cands[size_t(j)][size_t(state - 1)];
  return c.excluded ? kImpossible : std::log(std::max(kMinConfidence, double(c.confidence)));
}

double Pair(const FitCandidates& cands, const SkeletonOptions& options, int a, int sa, int b, int sb) {
  if (sb == 0) return 0.0;  // a missing child costs nothing here (its unary says how likely)
  if (sa == 0)              // below the shoulders a joint hangs from a present parent
    return options.require_tracked_parent && a != int(core::Joint::kNeck) ? kImpossible : 0.0;
  const float len = (cands[size_t(a)][size_t(sa - 1)].position - cands[size_t(b)][size_t(sb - 1)].position).norm();
  if (options.check_bone_lengths) {
    const auto [lo, hi] = BoneLengthRange(a, b);
    if (len < lo || len > hi) return std::min(0.0, double(options.implausible_bone_log));
  }
  const double mu = TypicalBoneLength(a, b), sigma = 0.3 * mu + 0.03;
  return mu > 0 ? -0.5 * ((len - mu) / sigma) * ((len - mu) / sigma) : 0.0;
}

}  // namespace

double FitScore(const FitCandidates& cands, const std::array<int, core::kNumJoints>& choice,
                const SkeletonOptions& options) {
  double score = 0;
  for (int j = 0; j < core::kNumJoints; ++j) score += Unary(cands, j, choice[size_t(j)] + 1);
  for (const auto& [a, b] : SkeletonBones())
    score += Pair(cands, options, a, choice[size_t(a)] + 1, b, choice[size_t(b)] + 1);
  return score;
}

std::array<int, core::kNumJoints> FitSkeleton(const FitCandidates& cands, const SkeletonOptions& options) {
  // best[j][s]: the best score of j's subtree with j in state s (0 missing, i + 1 candidate i).
  std::array<std::vector<double>, core::kNumJoints> best;
  for (int j = 0; j < core::kNumJoints; ++j)
    for (size_t st = 0; st <= cands[size_t(j)].size(); ++st) best[size_t(j)].push_back(Unary(cands, j, int(st)));
  // Leaves first (SkeletonBones lists parents before children): fold each child into its parent.
  std::array<std::vector<int>, core::kNumJoints> arg;  // [child][parent state] -> child state
  const auto& bones = SkeletonBones();
  for (auto it = bones.rbegin(); it != bones.rend(); ++it) {
    const int a = it->first, b = it->second;
    std::vector<int>& pick = arg[size_t(b)];
    pick.assign(best[size_t(a)].size(), 0);
    for (size_t sa = 0; sa < best[size_t(a)].size(); ++sa) {
      double top = kImpossible * 2;
      for (size_t sb = 0; sb < best[size_t(b)].size(); ++sb) {
        const double v = best[size_t(b)][sb] + Pair(cands, options, a, int(sa), b, int(sb));
        if (v > top) top = v, pick[sa] = int(sb);  // ties: the earlier state (missing, then the more confident)
      }
      best[size_t(a)][sa] += top;
    }
  }
  std::array<int, core::kNumJoints> state;
  state.fill(0);
  const int root = int(core::Joint::kNeck);
  const auto& rb = best[size_t(root)];
  state[size_t(root)] = int(std::max_element(rb.begin(), rb.end()) - rb.begin());
  for (const auto& [a, b] : bones) state[size_t(b)] = arg[size_t(b)][size_t(state[size_t(a)])];
  for (int& st : state) st -= 1;
  return state;
}

void SeparateCounterparts(FitCandidates& cands, std::array<int, core::kNumJoints>& chosen,
                          const SkeletonOptions& options) {
  const float d = options.counterpart_min_distance_m;
  if (!(d > 0)) return;
  using J = core::Joint;
  static constexpr std::array<std::pair<J, J>, 6> kPairs = {{{J::kLElbow, J::kRElbow},
                                                             {J::kLWrist, J::kRWrist},
                                                             {J::kLHand, J::kRHand},
                                                             {J::kLKnee, J::kRKnee},
                                                             {J::kLAnkle, J::kRAnkle},
                                                             {J::kLFoot, J::kRFoot}}};
  for (const auto& [left, right] : kPairs) {
    const int l = int(left), r = int(right);
    if (chosen[size_t(l)] < 0 || chosen[size_t(r)] < 0) continue;
    const Eigen::Vector3f pl = cands[size_t(l)][size_t(chosen[size_t(l)])].position;
    const Eigen::Vector3f pr = cands[size_t(r)][size_t(chosen[size_t(r)])].position;
    if ((pl - pr).norm() >= d) continue;
    // Side j gives way: its candidates within d of the other side's position are excluded.
    auto give_way = [&](int j, const Eigen::Vector3f& other) {
      FitCandidates c = cands;
      for (FitCandidate& fc : c[size_t(j)])
        if ((fc.position - other).norm() < d) fc.excluded = true;
      return c;
    };
    FitCandidates without_l = give_way(l, pr), without_r = give_way(r, pl);
    const auto fit_l = FitSkeleton(without_l, options), fit_r = FitSkeleton(without_r, options);
    if (FitScore(without_l, fit_l, options) >= FitScore(without_r, fit_r, options)) {
      cands = std::move(without_l);
      chosen = fit_l;
    } else {
      cands = std::move(without_r);
      chosen = fit_r;
    }
  }
}

std::string DescribeConfidence(const core::ConfidenceCalibration* calibration) {
  if (!calibration)
    return "uncalibrated fallback 1 - exp(-support / 0.002 m^2) (the forest has no calibration table: run "
           "tune-joints)";
  return "calibrated: precision on validation renders (tune-joints, " + std::to_string(calibration->samples) +
         " proposals, " +
         (calibration->method == core::ConfidenceCalibration::Method::kMeanShift ? "mean shift"
                                                                                 : "fast clustering") +
         ")";
}

namespace {

/// Two readings of the trees that agree (a part proposal and a vote candidate at one place),
/// taken as independent: the confidence that at least one is right.
float NoisyOr(float a, float b) { return 1.0f - (1.0f - a) * (1.0f - b); }

/// Per joint, what the candidates say before one is chosen (cues of the tracking model): a
/// proposal on the mask, a usable vote candidate, and how far apart the best of each lie.
struct CandidateCues {
  bool has_proposal = false, has_vote = false;
  Eigen::Vector3f proposal{0, 0, 0}, vote{0, 0, 0};
};

/// A vote candidate that projects onto the person's mask, with where and the mask's depth there.
struct UsableVote {
  const VoteCandidate* vote;
  Eigen::Vector2f pixel;
  int mask_depth;
};

/// One person's skeleton (mask `label`) being built by BuildSkeletons: its joints chosen from
/// the candidates, their cues, then tracked decided.
struct PersonFit {
  const FrameProposals& proposals;
  const core::LabelImage& masks;
  const core::DepthImage& depth;
  const core::CameraIntrinsics& camera;
  const core::ConfidenceCalibration* calibration;
  const SkeletonOptions& options;
  /// Vote candidates (offset votes, format 1.5) of this person, or null.
  const PersonVotes* person_votes;
  int label;
  double area;  ///< fx * fy: support (m^2) from a proposal's confidence
  int m;        ///< mask margin, pixels
  Skeleton& s;
  std::array<CandidateCues, core::kNumJoints> cand_cues{};
  // Which sides of the image cut the mask.
  bool left = false, right = false, top = false, bottom = false;

  /// The mask's depth at a pixel (nearest mask pixel within the margin), 0 = off it.
  int MaskDepthPx(const Eigen::Vector2f& pixel) const {
    // A pixel far outside the image (a vote cast beyond the frame, or not finite) is off the
    // mask; rounding it to int would overflow.
    if (!(std::abs(pixel.x()) < 1e6f && std::abs(pixel.y()) < 1e6f)) return 0;
    const int px = int(std::lround(pixel.x())), py = int(std::lround(pixel.y()));
    int mask_depth = 0, best = 1 << 30;
    for (int dy = -m; dy <= m; ++dy)
      for (int dx = -m; dx <= m; ++dx) {
        const int x = px + dx, y = py + dy;
        if (x < 0 || y < 0 || x >= masks.width || y >= masks.height || masks.at(x, y) != label) continue;
        const int d2 = dx * dx + dy * dy;
        if (d2 < best && depth.at(x, y)) best = d2, mask_depth = depth.at(x, y);
      }
    return mask_depth;
  }
  int MaskDepthAt(const JointProposal& p) const { return MaskDepthPx(p.pixel); }
  /// Joint j's vote candidates of this person that are usable: they project onto the mask and
  /// lie at most max_depth_gap_m in front of its surface and max_vote_behind_m behind it (a
  /// hidden joint lies behind what the camera sees).
  std::vector<UsableVote> UsableVotes(int j) const {
    std::vector<UsableVote> v;
    if (!person_votes) return v;
    for (const VoteCandidate& c : (*person_votes)[size_t(j)]) {
      if (!(c.position.z() > 0)) continue;
      const Eigen::Vector2f pixel = camera.Project(c.position.cast<double>()).cast<float>();
      const int d = MaskDepthPx(pixel);
      if (d == 0) {
        // Beyond the image, past a side that cuts the person: a joint out of the frame, which
        // only the votes can place (never tracked: the camera does not see it).
        if (options.votes_beyond_frame && BeyondCutSide(pixel)) v.push_back({&c, pixel, 0});
        continue;
      }
      const float gap = c.position.z() - float(d) * 1e-3f;
      if (gap < -options.max_depth_gap_m || gap > options.max_vote_behind_m) continue;
      v.push_back({&c, pixel, d});
    }
    return v;
  }
  /// Whether `pixel` lies outside the image (as PixelInImage bounds it) past a side that cuts
  /// this person's mask.
  bool BeyondCutSide(const Eigen::Vector2f& pixel) const {
    const float w = float(masks.width) - 0.5f, h = float(masks.height) - 0.5f;
    return (left && pixel.x() < -0.5f) || (right && pixel.x() >= w) || (top && pixel.y() < -0.5f) ||
           (bottom && pixel.y() >= h);
  }
  /// Places vote candidate `u`; `confidence` (>= 0) replaces its own (an agreement's noisy-OR).
  void PlaceVote(int j, const UsableVote& u, float confidence = -1) {
    SkeletonJoint& joint = s.joints[size_t(j)];
    joint = SkeletonJoint();
    joint.found = true;
    joint.voted = true;
    joint.position_m = u.vote->position;
    joint.pixel = u.pixel;
    joint.confidence = confidence >= 0 ? confidence : u.vote->confidence;
    if (u.mask_depth == 0) {  // beyond the frame: hidden by its edge
      joint.inferred = joint.confidence >= options.min_confidence;
      return;
    }
    const float gap = u.vote->position.z() - float(u.mask_depth) * 1e-3f;
    joint.tracked = joint.confidence >= options.min_confidence && std::abs(gap) <= options.max_depth_gap_m;
    // Confident, but behind what the camera sees there: a hidden joint, placed by the votes.
    joint.inferred = joint.confidence >= options.min_confidence && gap > options.max_depth_gap_m;
  }
  float Calibrated(int j, float support_m2) const {
    return calibration ? calibration->Confidence(j, support_m2) : core::FallbackConfidence(support_m2);
  }
  /// Places proposal `p`; `confidence` (>= 0) replaces its calibrated one (an agreement's noisy-OR).
  void Place(int j, const JointProposal& p, int mask_depth, float confidence = -1) {
    SkeletonJoint& joint = s.joints[size_t(j)];
    joint = SkeletonJoint();
    joint.found = true;
    joint.position_m = p.position;
    joint.pixel = p.pixel;
    joint.support_m2 = float(double(p.confidence) / area);
    joint.confidence = confidence >= 0 ? confidence : Calibrated(j, joint.support_m2);
    const float gap = p.position.z() - float(mask_depth) * 1e-3f;
    joint.tracked = joint.support_m2 >= options.min_support_m2 && joint.confidence >= options.min_confidence &&
                    std::abs(gap) <= options.max_depth_gap_m;
  }

  /// SkeletonFit::kGreedy: proposals come most confident first: the first one on this
  /// person's mask wins, unless a vote candidate is more confident.
  void FitGreedy() {
    for (int j = 0; j < core::kNumJoints; ++j) {
      const JointProposal* placed = nullptr;
      int placed_depth = 0;
      for (const JointProposal& p : proposals[size_t(j)])
        if (const int d = MaskDepthAt(p); d != 0) {
          Place(j, p, d);
          placed = &p, placed_depth = d;
          cand_cues[size_t(j)].has_proposal = true;
          cand_cues[size_t(j)].proposal = p.position;
          break;
        }
      const auto v = UsableVotes(j);
      if (v.empty()) continue;
      cand_cues[size_t(j)].has_vote = true;
      cand_cues[size_t(j)].vote = v[0].vote->position;
      const SkeletonJoint& joint = s.joints[size_t(j)];
      // A proposal and the vote agreeing: the one placed takes their noisy-OR.
      const bool agree = placed && options.agree_radius_m > 0 &&
                         (joint.position_m - v[0].vote->position).norm() <= options.agree_radius_m;
      const float confidence = agree ? NoisyOr(joint.confidence, v[0].vote->confidence) : -1.0f;
      if (!placed || v[0].vote->confidence > joint.confidence)
        PlaceVote(j, v[0], confidence);
      else if (agree)
        Place(j, *placed, placed_depth, confidence);
    }
  }

  /// The joint fit (FitSkeleton) over the candidates.
  void FitJointly() {
    // Candidates: the most confident proposals on the mask whose depth agrees with it.
    FitCandidates cands;
    std::array<std::vector<const JointProposal*>, core::kNumJoints> cand_proposal;
    std::array<const JointProposal*, core::kNumJoints> first_on_mask{};
    std::array<int, core::kNumJoints> first_depth{};
    std::array<std::vector<int>, core::kNumJoints> cand_depth;
    for (int j = 0; j < core::kNumJoints; ++j)
      for (const JointProposal& p : proposals[size_t(j)]) {
        if (int(cands[size_t(j)].size()) >= std::max(1, options.fit_candidates)) break;
        const int d = MaskDepthAt(p);
        if (d == 0) continue;
        if (!first_on_mask[size_t(j)]) first_on_mask[size_t(j)] = &p, first_depth[size_t(j)] = d;
        if (std::abs(p.position.z() - float(d) * 1e-3f) > options.max_depth_gap_m) continue;
        const float support = float(double(p.confidence) / area);
        if (support < options.min_support_m2) continue;
        cands[size_t(j)].push_back({p.position, Calibrated(j, support)});
        cand_proposal[size_t(j)].push_back(&p);
        cand_depth[size_t(j)].push_back(d);
      }
    // The vote candidates after the proposals (cand_proposal null for them).
    std::array<std::vector<UsableVote>, core::kNumJoints> vote_of;
    for (int j = 0; j < core::kNumJoints; ++j)
      for (const UsableVote& u : UsableVotes(j)) {
        cands[size_t(j)].push_back({u.vote->position, u.vote->confidence});
        cand_proposal[size_t(j)].push_back(nullptr);
        cand_depth[size_t(j)].push_back(u.mask_depth);
        vote_of[size_t(j)].push_back(u);
      }
    // Two readings of the trees agreeing (a part proposal and a vote candidate within
    // agree_radius_m of each other): each takes the noisy-OR of the two confidences, with the
    // most confident candidate of the other kind there, as kGreedy's agreement does.
    if (options.agree_radius_m > 0)
      for (int j = 0; j < core::kNumJoints; ++j) {
        std::vector<FitCandidate>& c = cands[size_t(j)];
        const size_t proposals_end = c.size() - vote_of[size_t(j)].size();
        std::vector<float> fused(c.size());
        for (size_t i = 0; i < c.size(); ++i) {
          const bool is_proposal = i < proposals_end;
          float other = 0;
          for (size_t k = is_proposal ? proposals_end : 0; k < (is_proposal ? c.size() : proposals_end); ++k)
            if ((c[i].position - c[k].position).norm() <= options.agree_radius_m)
              other = std::max(other, c[k].confidence);
          fused[i] = NoisyOr(c[i].confidence, other);
        }
        for (size_t i = 0; i < c.size(); ++i) c[i].confidence = fused[i];
      }
    for (int j = 0; j < core::kNumJoints; ++j) {
      if (first_on_mask[size_t(j)])
        cand_cues[size_t(j)].has_proposal = true, cand_cues[size_t(j)].proposal = first_on_mask[size_t(j)]->position;
      if (!vote_of[size_t(j)].empty())
        cand_cues[size_t(j)].has_vote = true, cand_cues[size_t(j)].vote = vote_of[size_t(j)][0].vote->position;
    }
    auto chosen = FitSkeleton(cands, options);
    SeparateCounterparts(cands, chosen, options);
    for (int j = 0; j < core::kNumJoints; ++j) {
      const int c = chosen[size_t(j)];
      const float confidence = c >= 0 ? cands[size_t(j)][size_t(c)].confidence : -1.0f;
      if (c >= 0 && !cand_proposal[size_t(j)][size_t(c)]) {
        PlaceVote(j, vote_of[size_t(j)][size_t(c) - (cand_proposal[size_t(j)].size() - vote_of[size_t(j)].size())],
                  confidence);
      } else if (c >= 0) {
        Place(j, *cand_proposal[size_t(j)][size_t(c)], cand_depth[size_t(j)][size_t(c)], confidence);
      } else if (first_on_mask[size_t(j)]) {  // found, but the fit leaves it out: not tracked
        Place(j, *first_on_mask[size_t(j)], first_depth[size_t(j)]);
        s.joints[size_t(j)].tracked = false;
      }
    }
  }

  /// Cut by the image border: which sides the mask touches.
  void FindCutSides() {
    for (int y = 0; y < masks.height; ++y) {
      left |= masks.at(0, y) == label;
      right |= masks.at(masks.width - 1, y) == label;
    }
    for (int x = 0; x < masks.width; ++x) {
      top |= masks.at(x, 0) == label;
      bottom |= masks.at(x, masks.height - 1) == label;
    }
  }
  bool NearCutEdge(const SkeletonJoint& joint, float margin_m) const {
    if (!(joint.position_m.z() > 0)) return false;
    const float margin = float(camera.fx) * margin_m / joint.position_m.z();
    const float x = joint.pixel.x(), y = joint.pixel.y();
    return (left && x < margin) || (right && x > float(masks.width - 1) - margin) || (top && y < margin) ||
           (bottom && y > float(masks.height - 1) - margin);
  }

  /// The tracking model's cues of every found joint (whether or not a model decides).
  void SetCues() {
    // The tracking model's cues of every found joint (whether or not a model decides).
    for (int j = 0; j < core::kNumJoints; ++j) {
      SkeletonJoint& joint = s.joints[size_t(j)];
      joint.base_confidence = joint.confidence;
      if (!joint.found) continue;
      const CandidateCues& cc = cand_cues[size_t(j)];
      core::TrackingFeatures& f = joint.cues;
      f[core::kFeatVoted] = joint.voted;
      f[core::kFeatHasProposal] = cc.has_proposal;
      f[core::kFeatHasVote] = cc.has_vote;
      const float pv = cc.has_proposal && cc.has_vote ? (cc.proposal - cc.vote).norm() : 0.5f;
      f[core::kFeatProposalVoteGap] = std::min(pv, 0.5f);
      f[core::kFeatAgreed] = cc.has_proposal && cc.has_vote && pv <= options.agree_radius_m;
      f[core::kFeatNearCutEdge] = NearCutEdge(joint, core::kCutEdgeCueMarginM);
      const int d = MaskDepthPx(joint.pixel);
      f[core::kFeatDepthGap] = d ? std::min(0.5f, std::abs(joint.position_m.z() - float(d) * 1e-3f)) : 0.5f;
    }
    for (const auto& [a, b] : SkeletonBones()) {
      SkeletonJoint& parent = s.joints[size_t(a)];
      SkeletonJoint& child = s.joints[size_t(b)];
      if (!child.found || !parent.found) continue;
      const auto [lo, hi] = BoneLengthRange(a, b);
      const float len = (parent.position_m - child.position_m).norm();
      const bool ok = len >= lo && len <= hi;
      child.cues[core::kFeatBoneOk] = ok;
      child.cues[core::kFeatBoneBad] = !ok;
      child.cues[core::kFeatParentLogit] = core::ClampedLogit(parent.base_confidence);
      parent.cues[core::kFeatChildrenOk] += ok;
    }
  }

  /// The learned decision: P(within 0.1 m) from all the cues is the confidence; tracked when
  /// likely seen (the seen model), else when likely within 0.1 m, and at the surface's depth (a
  /// joint behind the surface stays inferred or not tracked).
  void DecideWithModel(const core::TrackingModel& tracking) {
    const core::TrackingWeights* seen = tracking.seen && options.use_seen_model ? &*tracking.seen : nullptr;
    for (int j = 0; j < core::kNumJoints; ++j) {
      SkeletonJoint& joint = s.joints[size_t(j)];
      if (!joint.found) continue;
      joint.confidence = tracking.Probability(j, joint.base_confidence, joint.cues);
      const float decide = seen ? seen->Probability(j, joint.base_confidence, joint.cues) : joint.confidence;
      const float threshold = seen ? options.seen_probability : options.track_probability;
      const int d = MaskDepthPx(joint.pixel);
      const bool at_surface = d && std::abs(joint.position_m.z() - float(d) * 1e-3f) <= options.max_depth_gap_m;
      joint.tracked = at_surface && decide >= threshold;
      if (joint.tracked) joint.inferred = false;
      // Likely hidden, and its candidate confident: placed, not seen (Azure Kinect's "LOW").
      else if (seen && decide < threshold && joint.base_confidence >= options.min_confidence)
        joint.inferred = true;
    }
  }

  /// The rules: cut edges, then bones from the neck outwards.
  void DecideWithRules() {
    if (options.edge_margin_m > 0)
      for (SkeletonJoint& joint : s.joints)
        if (joint.tracked && NearCutEdge(joint, options.edge_margin_m)) joint.tracked = false;
    // Bones from the neck outwards (SkeletonBones lists parents before children).
    if (options.check_bone_lengths || options.require_tracked_parent)
      for (const auto& [a, b] : SkeletonBones()) {
        const SkeletonJoint& parent = s.joints[size_t(a)];
        SkeletonJoint& child = s.joints[size_t(b)];
        if (!child.tracked) continue;
        if (!parent.tracked) {
          // The neck is the root; its own children (head, shoulders) stand alone.
          if (options.require_tracked_parent && a != int(core::Joint::kNeck)) child.tracked = false;
          continue;
        }
        const auto [lo, hi] = BoneLengthRange(a, b);
        const float len = (parent.position_m - child.position_m).norm();
        if (options.check_bone_lengths && (len < lo || len > hi)) child.tracked = false;
      }
  }
};

}  // namespace

std::vector<Skeleton> BuildSkeletons(const FrameProposals& proposals, const core::LabelImage& masks,
                                     int num_people, const core::DepthImage& depth,
                                     const core::CameraIntrinsics& camera,
                                     const core::ConfidenceCalibration* calibration,
                                     const SkeletonOptions& options, const std::vector<PersonVotes>* votes,
                                     const core::TrackingModel* tracking) {
  std::vector<Skeleton> out;
  if (num_people <= 0 || masks.empty() || masks.width != depth.width || masks.height != depth.height)
    return out;
  // Centroids and sizes in one pass over the frame. Unproject is linear in depth, so the
  // integer sums of d, x d and y d (exact in 64 bits) give the mean point.
  struct Sums {
    int64_t d = 0, xd = 0, yd = 0;
    int count = 0;
  };
  // Run by run of one label: the sums of a run stay in registers and vectorize, where a
  // read-modify-write of sums[l] per pixel made one chain through memory (a quarter of a
  // millisecond a frame, with the other thread idle).
  std::vector<Sums> sums(size_t(num_people) + 1);
  const int w = masks.width;
  for (int y = 0; y < masks.height; ++y) {
    const uint8_t* mask_row = masks.pixels.data() + size_t(y) * size_t(w);
    const uint16_t* depth_row = depth.pixels.data() + size_t(y) * size_t(depth.width);
    int x = 0;
    while (x < w) {
      const int l = mask_row[x];
      int end = x + 1;
      if (l == 0)  // the background, most of a frame: 8 labels at a time
        for (uint64_t word; end + 8 <= w && (std::memcpy(&word, mask_row + end, 8), word == 0);) end += 8;
      while (end < w && mask_row[end] == l) ++end;
      if (l > 0 && l <= num_people) {
        int64_t d = 0, xd = 0;
        int count = 0;
        for (int i = x; i < end; ++i) {
          const int64_t di = depth_row[i];
          d += di, xd += int64_t(i) * di, count += di != 0;
        }
        Sums& sl = sums[size_t(l)];
        sl.d += d, sl.xd += xd, sl.yd += int64_t(y) * d, sl.count += count;
      }
      x = end;
    }
  }
  const double area = camera.fx * camera.fy;
  const int m = std::max(0, options.mask_margin_px);
  for (int label = 1; label <= num_people; ++label) {
    const Sums& sl = sums[size_t(label)];
    if (sl.count == 0) continue;
    Skeleton s;
    s.mask_label = label;
    s.pixels = sl.count;
    const double n = sl.count, mean_z = double(sl.d) * 1e-3 / n;
    s.centroid_m = Eigen::Vector3d((double(sl.xd) * 1e-3 / n - camera.cx * mean_z) / camera.fx,
                                   (double(sl.yd) * 1e-3 / n - camera.cy * mean_z) / camera.fy, mean_z)
                       .cast<float>();
    const PersonVotes* person_votes =
        votes && size_t(label - 1) < votes->size() ? &(*votes)[size_t(label - 1)] : nullptr;
    PersonFit fit{proposals, masks, depth, camera, calibration, options, person_votes, label, area, m, s};
    fit.FindCutSides();
    if (ResolveSkeletonFit(options, tracking) == SkeletonFit::kGreedy)
      fit.FitGreedy();
    else
      fit.FitJointly();
    fit.SetCues();
    if (tracking && options.use_tracking_model)
      fit.DecideWithModel(*tracking);
    else
      fit.DecideWithRules();
    out.push_back(std::move(s));
  }
  return out;
}

double SkeletonTracker::OneEuro::Filter(double value, double dt, const SkeletonOptions& o) {
  auto alpha = [dt](double cutoff) {
    const double tau = 1.0 / (2 * std::numbers::pi * cutoff);
    return 1.0 / (1.0 + tau / dt);
  };
  if (!init || !(dt > 0)) {
    init = true;
    x = value, dx = 0;
    return x;
  }
  const double raw_dx = (value - x) / dt;
  dx += alpha(o.d_cutoff_hz) * (raw_dx - dx);
  const double cutoff = o.min_cutoff_hz + o.beta * std::abs(dx);
  x += alpha(cutoff) * (value - x);
  return x;
}

std::vector<Skeleton> SkeletonTracker::Update(std::vector<Skeleton> skeletons, double timestamp_s,
                                              const core::CameraIntrinsics& camera) {
  // Greedy nearest-centroid matching: every (track, skeleton) pair within reach, closest first.
  struct Pair {
    float d;
    size_t track, skel;
  };
  std::vector<Pair> pairs;
  for (size_t t = 0; t < tracks_.size(); ++t)
    for (size_t k = 0; k < skeletons.size(); ++k) {
      const float d = (tracks_[t].centroid - skeletons[k].centroid_m).norm();
      if (d <= options_.max_match_distance_m) pairs.push_back({d, t, k});
    }
  std::stable_sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.d < b.d; });
  std::vector<int> track_of(skeletons.size(), -1);
  std::vector<bool> track_used(tracks_.size(), false);
  for (const Pair& p : pairs)
    if (track_of[p.skel] < 0 && !track_used[p.track])
      track_of[p.skel] = int(p.track), track_used[p.track] = true;
  for (size_t t = 0; t < tracks_.size(); ++t)
    if (!track_used[t]) ++tracks_[t].missed;
  for (size_t k = 0; k < skeletons.size(); ++k) {
    if (track_of[k] < 0) {
      Track t;
      t.id = next_id_++;
      t.last_time = timestamp_s;
      tracks_.push_back(t);
      track_of[k] = int(tracks_.size()) - 1;
    }
    Track& t = tracks_[size_t(track_of[k])];
    Skeleton& s = skeletons[k];
    s.id = t.id;
    t.centroid = s.centroid_m;
    t.missed = 0;
    const double dt = timestamp_s - t.last_time;
    t.last_time = timestamp_s;
    for (int j = 0; j < core::kNumJoints; ++j) {
      SkeletonJoint& joint = s.joints[size_t(j)];
      auto& f = t.filters[size_t(j)];
      if (!options_.smooth || !joint.tracked) {
        for (auto& c : f) c.init = false;  // a joint that comes back starts afresh
        continue;
      }
      for (int c = 0; c < 3; ++c)
        joint.position_m[c] = float(f[size_t(c)].Filter(joint.position_m[c], dt, options_));
      if (joint.position_m.z() > 0)
        joint.pixel = camera.Project(joint.position_m.cast<double>()).cast<float>();
    }
  }
  std::erase_if(tracks_, [&](const Track& t) { return t.missed > options_.max_missed_frames; });
  std::sort(skeletons.begin(), skeletons.end(),
            [](const Skeleton& a, const Skeleton& b) { return a.id < b.id; });
  return skeletons;
}

double PrintedValue(double v, const char* format) {
  if (!std::isfinite(v)) return 0.0;  // never reached for found joints: their positions are finite
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return std::strtod(buf, nullptr);
}

std::string SkeletonsJsonLine(int64_t index, double time_s, const std::string& source,
                              const std::vector<Skeleton>& skeletons) {
  using Json = nlohmann::ordered_json;
  auto vec = [](const float* v, int n, const char* format) {
    Json a = Json::array();
    for (int i = 0; i < n; ++i) a.push_back(PrintedValue(double(v[i]), format));
    return a;
  };
  Json people = Json::array();
  for (const Skeleton& s : skeletons) {
    Json joints = Json::array();
    for (int j = 0; j < core::kNumJoints; ++j) {
      const SkeletonJoint& joint = s.joints[size_t(j)];
      joints.push_back({{"name", core::JointName(j)},
                        {"position_m", joint.found ? vec(joint.position_m.data(), 3, "%.4f") : Json(nullptr)},
                        {"pixel", joint.found ? vec(joint.pixel.data(), 2, "%.1f") : Json(nullptr)},
                        {"confidence", PrintedValue(double(joint.confidence), "%.4f")},
                        {"tracked", joint.tracked},
                        {"state", JointStateName(StateOf(joint))}});
    }
    people.push_back({{"id", s.id},
                      {"pixels", s.pixels},
                      {"centroid_m", vec(s.centroid_m.data(), 3, "%.4f")},
                      {"joints", std::move(joints)}});
  }
  const Json record = {{"index", index},
                       {"time_s", PrintedValue(time_s, "%.6f")},
                       {"source", source},
                       {"people", std::move(people)}};
  return record.dump(-1, ' ', false, Json::error_handler_t::replace);
}

JointState StateOf(const SkeletonJoint& joint) {
  if (joint.tracked) return JointState::kTracked;
  return joint.found && joint.inferred ? JointState::kInferred : JointState::kNotTracked;
}

std::string_view JointStateName(JointState state) {
  switch (state) {
    case JointState::kTracked:
      return "tracked";
    case JointState::kInferred:
      return "inferred";
    case JointState::kNotTracked:
      break;
  }
  return "not_tracked";
}

}  // namespace poseforest::runtime
