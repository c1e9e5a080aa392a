// poseforest import-pcl: convert PCL's trained people trees into a poseforest forest file.
#include <cstdio>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "runtime/core/forest_format.h"
#include "runtime/pcl_import.h"

namespace poseforest::apps::commands {
namespace {
constexpr const char* kUsage = R"(usage: poseforest import-pcl --out FOREST.pff TREE [TREE...]

Converts trees trained by the Point Cloud Library's Shotton-style people detector
(pcl::gpu::people; text files "tree_20.txt", or their .bz2 as in shared/data/pretrained/
pcl_people_trees) into one poseforest forest with PCL's 25-part table, so the runtime can
run them (e.g. `poseforest infer --forest pcl.pff frame`). See runtime/pcl_import.h for how
PCL's feature maps onto ours and the two small differences that remain.

options:
  --out FILE   forest file to write (required)
  --help       this text
)";
}  // namespace

int ImportPclMain(int argc, char** argv) {
  Args args({"out"}, {"help"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  const auto out = args.Get("out");
  if (!out || args.positional().empty()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n\n%s", !out ? "--out is required" : "no tree file given", kUsage);
    return 2;
  }
  std::fprintf(stderr, "importing %zu PCL tree(s)...\n", args.positional().size());
  auto forest = runtime::ImportPclTrees(args.positional());
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  if (auto st = core::SaveForest(*forest, *out); !st.ok()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n", st.ToString().c_str());
    return 1;
  }
  std::printf("wrote %s: %zu trees, depth %u, %zu nodes, %d parts\n", out->c_str(), forest->trees.size(),
              forest->max_depth(), forest->total_nodes(), forest->num_parts);
  return 0;
}

}  // namespace poseforest::apps::commands
