#pragma once
// Skeletons: one per person the segmentation found, one position per joint, a confidence in
// 0..1 that means something, a tracked / not-tracked state, ids stable over a sequence and
// optional One Euro smoothing - what Kinect's SDK, NiTE and Azure Kinect Body Tracking give.
//
// Per person (a mask label), each joint's position is chosen among its candidates on that
// person's mask (section 3.4's proposals are made for the whole frame; offset votes add more):
// by one kinematic fit of the whole skeleton (SkeletonFit::kKinematic, the default) or joint by
// joint, the most confident (kGreedy). Its
// confidence is the forest's calibration (core::ConfidenceCalibration: the precision proposals of
// that support had on validation renders) or, for forests without one, FallbackConfidence. A
// joint is *tracked* only if it has such a proposal, the proposal's support and calibrated
// confidence reach their minimums, its depth agrees with the mask's depth there, it is not at an
// image border that cuts the person, and its bone to its parent joint has a possible length: an
// upper-body frame whose legs are out of view gets no invented knees. A forest with a learned
// tracking decision (core::TrackingModel, format 1.6) replaces those rules: its P(within 0.1 m)
// of the joint, from the confidence and the same cues, is the confidence, and P >= 0.5 tracks;
// with its seen model (format 1.8) P(the camera sees the joint) >= 0.2 tracks instead
// (SkeletonOptions::seen_probability: reported not seen only when P(hidden) >= 0.8).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/confidence_calibration.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/tracking_model.h"
#include "runtime/joint_proposals.h"
#include "runtime/joint_votes.h"

