#pragma once
// Per-joint parameters of the joint proposals (section 3.4): mean-shift bandwidth b_c,
// probability threshold lambda_c for seeds, and the surface-to-interior z offset zeta_c. Learned
// per joint by grid search on held-out renders and stored with the forest, one set per proposal
// method (format 1.1: optional section JPAR, mean shift; 1.2: JPFC, the fast clustering), so
// `infer` needs nothing else.

#include <array>

#include "runtime/core/body_parts.h"

namespace poseforest::core {

struct JointParams {
  float bandwidth_m = 0.065f;    ///< b_c, metres (the paper's learned mean)
  float prob_threshold = 0.14f;  ///< lambda_c: pixels above it seed mean shift (paper's mean)
  float z_offset_m = 0.039f;     ///< zeta_c, metres: a mode on the surface is pushed back this far
  bool operator==(const JointParams&) const = default;
};

/// One JointParams per evaluated joint, in core::Joint order.
using ProposalParams = std::array<JointParams, kNumJoints>;

/// The paper's mean values for every joint, the default until a forest carries learned ones.
inline ProposalParams DefaultProposalParams() { return ProposalParams{}; }

/// Where the parameters a proposal method runs with come from (Forest::ProposalParamsFor).
enum class ProposalParamsSource {
  kLearned,       ///< learned for this method (`tune-joints`) and stored with the forest
  kMeanShiftSet,  ///< the fast clustering without a set of its own runs with the mean-shift set
                  ///< (format 1.1's rule: its one set served both methods)
  kPaperMeans,    ///< nothing stored: the paper's means
};

struct ProposalParamsChoice {
  ProposalParams params;
  ProposalParamsSource source = ProposalParamsSource::kPaperMeans;
};

/// A few words for messages: "learned (stored in the forest)", ...
inline const char* DescribeProposalParamsSource(ProposalParamsSource source) {
  switch (source) {
    case ProposalParamsSource::kLearned:
      return "learned (stored in the forest)";
    case ProposalParamsSource::kMeanShiftSet:
      return "the forest's mean-shift set (none learned for this method)";
    case ProposalParamsSource::kPaperMeans:
      break;
  }
  return "the paper's means (forest has none)";
}

}  // namespace poseforest::core
