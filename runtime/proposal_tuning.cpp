#include "runtime/proposal_tuning.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <exception>

namespace poseforest::runtime {
namespace {

// Proposals of every frame with `opt` (frames in parallel, one thread per frame).
std::vector<FrameProposals> ProposeAll(const std::vector<ValidationFrame>& frames, ProposalOptions opt,
                                       int threads) {
  opt.num_threads = 1;
  std::vector<FrameProposals> out(frames.size());
  std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (long k = 0; k < long(frames.size()); ++k) {
    try {
      out[size_t(k)] = ProposeJoints(frames[size_t(k)].depth, frames[size_t(k)].probs, opt);
    } catch (...) {
#pragma omp critical(poseforest_tuning_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
  return out;
}

// AP of joint j over all frames with the proposals moved by dz along z.
double ApShifted(const std::vector<ValidationFrame>& frames, const std::vector<FrameProposals>& proposals,
                 int j, float dz, float distance_m) {
  JointApEvaluator ev(distance_m);
  FrameProposals one;
  for (size_t k = 0; k < frames.size(); ++k) {
    one[size_t(j)] = proposals[k][size_t(j)];
    for (JointProposal& p : one[size_t(j)]) p.position.z() += dz;
    ev.AddFrame(one, frames[k].people);
  }
  return ev.AveragePrecision(j);
}

}  // namespace

TuningResult TuneProposalParams(const std::vector<ValidationFrame>& frames, const ProposalOptions& base,
                                const TuningGrid& grid, float distance_m,
                                const std::function<void(int done, int total)>& progress) {
  const int threads = base.num_threads > 0 ? base.num_threads : omp_get_max_threads();
  TuningResult result;
  result.params = base.params;
  std::array<bool, core::kNumJoints> visible{};
  for (const auto& f : frames)
    for (const auto& p : f.people)
      for (int j = 0; j < core::kNumJoints; ++j) visible[size_t(j)] |= p.visible[size_t(j)];

  {  // The starting point, for the before/after comparison.
    const auto proposals = ProposeAll(frames, base, threads);
    JointApEvaluator ev(distance_m);
    for (size_t k = 0; k < frames.size(); ++k) ev.AddFrame(proposals[k], frames[k].people);
    for (int j = 0; j < core::kNumJoints; ++j) result.base_ap[size_t(j)] = ev.AveragePrecision(j);
  }

  std::array<double, core::kNumJoints> best_ap, best_score;
  best_ap.fill(-1.0);
  best_score.fill(-1.0);
  const int total = int(grid.bandwidth_m.size() * grid.prob_threshold.size());
  int done = 0;
  for (float b : grid.bandwidth_m) {
    for (float lambda : grid.prob_threshold) {
      // Every joint at (b, lambda, 0) in one run: joints do not interact.
      ProposalOptions opt = base;
      for (auto& p : opt.params) p = {b, lambda, 0.0f};
      const auto at_surface = ProposeAll(frames, opt, threads);
      std::vector<double> aps(size_t(core::kNumJoints) * grid.z_offset_m.size(), -1.0);
#pragma omp parallel for collapse(2) schedule(dynamic, 1) num_threads(threads)
      for (int j = 0; j < core::kNumJoints; ++j)
        for (int z = 0; z < int(grid.z_offset_m.size()); ++z)
          if (visible[size_t(j)])
            aps[size_t(j) * grid.z_offset_m.size() + size_t(z)] =
                ApShifted(frames, at_surface, j, grid.z_offset_m[size_t(z)], distance_m);
      // Strictly better wins, in grid order, so ties keep the earlier (smaller) grid values.
      // With mirror_pairs the score of a joint is the mean AP of it and its mirror (over those
      // of the two that appear), so both sides pick the same point.
      const size_t nz = grid.z_offset_m.size();
      for (int j = 0; j < core::kNumJoints; ++j) {
        if (!visible[size_t(j)]) continue;
        const int m = grid.mirror_pairs ? core::MirrorJoint(j) : j;
        for (size_t z = 0; z < nz; ++z) {
          double score = aps[size_t(j) * nz + z];
          if (m != j && visible[size_t(m)]) score = (score + aps[size_t(m) * nz + z]) / 2;
          if (score > best_score[size_t(j)]) {
            best_score[size_t(j)] = score;
            best_ap[size_t(j)] = aps[size_t(j) * nz + z];
            result.params[size_t(j)] = {b, lambda, grid.z_offset_m[z]};
          }
        }
      }
      if (progress) progress(++done, total);
    }
  }
  double sum = 0, base_sum = 0;
  int n = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    if (!visible[size_t(j)]) continue;
    result.ap[size_t(j)] = best_ap[size_t(j)];
    sum += result.ap[size_t(j)];
    base_sum += result.base_ap[size_t(j)];
    ++n;
  }
  result.mean_ap = n ? sum / n : 0.0;
  result.base_mean_ap = n ? base_sum / n : 0.0;
  return result;
}

std::vector<float> IsotonicFit(const std::vector<double>& values, const std::vector<double>& weights) {
  struct Block {
    double w, wy;
    size_t n;  // entries (with weight) pooled
  };
  std::vector<Block> blocks;
  std::vector<size_t> weighted;
  for (size_t i = 0; i < values.size(); ++i) {
    if (!(weights[i] > 0)) continue;
    weighted.push_back(i);
    blocks.push_back({weights[i], weights[i] * values[i], 1});
    while (blocks.size() > 1 &&
           blocks[blocks.size() - 2].wy / blocks[blocks.size() - 2].w > blocks.back().wy / blocks.back().w) {
      const Block b = blocks.back();
      blocks.pop_back();
      blocks.back().w += b.w, blocks.back().wy += b.wy, blocks.back().n += b.n;
    }
  }
  std::vector<float> out(values.size(), 0.0f);
  if (weighted.empty()) return out;
  std::vector<double> fitted;
  for (const Block& b : blocks) fitted.insert(fitted.end(), b.n, b.wy / b.w);
  size_t next = 0;
  double current = fitted[0];
  for (size_t i = 0; i < values.size(); ++i) {
    if (next < weighted.size() && weighted[next] == i) current = fitted[next++];
    out[i] = float(current);
  }
  return out;
}

core::ConfidenceCalibration CalibrateConfidence(const std::vector<ValidationFrame>& frames,
                                                const ProposalOptions& options, float distance_m) {
  const int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();
  const auto proposals = ProposeAll(frames, options, threads);
  core::ConfidenceCalibration cal;
  cal.method = options.method == ProposalMethod::kFastClustering
                   ? core::ConfidenceCalibration::Method::kFastClustering
                   : core::ConfidenceCalibration::Method::kMeanShift;
  cal.support_edges_m2 = core::DefaultSupportEdges();
  const size_t bins = cal.support_edges_m2.size();
  const double area = options.camera.fx * options.camera.fy;
  std::array<std::vector<double>, core::kNumJoints> n, tp;
  for (int j = 0; j < core::kNumJoints; ++j) n[size_t(j)].assign(bins, 0), tp[size_t(j)].assign(bins, 0);
  for (size_t k = 0; k < frames.size(); ++k)
    for (int j = 0; j < core::kNumJoints; ++j)
      for (const JointProposal& p : proposals[k][size_t(j)]) {
        const float support = float(double(p.confidence) / area);
        const size_t bin = size_t(std::max<std::ptrdiff_t>(
            0, std::upper_bound(cal.support_edges_m2.begin(), cal.support_edges_m2.end(), support) -
                   cal.support_edges_m2.begin() - 1));
        bool right = false;
        for (const PersonJoints& person : frames[k].people)
          right |= (person.position[size_t(j)] - p.position).norm() <= distance_m;
        n[size_t(j)][bin] += 1;
        tp[size_t(j)][bin] += right;
        ++cal.samples;
      }
  for (int j = 0; j < core::kNumJoints; ++j) {
    std::vector<double> precision(bins, 0);
    bool any = false;
    for (size_t b = 0; b < bins; ++b) {
      if (n[size_t(j)][b] > 0) precision[b] = tp[size_t(j)][b] / n[size_t(j)][b], any = true;
    }
    if (!any) {
      auto& row = cal.precision[size_t(j)];
      row.resize(bins);
      for (size_t b = 0; b < bins; ++b) {
        const double hi = b + 1 < bins ? cal.support_edges_m2[b + 1] : cal.support_edges_m2[b] * 1.5;
        row[b] = core::FallbackConfidence(float(std::sqrt(double(cal.support_edges_m2[b]) * hi)));
      }
      continue;
    }
    cal.precision[size_t(j)] = IsotonicFit(precision, n[size_t(j)]);
  }
  return cal;
}

}  // namespace poseforest::runtime