namespace poseforest::runtime {

/// How a person's joints are chosen among the proposals on their mask. The values are
/// core::TrackingFit's (the fit a learned tracking decision was fitted on).
enum class SkeletonFit : uint8_t {
  /// Each joint alone: its most confident proposal on the mask (or vote candidate, when more
  /// confident).
  kGreedy = 0,
  /// One exact fit per person (pictorial structures, Felzenszwalb & Huttenlocher 2005) choosing
  /// WHICH candidate each joint takes: per joint up to fit_candidates proposals on the mask (depth
  /// agreeing, support enough) and its usable vote candidates, a proposal and a vote candidate
  /// that agree (within agree_radius_m) each taking the noisy-OR of their confidences; the choice
  /// maximizing the sum of log confidences and of bone terms along SkeletonBones (FitScore), by
  /// dynamic programming on the tree. A bone outside BoneLengthRange costs implausible_bone_log,
  /// so a confident left wrist on the right arm gives way to a less confident one that the left
  /// elbow can reach, while a wrong elbow does not drag a well-found wrist with it. Whether a
  /// chosen joint is tracked is decided as for kGreedy (the learned decision, or the rules).
  /// Then SeparateCounterparts keeps a left joint and its right counterpart apart.
  /// The default since 28 Nov 2026: it tracks more visible joints right than kGreedy on
  /// held-out renders with every forest measured (docs/runtime/live.md, "Skeleton fit").
  kKinematic = 1,
};

/// "greedy" or "kinematic" (the `--fit` flag of live and eval); nullopt for any other name.
std::optional<SkeletonFit> SkeletonFitFromName(std::string_view name);
/// "greedy" or "kinematic".
std::string_view SkeletonFitName(SkeletonFit fit);

struct SkeletonOptions;
/// The fit BuildSkeletons runs: options.fit if set, else the fit `tracking` (the forest's learned
/// decision, may be null) was fitted on when options.use_tracking_model, else kKinematic.
SkeletonFit ResolveSkeletonFit(const SkeletonOptions& options, const core::TrackingModel* tracking);

struct SkeletonOptions {
  /// The fit; unset: the one the forest's tracking decision was learned on (core::TrackingModel::
  /// fit: kGreedy for decisions of format 1.6), and kKinematic for a forest without one or when
  /// the decision is not used (ResolveSkeletonFit).
  std::optional<SkeletonFit> fit;
  int fit_candidates = 8;  ///< kKinematic: proposals per joint considered (most confident first)
  /// kKinematic: the log-likelihood of a bone outside BoneLengthRange (one of its ends is a
  /// wrong candidate), instead of ruling the pair out. log(0.05): on the main job's validation
  /// renders -2, -3 and -4 tracked the most visible joints right (docs/runtime/live.md); a
  /// very negative value (-1e30) makes such bones impossible, as before 28 Nov 2026.
  float implausible_bone_log = -3.0f;
  /// kKinematic: a left joint and its right counterpart (elbows, wrists, hands, knees, ankles,
  /// feet) placed within this distance of each other are one body part read twice, so one is
  /// wrong: SeparateCounterparts. 0 disables. 0.12 m: on the main job's validation renders 0,
  /// 0.05, 0.08, 0.12, 0.16, 0.2 and 0.25 m tracked 0.753, 0.755, 0.755, 0.758, 0.746, 0.741
  /// and 0.717 of the visible joints right (docs/runtime/live.md, "Skeleton fit").
  float counterpart_min_distance_m = 0.12f;
  /// Vote candidates that project outside the image, past a side that cuts the person, are
  /// candidates too: a joint out of the frame is placed (inferred, never tracked) instead of
  /// being left without a position.
  bool votes_beyond_frame = true;
  float min_confidence = 0.3f;   ///< calibrated confidence below this: not tracked
  float min_support_m2 = 1e-4f;  ///< proposal support (raw confidence / (fx fy)) below this: not tracked
  int mask_margin_px = 2;        ///< a proposal's pixel may miss the mask by this many pixels
  /// The proposal lies at most this far behind or in front of the mask's depth at its pixel
  /// (the z offset zeta pushes it behind the surface; 0.25 m leaves room for it).
  float max_depth_gap_m = 0.25f;
  /// A vote candidate may lie up to this far behind the mask's surface at its pixel (a hidden
  /// joint: found, not tracked); in front of it, max_depth_gap_m as for proposals.
  float max_vote_behind_m = 0.6f;
  /// kGreedy with votes: where the joint's part proposal and its best vote candidate lie within
  /// this distance of each other, two different readings of the trees (the pixels' parts and
  /// their offsets) agree, and the joint's confidence becomes 1 - (1 - c_proposal)(1 - c_vote)
  /// (noisy-OR), at the position of the more confident one. 0 disables.
  float agree_radius_m = 0.1f;
  /// Where a person's mask is cut by the image border, joints within this distance of that
  /// border are not tracked: on an upper-body frame the thighs at the bottom edge are read as
  /// knees, and the real knees lie below the picture. 0 disables.
  float edge_margin_m = 0.15f;
  /// A joint whose bone to its tracked parent (SkeletonBones: towards the head) is outside the
  /// lengths an adult or child can have (BoneLengthRange) is not tracked.
  bool check_bone_lengths = true;
  /// With a forest's learned tracking decision (core::TrackingModel, format 1.6): a joint's
  /// confidence is the model's P(within 0.1 m of the truth), and it is tracked when that reaches
  /// track_probability and it lies at the surface's depth; min_confidence, min_support_m2, the
  /// image-border, bone-length and tracked-parent rules are then cues of the model, not vetoes.
  /// false (`--no-tracking-model`) keeps the rules.
  bool use_tracking_model = true;
  /// With the decision's seen model (format 1.8, JSEE; core::TrackingModel::seen): a joint is
  /// tracked when P(the camera sees it) reaches seen_probability and it lies at the surface's
  /// depth, as Kinect's and Azure Kinect's trackers mean "tracked"; a found joint likely hidden
  /// is inferred. Its confidence stays P(within 0.1 m). false (`--no-seen-model`): tracked when
  /// P(within 0.1 m) reaches track_probability, as before 1.8.
  bool use_seen_model = true;
  /// The threshold on P(within 0.1 m) without a seen model (`--no-seen-model`, forests before 1.8).
  float track_probability = 0.5f;
  /// The threshold on P(seen) with the seen model. 0.2: a joint is reported not seen (inferred or
  /// not tracked) only when P(hidden) >= 0.8, so that a "not tracked" joint is really hidden at
  /// least 0.8 of the time (issue 26's aim) with a calibrated model. At 0.5 (before 29 Nov 2026,
  /// the likelier of the two) "not tracked" was right 0.65 of the time facing the camera; 0.2 makes
  /// it 0.81, tracks more visible joints, and tracks more hidden ones on a visible surface, so
  /// tracked joints are right a little less often (docs/runtime/votes.md, "The seen threshold").
  float seen_probability = 0.2f;
  /// A joint below the shoulders (elbow, wrist, hand, knee, ankle, foot) is tracked only if its
  /// parent is: a foot found below knees that are not tracked is a guess.
  bool require_tracked_parent = true;
  // Identity over a sequence: nearest centroid, greedy by distance.
  float max_match_distance_m = 0.5f;  ///< a person moving farther between frames gets a new id
  int max_missed_frames = 10;         ///< a person unseen this many frames is forgotten
  // One Euro filter (Casiez et al. 2012) on tracked joint positions, per coordinate.
  bool smooth = false;
  double min_cutoff_hz = 1.0;  ///< cutoff at rest: lower = smoother, more lag
  double beta = 0.5;           ///< speed coefficient (per m/s): higher = less lag when moving
  double d_cutoff_hz = 1.0;    ///< cutoff of the speed estimate
};

struct SkeletonJoint {
  bool found = false;                   ///< a proposal lies on the person (position and pixel valid)
  bool tracked = false;                 ///< found, supported, confident and on the person's depth
  Eigen::Vector3f position_m{0, 0, 0};  ///< camera frame, metres (smoothed when smoothing is on)
  Eigen::Vector2f pixel{0, 0};          ///< position_m projected, pixels
  float confidence = 0;                 ///< 0..1 (calibrated, or the fallback); 0 when not found
  float support_m2 = 0;                 ///< the proposal's raw confidence / (fx fy), m^2 (0 for votes)
  bool voted = false;                   ///< the position is a vote candidate's (runtime/joint_votes.h)
  /// Not tracked, but placed by a confident vote candidate behind the person's visible surface:
  /// a hidden joint the body model puts there (Azure Kinect's "LOW: predicted"). Never with
  /// `tracked`.
  bool inferred = false;
  /// The calibrated confidence of its proposal or vote candidate (before the tracking model;
  /// equal to `confidence` without one).
  float base_confidence = 0;
  /// The tracking model's cues for this joint (core::TrackingFeature order), filled for every
  /// found joint whether or not a model is applied: `learn-votes` fits the model on them.
  core::TrackingFeatures cues{};
};

/// A joint's state as every output names it (Azure Kinect Body Tracking's confidence levels):
/// tracked (MEDIUM), inferred (LOW: predicted, placed behind the visible surface by the votes)
/// or not tracked (NONE: not found, or found but failing a tracking rule). The numbers are the
/// C API's PF_JOINT_* values and the ROS 2 message's constants: never renumber them.
enum class JointState : uint8_t { kNotTracked = 0, kInferred = 1, kTracked = 2 };

/// kTracked if `tracked`; kInferred if found and `inferred` (and not tracked); else kNotTracked.
JointState StateOf(const SkeletonJoint& joint);
/// Whether a joint's pixel lies in a width x height image (one placed beyond the frame,
/// SkeletonOptions::votes_beyond_frame, does not).
inline bool PixelInImage(const Eigen::Vector2f& pixel, int width, int height) {
  return pixel.x() >= -0.5f && pixel.y() >= -0.5f && pixel.x() < float(width) - 0.5f &&
         pixel.y() < float(height) - 0.5f;
}
/// "tracked", "inferred" or "not_tracked" (the JSON Lines and Python `state` strings).
std::string_view JointStateName(JointState state);

struct Skeleton {
  int id = 0;                           ///< stable over a sequence (SkeletonTracker); 0 before tracking
  int mask_label = 0;                   ///< the person's value in the segmentation's label image
  int pixels = 0;                       ///< mask pixels
  Eigen::Vector3f centroid_m{0, 0, 0};  ///< mean of the mask's back-projected pixels, metres
  std::array<SkeletonJoint, core::kNumJoints> joints;
  int tracked_joints() const;
};

/// The lines of a skeleton picture / marker, (parent, child) pairs of core::Joint indices, a tree
/// rooted at the neck, parents listed before their children. The paper's 16 joints have no hips,
/// so the legs hang from the shoulders (the torso's sides).
const std::vector<std::pair<int, int>>& SkeletonBones();

/// Plausible length range of bone (parent, child) in metres (generous: children to tall adults,
/// joint positions being proposals, not anatomy).
std::pair<float, float> BoneLengthRange(int parent, int child);

/// A typical adult length of bone (parent, child), metres: the centre of the soft preference of
/// SkeletonFit::kKinematic (tests/runtime/test_skeleton.cpp checks these against the renderer's
/// body family). 0 for a pair that is not a bone.
float TypicalBoneLength(int parent, int child);

/// SkeletonFit::kKinematic's inputs for one person: per joint, its candidate proposals' positions
/// (camera frame, metres) and calibrated confidences, most confident first.
struct FitCandidate {
  Eigen::Vector3f position{0, 0, 0};
  float confidence = 0;
  bool excluded = false;  ///< the fit may not choose it (SkeletonOptions::counterpart_min_distance_m)
};
using FitCandidates = std::array<std::vector<FitCandidate>, core::kNumJoints>;
/// The fit's objective for `choice` (per joint a candidate index, -1 = missing): the sum of log
/// confidences (missing: a constant below any candidate's; an excluded candidate: impossible,
/// -1e30) and of the bones' terms (BoneLengthRange
/// outside: options.implausible_bone_log; within: a Gaussian about TypicalBoneLength, sigma
/// 0.3 mu + 3 cm; a joint below the shoulders with a missing parent: impossible, -1e30).
double FitScore(const FitCandidates& candidates, const std::array<int, core::kNumJoints>& choice,
                const SkeletonOptions& options);
/// The choice maximizing FitScore, exactly (dynamic programming on SkeletonBones' tree).
std::array<int, core::kNumJoints> FitSkeleton(const FitCandidates& candidates, const SkeletonOptions& options);
/// After FitSkeleton (`chosen`): where a left joint and its right counterpart (elbows, wrists,
/// hands, knees, ankles, feet, in that order) were chosen within
/// options.counterpart_min_distance_m of each other, the fit is run again twice, once with each
/// side's candidates within that distance of the other side's position excluded; the one with
/// the higher FitScore stands (its exclusions stay in `candidates`, and `chosen` becomes its
/// choice). The tree has no edge between the two sides, so the exact fit cannot keep them apart.
void SeparateCounterparts(FitCandidates& candidates, std::array<int, core::kNumJoints>& chosen,
                          const SkeletonOptions& options);

/// Which confidence a table gives: "calibrated (tune-joints, N validation proposals)" or the
/// fallback's name, for messages.
std::string DescribeConfidence(const core::ConfidenceCalibration* calibration);

/// One skeleton per person label 1..num_people of `masks` (0 = background) with at least one
/// pixel; `depth` (mm) is the frame the proposals were made on. `calibration` may be null (the
/// fallback). Skeletons come in label order with id 0. `votes` (CastVotes: per person, label - 1),
/// when given, adds vote candidates: greedy takes one over the proposals when it is more
/// confident; kinematic weighs them with the proposals in the fit. A joint placed by a vote is
/// tracked only if its calibrated confidence reaches min_confidence and it lies at the mask's
/// depth (a hidden joint's vote is found, not tracked). `tracking` (the forest's learned
/// decision), when given and options.use_tracking_model, decides tracked instead of the rules
/// (SkeletonOptions::use_tracking_model).
std::vector<Skeleton> BuildSkeletons(const FrameProposals& proposals, const core::LabelImage& masks,
                                     int num_people, const core::DepthImage& depth,
                                     const core::CameraIntrinsics& camera,
                                     const core::ConfidenceCalibration* calibration,
                                     const SkeletonOptions& options,
                                     const std::vector<PersonVotes>* votes = nullptr,
                                     const core::TrackingModel* tracking = nullptr);

/// Person ids over a sequence and the optional smoothing. Not thread-safe; one per stream.
class SkeletonTracker {
 public:
  explicit SkeletonTracker(const SkeletonOptions& options) : options_(options) {}
  /// Gives each skeleton an id (the nearest previous person's, else a new one, from 1 up),
  /// smooths its tracked joints if asked (time in seconds, increasing), and returns them
  /// ordered by id. Joint pixels are re-projected with `camera` after smoothing.
  std::vector<Skeleton> Update(std::vector<Skeleton> skeletons, double timestamp_s,
                               const core::CameraIntrinsics& camera);
  int people_seen() const { return next_id_ - 1; }

 private:
  struct OneEuro {
    bool init = false;
    double x = 0, dx = 0;
    double Filter(double value, double dt, const SkeletonOptions& o);
  };
  struct Track {
    int id = 0;
    Eigen::Vector3f centroid{0, 0, 0};
    int missed = 0;
    double last_time = 0;
    std::array<std::array<OneEuro, 3>, core::kNumJoints> filters;
  };
  SkeletonOptions options_;
  std::vector<Track> tracks_;
  int next_id_ = 1;
};

/// `v` as printf writes it with `format` (e.g. "%.4f", "%.5g"), read back: how the runtime's JSON
/// records round their numbers. NaN and infinities (which JSON lacks) give 0.
double PrintedValue(double v, const char* format);

/// One JSON Lines record (no newline) for a frame: docs/runtime/live.md has the schema.
/// Written with nlohmann-json (strings escaped by it, invalid UTF-8 replaced by U+FFFD);
/// positions rounded to 0.1 mm, pixels to 0.1 px, confidences to 4 decimals, time to 1 us.
std::string SkeletonsJsonLine(int64_t index, double time_s, const std::string& source,
                              const std::vector<Skeleton>& skeletons);

}  // namespace poseforest::runtime
