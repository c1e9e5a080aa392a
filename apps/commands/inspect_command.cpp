// poseforest inspect: print and validate a forest file.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {
namespace {

class InspectCommand final : public Command {
 public:
  InspectCommand()
      : Command("inspect",
                "Loads each forest file, runs every validity check of the loader (sizes, checksum, child and\n"
                "leaf indices, thresholds, leaf sums), and prints its format version, trees, depth, node and\n"
                "leaf counts, bytes, feature constants and the joint-proposal parameters stored by\n"
                "`poseforest tune-joints`, one set per method (JPAR: mean shift, JPFC: the fast clustering;\n"
                "means over joints) and which set each method runs with, and the offset votes stored by\n"
                "`poseforest learn-votes` (JVOT: votes, trees, max offset, bandwidths, calibration bins) and\n"
                "its tracking decision (JTRK: the learned weights of the cues; JSEE: the seen decision's;\n"
                "JTFT: the skeleton fit it was learned on). Exit status 1 if any file is invalid.") {
    app_.add_option("FOREST.pff", paths_, "forest files")->required();
    app_.add_flag("--parts", parts_, "also list the part table");
    app_.add_flag("--joints", joints_,
                  "also list each joint's proposal parameters (b, lambda, zeta) for each method");
  }
  int Run() override;

