// poseforest inspect: print and validate a forest file.
#include <cstdio>
#include <string>

#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"
#include "runtime/core/forest_format.h"

namespace poseforest::cli {
namespace {
constexpr const char* kUsage = R"(usage: poseforest inspect [--parts] [--joints] FOREST.pff [FOREST.pff...]

Loads each forest file, runs every validity check of the loader (sizes, checksum, child and leaf
indices, thresholds, leaf sums), and prints its format version, trees, depth, node and leaf counts,
bytes, feature constants and the joint-proposal parameters stored by `poseforest tune-joints`
(JPAR; means over joints). Exit status 1 if any file is invalid.

options:
  --parts   also list the part table
  --joints  also list the joint-proposal parameters of each joint (b, lambda, zeta)
  --help    this text
)";
}  // namespace

int InspectMain(int argc, char** argv) {
  Args args({}, {"parts", "joints", "help"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest inspect: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (args.positional().empty()) {
    std::fprintf(stderr, "poseforest inspect: no forest file given\n\n%s", kUsage);
    return 2;
  }
  int failures = 0;
  for (const std::string& path : args.positional()) {
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
    std::printf("  feature: background %u mm, offset unit %.6g pixel*m\n", f.constants.background_mm,
                double(f.constants.offset_unit));
    std::printf("  leaves: uint8 numerators summing to 255, %d bytes per leaf\n", stride);
    for (size_t t = 0; t < f.trees.size(); ++t) {
      const auto& tree = f.trees[t];
      std::printf("  tree %zu: depth %u, %zu nodes (%zu split, %u leaves), %zu bytes of nodes + %zu of leaves\n", t,
                  tree.depth, tree.nodes.size(), tree.nodes.size() - tree.num_leaves, tree.num_leaves,
                  tree.nodes.size() * sizeof(core::Node), tree.leaves.size());
    }
    if (f.proposal_params) {
      double b = 0, lambda = 0, zeta = 0;
      for (const auto& p : *f.proposal_params) b += p.bandwidth_m, lambda += p.prob_threshold, zeta += p.z_offset_m;
      std::printf("  joint proposals: learned parameters (JPAR), mean b %.3f m, lambda %.3f, zeta %.3f m\n",
                  b / core::kNumJoints, lambda / core::kNumJoints, zeta / core::kNumJoints);
    } else {
      std::printf("  joint proposals: no learned parameters (infer uses the paper's means)\n");
    }
    if (args.Has("joints")) {
      const auto params = f.proposal_params.value_or(core::DefaultProposalParams());
      for (int j = 0; j < core::kNumJoints; ++j)
        std::printf("  joint %-11s b %.3f m, lambda %.3f, zeta %.3f m\n", std::string(core::JointName(j)).c_str(),
                    double(params[size_t(j)].bandwidth_m), double(params[size_t(j)].prob_threshold),
                    double(params[size_t(j)].z_offset_m));
    }
    if (args.Has("parts"))
      for (size_t p = 0; p < f.part_names.size(); ++p) std::printf("  part %2zu: %s\n", p, f.part_names[p].c_str());
  }
  return failures == 0 ? 0 : 1;
}

}  // namespace poseforest::cli
