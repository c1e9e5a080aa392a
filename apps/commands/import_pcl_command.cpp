// poseforest import-pcl: convert PCL's trained people trees into a poseforest forest file.
#include <cstdio>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "runtime/core/forest_format.h"
#include "runtime/pcl_import.h"

namespace poseforest::apps::commands {
namespace {

class ImportPclCommand final : public Command {
 public:
  ImportPclCommand()
      : Command("import-pcl",
                "Converts trees trained by the Point Cloud Library's Shotton-style people detector\n"
                "(pcl::gpu::people; text files \"tree_20.txt\", or their .bz2 as in shared/data/pretrained/\n"
                "pcl_people_trees) into one poseforest forest with PCL's 25-part table, so the runtime can\n"
                "run them (e.g. `poseforest infer --forest pcl.pff frame`). See runtime/pcl_import.h for how\n"
                "PCL's feature maps onto ours and the two small differences that remain.") {
    app_.add_option("TREE", trees_, "PCL tree files")->required();
    app_.add_option("--out", out_, "forest file to write")->type_name("FILE")->required();
  }
  int Run() override;

 private:
  std::vector<std::string> trees_;
  std::string out_;
};

int ImportPclCommand::Run() {
  if (const std::string bad = CheckOutputFile("--out", out_, trees_); !bad.empty()) return UsageError(bad);
  std::fprintf(stderr, "importing %zu PCL tree(s)...\n", trees_.size());
  auto forest = runtime::ImportPclTrees(trees_);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  if (auto st = core::SaveForest(*forest, out_); !st.ok()) {
    std::fprintf(stderr, "poseforest import-pcl: %s\n", st.ToString().c_str());
    return 1;
  }
  std::printf("wrote %s: %zu trees, depth %u, %zu nodes, %d parts\n", out_.c_str(), forest->trees.size(),
              forest->max_depth(), forest->total_nodes(), forest->num_parts);
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeImportPclCommand() { return std::make_unique<ImportPclCommand>(); }

}  // namespace poseforest::apps::commands
