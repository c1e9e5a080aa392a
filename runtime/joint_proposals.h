#pragma once
// Joint position proposals (section 3.4): the classified foreground pixels are reprojected to
// 3D; for each joint j, pixel i gets weight w_ij = P(j | I, x_i) * d_i^2 (eq. 8, d in metres;
// P pools the joint's parts, e.g. the four head parts), and the modes of the weighted Gaussian
// density (eq. 7) with bandwidth b_j are found by mean shift from the pixels whose probability
// exceeds lambda_j. A proposal's confidence is the summed weight of the seed pixels that reach
// its mode; the mode, on the body surface, is pushed back by zeta_j along the camera z axis.
// The paper's faster alternative (bottom-up clustering of the above-threshold pixels) is
// selectable.

#include <array>
#include <vector>

#include <Eigen/Core>

#include "runtime/classifier.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/camera.h"
#include "runtime/core/depth_image.h"
#include "runtime/core/proposal_params.h"

namespace poseforest::runtime {

enum class ProposalMethod {
  kMeanShift,       ///< eq. 7-8 with a Gaussian kernel (the paper's main method)
  kFastClustering,  ///< clusters of above-threshold pixels on a coarse 3D grid, weighted centroids
};

struct ProposalOptions {
  ProposalMethod method = ProposalMethod::kMeanShift;
  core::ProposalParams params = core::DefaultProposalParams();
  core::CameraIntrinsics camera = core::CameraIntrinsics::KinectV1();
  /// Mean shift runs over voxels of bandwidth * voxel_fraction (pixel weights and weighted
  /// positions summed per voxel): exact at 0, a small approximation that makes it ~100x
  /// cheaper at 0.5.
  float voxel_fraction = 0.5f;
  int max_iterations = 30;
  /// Mean shift starts from one point per cell of bandwidth * seed_cell_fraction (the seed
  /// weight-averaged position of the cell's seed voxels, carrying their summed seed weight)
  /// instead of from every seed voxel; 0 = every seed voxel.
  float seed_cell_fraction = 1.0f;
  /// Mean shift ignores pixels whose P(joint) is below this floor (they are never seeds when
  /// it is below prob_threshold, and add little density); 0 = every pixel with P > 0.
  float min_probability = 0.02f;
  /// Modes closer than this fraction of the bandwidth are one proposal.
  float merge_fraction = 0.5f;
  /// Fast clustering: cell size as a fraction of the joint's bandwidth; occupied cells that
  /// touch (26-neighbourhood) form one cluster. 0.5: bench/pipeline's e2e-forest mAP 0.414 ->
  /// 0.544 on its 50 held-out frames (seed 777) and 0.359 -> 0.515 on 50 others (seed 4242)
  /// against 1.0 (whole cells of b chain neighbouring blobs into one centroid).
  float cluster_cell_fraction = 0.5f;
  int num_threads = 0;  ///< OpenMP threads over joints; 0 = all
};

struct JointProposal {
  Eigen::Vector3f position;  ///< camera frame, metres (after the z offset)
  Eigen::Vector2f pixel;     ///< where the surface mode projects, pixels
  float confidence = 0;      ///< summed weight (P * d^2, m^2) of the seed pixels reaching the mode
};

/// Proposals per joint (core::Joint order), most confident first.
using FrameProposals = std::array<std::vector<JointProposal>, core::kNumJoints>;

/// Per foreground pixel input of the proposal stage: raster index and per-joint probability.
/// Built from a classification (inferred parts) or from ground-truth labels (Fig. 7's upper
/// bound).
struct JointProbabilities {
  int width = 0, height = 0;
  std::vector<uint32_t> pixel;                                ///< raster index y*width+x
  std::vector<std::array<float, core::kNumJoints>> prob;      ///< P(joint | pixel)
  /// Each listed pixel stands for pixel_stride^2 pixels (a classification on a subsampled
  /// grid, ClassifyOptions::pixel_stride): its weight in eq. 8 is multiplied by that, so the
  /// densities and the confidences (support, m^2) keep their scale.
  int pixel_stride = 1;
};

/// From an inferred classification: uses Classification::foreground_sums if present (classify
/// with want_foreground_distributions: one pass over the foreground only, `num_threads` OpenMP
/// threads, 0 = all), else the dense Classification::sums (want_distributions). Parts are
/// pooled per joint with core::JointParts. A forest with another part table (e.g. imported PCL
/// trees) has no joint mapping: returns empty probabilities. Either way the pixels come in
/// raster order with identical probabilities. Carries the classification's pixel_stride.
JointProbabilities ProbabilitiesFromClassification(const core::DepthImage& depth, const Classification& c,
                                                   int num_threads = 0);
/// From ground-truth part labels: P = 1 for the joint whose parts contain the label.
JointProbabilities ProbabilitiesFromLabels(const core::DepthImage& depth, const core::LabelImage& labels);

/// Proposes joints. Empty frames, all-background frames and pixels with no usable depth give
/// no proposals (never an error).
FrameProposals ProposeJoints(const core::DepthImage& depth, const JointProbabilities& probs,
                             const ProposalOptions& options);

/// The same from a classification, fused: with Classification::foreground_sums (classify with
/// want_foreground_distributions) the parts are pooled per joint inside the proposals' first
/// parallel pass, so no JointProbabilities is built; the result equals
/// ProposeJoints(depth, ProbabilitiesFromClassification(depth, c), options). Without them it
/// is exactly that.
FrameProposals ProposeJointsFromClassification(const core::DepthImage& depth, const Classification& c,
                                                const ProposalOptions& options);

/// Mean shift of one weighted point set (exposed for tests): modes reached from `seeds`
/// (indices into points), with the summed seed weight reaching each, most confident first.
struct Mode {
  Eigen::Vector3f position;
  float confidence;
};
std::vector<Mode> MeanShiftModes(const std::vector<Eigen::Vector3f>& points, const std::vector<float>& weights,
                                 const std::vector<float>& seed_weights, float bandwidth, int max_iterations,
                                 float merge_distance);

}  // namespace poseforest::runtime
