#include "runtime/proposal_tuning.h"

namespace poseforest::runtime {

TuningResult TuneProposalParams(const std::vector<ValidationFrame>& frames, const ProposalOptions& base,
                                const TuningGrid& grid, float distance_m,
                                const std::function<void(int joint, double ap)>& progress) {
  TuningResult result;
  result.params = base.params;
  for (int j = 0; j < core::kNumJoints; ++j) {
    double best_ap = -1;
    core::JointParams best = base.params[size_t(j)];
    for (float b : grid.bandwidth_m) {
      for (float lambda : grid.prob_threshold) {
        // Proposals at zeta = 0 for every frame; each zeta then only shifts them.
        ProposalOptions opt = base;
        opt.params[size_t(j)] = {b, lambda, 0.0f};
        std::vector<FrameProposals> at_surface;
        at_surface.reserve(frames.size());
        for (const ValidationFrame& f : frames) {
          FrameProposals all = ProposeJoints(f.depth, f.probs, opt);
          FrameProposals only;
          only[size_t(j)] = std::move(all[size_t(j)]);
          at_surface.push_back(std::move(only));
        }
        for (float zeta : grid.z_offset_m) {
          JointApEvaluator ev(distance_m);
          for (size_t k = 0; k < frames.size(); ++k) {
            FrameProposals shifted = at_surface[k];
            for (JointProposal& p : shifted[size_t(j)]) p.position.z() += zeta;
            ev.AddFrame(shifted, frames[k].people);
          }
          if (ev.positives(j) == 0) continue;
          const double ap = ev.AveragePrecision(j);
          // Strictly better wins, so ties keep the earlier (smaller) grid values.
          if (ap > best_ap) {
            best_ap = ap;
            best = {b, lambda, zeta};
          }
        }
      }
    }
    if (best_ap >= 0) {
      result.params[size_t(j)] = best;
      result.ap[size_t(j)] = best_ap;
    }
    if (progress) progress(j, std::max(best_ap, 0.0));
  }
  double sum = 0;
  int n = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    bool any = false;
    for (const auto& f : frames)
      for (const auto& p : f.people) any |= p.visible[size_t(j)];
    if (any) sum += result.ap[size_t(j)], ++n;
  }
  result.mean_ap = n ? sum / n : 0.0;
  return result;
}

}  // namespace poseforest::runtime