 private:
  std::vector<std::string> paths_;
  bool parts_ = false, joints_ = false;
};

int InspectCommand::Run() {
  int failures = 0;
  for (const std::string& path : paths_) {
    auto bytes = core::ReadFileBytes(path);
    if (!bytes.ok()) {
      std::fprintf(stderr, "poseforest inspect: %s\n", bytes.status().ToString().c_str());
      ++failures;
      continue;
    }
    auto forest = core::ParseForest(*bytes, path);
    if (!forest.ok()) {
      std::fprintf(stderr, "poseforest inspect: %s\n", forest.status().ToString().c_str());
      ++failures;
      continue;
    }
    const core::Forest& f = *forest;
    const int stride = f.leaf_stride();
    std::printf("%s: valid poseforest forest, format %u.%u, %zu bytes\n", path.c_str(), (*bytes)[8] | (*bytes)[9] << 8,
                (*bytes)[10] | (*bytes)[11] << 8, bytes->size());
    std::printf("  trees %zu, max depth %u, parts %d, nodes %zu\n", f.trees.size(), f.max_depth(), f.num_parts,
                f.total_nodes());
    std::printf(
        "  feature: background %u mm, offset unit %.6g pixel*m, probes past the image's edge read %s\n",
        f.constants.background_mm, double(f.constants.offset_unit),
        f.constants.edge == core::ProbeEdge::kClamp ? "the edge (PEDG)" : "the background");
    std::printf("  leaves: uint8 numerators summing to 255, %d bytes per leaf\n", stride);
    for (size_t t = 0; t < f.trees.size(); ++t) {
      const auto& tree = f.trees[t];
      std::printf("  tree %zu: depth %u, %zu nodes (%zu split, %u leaves), %zu bytes of nodes + %zu of leaves\n", t,
                  tree.depth, tree.nodes.size(), tree.nodes.size() - tree.num_leaves, tree.num_leaves,
                  tree.nodes.size() * sizeof(core::Node), tree.leaves.size());
    }
    // Each method's set: its own, the mean-shift set (the fast clustering without one; a 1.1
    // file's one set served both methods), or the paper's means.
    const int minor = (*bytes)[10] | (*bytes)[11] << 8;
    core::ProposalParamsChoice choice[2];
    for (const bool fast : {false, true}) {
      choice[fast] = f.ProposalParamsFor(fast);
      double b = 0, lambda = 0, zeta = 0;
      for (const auto& p : choice[fast].params)
        b += p.bandwidth_m, lambda += p.prob_threshold, zeta += p.z_offset_m;
      const char* method = fast ? "fast clustering" : "mean shift";
      switch (choice[fast].source) {
        case core::ProposalParamsSource::kLearned:
          std::printf(
              "  joint proposals, %s: learned parameters (%s), mean b %.3f m, lambda %.3f, zeta %.3f m\n",
              method, fast ? "JPFC" : "JPAR", b / core::kNumJoints, lambda / core::kNumJoints,
              zeta / core::kNumJoints);
          break;
        case core::ProposalParamsSource::kMeanShiftSet:
          std::printf("  joint proposals, %s: none of its own; runs with the mean-shift set (JPAR)%s\n",
                      method, minor < 2 ? ", format 1.1's one set for both methods" : "");
          break;
        case core::ProposalParamsSource::kPaperMeans:
          std::printf("  joint proposals, %s: no learned parameters (infer uses the paper's means)\n",
                      method);
          break;
      }
    }
    if (const auto& votes = f.offset_votes) {
      size_t leaves = 0;
      for (const auto& tree : f.trees) leaves += tree.num_leaves;
      const auto [b_min, b_max] = std::minmax_element(votes->bandwidth_m.begin(), votes->bandwidth_m.end());
      const size_t bins = votes->share_edges.size();
      std::printf(
          "  offset votes (JVOT): %zu votes over %zu trees (%.1f per leaf), max offset %.2f m, "
          "bandwidths %.2f..%.2f m, %s\n",
          votes->total_votes(), votes->trees.size(),
          leaves ? double(votes->total_votes()) / double(leaves) : 0.0, double(votes->max_offset_m),
          double(*b_min), double(*b_max),
          bins ? ("calibration " + std::to_string(bins) + " bins").c_str() : "no calibration");
    } else {
      std::printf("  offset votes: none (the skeleton uses part proposals only)\n");
    }
    if (const auto& model = f.tracking_model) {
      std::printf("  tracking decision (JTRK): learned on %u validation joints of the %s fit%s; cue weights:",
                  model->samples, core::TrackingFitName(model->fit),
                  model->fit == core::TrackingFit::kGreedy ? "" : " (JTFT)");
      for (int k = 0; k < core::kNumTrackingFeatures; ++k)
        std::printf(" %s %.2f%s", core::TrackingFeatureName(k), double(model->shared[size_t(k)]),
                    k + 1 < core::kNumTrackingFeatures ? "," : "\n");
      if (const auto& seen = model->seen) {
        std::printf("  seen decision (JSEE): a joint is tracked when likely seen; cue weights:");
        for (int k = 0; k < core::kNumTrackingFeatures; ++k)
          std::printf(" %s %.2f%s", core::TrackingFeatureName(k), double(seen->shared[size_t(k)]),
                      k + 1 < core::kNumTrackingFeatures ? "," : "\n");
      } else {
        std::printf("  seen decision: none (no JSEE section: a joint is tracked when P(within 0.1 m) >= 0.5)\n");
      }
    } else {
      std::printf("  tracking decision: the hand-set rules (no JTRK section)\n");
    }
    if (joints_) {
      std::printf("  %-17s %26s   %26s\n", "", "mean shift: b, lambda, zeta",
                  "fast clustering: b, lambda, zeta");
      for (int j = 0; j < core::kNumJoints; ++j) {
        const auto& m = choice[0].params[size_t(j)];
        const auto& q = choice[1].params[size_t(j)];
        std::printf("  joint %-11s %7.3f m, %5.3f, %6.3f m   %7.3f m, %5.3f, %6.3f m\n",
                    std::string(core::JointName(j)).c_str(), double(m.bandwidth_m), double(m.prob_threshold),
                    double(m.z_offset_m), double(q.bandwidth_m), double(q.prob_threshold),
                    double(q.z_offset_m));
      }
    }
    if (parts_)
      for (size_t p = 0; p < f.part_names.size(); ++p) std::printf("  part %2zu: %s\n", p, f.part_names[p].c_str());
  }
  return failures == 0 ? 0 : 1;
}

}  // namespace

std::unique_ptr<Command> MakeInspectCommand() { return std::make_unique<InspectCommand>(); }

}  // namespace poseforest::apps::commands
